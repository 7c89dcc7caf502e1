//! Replay regression: a recorded session's frames fed to a [`Supervisor`] in the log's own
//! time, and what it decided written as a trace — each command accepted or refused with the
//! reason, each change of watchdog level, E-stop state and control mode, each frame it sent.
//! The trace depends on nothing but the frames and the supervisor's configuration, so it is the
//! same on every run; a stored trace compared line by line finds the first decision a change
//! to the supervisor (a limit, a timeout) alters.
//!
//! [`Replay`] takes the frames in time order; between two frames it polls the supervisor at
//! each deadline it asks for, as a runner would.

use core::fmt::Write as _;

use bywire_core::node::{Node, Port};
use bywire_core::{Frame, Timestamp};

use crate::command::{ControlMode, EstopCode, WatchdogLevel};
use crate::supervisor::Supervisor;
use crate::wire::VehicleWire;

/// Polls made between two frames at most: a supervisor asks for one every few milliseconds,
/// so a gap of hours fits; a deadline that does not move ends the catching up.
const MAX_POLLS_BETWEEN_FRAMES: usize = 10_000_000;

/// A supervisor fed a recorded session, writing its decisions.
#[derive(Debug)]
pub struct Replay<W: VehicleWire> {
    supervisor: Supervisor<W>,
    now: Timestamp,
    /// The states last reported, to report each change.
    seen: Option<(WatchdogLevel, EstopCode, ControlMode)>,
}

/// `t` as seconds with microseconds, the trace's time column.
fn seconds(t: Timestamp) -> String {
    let ns = t.as_nanos();
    format!("{}.{:06}", ns / 1_000_000_000, (ns % 1_000_000_000) / 1_000)
}

impl<W: VehicleWire> Replay<W> {
    /// A replay into `supervisor` (as configured and wired for the vehicle).
    pub fn new(supervisor: Supervisor<W>) -> Self {
        Replay {
            supervisor,
            now: Timestamp::ZERO,
            seen: None,
        }
    }

    /// The supervisor, as the frames so far have left it.
    pub fn supervisor(&self) -> &Supervisor<W> {
        &self.supervisor
    }

    /// `frame` received at `at` on `port` ([`Supervisor::PORT_A`] or [`Supervisor::PORT_B`]),
    /// after the polls due before it; each trace line to `emit`. A frame earlier than the
    /// last is taken at the last's time (a merged log's ties and small reorderings).
    pub fn push(&mut self, at: Timestamp, port: Port, frame: &Frame, emit: &mut dyn FnMut(&str)) {
        let at = at.max(self.now);
        self.advance(at, emit);
        let before = self.supervisor.stats();
        self.now = at;
        self.supervisor.on_frame(at, port, frame);
        self.poll(at, emit);
        let after = self.supervisor.stats();
        if after.accepted > before.accepted {
            emit(&format!("{} command accepted", seconds(at)));
        }
        for why in after.rejected_since(before) {
            emit(&format!("{} command refused: {}", seconds(at), why.name()));
        }
    }

    /// The polls due up to `until` (the end of the session).
    pub fn finish(&mut self, until: Timestamp, emit: &mut dyn FnMut(&str)) {
        self.advance(until, emit);
    }

    /// Poll at every deadline before `until`.
    fn advance(&mut self, until: Timestamp, emit: &mut dyn FnMut(&str)) {
        for _ in 0..MAX_POLLS_BETWEEN_FRAMES {
            match self.supervisor.next_deadline() {
                Some(deadline) if deadline < until => {
                    let at = deadline.max(self.now);
                    self.now = at;
                    self.poll(at, emit);
                    if self.supervisor.next_deadline() == Some(deadline) {
                        break;
                    }
                }
                _ => break,
            }
        }
    }

    /// One poll: the frames it sent and the states that changed.
    fn poll(&mut self, at: Timestamp, emit: &mut dyn FnMut(&str)) {
        self.supervisor.poll(at, &mut |port, frame| {
            let mut line = format!("{} sent {} ", seconds(at), port.0);
            match frame.id() {
                Some(id) if id.is_extended() => {
                    let _ = write!(line, "{:08X}", id.as_raw());
                }
                Some(id) => {
                    let _ = write!(line, "{:03X}", id.as_raw());
                }
                None => line.push('-'),
            }
            line.push(' ');
            for byte in frame.data() {
                let _ = write!(line, "{byte:02X}");
            }
            emit(&line);
        });
        let now = (
            self.supervisor.watchdog().level(),
            self.supervisor.estop().code(),
            self.supervisor.mode(),
        );
        let before = self.seen.replace(now);
        if before.map(|b| b.0) != Some(now.0) {
            emit(&format!("{} watchdog {:?}", seconds(at), now.0));
        }
        if before.map(|b| b.1) != Some(now.1) {
            emit(&format!("{} estop {:?}", seconds(at), now.1));
        }
        if before.map(|b| b.2) != Some(now.2) {
            emit(&format!("{} mode {:?}", seconds(at), now.2));
        }
    }
}
