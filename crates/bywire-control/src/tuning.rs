//! Finding PID gains: Ziegler–Nichols from the ultimate gain and period (found by a
//! sustained-oscillation experiment or by relay feedback), and twiddle over any cost.
//!
//! The experiments run a [`Plant`] model (or a rig behind that trait) in closed loop; they are
//! tools for commissioning, not control-path code, but still allocate nothing and every loop is
//! bounded by the experiment's duration.

use core::f64::consts::PI;

use crate::math;
use crate::plant::Plant;

/// The ultimate gain (proportional gain at the stability limit) and the period of the
/// oscillation there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ultimate {
    /// Ku.
    pub gain: f64,
    /// Tu, seconds.
    pub period: f64,
}

/// Parallel-form gains.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gains {
    /// Proportional.
    pub kp: f64,
    /// Integral (kp / Ti).
    pub ki: f64,
    /// Derivative (kp · Td).
    pub kd: f64,
}

/// Tuning rules from the ultimate gain and period.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rule {
    /// Classic Ziegler–Nichols P: Kp = 0.5 Ku.
    P,
    /// Classic Ziegler–Nichols PI: Kp = 0.45 Ku, Ti = Tu / 1.2.
    Pi,
    /// Classic Ziegler–Nichols PID: Kp = 0.6 Ku, Ti = Tu / 2, Td = Tu / 8 (quarter decay;
    /// expect around 25 % overshoot).
    Pid,
    /// Pessen integral rule: Kp = 0.7 Ku, Ti = 0.4 Tu, Td = 0.15 Tu.
    PessenIntegral,
    /// "Some overshoot": Kp = Ku / 3, Ti = 0.5 Tu, Td = Tu / 3.
    SomeOvershoot,
    /// "No overshoot": Kp = 0.2 Ku, Ti = 0.5 Tu, Td = Tu / 3.
    NoOvershoot,
    /// Tyreus–Luyben PI, for slower, robust loops: Kp = Ku / 3.2, Ti = 2.2 Tu.
    TyreusLuybenPi,
    /// Tyreus–Luyben PID: Kp = Ku / 2.2, Ti = 2.2 Tu, Td = Tu / 6.3.
    TyreusLuybenPid,
}

impl Rule {
    /// Every rule, for tables.
    pub const ALL: [Rule; 8] = [
        Rule::P,
        Rule::Pi,
        Rule::Pid,
        Rule::PessenIntegral,
        Rule::SomeOvershoot,
        Rule::NoOvershoot,
        Rule::TyreusLuybenPi,
        Rule::TyreusLuybenPid,
    ];

    /// (Kp / Ku, Ti / Tu, Td / Tu); Ti = ∞ for no integral action.
    pub fn factors(self) -> (f64, f64, f64) {
        match self {
            Rule::P => (0.5, f64::INFINITY, 0.0),
            Rule::Pi => (0.45, 1.0 / 1.2, 0.0),
            Rule::Pid => (0.6, 0.5, 0.125),
            Rule::PessenIntegral => (0.7, 0.4, 0.15),
            Rule::SomeOvershoot => (1.0 / 3.0, 0.5, 1.0 / 3.0),
            Rule::NoOvershoot => (0.2, 0.5, 1.0 / 3.0),
            Rule::TyreusLuybenPi => (1.0 / 3.2, 2.2, 0.0),
            Rule::TyreusLuybenPid => (1.0 / 2.2, 2.2, 1.0 / 6.3),
        }
    }

    /// Gains for a loop with these ultimate values.
    pub fn gains(self, ultimate: Ultimate) -> Gains {
        let (p, i, d) = self.factors();
        let kp = p * ultimate.gain;
        let ti = i * ultimate.period;
        Gains {
            kp,
            ki: if ti.is_finite() && ti > 0.0 {
                kp / ti
            } else {
                0.0
            },
            kd: kp * d * ultimate.period,
        }
    }
}

/// Why an experiment found nothing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum TuningError {
    /// The loop never oscillated within the gain range (raise the upper bound).
    NoOscillation,
    /// Every gain in the range was already unstable (lower the lower bound).
    AlwaysUnstable,
    /// Too few oscillation cycles in the experiment to measure (lengthen it).
    TooFewCycles,
    /// A parameter is not positive and finite.
    BadParameter,
}

impl core::fmt::Display for TuningError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            TuningError::NoOscillation => "the loop never became unstable in the gain range",
            TuningError::AlwaysUnstable => "the loop was unstable at the lowest gain",
            TuningError::TooFewCycles => "too few oscillation cycles to measure",
            TuningError::BadParameter => "a parameter is not positive and finite",
        })
    }
}

/// A closed-loop experiment's time base.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Experiment {
    /// Step, seconds.
    pub dt: f64,
    /// Length, seconds.
    pub duration: f64,
}

impl Experiment {
    fn steps(&self) -> Result<u64, TuningError> {
        let ok = |x: f64| x > 0.0 && x.is_finite();
        if !(ok(self.dt) && ok(self.duration)) {
            return Err(TuningError::BadParameter);
        }
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let steps = (self.duration / self.dt) as u64;
        Ok(steps)
    }
}

/// Oscillation seen in one run of a P loop on a unit step: the peak-to-peak amplitude of the
/// output in the second and in the last quarter of the run.
fn p_loop_amplitudes<P: Plant>(
    plant: &mut P,
    kp: f64,
    run: Experiment,
) -> Result<(f64, f64), TuningError> {
    let steps = run.steps()?;
    let quarter = (steps / 4).max(1);
    let (mut second, mut last) = (
        (f64::INFINITY, f64::NEG_INFINITY),
        (f64::INFINITY, f64::NEG_INFINITY),
    );
    let mut y = plant.output();
    for k in 0..steps {
        y = plant.step(run.dt, kp * (1.0 - y));
        let window = match k / quarter {
            1 => &mut second,
            3 => &mut last,
            _ => continue,
        };
        window.0 = window.0.min(y);
        window.1 = window.1.max(y);
    }
    Ok((second.1 - second.0, last.1 - last.0))
}

/// Ziegler–Nichols' experiment: raise the proportional gain of a P loop until the output
/// oscillates with constant amplitude. Bisection between `low` and `high` (runs `iterations`
/// closed-loop experiments on fresh plants from `make`), then the period at the found gain.
pub fn ultimate_by_gain_search<P: Plant>(
    mut make: impl FnMut() -> P,
    low: f64,
    high: f64,
    iterations: u32,
    run: Experiment,
) -> Result<Ultimate, TuningError> {
    if !(low > 0.0 && high > low && high.is_finite()) {
        return Err(TuningError::BadParameter);
    }
    let grows = |make: &mut dyn FnMut() -> P, kp: f64| -> Result<bool, TuningError> {
        let (early, late) = p_loop_amplitudes(&mut make(), kp, run)?;
        Ok(late > early)
    };
    if grows(&mut make, low)? {
        return Err(TuningError::AlwaysUnstable);
    }
    if !grows(&mut make, high)? {
        return Err(TuningError::NoOscillation);
    }
    let (mut stable, mut unstable) = (low, high);
    for _ in 0..iterations {
        let mid = (stable + unstable) / 2.0;
        if grows(&mut make, mid)? {
            unstable = mid;
        } else {
            stable = mid;
        }
    }
    let gain = (stable + unstable) / 2.0;
    let period = oscillation_period(&mut make(), gain, run)?;
    Ok(Ultimate { gain, period })
}

/// The mean period of a P loop's oscillation over the second half of a run, from rising
/// crossings of the running mean of the output.
fn oscillation_period<P: Plant>(
    plant: &mut P,
    kp: f64,
    run: Experiment,
) -> Result<f64, TuningError> {
    let steps = run.steps()?;
    let half = steps / 2;
    let mut y = plant.output();
    // The loop settles around kp/(1+kp) times the plant's gain; track the mean online.
    let mut mean = 0.0;
    let mut count = 0.0;
    let mut previous = None;
    let (mut first, mut last, mut cycles) = (None, 0.0, 0u32);
    for k in 0..steps {
        y = plant.step(run.dt, kp * (1.0 - y));
        if k < half / 2 {
            continue;
        }
        count += 1.0;
        mean += (y - mean) / count;
        if k < half {
            continue;
        }
        #[allow(clippy::cast_precision_loss)]
        let t = (k as f64) * run.dt;
        if let Some(p) = previous {
            if p < mean && y >= mean {
                // Interpolate the crossing instant.
                let at = t - run.dt * (y - mean) / (y - p);
                match first {
                    None => first = Some(at),
                    Some(_) => cycles += 1,
                }
                last = at;
            }
        }
        previous = Some(y);
    }
    match first {
        Some(first) if cycles >= 2 => Ok((last - first) / f64::from(cycles)),
        _ => Err(TuningError::TooFewCycles),
    }
}

/// Relay feedback (Åström–Hägglund).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Relay {
    /// Relay output amplitude d (the output is bias ± d).
    pub amplitude: f64,
    /// Output around which the relay switches (the operating point).
    pub bias: f64,
    /// Hysteresis on the error, against noise (0 for an ideal relay).
    pub hysteresis: f64,
    /// Setpoint the output oscillates around.
    pub setpoint: f64,
}

impl Relay {
    /// The relay's output after seeing `y`, switching with hysteresis.
    fn switch(&self, high: &mut bool, y: f64) -> f64 {
        let e = self.setpoint - y;
        if *high && e < -self.hysteresis {
            *high = false;
        } else if !*high && e > self.hysteresis {
            *high = true;
        }
        self.bias
            + if *high {
                self.amplitude
            } else {
                -self.amplitude
            }
    }
}

/// Run a relay in closed loop until the limit cycle settles, then measure it: the ultimate
/// period is its period, and the ultimate gain `4d / (π a)` with `a` the amplitude of the
/// output's fundamental, by Fourier integration over whole cycles (which removes most of the
/// describing-function error of using the peak amplitude).
pub fn relay_autotune<P: Plant>(
    plant: &mut P,
    relay: Relay,
    run: Experiment,
) -> Result<Ultimate, TuningError> {
    let steps = run.steps()?;
    if !(relay.amplitude > 0.0 && relay.hysteresis >= 0.0) {
        return Err(TuningError::BadParameter);
    }
    let mut high = true;
    let mut y = plant.output();
    // First half: let the limit cycle form, and time its cycles by rising switches in the
    // second quarter.
    let half = steps / 2;
    let (mut switches, mut first, mut last) = (0u32, 0.0, 0.0);
    for k in 0..half {
        let was_high = high;
        let u = relay.switch(&mut high, y);
        #[allow(clippy::cast_precision_loss)]
        let t = (k as f64) * run.dt;
        if high && !was_high && k > half / 2 {
            if switches == 0 {
                first = t;
            }
            last = t;
            switches += 1;
        }
        y = plant.step(run.dt, u);
    }
    if switches < 3 {
        return Err(TuningError::TooFewCycles);
    }
    let period = (last - first) / f64::from(switches - 1);
    let omega = 2.0 * PI / period;
    // Second half: Fourier sums of the output over whole cycles, each cycle timed from its
    // own rising switch so that a small error in the period does not accumulate.
    let (mut cos_sum, mut sin_sum, mut in_cycle) = (0.0, 0.0, None::<f64>);
    let (mut whole, mut cycles) = ((0.0, 0.0, 0.0), 0u32);
    let mut elapsed = 0.0;
    for _ in half..steps {
        let was_high = high;
        let u = relay.switch(&mut high, y);
        if high && !was_high {
            if in_cycle.is_some() {
                cycles += 1;
                whole = (cos_sum, sin_sum, elapsed);
            }
            in_cycle = Some(0.0);
        }
        y = plant.step(run.dt, u);
        if let Some(t) = in_cycle.as_mut() {
            cos_sum += y * math::cos(omega * *t) * run.dt;
            sin_sum += y * math::sin(omega * *t) * run.dt;
            *t += run.dt;
            elapsed += run.dt;
        }
    }
    let (cos_sum, sin_sum, elapsed) = whole;
    if cycles < 2 || elapsed <= 0.0 {
        return Err(TuningError::TooFewCycles);
    }
    let fundamental = 2.0 / elapsed * math::hypot(cos_sum, sin_sum);
    Ok(Ultimate {
        gain: 4.0 * relay.amplitude / (PI * fundamental),
        period,
    })
}

/// What twiddle found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwiddleResult<const N: usize> {
    /// The best parameters.
    pub params: [f64; N],
    /// Their cost.
    pub cost: f64,
    /// Cost evaluations made.
    pub evaluations: u32,
}

/// Twiddle (coordinate ascent): try each parameter up and down by its step, keep what lowers
/// the cost and widen that step by 10 %, else narrow it by 10 %; stop when the steps sum below
/// `tolerance` or after `max_evaluations`. The best cost never rises; `on_improvement` sees
/// each new best. Non-finite costs count as infinitely bad.
pub fn twiddle<const N: usize>(
    initial: [f64; N],
    steps: [f64; N],
    tolerance: f64,
    max_evaluations: u32,
    mut cost: impl FnMut(&[f64; N]) -> f64,
    mut on_improvement: impl FnMut(&[f64; N], f64),
) -> TwiddleResult<N> {
    let mut evaluate = |p: &[f64; N], evaluations: &mut u32| {
        *evaluations += 1;
        let c = cost(p);
        if c.is_finite() {
            c
        } else {
            f64::INFINITY
        }
    };
    let mut evaluations = 0;
    let mut params = initial;
    let mut deltas = steps;
    let mut best = evaluate(&params, &mut evaluations);
    // Bounded by max_evaluations: every pass evaluates at least once per parameter.
    while deltas.iter().map(|d| d.abs()).sum::<f64>() > tolerance && evaluations < max_evaluations {
        for i in 0..N {
            let (Some(p), Some(d)) = (params.get(i).copied(), deltas.get(i).copied()) else {
                continue;
            };
            let mut trial = params;
            let mut improved = false;
            for candidate in [p + d, p - d] {
                if let Some(slot) = trial.get_mut(i) {
                    *slot = candidate;
                }
                let c = evaluate(&trial, &mut evaluations);
                if c < best {
                    best = c;
                    params = trial;
                    on_improvement(&params, best);
                    improved = true;
                    break;
                }
            }
            if let Some(slot) = deltas.get_mut(i) {
                *slot = if improved { d * 1.1 } else { d * 0.9 };
            }
        }
    }
    TwiddleResult {
        params,
        cost: best,
        evaluations,
    }
}
