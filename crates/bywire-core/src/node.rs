//! The one shape of every protocol or control node: frames and time in, frames out, and when
//! it next needs to run. Runners (real-time over a bus backend, or simulated) drive nodes only
//! through this trait; nothing below them reads a clock.

use crate::frame::Frame;
use crate::time::Timestamp;

/// A sans-IO node.
pub trait Node {
    /// Take in a frame seen on the bus (a node's own frames are not given back to it).
    fn on_frame(&mut self, now: Timestamp, frame: &Frame);
    /// Do what is due at `now`; frames to send go to `out`.
    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Frame));
    /// The latest time `poll` should next be called (`None`: only when a frame arrives).
    fn next_deadline(&self) -> Option<Timestamp>;
}
