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
    let ids = |id: u32| tug.bus1_log.iter().filter(|(_, f)| f.id().map(|i| i.as_raw()) == Some(id)).count();
    // Each ECU's status every 10 ms, the report every 20 ms.
    assert!(ids(VcuAStatus::ID) > 1_900 && ids(VcuBStatus::ID) > 1_900, "{} {}", ids(VcuAStatus::ID), ids(VcuBStatus::ID));
    assert!(ids(VehicleToAdsDegradation::ID) > 900);
    // Both ECUs see the tug the same: engaged, nominal.
    for side in [Side::A, Side::B] {
        let supervisor = pair.half(side).node().supervisor();
        assert_eq!(supervisor.mode(), bywire_tug::messages::ControlMode::Autonomous, "{side:?}");
        assert_eq!(supervisor.degradation().level(), bywire_vehicle::command::DegradationLevel::Nominal);
    }
    let _ = Timestamp::ZERO;
}
