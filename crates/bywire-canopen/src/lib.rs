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
//! - [`master`]: the NMT master: commands, heartbeat monitoring, SDO client, SYNC, EMCY.
//! - [`cia402`]: the CiA 402 drive state machine, a drive with a motor model, and the
//!   master-side driver that enables, commands and safely stops a drive.
//! - [`roboteq`]: Roboteq's objects, the MDC1460-like device, and the master-side helper.
//! - [`config`] (feature `std`): the bus description file.
#![cfg_attr(not(feature = "std"), no_std)]

extern crate alloc;

pub mod abort;
pub mod cia402;
#[cfg(feature = "std")]
pub mod config;
pub mod device;
pub mod eds;
pub mod master;
pub mod nmt;
pub mod od;
pub mod pdo;
pub mod queue;
pub mod roboteq;
pub mod sdo;

pub use abort::Abort;

pub use bywire_core::node::{Node, Port};

// The nodes of one bus connection: their inherent methods, on the main port.
bywire_core::single_port_node!(device::Device<A> where A: device::Application);
bywire_core::single_port_node!(master::Master);
