//! # bywire-core: CAN as it is on the wire
//!
//! A CAN bus carries *frames*: an identifier that is also the frame's priority (lower wins
//! arbitration), up to 8 data bytes (classic CAN) or 64 (CAN FD), and a CRC. Every node sees
//! every frame; a node that sees a protocol violation destroys the frame with an *error frame*
//! and counts the error, and a node that keeps failing falls silent (*bus-off*).
//!
//! This crate models exactly that, with no allocation, no I/O and no clock, so the same code runs
//! on an ECU and in a simulator:
//!
//! - [`frame`]: [`Frame`] (classic data and remote, CAN FD, error frames), [`Id`], [`Dlc`], and
//!   the can-utils text form (`123#DEADBEEF`, `1ABCDEF0##1...`);
//! - [`filter`]: SocketCAN `id:mask` / `id~mask` filters and error masks, matched as the kernel's
//!   `can_raw` matches them;
//! - [`wire`]: the exact bit sequence of a frame (stuffing, CRC-15/17/21, ISO CAN FD stuff count
//!   and fixed stuff bits), decoding with the five CAN error kinds, exact length and bus time;
//! - [`crc`]: the CAN and AUTOSAR CRCs;
//! - [`bittiming`]: prescaler and segments for a bitrate and sample point within a controller's
//!   register limits, the same answer the Linux kernel gives;
//! - [`confinement`]: the ISO 11898-1 error counters and bus-off as a pure state machine;
//! - [`busload`]: bus load from timestamped frames, and predicted load of periodic messages;
//! - [`e2e`]: rolling counters, checksums and AUTOSAR E2E profiles 1 and 2;
//! - [`text`]: Windows-1252 text, as legacy DBC and EDS files are written;
//! - [`time`]: [`Timestamp`], the only notion of time here, always passed in;
//! - `file_error` (with the `alloc` feature): `FileError`, how every configuration file
//!   (bus descriptions, vehicle profiles, scenarios, ECU descriptions) names its problems.
//!
//! ```
//! use bywire_core::{Frame, wire};
//! let frame: Frame = "123#DEADBEEF".parse().unwrap();
//! let bits = wire::encode(&frame).unwrap();
//! assert_eq!(frame.to_string(), "123#DEADBEEF");
//! assert!(bits.len() >= 44 + 32);
//! assert_eq!(wire::decode(bits.bits()).unwrap(), frame);
//! ```
#![no_std]
#![cfg_attr(docsrs, feature(doc_auto_cfg))]

#[cfg(feature = "alloc")]
extern crate alloc;

pub mod bittiming;
pub mod busload;
pub mod confinement;
pub mod crc;
pub mod e2e;
#[cfg(feature = "alloc")]
pub mod file_error;
pub mod filter;
pub mod frame;
pub mod node;
pub mod num;
pub mod schedule;
pub mod text;
pub mod time;
pub mod wire;

#[cfg(feature = "alloc")]
pub use file_error::FileError;
pub use filter::{ErrorMask, Filter, FilterSet};
pub use frame::{
    ClassicFrame, Dlc, ErrorClass, ErrorFrame, ExtendedId, FdFrame, Frame, FrameError, Id,
    ParseFrameError, StandardId,
};
pub use time::Timestamp;
