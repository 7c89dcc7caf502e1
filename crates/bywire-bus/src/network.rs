//! The simulated runner: named bit-timed buses ([`SimBus`]) with nodes wired to them by port,
//! run in simulated time by the rule in [`bywire_core::node`].
//!
//! A [`Network`] holds the buses and the wiring, not the nodes: each call that runs it takes
//! the nodes as a slice, in the order they were numbered when wired, so the caller keeps its
//! concrete node types to look at between runs. The runner is event-driven: it wakes at the
//! earliest of the nodes' deadlines and the buses' next changes (a delivery, a transmission's
//! start, a bus-off recovery), delivers each frame to the ports whose filters took it at its
//! end of frame, and polls the nodes that are due or received something.
//!
//! Faults are applied at the edges, never inside node code: a node's output dropped
//! ([`Network::drop_output`]), and whatever the buses themselves inject ([`Network::bus_mut`]:
//! tampered identifiers, destroyed frames, bus-off).
//!
//! It lives beside [`SimBus`] so that every crate's tests (CANopen, the vehicle interface) and
//! the simulator run their nodes on the same runner.

use std::time::Duration;

use bywire_core::node::{Node, Port};
use bywire_core::Timestamp;

use crate::sim::{NodeId, SimBus, MAX_ROUTED};
use crate::Filtering;

/// A node's index in the slice given to [`Network::run_until`].
pub type NodeIndex = usize;

/// A bus's index in the network.
pub type BusIndex = usize;

/// A node's deadline at or before the time it was last polled counts as this much later, so
/// a node that keeps asking for the past cannot stall simulated time.
const RESOLUTION: Duration = Duration::from_micros(1);

/// A slot's wake time when it has none (no run ends this late: every `until` is at most this).
const NEVER: u64 = u64::MAX;

/// Passes at one instant after which time is moved on by [`RESOLUTION`] (a bus that keeps
/// reporting a change it does not make must not stall the run).
const PASSES_PER_INSTANT: u32 = 64;

#[derive(Clone, Copy)]
struct Wire {
    node: NodeIndex,
    port: Port,
    bus: BusIndex,
    endpoint: NodeId,
}

/// What the runner keeps for one node between its events.
#[derive(Clone, Copy)]
struct Slot {
    /// Its deadline, cached until it is polled or given a frame.
    deadline: Option<Timestamp>,
    /// When it was last polled.
    polled: Option<Timestamp>,
    /// When it must next run, in nanoseconds ([`NEVER`] for no time), worked out from the two
    /// above whenever they change: the runner looks for the earliest of every node's at each
    /// event, a plain minimum over integers.
    wake: u64,
    /// From when it is due, in nanoseconds ([`NEVER`] for never; see [`Slot::due`]), worked
    /// out likewise: every node is asked at every event.
    due_from: u64,
    /// Changed by the caller since the last run (its deadline is asked again).
    changed: bool,
    /// It received something at the current instant.
    received: bool,
    /// Its output is dropped (the node is cut off or powered down).
    dropped: bool,
}

impl Slot {
    const NEW: Slot = Slot {
        deadline: None,
        polled: None,
        wake: 0,
        due_from: 0,
        changed: true,
        received: false,
        dropped: false,
    };

    /// A new deadline, asked of the node.
    fn set_deadline(&mut self, deadline: Option<Timestamp>) {
        self.deadline = deadline;
        self.wake = self.next_wake().map_or(NEVER, Timestamp::as_nanos);
        self.due_from = match (self.polled, deadline) {
            (None, _) => 0,
            (Some(_), None) => NEVER,
            // Any time after the last poll (the deadline has passed by then).
            (Some(last), Some(d)) if d <= last => last.as_nanos().saturating_add(1),
            // The deadline, which is after the last poll.
            (Some(_), Some(d)) => d.as_nanos(),
        };
    }

    /// Polled at `now`, after which the node asked for `deadline`.
    fn set_polled(&mut self, now: Timestamp, deadline: Option<Timestamp>) {
        self.polled = Some(now);
        self.set_deadline(deadline);
    }

    /// When it must next run: at once (time zero, which is never later than the present) if
    /// never polled; a deadline at or before its last poll counts RESOLUTION after that poll,
    /// so a node asking for the past cannot stall time.
    fn next_wake(&self) -> Option<Timestamp> {
        match (self.polled, self.deadline) {
            (None, _) => Some(Timestamp::ZERO),
            (Some(last), Some(d)) if d <= last => Some(last.saturating_add(RESOLUTION)),
            (Some(_), deadline) => deadline,
        }
    }

    /// Whether it is due at `now`: never polled, or polled before `now` with its deadline
    /// reached (one at or before the last poll, too: `wake` moved it on by RESOLUTION).
    fn due(&self, now: Timestamp) -> bool {
        now.as_nanos() >= self.due_from
    }
}

/// One simulated bus and what the runner knows of it.
struct NetBus {
    name: String,
    sim: SimBus,
    /// The wire (an index into the network's wires) of each endpoint, by its number on the
    /// bus (taps have none: their owner reads them).
    wire_of: Vec<Option<usize>>,
    /// When it next changes, cached until it is advanced, given a frame or read.
    next: Option<NextChange>,
}

/// The wire of `node`'s `port` (the first made, should there be several), among `wires` by
/// node.
fn port_wire(wires: &[Wire], wires_of: &[Vec<usize>], node: NodeIndex, port: Port) -> Option<Wire> {
    wires_of
        .get(node)?
        .iter()
        .filter_map(|&w| wires.get(w))
        .find(|w| w.port == port)
        .copied()
}

/// When a bus next changes, in its two kinds, in nanoseconds ([`NEVER`] for no time): the
/// runner takes the least of every bus's at every pass, plain minimums over integers.
#[derive(Clone, Copy)]
struct NextChange {
    /// A frame (or state report) arrives at the wired nodes.
    arrival: u64,
    /// A transmission starts or a node recovers from bus-off.
    activity: u64,
}

/// A time in nanoseconds, [`NEVER`] for none.
fn nanos(at: Option<Timestamp>) -> u64 {
    at.map_or(NEVER, Timestamp::as_nanos)
}

/// Named bit-timed buses and the wiring of nodes to them.
pub struct Network {
    buses: Vec<NetBus>,
    wires: Vec<Wire>,
    /// Each node's wires (indices into `wires`, in the order they were made): where its
    /// frames go, found without a pass over every wire.
    wires_of: Vec<Vec<usize>>,
    /// Single ports whose output is dropped (one of a node's buses cut).
    dropped_ports: Vec<(NodeIndex, Port)>,
    /// Per node.
    slots: Vec<Slot>,
    now: Timestamp,
    /// The earliest wake and the earliest due time of the first `nodes` nodes, kept until a
    /// node's deadline changes (the runner looks for them at every pass and every instant;
    /// they change only when a node was asked).
    earliest_wake: Option<Earliest>,
    /// The nodes given a frame at the current instant, each once: most instants are a
    /// frame's arrival with no node due, and only these are polled then.
    receivers: Vec<NodeIndex>,
}

/// The soonest any of the first `nodes` nodes must run ([`Slot::wake`]) and is due
/// ([`Slot::due_from`]), in nanoseconds ([`NEVER`] for never).
#[derive(Clone, Copy)]
struct Earliest {
    nodes: usize,
    wake: u64,
    due_from: u64,
}

impl Default for Network {
    fn default() -> Self {
        Network::new()
    }
}

impl Network {
    /// A network with no buses, at time zero.
    pub fn new() -> Network {
        Network {
            buses: Vec::new(),
            wires: Vec::new(),
            wires_of: Vec::new(),
            dropped_ports: Vec::new(),
            slots: Vec::new(),
            now: Timestamp::ZERO,
            earliest_wake: None,
            receivers: Vec::new(),
        }
    }

    /// Add a bus at `nominal` bit/s (FD data phases at `data` bit/s when given).
    pub fn add_bus(&mut self, name: &str, nominal: u32, data: Option<u32>) -> BusIndex {
        self.buses.push(NetBus {
            name: name.to_string(),
            sim: SimBus::new(nominal, data),
            wire_of: Vec::new(),
            next: None,
        });
        self.buses.len() - 1
    }

    /// A bus by name.
    pub fn bus_index(&self, name: &str) -> Option<BusIndex> {
        self.buses.iter().position(|b| b.name == name)
    }

    /// Wire `node`'s `port` to `bus`; the endpoint's number on that bus is returned (for the
    /// bus's events and faults). `None` for a bus that does not exist or already has
    /// [`MAX_ROUTED`] endpoints (taps included).
    pub fn wire(&mut self, node: NodeIndex, port: Port, bus: BusIndex) -> Option<NodeId> {
        let net_bus = self.buses.get_mut(bus)?;
        if net_bus.sim.node_count() >= MAX_ROUTED {
            return None;
        }
        let endpoint = net_bus.sim.add_node();
        // A node's own frames come back as its transmit confirmations; every frame a wired
        // node takes arrives once for all of them (the runner hands it to each).
        net_bus.sim.set_receive_own(endpoint, true);
        net_bus.sim.route(endpoint);
        net_bus.next = None;
        net_bus.wire_of.resize(endpoint, None);
        net_bus.wire_of.push(Some(self.wires.len()));
        if self.wires_of.len() <= node {
            self.wires_of.resize_with(node.saturating_add(1), Vec::new);
        }
        if let Some(wires) = self.wires_of.get_mut(node) {
            wires.push(self.wires.len());
        }
        self.wires.push(Wire {
            node,
            port,
            bus,
            endpoint,
        });
        self.size_for(node.saturating_add(1));
        Some(endpoint)
    }

    fn size_for(&mut self, nodes: usize) {
        if self.slots.len() < nodes {
            self.slots.resize(nodes, Slot::NEW);
            self.earliest_wake = None;
        }
    }

    /// A listener on `bus` that no node drives (a logger, a tap, an outside tool): read it and
    /// send from it with [`Network::bus_mut`].
    pub fn tap(&mut self, bus: BusIndex) -> Option<NodeId> {
        self.forget_bus(bus);
        self.buses.get_mut(bus).map(|b| b.sim.add_node())
    }

    /// Set what a port receives.
    pub fn set_filtering(&mut self, node: NodeIndex, port: Port, filtering: Filtering) {
        if let Some(w) = port_wire(&self.wires, &self.wires_of, node, port) {
            if let Some(b) = self.buses.get_mut(w.bus) {
                b.sim.set_filtering(w.endpoint, filtering);
            }
        }
    }

    /// Drop (or again let through) everything `node` sends: a node cut off the bus.
    pub fn drop_output(&mut self, node: NodeIndex, dropped: bool) {
        self.size_for(node.saturating_add(1));
        if let Some(slot) = self.slots.get_mut(node) {
            slot.dropped = dropped;
        }
    }

    /// Drop (or again let through) what `node` sends on `port` only: that one connection cut.
    pub fn drop_port_output(&mut self, node: NodeIndex, port: Port, dropped: bool) {
        self.dropped_ports.retain(|p| *p != (node, port));
        if dropped {
            self.dropped_ports.push((node, port));
        }
    }

    /// A bus, to inject faults into, send from a tap or read one.
    pub fn bus_mut(&mut self, bus: BusIndex) -> Option<&mut SimBus> {
        self.forget_bus(bus);
        self.buses.get_mut(bus).map(|b| &mut b.sim)
    }

    /// A bus, to read its events and counts.
    pub fn bus(&self, bus: BusIndex) -> Option<&SimBus> {
        self.buses.get(bus).map(|b| &b.sim)
    }

    /// Simulated time so far.
    pub fn now(&self) -> Timestamp {
        self.now
    }

    fn forget_bus(&mut self, bus: BusIndex) {
        if let Some(b) = self.buses.get_mut(bus) {
            b.next = None;
        }
    }

    /// Say that the caller changed `node` between runs in a way that may move its deadline
    /// (a new command, an operator's action): the next run asks it again. Nodes are otherwise
    /// asked only after they were polled or given a frame.
    pub fn changed(&mut self, node: NodeIndex) {
        if let Some(slot) = self.slots.get_mut(node) {
            slot.changed = true;
        }
    }

    /// Run everything that happens before `until`, driving `nodes` (indexed as wired). What
    /// falls at `until` itself happens in the next run, after whatever the caller changes at
    /// that time (a new command, a cut-off node — see [`Network::changed`]).
    pub fn run_until(&mut self, until: Timestamp, nodes: &mut [&mut dyn Node]) {
        self.size_for(nodes.len());
        for (slot, node) in self.slots.iter_mut().zip(nodes.iter()) {
            if slot.changed {
                slot.set_deadline(node.next_deadline());
                slot.changed = false;
                self.earliest_wake = None;
            }
        }
        // Each pass moves time forward to the next event (or ends at `until`): bounded by the
        // events between now and `until`, and by PASSES_PER_INSTANT at any one time.
        let mut passes_here = 0u32;
        loop {
            let next = self.start_ahead(nodes.len(), until).map(|at| {
                if at > self.now {
                    passes_here = 0;
                    at
                } else if passes_here >= PASSES_PER_INSTANT {
                    passes_here = 0;
                    self.now.saturating_add(RESOLUTION)
                } else {
                    passes_here += 1;
                    self.now
                }
            });
            let Some(at) = next.filter(|at| *at < until) else {
                for b in &mut self.buses {
                    b.sim.advance(until);
                    b.next = None;
                }
                self.now = self.now.max(until);
                return;
            };
            self.now = at;
            self.instant(nodes);
        }
    }

    /// Run the network for `duration` more.
    pub fn run_for(&mut self, duration: Duration, nodes: &mut [&mut dyn Node]) {
        let until = self.now.saturating_add(duration);
        self.run_until(until, nodes);
    }

    /// Node `i`'s wake and due time moved from `before` to `after`: the earliest of all
    /// follows without a pass over every node, unless `i` held one of them and it moved later.
    fn moved(&mut self, i: NodeIndex, before: (u64, u64), after: (u64, u64)) {
        let Some(e) = self.earliest_wake.as_mut().filter(|e| i < e.nodes) else {
            return;
        };
        let held = (before.0 == e.wake && after.0 > e.wake)
            || (before.1 == e.due_from && after.1 > e.due_from);
        if held {
            self.earliest_wake = None;
        } else {
            e.wake = e.wake.min(after.0);
            e.due_from = e.due_from.min(after.1);
        }
    }

    /// The earliest wake and due time of the nodes (kept until one changes).
    fn earliest(&mut self, nodes: usize) -> Earliest {
        if let Some(earliest) = self.earliest_wake.filter(|e| e.nodes == nodes) {
            return earliest;
        }
        let (wake, due_from) = self
            .slots
            .iter()
            .take(nodes)
            .fold((NEVER, NEVER), |(wake, due), s| {
                (wake.min(s.wake), due.min(s.due_from))
            });
        let earliest = Earliest {
            nodes,
            wake,
            due_from,
        };
        self.earliest_wake = Some(earliest);
        earliest
    }

    /// Advance each bus whose next activity (a transmission's start, a recovery) comes no
    /// later than anything else — a node's deadline, a frame's arrival — and before `until`:
    /// nothing is polled or delivered before it, so the bus gets there exactly as it would in
    /// an instant of its own, which would cost a pass over every node and bus. Its frame then
    /// arrives at its end of frame, an event like any other. Returns the earliest time
    /// something happens then: a node's deadline or a bus's next change.
    fn start_ahead(&mut self, nodes: usize, until: Timestamp) -> Option<Timestamp> {
        let until = until.as_nanos();
        let mut others = self.earliest(nodes).wake;
        for b in &mut self.buses {
            others = others.min(b.next_change().arrival);
        }
        // A bus advanced only moves its own changes, and its arrivals come no later than
        // before: the earliest event is gathered bus by bus as each is settled.
        let mut next = others;
        for b in &mut self.buses {
            let mut change = b.next_change();
            if change.activity < until && change.activity <= others {
                b.sim.advance(Timestamp::from_nanos(change.activity));
                b.next = None;
                change = b.next_change();
                others = others.min(change.arrival);
            }
            next = next.min(change.arrival).min(change.activity);
        }
        (next != NEVER).then(|| Timestamp::from_nanos(next))
    }

    /// Everything that happens at `self.now`: buses advanced, frames delivered (bus by bus, in
    /// the order the buses were added; on each, frame by frame, each to its wires in the order
    /// they were made: a node sees its frames of one bus in the order they arrived), the
    /// nodes that are due or received something polled, and their frames submitted (which end
    /// later: a frame takes time on the wire, so nothing more arrives at this instant).
    fn instant(&mut self, nodes: &mut [&mut dyn Node]) {
        let now = self.now;
        for b in &mut self.buses {
            // A bus with nothing to do before now is left where it is (and, having nothing
            // due, delivers nothing now).
            let change = b.next_change();
            if change.arrival.min(change.activity) > now.as_nanos() {
                continue;
            }
            b.sim.advance(now);
            b.next = None;
            // Frames in the order they arrived, each to its wires in the order they were made.
            // Each frame handed over where it lies (a frame and its addressing are a few
            // cache lines), then passed.
            while let Some(routed) = b.sim.peek_routed(now) {
                let mut to = routed.to;
                while to != 0 {
                    let endpoint = to.trailing_zeros() as usize;
                    to &= to - 1;
                    let wire = b.wire_of.get(endpoint).copied().flatten();
                    let Some(w) = wire.and_then(|i| self.wires.get(i)) else {
                        continue;
                    };
                    let (Some(node), Some(slot)) =
                        (nodes.get_mut(w.node), self.slots.get_mut(w.node))
                    else {
                        continue;
                    };
                    let r = &routed.received;
                    if routed.sender == Some(endpoint) {
                        // A confirmation may move the node's deadline (its next frame may be
                        // due now); it is polled when that comes, not for the confirmation.
                        if node.on_sent(r.timestamp, w.port, &r.frame) {
                            slot.set_deadline(node.next_deadline());
                            // (Rare: only nodes that time something by its confirmation.)
                            self.earliest_wake = None;
                        }
                    } else {
                        node.on_frame(r.timestamp, w.port, &r.frame);
                        if !slot.received {
                            slot.received = true;
                            self.receivers.push(w.node);
                        }
                    }
                }
                b.sim.pass_routed();
            }
        }
        // The nodes due or given a frame, in node order. Polling one changes no other's
        // deadline, so who is due is settled before the first poll.
        let mut receivers = std::mem::take(&mut self.receivers);
        if self.earliest(nodes.len()).due_from <= now.as_nanos() {
            for i in 0..nodes.len() {
                if self.slots.get(i).is_some_and(|s| s.due(now) || s.received) {
                    self.poll(i, nodes);
                }
            }
        } else {
            receivers.sort_unstable();
            for &i in &receivers {
                self.poll(i, nodes);
            }
        }
        for &i in &receivers {
            if let Some(slot) = self.slots.get_mut(i) {
                slot.received = false;
            }
        }
        receivers.clear();
        self.receivers = receivers;
    }

    /// Poll node `i` at `self.now` and submit what it sends.
    fn poll(&mut self, i: NodeIndex, nodes: &mut [&mut dyn Node]) {
        let now = self.now;
        let (Some(node), Some(slot)) = (nodes.get_mut(i), self.slots.get_mut(i)) else {
            return;
        };
        // What it sends goes to its buses as it is sent (they take it at `now`, whatever
        // else the node does in this poll), unless its output is dropped.
        let dropped = slot.dropped;
        let (wires, wires_of, buses) = (&self.wires, &self.wires_of, &mut self.buses);
        let dropped_ports = &self.dropped_ports;
        node.poll(now, &mut |port, frame| {
            if dropped || dropped_ports.contains(&(i, port)) {
                return;
            }
            let wire = port_wire(wires, wires_of, i, port);
            if let Some((w, b)) = wire.and_then(|w| buses.get_mut(w.bus).map(|b| (w, b))) {
                b.sim.submit(w.endpoint, frame, now);
                b.next = None;
            }
        });
        let before = (slot.wake, slot.due_from);
        slot.set_polled(now, node.next_deadline());
        let after = (slot.wake, slot.due_from);
        self.moved(i, before, after);
    }
}

impl NetBus {
    /// When it next changes (cached).
    fn next_change(&mut self) -> NextChange {
        if let Some(cached) = self.next {
            return cached;
        }
        let next = NextChange {
            arrival: nanos(self.sim.next_routed_arrival()),
            activity: nanos(self.sim.next_activity()),
        };
        self.next = Some(next);
        next
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]

    use super::*;
    use bywire_core::Frame;
    use bywire_core::Id;

    /// Sends one frame every 10 ms on its main port, counts what it hears.
    struct Ticker {
        id: u32,
        port: Port,
        next: Timestamp,
        heard: Vec<(Timestamp, Port, u32)>,
    }

    impl Node for Ticker {
        fn on_frame(&mut self, now: Timestamp, port: Port, frame: &Frame) {
            self.heard
                .push((now, port, frame.id().map_or(0, |id| id.as_raw())));
        }
        fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
            if now >= self.next {
                self.next = self.next.saturating_add(Duration::from_millis(10));
                let frame = Frame::classic(Id::standard(self.id).unwrap(), &[0; 8]).unwrap();
                out(self.port, frame);
            }
        }
        fn next_deadline(&self) -> Option<Timestamp> {
            Some(self.next)
        }
    }

    fn ticker(id: u32) -> Ticker {
        Ticker {
            id,
            port: Port::MAIN,
            next: Timestamp::ZERO,
            heard: Vec::new(),
        }
    }

    #[test]
    fn frames_arrive_at_their_end_of_frame_on_the_wired_port() {
        let mut net = Network::new();
        let bus = net.add_bus("bus1", 500_000, None);
        net.wire(0, Port::MAIN, bus).unwrap();
        net.wire(1, Port(3), bus).unwrap();
        let (mut a, mut b) = (ticker(0x100), ticker(0x200));
        b.port = Port(3);
        net.run_until(Timestamp::from_millis(35), &mut [&mut a, &mut b]);
        // Four frames each (0, 10, 20, 30 ms); each hears the other's, on its own port.
        assert_eq!(a.heard.len(), 4);
        assert_eq!(b.heard.len(), 4);
        assert!(b
            .heard
            .iter()
            .all(|(_, port, id)| *port == Port(3) && *id == 0x100));
        // Both submitted at 0: 0x100 wins arbitration, 0x200 follows it. A classic 8-byte
        // frame at 500 kbit/s takes 222–270 µs with stuffing, 3 bits of intermission between.
        let first_b = b.heard[0].0.as_nanos();
        let first_a = a.heard[0].0.as_nanos();
        assert!((200_000..300_000).contains(&first_b), "{first_b}");
        assert!(first_a > first_b + 200_000, "{first_a} after {first_b}");
        assert_eq!(net.now(), Timestamp::from_millis(35));
    }

    #[test]
    fn a_node_whose_output_is_dropped_is_not_heard() {
        let mut net = Network::new();
        let bus = net.add_bus("bus1", 500_000, None);
        net.wire(0, Port::MAIN, bus).unwrap();
        net.wire(1, Port::MAIN, bus).unwrap();
        net.drop_output(1, true);
        let (mut a, mut b) = (ticker(0x100), ticker(0x200));
        net.run_until(Timestamp::from_millis(50), &mut [&mut a, &mut b]);
        assert!(a.heard.is_empty());
        assert_eq!(b.heard.len(), 5);
    }

    /// Sends its next frame a gap after the last one's confirmation (as ISO-TP's STmin
    /// does), saying so from `on_sent` when `retimes`; counts the deadlines asked of it.
    struct Paced {
        retimes: bool,
        gap: Duration,
        next: Option<Timestamp>,
        sent_at: Vec<Timestamp>,
        asked: std::cell::Cell<u32>,
    }

    impl Node for Paced {
        fn on_frame(&mut self, _now: Timestamp, _port: Port, _frame: &Frame) {}
        fn on_sent(&mut self, now: Timestamp, _port: Port, _frame: &Frame) -> bool {
            self.sent_at.push(now);
            self.next = Some(now.saturating_add(self.gap));
            self.retimes
        }
        fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
            if self.next.is_some_and(|next| now >= next) {
                self.next = None;
                out(
                    Port::MAIN,
                    Frame::classic(Id::standard(0x10).unwrap(), &[0; 8]).unwrap(),
                );
            }
        }
        fn next_deadline(&self) -> Option<Timestamp> {
            self.asked.set(self.asked.get() + 1);
            self.next
        }
    }

    fn paced(retimes: bool) -> Paced {
        Paced {
            retimes,
            gap: Duration::from_millis(2),
            next: Some(Timestamp::ZERO),
            sent_at: Vec::new(),
            asked: std::cell::Cell::new(0),
        }
    }

    #[test]
    fn a_confirmation_retimes_a_node_only_when_it_says_its_deadline_moved() {
        let run = |node: &mut Paced| {
            let mut net = Network::new();
            let bus = net.add_bus("bus1", 500_000, None);
            net.wire(0, Port::MAIN, bus).unwrap();
            net.run_until(Timestamp::from_millis(20), &mut [node]);
        };
        // Said: each frame goes the gap after the last one's confirmation.
        let mut retimed = paced(true);
        run(&mut retimed);
        assert!(retimed.sent_at.len() >= 7, "{:?}", retimed.sent_at);
        for pair in retimed.sent_at.windows(2) {
            let between = pair[1].saturating_since(pair[0]);
            // The gap, then the frame's own time on the wire (under 300 µs).
            assert!(between > Duration::from_millis(2), "{between:?}");
            assert!(between < Duration::from_micros(2_300), "{between:?}");
        }
        // Not said: the runner does not ask; the node waits for a frame that never comes.
        let mut silent = paced(false);
        run(&mut silent);
        assert_eq!(silent.sent_at.len(), 1, "{:?}", silent.sent_at);
        assert!(silent.asked.get() < retimed.asked.get());
    }
}
