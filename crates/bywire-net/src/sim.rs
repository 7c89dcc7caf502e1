//! The bit-timed bus: a deterministic discrete-event simulation of one CAN bus.
//!
//! Nodes hand frames to their controller's transmit queue ([`SimBus::submit`]); whenever the bus
//! is idle, every node with a frame ready offers its highest-priority one and the lowest
//! identifier wins arbitration, as on a wire. A frame occupies the bus for its exact stuffed
//! length from the wire model (the data phase at the data bitrate for FD frames with BRS), then
//! 3 bits of intermission; receivers get it at the end of its EOF, with that timestamp.
//!
//! Faults ([`SimBus::corrupt`]) destroy transmissions: the receivers detect a CRC error at the
//! CRC delimiter, an error flag (6 bits) and delimiter (8 bits) follow, the counters change by
//! the ISO 11898-1 rules through `bywire-core`'s [`Confinement`], and the transmitter retries.
//! An error-passive transmitter waits 8 more bits (suspend transmission) before its next attempt;
//! a bus-off node takes no part until it has seen 128 sequences of 11 recessive bits.
//!
//! Time is simulated: [`SimBus::advance`] runs the bus up to a given instant, as fast as the
//! host computes it. Nothing here reads a clock.

use std::collections::VecDeque;

use bywire_core::confinement::{Confinement, Event, NodeState, StateChange, TransmitErrorCause};
use bywire_core::frame::{ErrorClass, ErrorFrame};
use bywire_core::time::earliest;
use bywire_core::wire::{self, ClassicHeader, Field};
use bywire_core::{Frame, Id, Timestamp};

use crate::{Filtering, Received};

/// Bits of intermission after every frame.
const INTERMISSION: u64 = 3;
/// Error flag (6) and error delimiter (8).
const ERROR_FRAME: u64 = 14;
/// Extra recessive bits an error-passive transmitter waits before sending again.
const SUSPEND: u64 = 8;
/// Recessive bits that make one bus-off recovery sequence.
const RECOVERY_BITS: u64 = 11;

/// Frames a node's receive queue holds by default.
pub const DEFAULT_RX_CAPACITY: usize = 4096;

/// A node's index on the bus.
pub type NodeId = usize;

/// Nodes a bus routes ([`SimBus::route`]): one bit each, so at most this many.
pub const MAX_ROUTED: usize = 64;

/// A frame's time in whole nanoseconds: exact at common bitrates, the rest rounded to nearest
/// (worked out once, when the frame's timing is first remembered).
#[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
fn whole_ns(time: f64) -> u64 {
    time.round() as u64
}

/// Nanoseconds for `n` bits at `nominal` bit/s, exact when the bit time is a whole number of
/// ns. In 64 bits while the product fits (a frame's few hundred bits): a 128-bit division is a
/// library call.
fn bits_ns(nominal: u32, n: u64) -> u64 {
    let nominal = u64::from(nominal.max(1));
    match n.checked_mul(1_000_000_000) {
        Some(product) => product / nominal,
        None => {
            let ns = u128::from(n) * 1_000_000_000 / u128::from(nominal);
            u64::try_from(ns).unwrap_or(u64::MAX)
        }
    }
}

/// Whether `node` is in `set`, a set of nodes one bit each (none past [`MAX_ROUTED`]).
fn has_node(set: u64, node: NodeId) -> bool {
    node < MAX_ROUTED && set >> node & 1 == 1
}

/// A frame (or a controller's state report) for the nodes a runner routes: one copy for all
/// the nodes it goes to, in the order the bus produced them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Routed {
    /// The frame and when it arrived (`own` is unset: see `sender`).
    pub received: Received,
    /// The routed nodes it goes to, one bit each.
    pub to: u64,
    /// The node that sent it: its copy is the transmit confirmation (`None` for a report).
    pub sender: Option<NodeId>,
}

/// What happened on the bus, in time order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BusEvent {
    /// A frame was sent successfully.
    Transmitted {
        /// The sender.
        node: NodeId,
        /// Its identifier.
        id: Id,
        /// Start of frame.
        start: Timestamp,
        /// End of EOF (when receivers get it).
        end: Timestamp,
        /// From `submit` to `end`: queueing, arbitration and transmission.
        latency_ns: u64,
    },
    /// A transmission was destroyed by an error frame; the frame will be retried.
    Destroyed {
        /// The sender.
        node: NodeId,
        /// Its identifier.
        id: Id,
        /// Start of frame.
        start: Timestamp,
        /// End of the error delimiter.
        end: Timestamp,
    },
    /// A node offered a frame but another won arbitration.
    ArbitrationLost {
        /// The loser.
        node: NodeId,
        /// The identifier it offered.
        id: Id,
        /// When.
        at: Timestamp,
    },
    /// A node's fault-confinement state changed.
    StateChanged {
        /// The node.
        node: NodeId,
        /// Its new state.
        state: NodeState,
        /// When.
        at: Timestamp,
    },
}

struct Pending {
    frame: Frame,
    /// Its identifier (every queued frame has one: error frames are never queued).
    id: Id,
    /// Its priority in arbitration, worked out once ([`Id::arbitration_key`]): the queue is
    /// searched at every arbitration.
    priority: u32,
    submitted: Timestamp,
    /// Submission order, for equal identifiers.
    seq: u64,
}

struct Node {
    /// Frames to send, in arbitration order (priority, then submission): the first that may
    /// start is the node's offer.
    queue: Vec<Pending>,
    /// The earliest submission time in `queue` (meaningless while it is empty): the bus asks
    /// for it after every frame, and one node's queue changes at a time.
    first_submitted: Timestamp,
    rx: VecDeque<Received>,
    /// Frames `rx` holds before new ones are dropped.
    rx_capacity: usize,
    /// Frames dropped because `rx` was full.
    rx_dropped: u64,
    filtering: Filtering,
    receive_own: bool,
    confinement: Confinement,
    /// Earliest start of its next transmission (suspend transmission).
    not_before: Timestamp,
    /// Recessive bits seen in a row while bus-off.
    recessive_run: u64,
}

impl Node {
    /// A frame `winner` sent reaches node `index` (`accepts`: its filters take it): queued
    /// here, or its bit returned when the node is routed (one of `routed`).
    fn receive(
        &mut self,
        index: NodeId,
        winner: NodeId,
        accepts: bool,
        routed: u64,
        received: Received,
    ) -> u64 {
        let own = index == winner;
        // The sender's own copy is its transmit confirmation, past its filters.
        if self.confinement.state() == NodeState::BusOff
            || (own && !self.receive_own)
            || (!own && !accepts)
        {
            return 0;
        }
        if has_node(routed, index) {
            return 1 << index;
        }
        self.deliver(Received { own, ..received });
        0
    }

    fn deliver(&mut self, received: Received) {
        if self.rx.len() >= self.rx_capacity {
            self.rx_dropped += 1;
        } else {
            self.rx.push_back(received);
        }
    }
}

/// The error frame a SocketCAN driver sends its sockets on a state change (the kernel's
/// `can_change_state` and bus-off handling): controller problem with the passive/active detail,
/// bus-off, or restarted, always with the counters.
fn state_report(change: StateChange, now: &Confinement) -> ErrorFrame {
    let (tec, rec) = (now.tec(), now.rec());
    let tec_byte = u8::try_from(tec).unwrap_or(u8::MAX);
    let rec_byte = u8::try_from(rec).unwrap_or(u8::MAX);
    let (class, detail) = match (change.from, change.to) {
        (_, NodeState::BusOff) => (ErrorClass::BusOff.bit(), 0),
        (NodeState::BusOff, _) => (ErrorClass::Restarted.bit(), 0),
        (_, NodeState::ErrorPassive) if tec >= rec => (ErrorClass::Controller.bit(), 0x20),
        (_, NodeState::ErrorPassive) => (ErrorClass::Controller.bit(), 0x10),
        (_, NodeState::ErrorActive) => (ErrorClass::Controller.bit(), 0x40),
    };
    let data = [0, detail, 0, 0, 0, 0, tec_byte, rec_byte];
    ErrorFrame::from_array(class | ErrorClass::Counters.bit(), data)
}

/// A fault: destroy the next `count` transmissions that match.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Fault {
    /// Only this sender's frames (any sender when `None`).
    pub node: Option<NodeId>,
    /// Only this identifier (any when `None`).
    pub id: Option<Id>,
    /// How many more transmissions to destroy.
    pub count: u32,
    /// Which error the disturbance causes, and so where the error frame starts.
    pub kind: Corruption,
}

/// The error a disturbance on the wire causes (ISO 11898-1's error kinds a frame's content
/// can cause), placed in the frame's data: it decides which node finds the error and at which
/// bit, and so when the error frame starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Corruption {
    /// A bit flipped in the data without breaking the stuffing: the receivers find the CRC
    /// wrong at the CRC delimiter.
    #[default]
    Crc,
    /// The transmitter reads back another level than it sent at the first data bit (the
    /// DLC's first without data) and signals at once.
    Bit,
    /// A stuff bit overwritten, so receivers read six equal levels: found at the frame's
    /// first stuff bit (five bits into the data when the frame has none).
    Stuff,
}

impl Corruption {
    /// Bits the frame is read for before the error is found (the error flag starts after
    /// them); `None` for [`Corruption::Crc`], whose point the bus keeps cached per frame.
    fn detected_after(self, frame: &Frame) -> Option<usize> {
        if self == Corruption::Crc {
            return None;
        }
        let bits = wire::encode(frame).ok()?;
        let data = bits
            .spans()
            .iter()
            .find(|s| s.field == Field::Data)
            .or_else(|| bits.spans().iter().find(|s| s.field == Field::Dlc))
            .map(|s| s.start)?;
        let at = match self {
            Corruption::Bit => data,
            _ => (0..bits.len())
                .find(|i| bits.is_stuff_bit(*i))
                .unwrap_or(data + 5),
        };
        Some(at + 1)
    }
}

/// What a faulty sender does to frames of one identifier (see [`SimBus::tamper`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tamper {
    /// The lowest bit of the first data byte flipped (checksums catch it; CAN's CRC cannot,
    /// it is computed over the wrong data).
    FlipBit,
    /// Sent twice.
    Duplicate,
    /// Sent this much later.
    Delay(std::time::Duration),
    /// Never sent (the sender's software loses it).
    Drop,
}

/// `frame` with the lowest bit of its first data byte flipped (as it is without data).
fn flipped(frame: Frame) -> Frame {
    if frame.is_remote() || frame.is_error() || frame.data().is_empty() {
        return frame;
    }
    let mut data = [0u8; 64];
    data.iter_mut().zip(frame.data()).for_each(|(d, s)| *d = *s);
    if let Some(first) = data.first_mut() {
        *first ^= 0x01;
    }
    let data = data.get(..frame.data().len()).unwrap_or(&[]);
    let rebuilt = match frame {
        Frame::Classic(c) => Frame::classic(c.id(), data),
        Frame::Fd(f) => Frame::fd(f.id(), data, f.brs(), f.esi()),
        Frame::Error(_) => Ok(frame),
    };
    rebuilt.unwrap_or(frame)
}

/// Whether `event` leaves a node's counters and state as they are: a success counts a
/// counter down, so one already at zero (or a node off the bus) has nothing to change. Most
/// frames on a healthy bus are such events for every node, and the simulator skips them.
fn unchanged_by(confinement: &Confinement, event: Event) -> bool {
    let off = confinement.state() == NodeState::BusOff;
    match event {
        Event::TransmitSuccess => off || confinement.tec() == 0,
        Event::ReceiveSuccess => off || confinement.rec() == 0,
        _ => off,
    }
}

/// Slots of the acceptance table (a power of two): with 256, three pairs of the tug's CANopen
/// identifiers (0x191 and 0x221 among them) shared a slot and missed on every frame.
const ACCEPTANCE_CACHE: usize = 1 << 10;

/// Slots of the classic-frame timing table (a power of two).
const CLASSIC_CACHE: usize = 1 << 10;

/// Slots for classic frame headers (by identifier, flags and DLC).
const HEADER_CACHE: usize = 1 << 8;

/// A classic frame's content as a table key: identifier with its extended and remote flags,
/// DLC, and the data bytes as one word.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct ClassicKey {
    id: u32,
    dlc: u8,
    data: u64,
}

impl ClassicKey {
    fn of(frame: &Frame) -> Option<ClassicKey> {
        let Frame::Classic(c) = frame else {
            return None;
        };
        let id = match c.id() {
            Id::Standard(id) => u32::from(id.as_raw()),
            Id::Extended(id) => id.as_raw() | 1 << 31,
        } | u32::from(c.is_remote()) << 30;
        let mut data = [0u8; 8];
        data.iter_mut().zip(frame.data()).for_each(|(d, s)| *d = *s);
        Some(ClassicKey {
            id,
            dlc: c.dlc().as_raw(),
            data: u64::from_le_bytes(data),
        })
    }

    /// Its header's slot (identifier, flags and DLC alone).
    fn header_slot(self) -> usize {
        let mixed =
            (u64::from(self.id) | u64::from(self.dlc) << 32).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        usize::try_from(mixed >> (64 - HEADER_CACHE.trailing_zeros())).unwrap_or(0)
    }

    /// Its slot: a multiplicative hash's top bits.
    fn slot(self) -> usize {
        let mixed = (u64::from(self.id) | u64::from(self.dlc) << 32)
            .wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ self.data.wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
        usize::try_from(mixed >> (64 - CLASSIC_CACHE.trailing_zeros())).unwrap_or(0)
    }
}

/// One simulated bus.
pub struct SimBus {
    /// Frame time (ns) and the bits a receiver reads before it finds a destroyed frame's CRC
    /// wrong, by frame: the wire model is exact but costly, and periodic traffic repeats the
    /// same frames (bounded: cleared when full; a pure function, so runs stay deterministic).
    timings: std::collections::HashMap<Frame, (u64, usize)>,
    /// The same for classic frames, direct-mapped by content: cheaper than hashing them.
    classic_timings: Vec<Option<(ClassicKey, (u64, usize))>>,
    /// Classic frames' headers by identifier (with its flags) and DLC: a payload not yet
    /// timed is counted on from its header.
    classic_headers: Vec<Option<(u32, u8, ClassicHeader)>>,
    /// Which nodes' filters take a frame, by its SocketCAN identifier (all that acceptance
    /// depends on): a direct-mapped table of node bit sets, emptied whenever a node or a
    /// filter changes. Delivering is where a bus's time goes; most buses carry a few dozen
    /// identifiers to a dozen nodes.
    acceptance: Vec<Option<(u32, u64)>>,
    /// Faulty senders, by identifier.
    tampered: Vec<(Id, Tamper)>,
    nominal: u32,
    data: Option<u32>,
    /// The intermission after every frame, ns (worked out once: a division a frame).
    intermission_ns: u64,
    /// The bus is idle from here on (after the last intermission).
    idle_from: Timestamp,
    /// The earliest a queued frame may start, bus idle or not (`None` inside: no frame
    /// queued), remembered until a queue, a suspension or a node's state changes: runners ask
    /// for the next change far more often than frames are queued.
    ready: std::cell::Cell<Option<Option<Timestamp>>>,
    /// Simulated up to here.
    now: Timestamp,
    nodes: Vec<Node>,
    /// Faults, each with whether it ends when its victim is bus-off.
    faults: Vec<(Fault, bool)>,
    events: Vec<BusEvent>,
    /// Whether arbitration losses are among the events.
    report_arbitration: bool,
    next_seq: u64,
    busy_ns: u64,
    /// Nodes that are bus-off (counted when a state changes).
    bus_off_nodes: usize,
    /// Nodes a successful reception changes (receive errors to count down), counted likewise.
    counting_receivers: usize,
    /// Nodes whose frames go to `routed_rx` instead of their own queue, one bit each.
    routed: u64,
    /// Their frames, one copy for all of them: a runner with a dozen nodes on a bus would
    /// otherwise copy every frame a dozen times and look in every queue for the next.
    routed_rx: VecDeque<Routed>,
    /// The nodes with frames queued, in node order: arbitration and the next start look at
    /// these, not at every node on the bus.
    queued: Vec<NodeId>,
}

impl SimBus {
    /// A bus at `nominal` bit/s, with FD data phases at `data` bit/s when given.
    pub fn new(nominal: u32, data: Option<u32>) -> Self {
        SimBus {
            timings: std::collections::HashMap::new(),
            classic_timings: vec![None; CLASSIC_CACHE],
            classic_headers: vec![None; HEADER_CACHE],
            acceptance: vec![None; ACCEPTANCE_CACHE],
            tampered: Vec::new(),
            nominal: nominal.max(1),
            data,
            intermission_ns: bits_ns(nominal, INTERMISSION),
            idle_from: Timestamp::ZERO,
            ready: std::cell::Cell::new(None),
            now: Timestamp::ZERO,
            nodes: Vec::new(),
            faults: Vec::new(),
            events: Vec::new(),
            report_arbitration: true,
            next_seq: 0,
            busy_ns: 0,
            bus_off_nodes: 0,
            counting_receivers: 0,
            routed: 0,
            routed_rx: VecDeque::new(),
            queued: Vec::new(),
        }
    }

    /// Route a node's frames to [`SimBus::next_routed`] instead of its own queue (a runner
    /// that drives many nodes takes each frame once for all of them); `false` when the node
    /// does not exist or is past the first [`MAX_ROUTED`].
    pub fn route(&mut self, node: NodeId) -> bool {
        if node >= MAX_ROUTED || node >= self.nodes.len() {
            return false;
        }
        self.routed |= 1 << node;
        true
    }

    /// The next frame for the routed nodes that arrived by `at`.
    pub fn next_routed(&mut self, at: Timestamp) -> Option<Routed> {
        if self.routed_rx.front()?.received.timestamp > at {
            return None;
        }
        self.routed_rx.pop_front()
    }

    /// The next frame for the routed nodes if it arrived by `at`, left in place (a runner
    /// hands it to each node, then [`SimBus::pass_routed`]).
    pub fn peek_routed(&self, at: Timestamp) -> Option<&Routed> {
        self.routed_rx
            .front()
            .filter(|r| r.received.timestamp <= at)
    }

    /// Done with the next frame for the routed nodes.
    pub fn pass_routed(&mut self) {
        let _ = self.routed_rx.pop_front();
    }

    /// When the next frame for the routed nodes arrives (already decided: a transmission
    /// that started).
    pub fn next_routed_arrival(&self) -> Option<Timestamp> {
        self.routed_rx.front().map(|r| r.received.timestamp)
    }

    /// When the bus itself next does something a runner must [`advance`](Self::advance) to:
    /// the next transmission's start or a bus-off recovery (arrivals aside).
    pub fn next_activity(&self) -> Option<Timestamp> {
        let from = self.idle_from.max(self.now);
        earliest([self.next_start(), self.next_recovery(from)])
    }

    fn is_routed(&self, node: NodeId) -> bool {
        has_node(self.routed, node)
    }

    /// Add a node; it receives every data frame until its filtering says otherwise.
    pub fn add_node(&mut self) -> NodeId {
        self.nodes.push(Node {
            queue: Vec::new(),
            rx: VecDeque::new(),
            rx_capacity: DEFAULT_RX_CAPACITY,
            rx_dropped: 0,
            filtering: Filtering::default(),
            receive_own: false,
            confinement: Confinement::default(),
            not_before: Timestamp::ZERO,
            recessive_run: 0,
            first_submitted: Timestamp::ZERO,
        });
        self.forget_acceptance();
        self.ready.set(None);
        self.nodes.len() - 1
    }

    /// How many nodes the bus has.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Replace a node's receive filtering.
    pub fn set_filtering(&mut self, node: NodeId, filtering: Filtering) {
        if let Some(n) = self.nodes.get_mut(node) {
            n.filtering = filtering;
        }
        self.forget_acceptance();
    }

    /// How many received frames a node holds before new ones are dropped and counted.
    pub fn set_rx_capacity(&mut self, node: NodeId, capacity: usize) {
        if let Some(n) = self.nodes.get_mut(node) {
            n.rx_capacity = capacity.max(1);
        }
    }

    /// Frames a node dropped because its receive queue was full.
    pub fn rx_dropped(&self, node: NodeId) -> u64 {
        self.nodes.get(node).map_or(0, |n| n.rx_dropped)
    }

    /// Whether a node receives its own frames.
    pub fn set_receive_own(&mut self, node: NodeId, on: bool) {
        if let Some(n) = self.nodes.get_mut(node) {
            n.receive_own = on;
        }
    }

    /// Hand a frame to a node's controller at `at` (not before the current simulated time).
    /// Error frames are controller reports, not frames to send: they are ignored.
    pub fn submit(&mut self, node: NodeId, frame: Frame, at: Timestamp) {
        let Some(id) = frame.id() else {
            return;
        };
        let at = at.max(self.now);
        let tamper = self
            .tampered
            .iter()
            .find(|(t, _)| *t == id)
            .map(|(_, tamper)| *tamper);
        let (frame, at, copies) = match tamper {
            None => (frame, at, 1),
            Some(Tamper::FlipBit) => (flipped(frame), at, 1),
            Some(Tamper::Duplicate) => (frame, at, 2),
            Some(Tamper::Delay(delay)) => (frame, at.saturating_add(delay), 1),
            Some(Tamper::Drop) => return,
        };
        // A tampered identifier is the one that goes out.
        let (Some(id), Some(n)) = (frame.id(), self.nodes.get_mut(node)) else {
            return;
        };
        if n.queue.is_empty() {
            if let Err(at) = self.queued.binary_search(&node) {
                self.queued.insert(at, node);
            }
            n.first_submitted = at;
        }
        n.first_submitted = n.first_submitted.min(at);
        let priority = id.arbitration_key();
        for _ in 0..copies {
            // After every frame of the same or higher priority: those were submitted earlier.
            let place = n.queue.partition_point(|p| p.priority <= priority);
            n.queue.insert(
                place,
                Pending {
                    frame,
                    id,
                    priority,
                    submitted: at,
                    seq: self.next_seq,
                },
            );
            self.next_seq += 1;
        }
        // The earliest start moves to this frame's if it is earlier (and its node takes
        // part): nodes submit far more often than frames start, so it is not looked for again.
        let ready = match self.ready.get() {
            Some(_) if n.confinement.state() == NodeState::BusOff => self.ready.get(),
            Some(ready) => Some(earliest([ready, Some(at.max(n.not_before))])),
            None => None,
        };
        self.ready.set(ready);
    }

    /// A faulty sender for frames with identifier `id`, from whichever node (`None`: mend it):
    /// what leaves the node is not what it meant to send — unlike [`SimBus::corrupt`], the
    /// frames are well formed on the wire.
    pub fn tamper(&mut self, id: Id, tamper: Option<Tamper>) {
        self.tampered.retain(|(t, _)| *t != id);
        if let Some(tamper) = tamper {
            self.tampered.push((id, tamper));
        }
    }

    /// Empty a node's transmit and receive queues (the node leaves the bus).
    pub fn withdraw(&mut self, node: NodeId) {
        if let Some(n) = self.nodes.get_mut(node) {
            n.queue.clear();
            n.rx.clear();
        }
        self.queued.retain(|q| *q != node);
        if self.is_routed(node) {
            let bit = 1u64 << node;
            self.routed_rx.iter_mut().for_each(|r| r.to &= !bit);
            self.routed_rx.retain(|r| r.to != 0);
        }
        self.ready.set(None);
    }

    /// Destroy the next matching transmissions.
    pub fn corrupt(&mut self, fault: Fault) {
        self.faults.push((fault, false));
    }

    /// Destroy every matching transmission until its sender is bus-off (a broken transceiver,
    /// a shorted stub): however many frames of its own succeed in between, it gets there, and
    /// after its recovery it sends again unharmed.
    pub fn take_off_bus(&mut self, node: Option<NodeId>, id: Option<Id>) {
        let fault = Fault {
            node,
            id,
            count: u32::MAX,
            kind: Corruption::Crc,
        };
        self.faults.push((fault, true));
    }

    /// The next frame a node received.
    pub fn receive(&mut self, node: NodeId) -> Option<Received> {
        self.nodes.get_mut(node).and_then(|n| n.rx.pop_front())
    }

    /// The next frame a node received by `at` (a frame whose transmission the simulation has
    /// already decided may end later than the caller's present).
    pub fn receive_by(&mut self, node: NodeId, at: Timestamp) -> Option<Received> {
        let n = self.nodes.get_mut(node)?;
        if n.rx.front()?.timestamp > at {
            return None;
        }
        n.rx.pop_front()
    }

    /// When something next happens that a runner must [`advance`](Self::advance) to: the next
    /// frame a node receives, the start of the next transmission, or a bus-off recovery.
    pub fn next_change(&self, node: NodeId) -> Option<Timestamp> {
        let delivery = self
            .nodes
            .get(node)
            .and_then(|n| n.rx.front())
            .map(|r| r.timestamp);
        let delivery = if self.is_routed(node) {
            self.next_routed_arrival()
        } else {
            delivery
        };
        earliest([delivery, self.next_activity()])
    }

    /// [`next_change`](Self::next_change) for several nodes at once: the earliest frame any
    /// of `nodes` receives, the next transmission's start, or a bus-off recovery.
    pub fn next_change_of(&self, nodes: &[NodeId]) -> Option<Timestamp> {
        let delivery = nodes
            .iter()
            .filter_map(|node| self.nodes.get(*node).and_then(|n| n.rx.front()))
            .map(|r| r.timestamp)
            .min();
        let delivery = earliest([delivery, self.next_routed_arrival()]);
        earliest([delivery, self.next_activity()])
    }

    /// The earliest start of a transmission with the frames queued now.
    fn next_start(&self) -> Option<Timestamp> {
        let ready = self.ready.get().unwrap_or_else(|| {
            let ready = self
                .queued
                .iter()
                .filter_map(|node| self.nodes.get(*node))
                .filter(|n| n.confinement.state() != NodeState::BusOff)
                .map(|n| n.first_submitted.max(n.not_before))
                .min();
            self.ready.set(Some(ready));
            ready
        });
        ready.map(|ready| ready.max(self.idle_from))
    }

    /// The earliest moment a bus-off node completes its 128th recovery sequence, counting idle
    /// bits from `from`.
    fn next_recovery(&self, from: Timestamp) -> Option<Timestamp> {
        if !self.any_bus_off() {
            return None;
        }
        let bit = self.bits(1).max(1);
        self.nodes
            .iter()
            .filter(|n| n.confinement.state() == NodeState::BusOff)
            .map(|n| {
                let remaining = u64::from(128u16.saturating_sub(n.confinement.recovery_progress()));
                let bits = (remaining * RECOVERY_BITS).saturating_sub(n.recessive_run);
                from.saturating_add(std::time::Duration::from_nanos(bits.saturating_mul(bit)))
            })
            .min()
    }

    fn forget_acceptance(&mut self) {
        self.acceptance.iter_mut().for_each(|slot| *slot = None);
    }

    /// The nodes whose filters take `frame`, one bit each (`None` past 64 nodes: ask each).
    fn accepting(&mut self, frame: &Frame) -> Option<u64> {
        if self.nodes.len() > 64 {
            return None;
        }
        let can_id = frame.socketcan_id();
        let mixed = u64::from(can_id).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        let slot = usize::try_from(mixed >> (64 - ACCEPTANCE_CACHE.trailing_zeros())).ok()?;
        if let Some(Some((cached, nodes))) = self.acceptance.get(slot) {
            if *cached == can_id {
                return Some(*nodes);
            }
        }
        let nodes = self
            .nodes
            .iter()
            .enumerate()
            .filter(|(_, n)| n.filtering.accepts(frame))
            .fold(0u64, |set, (i, _)| set | 1 << i);
        if let Some(entry) = self.acceptance.get_mut(slot) {
            *entry = Some((can_id, nodes));
        }
        Some(nodes)
    }

    fn any_bus_off(&self) -> bool {
        self.bus_off_nodes > 0
    }

    /// A node's fault-confinement state and counters.
    pub fn confinement(&self, node: NodeId) -> Option<Confinement> {
        self.nodes.get(node).map(|n| n.confinement)
    }

    /// Whether arbitration losses are reported ([`BusEvent::ArbitrationLost`]; on by
    /// default): a busy bus has several for most frames, and a reader that does not look at
    /// them need not have them made.
    pub fn report_arbitration(&mut self, report: bool) {
        self.report_arbitration = report;
    }

    /// Events since the last call.
    pub fn take_events(&mut self) -> Vec<BusEvent> {
        std::mem::take(&mut self.events)
    }

    /// The same, keeping the buffer for the events to come (no allocation once it has grown).
    pub fn drain_events(&mut self) -> std::vec::Drain<'_, BusEvent> {
        self.events.drain(..)
    }

    /// Simulated time so far.
    pub fn now(&self) -> Timestamp {
        self.now
    }

    /// Time the bus spent carrying frames and error frames, each with the intermission after
    /// it, in nanoseconds.
    pub fn busy_ns(&self) -> u64 {
        self.busy_ns
    }

    fn bits(&self, n: u64) -> u64 {
        bits_ns(self.nominal, n)
    }

    fn set_state(&mut self, node: NodeId, event: Event, at: Timestamp) {
        self.ready.set(None);
        let routed = self.is_routed(node);
        let Some(n) = self.nodes.get_mut(node) else {
            return;
        };
        if let Some(change) = n.confinement.on_event(event) {
            if change.to == NodeState::BusOff {
                n.recessive_run = 0;
            }
            let report = Frame::Error(state_report(change, &n.confinement));
            if n.filtering.accepts(&report) {
                let received = Received {
                    frame: report,
                    timestamp: at,
                    own: false,
                    local: true,
                    hardware: None,
                };
                if routed {
                    self.routed_rx.push_back(Routed {
                        received,
                        to: 1 << node,
                        sender: None,
                    });
                } else {
                    n.deliver(received);
                }
            }
            self.events.push(BusEvent::StateChanged {
                node,
                state: change.to,
                at,
            });
        }
        self.count_states();
    }

    /// Counters and states change only in `set_state`: what every frame and gap asks of all the
    /// nodes is counted there again (rarely: a healthy bus has nothing to count down).
    fn count_states(&mut self) {
        let (mut off, mut counting) = (0, 0);
        for n in &self.nodes {
            off += usize::from(n.confinement.state() == NodeState::BusOff);
            counting += usize::from(!unchanged_by(&n.confinement, Event::ReceiveSuccess));
        }
        self.bus_off_nodes = off;
        self.counting_receivers = counting;
    }

    /// Apply `event` to every node on the bus except the sender.
    fn tell_receivers(&mut self, sender: NodeId, event: Event, at: Timestamp) {
        if event == Event::ReceiveSuccess && self.counting_receivers == 0 {
            return;
        }
        for node in 0..self.nodes.len() {
            let affected = self
                .nodes
                .get(node)
                .is_some_and(|n| !unchanged_by(&n.confinement, event));
            if node != sender && affected {
                self.set_state(node, event, at);
            }
        }
    }

    /// Count idle recessive bits from `from` towards bus-off recovery, up to `to` or to the first
    /// recovery, whichever comes first; returns the time of that recovery.
    fn idle(&mut self, from: Timestamp, to: Timestamp) -> Option<Timestamp> {
        if !self.any_bus_off() {
            return None;
        }
        let bit = self.bits(1).max(1);
        let at_bits = |bits: u64| {
            from.saturating_add(std::time::Duration::from_nanos(bits.saturating_mul(bit)))
        };
        let recovery = self.next_recovery(from).filter(|r| *r <= to);
        let end = recovery.unwrap_or(to);
        let gap_bits = u64::try_from(end.saturating_since(from).as_nanos() / u128::from(bit))
            .unwrap_or(u64::MAX);
        for node in 0..self.nodes.len() {
            let Some(n) = self.nodes.get_mut(node) else {
                continue;
            };
            if n.confinement.state() != NodeState::BusOff {
                continue;
            }
            let before = n.recessive_run;
            let total = before.saturating_add(gap_bits);
            n.recessive_run = total % RECOVERY_BITS;
            // One event per completed sequence, at its own instant; at most 128 matter.
            let complete = (total / RECOVERY_BITS).min(128);
            for k in 1..=complete {
                self.set_state(
                    node,
                    Event::RecessiveSequence,
                    at_bits(k * RECOVERY_BITS - before),
                );
            }
            if let (Some(r), Some(n)) = (recovery, self.nodes.get_mut(node)) {
                if n.confinement.state() != NodeState::BusOff {
                    n.not_before = r;
                    n.recessive_run = 0;
                    self.ready.set(None);
                }
            }
        }
        recovery
    }

    /// A frame's time on this bus (whole ns) and where receivers find a destroyed copy's CRC
    /// wrong (bits from its start); `None` for what has no bits on the wire.
    fn timing(&mut self, frame: &Frame) -> Option<(u64, usize)> {
        // Classic frames are counted (without building their bits) and remembered in a small
        // direct-mapped table; FD frames are encoded once and remembered.
        if let Some(key) = ClassicKey::of(frame) {
            if let Some(Some((cached, timing))) = self.classic_timings.get(key.slot()) {
                if *cached == key {
                    return Some(*timing);
                }
            }
            // A new payload (a setpoint, a reading): counted on from its identifier's header.
            let header_slot = self.classic_headers.get_mut(key.header_slot())?;
            let header = match header_slot {
                Some((id, dlc, header)) if (*id, *dlc) == (key.id, key.dlc) => *header,
                _ => {
                    let header = ClassicHeader::of(frame)?;
                    *header_slot = Some((key.id, key.dlc, header));
                    header
                }
            };
            let (bits, detected) = header.length(frame.data());
            let bits = f64::from(u32::try_from(bits).unwrap_or(u32::MAX));
            let timing = (
                whole_ns(bits * (1e9 / f64::from(self.nominal.max(1)))),
                detected + 1,
            );
            if let Some(slot) = self.classic_timings.get_mut(key.slot()) {
                *slot = Some((key, timing));
            }
            return Some(timing);
        }
        if let Some(timing) = self.timings.get(frame) {
            return Some(*timing);
        }
        let bits = wire::encode(frame).ok()?;
        let brs = matches!(frame, Frame::Fd(f) if f.brs());
        let time = bits.time_ns(self.nominal, if brs { self.data } else { None });
        // Receivers find the CRC wrong at the CRC delimiter, then the error frame follows.
        let detected = bits
            .spans()
            .iter()
            .find(|s| s.field == Field::CrcDelimiter)
            .map_or(bits.len(), |s| s.start + 1);
        if self.timings.len() >= 4_096 {
            self.timings.clear();
        }
        let timing = (whole_ns(time), detected);
        self.timings.insert(*frame, timing);
        Some(timing)
    }

    /// Run the bus up to `until`.
    pub fn advance(&mut self, until: Timestamp) {
        // Each pass sends or destroys one frame, brings a node back from bus-off, or ends:
        // bounded by the work queued and the nodes.
        loop {
            let start = self.next_start();
            let limit = start.unwrap_or(until).min(until);
            if let Some(recovered) = self.idle(self.idle_from.max(self.now), limit) {
                self.now = recovered;
                continue;
            }
            match start {
                Some(start) if start <= until => self.transmit_at(start),
                _ => {
                    self.now = self.now.max(until);
                    return;
                }
            }
        }
    }

    /// A node's offer at `start`: the first frame in its queue that may start then (its
    /// queue's index), unless the node is off the bus or suspended.
    fn offer(n: &Node, start: Timestamp) -> Option<(usize, &Pending)> {
        if n.confinement.state() == NodeState::BusOff || n.not_before > start {
            return None;
        }
        n.queue
            .iter()
            .enumerate()
            .find(|(_, p)| p.submitted <= start)
    }

    fn transmit_at(&mut self, start: Timestamp) {
        // Every ready node offers its highest-priority frame; the lowest identifier wins, the
        // earlier submitted of two equal ones (submission numbers are unique on a bus).
        let mut best: Option<(u32, u64, NodeId, usize)> = None;
        for &node in &self.queued {
            let Some((index, p)) = self.nodes.get(node).and_then(|n| Self::offer(n, start)) else {
                continue;
            };
            if best.is_none_or(|(priority, seq, ..)| (p.priority, p.seq) < (priority, seq)) {
                best = Some((p.priority, p.seq, node, index));
            }
        }
        let Some((_, _, winner, index)) = best else {
            return;
        };
        if self.report_arbitration {
            for &node in self.queued.iter().filter(|&&node| node != winner) {
                if let Some((_, p)) = self.nodes.get(node).and_then(|n| Self::offer(n, start)) {
                    self.events.push(BusEvent::ArbitrationLost {
                        node,
                        id: p.id,
                        at: start,
                    });
                }
            }
        }
        let Some(pending) = self.nodes.get(winner).and_then(|n| n.queue.get(index)) else {
            return;
        };
        let id = pending.id;
        let (frame, submitted) = (pending.frame, pending.submitted);
        let Some((time, detected)) = self.timing(&frame) else {
            return;
        };
        let fault = self.faults.iter_mut().find(|(f, _)| {
            f.count > 0 && f.node.is_none_or(|n| n == winner) && f.id.is_none_or(|i| i == id)
        });
        let ns = |bus: &SimBus, n: u64| std::time::Duration::from_nanos(bus.bits(n));
        let end;
        if let Some((fault, _)) = fault {
            fault.count -= 1;
            let detected = fault.kind.detected_after(&frame).unwrap_or(detected);
            let error_end =
                start.saturating_add(ns(self, u64::try_from(detected).unwrap_or(0) + ERROR_FRAME));
            end = error_end;
            self.events.push(BusEvent::Destroyed {
                node: winner,
                id,
                start,
                end: error_end,
            });
            self.set_state(
                winner,
                Event::TransmitError(TransmitErrorCause::Other),
                error_end,
            );
            self.tell_receivers(winner, Event::ReceiveError, error_end);
            let off = self
                .nodes
                .get(winner)
                .is_some_and(|n| n.confinement.state() == NodeState::BusOff);
            // Spent faults go; so do those that were to last until this node's bus-off.
            let ended = |f: &Fault, until: bool| {
                f.count == 0
                    || (until
                        && off
                        && f.node.is_none_or(|n| n == winner)
                        && f.id.is_none_or(|i| i == id))
            };
            self.faults.retain(|(f, until)| !ended(f, *until));
        } else {
            let eof = start.saturating_add(std::time::Duration::from_nanos(time));
            end = eof;
            if let Some(n) = self.nodes.get_mut(winner) {
                // The rest stay in arbitration order.
                n.queue.remove(index);
                n.first_submitted = n
                    .queue
                    .iter()
                    .map(|p| p.submitted)
                    .min()
                    .unwrap_or(Timestamp::ZERO);
                if n.queue.is_empty() {
                    self.queued.retain(|q| *q != winner);
                }
            }
            self.events.push(BusEvent::Transmitted {
                node: winner,
                id,
                start,
                end: eof,
                latency_ns: u64::try_from(eof.saturating_since(submitted).as_nanos())
                    .unwrap_or(u64::MAX),
            });
            let received = Received {
                frame,
                timestamp: eof,
                own: false,
                local: true,
                hardware: None,
            };
            let mut routed_to = 0u64;
            match self.accepting(&frame) {
                // The nodes whose filters take it and the sender, one bit each.
                Some(accepting) => {
                    let mut candidates = accepting | 1 << winner;
                    while candidates != 0 {
                        let node = candidates.trailing_zeros() as usize;
                        candidates &= candidates - 1;
                        if let Some(n) = self.nodes.get_mut(node) {
                            let accepts = has_node(accepting, node);
                            routed_to |= n.receive(node, winner, accepts, self.routed, received);
                        }
                    }
                }
                None => {
                    for (node, n) in self.nodes.iter_mut().enumerate() {
                        let accepts = n.filtering.accepts(&frame);
                        routed_to |= n.receive(node, winner, accepts, self.routed, received);
                    }
                }
            }
            if routed_to != 0 {
                self.routed_rx.push_back(Routed {
                    received,
                    to: routed_to,
                    sender: Some(winner),
                });
            }
            if self
                .nodes
                .get(winner)
                .is_some_and(|n| !unchanged_by(&n.confinement, Event::TransmitSuccess))
            {
                self.set_state(winner, Event::TransmitSuccess, eof);
            }
            self.tell_receivers(winner, Event::ReceiveSuccess, eof);
        }
        self.idle_from = end.saturating_add(std::time::Duration::from_nanos(self.intermission_ns));
        // The intermission counts as busy: bus load as canbusload and `bywire busload` count it.
        self.busy_ns = self.busy_ns.saturating_add(
            u64::try_from(self.idle_from.saturating_since(start).as_nanos()).unwrap_or(0),
        );
        self.now = self.idle_from;
        let passive = self
            .nodes
            .get(winner)
            .is_some_and(|n| n.confinement.state() == NodeState::ErrorPassive);
        self.ready.set(None);
        let not_before = if passive {
            self.idle_from.saturating_add(ns(self, SUSPEND))
        } else {
            self.idle_from
        };
        if let Some(n) = self.nodes.get_mut(winner) {
            n.not_before = not_before;
        }
    }
}
