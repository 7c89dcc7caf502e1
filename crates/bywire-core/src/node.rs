//! The one shape of every protocol or control node: frames and time in, frames out, and when
//! it next needs to run. Runners (real-time over bus backends, or simulated over bit-timed
//! buses) drive nodes only through this trait; nothing below them reads a clock.
//!
//! A node has one or more **ports**, one per bus connection (the tug's vehicle control ECU has
//! four: bus 1, bus 1b, bus 2, bus 3). Which bus a port is attached to is the runner's
//! business; the node only names its ports. A node with one bus connection uses
//! [`Port::MAIN`] and may ignore the port of what it receives.
//!
//! # The time a node is given
//! Both runners follow one rule, so a node behaves the same in simulation and on a vehicle:
//!
//! 1. Time never goes backwards: each call's `now` is at or after the previous call's.
//! 2. `on_frame(now, port, frame)` is called with the time the frame became available to the
//!    node: its end of frame on a simulated bus, the moment the runner took it from the
//!    backend in real time. A node's own frames are not given back to it as frames.
//! 3. `on_sent(now, port, frame)` confirms that a frame the node gave to `out` went onto the
//!    bus (ISO-TP's N_As/N_Ar are timed from it): at its end of frame in simulation; in real
//!    time when the backend echoes it (SocketCAN's own-message loopback), or, on a backend
//!    that cannot echo, when the backend accepted it. A frame that never made it (a silenced
//!    node, a bus without acknowledgement) is never confirmed.
//! 4. `poll(now, out)` is called after every batch of frames delivered at one time, and
//!    otherwise no later than [`Node::next_deadline`] (as soon as a runner can: at that time in
//!    simulation, within the scheduler's wake-up delay in real time). A node must tolerate
//!    being polled early or more often than it asked; it must not rely on being polled late.
//! 5. Frames given to `out` are sent in the order given, on the port named.
//!
//! # Example
//! ```
//! use bywire_core::node::{Node, Port};
//! use bywire_core::{Frame, Id, Timestamp};
//!
//! /// Answers every frame on its port with the same frame under identifier 0x7FF.
//! struct Echo(Option<Frame>);
//!
//! impl Node for Echo {
//!     fn on_frame(&mut self, _now: Timestamp, _port: Port, frame: &Frame) {
//!         let id = Id::standard(0x7FF).unwrap();
//!         self.0 = Frame::classic(id, frame.data()).ok();
//!     }
//!     fn poll(&mut self, _now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
//!         if let Some(frame) = self.0.take() {
//!             out(Port::MAIN, frame);
//!         }
//!     }
//!     fn next_deadline(&self) -> Option<Timestamp> {
//!         None
//!     }
//! }
//!
//! let mut echo = Echo(None);
//! let frame = Frame::classic(Id::standard(0x123).unwrap(), &[1, 2]).unwrap();
//! echo.on_frame(Timestamp::ZERO, Port::MAIN, &frame);
//! let mut sent = None;
//! echo.poll(Timestamp::ZERO, &mut |port, f| sent = Some((port, f)));
//! let (port, answer) = sent.unwrap();
//! assert_eq!((port, answer.data()), (Port::MAIN, &[1u8, 2][..]));
//! ```

use core::fmt;

use crate::frame::Frame;
use crate::time::Timestamp;

/// One of a node's bus connections, numbered by the node from 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct Port(pub u8);

impl Port {
    /// The port of a node with a single bus connection (and the first of several).
    pub const MAIN: Port = Port(0);

    /// The port's number, as an index.
    pub fn index(self) -> usize {
        usize::from(self.0)
    }
}

impl fmt::Display for Port {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "port {}", self.0)
    }
}

/// A sans-IO node.
pub trait Node {
    /// Take in a frame seen on `port` (a node's own frames are not given back to it).
    fn on_frame(&mut self, now: Timestamp, port: Port, frame: &Frame);
    /// A frame this node sent on `port` is on the bus (its transmit confirmation). Returns
    /// whether taking it may have moved the node's deadline: a runner asks the deadline again
    /// only then. Nodes that do not time their own transmissions ignore it (`false`).
    fn on_sent(&mut self, _now: Timestamp, _port: Port, _frame: &Frame) -> bool {
        false
    }
    /// Do what is due at `now`; frames to send go to `out` with the port to send them on.
    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame));
    /// The latest time `poll` should next be called (`None`: only when a frame arrives).
    fn next_deadline(&self) -> Option<Timestamp>;
}

impl<N: Node + ?Sized> Node for &mut N {
    fn on_frame(&mut self, now: Timestamp, port: Port, frame: &Frame) {
        (**self).on_frame(now, port, frame);
    }
    fn on_sent(&mut self, now: Timestamp, port: Port, frame: &Frame) -> bool {
        (**self).on_sent(now, port, frame)
    }
    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        (**self).poll(now, out);
    }
    fn next_deadline(&self) -> Option<Timestamp> {
        (**self).next_deadline()
    }
}
