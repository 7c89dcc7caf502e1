//! `sim:NAME@BITRATE`: the bit-timed bus ([`SimBus`]) run against the wall clock, so that
//! programs use it like any other bus.
//!
//! Every endpoint is a node with its own controller on one shared [`SimBus`]. Simulated time is
//! the time since the bus was created: a send hands the frame to the node's controller at the
//! present instant, and a receive runs the simulation up to the present and returns frames
//! whose end of frame has passed, so frames arrive when they would on a wire, in arbitration
//! order, with the wire's timestamps. Error frames for state changes (error passive, bus-off,
//! restarted) reach endpoints whose error mask asks for them, as from a SocketCAN driver.

use std::collections::HashMap;
use std::sync::{Arc, Condvar, Mutex, MutexGuard, OnceLock, PoisonError, Weak};
use std::time::{Duration, Instant};

use bywire_core::confinement::NodeState;
use bywire_core::{Frame, Timestamp};

use crate::{
    Bus, BusError, BusRx, BusStatus, BusTx, ControllerState, Filtering, Received, SharedEndpoint,
    Stats,
};
use bywire_net::sim::{Fault, NodeId, SimBus};

/// The bitrates a simulated bus runs at.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Bitrates {
    /// Nominal (arbitration) bitrate, bit/s.
    pub nominal: u32,
    /// FD data-phase bitrate, bit/s, when FD frames with BRS switch.
    pub data: Option<u32>,
}

struct State {
    bus: SimBus,
    stats: HashMap<NodeId, Stats>,
}

struct Shared {
    state: Mutex<State>,
    changed: Condvar,
    bitrates: Bitrates,
    epoch: Instant,
    /// Unix time at `epoch`: received frames are stamped in Unix time, as SocketCAN does.
    unix_at_epoch: Timestamp,
}

impl Shared {
    /// The state; every update is complete before the lock is released, so a panic elsewhere
    /// cannot leave it half-changed and poisoning is ignored.
    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Simulated time: the time since the bus was created.
    fn now(&self) -> Timestamp {
        Timestamp::from_nanos(u64::try_from(self.epoch.elapsed().as_nanos()).unwrap_or(u64::MAX))
    }
}

fn registry() -> &'static Mutex<HashMap<String, Weak<Shared>>> {
    static REGISTRY: OnceLock<Mutex<HashMap<String, Weak<Shared>>>> = OnceLock::new();
    REGISTRY.get_or_init(Mutex::default)
}

/// A simulated bus of that name already runs at other bitrates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("this simulated bus already runs at {running:?}, not {asked:?}")]
pub struct BitrateMismatch {
    /// The bus's bitrates.
    pub running: Bitrates,
    /// The bitrates asked for.
    pub asked: Bitrates,
}

/// A node on the process's simulated bus called NAME.
struct Member {
    shared: Arc<Shared>,
    node: NodeId,
}

/// One endpoint (a node with its own controller) on a simulated bus.
pub struct SimEndpoint {
    member: Arc<Member>,
}

impl SimEndpoint {
    /// Join (or create) the simulated bus called `name`, holding up to `capacity` received
    /// frames before dropping and counting new ones.
    pub fn join(
        name: &str,
        bitrates: Bitrates,
        capacity: usize,
    ) -> Result<SimEndpoint, BitrateMismatch> {
        let shared = {
            let mut buses = registry().lock().unwrap_or_else(PoisonError::into_inner);
            match buses.get(name).and_then(Weak::upgrade) {
                Some(shared) if shared.bitrates != bitrates => {
                    return Err(BitrateMismatch {
                        running: shared.bitrates,
                        asked: bitrates,
                    })
                }
                Some(shared) => shared,
                None => {
                    let shared = Arc::new(Shared {
                        state: Mutex::new(State {
                            bus: SimBus::new(bitrates.nominal, bitrates.data),
                            stats: HashMap::new(),
                        }),
                        changed: Condvar::new(),
                        bitrates,
                        epoch: Instant::now(),
                        unix_at_epoch: crate::monotonic_unix_now(),
                    });
                    buses.retain(|_, bus| bus.strong_count() > 0);
                    buses.insert(name.to_string(), Arc::downgrade(&shared));
                    shared
                }
            }
        };
        let node = {
            let mut state = shared.lock();
            let node = state.bus.add_node();
            state.bus.set_rx_capacity(node, capacity);
            state.stats.insert(node, Stats::default());
            node
        };
        Ok(SimEndpoint {
            member: Arc::new(Member { shared, node }),
        })
    }

    /// Destroy the next `count` transmissions of this endpoint (all identifiers), as a fault on
    /// the wire would: error frames, retransmissions, and the error counters rising.
    pub fn corrupt_own(&self, count: u32) {
        let mut state = self.member.shared.lock();
        state.bus.corrupt(Fault {
            node: Some(self.member.node),
            id: None,
            count,
            kind: Default::default(),
        });
    }

    fn update(&mut self, change: impl FnOnce(&mut SimBus, NodeId)) -> Result<(), BusError> {
        let mut state = self.member.shared.lock();
        change(&mut state.bus, self.member.node);
        Ok(())
    }
}

impl Drop for Member {
    fn drop(&mut self) {
        // The node leaves the bus: it stops receiving, and what it had queued is never sent.
        let mut state = self.shared.lock();
        state.bus.set_filtering(
            self.node,
            Filtering {
                filters: Vec::new(),
                error_mask: bywire_core::ErrorMask::NONE,
                join: false,
            },
        );
        state.bus.set_receive_own(self.node, false);
        state.bus.withdraw(self.node);
        state.stats.remove(&self.node);
    }
}

impl SharedEndpoint for Member {
    fn stats(&self) -> Stats {
        let state = self.shared.lock();
        let mut stats = state.stats.get(&self.node).copied().unwrap_or_default();
        stats.rx_dropped = state.bus.rx_dropped(self.node);
        stats
    }

    fn send(&self, frame: &Frame) -> Result<(), BusError> {
        if frame.is_error() {
            return Err(BusError::Unsupported("error frames".into()));
        }
        let mut state = self.shared.lock();
        let now = self.shared.now();
        state.bus.advance(now);
        state.bus.submit(self.node, *frame, now);
        if let Some(stats) = state.stats.get_mut(&self.node) {
            stats.count_sent(frame);
        }
        drop(state);
        self.shared.changed.notify_all();
        Ok(())
    }

    fn recv(&self, timeout: Option<Duration>) -> Result<Option<Received>, BusError> {
        let deadline = timeout.map(|t| Instant::now() + t);
        let mut state = self.shared.lock();
        // Each pass returns or sleeps until the next simulated event, a send, or the deadline.
        loop {
            let now = self.shared.now();
            state.bus.advance(now);
            if let Some(mut received) = state.bus.receive_by(self.node, now) {
                if let Some(stats) = state.stats.get_mut(&self.node) {
                    stats.count_received(&received.frame);
                }
                received.timestamp = self
                    .shared
                    .unix_at_epoch
                    .saturating_add(Duration::from_nanos(received.timestamp.as_nanos()));
                return Ok(Some(received));
            }
            let until_event = state
                .bus
                .next_change(self.node)
                .map(|at| at.saturating_since(now).max(Duration::from_micros(1)));
            let until_deadline = match deadline {
                Some(deadline) => {
                    let left = deadline.saturating_duration_since(Instant::now());
                    if left.is_zero() {
                        return Ok(None);
                    }
                    Some(left)
                }
                None => None,
            };
            state = match until_event.into_iter().chain(until_deadline).min() {
                Some(wait) => {
                    self.shared
                        .changed
                        .wait_timeout(state, wait)
                        .unwrap_or_else(PoisonError::into_inner)
                        .0
                }
                None => self
                    .shared
                    .changed
                    .wait(state)
                    .unwrap_or_else(PoisonError::into_inner),
            };
        }
    }
}

impl BusTx for SimEndpoint {
    fn send(&mut self, frame: &Frame) -> Result<(), BusError> {
        self.member.send(frame)
    }
}

impl BusRx for SimEndpoint {
    fn recv(&mut self, timeout: Option<Duration>) -> Result<Option<Received>, BusError> {
        self.member.recv(timeout)
    }

    fn stats(&self) -> Stats {
        SharedEndpoint::stats(self.member.as_ref())
    }
}

impl Bus for SimEndpoint {
    fn set_filtering(&mut self, filtering: Filtering) -> Result<(), BusError> {
        self.update(|bus, node| bus.set_filtering(node, filtering))
    }

    fn set_receive_own(&mut self, on: bool) -> Result<(), BusError> {
        self.update(|bus, node| bus.set_receive_own(node, on))
    }

    /// Every endpoint is a controller of its own on the simulated wire, not a socket sharing a
    /// host's controller: there is no local delivery to switch off.
    fn set_loopback(&mut self, _on: bool) -> Result<(), BusError> {
        Ok(())
    }

    fn status(&self) -> Result<Option<BusStatus>, BusError> {
        let state = self.member.shared.lock();
        Ok(state.bus.confinement(self.member.node).map(|c| BusStatus {
            state: match c.state() {
                NodeState::BusOff => ControllerState::BusOff,
                NodeState::ErrorPassive => ControllerState::ErrorPassive,
                NodeState::ErrorActive if c.is_warning() => ControllerState::ErrorWarning,
                NodeState::ErrorActive => ControllerState::ErrorActive,
            },
            tec: c.tec(),
            rec: c.rec(),
        }))
    }

    fn split(self: Box<Self>) -> (Box<dyn BusTx>, Box<dyn BusRx>) {
        crate::split_halves(self.member)
    }
}
