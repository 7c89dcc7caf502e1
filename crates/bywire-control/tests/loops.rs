//! Controllers on plants: anti-windup against windup after saturation, dead-zone and backlash
//! compensation on plants that have them, tuners against the analytical ultimate values of a
//! third-order lag, twiddle's monotone cost, and step metrics against hand-computed values.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::f64::consts::PI;

use bywire_control::metrics::{step_metrics, MetricsError};
use bywire_control::pid::{AntiWindup, Pid, PidConfig};
use bywire_control::plant::{Backlash, DeadZone, FirstOrder, Integrator, Lag, Plant, SecondOrder};
use bywire_control::stages::{BacklashCompensation, DeadZoneCompensation};
use bywire_control::tuning::{
    relay_autotune, twiddle, ultimate_by_gain_search, Experiment, Relay, Rule, TuningError,
    Ultimate,
};

const DT: f64 = 0.001;

/// Seconds from the end of a long saturating setpoint until the output is back within 2 % of
/// the new setpoint for good: the classic windup scenario (a setpoint the actuator cannot
/// reach, then a reachable one).
fn recovery_time(anti_windup: AntiWindup, plant: &mut dyn Plant) -> f64 {
    let mut pid = Pid::new(PidConfig {
        kp: 2.0,
        ki: 4.0,
        output_min: -1.0,
        output_max: 1.0,
        anti_windup,
        ..PidConfig::default()
    });
    let mut y = 0.0;
    // 2 s asking for 5 (the plant can reach 1 at full output), then 0.5.
    for _ in 0..2_000 {
        y = plant.step(DT, pid.step(DT, 5.0, y, 0.0));
    }
    let mut last_outside = 0.0;
    for k in 0..30_000 {
        y = plant.step(DT, pid.step(DT, 0.5, y, 0.0));
        if (y - 0.5).abs() > 0.01 {
            last_outside = f64::from(k) * DT;
        }
    }
    last_outside
}

#[test]
fn anti_windup_recovers_at_least_three_times_faster() {
    for (name, make) in [
        (
            "first order",
            (|| Box::new(FirstOrder::new(1.0, 0.5)) as Box<dyn Plant>) as fn() -> Box<dyn Plant>,
        ),
        ("second order", || Box::new(SecondOrder::new(1.0, 4.0, 0.8))),
    ] {
        let windup = recovery_time(AntiWindup::None, &mut *make());
        let clamping = recovery_time(AntiWindup::Clamping, &mut *make());
        let back = recovery_time(
            AntiWindup::BackCalculation { tracking_time: 0.3 },
            &mut *make(),
        );
        assert!(
            windup >= 3.0 * clamping,
            "{name}: {windup} vs clamping {clamping}"
        );
        assert!(
            windup >= 3.0 * back,
            "{name}: {windup} vs back-calculation {back}"
        );
        assert!(
            windup < 29.0,
            "{name}: the wound-up loop must recover within the run"
        );
    }
}

/// Integral of |error| of a PI loop on a first-order plant behind an input dead zone (of
/// `width`), with and without compensation.
fn dead_zone_loop(width: f64, compensate: bool) -> f64 {
    let zone = DeadZone { width };
    let compensation = DeadZoneCompensation {
        width: 0.3,
        threshold: 0.02,
    };
    let mut plant = FirstOrder::new(1.0, 0.2);
    let mut pid = Pid::new(PidConfig {
        kp: 4.0,
        ki: 8.0,
        ..PidConfig::default()
    });
    let (mut y, mut iae) = (0.0, 0.0);
    for k in 0..5_000 {
        // A slow sine setpoint: the loop crosses the dead zone twice per period.
        let setpoint = 0.5 * (2.0 * PI * 0.5 * f64::from(k) * DT).sin();
        let u = pid.step(DT, setpoint, y, 0.0);
        let u = if compensate { compensation.apply(u) } else { u };
        y = plant.step(DT, zone.apply(u));
        if k >= 2_000 {
            iae += (setpoint - y).abs() * DT;
        }
    }
    iae
}

#[test]
fn dead_zone_compensation_tracks_through_the_zone() {
    let ideal = dead_zone_loop(0.0, false);
    let plain = dead_zone_loop(0.3, false);
    let compensated = dead_zone_loop(0.3, true);
    // What the dead zone costs, with and without compensation.
    assert!(
        compensated - ideal < (plain - ideal) / 3.0,
        "tracking error {compensated} with compensation vs {plain} without ({ideal} with no zone)"
    );
}

/// Largest load position error over a back-and-forth move through a gear with play.
fn backlash_error(compensate: bool) -> f64 {
    let mut gear = Backlash { gap: 0.2, y: 0.0 };
    let mut compensation = BacklashCompensation::new(0.2, 0.001);
    // A fast position servo (the motor) drives the gear's input.
    let mut motor = FirstOrder::new(1.0, 0.01);
    let mut worst: f64 = 0.0;
    for k in 0..6_000 {
        let t = f64::from(k) * DT;
        let target = (2.0 * PI * 0.5 * t).sin();
        let command = if compensate {
            compensation.apply(target)
        } else {
            target
        };
        let load = gear.apply(motor.step(DT, command));
        if t > 1.0 {
            worst = worst.max((target - load).abs());
        }
    }
    worst
}

#[test]
fn backlash_compensation_removes_the_play_from_the_load() {
    let plain = backlash_error(false);
    let compensated = backlash_error(true);
    assert!(plain > 0.09, "the play shows: {plain}");
    assert!(compensated < plain / 3.0, "{compensated} vs {plain}");
}

/// The third-order lag 1/(s+1)³: Ku = 8, Tu = 2π/√3.
const KU: f64 = 8.0;
const TU: f64 = 2.0 * PI / 1.732_050_807_568_877_2;

fn within(found: f64, expected: f64, tolerance: f64) -> bool {
    (found - expected).abs() <= tolerance * expected
}

#[test]
fn ziegler_nichols_experiment_finds_the_ultimate_values() {
    let run = Experiment {
        dt: 0.002,
        duration: 120.0,
    };
    let u = ultimate_by_gain_search(|| Lag::<3>::new(1.0, 1.0), 2.0, 20.0, 20, run).unwrap();
    assert!(within(u.gain, KU, 0.05), "Ku {}", u.gain);
    assert!(within(u.period, TU, 0.05), "Tu {}", u.period);
    // A plant that never oscillates under P control, and a range that is unstable throughout.
    assert_eq!(
        ultimate_by_gain_search(|| FirstOrder::new(1.0, 1.0), 1.0, 50.0, 5, run),
        Err(TuningError::NoOscillation)
    );
    assert_eq!(
        ultimate_by_gain_search(|| Lag::<3>::new(1.0, 1.0), 10.0, 20.0, 5, run),
        Err(TuningError::AlwaysUnstable)
    );
    assert_eq!(
        ultimate_by_gain_search(|| Lag::<3>::new(1.0, 1.0), 20.0, 10.0, 5, run),
        Err(TuningError::BadParameter)
    );
}

#[test]
fn relay_autotune_finds_the_ultimate_values() {
    let mut plant = Lag::<3>::new(1.0, 1.0);
    let relay = Relay {
        amplitude: 0.5,
        bias: 0.0,
        hysteresis: 0.0,
        setpoint: 0.0,
    };
    let u = relay_autotune(
        &mut plant,
        relay,
        Experiment {
            dt: 0.001,
            duration: 80.0,
        },
    )
    .unwrap();
    assert!(within(u.gain, KU, 0.05), "Ku {}", u.gain);
    assert!(within(u.period, TU, 0.05), "Tu {}", u.period);
    // Too short a run to see whole cycles, and a relay of no amplitude.
    let short = Experiment {
        dt: 0.01,
        duration: 4.0,
    };
    assert_eq!(
        relay_autotune(&mut Lag::<3>::new(1.0, 1.0), relay, short),
        Err(TuningError::TooFewCycles)
    );
    let flat = Relay {
        amplitude: 0.0,
        ..relay
    };
    assert_eq!(
        relay_autotune(&mut Integrator { gain: 1.0, y: 0.0 }, flat, short),
        Err(TuningError::BadParameter)
    );
}

#[test]
fn rule_table_matches_the_published_factors() {
    let u = Ultimate {
        gain: 10.0,
        period: 2.0,
    };
    let g = Rule::Pid.gains(u);
    assert!((g.kp - 6.0).abs() < 1e-12 && (g.ki - 6.0).abs() < 1e-12 && (g.kd - 1.5).abs() < 1e-12);
    let g = Rule::Pi.gains(u);
    assert!((g.kp - 4.5).abs() < 1e-12 && (g.ki - 4.5 * 1.2 / 2.0).abs() < 1e-12 && g.kd == 0.0);
    assert_eq!(Rule::P.gains(u).ki, 0.0);
    // Every rule gives a stable, finite controller for the lag.
    for rule in Rule::ALL {
        let g = rule.gains(Ultimate {
            gain: KU,
            period: TU,
        });
        let mut pid = Pid::new(PidConfig {
            kp: g.kp,
            ki: g.ki,
            kd: g.kd,
            derivative_filter: 0.01,
            ..PidConfig::default()
        });
        let mut plant = Lag::<3>::new(1.0, 1.0);
        let mut y = 0.0;
        for _ in 0..60_000 {
            y = plant.step(DT, pid.step(DT, 1.0, y, 0.0));
        }
        let expected = if g.ki > 0.0 { 1.0 } else { g.kp / (1.0 + g.kp) };
        assert!((y - expected).abs() < 0.02, "{rule:?}: {y}");
    }
}

/// ITAE of a unit step on the lag with PID gains (kp, ki, kd).
fn itae(gains: &[f64; 3]) -> f64 {
    let mut pid = Pid::new(PidConfig {
        kp: gains[0],
        ki: gains[1],
        kd: gains[2],
        derivative_filter: 0.01,
        output_min: -20.0,
        output_max: 20.0,
        ..PidConfig::default()
    });
    let mut plant = Lag::<3>::new(1.0, 1.0);
    let (mut y, mut cost) = (0.0, 0.0);
    for k in 0..1_500 {
        let t = f64::from(k) * 0.01;
        y = plant.step(0.01, pid.step(0.01, 1.0, y, 0.0));
        cost += t * (1.0 - y).abs() * 0.01;
    }
    cost
}

#[test]
fn twiddle_lowers_the_cost_monotonically() {
    let start = [1.0, 0.1, 0.0];
    let mut history = vec![itae(&start)];
    let result = twiddle(start, [0.5, 0.1, 0.5], 0.01, 400, itae, |_, cost| {
        history.push(cost)
    });
    assert!(history.windows(2).all(|w| w[1] < w[0]), "{history:?}");
    assert!(
        result.cost < history[0] / 2.0,
        "{} from {}",
        result.cost,
        history[0]
    );
    assert_eq!(result.cost, *history.last().unwrap());
    assert!(result.evaluations <= 400 + 6);
    // A cost that is NaN somewhere is never chosen there.
    let result = twiddle(
        [0.0],
        [1.0],
        0.001,
        200,
        |p| {
            if p[0] > 0.5 {
                f64::NAN
            } else {
                (p[0] + 2.0).powi(2)
            }
        },
        |_, _| {},
    );
    assert!((result.params[0] + 2.0).abs() < 0.05, "{:?}", result.params);
}

#[test]
fn step_metrics_match_hand_computed_values() {
    // A first-order response y = 1 − e^(−t/τ), τ = 1: rise time τ·ln 9, settling (2 %)
    // τ·ln 50, (5 %) τ·ln 20, no overshoot.
    let times: Vec<f64> = (0..=10_000).map(|k| f64::from(k) * 0.001).collect();
    let values: Vec<f64> = times.iter().map(|t| 1.0 - (-t).exp()).collect();
    let m = step_metrics(&times, &values, 0.0, 1.0).unwrap();
    // Relative to the final value (1 − e^−10), which is 1 to within 5e-5.
    assert!((m.rise_time.unwrap() - 9f64.ln()).abs() < 2e-3, "{m:?}");
    assert!((m.settling_time_2 - 50f64.ln()).abs() < 3e-3, "{m:?}");
    assert!((m.settling_time_5 - 20f64.ln()).abs() < 3e-3, "{m:?}");
    assert_eq!(m.overshoot_percent, 0.0);
    // IAE of e^−t over 10 s is 1 − e^−10; ISE is (1 − e^−20)/2; ITAE is 1 − 11e^−10.
    assert!((m.iae - (1.0 - (-10f64).exp())).abs() < 1e-5, "{m:?}");
    assert!((m.ise - (1.0 - (-20f64).exp()) / 2.0).abs() < 1e-5, "{m:?}");
    assert!(
        (m.itae - (1.0 - 11.0 * (-10f64).exp())).abs() < 1e-5,
        "{m:?}"
    );
    assert!((m.steady_state_error - (-10f64).exp()).abs() < 1e-12);

    // An underdamped second-order response, ζ = 0.5, ωn = 1: overshoot e^(−πζ/√(1−ζ²)) =
    // 16.30 %, at the peak time π/ωd = 3.628 s.
    let zeta: f64 = 0.5;
    let wd = (1.0 - zeta * zeta).sqrt();
    let phi = wd.atan2(zeta);
    let times: Vec<f64> = (0..=40_000).map(|k| f64::from(k) * 0.001).collect();
    let values: Vec<f64> = times
        .iter()
        .map(|t| 1.0 - (-zeta * t).exp() / wd * (wd * t + phi).sin())
        .collect();
    let m = step_metrics(&times, &values, 0.0, 1.0).unwrap();
    let expected = 100.0 * (-PI * zeta / wd).exp();
    assert!((m.overshoot_percent - expected).abs() < 0.01, "{m:?}");
    assert!((m.peak_time - PI / wd).abs() < 2e-3, "{m:?}");
    // Downward steps and errors.
    let down: Vec<f64> = values.iter().map(|v| 5.0 - 2.0 * v).collect();
    let m2 = step_metrics(&times, &down, 5.0, 3.0).unwrap();
    assert!((m2.overshoot_percent - expected).abs() < 0.01);
    assert_eq!(
        step_metrics(&[0.0], &[1.0], 0.0, 1.0),
        Err(MetricsError::TooShort)
    );
    assert_eq!(
        step_metrics(&[0.0, 1.0], &[1.0], 0.0, 1.0),
        Err(MetricsError::LengthMismatch)
    );
    assert_eq!(
        step_metrics(&[0.0, 1.0, 1.0], &[0.0, 1.0, 1.0], 0.0, 1.0),
        Err(MetricsError::BadSample { index: 2 })
    );
    assert_eq!(
        step_metrics(&[0.0, 1.0], &[0.0, f64::NAN], 0.0, 1.0),
        Err(MetricsError::BadSample { index: 1 })
    );
    assert_eq!(
        step_metrics(&[0.0, 1.0], &[2.0, 2.0], 2.0, 3.0),
        Err(MetricsError::NoStep)
    );
}
