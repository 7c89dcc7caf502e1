//! Counters and checksums declared, not guessed.
//!
//! A message binds a rolling counter signal and a checksum signal with an algorithm from
//! `bywire-core`'s E2E primitives, through signal attributes:
//!
//! ```text
//! BA_DEF_ SG_ "RollingCounter" INT 0 1;        1 marks the counter
//! BA_DEF_ SG_ "ChecksumAlgorithm" STRING;      xor8, sum8, crc8_sae_j1850, crc8_h2f or e2e_profile1
//! BA_DEF_ SG_ "ChecksumDataId" INT 0 65535;    optional data ID fed to the CRC first (low, high)
//! ```
//!
//! or, as a fallback, by opendbc's naming: a signal named `COUNTER` (or ending in `_COUNTER`)
//! is the counter and one named `CHECKSUM` the checksum. A checksum found only by name has no
//! algorithm: [`Protection::fill`] and [`Protection::verify`] then report it as undeclared
//! rather than guess one (opendbc's checksums differ per vendor); a vehicle profile supplies it.
//!
//! The checksum covers every payload byte except those the checksum occupies entirely, with the
//! checksum's own bits cleared, after the data ID bytes when one is declared.

use bywire_core::crc;

use crate::codec::MessageCodec;
use crate::model::{AttrValue, Message, Num};

/// A checksum algorithm.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ChecksumAlgorithm {
    /// XOR of the bytes.
    Xor8,
    /// Sum of the bytes modulo 256.
    Sum8,
    /// CRC-8 SAE J1850 as the standard gives it (initial value and final XOR 0xFF).
    Crc8SaeJ1850,
    /// AUTOSAR E2E Profile 1's CRC: SAE J1850's polynomial chained as `Crc_CalculateCRC8`
    /// from a start value of 0xFF, the result inverted (an initial value and final XOR of 0).
    E2eProfile1,
    /// CRC-8H2F (AUTOSAR E2E Profile 2's CRC).
    Crc8H2f,
}

impl ChecksumAlgorithm {
    /// By name, as written in the `ChecksumAlgorithm` attribute.
    pub fn from_name(name: &str) -> Option<Self> {
        Some(match name.to_ascii_lowercase().as_str() {
            "xor8" | "xor" => ChecksumAlgorithm::Xor8,
            "sum8" | "sum" => ChecksumAlgorithm::Sum8,
            "crc8_sae_j1850" | "crc8" | "sae_j1850" => ChecksumAlgorithm::Crc8SaeJ1850,
            "crc8_h2f" | "crc8h2f" => ChecksumAlgorithm::Crc8H2f,
            "e2e_profile1" | "e2e_p01" | "profile1" => ChecksumAlgorithm::E2eProfile1,
            _ => return None,
        })
    }

    /// The checksum of a byte stream, fed one byte at a time (the CRCs chain exactly).
    fn compute(self, bytes: impl Iterator<Item = u8>) -> u8 {
        let chain = |first: fn(&[u8]) -> u8,
                     next: fn(u8, &[u8]) -> u8,
                     bytes: &mut dyn Iterator<Item = u8>| {
            let start = first(&[]);
            let mut crc: Option<u8> = None;
            for b in bytes {
                crc = Some(match crc {
                    None => first(&[b]),
                    Some(c) => next(c, &[b]),
                });
            }
            crc.unwrap_or(start)
        };
        let mut bytes = bytes;
        match self {
            ChecksumAlgorithm::Xor8 => bytes.fold(0u8, |a, b| a ^ b),
            ChecksumAlgorithm::Sum8 => bytes.fold(0u8, u8::wrapping_add),
            ChecksumAlgorithm::Crc8SaeJ1850 => chain(
                crc::crc8_sae_j1850,
                crc::crc8_sae_j1850_continue,
                &mut bytes,
            ),
            ChecksumAlgorithm::Crc8H2f => chain(crc::crc8_h2f, crc::crc8_h2f_continue, &mut bytes),
            ChecksumAlgorithm::E2eProfile1 => {
                bytes.fold(0xFF, |c, b| crc::crc8_sae_j1850_continue(c, &[b])) ^ 0xFF
            }
        }
    }
}

/// The counter and checksum of one message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Protection {
    /// Index of the counter signal and its width in bits.
    pub counter: Option<(usize, u32)>,
    /// Index of the checksum signal and its algorithm (`None`: found by name, not declared).
    pub checksum: Option<(usize, Option<ChecksumAlgorithm>)>,
    /// Data ID fed to the checksum first.
    pub data_id: Option<u16>,
}

/// Why a frame's protection does not check out, or cannot be applied.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ProtectionError {
    /// The checksum in the frame differs from the computed one.
    #[error("checksum {found:#04X} does not match the computed {expected:#04X}")]
    Checksum {
        /// In the frame.
        found: u64,
        /// Computed.
        expected: u64,
    },
    /// The message has a checksum signal but no declared algorithm.
    #[error("the checksum signal has no declared algorithm (set the ChecksumAlgorithm attribute)")]
    Undeclared,
    /// The payload is shorter than the message.
    #[error("the payload is shorter than the message")]
    Payload,
}

fn attr_str<'a>(attrs: &'a [(String, AttrValue)], name: &str) -> Option<&'a str> {
    attrs.iter().find_map(|(n, v)| match v {
        AttrValue::Str(s) if n == name => Some(s.as_str()),
        _ => None,
    })
}

fn attr_int(attrs: &[(String, AttrValue)], name: &str) -> Option<i128> {
    attrs.iter().find_map(|(n, v)| match v {
        AttrValue::Number(Num::Int(i)) if n == name => Some(*i),
        _ => None,
    })
}

impl Protection {
    /// The protection a message declares, or that opendbc's naming implies; `None` when it has
    /// neither counter nor checksum.
    pub fn of(message: &Message) -> Option<Protection> {
        let declared_counter = message
            .signals
            .iter()
            .position(|s| attr_int(&s.attributes, "RollingCounter") == Some(1));
        let declared_checksum = message.signals.iter().enumerate().find_map(|(i, s)| {
            attr_str(&s.attributes, "ChecksumAlgorithm")
                .map(|a| (i, ChecksumAlgorithm::from_name(a)))
        });
        let named = |pred: &dyn Fn(&str) -> bool| {
            message
                .signals
                .iter()
                .position(|s| pred(&s.name.to_ascii_uppercase()))
        };
        let counter =
            declared_counter.or_else(|| named(&|n| n == "COUNTER" || n.ends_with("_COUNTER")));
        let checksum = declared_checksum.or_else(|| named(&|n| n == "CHECKSUM").map(|i| (i, None)));
        if counter.is_none() && checksum.is_none() {
            return None;
        }
        let data_id = checksum
            .and_then(|(i, _)| message.signals.get(i))
            .and_then(|s| attr_int(&s.attributes, "ChecksumDataId"))
            .and_then(|v| u16::try_from(v).ok());
        Some(Protection {
            counter: counter.and_then(|i| Some((i, message.signals.get(i)?.length))),
            checksum,
            data_id,
        })
    }

    fn checksum_of(
        &self,
        codec: &MessageCodec,
        index: usize,
        algorithm: ChecksumAlgorithm,
        payload: &[u8],
    ) -> Option<u8> {
        let payload = payload.get(..codec.size())?;
        // The checksum's own bits, on the stack (payloads are at most 64 bytes): no
        // allocation per frame.
        let mut mask = [0u8; 64];
        let mask = mask.get_mut(..payload.len())?;
        if !codec.write_raw(index, u64::MAX, mask) {
            return None;
        }
        // Bytes the checksum fills entirely are left out; partly filled ones count with its
        // bits cleared; the data ID goes first.
        let data = payload
            .iter()
            .zip(mask.iter())
            .filter(|(_, m)| **m != 0xFF)
            .map(|(c, m)| c & !m);
        let id = self.data_id.map(u16::to_le_bytes).into_iter().flatten();
        Some(algorithm.compute(id.chain(data)))
    }

    /// Write `counter` (masked to the counter's width) and the checksum into an encoded payload.
    pub fn fill(
        &self,
        codec: &MessageCodec,
        counter: u64,
        payload: &mut [u8],
    ) -> Result<(), ProtectionError> {
        if payload.len() < codec.size() {
            return Err(ProtectionError::Payload);
        }
        if let Some((index, _)) = self.counter {
            codec.write_raw(index, counter, payload);
        }
        if let Some((index, algorithm)) = self.checksum {
            let algorithm = algorithm.ok_or(ProtectionError::Undeclared)?;
            let sum = self
                .checksum_of(codec, index, algorithm, payload)
                .ok_or(ProtectionError::Payload)?;
            codec.write_raw(index, u64::from(sum), payload);
        }
        Ok(())
    }

    /// Check the checksum of a received payload and return its counter value (if it has one).
    pub fn verify(
        &self,
        codec: &MessageCodec,
        payload: &[u8],
    ) -> Result<Option<u64>, ProtectionError> {
        if payload.len() < codec.size() {
            return Err(ProtectionError::Payload);
        }
        if let Some((index, algorithm)) = self.checksum {
            let algorithm = algorithm.ok_or(ProtectionError::Undeclared)?;
            let expected = u64::from(
                self.checksum_of(codec, index, algorithm, payload)
                    .ok_or(ProtectionError::Payload)?,
            );
            let found = codec
                .read_raw(index, payload)
                .ok_or(ProtectionError::Payload)?;
            let width_mask = codec.raw_mask(index).unwrap_or(u64::MAX);
            if found != expected & width_mask {
                return Err(ProtectionError::Checksum {
                    found,
                    expected: expected & width_mask,
                });
            }
        }
        Ok(self
            .counter
            .and_then(|(index, _)| codec.read_raw(index, payload)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::Value;
    use crate::{parse_str, Mode};
    use bywire_core::e2e::{CounterChecker, CounterStatus};
    use bywire_core::Timestamp;

    const DECLARED: &str = "BA_DEF_ SG_ \"RollingCounter\" INT 0 1;\nBA_DEF_ SG_ \"ChecksumAlgorithm\" STRING;\nBA_DEF_ SG_ \"ChecksumDataId\" INT 0 65535;\n\
BO_ 256 AdsToVehicle_Control: 8 ADS\n SG_ Steering : 0|16@1- (0.001,0) [-1|1] \"rad\" ECU\n SG_ Speed : 16|16@1+ (0.01,0) [0|10] \"m/s\" ECU\n SG_ Alive : 48|4@1+ (1,0) [0|15] \"\" ECU\n SG_ Crc : 56|8@1+ (1,0) [0|255] \"\" ECU\n\
BA_ \"RollingCounter\" SG_ 256 Alive 1;\nBA_ \"ChecksumAlgorithm\" SG_ 256 Crc \"crc8_sae_j1850\";\nBA_ \"ChecksumDataId\" SG_ 256 Crc 4660;\n";

    #[test]
    fn declared_counter_and_crc_are_filled_and_verified() {
        let (db, diags) = parse_str(DECLARED, Mode::Strict).unwrap();
        assert!(diags.is_empty());
        let m = &db.messages[0];
        let p = Protection::of(m).unwrap();
        assert_eq!(p.counter, Some((2, 4)));
        assert_eq!(p.checksum, Some((3, Some(ChecksumAlgorithm::Crc8SaeJ1850))));
        assert_eq!(p.data_id, Some(0x1234));
        let codec = MessageCodec::new(m);
        let mut checker = CounterChecker::new(4, 1, core::time::Duration::from_millis(100));
        for n in 0..20u64 {
            let mut payload = [0u8; 8];
            codec
                .encode(
                    &[
                        Some(Value::Float(0.25)),
                        Some(Value::Float(3.5)),
                        None,
                        None,
                    ],
                    &mut payload,
                )
                .unwrap();
            p.fill(&codec, n, &mut payload).unwrap();
            // The CRC covers the data ID then bytes 0..7 (byte 7 is the CRC's own).
            let mut input = vec![0x34, 0x12];
            input.extend_from_slice(&payload[..7]);
            assert_eq!(payload[7], bywire_core::crc::crc8_sae_j1850(&input));
            let counter = p.verify(&codec, &payload).unwrap().unwrap();
            assert_eq!(counter, n % 16);
            let status = checker.check(
                Timestamp::from_millis(n * 20),
                u8::try_from(counter).unwrap(),
            );
            assert!(
                matches!(status, CounterStatus::Initial | CounterStatus::InSequence),
                "{status:?}"
            );
            // Any single flipped bit outside the CRC is caught.
            for bit in 0..56 {
                let mut bad = payload;
                bad[bit / 8] ^= 1 << (bit % 8);
                assert!(
                    matches!(
                        p.verify(&codec, &bad),
                        Err(ProtectionError::Checksum { .. })
                    ),
                    "bit {bit}"
                );
            }
        }
    }

    #[test]
    fn opendbc_names_are_found_but_no_algorithm_is_guessed() {
        let text = "BO_ 228 STEERING_CONTROL: 5 EON\n SG_ STEER_TORQUE : 7|16@0- (1,0) [-4096|4096] \"\" EPS\n SG_ COUNTER : 37|2@0+ (1,0) [0|3] \"\" EPS\n SG_ CHECKSUM : 35|4@0+ (1,0) [0|15] \"\" EPS\n";
        let (db, _) = parse_str(text, Mode::Lenient).unwrap();
        let p = Protection::of(&db.messages[0]).unwrap();
        assert_eq!(p.counter, Some((1, 2)));
        assert_eq!(p.checksum, Some((2, None)));
        let codec = MessageCodec::new(&db.messages[0]);
        let mut payload = [0u8; 5];
        assert_eq!(
            p.fill(&codec, 1, &mut payload),
            Err(ProtectionError::Undeclared)
        );
        assert_eq!(
            codec.read_raw(1, &payload),
            Some(1),
            "the counter is still written"
        );
        assert!(Protection::of(
            &parse_str(
                "BO_ 1 M: 1 N\n SG_ A : 0|8@1+ (1,0) [0|0] \"\" N\n",
                Mode::Lenient
            )
            .unwrap()
            .0
            .messages[0]
        )
        .is_none());
    }

    #[test]
    fn xor_and_sum_over_a_shared_byte() {
        // A 4-bit checksum sharing its byte with a 4-bit counter: the byte counts with the
        // checksum bits cleared.
        let text = "BA_DEF_ SG_ \"ChecksumAlgorithm\" STRING;\nBO_ 1 M: 3 N\n SG_ A : 0|16@1+ (1,0) [0|0] \"\" N\n SG_ COUNTER : 16|4@1+ (1,0) [0|15] \"\" N\n SG_ Sum : 20|4@1+ (1,0) [0|15] \"\" N\nBA_ \"ChecksumAlgorithm\" SG_ 1 Sum \"xor8\";\n";
        let (db, _) = parse_str(text, Mode::Strict).unwrap();
        let p = Protection::of(&db.messages[0]).unwrap();
        let codec = MessageCodec::new(&db.messages[0]);
        let mut payload = [0u8; 3];
        codec
            .encode(&[Some(Value::Int(0x1234)), None, None], &mut payload)
            .unwrap();
        p.fill(&codec, 5, &mut payload).unwrap();
        let expected = (0x34 ^ 0x12 ^ 0x05) & 0x0F;
        assert_eq!(codec.read_raw(2, &payload), Some(expected));
        assert_eq!(p.verify(&codec, &payload), Ok(Some(5)));
    }
}
