//! The simulated runner: named bit-timed buses ([`SimBus`]) and the nodes wired to them by
//! port, run in simulated time by the rule in [`bywire_core::node`].
//!
//! A [`Network`] owns its nodes: [`Network::add_node`] gives a typed [`NodeHandle`], through
//! which the caller wires the node ([`Network::wire`]) and looks at it between runs
//! ([`Network::node`], or [`Network::node_mut`], whose guard tells the runner that the node's
//! deadline may have moved when it is dropped). The runner is event-driven: it wakes at the
//! earliest of the nodes' deadlines and the buses' next changes (a delivery, a transmission's
//! start, a bus-off recovery), delivers each frame to the ports whose filters took it at its
//! end of frame, and polls the nodes that are due or received something.
//!
//! Faults are applied at the edges, never inside node code: a node's output dropped
//! ([`Network::drop_output`]), and whatever the buses themselves inject ([`Network::bus_mut`]:
//! tampered identifiers, destroyed frames, bus-off).
//!
//! ```
//! use bywire_core::node::{Node, Port};
//! use bywire_core::{Frame, Timestamp};
//! use bywire_net::network::Network;
//!
//! /// Sends one frame at start-up, counts what it hears.
//! #[derive(Default)]
//! struct Greeter { sent: bool, heard: usize }
//! impl Node for Greeter {
//!     fn on_frame(&mut self, _: Timestamp, _: Port, _: &Frame) { self.heard += 1; }
//!     fn poll(&mut self, _: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
//!         if !self.sent {
//!             self.sent = true;
//!             out(Port::MAIN, "123#CAFE".parse().unwrap());
//!         }
//!     }
//!     fn next_deadline(&self) -> Option<Timestamp> { None }
//! }
//!
//! let mut net = Network::new();
//! let bus = net.add_bus("can0", 500_000, None);
//! let (a, b) = (net.add_node(Greeter::default()), net.add_node(Greeter::default()));
//! net.wire(a, Port::MAIN, bus).unwrap();
//! net.wire(b, Port::MAIN, bus).unwrap();
//! net.run_until(Timestamp::from_millis(1));
//! // Each heard the other's frame, not its own.
//! assert_eq!(net.node(a).unwrap().heard, 1);
//! assert_eq!(net.node(b).unwrap().heard, 1);
//! ```

use std::any::Any;
use std::marker::PhantomData;
use std::ops::{Deref, DerefMut};
use std::time::Duration;

use bywire_core::node::{Node, Port};
use bywire_core::Timestamp;

use crate::sim::{NodeId, SimBus, MAX_ROUTED};
use crate::Filtering;

/// A node's place in a network, whatever its type (for lists of nodes of several types).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct NodeKey(usize);

/// A node added to a network, with its type: what [`Network::node`] and
/// [`Network::node_mut`] give back is that node, without a cast at the call site.
pub struct NodeHandle<N> {
    key: NodeKey,
    node: PhantomData<fn() -> N>,
}

impl<N> NodeHandle<N> {
    /// Its place, whatever its type.
    pub fn key(self) -> NodeKey {
        self.key
    }
}

// By hand: derived, they would ask the node type for the same traits.
impl<N> Clone for NodeHandle<N> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<N> Copy for NodeHandle<N> {}
impl<N> PartialEq for NodeHandle<N> {
    fn eq(&self, other: &Self) -> bool {
        self.key == other.key
    }
}
impl<N> Eq for NodeHandle<N> {}
impl<N> std::fmt::Debug for NodeHandle<N> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "NodeHandle({})", self.key.0)
    }
}

impl<N> From<NodeHandle<N>> for NodeKey {
    fn from(handle: NodeHandle<N>) -> NodeKey {
        handle.key
    }
}

/// A node the network owns: a [`Node`] it can hand back as its own type (seen as `dyn Any`
/// by trait upcasting: one virtual call, the type's, per lookup).
trait Owned: Node + Any {}

impl<N: Node + Any> Owned for N {}

/// A node borrowed from its network to be changed: when the guard is dropped, the runner
/// asks the node's deadline again at its next run (a new command, an operator's action may
/// have moved it). Dereferences to the node.
pub struct NodeMut<'a, N> {
    node: &'a mut N,
    changed: &'a mut bool,
    any_changed: &'a mut bool,
}

impl<N> Deref for NodeMut<'_, N> {
    type Target = N;
    fn deref(&self) -> &N {
        self.node
    }
}

impl<N> DerefMut for NodeMut<'_, N> {
    fn deref_mut(&mut self) -> &mut N {
        self.node
    }
}

impl<N> Drop for NodeMut<'_, N> {
    fn drop(&mut self) {
        *self.changed = true;
        *self.any_changed = true;
    }
}

/// The nodes of one run: the network's own, one of which may have another node standing in
/// its place (see [`Network::run_until_standing_in`]).
struct RunNodes<'a, 'b> {
    owned: &'a mut [Box<dyn Owned>],
    stand_in: Option<(usize, &'b mut dyn Node)>,
}

impl RunNodes<'_, '_> {
    fn len(&self) -> usize {
        self.owned.len()
    }

    fn get_mut(&mut self, i: usize) -> Option<&mut dyn Node> {
        match &mut self.stand_in {
            Some((at, node)) if *at == i => Some(&mut **node),
            _ => self
                .owned
                .get_mut(i)
                .map(|node| &mut **node as &mut dyn Node),
        }
    }
}

/// A node's index among the network's nodes (inside the runner).
type NodeIndex = usize;

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

/// Named bit-timed buses, the nodes on them and their wiring.
pub struct Network {
    buses: Vec<NetBus>,
    /// The nodes, in the order they were added (their [`NodeKey`]s).
    nodes: Vec<Box<dyn Owned>>,
    wires: Vec<Wire>,
    /// Each node's wires (indices into `wires`, in the order they were made): where its
    /// frames go, found without a pass over every wire.
    wires_of: Vec<Vec<usize>>,
    /// Single ports whose output is dropped (one of a node's buses cut).
    dropped_ports: Vec<(NodeIndex, Port)>,
    /// Per node, in the nodes' order.
    slots: Vec<Slot>,
    /// Some slot is marked changed (most runs have none to ask again).
    any_changed: bool,
    now: Timestamp,
    /// The earliest wake and the earliest due time of the nodes, kept until a node's
    /// deadline changes (the runner looks for them at every pass and every instant;
    /// they change only when a node was asked).
    earliest_wake: Option<Earliest>,
    /// The nodes given a frame at the current instant, each once: most instants are a
    /// frame's arrival with no node due, and only these are polled then.
    receivers: Vec<NodeIndex>,
}

/// The soonest any node must run ([`Slot::wake`]) and is due ([`Slot::due_from`]), in
/// nanoseconds ([`NEVER`] for never).
#[derive(Clone, Copy)]
struct Earliest {
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
            nodes: Vec::new(),
            wires: Vec::new(),
            wires_of: Vec::new(),
            dropped_ports: Vec::new(),
            slots: Vec::new(),
            any_changed: false,
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

    /// Add a node; it is polled from the next run on, and hears nothing until it is wired.
    pub fn add_node<N: Node + 'static>(&mut self, node: N) -> NodeHandle<N> {
        self.nodes.push(Box::new(node));
        self.slots.push(Slot::NEW);
        self.any_changed = true;
        self.wires_of.push(Vec::new());
        self.earliest_wake = None;
        NodeHandle {
            key: NodeKey(self.nodes.len() - 1),
            node: PhantomData,
        }
    }

    /// A node, to look at.
    pub fn node<N: Node + 'static>(&self, handle: NodeHandle<N>) -> Option<&N> {
        let node: &dyn Any = &**self.nodes.get(handle.key.0)?;
        node.downcast_ref()
    }

    /// A node, to change: the guard tells the runner to ask its deadline again.
    pub fn node_mut<N: Node + 'static>(&mut self, handle: NodeHandle<N>) -> Option<NodeMut<'_, N>> {
        let i = handle.key.0;
        let node: &mut dyn Any = &mut **self.nodes.get_mut(i)?;
        let node = node.downcast_mut()?;
        let changed = &mut self.slots.get_mut(i)?.changed;
        Some(NodeMut {
            node,
            changed,
            any_changed: &mut self.any_changed,
        })
    }

    /// Give a node an input through `input`, which says whether the node's deadline may have
    /// moved (as [`Node::on_sent`] does): only then is it asked again. For inputs a node takes
    /// often (a plant's readings every millisecond) whose effect on its timing the node itself
    /// reports; anything else goes through [`Network::node_mut`]. Returns whether the node is
    /// this network's.
    pub fn feed<N: Node + 'static>(
        &mut self,
        handle: NodeHandle<N>,
        input: impl FnOnce(&mut N) -> bool,
    ) -> bool {
        let i = handle.key.0;
        let Some(node) = self
            .nodes
            .get_mut(i)
            .and_then(|n| (&mut **n as &mut dyn Any).downcast_mut::<N>())
        else {
            return false;
        };
        if input(node) {
            if let Some(slot) = self.slots.get_mut(i) {
                slot.changed = true;
                self.any_changed = true;
            }
        }
        true
    }

    /// Wire `node`'s `port` to `bus`; the endpoint's number on that bus is returned (for the
    /// bus's events and faults). `None` for a node or bus that is not this network's, or a bus
    /// that already has [`MAX_ROUTED`] endpoints (taps included).
    pub fn wire(&mut self, node: impl Into<NodeKey>, port: Port, bus: BusIndex) -> Option<NodeId> {
        let node = node.into().0;
        let wires = self.wires_of.get_mut(node)?;
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
        wires.push(self.wires.len());
        self.wires.push(Wire {
            node,
            port,
            bus,
            endpoint,
        });
        Some(endpoint)
    }

    /// A listener on `bus` that no node drives (a logger, a tap, an outside tool): read it and
    /// send from it with [`Network::bus_mut`].
    pub fn tap(&mut self, bus: BusIndex) -> Option<NodeId> {
        self.forget_bus(bus);
        self.buses.get_mut(bus).map(|b| b.sim.add_node())
    }

    /// Set what a port receives.
    pub fn set_filtering(&mut self, node: impl Into<NodeKey>, port: Port, filtering: Filtering) {
        let node = node.into().0;
        if let Some(w) = port_wire(&self.wires, &self.wires_of, node, port) {
            if let Some(b) = self.buses.get_mut(w.bus) {
                b.sim.set_filtering(w.endpoint, filtering);
            }
        }
    }

    /// Drop (or again let through) everything `node` sends: a node cut off the bus.
    pub fn drop_output(&mut self, node: impl Into<NodeKey>, dropped: bool) {
        let node = node.into().0;
        if let Some(slot) = self.slots.get_mut(node) {
            slot.dropped = dropped;
        }
    }

    /// Drop (or again let through) what `node` sends on `port` only: that one connection cut.
    pub fn drop_port_output(&mut self, node: impl Into<NodeKey>, port: Port, dropped: bool) {
        let node = node.into().0;
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

    /// Run everything that happens before `until`. What falls at `until` itself happens in
    /// the next run, after whatever the caller changes at that time (a new command through
    /// [`Network::node_mut`], a cut-off node).
    pub fn run_until(&mut self, until: Timestamp) {
        self.run(until, None);
    }

    /// Run the network for `duration` more.
    pub fn run_for(&mut self, duration: Duration) {
        let until = self.now.saturating_add(duration);
        self.run_until(until);
    }

    /// As [`Network::run_until`], with `stand_in` in `node`'s place for this run: wired as
    /// `node` is, polled and given its frames instead of it (an outside node lent for one run:
    /// a tester in a built-in node's place). Its deadline is asked at the start of the run,
    /// and `node`'s again at the next run without it.
    pub fn run_until_standing_in<N>(
        &mut self,
        until: Timestamp,
        node: NodeHandle<N>,
        stand_in: &mut dyn Node,
    ) {
        self.run(until, Some((node.key.0, stand_in)));
    }

    fn run(&mut self, until: Timestamp, stand_in: Option<(usize, &mut dyn Node)>) {
        // The nodes are taken out for the run (a move, not a copy) so that the runner can
        // hand them frames while it changes its own state.
        let mut owned = std::mem::take(&mut self.nodes);
        let stood_in = stand_in.as_ref().map(|(at, _)| *at);
        let mut nodes = RunNodes {
            owned: &mut owned,
            stand_in,
        };
        // The nodes changed since the last run, and the stand-in, are asked their deadlines.
        let ask = std::mem::take(&mut self.any_changed) || stood_in.is_some();
        for i in (0..self.slots.len()).filter(|_| ask) {
            let Some(slot) = self.slots.get_mut(i) else {
                continue;
            };
            if !slot.changed && stood_in != Some(i) {
                continue;
            }
            slot.changed = false;
            let before = (slot.wake, slot.due_from);
            if let Some(node) = nodes.get_mut(i) {
                slot.set_deadline(node.next_deadline());
            }
            let after = (slot.wake, slot.due_from);
            self.moved(before, after);
        }
        self.run_nodes(until, &mut nodes);
        self.nodes = owned;
        // The node stood in for is asked again when it is back.
        if let Some(slot) = stood_in.and_then(|i| self.slots.get_mut(i)) {
            slot.changed = true;
            self.any_changed = true;
        }
    }

    fn run_nodes(&mut self, until: Timestamp, nodes: &mut RunNodes<'_, '_>) {
        // Each pass moves time forward to the next event (or ends at `until`): bounded by the
        // events between now and `until`, and by PASSES_PER_INSTANT at any one time.
        let mut passes_here = 0u32;
        loop {
            let next = self.start_ahead(until).map(|at| {
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

    /// A node's wake and due time moved from `before` to `after`: the earliest of all follows
    /// without a pass over every node, unless the node held one of them and it moved later.
    fn moved(&mut self, before: (u64, u64), after: (u64, u64)) {
        let Some(e) = self.earliest_wake.as_mut() else {
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
    fn earliest(&mut self) -> Earliest {
        if let Some(earliest) = self.earliest_wake {
            return earliest;
        }
        let (wake, due_from) = self.slots.iter().fold((NEVER, NEVER), |(wake, due), s| {
            (wake.min(s.wake), due.min(s.due_from))
        });
        let earliest = Earliest { wake, due_from };
        self.earliest_wake = Some(earliest);
        earliest
    }

    /// Advance each bus whose next activity (a transmission's start, a recovery) comes no
    /// later than anything else — a node's deadline, a frame's arrival — and before `until`:
    /// nothing is polled or delivered before it, so the bus gets there exactly as it would in
    /// an instant of its own, which would cost a pass over every node and bus. Its frame then
    /// arrives at its end of frame, an event like any other. Returns the earliest time
    /// something happens then: a node's deadline or a bus's next change.
    fn start_ahead(&mut self, until: Timestamp) -> Option<Timestamp> {
        let until = until.as_nanos();
        let mut others = self.earliest().wake;
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
    fn instant(&mut self, nodes: &mut RunNodes<'_, '_>) {
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
        if self.earliest().due_from <= now.as_nanos() {
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
    fn poll(&mut self, i: NodeIndex, nodes: &mut RunNodes<'_, '_>) {
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
        self.moved(before, after);
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
        let a = net.add_node(ticker(0x100));
        let b = net.add_node(Ticker {
            port: Port(3),
            ..ticker(0x200)
        });
        net.wire(a, Port::MAIN, bus).unwrap();
        net.wire(b, Port(3), bus).unwrap();
        net.run_until(Timestamp::from_millis(35));
        let (a, b) = (net.node(a).unwrap(), net.node(b).unwrap());
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
        let (a, b) = (net.add_node(ticker(0x100)), net.add_node(ticker(0x200)));
        net.wire(a, Port::MAIN, bus).unwrap();
        net.wire(b, Port::MAIN, bus).unwrap();
        net.drop_output(b, true);
        net.run_until(Timestamp::from_millis(50));
        assert!(net.node(a).unwrap().heard.is_empty());
        assert_eq!(net.node(b).unwrap().heard.len(), 5);
    }

    /// Sends one frame when told to (`send_at`), asks for no time otherwise.
    #[derive(Default)]
    struct OnRequest {
        send_at: Option<Timestamp>,
        sent: Vec<Timestamp>,
    }

    impl Node for OnRequest {
        fn on_frame(&mut self, _now: Timestamp, _port: Port, _frame: &Frame) {}
        fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
            if self.send_at.is_some_and(|at| now >= at) {
                self.send_at = None;
                self.sent.push(now);
                out(Port::MAIN, "321#01".parse().unwrap());
            }
        }
        fn next_deadline(&self) -> Option<Timestamp> {
            self.send_at
        }
    }

    #[test]
    fn a_node_changed_through_its_guard_is_asked_its_deadline_again() {
        let mut net = Network::new();
        let bus = net.add_bus("bus1", 500_000, None);
        let node = net.add_node(OnRequest::default());
        let listener = net.add_node(ticker(0x100));
        net.wire(node, Port::MAIN, bus).unwrap();
        net.wire(listener, Port::MAIN, bus).unwrap();
        net.run_until(Timestamp::from_millis(10));
        assert!(net.node(node).unwrap().sent.is_empty());
        // Told to send at 15 ms: the runner wakes for it although nothing else happens then.
        net.node_mut(node).unwrap().send_at = Some(Timestamp::from_millis(15));
        net.run_until(Timestamp::from_millis(30));
        assert_eq!(net.node(node).unwrap().sent, [Timestamp::from_millis(15)]);
        let heard = &net.node(listener).unwrap().heard;
        assert!(heard.iter().any(|(_, _, id)| *id == 0x321), "{heard:?}");
    }

    #[test]
    fn a_fed_input_re_asks_the_deadline_only_when_the_node_says_it_moved() {
        let run = |moved: bool| {
            let mut net = Network::new();
            let bus = net.add_bus("bus1", 500_000, None);
            let node = net.add_node(OnRequest::default());
            net.wire(node, Port::MAIN, bus).unwrap();
            net.run_until(Timestamp::from_millis(10));
            assert!(net.feed(node, |n: &mut OnRequest| {
                n.send_at = Some(Timestamp::from_millis(15));
                moved
            }));
            net.run_until(Timestamp::from_millis(30));
            net.node(node).unwrap().sent.clone()
        };
        assert_eq!(run(true), [Timestamp::from_millis(15)]);
        // Not said: nothing wakes it (the caller's word is the node's to give).
        assert!(run(false).is_empty());
    }

    #[test]
    fn a_stand_in_takes_a_nodes_place_for_one_run_and_hands_it_back() {
        let mut net = Network::new();
        let bus = net.add_bus("bus1", 500_000, None);
        let built_in = net.add_node(ticker(0x100));
        let listener = net.add_node(ticker(0x200));
        net.wire(built_in, Port::MAIN, bus).unwrap();
        net.wire(listener, Port::MAIN, bus).unwrap();
        let mut stand_in = ticker(0x300);
        net.run_until_standing_in(Timestamp::from_millis(15), built_in, &mut stand_in);
        // The stand-in sent at 0 and 10 ms and heard the listener; the built-in did nothing.
        let ids = |n: &Ticker| n.heard.iter().map(|(_, _, id)| *id).collect::<Vec<_>>();
        assert_eq!(ids(net.node(listener).unwrap()), [0x300, 0x300]);
        assert_eq!(ids(&stand_in), [0x200, 0x200]);
        assert!(net.node(built_in).unwrap().heard.is_empty());
        // Back in its place, the built-in node runs from its own deadline (it never ran: at
        // once).
        net.run_until(Timestamp::from_millis(25));
        let heard = &net.node(listener).unwrap().heard;
        assert!(heard.len() > 2, "{heard:?}");
        assert!(
            heard[2..]
                .iter()
                .all(|(at, _, id)| *id == 0x100 && *at > Timestamp::from_millis(15)),
            "{heard:?}"
        );
    }

    #[test]
    fn a_handle_from_another_network_finds_nothing_of_another_type() {
        let mut first = Network::new();
        let ticker_handle = first.add_node(ticker(0x100));
        let mut second = Network::new();
        second.add_node(OnRequest::default());
        assert!(second.node(ticker_handle).is_none());
        assert!(second.node_mut(ticker_handle).is_none());
        assert!(second
            .wire(
                NodeHandle::<Ticker> {
                    key: NodeKey(7),
                    node: PhantomData
                },
                Port::MAIN,
                0
            )
            .is_none());
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
        let run = |node: Paced| {
            let mut net = Network::new();
            let bus = net.add_bus("bus1", 500_000, None);
            let node = net.add_node(node);
            net.wire(node, Port::MAIN, bus).unwrap();
            net.run_until(Timestamp::from_millis(20));
            let node = net.node(node).unwrap();
            (node.sent_at.clone(), node.asked.get())
        };
        // Said: each frame goes the gap after the last one's confirmation.
        let (retimed, retimed_asked) = run(paced(true));
        assert!(retimed.len() >= 7, "{retimed:?}");
        for pair in retimed.windows(2) {
            let between = pair[1].saturating_since(pair[0]);
            // The gap, then the frame's own time on the wire (under 300 µs).
            assert!(between > Duration::from_millis(2), "{between:?}");
            assert!(between < Duration::from_micros(2_300), "{between:?}");
        }
        // Not said: the runner does not ask; the node waits for a frame that never comes.
        let (silent, silent_asked) = run(paced(false));
        assert_eq!(silent.len(), 1, "{silent:?}");
        assert!(silent_asked < retimed_asked);
    }
}
