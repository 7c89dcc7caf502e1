//! Frames the vehicle tests send: sealed with the reference tug's CRC.
#![allow(dead_code, clippy::unwrap_used)]

use bywire_core::{Frame, Id, Timestamp};
use bywire_tug::messages::{self, AdsToVehicleControl, ControlMode};

/// The rigs' plant, the same in every suite: the vehicle's speed is its speed setpoint, 0
/// while it brakes (its steering, where a rig feeds it back, is at its setpoint).
pub fn plant_speed(a: &bywire_vehicle::supervisor::Actuators) -> f64 {
    if a.brake > 0.0 {
        0.0
    } else {
        a.velocity
    }
}

/// Keep a state-space check's figures for the evidence report
/// (`target/evidence/state-space/MACHINE.json`, gathered by `scripts/evidence.sh`).
pub fn record_state_space(
    machine: &str,
    requirements: &[&str],
    (states, transitions, depth, fixed_point): (usize, u64, usize, bool),
    took: std::time::Duration,
) {
    let dir =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target/evidence/state-space");
    std::fs::create_dir_all(&dir).unwrap();
    let json = format!(
        "{{\"machine\":\"{machine}\",\"requirements\":{requirements:?},\"states\":{states},\"transitions\":{transitions},\"depth\":{depth},\"fixed_point\":{fixed_point},\"seconds\":{}}}\n",
        took.as_secs_f64()
    );
    std::fs::write(dir.join(format!("{machine}.json")), json).unwrap();
    eprintln!("{machine}: {states} states, {transitions} transitions, depth {depth} in {took:?}");
}

pub fn ms(t: u64) -> Timestamp {
    Timestamp::from_millis(t)
}

/// A classic frame with `payload` and its CRC in byte 7.
pub fn sealed(id: u32, mut payload: [u8; 8]) -> Frame {
    messages::seal(id, &mut payload);
    Frame::classic(Id::standard(id).unwrap(), &payload).unwrap()
}

/// An autonomous drive command with counter `counter`, changed by `edit`.
pub fn command(counter: u8, edit: impl FnOnce(&mut AdsToVehicleControl)) -> Frame {
    let mut m = AdsToVehicleControl::default();
    m.set_velocity_cmd(2.0).unwrap();
    m.set_gear_cmd_raw(3);
    m.set_control_mode_cmd_raw(ControlMode::Autonomous as u64);
    m.set_heartbeat_counter_raw(u64::from(counter & 0x0F));
    edit(&mut m);
    sealed(AdsToVehicleControl::ID, m.0)
}

/// The vehicles the suites run over: a wire and the configurations its profile gives.
pub mod vehicles {
    use std::path::Path;

    use bywire_tug::wire::ReferenceWire;
    use bywire_vehicle::ads::AdsConfig;
    use bywire_vehicle::profile::{LoadedProfile, Profile};
    use bywire_vehicle::supervisor::SupervisorConfig;
    use bywire_vehicle::wire::ProfileWire;

    /// One vehicle under test.
    #[derive(Clone)]
    pub struct Vehicle<W> {
        pub wire: W,
        pub supervisor: SupervisorConfig,
        pub ads: AdsConfig,
    }

    /// The reference tug through its generated structs.
    pub fn reference_wire() -> Vehicle<ReferenceWire> {
        Vehicle {
            wire: ReferenceWire,
            supervisor: SupervisorConfig::default(),
            ads: AdsConfig::default(),
        }
    }

    /// Any vehicle through its profile.
    pub fn by_profile(loaded: &LoadedProfile) -> Vehicle<ProfileWire> {
        Vehicle {
            wire: ProfileWire::new(loaded).unwrap(),
            supervisor: loaded.supervisor_config(),
            ads: loaded.ads_config(),
        }
    }

    /// The shuttle's profile and DBC text (as the crate ships them).
    pub fn shuttle_texts() -> (String, String) {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("profiles");
        (
            std::fs::read_to_string(dir.join("shuttle.toml")).unwrap(),
            std::fs::read_to_string(dir.join("shuttle.dbc")).unwrap(),
        )
    }

    /// The shuttle test vehicle, its DBC changed by `edit`.
    pub fn shuttle_with(edit: impl FnOnce(String) -> String) -> LoadedProfile {
        let (toml, dbc) = shuttle_texts();
        let dbc = edit(dbc);
        Profile::parse("shuttle", &toml, |_| Ok(dbc.clone())).unwrap()
    }

    /// The shuttle's supervisor duplicated as its profile declares (A in control, B in hot
    /// standby, the fence between them), both started at zero; and its profile.
    pub fn duplicated_shuttle() -> (
        bywire_vehicle::arbitration::FencedPair<
            bywire_vehicle::supervisor::Supervisor<ProfileWire>,
            bywire_vehicle::wire::ProfileDuplexWire,
        >,
        LoadedProfile,
    ) {
        duplicated_shuttle_with(|_| {})
    }

    /// The same, each half's supervisor configured as `adjust` leaves the profile's.
    pub fn duplicated_shuttle_with(
        adjust: impl Fn(&mut bywire_vehicle::supervisor::SupervisorConfig),
    ) -> (
        bywire_vehicle::arbitration::FencedPair<
            bywire_vehicle::supervisor::Supervisor<ProfileWire>,
            bywire_vehicle::wire::ProfileDuplexWire,
        >,
        LoadedProfile,
    ) {
        use bywire_vehicle::arbitration::{Duplex, FencedPair, Side};
        let loaded = shuttle_with(|dbc| dbc);
        let wire = ProfileWire::new(&loaded).unwrap();
        let duplex = bywire_vehicle::wire::ProfileDuplexWire::new(&loaded)
            .unwrap()
            .unwrap();
        let mut config = loaded.supervisor_config();
        adjust(&mut config);
        let fail_operational = loaded.profile.fail_operational.as_ref().unwrap();
        let arbiter = fail_operational.control.as_ref().unwrap().config();
        let half = |side| {
            let supervisor =
                bywire_vehicle::supervisor::Supervisor::with_wire(config, wire.clone());
            Duplex::new(
                side,
                arbiter,
                supervisor,
                duplex.clone(),
                bywire_core::Timestamp::ZERO,
            )
        };
        (FencedPair::new(half(Side::A), half(Side::B)), loaded)
    }
}
