//! Vehicle profiles: the shipped ones load and configure the nodes; broken ones are refused
//! with the key at fault named.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::time::Duration;

use bywire_vehicle::profile::{Profile, ProfileError};
use bywire_vehicle::supervisor::Cascade;

const TUG: &str = bywire_tug::PROFILE;

fn with_tug_dbc(text: &str) -> Result<bywire_vehicle::profile::LoadedProfile, ProfileError> {
    Profile::parse("test.toml", text, |_| {
        Ok(bywire_tug::messages::DBC.to_string())
    })
}

fn error(text: &str) -> String {
    with_tug_dbc(text).unwrap_err().to_string()
}

#[test]
fn shipped_profiles_load_and_configure_the_nodes() {
    let tug = bywire_tug::profile().unwrap();
    let s = tug.supervisor_config();
    assert_eq!(s.cycle, Duration::from_millis(20));
    assert_eq!(
        s.cascade,
        Cascade {
            hold: 2,
            decelerate: 4,
            recovery_run: 10
        }
    );
    assert_eq!((s.steering_range, s.speed_limit), (40.0, 5.0));
    let a = tug.ads_config();
    assert_eq!(a.staleness, Duration::from_millis(200));
    assert_eq!(a.brake_repeat, Duration::from_millis(50));
    let autoware = Profile::builtin("autoware-can").unwrap();
    assert_eq!(autoware.profile.autoware.unwrap().output, "can-only");
    assert!(matches!(
        Profile::builtin("hovercraft"),
        Err(ProfileError::UnknownBuiltin(_))
    ));
}

#[test]
fn a_profile_file_reads_its_dbc_beside_it() {
    let dir = std::env::temp_dir().join(format!("bywire-profile-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("tug.toml"), TUG).unwrap();
    let e = Profile::load(&dir.join("tug.toml"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("reference-tug.dbc"), "{e}");
    std::fs::write(dir.join("reference-tug.dbc"), bywire_tug::messages::DBC).unwrap();
    assert!(Profile::load(&dir.join("tug.toml")).is_ok());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn broken_profiles_name_the_key() {
    for (from, to, says) in [
        (
            "steering = \"SteeringAngleCmd\"",
            "steering = \"SteerCmd\"",
            "command.steering: no signal 'SteerCmd' in message 'AdsToVehicle_Control'",
        ),
        (
            "message = \"VehicleToAds_State\"",
            "message = \"VehicleState\"",
            "state.message: no message 'VehicleState' in the DBC",
        ),
        (
            "checksum_algorithm = \"crc8_sae_j1850\"",
            "checksum_algorithm = \"md5\"",
            "command.checksum_algorithm: 'md5' is not one of",
        ),
        (
            "Drive = 3",
            "Drive = 4",
            "enums.gear.Drive: 4 does not fit the 2-bit signal",
        ),
        (
            "speed_m_s = 5.0",
            "speed_m_s = -5.0",
            "limits.speed_m_s: -5 is not a positive number",
        ),
        (
            "decelerate_cycles = 4",
            "decelerate_cycles = 1",
            "watchdog.decelerate_cycles: the cascade needs",
        ),
        (
            "checksum_algorithm = \"crc8_sae_j1850\"",
            "checksum_algorithm = \"crc8_sae_j1850\"\nturn_indicators = \"Blinker\"",
            "command.turn_indicators: no signal 'Blinker' in message 'AdsToVehicle_Control'",
        ),
        (
            "heartbeat_echo = \"HeartbeatEcho\"",
            "heartbeat_echo = \"HeartbeatEcho\"\nhazard_lights = \"Beacon\"",
            "state.hazard_lights: no signal 'Beacon' in message 'VehicleToAds_State'",
        ),
        (
            "[enums.steering_mode]",
            "[enums.turn_indicators]\nLeft = 1\n\n[enums.steering_mode]",
            "enums.turn_indicators: not a command role",
        ),
        (
            "bitrate = 500000",
            "bitrate = 0",
            "bitrate: 0 is not a CAN bitrate",
        ),
        (
            "signals = [\"WheelSpeedFL\", \"WheelSpeedFR\", \"WheelSpeedRL\", \"WheelSpeedRR\"]",
            "signals = [\"WheelSpeedFL\"]",
            "wheel_speeds.signals: four signals",
        ),
    ] {
        assert_eq!(TUG.matches(from).count(), 1, "{from}");
        let e = error(&TUG.replace(from, to));
        assert!(e.contains(says), "{from} -> {to}: {e}");
        assert!(e.starts_with("test.toml: "), "{e}");
    }
}

#[test]
fn toml_mistakes_are_refused_with_their_position() {
    let e = error(&format!("{TUG}\n[limits]\nsteering_deg = 1.0\n"));
    assert!(e.contains("line"), "{e}");
    let e = error(&TUG.replace("[takeover]", "[takeover]\ntorque = 2"));
    assert!(e.contains("unknown field `torque`"), "{e}");
    let e = error(&TUG.replace(
        "period_ms = 20\nstaleness_ms",
        "period_ms = \"fast\"\nstaleness_ms",
    ));
    assert!(e.contains("period_ms") || e.contains("invalid type"), "{e}");
    let e = error("name = \"x\"\n");
    assert!(e.contains("missing field"), "{e}");
}

/// Verifies: REQ-SS-2.
#[test]
fn a_stop_harder_than_the_vehicle_can_is_braking_as_hard_as_it_can() {
    let limits = bywire_tug::profile().unwrap().profile.limits;
    let most = limits.deceleration_m_s2;
    for asked in [most + 1.0, 9.81, 1e30, f64::INFINITY] {
        let taken = limits.emergency_deceleration(asked).unwrap();
        assert_eq!(taken.value, most, "{asked}");
        let warning = taken.warning.unwrap();
        assert!(warning.contains("braking as hard as it can"), "{warning}");
    }
    assert_eq!(limits.emergency_deceleration(1e100).unwrap().warning.unwrap(),
        format!("emergency_brake 1e100: beyond this vehicle's {most} m/s², braking as hard as it can ({most} m/s²)"));
    let within = limits.emergency_deceleration(most / 2.0).unwrap();
    assert_eq!((within.value, within.warning), (most / 2.0, None));
    for refused in [0.0, -1.0, f64::NAN, f64::NEG_INFINITY] {
        let why = limits.emergency_deceleration(refused).unwrap_err();
        assert!(
            why.contains("a deceleration above 0 m/s² is needed"),
            "{why}"
        );
    }
    let brake = limits.brake_request(250.0).unwrap();
    assert_eq!(brake.value, 100.0);
    assert!(brake
        .warning
        .unwrap()
        .starts_with("brake 250: beyond this vehicle's 100 %"));
    assert_eq!(limits.brake_request(35.0).unwrap().value, 35.0);
    assert!(limits.brake_request(-1.0).is_err());
    assert!(limits.brake_request(f64::NAN).is_err());
}
