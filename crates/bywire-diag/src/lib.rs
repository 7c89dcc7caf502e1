//! Diagnostics as sans-IO nodes (`no_std` + `alloc`): frames and time in, frames out.
//!
//! - [`isotp`]: ISO-TP (ISO 15765-2), one channel between two addresses, classic and CAN FD.
#![no_std]

extern crate alloc;

pub mod isotp;
