//! # bywire-net: the deterministic engine
//!
//! Simulated CAN as exactly as the wire model allows, with no clock, no thread and no I/O:
//!
//! - [`sim::SimBus`]: one bit-timed bus as a discrete-event simulation (arbitration, exact
//!   frame times, error frames and fault confinement to bus-off and back, tampering);
//! - [`network::Network`]: named buses that own sans-IO nodes ([`bywire_core::node::Node`]),
//!   wired to them by port and run in simulated time by the node contract's rule.
//!
//! The same run gives the same frames at the same nanoseconds, whatever the host: a simulator,
//! a test rig and a sweep all build on this. Real buses (SocketCAN, serial, network) live in
//! `bywire-bus`, which opens this engine as the `sim:` backend.

pub mod network;
pub mod sim;

use bywire_core::filter::{ErrorMask, Filter};
use bywire_core::{Frame, Timestamp};

/// A frame as received.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Received {
    /// The frame.
    pub frame: Frame,
    /// When it was on the bus (nanoseconds on the backend's clock).
    pub timestamp: Timestamp,
    /// Whether this endpoint sent it (delivered only with receive-own on). An own frame is the
    /// transmit confirmation: its timestamp is when it left (SocketCAN echoes it after the
    /// controller sent it; the bit-timed bus at its end of frame).
    pub own: bool,
    /// Whether a program on this host sent it (this endpoint or another): SocketCAN marks
    /// such frames `MSG_DONTROUTE`, which candump `-x` shows as TX. In-process buses: always.
    pub local: bool,
    /// The controller's own timestamp, on its clock, where the backend has one.
    pub hardware: Option<Timestamp>,
}

/// Receive filtering: SocketCAN's filter list, error mask and join option.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Filtering {
    /// Filters (any must match; all with `join`). Empty: no data frames.
    pub filters: Vec<Filter>,
    /// Error classes delivered as error frames.
    pub error_mask: ErrorMask,
    /// Frames must match every filter.
    pub join: bool,
}

impl Default for Filtering {
    /// Like a fresh SocketCAN raw socket: every data frame, no error frames.
    fn default() -> Self {
        Filtering {
            filters: vec![Filter::ALL],
            error_mask: ErrorMask::NONE,
            join: false,
        }
    }
}

impl Filtering {
    /// Whether a socket with these settings receives `frame`.
    pub fn accepts(&self, frame: &Frame) -> bool {
        bywire_core::FilterSet {
            filters: &self.filters,
            error_mask: self.error_mask,
            join: self.join,
        }
        .accepts(frame)
    }
}
