//! # bywire-tug: the reference vehicle
//!
//! An electric airside baggage tug with four-wheel steering (normal, crab, tank turn) and
//! electrohydraulic steering, as an opendbc-style "car" over the generic vehicle crate:
//!
//! - [`messages`]: its bus-1 DBC (`dbc/reference-tug.dbc`) as structs generated at build time,
//!   with the E2E protection every message carries (4-bit counter, CRC-8 with data ID);
//! - [`wire`]: [`wire::ReferenceWire`], both ends of the wire through those structs (`no_std`);
//! - [`profile`]: its vehicle profile (`profiles/reference-tug.toml`) for the runtime codec,
//!   and [`redundant_profile`], the same with its fail-operational layers;
//! - [`duplex`]: the two control ECUs' status and the comparison of their setpoints;
//! - [`secured`]: its secured variant — the command path authenticated (SecOC profile 1) in
//!   CAN FD frames, with the figures that chose FD over a companion frame;
//! - [`plausibility`]: the ECU's check of each corner's two steering-sensor tracks;
//! - [`backup_steering`]: the redundant tug's backup steering valves and their judge;
//! - [`ecu`]: the vehicle control ECU as one node on its four buses — the supervisor, the
//!   CANopen master of the eight drives, the plausibility check, the 4WS mapping, its reports;
//! - [`diagnostics`]: the ECU's UDS server — its faults as DTCs with snapshots, its DIDs, the
//!   steering calibration sweep.
//!
//! Nothing below this crate names the tug.
//!
//! ```
//! use bywire_tug::messages::{self, AdsToVehicleControl};
//! use bywire_vehicle::command::{ControlCommand, ControlMode};
//!
//! let command = ControlCommand { velocity: 1.5, mode: ControlMode::Autonomous, ..Default::default() };
//! let message = messages::command_message(&command, 3).unwrap();
//! let frame = messages::sealed_frame(AdsToVehicleControl::ID, message.0);
//! let payload = messages::payload(&frame).unwrap();
//! assert!(messages::is_sealed(AdsToVehicleControl::ID, &payload));
//! assert_eq!(messages::command_of(&AdsToVehicleControl(payload)), Some(command));
//! ```

pub mod backup_steering;
pub mod diagnostics;
pub mod drives;
pub mod duplex;
pub mod ecu;
pub mod messages;
pub mod plausibility;
pub mod secured;
pub mod wire;

use bywire_vehicle::profile::{LoadedProfile, Profile, ProfileError};

/// The DBC of bus 2 (the drives' CANopen bus): SYNC, PDOs, emergencies and heartbeats with
/// their cycle times, minimum intervals and jitter, for decoding and for
/// `bywire latency --predict`.
pub const DRIVES_DBC: &str = include_str!("../dbc/reference-tug-drives.dbc");

/// The tug's profile text.
pub const PROFILE: &str = include_str!("../profiles/reference-tug.toml");

/// The tug's vehicle profile, checked against its DBC (both ship with this crate; its tests
/// load them).
pub fn profile() -> Result<LoadedProfile, ProfileError> {
    Profile::parse("reference-tug", PROFILE, |_| Ok(messages::DBC.to_string()))
}

/// The redundant tug's fail-operational sections, which `reference-tug-redundant` adds to
/// the tug's profile.
pub const REDUNDANCY: &str = include_str!("../profiles/redundancy.toml");

/// The redundant tug's profile: the tug's, with its fail-operational layers declared (two
/// control ECUs, the degradation levels and their report).
pub fn redundant_profile() -> Result<LoadedProfile, ProfileError> {
    let plain = PROFILE.replacen(
        "name = \"reference-tug\"",
        "name = \"reference-tug-redundant\"",
        1,
    );
    let text = format!("{plain}\n{REDUNDANCY}");
    Profile::parse("reference-tug-redundant", &text, |_| {
        Ok(messages::DBC.to_string())
    })
}

/// A profile named as a user names one: the file at that path (relative to `base`) when there
/// is one, else a shipped profile ([`builtin`]).
pub fn named_or_file(name: &str, base: &std::path::Path) -> Result<LoadedProfile, ProfileError> {
    let path = base.join(name);
    if path.exists() {
        Profile::load(&path)
    } else {
        builtin(name)
    }
}

/// A shipped profile by name: `reference-tug`, `reference-tug-redundant`, or one the vehicle
/// crate ships (`autoware-can`, `shuttle`).
pub fn builtin(name: &str) -> Result<LoadedProfile, ProfileError> {
    match name {
        "reference-tug" => profile(),
        "reference-tug-redundant" => redundant_profile(),
        _ => Profile::builtin(name),
    }
}
