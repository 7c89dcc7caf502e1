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

use bywire_core::frame::Dlc;
use bywire_core::{Frame, Id, StandardId};

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

/// The setpoints and requests `AdsToVehicle_Control` carries (without its counter and CRC):
/// what the ADS side sends and what the supervisor takes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControlCommand {
    /// Steering angle, degrees.
    pub steering: f64,
    /// Speed, m/s.
    pub velocity: f64,
    /// Brake, %.
    pub brake: f64,
    /// Gear.
    pub gear: Gear,
    /// Control mode requested.
    pub mode: ControlMode,
    /// Steering mode.
    pub steering_mode: SteeringMode,
    /// Re-engage request.
    pub engage: bool,
    /// Operator reset (E-stop sequence).
    pub operator_reset: bool,
}

impl Default for ControlCommand {
    /// Parked, manual, straight, no requests.
    fn default() -> Self {
        ControlCommand {
            steering: 0.0,
            velocity: 0.0,
            brake: 0.0,
            gear: Gear::Park,
            mode: ControlMode::Manual,
            steering_mode: SteeringMode::Normal,
            engage: false,
            operator_reset: false,
        }
    }
}

impl ControlCommand {
    /// The message with this command and `counter` (CRC not yet set). Values beyond the DBC's
    /// ranges are clamped to them: the vehicle side refuses what its own, narrower limits do.
    pub fn to_message(&self, counter: u8) -> AdsToVehicleControl {
        let mut m = AdsToVehicleControl::default();
        let _ = m.set_steering_angle_cmd(self.steering.clamp(-45.0, 45.0));
        let _ = m.set_velocity_cmd(self.velocity.clamp(-5.0, 8.0));
        let _ = m.set_brake_cmd(self.brake.clamp(0.0, 100.0));
        m.set_gear_cmd_raw(self.gear as u64);
        m.set_control_mode_cmd_raw(self.mode as u64);
        m.set_steering_mode_cmd_raw(self.steering_mode as u64);
        m.set_engage_request_raw(u64::from(self.engage));
        m.set_operator_reset_raw(u64::from(self.operator_reset));
        m.set_heartbeat_counter_raw(u64::from(counter));
        m
    }

    /// The command a message carries; `None` for an undefined steering mode.
    pub fn from_message(m: &AdsToVehicleControl) -> Option<Self> {
        Some(ControlCommand {
            steering: m.steering_angle_cmd(),
            velocity: m.velocity_cmd(),
            brake: m.brake_cmd(),
            gear: Gear::from_raw(m.gear_cmd_raw()),
            mode: ControlMode::from_raw(m.control_mode_cmd_raw()),
            steering_mode: SteeringMode::from_raw(m.steering_mode_cmd_raw())?,
            engage: m.engage_request_raw() == 1,
            operator_reset: m.operator_reset_raw() == 1,
        })
    }
}

/// Control modes (`ControlModeCmd`, `ControlMode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ControlMode {
    /// A driver drives.
    Manual = 0,
    /// The ADS drives.
    Autonomous = 1,
    /// Stopped by the E-stop chain.
    Estop = 2,
    /// Service: actuators calibrated, no driving.
    Calibration = 3,
}

impl ControlMode {
    /// From the 2-bit signal.
    pub fn from_raw(raw: u64) -> Self {
        match raw & 3 {
            1 => ControlMode::Autonomous,
            2 => ControlMode::Estop,
            3 => ControlMode::Calibration,
            _ => ControlMode::Manual,
        }
    }
}

/// Steering modes (`SteeringModeCmd`, `SteeringMode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SteeringMode {
    /// Front and rear in counter-phase.
    Normal = 0,
    /// All wheels parallel.
    Crab = 1,
    /// Rotation on the spot.
    Tank = 2,
}

impl SteeringMode {
    /// From the 2-bit signal; 3 is not a mode.
    pub fn from_raw(raw: u64) -> Option<Self> {
        match raw {
            0 => Some(SteeringMode::Normal),
            1 => Some(SteeringMode::Crab),
            2 => Some(SteeringMode::Tank),
            _ => None,
        }
    }
}

/// Gears (`GearCmd`, `Gear`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Gear {
    /// Park.
    Park = 0,
    /// Reverse.
    Reverse = 1,
    /// Neutral.
    Neutral = 2,
    /// Drive.
    Drive = 3,
}

impl Gear {
    /// From the 2-bit signal.
    pub fn from_raw(raw: u64) -> Self {
        match raw & 3 {
            1 => Gear::Reverse,
            2 => Gear::Neutral,
            3 => Gear::Drive,
            _ => Gear::Park,
        }
    }
}
