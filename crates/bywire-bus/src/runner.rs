//! The real-time runner: one sans-IO node on N bus endpoints (port → bus), against the
//! monotonic clock, giving the node time by the rule in [`bywire_core::node`].
//!
//! Each endpoint is split; a receive thread per endpoint hands frames to the runner through
//! one bounded queue (when the runner falls behind, the queue fills and the backend's own
//! queue counts the drops), and the runner's thread polls the node and sends what it emits.
//! Each bus is asked to echo what it sends: the echo is the node's transmit confirmation
//! ([`Node::on_sent`]); a backend that cannot echo (socketcand, SLCAN) confirms a frame when
//! it accepts it. An echo must pass the endpoint's own filters (SocketCAN applies them to
//! it), so a filtered bus should let the node's own identifiers through.
//! A bus that fails is reported to the caller ([`Hooks::bus_lost`]) and left out from then
//! on: the node goes on running on the others, so losing a redundant bus degrades instead of
//! silencing the healthy one. The run ends with an error only when every bus is lost.
//!
//! A wait that ends over 10 ms late means the process was stopped or starved (a stall): the
//! frames that came meanwhile sit in the backends, and the receive threads hand them over at
//! once when they run again. The runner gives them 5 ms to, and delivers what came before it
//! polls, so a node that times its inputs (a command watchdog) does not see them as missed.
//!
//! The caller steers a run through [`Hooks`]: after each poll it may look at or change the
//! node (give it inputs, print its state) and stop the run; a [`Waker`] lets another thread
//! (say, one reading stdin) wake the runner at once instead of at its next deadline.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, SyncSender};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use bywire_core::node::{Node, Port};
use bywire_core::time::earliest;
use bywire_core::{Frame, Timestamp};

use crate::{Bus, BusError, BusTx};

/// The longest the runner waits without looking at `stop`.
const MAX_WAIT: Duration = Duration::from_millis(20);
/// How long a receive thread waits before looking whether the run has ended.
const RECEIVE_SLICE: Duration = Duration::from_millis(50);
/// Frames waiting between the receive threads and the runner.
const QUEUE: usize = 4096;
/// Frames delivered in one batch before the node is polled again.
const BATCH: usize = 256;
/// A wait that ends this much later than asked: the process was stopped or starved (a stall).
const STALLED: Duration = Duration::from_millis(10);
/// After a stall, how long the runner waits for the receive threads to hand over what came
/// meanwhile (they read it at once) before it polls: a node that times what it receives (a
/// watchdog) would otherwise see its inputs late that were there all along.
const AFTER_STALL: Duration = Duration::from_millis(5);

/// What to do after a poll.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Flow {
    /// Go on.
    Continue,
    /// End the run.
    Stop,
}

/// How the caller takes part in a run; every method has a default that does nothing.
pub trait Hooks<N> {
    /// Called after each poll once its frames are sent.
    fn after_poll(&mut self, _node: &mut N, _now: Timestamp) -> Flow {
        Flow::Continue
    }
    /// A time the caller wants the runner awake at (besides the node's deadline).
    fn wake_at(&self) -> Option<Timestamp> {
        None
    }
    /// A bus failed, receiving or sending: it is left out from now on.
    fn bus_lost(&mut self, _node: &mut N, _now: Timestamp, _port: Port, _error: &BusError) {}
}

/// A closure as hooks: called after each poll.
impl<N, F: FnMut(&mut N, Timestamp) -> Flow> Hooks<N> for F {
    fn after_poll(&mut self, node: &mut N, now: Timestamp) -> Flow {
        self(node, now)
    }
}

/// How a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ended {
    /// The hooks said stop.
    ByHooks,
    /// The stop flag was set.
    Stopped,
    /// The time limit passed.
    TimeLimit,
}

/// Counts of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RunStats {
    /// Frames delivered to the node.
    pub received: u64,
    /// Frames sent.
    pub sent: u64,
    /// Frames the node sent on a port that has no bus (or whose bus was lost).
    pub unattached: u64,
}

enum Arrival {
    Frame(Port, Frame),
    /// The backend's echo of a frame this runner sent (its transmit confirmation).
    Sent(Port, Frame),
    Lost(Port, BusError),
    Wake,
}

/// Wakes a running runner from another thread.
#[derive(Clone)]
pub struct Waker(SyncSender<Arrival>);

impl Waker {
    /// Wake the runner now (it polls the node and calls the hooks).
    pub fn wake(&self) {
        // A full queue wakes the runner anyway; a closed one means the run is over.
        let _ = self.0.try_send(Arrival::Wake);
    }
}

struct Attached {
    port: Port,
    tx: Option<Box<dyn BusTx>>,
    /// The backend echoes what it sent; otherwise a frame is confirmed once accepted.
    echoes: bool,
}

/// A node's endpoints, ready to run.
pub struct Runner {
    attached: Vec<Attached>,
    arrivals: Receiver<Arrival>,
    sender: SyncSender<Arrival>,
    receivers: Vec<JoinHandle<()>>,
    ended: Arc<AtomicBool>,
    start: Instant,
    stats: RunStats,
}

impl Runner {
    /// Attach each bus to its port; time starts at zero now.
    pub fn new(endpoints: Vec<(Port, Box<dyn Bus>)>) -> Runner {
        let (sender, arrivals) = mpsc::sync_channel(QUEUE);
        let ended = Arc::new(AtomicBool::new(false));
        let mut attached = Vec::with_capacity(endpoints.len());
        let mut receivers = Vec::with_capacity(endpoints.len());
        for (port, mut bus) in endpoints {
            // Own frames come back as transmit confirmations where the backend can echo.
            let echoes = bus.set_receive_own(true).is_ok();
            let (tx, mut rx) = bus.split();
            attached.push(Attached {
                port,
                tx: Some(tx),
                echoes,
            });
            let queue = sender.clone();
            let ended = Arc::clone(&ended);
            receivers.push(std::thread::spawn(move || {
                while !ended.load(Ordering::Relaxed) {
                    let arrival = match rx.recv(Some(RECEIVE_SLICE)) {
                        Ok(None) => continue,
                        Ok(Some(r)) if r.own => Arrival::Sent(port, r.frame),
                        Ok(Some(r)) => Arrival::Frame(port, r.frame),
                        Err(e) => {
                            let _ = queue.send(Arrival::Lost(port, e));
                            return;
                        }
                    };
                    // Blocks while the runner is behind; fails once the run is over.
                    if queue.send(arrival).is_err() {
                        return;
                    }
                }
            }));
        }
        Runner {
            attached,
            arrivals,
            sender,
            receivers,
            ended,
            start: Instant::now(),
            stats: RunStats::default(),
        }
    }

    /// A handle that wakes this runner from another thread.
    pub fn waker(&self) -> Waker {
        Waker(self.sender.clone())
    }

    /// The runner's clock: time since [`Runner::new`].
    pub fn now(&self) -> Timestamp {
        Timestamp::from_nanos(u64::try_from(self.start.elapsed().as_nanos()).unwrap_or(u64::MAX))
    }

    /// Counts so far.
    pub fn stats(&self) -> RunStats {
        self.stats
    }

    /// Run `node` until the hooks stop it, `stop` is set or `limit` (from the runner's start)
    /// has passed. Fails only when every bus is lost (with the last bus's error).
    pub fn run<N: Node>(
        &mut self,
        node: &mut N,
        stop: &AtomicBool,
        limit: Option<Duration>,
        hooks: &mut impl Hooks<N>,
    ) -> Result<Ended, BusError> {
        let mut outgoing: Vec<(Port, Frame)> = Vec::with_capacity(64);
        loop {
            if stop.load(Ordering::Relaxed) {
                return Ok(Ended::Stopped);
            }
            if limit.is_some_and(|limit| self.start.elapsed() >= limit) {
                return Ok(Ended::TimeLimit);
            }
            let now = self.now();
            node.poll(now, &mut |port, frame| outgoing.push((port, frame)));
            for (port, frame) in outgoing.drain(..) {
                self.send(node, hooks, now, port, &frame);
            }
            if hooks.after_poll(node, now) == Flow::Stop {
                return Ok(Ended::ByHooks);
            }
            if self.attached.iter().all(|a| a.tx.is_none()) {
                return Err(BusError::Closed);
            }
            let deadline = earliest([node.next_deadline(), hooks.wake_at()]);
            let wait = deadline
                .map_or(MAX_WAIT, |at| at.saturating_since(self.now()))
                .min(MAX_WAIT);
            let waited = Instant::now();
            let mut first = match self.arrivals.recv_timeout(wait) {
                Ok(arrival) => Some(arrival),
                Err(RecvTimeoutError::Timeout) => None,
                // Cannot happen while `self.sender` lives; treat as every bus gone.
                Err(RecvTimeoutError::Disconnected) => return Err(BusError::Closed),
            };
            if first.is_none() && waited.elapsed() > wait.saturating_add(STALLED) {
                first = self.arrivals.recv_timeout(AFTER_STALL).ok();
            }
            // Deliver what has arrived, in order (at most a batch), then poll again.
            let mut delivered = 0;
            while let Some(arrival) = first.take().or_else(|| {
                (delivered < BATCH)
                    .then(|| self.arrivals.try_recv().ok())
                    .flatten()
            }) {
                delivered += 1;
                let now = self.now();
                match arrival {
                    Arrival::Frame(port, frame) => {
                        self.stats.received = self.stats.received.saturating_add(1);
                        node.on_frame(now, port, &frame);
                    }
                    // The deadline is asked at every turn of the loop whatever this says.
                    Arrival::Sent(port, frame) => {
                        node.on_sent(now, port, &frame);
                    }
                    Arrival::Lost(port, error) => self.lose(node, hooks, now, port, &error),
                    Arrival::Wake => {}
                }
            }
        }
    }

    fn send<N: Node>(
        &mut self,
        node: &mut N,
        hooks: &mut impl Hooks<N>,
        now: Timestamp,
        port: Port,
        frame: &Frame,
    ) {
        let Some(attached) = self.attached.iter_mut().find(|a| a.port == port) else {
            self.stats.unattached = self.stats.unattached.saturating_add(1);
            return;
        };
        let Some(tx) = attached.tx.as_mut() else {
            self.stats.unattached = self.stats.unattached.saturating_add(1);
            return;
        };
        match tx.send(frame) {
            Ok(()) => {
                self.stats.sent = self.stats.sent.saturating_add(1);
                if !attached.echoes {
                    node.on_sent(now, port, frame);
                }
            }
            // A frame this bus cannot carry is refused, not a lost bus.
            Err(BusError::Unsupported(_)) => {
                self.stats.unattached = self.stats.unattached.saturating_add(1)
            }
            Err(error) => self.lose(node, hooks, now, port, &error),
        }
    }

    fn lose<N>(
        &mut self,
        node: &mut N,
        hooks: &mut impl Hooks<N>,
        now: Timestamp,
        port: Port,
        error: &BusError,
    ) {
        if let Some(attached) = self.attached.iter_mut().find(|a| a.port == port) {
            if attached.tx.take().is_some() {
                hooks.bus_lost(node, now, port, error);
            }
        }
    }
}

impl Drop for Runner {
    fn drop(&mut self) {
        self.ended.store(true, Ordering::Relaxed);
        // Each receive thread looks at `ended` at least every RECEIVE_SLICE; one blocked on a
        // full queue is freed by the draining.
        for handle in self.receivers.drain(..) {
            while !handle.is_finished() {
                while self.arrivals.try_recv().is_ok() {}
                std::thread::sleep(Duration::from_millis(1));
            }
            let _ = handle.join();
        }
    }
}

/// Run `node` on `bus` (its main port) until `stop` is set or the bus fails; gives the node
/// back. Time starts at zero when the runner starts.
pub fn run<N: Node>(bus: Box<dyn Bus>, mut node: N, stop: &AtomicBool) -> Result<N, BusError> {
    run_until(bus, &mut node, stop, None, |_| false)?;
    Ok(node)
}

/// Run `node` on `bus` (its main port) until `done` says so (checked after each poll has been
/// sent, so what the node answered last goes out), `stop` is set, or `limit` has passed;
/// `true` when `done` ended it.
pub fn run_until<N: Node>(
    bus: Box<dyn Bus>,
    node: &mut N,
    stop: &AtomicBool,
    limit: Option<Duration>,
    mut done: impl FnMut(&mut N) -> bool,
) -> Result<bool, BusError> {
    let mut runner = Runner::new(vec![(Port::MAIN, bus)]);
    let mut hooks = |node: &mut N, _now: Timestamp| {
        if done(node) {
            Flow::Stop
        } else {
            Flow::Continue
        }
    };
    let ended = runner.run(node, stop, limit, &mut hooks)?;
    Ok(ended == Ended::ByHooks)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

    use super::*;
    use crate::virtual_bus::VirtualBus;
    use crate::BusRx;
    use bywire_core::Id;

    /// Answers each frame on the port it came from, with identifier + 1.
    #[derive(Default)]
    struct Answer {
        pending: Vec<(Port, Frame)>,
        heard: Vec<Port>,
    }

    impl Node for Answer {
        fn on_frame(&mut self, _now: Timestamp, port: Port, frame: &Frame) {
            self.heard.push(port);
            let raw = frame.id().map_or(0, |id| id.as_raw());
            let id = Id::standard(raw + 1).unwrap();
            self.pending
                .push((port, Frame::classic(id, frame.data()).unwrap()));
        }
        fn poll(&mut self, _now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
            for (port, frame) in self.pending.drain(..) {
                out(port, frame);
            }
        }
        fn next_deadline(&self) -> Option<Timestamp> {
            None
        }
    }

    fn frame(id: u32) -> Frame {
        Frame::classic(Id::standard(id).unwrap(), &[7]).unwrap()
    }

    #[test]
    fn frames_come_in_and_go_out_by_port() {
        let a = VirtualBus::join("runner-ports-a");
        let b = VirtualBus::join("runner-ports-b");
        let mut peer_a = VirtualBus::join("runner-ports-a");
        let mut peer_b = VirtualBus::join("runner-ports-b");
        let mut runner = Runner::new(vec![(Port(0), Box::new(a)), (Port(1), Box::new(b))]);
        let mut node = Answer::default();
        peer_a.send(&frame(0x10)).unwrap();
        peer_b.send(&frame(0x20)).unwrap();
        let stop = AtomicBool::new(false);
        let mut hooks = |n: &mut Answer, _| {
            if n.heard.len() == 2 {
                Flow::Stop
            } else {
                Flow::Continue
            }
        };
        let ended = runner
            .run(&mut node, &stop, Some(Duration::from_secs(5)), &mut hooks)
            .unwrap();
        assert_eq!(ended, Ended::ByHooks);
        let got_a = peer_a.recv(Some(Duration::from_secs(1))).unwrap().unwrap();
        let got_b = peer_b.recv(Some(Duration::from_secs(1))).unwrap().unwrap();
        assert_eq!(got_a.frame.id().unwrap().as_raw(), 0x11);
        assert_eq!(got_b.frame.id().unwrap().as_raw(), 0x21);
        let mut heard = node.heard.clone();
        heard.sort();
        assert_eq!(heard, vec![Port(0), Port(1)]);
    }

    /// Sends frame 0x30 on each port once, and records the confirmations it is given.
    #[derive(Default)]
    struct Confirmed {
        sent: bool,
        confirmed: Vec<(Port, Frame)>,
        heard: usize,
    }

    impl Node for Confirmed {
        fn on_frame(&mut self, _now: Timestamp, _port: Port, _frame: &Frame) {
            self.heard += 1;
        }
        fn on_sent(&mut self, _now: Timestamp, port: Port, frame: &Frame) -> bool {
            self.confirmed.push((port, *frame));
            false
        }
        fn poll(&mut self, _now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
            if !std::mem::replace(&mut self.sent, true) {
                for port in 0..3 {
                    out(Port(port), frame(0x30));
                }
            }
        }
        fn next_deadline(&self) -> Option<Timestamp> {
            None
        }
    }

    /// A virtual bus that cannot echo, as socketcand and SLCAN cannot.
    struct NoEcho(VirtualBus);

    impl BusTx for NoEcho {
        fn send(&mut self, frame: &Frame) -> Result<(), BusError> {
            self.0.send(frame)
        }
    }
    impl crate::BusRx for NoEcho {
        fn recv(&mut self, timeout: Option<Duration>) -> Result<Option<crate::Received>, BusError> {
            self.0.recv(timeout)
        }
        fn stats(&self) -> crate::Stats {
            self.0.stats()
        }
    }

    impl Bus for NoEcho {
        fn set_filtering(&mut self, filtering: crate::Filtering) -> Result<(), BusError> {
            self.0.set_filtering(filtering)
        }
        fn set_receive_own(&mut self, _: bool) -> Result<(), BusError> {
            Err(BusError::Unsupported("receive-own".into()))
        }
        fn set_loopback(&mut self, on: bool) -> Result<(), BusError> {
            self.0.set_loopback(on)
        }
        fn split(self: Box<Self>) -> (Box<dyn BusTx>, Box<dyn crate::BusRx>) {
            Box::new(self.0).split()
        }
    }

    /// Each frame sent is confirmed once, on its port, as a confirmation and not as a frame:
    /// from the echo of a bus that echoes; when accepted by one that cannot echo; from a
    /// silenced bus (its frames dropped) never.
    #[test]
    fn frames_sent_are_confirmed_by_their_echo_and_only_when_they_went_out() {
        use crate::faults::{Action, FaultyBus, Match, Rule, When};
        let echoing = VirtualBus::join("runner-confirm-a");
        let silenced = FaultyBus::new(
            VirtualBus::join("runner-confirm-b"),
            vec![Rule {
                matching: Match::All,
                when: When::Always,
                action: Action::Drop,
            }],
            1,
        );
        let mut peer = VirtualBus::join("runner-confirm-a");
        let mut runner = Runner::new(vec![
            (Port(0), Box::new(echoing)),
            (Port(1), Box::new(silenced)),
            (
                Port(2),
                Box::new(NoEcho(VirtualBus::join("runner-confirm-c"))),
            ),
        ]);
        let mut node = Confirmed::default();
        let stop = AtomicBool::new(false);
        let ended = runner
            .run(
                &mut node,
                &stop,
                Some(Duration::from_millis(300)),
                &mut |_: &mut Confirmed, _| Flow::Continue,
            )
            .unwrap();
        assert_eq!(ended, Ended::TimeLimit);
        node.confirmed.sort_by_key(|(port, _)| *port);
        assert_eq!(
            node.confirmed,
            vec![(Port(0), frame(0x30)), (Port(2), frame(0x30))]
        );
        assert_eq!(node.heard, 0, "an echo is not a frame heard");
        assert_eq!(runner.stats().received, 0);
        let got = peer.recv(Some(Duration::from_secs(1))).unwrap().unwrap();
        assert_eq!(got.frame, frame(0x30));
    }

    /// A waker from another thread has a node without a deadline polled at once, not at the
    /// runner's next idle check (every 20 ms); after the run it does nothing.
    #[test]
    fn a_waker_polls_a_sleeping_node_at_once() {
        use std::sync::{Arc, Mutex};
        let bus = VirtualBus::join("runner-waker");
        let mut runner = Runner::new(vec![(Port(0), Box::new(bus))]);
        let waker = runner.waker();
        let woken = Arc::new(Mutex::new(Vec::new()));
        let times = Arc::clone(&woken);
        let waking = std::thread::spawn(move || {
            // Offsets that do not line up with the 20 ms idle checks.
            for pause in [7, 13, 29, 11, 17, 23, 9, 31, 5, 19] {
                std::thread::sleep(Duration::from_millis(pause));
                times.lock().unwrap().push(std::time::Instant::now());
                waker.wake();
            }
            waker
        });
        let mut node = Answer::default();
        let stop = AtomicBool::new(false);
        let mut polls = Vec::new();
        let mut hooks = |_: &mut Answer, _: Timestamp| {
            polls.push(std::time::Instant::now());
            Flow::Continue
        };
        runner
            .run(
                &mut node,
                &stop,
                Some(Duration::from_millis(400)),
                &mut hooks,
            )
            .unwrap();
        let waker = waking.join().unwrap();
        let woken = woken.lock().unwrap().clone();
        assert_eq!(woken.len(), 10);
        for wake in &woken {
            let answered = polls
                .iter()
                .find(|p| *p >= wake)
                .expect("a poll after the wake");
            assert!(
                answered.duration_since(*wake) < Duration::from_millis(10),
                "polled {:?} after a wake",
                answered.duration_since(*wake)
            );
        }
        drop(runner);
        waker.wake(); // the run is over: nothing to wake, nothing breaks
    }

    /// Emits a frame on both ports every millisecond.
    struct Beacon {
        next: Timestamp,
    }

    impl Node for Beacon {
        fn on_frame(&mut self, _: Timestamp, _: Port, _: &Frame) {}
        fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
            if now >= self.next {
                self.next = now.saturating_add(Duration::from_millis(1));
                out(Port(0), frame(0x100));
                out(Port(1), frame(0x100));
            }
        }
        fn next_deadline(&self) -> Option<Timestamp> {
            Some(self.next)
        }
    }

    /// A bus whose sends fail from the start.
    struct Broken;

    impl crate::BusTx for Broken {
        fn send(&mut self, _: &Frame) -> Result<(), BusError> {
            Err(BusError::Io(std::io::Error::other("unplugged")))
        }
    }
    impl crate::BusRx for Broken {
        fn recv(&mut self, _: Option<Duration>) -> Result<Option<crate::Received>, BusError> {
            std::thread::sleep(Duration::from_millis(1));
            Ok(None)
        }
        fn stats(&self) -> crate::Stats {
            crate::Stats::default()
        }
    }
    impl Bus for Broken {
        fn set_filtering(&mut self, _: crate::Filtering) -> Result<(), BusError> {
            Ok(())
        }
        fn set_receive_own(&mut self, _: bool) -> Result<(), BusError> {
            Ok(())
        }
        fn set_loopback(&mut self, _: bool) -> Result<(), BusError> {
            Ok(())
        }
        fn split(self: Box<Self>) -> (Box<dyn BusTx>, Box<dyn crate::BusRx>) {
            (Box::new(Broken), Box::new(Broken))
        }
    }

    struct Lost(Vec<Port>);
    impl Hooks<Beacon> for Lost {
        fn bus_lost(&mut self, _: &mut Beacon, _: Timestamp, port: Port, _: &BusError) {
            self.0.push(port);
        }
    }

    #[test]
    fn a_lost_bus_leaves_the_other_running() {
        let healthy = VirtualBus::join("runner-lost-a");
        let mut peer = VirtualBus::join("runner-lost-a");
        let mut runner = Runner::new(vec![
            (Port(0), Box::new(healthy)),
            (Port(1), Box::new(Broken)),
        ]);
        let mut node = Beacon {
            next: Timestamp::ZERO,
        };
        let mut hooks = Lost(Vec::new());
        let stop = AtomicBool::new(false);
        let ended = runner
            .run(
                &mut node,
                &stop,
                Some(Duration::from_millis(200)),
                &mut hooks,
            )
            .unwrap();
        assert_eq!(ended, Ended::TimeLimit);
        assert_eq!(hooks.0, vec![Port(1)], "bus B reported lost once");
        let mut frames = 0;
        while peer.recv(Some(Duration::ZERO)).unwrap().is_some() {
            frames += 1;
        }
        assert!(frames >= 50, "bus A kept getting frames: {frames}");
        assert!(runner.stats().unattached >= 50);
    }

    #[test]
    fn every_bus_lost_ends_the_run_with_an_error() {
        let mut runner = Runner::new(vec![(Port(0), Box::new(Broken))]);
        let mut node = Beacon {
            next: Timestamp::ZERO,
        };
        let stop = AtomicBool::new(false);
        let result = runner.run(
            &mut node,
            &stop,
            Some(Duration::from_secs(5)),
            &mut |_: &mut Beacon, _| Flow::Continue,
        );
        assert!(matches!(result, Err(BusError::Closed)), "{result:?}");
    }
}
