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

use bywire_core::frame::Frame;
use bywire_core::time::Timestamp;

pub use bywire_core::node::Node;

impl<A: device::Application> Node for device::Device<A> {
    fn on_frame(&mut self, now: Timestamp, frame: &Frame) {
        device::Device::on_frame(self, now, frame);
    }
    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Frame)) {
        device::Device::poll(self, now, out);
    }
    fn next_deadline(&self) -> Option<Timestamp> {
        device::Device::next_deadline(self)
    }
}

impl Node for master::Master {
    fn on_frame(&mut self, now: Timestamp, frame: &Frame) {
        master::Master::on_frame(self, now, frame);
    }
    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Frame)) {
        master::Master::poll(self, now, out);
    }
    fn next_deadline(&self) -> Option<Timestamp> {
        master::Master::next_deadline(self)
    }
}
