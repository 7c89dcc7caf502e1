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
