//! The ADS side's command checks against the vehicle's: none apart on the reference tug and on
//! the shuttle (a second, non-tug profile), and a limit set apart on either side found.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::path::Path;

use bywire_vehicle::fuzz::fuzz;
use bywire_vehicle::profile::{LoadedProfile, Profile};
use bywire_vehicle::wire::ProfileWire;

fn shuttle() -> LoadedProfile {
    Profile::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("profiles/shuttle.toml")).unwrap()
}

fn wires(loaded: &LoadedProfile) -> (ProfileWire, ProfileWire) {
    (
        ProfileWire::new(loaded).unwrap(),
        ProfileWire::new(loaded).unwrap(),
    )
}

/// Verifies: REQ-RNG-1, REQ-RNG-2.
#[test]
fn the_ads_side_and_the_vehicle_judge_every_command_alike() {
    for loaded in [bywire_tug::profile().unwrap(), shuttle()] {
        let name = loaded.profile.name.clone();
        let report = fuzz(
            &loaded.profile.limits,
            wires(&loaded),
            loaded.supervisor_config(),
            10_000,
            7,
        );
        assert_eq!(report.disagreements, 0, "{name}: {:#?}", report.kept);
        // Enough of each kind judged: sent and taken, refused by both.
        assert!(report.sent > 1_000, "{name}: {report:?}");
        let judged = report.commands - report.unencodable;
        assert!(judged - report.sent > 1_000, "{name}: {report:?}");
    }
    // The reference tug's own generated wire on the ADS side: the same.
    let loaded = bywire_tug::profile().unwrap();
    let report = fuzz(
        &loaded.profile.limits,
        (
            bywire_tug::wire::ReferenceWire,
            ProfileWire::new(&loaded).unwrap(),
        ),
        loaded.supervisor_config(),
        10_000,
        8,
    );
    assert_eq!(report.disagreements, 0, "{:#?}", report.kept);
}

/// Verifies: REQ-RNG-2.
#[test]
fn a_limit_set_apart_is_found_on_either_side() {
    let loaded = bywire_tug::profile().unwrap();
    let limits = loaded.profile.limits;
    // The ADS side allows 45° where the vehicle allows 40°: it sends what the vehicle refuses.
    let mut wide = limits;
    wide.steering_deg = 45.0;
    let report = fuzz(&wide, wires(&loaded), loaded.supervisor_config(), 10_000, 1);
    assert!(report.disagreements > 10, "{report:?}");
    for d in &report.kept {
        assert!(d.ads.is_ok(), "{d:?}");
        assert_eq!(d.vehicle, Err("out of range".to_string()), "{d:?}");
        assert!(d.command.steering.abs() > limits.steering_deg, "{d:?}");
    }
    // The ADS side allows 4 m/s where the vehicle allows 5: it refuses what the vehicle takes.
    let mut narrow = limits;
    narrow.speed_m_s = 4.0;
    let report = fuzz(
        &narrow,
        wires(&loaded),
        loaded.supervisor_config(),
        10_000,
        1,
    );
    assert!(report.disagreements > 10, "{report:?}");
    for d in &report.kept {
        assert!(d.ads.as_ref().unwrap_err().contains("velocity"), "{d:?}");
        assert!(d.vehicle.is_ok(), "{d:?}");
        assert!(d.command.velocity.abs() > 4.0, "{d:?}");
    }
}
