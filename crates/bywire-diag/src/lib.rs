//! Diagnostics as sans-IO nodes (`no_std` + `alloc`): frames and time in, frames out.
//!
//! - [`isotp`]: ISO-TP (ISO 15765-2), one channel between two addresses, classic and CAN FD.
//! - [`uds`]: a UDS (ISO 14229-1) server's request handling over an ISO-TP channel.
#![no_std]

extern crate alloc;

pub mod isotp;
pub mod uds;
