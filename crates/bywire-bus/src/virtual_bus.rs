//! The in-process virtual bus: any number of endpoints in one process share a named bus.
//!
//! Every frame reaches every other endpoint whose filters accept it (and the sender when it
//! asked for its own frames), all endpoints see frames in one global order (delivery happens
//! under one lock), and each endpoint has a bounded queue: when a reader does not keep up, new
//! frames for it are dropped and counted in its [`Stats::rx_dropped`], never blocking the bus or
//! the other readers.

use std::collections::{HashMap, VecDeque};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, OnceLock, PoisonError, Weak};
use std::time::{Duration, Instant};

use bywire_core::Frame;

use crate::{Bus, BusError, BusRx, BusTx, Filtering, Received, SharedEndpoint, Stats};

/// Frames an endpoint holds before it starts dropping.
pub const DEFAULT_QUEUE: usize = 4096;

struct Endpoint {
    queue: VecDeque<Received>,
    capacity: usize,
    filtering: Filtering,
    receive_own: bool,
    stats: Stats,
}

#[derive(Default)]
struct State {
    endpoints: HashMap<u64, Endpoint>,
    next_id: u64,
}

struct Shared {
    state: Mutex<State>,
    arrived: Condvar,
}

impl Shared {
    /// The state; a panic in another thread while holding the lock cannot leave it
    /// inconsistent (every update is a single push or counter change), so poisoning is ignored.
    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

fn registry() -> &'static Mutex<HashMap<String, Weak<Shared>>> {
    static REGISTRY: OnceLock<Mutex<HashMap<String, Weak<Shared>>>> = OnceLock::new();
    REGISTRY.get_or_init(Mutex::default)
}

/// An endpoint's membership: removed from the bus when the last half is dropped.
struct Membership {
    shared: Arc<Shared>,
    id: u64,
    /// Whether this endpoint's frames reach the others. Kept here rather than in the shared
    /// map: a lookup on every send, under the bus lock, cost two thirds of the throughput.
    loopback: AtomicBool,
}

impl Drop for Membership {
    fn drop(&mut self) {
        self.shared.lock().endpoints.remove(&self.id);
    }
}

/// One endpoint on a virtual bus.
pub struct VirtualBus {
    member: Arc<Membership>,
}

impl VirtualBus {
    /// Join (or create) the bus called `name` with the default queue length.
    pub fn join(name: &str) -> VirtualBus {
        Self::join_with_queue(name, DEFAULT_QUEUE)
    }

    /// Join (or create) the bus called `name`; this endpoint holds up to `capacity` frames.
    pub fn join_with_queue(name: &str, capacity: usize) -> VirtualBus {
        let shared = {
            let mut buses = registry().lock().unwrap_or_else(PoisonError::into_inner);
            match buses.get(name).and_then(Weak::upgrade) {
                Some(shared) => shared,
                None => {
                    let shared = Arc::new(Shared {
                        state: Mutex::default(),
                        arrived: Condvar::new(),
                    });
                    buses.retain(|_, bus| bus.strong_count() > 0);
                    buses.insert(name.to_string(), Arc::downgrade(&shared));
                    shared
                }
            }
        };
        let id = {
            let mut state = shared.lock();
            let id = state.next_id;
            state.next_id += 1;
            state.endpoints.insert(
                id,
                Endpoint {
                    queue: VecDeque::new(),
                    capacity: capacity.max(1),
                    filtering: Filtering::default(),
                    receive_own: false,
                    stats: Stats::default(),
                },
            );
            id
        };
        VirtualBus {
            member: Arc::new(Membership {
                shared,
                id,
                loopback: AtomicBool::new(true),
            }),
        }
    }
}

impl VirtualBus {
    fn update(&mut self, change: impl FnOnce(&mut Endpoint)) -> Result<(), BusError> {
        let mut state = self.member.shared.lock();
        let endpoint = state
            .endpoints
            .get_mut(&self.member.id)
            .ok_or(BusError::Closed)?;
        change(endpoint);
        Ok(())
    }
}

impl SharedEndpoint for Membership {
    fn stats(&self) -> Stats {
        self.shared
            .lock()
            .endpoints
            .get(&self.id)
            .map(|e| e.stats)
            .unwrap_or_default()
    }

    fn send(&self, frame: &Frame) -> Result<(), BusError> {
        let mut state = self.shared.lock();
        let timestamp = crate::monotonic_unix_now();
        let loopback = self.loopback.load(Ordering::Relaxed);
        for (&id, endpoint) in state.endpoints.iter_mut() {
            let own = id == self.id;
            if own {
                endpoint.stats.count_sent(frame);
            }
            // As in SocketCAN, own frames come back only through the loopback.
            let wanted = loopback && (!own || endpoint.receive_own);
            if !wanted || !endpoint.filtering.accepts(frame) {
                continue;
            }
            if endpoint.queue.len() >= endpoint.capacity {
                endpoint.stats.rx_dropped += 1;
                continue;
            }
            endpoint.queue.push_back(Received {
                frame: *frame,
                timestamp,
                own,
                local: true,
                hardware: None,
            });
        }
        drop(state);
        self.shared.arrived.notify_all();
        Ok(())
    }

    fn recv(&self, timeout: Option<Duration>) -> Result<Option<Received>, BusError> {
        let deadline = timeout.map(|t| Instant::now() + t);
        let mut state = self.shared.lock();
        // Each pass either returns or waits on the condition variable; spurious wake-ups go round
        // again until the deadline.
        loop {
            let endpoint = state.endpoints.get_mut(&self.id).ok_or(BusError::Closed)?;
            if let Some(received) = endpoint.queue.pop_front() {
                endpoint.stats.count_received(&received.frame);
                return Ok(Some(received));
            }
            state = match deadline {
                None => self
                    .shared
                    .arrived
                    .wait(state)
                    .unwrap_or_else(PoisonError::into_inner),
                Some(deadline) => {
                    let left = deadline.saturating_duration_since(Instant::now());
                    if left.is_zero() {
                        return Ok(None);
                    }
                    self.shared
                        .arrived
                        .wait_timeout(state, left)
                        .unwrap_or_else(PoisonError::into_inner)
                        .0
                }
            };
        }
    }
}

impl BusTx for VirtualBus {
    fn send(&mut self, frame: &Frame) -> Result<(), BusError> {
        self.member.send(frame)
    }
}

impl BusRx for VirtualBus {
    fn recv(&mut self, timeout: Option<Duration>) -> Result<Option<Received>, BusError> {
        self.member.recv(timeout)
    }

    fn stats(&self) -> Stats {
        SharedEndpoint::stats(self.member.as_ref())
    }
}

impl Bus for VirtualBus {
    fn set_filtering(&mut self, filtering: Filtering) -> Result<(), BusError> {
        self.update(|endpoint| endpoint.filtering = filtering)
    }

    fn set_receive_own(&mut self, on: bool) -> Result<(), BusError> {
        self.update(|endpoint| endpoint.receive_own = on)
    }

    fn set_loopback(&mut self, on: bool) -> Result<(), BusError> {
        self.member.loopback.store(on, Ordering::Relaxed);
        Ok(())
    }

    fn split(self: Box<Self>) -> (Box<dyn BusTx>, Box<dyn BusRx>) {
        crate::split_halves(self.member)
    }
}
