//! # bywire-canopen: CANopen from the object dictionary to CiA 402 drives
//!
//! Every protocol piece is a sans-IO node: frames and time in (`on_frame(now, frame)`), frames
//! out (`poll(now, out)`), and `next_deadline()` to say when it next needs a poll. Nothing here
//! reads a clock, sleeps or does I/O; the same code runs on a real bus, a virtual one, or in
//! simulated time.
//!
//! - [`od`]: the object dictionary (typed entries, access, limits, PDO mappability);
//!   [`eds`] reads and writes it as EDS/DCF.
//! - [`nmt`]: NMT states and commands, heartbeat consumer, node guarding.
//! - [`sdo`]: SDO server and client: expedited, segmented, block (with CRC), abort codes.
//! - [`pdo`]: PDO parameters, mapping and transmission types.
//! - [`device`]: a device (NMT slave) with EMCY, SYNC and heartbeat, running an
//!   [`device::Application`].
//! - [`emcy`]: emergency messages and the error register.
//! - [`master`]: the NMT master: commands, heartbeat monitoring, SDO client, SYNC, EMCY.
//! - [`cia402`]: the CiA 402 drive state machine, a drive with a motor model, and the
//!   master-side driver that enables, commands and safely stops a drive.
//! - [`roboteq`]: Roboteq's objects, the MDC1460-like device, and the master-side helper.
//! - [`config`] (feature `std`): the bus description file (TOML; ros2_canopen's `bus.yml` with
//!   the feature `yaml`).
//!
//! A drive answering an SDO upload of its device type (0x1000), as a master would ask:
//! ```
//! use bywire_canopen::cia402::{self, Drive};
//! use bywire_canopen::device::Device;
//! use bywire_canopen::{Node, Port};
//! use bywire_core::{Frame, Id, Timestamp};
//!
//! let mut drive = Device::new(2, cia402::drive_dictionary(2), Drive::new());
//! drive.poll(Timestamp::ZERO, &mut |_, _boot_up| {}); // boots into pre-operational
//! let request = Frame::classic(Id::standard(0x602).unwrap(), &[0x40, 0x00, 0x10, 0, 0, 0, 0, 0]).unwrap();
//! drive.on_frame(Timestamp::ZERO, Port::MAIN, &request);
//! let mut answers = Vec::new();
//! drive.poll(Timestamp::ZERO, &mut |_, frame| answers.push(frame));
//! let answer = answers.iter().find(|f| f.id() == Id::standard(0x582).ok()).unwrap();
//! // An expedited upload of four bytes: a CiA 402 drive's device type, 0x00020192.
//! assert_eq!(answer.data(), &[0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00]);
//! ```
#![cfg_attr(not(feature = "std"), no_std)]

#[cfg(feature = "alloc")]
extern crate alloc;

pub mod abort;
pub mod cia402;
#[cfg(feature = "std")]
pub mod config;
#[cfg(feature = "yaml")]
mod config_yaml;
#[cfg(feature = "alloc")]
pub mod device;
#[cfg(feature = "alloc")]
pub mod eds;
pub mod emcy;
#[cfg(feature = "alloc")]
pub mod master;
pub mod nmt;
#[cfg(feature = "alloc")]
pub mod od;
#[cfg(feature = "alloc")]
pub mod pdo;
pub mod queue;
#[cfg(feature = "alloc")]
pub mod roboteq;
#[cfg(feature = "alloc")]
pub mod scan;
#[cfg(feature = "alloc")]
pub mod sdo;

pub use abort::Abort;

pub use bywire_core::node::{Node, Port};
