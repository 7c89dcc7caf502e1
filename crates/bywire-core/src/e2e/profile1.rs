//! AUTOSAR E2E Profile 1: CRC-8 SAE J1850 over the data ID and the data, a 4-bit counter 0–14.
//!
//! Standard layout (`E2E_P01_DATAID_*` variants): the CRC in byte 0 (bit offset 0), the counter
//! in the low nibble of byte 1 (bit offset 8); in `Nibble` mode the high nibble of byte 1 carries
//! the data ID's high nibble.

use super::error::E2eError;
use super::sequence::{self, Profile};
use super::SequenceConfig;
use crate::crc::crc8_sae_j1850_continue;

/// How the 16-bit data ID enters the CRC.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DataIdMode {
    /// Both bytes, low then high.
    Both,
    /// Low byte for even counters, high byte for odd ones.
    Alt,
    /// Low byte only (the high byte must be 0).
    Low,
    /// Low byte, then the high nibble sent in the data and a zero byte in the CRC.
    Nibble,
}

/// Profile 1 settings (the standard layout, offsets in bits).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Config {
    /// The data ID.
    pub data_id: u16,
    /// Data ID inclusion mode.
    pub data_id_mode: DataIdMode,
    /// Bytes of the protected data (CRC byte included), at least 2.
    pub length: usize,
    /// Receiver sequence settings.
    pub sequence: SequenceConfig,
}

const CRC_BYTE: usize = 0;
const COUNTER_BYTE: usize = 1;
/// Counter values run 0..=14; 15 is never sent.
const MODULUS: u8 = 15;

fn region(config: &Config, data: &[u8]) -> Result<usize, E2eError> {
    if config.length < 2 || data.len() < config.length {
        return Err(E2eError::Length {
            needed: config.length.max(2),
            actual: data.len(),
        });
    }
    Ok(config.length)
}

/// The profile's CRC of `data` (whose counter is already written).
pub fn crc(config: &Config, data: &[u8]) -> Result<u8, E2eError> {
    let len = region(config, data)?;
    let [low, high] = config.data_id.to_le_bytes();
    let counter = data.get(COUNTER_BYTE).map_or(0, |b| b & 0x0F);
    // The profile calls the CRC routine with start value 0xFF, which the routine XORs with its
    // 0xFF: the register starts at 0x00, not at SAE J1850's usual 0xFF.
    let first = |byte: u8| crc8_sae_j1850_continue(0xFF, &[byte]);
    let start = match config.data_id_mode {
        DataIdMode::Both => crc8_sae_j1850_continue(first(low), &[high]),
        DataIdMode::Alt if counter.is_multiple_of(2) => first(low),
        DataIdMode::Alt => first(high),
        DataIdMode::Low => first(low),
        DataIdMode::Nibble => crc8_sae_j1850_continue(first(low), &[0]),
    };
    // CRC over the bytes after the CRC byte, then inverted once more (the profile's final XOR).
    let body = data.get(COUNTER_BYTE..len).unwrap_or(&[]);
    Ok(crc8_sae_j1850_continue(start, body) ^ 0xFF)
}

/// The sender's state: the counter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Protector {
    counter: u8,
}

impl Protector {
    /// A sender starting at counter 0.
    pub fn new() -> Self {
        Protector::default()
    }

    /// Write counter (and data ID nibble) and CRC into `data`, then advance the counter.
    pub fn protect(&mut self, config: &Config, data: &mut [u8]) -> Result<(), E2eError> {
        region(config, data)?;
        if let Some(b) = data.get_mut(COUNTER_BYTE) {
            let high = if config.data_id_mode == DataIdMode::Nibble {
                // the data ID's bits 8..12 in the high nibble
                u8::try_from((config.data_id >> 8) & 0x0F).unwrap_or(0) << 4
            } else {
                *b & 0xF0
            };
            *b = high | self.counter;
        }
        let crc = crc(config, data)?;
        if let Some(b) = data.get_mut(CRC_BYTE) {
            *b = crc;
        }
        self.counter = (self.counter + 1) % MODULUS;
        Ok(())
    }
}

/// This profile, for the shared receiver.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Rules {}

impl Profile for Rules {
    type Config = Config;
    const MODULUS: u8 = MODULUS;

    fn sequence(config: &Config) -> &SequenceConfig {
        &config.sequence
    }

    fn read(config: &Config, data: &[u8]) -> Result<Result<u8, ()>, E2eError> {
        let expected = crc(config, data)?;
        let nibble_ok = config.data_id_mode != DataIdMode::Nibble
            || data.get(COUNTER_BYTE).map(|b| b >> 4)
                == u8::try_from((config.data_id >> 8) & 0x0F).ok();
        let counter = data.get(COUNTER_BYTE).map_or(0, |b| b & 0x0F);
        let intact = data.get(CRC_BYTE) == Some(&expected) && nibble_ok && counter < MODULUS;
        Ok(if intact { Ok(counter) } else { Err(()) })
    }
}

/// The receiver's state.
pub type Checker = sequence::Checker<Rules>;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::e2e::CheckStatus;

    fn config(mode: DataIdMode) -> Config {
        Config {
            data_id: 0x1234,
            data_id_mode: mode,
            length: 8,
            sequence: SequenceConfig {
                max_delta_counter_init: 2,
                max_no_new_or_repeated_data: 1,
                sync_counter_init: 0,
            },
        }
    }

    /// DATAIDMODE_ALT: the data ID's low byte in the CRC on even counters, its high byte on odd.
    #[test]
    fn the_alternating_data_id_takes_the_low_byte_on_even_counters_the_high_on_odd() {
        let with = |mode, data_id| Config {
            data_id,
            ..config(mode)
        };
        for counter in 0..16u8 {
            let mut data = [0x5A; 8];
            data[COUNTER_BYTE] = counter;
            let alternating = crc(&with(DataIdMode::Alt, 0x1234), &data).unwrap();
            let byte_used = if counter % 2 == 0 { 0x34 } else { 0x12 };
            assert_eq!(
                alternating,
                crc(&with(DataIdMode::Low, byte_used), &data).unwrap(),
                "counter {counter}"
            );
        }
    }

    /// Two bytes, the CRC and the counter, are the least a protected message can be.
    #[test]
    fn two_bytes_are_protected_and_one_is_refused() {
        let two = Config {
            length: 2,
            ..config(DataIdMode::Both)
        };
        let mut data = [0u8; 2];
        Protector::new().protect(&two, &mut data).unwrap();
        assert_eq!(
            Checker::new().check(&two, Some(&data)),
            Ok(CheckStatus::Initial)
        );
        let one = Config { length: 1, ..two };
        assert_eq!(
            crc(&one, &data),
            Err(E2eError::Length {
                needed: 2,
                actual: 2
            })
        );
    }

    #[test]
    fn outside_nibble_mode_the_counter_bytes_high_nibble_is_the_senders() {
        let mut data = [0u8; 8];
        data[COUNTER_BYTE] = 0xA0;
        let mut protector = Protector::new();
        for counter in 0..3u8 {
            protector
                .protect(&config(DataIdMode::Low), &mut data)
                .unwrap();
            assert_eq!(data[COUNTER_BYTE], 0xA0 | counter);
        }
    }

    #[test]
    fn protect_then_check_through_the_statuses() {
        let cfg = config(DataIdMode::Both);
        let mut tx = Protector::new();
        let mut rx = Checker::new();
        let mut frames = [[0u8, 0, 1, 2, 3, 4, 5, 6]; 20];
        for f in frames.iter_mut() {
            tx.protect(&cfg, f).unwrap();
        }
        assert_eq!(frames[14][1] & 0x0F, 14);
        assert_eq!(frames[15][1] & 0x0F, 0, "counter skips 15");
        assert_eq!(rx.check(&cfg, Some(&frames[0])), Ok(CheckStatus::Initial));
        assert_eq!(rx.check(&cfg, Some(&frames[1])), Ok(CheckStatus::Ok));
        assert_eq!(rx.check(&cfg, Some(&frames[1])), Ok(CheckStatus::Repeated));
        assert_eq!(rx.check(&cfg, Some(&frames[2])), Ok(CheckStatus::Ok));
        assert_eq!(rx.check(&cfg, None), Ok(CheckStatus::NoNewData));
        assert_eq!(
            rx.check(&cfg, Some(&frames[4])),
            Ok(CheckStatus::OkSomeLost)
        );
        assert_eq!(
            rx.check(&cfg, Some(&frames[9])),
            Ok(CheckStatus::WrongSequence)
        );
        let mut bad = frames[5];
        bad[4] ^= 0x01;
        assert_eq!(rx.check(&cfg, Some(&bad)), Ok(CheckStatus::WrongCrc));
        // Another data ID gives another CRC.
        let other = Config {
            data_id: 0x1235,
            ..cfg
        };
        assert_eq!(
            rx.check(&other, Some(&frames[5])),
            Ok(CheckStatus::WrongCrc)
        );
        assert_eq!(
            rx.check(&cfg, Some(&[0u8; 3])),
            Err(E2eError::Length {
                needed: 8,
                actual: 3
            })
        );
    }

    #[test]
    fn nibble_mode_sends_the_high_nibble() {
        let cfg = config(DataIdMode::Nibble);
        let mut data = [0u8; 8];
        Protector::new().protect(&cfg, &mut data).unwrap();
        assert_eq!(data[1] >> 4, 0x2);
        assert_eq!(
            Checker::new().check(&cfg, Some(&data)),
            Ok(CheckStatus::Initial)
        );
    }
}
