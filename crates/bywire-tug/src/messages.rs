//! The reference tug's messages: generated structs (one per DBC message, with typed getters
//! and range-checked setters) and the E2E protection they share.
//!
//! Every message ends with a 4-bit rolling counter and an 8-bit CRC in its last byte: CRC-8
//! SAE J1850 over the message's data ID (its identifier, low byte first) and payload bytes
//! 0–6, as the DBC declares with the `ChecksumAlgorithm` and `ChecksumDataId` attributes.

#[allow(missing_docs, clippy::indexing_slicing, clippy::unwrap_used)]
mod generated {
    include!(concat!(env!("OUT_DIR"), "/reference_tug.rs"));
}

pub use generated::messages::*;

pub use bywire_vehicle::command::{ControlCommand, ControlMode, Gear, SteeringMode};

use bywire_core::frame::Dlc;
use bywire_core::{Frame, Id, StandardId};
use bywire_vehicle::command::TurnIndicators;

/// The DBC the structs were generated from, for tools that decode by name.
pub const DBC: &str = include_str!("../dbc/reference-tug.dbc");

/// The CRC every reference-tug message carries in byte 7.
pub fn checksum(id: u32, payload: &[u8; 8]) -> u8 {
    let [lo, hi, ..] = id.to_le_bytes();
    let [b0, b1, b2, b3, b4, b5, b6, _] = *payload;
    bywire_core::crc::crc8_sae_j1850(&[lo, hi, b0, b1, b2, b3, b4, b5, b6])
}

/// Set byte 7 of `payload` to its CRC.
pub fn seal(id: u32, payload: &mut [u8; 8]) {
    let crc = checksum(id, payload);
    let [.., last] = payload;
    *last = crc;
}

/// Whether byte 7 of `payload` is its CRC.
pub fn is_sealed(id: u32, payload: &[u8; 8]) -> bool {
    checksum(id, payload) == payload[7]
}

/// A classic frame of message `id` with `payload`, its CRC set in byte 7.
pub fn sealed_frame(id: u32, mut payload: [u8; 8]) -> Frame {
    seal(id, &mut payload);
    // Every reference-tug identifier is a standard one.
    let id =
        Id::Standard(StandardId::new(u16::try_from(id).unwrap_or(0)).unwrap_or(StandardId::ZERO));
    Frame::classic(id, &payload).unwrap_or(Frame::remote(id, Dlc::from_nibble(0)))
}

/// The payload of a classic 8-byte data frame (every reference-tug message is one).
pub fn payload(frame: &Frame) -> Option<[u8; 8]> {
    match frame {
        Frame::Classic(f) if !f.is_remote() => f.data().try_into().ok(),
        _ => None,
    }
}

/// The message with `command` and `counter` (CRC not yet set); `None` for a setpoint beyond
/// its signal's range (or not a number), which the message would carry as another value.
pub fn command_message(command: &ControlCommand, counter: u8) -> Option<AdsToVehicleControl> {
    let mut m = AdsToVehicleControl::default();
    m.set_steering_angle_cmd(command.steering).ok()?;
    m.set_velocity_cmd(command.velocity).ok()?;
    m.set_brake_cmd(command.brake).ok()?;
    m.set_gear_cmd_raw(command.gear.raw());
    m.set_control_mode_cmd_raw(command.mode.raw());
    m.set_steering_mode_cmd_raw(command.steering_mode.raw());
    m.set_engage_request_raw(u64::from(command.engage));
    m.set_operator_reset_raw(u64::from(command.operator_reset));
    m.set_heartbeat_counter_raw(u64::from(counter));
    Some(m)
}

/// The command a message carries; `None` for an undefined steering mode.
pub fn command_of(m: &AdsToVehicleControl) -> Option<ControlCommand> {
    Some(ControlCommand {
        steering: m.steering_angle_cmd(),
        velocity: m.velocity_cmd(),
        brake: m.brake_cmd(),
        // Two-bit signals: every value is a gear and a mode.
        gear: Gear::from_raw(m.gear_cmd_raw()).unwrap_or_default(),
        mode: ControlMode::from_raw(m.control_mode_cmd_raw()).unwrap_or_default(),
        steering_mode: SteeringMode::from_raw(m.steering_mode_cmd_raw())?,
        engage: m.engage_request_raw() == 1,
        operator_reset: m.operator_reset_raw() == 1,
        // The tug's command message has no lights.
        turn_indicators: TurnIndicators::Off,
        hazard_lights: false,
    })
}
