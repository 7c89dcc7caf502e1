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

use crate::supervisor::{CommandStats, Supervisor};
use crate::wire::VehicleWire;

/// Polls made between two frames at most: a supervisor asks for one every few milliseconds,
/// so a gap of hours fits; a deadline that does not move ends the catching up.
const MAX_POLLS_BETWEEN_FRAMES: usize = 10_000_000;

/// What a trace line can change from: the states reported when they change.
#[derive(Debug, Clone, PartialEq)]
struct Seen {
    watchdog: String,
    estop: String,
    mode: String,
}

/// A supervisor fed a recorded session, writing its decisions.
#[derive(Debug)]
pub struct Replay<W: VehicleWire> {
    supervisor: Supervisor<W>,
    now: Timestamp,
    seen: Option<Seen>,
}

/// Each rejection count with the reason a trace names.
fn rejections(s: &CommandStats) -> [(u64, &'static str); 7] {
    [
        (s.malformed, "malformed"),
        (s.checksum, "checksum"),
        (s.repeated, "repeated counter"),
        (s.skipped, "skipped counter"),
        (s.out_of_range, "out of range"),
        (s.disagreements, "the two buses disagree"),
        (s.authentication, "not authenticated"),
    ]
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
        let mut line = String::new();
        if after.accepted > before.accepted {
            let _ = write!(line, "{} command accepted", seconds(at));
            emit(&line);
        }
        for ((was, _), (is, why)) in rejections(&before).iter().zip(rejections(&after)) {
            if is > *was {
                line.clear();
                let _ = write!(line, "{} command refused: {why}", seconds(at));
                emit(&line);
            }
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
        let mut sent = Vec::new();
        self.supervisor
            .poll(at, &mut |port, frame| sent.push((port, frame)));
        for (port, frame) in sent {
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
        }
        let now = Seen {
            watchdog: format!("{:?}", self.supervisor.watchdog().level()),
            estop: format!("{:?}", self.supervisor.estop().code()),
            mode: format!("{:?}", self.supervisor.mode()),
        };
        let before = self.seen.replace(now.clone());
        for (what, was, is) in [
            (
                "watchdog",
                before.as_ref().map(|s| &s.watchdog),
                &now.watchdog,
            ),
            ("estop", before.as_ref().map(|s| &s.estop), &now.estop),
            ("mode", before.as_ref().map(|s| &s.mode), &now.mode),
        ] {
            if was != Some(is) {
                emit(&format!("{} {what} {is}", seconds(at)));
            }
        }
    }
}
