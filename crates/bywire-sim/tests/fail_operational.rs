//! The redundant tug: two vehicle control ECUs in step, A in control and B in hot standby,
//! the fence between them; faults of A taken over by B within the bound, the degradation
//! level reported to the ADS, and a second fault stopping the tug where it is.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use bywire_core::Timestamp;
use bywire_sim::scenario::Scenario;
use bywire_sim::tug::{Tug, TugParams};
use bywire_tug::messages::{VcuAStatus, VcuBStatus, VehicleToAdsDegradation};
use bywire_vehicle::arbitration::Side;

fn redundant() -> Tug {
    let scenario = Scenario::builtin("apron-loop").unwrap();
    Tug::new(TugParams {
        redundant: true,
        ..scenario.params(1, 2_000.0)
    })
    .unwrap()
}

fn run_for(tug: &mut Tug, ms: u64) {
    for _ in 0..ms {
        tug.step();
    }
}

#[test]
fn the_redundant_tug_drives_with_a_in_control_and_b_in_step() {
    let mut tug = redundant();
    run_for(&mut tug, 20_000);
    assert!(tug.engaged_at().is_some());
    assert_eq!(tug.ecu_in_control(), Some(Side::A));
    let pair = tug.ecu_pair().unwrap();
    assert_eq!(pair.half(Side::B).arbiter().took_over(), None);
    let ids = |id: u32| {
        tug.bus1_log
            .iter()
            .filter(|(_, f)| f.id().map(|i| i.as_raw()) == Some(id))
            .count()
    };
    // Each ECU's status every 10 ms, the report every 20 ms.
    assert!(
        ids(VcuAStatus::ID) > 1_900 && ids(VcuBStatus::ID) > 1_900,
        "{} {}",
        ids(VcuAStatus::ID),
        ids(VcuBStatus::ID)
    );
    assert!(ids(VehicleToAdsDegradation::ID) > 900);
    // Both ECUs see the tug the same: engaged, nominal.
    for side in [Side::A, Side::B] {
        let supervisor = pair.half(side).node().supervisor();
        assert_eq!(
            supervisor.mode(),
            bywire_tug::messages::ControlMode::Autonomous,
            "{side:?}"
        );
        assert_eq!(
            supervisor.degradation().level(),
            bywire_vehicle::command::DegradationLevel::Nominal
        );
    }
}

use bywire_sim::event::Happening;
use bywire_sim::fault::Fault;
use bywire_vehicle::command::DegradationLevel;

/// When `what` first happened after `from`.
fn first_after(tug: &Tug, from: Timestamp, what: impl Fn(&Happening) -> bool) -> Option<Timestamp> {
    tug.events
        .iter()
        .find(|e| e.t >= from && what(&e.what))
        .map(|e| e.t)
}

/// A's `fault` 20 s into the redundant apron loop, 2 s on: when B took control.
fn takeover(fault: Fault) -> (Tug, Timestamp, Timestamp) {
    let mut tug = redundant();
    run_for(&mut tug, 20_000);
    let at = tug.now();
    tug.inject(fault, None);
    run_for(&mut tug, 2_000);
    let took =
        first_after(&tug, at, |h| *h == Happening::Control(Some(Side::B))).unwrap_or_else(|| {
            panic!(
                "B never took control after {fault:?}: {:?}",
                &tug.events[tug.events.len().saturating_sub(10)..]
            )
        });
    (tug, at, took)
}

fn ms_between(from: Timestamp, to: Timestamp) -> f64 {
    to.saturating_since(from).as_secs_f64() * 1e3
}

#[test]
fn b_takes_over_each_fault_of_a_within_50_ms_and_the_tug_drives_on_at_the_minimal_risk_limit() {
    for fault in [
        Fault::EcuSilent(Side::A),
        Fault::EcuWrongOutput(Side::A),
        Fault::EcuBabble(Side::A),
    ] {
        let (tug, at, took) = takeover(fault);
        let ms = ms_between(at, took);
        assert!(ms <= 50.0, "{fault:?}: B took control {ms} ms after");
        assert_eq!(tug.ecu_in_control(), Some(Side::B), "{fault:?}");
        let level = first_after(&tug, at, |h| {
            matches!(h, Happening::Degradation(DegradationLevel::MinimalRisk, _))
        });
        assert!(
            level.is_some(),
            "{fault:?}: {:?}",
            tug.events.iter().rev().take(8).collect::<Vec<_>>()
        );
        let ads = tug.ads().unwrap().ads().state();
        assert_eq!(
            ads.degradation.value,
            Some(DegradationLevel::MinimalRisk),
            "{fault:?}"
        );
        // Still driving, at most at the level's 1.5 m/s.
        let speed = tug.pose_speed();
        assert!(speed > 0.3 && speed <= 1.6, "{fault:?}: {speed} m/s");
    }
}

/// Verifies: REQ-FO-2.
#[test]
fn a_second_ecu_fault_stops_the_tug_where_it_is() {
    let (mut tug, _, _) = takeover(Fault::EcuSilent(Side::A));
    let at = tug.now();
    tug.inject(Fault::EcuSilent(Side::B), None);
    run_for(&mut tug, 4_000);
    assert_eq!(tug.ecu_in_control(), None);
    assert!(first_after(&tug, at, |h| *h == Happening::Control(None)).is_some());
    assert!(tug.pose_speed() < 0.05, "{} m/s", tug.pose_speed());
}

/// Verifies: REQ-FO-2.
#[test]
fn after_a_takeover_the_tug_drives_on_to_the_next_safe_stop_point_and_stops_there() {
    use bywire_control::kinematics::Point;
    use bywire_control::path::Path;
    use bywire_sim::mission::MissionEvent;
    let scenario = Scenario::builtin("apron-loop").unwrap();
    let mut tug = Tug::new(TugParams {
        redundant: true,
        safe_stops: vec![25.0, 50.0, 75.0, 100.0],
        ..scenario.params(1, 2_000.0)
    })
    .unwrap();
    run_for(&mut tug, 20_000);
    let at = tug.now();
    tug.inject(Fault::EcuSilent(Side::A), None);
    run_for(&mut tug, 40_000);
    let stop_at = tug
        .events
        .iter()
        .find_map(|e| match e.what {
            Happening::Mission(MissionEvent::MinimalRisk { stop_at }) if e.t >= at => Some(stop_at),
            _ => None,
        })
        .expect("a minimal-risk manoeuvre")
        .expect("a safe stop point ahead");
    assert!(tug.events.iter().any(|e| matches!(
        e.what,
        Happening::Mission(MissionEvent::MinimalRiskStop { .. })
    )));
    assert!(tug.pose_speed() < 0.05);
    let path = Path::new(tug.route()).unwrap();
    let pose = tug.pose();
    let station = path
        .project(Point {
            x: pose.x,
            y: pose.y,
        })
        .station;
    assert!(
        (station - stop_at).abs() < 1.0,
        "stopped at {station:.2} m for the point at {stop_at} m"
    );
}

#[test]
fn a_stuck_angle_sensor_is_voted_out_and_a_second_on_its_corner_stops_the_tug() {
    use bywire_sim::steering::SensorFault;
    let mut tug = redundant();
    run_for(&mut tug, 20_000);
    let at = tug.now();
    tug.inject(
        Fault::AngleSensor {
            corner: 0,
            module: 1,
            fault: SensorFault::Stuck(8.0),
        },
        None,
    );
    run_for(&mut tug, 1_000);
    let raised = first_after(&tug, at, |h| {
        matches!(
            h,
            Happening::Degradation(
                DegradationLevel::MinimalRisk,
                Some(bywire_vehicle::command::FaultClass::SensorChannelOut)
            )
        )
    })
    .unwrap_or_else(|| {
        panic!(
            "not voted out: {:?}",
            tug.events
                .iter()
                .filter(|e| e.t.as_nanos() > 0)
                .take(12)
                .collect::<Vec<_>>()
        )
    });
    let ms = ms_between(at, raised);
    assert!(ms <= 60.0, "voted out after {ms} ms");
    assert_eq!(
        tug.ecu_in_control(),
        Some(Side::A),
        "no takeover for a sensor"
    );
    assert!(
        tug.pose_speed() > 0.3,
        "still driving: {}",
        tug.pose_speed()
    );
    // The corner's second track sticks too: two left that disagree, no majority.
    let at = tug.now();
    tug.inject(
        Fault::AngleSensor {
            corner: 0,
            module: 0,
            fault: SensorFault::Stuck(-8.0),
        },
        None,
    );
    run_for(&mut tug, 4_000);
    assert!(first_after(&tug, at, |h| matches!(
        h,
        Happening::Degradation(DegradationLevel::SafeStop, _)
    ))
    .is_some());
    assert!(tug.pose_speed() < 0.05, "{} m/s", tug.pose_speed());
}
