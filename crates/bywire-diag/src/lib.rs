//! Diagnostics as sans-IO nodes (`no_std` + `alloc`): frames and time in, frames out.
//!
//! - [`isotp`]: ISO-TP (ISO 15765-2), one channel between two addresses, classic and CAN FD.
//! - [`uds`]: a UDS (ISO 14229-1) server's request handling over an ISO-TP channel.
//! - [`client`]: a UDS client (the tester) over an ISO-TP channel, P2/P2* and S3 timed.
//! - [`describe`]: an ECU's DIDs and DTCs as a tester names them; J2012 DTC codes.
#![no_std]

extern crate alloc;

pub mod client;
pub mod describe;
pub mod isotp;
pub mod uds;
