//! Network management: the NMT states and commands, heartbeat production and consumption,
//! and node guarding.

use core::time::Duration;

use bywire_core::frame::{Dlc, Frame, Id, StandardId};
use bywire_core::time::Timestamp;

use crate::queue::EventQueue;

/// An NMT state as a heartbeat reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum NmtState {
    /// Initialising; reported once, as the boot-up message.
    BootUp,
    /// Stopped: only NMT and heartbeat/guarding.
    Stopped,
    /// Operational: everything, PDOs included.
    Operational,
    /// Pre-operational: SDO, SYNC, EMCY, no PDOs.
    PreOperational,
}

impl NmtState {
    /// The state byte of a heartbeat.
    pub fn code(self) -> u8 {
        match self {
            NmtState::BootUp => 0x00,
            NmtState::Stopped => 0x04,
            NmtState::Operational => 0x05,
            NmtState::PreOperational => 0x7F,
        }
    }

    /// The state a heartbeat byte reports (the guarding toggle bit is ignored).
    pub fn from_code(code: u8) -> Option<NmtState> {
        match code & 0x7F {
            0x00 => Some(NmtState::BootUp),
            0x04 => Some(NmtState::Stopped),
            0x05 => Some(NmtState::Operational),
            0x7F => Some(NmtState::PreOperational),
            _ => None,
        }
    }

    /// The name python-canopen and CiA 301 use.
    pub fn name(self) -> &'static str {
        match self {
            NmtState::BootUp => "INITIALISING",
            NmtState::Stopped => "STOPPED",
            NmtState::Operational => "OPERATIONAL",
            NmtState::PreOperational => "PRE-OPERATIONAL",
        }
    }
}

/// An NMT command (CiA 301 command specifiers).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum NmtCommand {
    /// Enter operational (1).
    Start,
    /// Enter stopped (2).
    Stop,
    /// Enter pre-operational (0x80).
    EnterPreOperational,
    /// Reset the application (0x81).
    ResetNode,
    /// Reset communication (0x82).
    ResetCommunication,
}

impl NmtCommand {
    /// The command specifier.
    pub fn code(self) -> u8 {
        match self {
            NmtCommand::Start => 0x01,
            NmtCommand::Stop => 0x02,
            NmtCommand::EnterPreOperational => 0x80,
            NmtCommand::ResetNode => 0x81,
            NmtCommand::ResetCommunication => 0x82,
        }
    }

    /// The command a specifier names.
    pub fn from_code(code: u8) -> Option<NmtCommand> {
        match code {
            0x01 => Some(NmtCommand::Start),
            0x02 => Some(NmtCommand::Stop),
            0x80 => Some(NmtCommand::EnterPreOperational),
            0x81 => Some(NmtCommand::ResetNode),
            0x82 => Some(NmtCommand::ResetCommunication),
            _ => None,
        }
    }

    /// The frame on COB-ID 0 commanding `node` (0: every node).
    pub fn frame(self, node: u8) -> Frame {
        classic(0x000, &[self.code(), node])
    }

    /// Read an NMT command frame: `(command, addressed node)`; `None` if malformed.
    pub fn parse(frame: &Frame) -> Option<(NmtCommand, u8)> {
        if frame.is_remote() || frame.is_fd() || frame.id() != Id::standard(0).ok() {
            return None;
        }
        match frame.data() {
            [command, node] => Some((NmtCommand::from_code(*command)?, *node)),
            _ => None,
        }
    }

    /// The state a slave enters on this command (resets pass through boot-up).
    pub fn target(self) -> NmtState {
        match self {
            NmtCommand::Start => NmtState::Operational,
            NmtCommand::Stop => NmtState::Stopped,
            NmtCommand::EnterPreOperational => NmtState::PreOperational,
            NmtCommand::ResetNode | NmtCommand::ResetCommunication => NmtState::BootUp,
        }
    }
}

/// A classic data frame on a standard identifier (masked to 11 bits, data cut to 8 bytes, so
/// the fallback is never taken).
pub(crate) fn classic(cob_id: u16, data: &[u8]) -> Frame {
    let id = Id::Standard(StandardId::new(cob_id & 0x7FF).unwrap_or(StandardId::ZERO));
    Frame::classic(id, data.get(..8).unwrap_or(data))
        .unwrap_or(Frame::remote(id, Dlc::from_nibble(0)))
}

/// The standard identifier of a frame that can carry CANopen (classic, data or remote).
pub(crate) fn cob_id(frame: &Frame) -> Option<u16> {
    match frame.id()? {
        Id::Standard(id) if !frame.is_fd() => Some(id.as_raw()),
        _ => None,
    }
}

/// A heartbeat frame (`0x700 + node`, one state byte).
pub fn heartbeat_frame(node: u8, state: NmtState) -> Frame {
    classic(0x700 + u16::from(node & 0x7F), &[state.code()])
}

/// Read a heartbeat: `(node, state)`.
pub fn parse_heartbeat(frame: &Frame) -> Option<(u8, NmtState)> {
    let id = cob_id(frame)?;
    if !(0x701..=0x77F).contains(&id) || frame.is_remote() {
        return None;
    }
    match frame.data() {
        [state] => Some((u8::try_from(id - 0x700).ok()?, NmtState::from_code(*state)?)),
        _ => None,
    }
}

/// What the heartbeat consumer saw.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HeartbeatEvent {
    /// A node sent its boot-up message.
    BootUp {
        /// The node.
        node: u8,
    },
    /// A monitored node reported a different state.
    StateChanged {
        /// The node.
        node: u8,
        /// Its new state.
        state: NmtState,
    },
    /// No heartbeat within the node's consumer time.
    Lost {
        /// The node.
        node: u8,
    },
    /// A lost node's heartbeat came back.
    Recovered {
        /// The node.
        node: u8,
        /// The state it reports.
        state: NmtState,
    },
}

/// What is known of one monitored node.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Liveness {
    /// Never heard: not yet monitored (CiA 301 starts the timer at the first heartbeat).
    Unknown,
    /// Heard within its consumer time.
    Alive {
        /// Last reported state.
        state: NmtState,
        /// When.
        last: Timestamp,
    },
    /// Silent past its consumer time.
    Lost {
        /// Last reported state.
        state: NmtState,
    },
}

/// One monitored node.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Watched {
    node: u8,
    timeout: Duration,
    liveness: Liveness,
}

/// Consumer of heartbeats (object 0x1016): per-node timeouts, events on loss and recovery.
/// Holds at most [`HeartbeatConsumer::CAPACITY`] nodes; no allocation.
#[derive(Debug, Clone)]
pub struct HeartbeatConsumer {
    /// The watched nodes in `watched[..used]` (kept together, so scans stop there).
    watched: [Option<Watched>; HeartbeatConsumer::CAPACITY],
    used: usize,
    events: EventQueue<HeartbeatEvent, 32>,
    /// The earliest time a watched node would be declared lost, worked out again whenever a
    /// node's watch or liveness changes: runners ask for it after every poll and frame.
    deadline: Option<Timestamp>,
}

impl Default for HeartbeatConsumer {
    fn default() -> Self {
        HeartbeatConsumer {
            watched: [None; HeartbeatConsumer::CAPACITY],
            used: 0,
            events: EventQueue::new(),
            deadline: None,
        }
    }
}

impl HeartbeatConsumer {
    /// Nodes one consumer can watch (the sub-indices 0x1016 may have).
    pub const CAPACITY: usize = 127;

    /// Watch `node` with `timeout` (replacing an earlier time); a zero timeout stops
    /// watching it. `false` if the table is full.
    pub fn watch(&mut self, node: u8, timeout: Duration) -> bool {
        let watched = self.watch_entry(node, timeout);
        self.deadline = self.earliest_loss();
        watched
    }

    fn watch_entry(&mut self, node: u8, timeout: Duration) -> bool {
        let entry = Watched {
            node,
            timeout,
            liveness: Liveness::Unknown,
        };
        let at = self
            .watched
            .iter()
            .take(self.used)
            .position(|w| w.is_some_and(|w| w.node == node));
        match (at, timeout.is_zero()) {
            (Some(at), false) => {
                if let Some(slot) = self.watched.get_mut(at) {
                    *slot = Some(entry);
                }
                true
            }
            (Some(at), true) => {
                // Keep the watched nodes together: the last one takes the freed place.
                self.used -= 1;
                self.watched.swap(at, self.used);
                if let Some(slot) = self.watched.get_mut(self.used) {
                    *slot = None;
                }
                true
            }
            (None, true) => true,
            (None, false) => match self.watched.get_mut(self.used) {
                Some(slot) => {
                    *slot = Some(entry);
                    self.used += 1;
                    true
                }
                None => false,
            },
        }
    }

    /// Stop watching every node.
    pub fn clear(&mut self) {
        self.watched = [None; HeartbeatConsumer::CAPACITY];
        self.used = 0;
        self.deadline = None;
    }

    fn in_use(&self) -> impl Iterator<Item = &Watched> {
        self.watched.iter().take(self.used).flatten()
    }

    /// What is known of `node` (`None` if not watched).
    pub fn liveness(&self, node: u8) -> Option<Liveness> {
        self.in_use().find(|w| w.node == node).map(|w| w.liveness)
    }

    /// Take in a frame; heartbeats of watched nodes update them.
    pub fn on_frame(&mut self, now: Timestamp, frame: &Frame) {
        let Some((node, state)) = parse_heartbeat(frame) else {
            return;
        };
        if state == NmtState::BootUp {
            let _ = self.events.push(HeartbeatEvent::BootUp { node });
        }
        let Some(watched) = self
            .watched
            .iter_mut()
            .take(self.used)
            .flatten()
            .find(|w| w.node == node)
        else {
            return;
        };
        let event = match watched.liveness {
            Liveness::Lost { .. } => Some(HeartbeatEvent::Recovered { node, state }),
            Liveness::Alive { state: before, .. } if before != state => {
                Some(HeartbeatEvent::StateChanged { node, state })
            }
            Liveness::Unknown if state != NmtState::BootUp => {
                Some(HeartbeatEvent::StateChanged { node, state })
            }
            _ => None,
        };
        watched.liveness = Liveness::Alive { state, last: now };
        if let Some(event) = event {
            let _ = self.events.push(event);
        }
        self.deadline = self.earliest_loss();
    }

    /// Mark nodes silent past their consumer time as lost.
    #[inline]
    pub fn poll(&mut self, now: Timestamp) {
        // Nothing is lost before the deadline (and a loss is all that moves it here): the
        // usual case, inlined into every device's poll.
        if self.deadline.is_none_or(|deadline| now < deadline) {
            return;
        }
        self.find_losses(now);
    }

    fn find_losses(&mut self, now: Timestamp) {
        for watched in self.watched.iter_mut().take(self.used).flatten() {
            if let Liveness::Alive { state, last } = watched.liveness {
                if now >= last.saturating_add(watched.timeout) {
                    watched.liveness = Liveness::Lost { state };
                    let _ = self
                        .events
                        .push(HeartbeatEvent::Lost { node: watched.node });
                }
            }
        }
        self.deadline = self.earliest_loss();
    }

    /// The earliest time a watched node would be declared lost.
    pub fn next_deadline(&self) -> Option<Timestamp> {
        self.deadline
    }

    fn earliest_loss(&self) -> Option<Timestamp> {
        self.in_use()
            .filter_map(|w| match w.liveness {
                Liveness::Alive { last, .. } => Some(last.saturating_add(w.timeout)),
                Liveness::Unknown | Liveness::Lost { .. } => None,
            })
            .min()
    }

    /// The next event, oldest first.
    pub fn next_event(&mut self) -> Option<HeartbeatEvent> {
        self.events.pop()
    }

    /// Events dropped because nobody took them in time.
    pub fn dropped_events(&self) -> u64 {
        self.events.dropped
    }
}

/// Node guarding, master side: a remote frame on `0x700 + node` every guard time, and the
/// node is lost when `life_time_factor` guard times pass without an answer or an answer
/// repeats its toggle bit. An option beside heartbeats for devices that only guard.
#[derive(Debug, Clone)]
pub struct NodeGuard {
    node: u8,
    guard_time: Duration,
    life_time_factor: u32,
    next_request: Timestamp,
    last_answer: Option<Timestamp>,
    expected_toggle: Option<bool>,
    state: Option<NmtState>,
    lost: bool,
}

impl NodeGuard {
    /// Guard `node` every `guard_time`, lost after `life_time_factor` silent periods.
    pub fn new(node: u8, guard_time: Duration, life_time_factor: u32, now: Timestamp) -> NodeGuard {
        NodeGuard {
            node,
            guard_time,
            life_time_factor: life_time_factor.max(1),
            next_request: now,
            last_answer: None,
            expected_toggle: None,
            state: None,
            lost: false,
        }
    }

    /// Take in a frame; answers of the guarded node count.
    pub fn on_frame(&mut self, now: Timestamp, frame: &Frame) {
        if cob_id(frame) != Some(0x700 + u16::from(self.node)) || frame.is_remote() {
            return;
        }
        let [byte] = frame.data() else { return };
        let toggle = byte & 0x80 != 0;
        if self
            .expected_toggle
            .is_some_and(|expected| expected != toggle)
        {
            // A repeated toggle is a lost answer, not a live one.
            return;
        }
        self.expected_toggle = Some(!toggle);
        self.state = NmtState::from_code(*byte);
        self.last_answer = Some(now);
        self.lost = false;
    }

    /// Send the guard request when due; `true` the first time the node counts as lost.
    pub fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Frame)) -> bool {
        if now >= self.next_request {
            let id =
                StandardId::new(0x700 + u16::from(self.node & 0x7F)).unwrap_or(StandardId::ZERO);
            out(Frame::remote(Id::Standard(id), Dlc::from_nibble(1)));
            self.next_request = now.saturating_add(self.guard_time);
        }
        let life = self.guard_time.saturating_mul(self.life_time_factor);
        let silent_since = self.last_answer.unwrap_or(Timestamp::ZERO);
        if !self.lost && self.last_answer.is_some() && now >= silent_since.saturating_add(life) {
            self.lost = true;
            return true;
        }
        false
    }

    /// The guarded node's last reported state.
    pub fn state(&self) -> Option<NmtState> {
        self.state
    }

    /// The node is lost.
    pub fn is_lost(&self) -> bool {
        self.lost
    }

    /// When `poll` next has work.
    pub fn next_deadline(&self) -> Timestamp {
        self.next_request
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_and_heartbeats_round_trip() {
        for command in [
            NmtCommand::Start,
            NmtCommand::Stop,
            NmtCommand::EnterPreOperational,
            NmtCommand::ResetNode,
            NmtCommand::ResetCommunication,
        ] {
            assert_eq!(NmtCommand::parse(&command.frame(5)), Some((command, 5)));
        }
        assert_eq!(NmtCommand::Start.frame(1).data(), [0x01, 0x01]);
        assert_eq!(NmtCommand::parse(&classic(0, &[0x01])), None);
        assert_eq!(NmtCommand::parse(&classic(0, &[0x03, 1])), None);
        let frame = heartbeat_frame(3, NmtState::PreOperational);
        assert_eq!(cob_id(&frame), Some(0x703));
        assert_eq!(frame.data(), [0x7F]);
        assert_eq!(parse_heartbeat(&frame), Some((3, NmtState::PreOperational)));
        assert_eq!(parse_heartbeat(&classic(0x703, &[0x7F, 0])), None);
        assert_eq!(parse_heartbeat(&classic(0x703, &[0x33])), None);
    }

    #[test]
    fn a_silent_node_is_lost_at_its_consumer_time_and_recovers() {
        let mut consumer = HeartbeatConsumer::default();
        assert!(consumer.watch(2, Duration::from_millis(100)));
        consumer.poll(Timestamp::from_millis(1_000));
        assert_eq!(
            consumer.next_event(),
            None,
            "never heard: not monitored yet"
        );
        consumer.on_frame(
            Timestamp::from_millis(0),
            &heartbeat_frame(2, NmtState::BootUp),
        );
        assert_eq!(
            consumer.next_event(),
            Some(HeartbeatEvent::BootUp { node: 2 })
        );
        consumer.on_frame(
            Timestamp::from_millis(10),
            &heartbeat_frame(2, NmtState::PreOperational),
        );
        assert_eq!(
            consumer.next_event(),
            Some(HeartbeatEvent::StateChanged {
                node: 2,
                state: NmtState::PreOperational
            })
        );
        assert_eq!(consumer.next_deadline(), Some(Timestamp::from_millis(110)));
        consumer.poll(Timestamp::from_millis(109));
        assert_eq!(consumer.next_event(), None);
        consumer.poll(Timestamp::from_millis(110));
        assert_eq!(
            consumer.next_event(),
            Some(HeartbeatEvent::Lost { node: 2 })
        );
        consumer.poll(Timestamp::from_millis(500));
        assert_eq!(consumer.next_event(), None, "lost once, reported once");
        consumer.on_frame(
            Timestamp::from_millis(600),
            &heartbeat_frame(2, NmtState::Operational),
        );
        assert_eq!(
            consumer.next_event(),
            Some(HeartbeatEvent::Recovered {
                node: 2,
                state: NmtState::Operational
            })
        );
    }

    #[test]
    fn watching_and_unwatching_keeps_the_table_consistent() {
        let mut consumer = HeartbeatConsumer::default();
        for node in 1..=5 {
            assert!(consumer.watch(node, Duration::from_millis(100)));
        }
        assert!(consumer.watch(2, Duration::ZERO), "stop watching 2");
        assert!(
            consumer.watch(3, Duration::from_millis(50)),
            "a new time for 3"
        );
        assert_eq!(consumer.liveness(2), None);
        for node in [1, 3, 4, 5] {
            assert_eq!(consumer.liveness(node), Some(Liveness::Unknown), "{node}");
            consumer.on_frame(
                Timestamp::ZERO,
                &heartbeat_frame(node, NmtState::Operational),
            );
        }
        assert_eq!(
            consumer.next_deadline(),
            Some(Timestamp::from_millis(50)),
            "node 3's new time"
        );
        consumer.clear();
        assert_eq!(consumer.liveness(1), None);
        for node in 1..=127 {
            assert!(consumer.watch(node, Duration::from_millis(1)));
        }
        assert!(!consumer.watch(0, Duration::from_millis(1)), "full");
    }

    /// What the consumer does to its table, for the deadline property.
    #[derive(Debug, Clone)]
    enum ConsumerStep {
        Watch(u8, u64),
        Heartbeat(u8),
        Poll,
        Clear,
    }

    fn consumer_step() -> impl proptest::strategy::Strategy<Value = ConsumerStep> {
        use proptest::prelude::*;
        prop_oneof![
            (1u8..=4, 0u64..=30).prop_map(|(n, t)| ConsumerStep::Watch(n, t)),
            (1u8..=5).prop_map(ConsumerStep::Heartbeat),
            Just(ConsumerStep::Poll),
            Just(ConsumerStep::Clear),
        ]
    }

    proptest::proptest! {
        /// The deadline kept between changes is always the earliest loss worked out afresh
        /// from what is known of each watched node.
        #[test]
        fn the_deadline_is_always_the_earliest_loss(
            steps in proptest::collection::vec((consumer_step(), 0u64..=20), 1..60)
        ) {
            let mut consumer = HeartbeatConsumer::default();
            let mut timeouts = [None::<u64>; 6];
            let mut now = 0u64;
            for (step, advance) in steps {
                now += advance;
                let at = Timestamp::from_millis(now);
                match step {
                    ConsumerStep::Watch(node, millis) => {
                        consumer.watch(node, Duration::from_millis(millis));
                        timeouts[usize::from(node)] = (millis > 0).then_some(millis);
                    }
                    ConsumerStep::Heartbeat(node) => {
                        consumer.on_frame(at, &heartbeat_frame(node, NmtState::Operational));
                    }
                    ConsumerStep::Poll => consumer.poll(at),
                    ConsumerStep::Clear => {
                        consumer.clear();
                        timeouts = [None; 6];
                    }
                }
                let expected = (1u8..=5)
                    .filter_map(|node| {
                        let timeout = timeouts[usize::from(node)]?;
                        match consumer.liveness(node)? {
                            Liveness::Alive { last, .. } => {
                                Some(last.saturating_add(Duration::from_millis(timeout)))
                            }
                            Liveness::Unknown | Liveness::Lost { .. } => None,
                        }
                    })
                    .min();
                proptest::prop_assert_eq!(consumer.next_deadline(), expected);
            }
        }
    }

    #[test]
    fn node_guarding_detects_silence_and_repeated_toggles() {
        let mut guard = NodeGuard::new(4, Duration::from_millis(100), 3, Timestamp::ZERO);
        let mut sent = alloc::vec::Vec::new();
        assert!(!guard.poll(Timestamp::ZERO, &mut |f| sent.push(f)));
        assert!(sent
            .first()
            .is_some_and(|f| f.is_remote() && cob_id(f) == Some(0x704)));
        guard.on_frame(Timestamp::from_millis(1), &classic(0x704, &[0x05]));
        assert_eq!(guard.state(), Some(NmtState::Operational));
        // The same toggle again is not an answer.
        guard.on_frame(Timestamp::from_millis(101), &classic(0x704, &[0x05]));
        assert!(!guard.poll(Timestamp::from_millis(300), &mut |_| {}));
        assert!(guard.poll(Timestamp::from_millis(301), &mut |_| {}));
        assert!(guard.is_lost());
    }
}
