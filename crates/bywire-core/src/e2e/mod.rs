//! End-to-end protection: rolling counters and checksums that let a receiver tell fresh, intact
//! data from repeated, lost, stale or corrupted data.
//!
//! - [`RollingCounter`] and [`CounterChecker`]: a counter of any width 1–8 bits and a checker
//!   that tells in-sequence, repeated, skipped-N, out-of-sequence and stale apart, with time
//!   passed in.
//! - Checksums: [`crate::crc::xor8`], [`crate::crc::crc8_sae_j1850`], [`crate::crc::crc8_h2f`].
//! - [`profile1`] and [`profile2`]: AUTOSAR E2E Profiles 1 and 2 (CRC-8 over a data ID and the
//!   data, a 4-bit counter), protect and check with the profiles' status outcomes.

mod counter;
mod error;
pub mod profile1;
pub mod profile2;
mod sequence;

pub use counter::{CounterChecker, CounterStatus, RollingCounter};
pub use error::E2eError;
pub use sequence::{CheckStatus, Checker, Profile, SequenceConfig};
