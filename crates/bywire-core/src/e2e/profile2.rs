//! AUTOSAR E2E Profile 2: CRC-8H2F over the data and a data ID chosen by the counter from a list
//! of 16, a 4-bit counter 0–15 in the low nibble of byte 1, the CRC in byte 0.

use super::error::E2eError;
use super::sequence::{self, Profile};
use super::SequenceConfig;
use crate::crc::crc8_h2f;

/// Profile 2 settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Config {
    /// One data ID per counter value.
    pub data_id_list: [u8; 16],
    /// Bytes of the protected data (CRC byte included), at least 2.
    pub length: usize,
    /// Receiver sequence settings.
    pub sequence: SequenceConfig,
}

const MODULUS: u8 = 16;

/// The profile's CRC of `data` (whose counter is already written).
pub fn crc(config: &Config, data: &[u8]) -> Result<u8, E2eError> {
    if config.length < 2 || data.len() < config.length {
        return Err(E2eError::Length {
            needed: config.length.max(2),
            actual: data.len(),
        });
    }
    let counter = data.get(1).map_or(0, |b| b & 0x0F);
    let data_id = config
        .data_id_list
        .get(usize::from(counter))
        .copied()
        .unwrap_or(0);
    // CRC-8H2F over bytes 1.. then the data ID, continued as one pass.
    let body = data.get(1..config.length).unwrap_or(&[]);
    Ok(crate::crc::crc8_h2f_continue(crc8_h2f(body), &[data_id]))
}

/// The sender's state: the counter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Protector {
    counter: u8,
}

impl Protector {
    /// A sender whose first frame carries counter 1 (the profile increments before sending).
    pub fn new() -> Self {
        Protector::default()
    }

    /// Advance the counter, write it and the CRC into `data`.
    pub fn protect(&mut self, config: &Config, data: &mut [u8]) -> Result<(), E2eError> {
        crc(config, data)?;
        self.counter = (self.counter + 1) % MODULUS;
        if let Some(b) = data.get_mut(1) {
            *b = (*b & 0xF0) | self.counter;
        }
        let crc = crc(config, data)?;
        if let Some(b) = data.get_mut(0) {
            *b = crc;
        }
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
        let counter = data.get(1).map_or(0, |b| b & 0x0F);
        Ok(if data.first() == Some(&expected) {
            Ok(counter)
        } else {
            Err(())
        })
    }
}

/// The receiver's state.
pub type Checker = sequence::Checker<Rules>;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::e2e::CheckStatus;

    #[test]
    fn a_length_too_short_for_counter_and_crc_or_for_the_data_is_refused() {
        let cfg = |length| Config {
            data_id_list: [0; 16],
            length,
            sequence: SequenceConfig::default(),
        };
        assert_eq!(
            crc(&cfg(1), &[0; 8]),
            Err(E2eError::Length {
                needed: 2,
                actual: 8
            })
        );
        assert_eq!(
            crc(&cfg(8), &[0; 7]),
            Err(E2eError::Length {
                needed: 8,
                actual: 7
            })
        );
        assert_eq!(
            Protector::new().protect(&cfg(8), &mut [0; 4]),
            Err(E2eError::Length {
                needed: 8,
                actual: 4
            })
        );
    }

    #[test]
    fn protect_then_check() {
        let cfg = Config {
            data_id_list: core::array::from_fn(|i| u8::try_from(i * 17).unwrap()),
            length: 8,
            sequence: SequenceConfig {
                max_delta_counter_init: 1,
                max_no_new_or_repeated_data: 2,
                sync_counter_init: 2,
            },
        };
        let mut tx = Protector::new();
        let mut rx = Checker::new();
        let mut frames = [[0u8, 0, 9, 8, 7, 6, 5, 4]; 7];
        for f in frames.iter_mut() {
            tx.protect(&cfg, f).unwrap();
        }
        assert_eq!(frames[0][1], 1);
        assert_eq!(rx.check(&cfg, Some(&frames[0])), Ok(CheckStatus::Initial));
        assert_eq!(rx.check(&cfg, Some(&frames[1])), Ok(CheckStatus::Ok));
        // The allowed step grows by one with every check call (a call may find nothing new), so
        // right after an OK a jump of 3 exceeds MaxDeltaCounterInit 1 + 1; the receiver then
        // needs SyncCounterInit correct receptions before it reports OK again.
        assert_eq!(
            rx.check(&cfg, Some(&frames[4])),
            Ok(CheckStatus::WrongSequence)
        );
        assert_eq!(rx.check(&cfg, Some(&frames[5])), Ok(CheckStatus::Sync));
        assert_eq!(rx.check(&cfg, Some(&frames[6])), Ok(CheckStatus::Sync));
        let mut next = [0u8, 0, 9, 8, 7, 6, 5, 4];
        tx.protect(&cfg, &mut next).unwrap();
        assert_eq!(rx.check(&cfg, Some(&next)), Ok(CheckStatus::Ok));
        next[7] ^= 0x80;
        assert_eq!(rx.check(&cfg, Some(&next)), Ok(CheckStatus::WrongCrc));
    }
}
