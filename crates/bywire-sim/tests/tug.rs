//! The simulated tug drives a route over its buses: the ADS engages the vehicle control ECU
//! on bus 1, the ECU walks eight CiA 402 drives to Operation enabled on bus 2, and the plants
//! carry the tug along the route.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use bywire_control::kinematics::Point;
use bywire_sim::tug::{Tug, TugBus, TugParams};
use bywire_tug::messages::ControlMode;

fn route() -> Vec<Point> {
    // 30 m straight, a quarter circle of 15 m radius to the left, 20 m straight.
    let mut points = straight(30);
    for k in 1..=20 {
        let a = f64::from(k) / 20.0 * std::f64::consts::FRAC_PI_2;
        points.push(Point {
            x: 30.0 + 15.0 * a.sin(),
            y: 15.0 - 15.0 * a.cos(),
        });
    }
    for y in 1..=20 {
        points.push(Point {
            x: 45.0,
            y: 15.0 + f64::from(y),
        });
    }
    points
}

fn run(seed: u64) -> Tug {
    let mut tug = Tug::new(TugParams {
        seed,
        route: route(),
        ..TugParams::default()
    })
    .unwrap();
    for _ in 0..60_000 {
        tug.step();
        if tug.remaining().unwrap() < 0.5 && tug.now().as_nanos() > 5_000_000_000 {
            break;
        }
    }
    tug
}

#[test]
fn the_tug_follows_its_route_over_its_buses() {
    let tug = run(1);
    let pose = tug.pose();
    assert_eq!(
        tug.ecu().unwrap().mode(),
        ControlMode::Autonomous,
        "engaged over bus 1"
    );
    assert!(
        tug.remaining().unwrap() < 1.0,
        "reached the end: {} m left at {:?}, pose {pose:?}",
        tug.remaining().unwrap(),
        tug.now()
    );
    // 73 m at up to 3 m/s with the start and the stop: under 40 s.
    assert!(tug.now().as_nanos() < 40_000_000_000, "{:?}", tug.now());
    let worst = tug.tracking_errors.iter().cloned().fold(0.0, f64::max);
    let mean = tug.tracking_errors.iter().sum::<f64>() / tug.tracking_errors.len() as f64;
    assert!(
        worst < 0.5 && mean < 0.2,
        "tracking error: worst {worst} m, mean {mean} m"
    );
    // Commands and state at 50 Hz on 500 kbit/s; eight drives' PDOs and heartbeats on 1 Mbit/s.
    // IMU, the hub encoders and the steering sensors' second tracks at 100 Hz on 500 kbit/s;
    // bus 1b carries the ADS's frames alone.
    let [load1, load2, load3, load1b] = tug.bus_loads();
    assert!(
        (0.01..0.1).contains(&load1)
            && (0.1..0.5).contains(&load2)
            && (0.03..0.12).contains(&load3)
            && (0.005..load1).contains(&load1b),
        "bus loads {load1} {load2} {load3} {load1b}"
    );
    // The ADS validated the ECU's wheel reports.
    assert!(tug
        .bus1_log
        .iter()
        .any(|(_, f)| f.id().unwrap().as_raw() == 0x102));
    assert!(tug.soc() < 0.8, "the battery drove it");
}

#[test]
fn the_same_seed_gives_the_same_frames() {
    let (a, b) = (run(7), run(7));
    assert_eq!(a.bus1_log, b.bus1_log);
    assert_eq!(a.bus2_log, b.bus2_log);
    assert_eq!(a.bus3_log, b.bus3_log);
    assert_eq!(a.bus1b_log, b.bus1b_log);
    assert_eq!(a.pose(), b.pose());
}

use std::time::Duration;

use bywire_core::confinement::NodeState;
use bywire_sim::event::{Happening, SimEvent};
use bywire_sim::fault::Fault;
use bywire_sim::mission::MissionEvent;
use bywire_tug::ecu::EcuEvent;
use bywire_vehicle::command::SteeringMode;
use bywire_vehicle::supervisor::{EstopState, Watchdog};

fn cruising() -> Tug {
    let mut tug = Tug::new(TugParams {
        seed: 2,
        payload: 0.0,
        ..TugParams::default()
    })
    .unwrap();
    while tug.now().as_nanos() < 8_000_000_000 {
        tug.step();
    }
    assert_eq!(tug.ecu().unwrap().mode(), ControlMode::Autonomous);
    assert!(tug.pose_speed() > 2.5, "cruising: {}", tug.pose_speed());
    tug
}

fn run_for(tug: &mut Tug, millis: u64) {
    for _ in 0..millis {
        tug.step();
    }
}

/// Events after `from`, as (ms after it, what).
fn after(tug: &Tug, from: u64) -> Vec<(u64, Happening)> {
    tug.events
        .iter()
        .filter(|e: &&SimEvent| e.t.as_nanos() >= from)
        .map(|e| ((e.t.as_nanos() - from) / 1_000_000, e.what.clone()))
        .collect()
}

/// Verifies: REQ-TO-1, REQ-FI-1.
#[test]
fn a_silent_ads_walks_the_watchdog_cascade_and_the_tug_stops() {
    let mut tug = cruising();
    let injected = tug.now().as_nanos();
    tug.inject(Fault::AdsSilence, Some(Duration::from_secs(3)));
    run_for(&mut tug, 2_000);
    // Times from the last command the ECU received.
    let from = tug
        .bus1_log
        .iter()
        .rfind(|(t, f)| t.as_nanos() < injected && f.id().unwrap().as_raw() == 0x100)
        .unwrap()
        .0
        .as_nanos();
    let events = after(&tug, from);
    let at = |level: fn(&Watchdog) -> bool| {
        events
            .iter()
            .find(|(_, what)| matches!(what, Happening::Watchdog(w) if level(w)))
            .map(|(t, _)| *t)
    };
    // Commands every 20 ms, a cycle counting as missed half a cycle after it was due: hold at
    // the first missed (30 ms), decelerate at the third (70 ms), full braking at the fifth
    // (110 ms), each within the millisecond the runner steps by.
    let (hold, decelerate, brake) = (
        at(|w| matches!(w, Watchdog::Holding { .. })).unwrap(),
        at(|w| matches!(w, Watchdog::Decelerating { .. })).unwrap(),
        at(|w| *w == Watchdog::FullBraking).unwrap(),
    );
    assert!((30..=31).contains(&hold), "{events:?}");
    assert!((70..=71).contains(&decelerate), "{events:?}");
    assert!((110..=111).contains(&brake), "{events:?}");
    assert!(tug.pose_speed() < 0.05, "stopped: {}", tug.pose_speed());
}

/// Verifies: REQ-ES-1.
#[test]
fn an_estop_latches_until_the_operator_resets_it() {
    let mut tug = cruising();
    let from = tug.now().as_nanos();
    tug.inject(Fault::Estop, Some(Duration::from_secs(2)));
    run_for(&mut tug, 6_000);
    assert!(tug.pose_speed() < 0.05);
    // (The latch passes E-stop requested and motors disabled within one evaluation.)
    let estop = |tug: &Tug| -> Vec<(u64, EstopState)> {
        after(tug, from)
            .into_iter()
            .filter_map(|(t, what)| match what {
                Happening::Estop(state) => Some((t, state)),
                _ => None,
            })
            .collect()
    };
    let states = estop(&tug);
    assert_eq!(
        states.iter().map(|(_, state)| *state).collect::<Vec<_>>(),
        [EstopState::BrakesApplied, EstopState::Stopped],
        "latched, no automatic reset: {states:?}"
    );
    assert!(
        states[0].0 <= 21,
        "braking within a frame of the E-stop: {states:?}"
    );
    let reset_at = tug.now().as_nanos() - from;
    tug.inject(Fault::OperatorReset, None);
    run_for(&mut tug, 4_000);
    let states = estop(&tug);
    assert!(
        states[2..].iter().all(|(t, _)| t * 1_000_000 >= reset_at),
        "{states:?}"
    );
    assert_eq!(states.last().unwrap().1, EstopState::Normal, "{states:?}");
    assert_eq!(
        tug.ecu().unwrap().mode(),
        ControlMode::Autonomous,
        "re-engaged"
    );
    assert!(tug.pose_speed() > 1.0, "driving again");
}

/// Verifies: REQ-FI-1.
#[test]
fn a_silent_drive_is_lost_within_its_consumer_time_and_the_tug_brakes() {
    let mut tug = cruising();
    let from = tug.now().as_nanos();
    tug.inject(Fault::DriveSilence(0x21), Some(Duration::from_secs(2)));
    run_for(&mut tug, 3_000);
    let events = after(&tug, from);
    let lost = events
        .iter()
        .find(|(_, what)| *what == Happening::Ecu(EcuEvent::HeartbeatLost(0x21)))
        .map(|(t, _)| *t)
        .unwrap();
    // Heartbeats every 100 ms, consumer time 250 ms: lost 150–251 ms after the cut.
    assert!((150..=251).contains(&lost), "{events:?}");
    assert!(
        tug.pose_speed() < 0.05,
        "braked to a stop: {}",
        tug.pose_speed()
    );
}

#[test]
fn a_crab_approach_moves_sideways_with_the_heading_held() {
    // 30 m along x, then 20 m on a diagonal 4 m to the left: the stand approach in crab.
    let mut points = straight(30);
    for k in 1..=20 {
        points.push(Point {
            x: 30.0 + f64::from(k),
            y: 0.2 * f64::from(k),
        });
    }
    let mut tug = Tug::new(TugParams {
        seed: 3,
        payload: 1_000.0,
        route: points,
        speed: 2.0,
        crab_final_m: 26.0,
        ..TugParams::default()
    })
    .unwrap();
    let mut crab_angles = Vec::new();
    for _ in 0..60_000 {
        tug.step();
        if tug.remaining().unwrap() < 15.0 && tug.remaining().unwrap() > 3.0 {
            crab_angles.push((tug.wheel_angles(), tug.pose().yaw));
        }
        if tug.remaining().unwrap() < 0.5 && tug.now().as_nanos() > 5_000_000_000 {
            break;
        }
    }
    let pose = tug.pose();
    assert!(
        (pose.y - 4.0).abs() < 0.5 && (pose.x - 50.0).abs() < 1.0,
        "at the stand: {pose:?}"
    );
    assert!(
        tug.events
            .iter()
            .any(|e| e.what == Happening::Mission(MissionEvent::SteeringMode(SteeringMode::Crab))),
        "the ADS asked for crab"
    );
    assert!(!crab_angles.is_empty());
    for (angles, yaw) in &crab_angles {
        assert!(yaw.abs() < 3f64.to_radians(), "heading held: {yaw}");
        // Every wheel at the same angle (degrees), to the left (the diagonal is 11.3°).
        for angle in angles {
            assert!((angle - angles[0]).abs() < 1.5, "crab: {angles:?}");
        }
        assert!(angles[0] > 5.0, "to the left: {angles:?}");
    }
}

fn straight(length: u32) -> Vec<Point> {
    (0..=length)
        .map(|x| Point {
            x: f64::from(x),
            y: 0.0,
        })
        .collect()
}

#[test]
fn a_tank_turn_at_the_end_rotates_the_tug_in_place() {
    let mut tug = Tug::new(TugParams {
        seed: 4,
        route: straight(20),
        speed: 2.0,
        tank_turn_deg: 90.0,
        ..TugParams::default()
    })
    .unwrap();
    let mut stopped_at = None;
    for _ in 0..120_000 {
        tug.step();
        if tug.remaining().unwrap() < 0.3 && tug.pose_speed() < 0.01 && stopped_at.is_none() {
            stopped_at = Some(tug.pose());
        }
        if tug.arrived() {
            break;
        }
    }
    assert!(tug.arrived(), "turned and stopped by {:?}", tug.now());
    let (start, end) = (stopped_at.unwrap(), tug.pose());
    assert!(
        (end.yaw - start.yaw - 90f64.to_radians()).abs() < 1.5f64.to_radians(),
        "turned 90° left: {start:?} → {end:?}"
    );
    assert!(
        (end.x - start.x).hypot(end.y - start.y) < 0.3,
        "in place: {start:?} → {end:?}"
    );
    let modes: Vec<SteeringMode> = tug
        .events
        .iter()
        .filter_map(|e| match e.what {
            Happening::Mission(MissionEvent::SteeringMode(mode)) => Some(mode),
            _ => None,
        })
        .collect();
    assert_eq!(modes, [SteeringMode::Tank, SteeringMode::Normal]);
    // The trace follows the ECU's target for the wheel, not the ADS's steering command (0°
    // in a tank turn): what run.png plots beside the wheel's angle.
    assert!(
        tug.trace
            .iter()
            .any(|s| s.steering_command == 0.0 && (s.steering_target + 60.6).abs() < 0.5),
        "the tank angle as the wheel's target"
    );
    // The front-left wheel goes to its tank angle and holds it (it used to hunt ±2° around
    // −60° for the whole turn: the linkage doubles the loop's gain there).
    let (_, turn) = tug
        .steering
        .tank_turn
        .as_ref()
        .expect("the turn was recorded");
    let m = turn.metrics().unwrap();
    assert!((turn.to + 60.6).abs() < 0.5, "{}", turn.to);
    assert!(m.settling_time_2 < 4.0, "{m:?}");
    assert!(m.overshoot_percent < 8.0, "{m:?}");
    assert!(
        turn.hold_peak_to_peak() < 0.3,
        "holds within {:.2}°",
        turn.hold_peak_to_peak()
    );
}

#[test]
fn the_step_test_records_each_step_of_the_steering() {
    let mut tug = Tug::new(TugParams {
        seed: 5,
        payload: 0.0,
        route: straight(10),
        speed: 2.0,
        steering_steps: vec![10.0, -10.0],
        ..TugParams::default()
    })
    .unwrap();
    // Engaged at about 0.4 s, two steps of 3 s, then away.
    for _ in 0..6_300 {
        tug.step();
    }
    assert!(
        tug.pose().x < 0.05,
        "standing during the test: {:?}",
        tug.pose()
    );
    for _ in 0..2_000 {
        tug.step();
    }
    assert!(tug.pose().x > 0.5, "away after it: {:?}", tug.pose());
    let steps = &tug.steering.steps;
    assert_eq!(steps.len(), 2);
    assert_eq!((steps[0].from, steps[0].to), (0.0, 10.0));
    assert_eq!((steps[1].from, steps[1].to), (10.0, -10.0));
    let mut rises = Vec::new();
    for step in steps {
        // A sample a millisecond for the hold (the ADS commands on its 20 ms cycle).
        assert!(
            (2_950..=3_000).contains(&step.times.len()),
            "{}",
            step.times.len()
        );
        let m = step.metrics().unwrap();
        // The drive's profile (20°/s of the position target, 60°/s²) and the valve's follow-up
        // bound the response: a rise of a few tenths of a second, growing with the step, a
        // modest overshoot, settled well inside the hold.
        let span = (step.to - step.from).abs();
        let rise = m.rise_time.unwrap();
        assert!((0.2..1.2).contains(&rise), "rise {rise} s for {span}°");
        assert!(m.overshoot_percent < 15.0, "{m:?}");
        assert!(m.settling_time_2 < 2.5, "{m:?}");
        assert!(m.steady_state_error.abs() < 0.5, "{m:?}");
        rises.push(rise);
    }
    assert!(
        rises[1] > rises[0],
        "the larger step rises longer: {rises:?}"
    );
}

#[test]
fn speeds_along_the_route_and_a_stop_are_kept() {
    let mut tug = Tug::new(TugParams {
        seed: 6,
        payload: 1_000.0,
        route: straight(60),
        speeds: vec![(20.0, 1.0), (45.0, 2.0)],
        stops: vec![(40.0, Duration::from_secs(3))],
        ..TugParams::default()
    })
    .unwrap();
    let (mut fastest_slow_part, mut fastest_before) = (0.0f64, 0.0f64);
    for _ in 0..120_000 {
        tug.step();
        let x = tug.pose().x;
        if (21.0..39.0).contains(&x) {
            fastest_slow_part = fastest_slow_part.max(tug.pose_speed());
        }
        if x < 12.0 {
            fastest_before = fastest_before.max(tug.pose_speed());
        }
        if tug.arrived() {
            break;
        }
    }
    assert!(tug.arrived(), "at the end by {:?}", tug.now());
    assert!(fastest_before > 2.5, "cruising before: {fastest_before}");
    assert!(
        fastest_slow_part < 1.15,
        "1 m/s from 20 m on: {fastest_slow_part}"
    );
    let at = |which: fn(&MissionEvent) -> bool| {
        tug.events
            .iter()
            .find(|e| matches!(&e.what, Happening::Mission(m) if which(m)))
            .unwrap_or_else(|| panic!("{:?}", tug.events))
            .t
    };
    let stopped = at(|m| matches!(m, MissionEvent::Stop { .. }));
    let departed = at(|m| matches!(m, MissionEvent::Depart { .. }));
    let dwell = departed.saturating_since(stopped);
    assert!(
        dwell >= Duration::from_secs(3) && dwell < Duration::from_millis(3_100),
        "{dwell:?}"
    );
}

/// Verifies: REQ-FI-1.
#[test]
fn frames_of_a_chosen_identifier_are_delayed_or_corrupted() {
    use bywire_net::sim::Tamper;
    // Drive 0x21's heartbeats on bus 2 (every 100 ms), 300 ms late for a second: the gap
    // trips the ECU's 250 ms heartbeat consumer 250 ms after the last one on time, and the
    // heartbeat comes back.
    let mut tug = cruising();
    let from = tug.now().as_nanos();
    tug.inject(
        Fault::TamperFrames {
            bus: TugBus::Bus2,
            id: 0x721,
            tamper: Tamper::Delay(Duration::from_millis(300)),
        },
        Some(Duration::from_secs(1)),
    );
    run_for(&mut tug, 2_000);
    let events = after(&tug, from);
    let lost = events
        .iter()
        .find(|(_, what)| *what == Happening::Ecu(EcuEvent::HeartbeatLost(0x21)))
        .unwrap_or_else(|| panic!("{events:?}"));
    assert!(
        (150..=251).contains(&lost.0),
        "lost {} ms after the delay began",
        lost.0
    );
    assert!(events.iter().any(
        |(t, what)| *t > lost.0 && *what == Happening::Ecu(EcuEvent::HeartbeatRecovered(0x21))
    ));
    // The ADS's commands (0x100 on bus 1), a bit flipped for 100 ms: every one fails its
    // checksum (the CAN CRC, computed over the flipped data, passes).
    let mut tug = cruising();
    let before = tug.ecu().unwrap().stats().checksum;
    tug.inject(
        Fault::TamperFrames {
            bus: TugBus::Bus1,
            id: 0x100,
            tamper: Tamper::FlipBit,
        },
        Some(Duration::from_millis(100)),
    );
    run_for(&mut tug, 300);
    let corrupted = tug.ecu().unwrap().stats().checksum - before;
    assert!(
        (4..=6).contains(&corrupted),
        "{corrupted} checksum failures"
    );
}

/// Bus-off of the node sending a chosen identifier: drive 0x23 (its heartbeat 0x723 on bus 2)
/// goes bus-off at its next heartbeat and, alone, recovers after 128 × 11 recessive bits.
#[test]
fn the_sender_of_a_chosen_identifier_goes_bus_off_and_recovers() {
    let mut tug = cruising();
    let from = tug.now().as_nanos();
    tug.inject(
        Fault::BusOff {
            bus: TugBus::Bus2,
            id: 0x723,
        },
        None,
    );
    run_for(&mut tug, 500);
    let events = after(&tug, from);
    let states: Vec<(u64, TugBus, &str, NodeState)> = events
        .iter()
        .filter_map(|(t, what)| match what {
            Happening::BusState { bus, who, state } => Some((*t, *bus, who.as_str(), *state)),
            _ => None,
        })
        .collect();
    let off = states
        .iter()
        .find(|(.., state)| *state == NodeState::BusOff)
        .unwrap_or_else(|| panic!("{events:?}"));
    // Within a heartbeat period (100 ms).
    assert!(off.0 <= 101, "bus-off {} ms after the fault", off.0);
    assert_eq!((off.1, off.2), (TugBus::Bus2, "drive 0x23"));
    let back = states
        .iter()
        .find(|(t, bus, who, state)| {
            *t >= off.0 && (*bus, *who, *state) == (off.1, off.2, NodeState::ErrorActive)
        })
        .unwrap_or_else(|| panic!("{events:?}"));
    // 1408 bit times at 1 Mbit/s, within the step that follows.
    assert!(back.0 - off.0 <= 2, "recovered {} ms after", back.0 - off.0);
    assert_eq!(
        states
            .iter()
            .filter(|(.., state)| *state == NodeState::BusOff)
            .count(),
        1,
        "only that node: {states:?}"
    );
}

/// Bus loads over the run, in windows: each within 0–100 %, the drives' bus the busiest, and
/// together what the buses carried on the whole.
#[test]
fn bus_loads_over_windows_add_up_to_the_whole() {
    let mut tug = cruising();
    run_for(&mut tug, 6_000);
    let loads = bywire_sim::record::windowed_loads(&tug.trace, 10);
    let overall = tug.bus_loads();
    for (bus, series) in loads.iter().enumerate() {
        assert!(series.len() >= 10, "bus {bus}: {} windows", series.len());
        assert!(
            series.iter().all(|(_, l)| (0.0..=1.0).contains(l)),
            "{series:?}"
        );
        // Windows are equal: their mean is the load from the first window's start on.
        let mean = series.iter().map(|(_, l)| l).sum::<f64>() / series.len() as f64;
        assert!(
            (mean - overall[bus]).abs() < 0.02,
            "bus {bus}: {mean} over windows, {} overall",
            overall[bus]
        );
    }
    let mean = |bus: usize| loads[bus].iter().map(|(_, l)| l).sum::<f64>();
    assert!(mean(1) > mean(0) && mean(1) > mean(2) && mean(3) > 0.0);
}
