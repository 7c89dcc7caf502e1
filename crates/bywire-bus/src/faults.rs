//! Fault injection on any bus: a wrapper that applies rules to what its endpoint sends.
//!
//! A [`Rule`] picks frames ([`Match`]: by identifier or all), decides when it applies
//! ([`When`]: always, with a seeded probability, or within a time window counted from the
//! wrapper's creation) and what happens ([`Action`]): drop, delay, duplicate, reorder, corrupt
//! payload bytes, freeze the payload (a message that keeps coming with a stale counter), or
//! silence the node. The first rule that applies to a frame decides; frames no rule applies to
//! pass unchanged. The same seed gives the same faults.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use bywire_core::frame::{ClassicFrame, FdFrame};
use bywire_core::{Frame, Id};

use crate::{Bus, BusError, BusRx, BusStatus, BusTx, Filtering, Received, Stats};

/// Which frames a rule looks at.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Match {
    /// Every frame.
    All,
    /// Frames with one of these identifiers.
    Ids(Vec<Id>),
}

/// When a rule applies to a frame it matches.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum When {
    /// Every time.
    Always,
    /// With this probability (0–1), drawn from the wrapper's seeded generator.
    Probability(f64),
    /// Between these offsets from the wrapper's creation.
    Window {
        /// Start (inclusive).
        from: Duration,
        /// End (exclusive).
        to: Duration,
    },
}

/// What happens to a frame a rule applies to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Action {
    /// Not sent.
    Drop,
    /// Sent this much later (on a later `send` or `recv` of this wrapper).
    Delay(Duration),
    /// Sent twice.
    Duplicate,
    /// Held back and sent after the next frame.
    Reorder,
    /// This many payload bytes get a random bit flipped.
    Corrupt {
        /// Bytes to disturb.
        bytes: usize,
    },
    /// Sent with the payload it had when the rule first applied (a stale message).
    Freeze,
    /// Nothing is sent at all (the node falls silent).
    Silence,
}

/// One fault rule.
#[derive(Debug, Clone, PartialEq)]
pub struct Rule {
    /// Which frames.
    pub matching: Match,
    /// When.
    pub when: When,
    /// What happens.
    pub action: Action,
}

/// The rule engine: turns each frame to send into the frames that actually go out.
struct Injector {
    rules: Vec<(Rule, Option<Frame>)>,
    rng: fastrand::Rng,
    started: Instant,
    delayed: VecDeque<(Instant, Frame)>,
    held: Option<Frame>,
}

impl Injector {
    /// Delayed frames that are due, in order.
    fn due(&mut self, out: &mut Vec<Frame>) {
        let now = Instant::now();
        while self.delayed.front().is_some_and(|(due, _)| *due <= now) {
            if let Some((_, frame)) = self.delayed.pop_front() {
                out.push(frame);
            }
        }
    }

    fn corrupt(&mut self, frame: &Frame, bytes: usize) -> Frame {
        let mut data = frame.data().to_vec();
        for _ in 0..bytes.min(data.len()) {
            let i = self.rng.usize(..data.len());
            if let Some(b) = data.get_mut(i) {
                *b ^= 1 << self.rng.u8(..8);
            }
        }
        with_data(frame, &data)
    }

    /// What goes out for `frame`, after any due delayed frames.
    fn apply(&mut self, frame: &Frame, out: &mut Vec<Frame>) {
        self.due(out);
        let elapsed = self.started.elapsed();
        let mut decided = None;
        for (rule, frozen) in self.rules.iter_mut() {
            let matches = match &rule.matching {
                Match::All => true,
                Match::Ids(ids) => frame.id().is_some_and(|id| ids.contains(&id)),
            };
            if !matches {
                continue;
            }
            let applies = match rule.when {
                When::Always => true,
                When::Probability(p) => self.rng.f64() < p,
                When::Window { from, to } => elapsed >= from && elapsed < to,
            };
            if applies {
                if rule.action == Action::Freeze && frozen.is_none() {
                    *frozen = Some(*frame);
                }
                decided = Some((rule.action, *frozen));
                break;
            }
        }
        let sent = match decided {
            None => Some(*frame),
            Some((Action::Drop | Action::Silence, _)) => None,
            Some((Action::Delay(d), _)) => {
                self.delayed.push_back((Instant::now() + d, *frame));
                None
            }
            Some((Action::Duplicate, _)) => {
                out.push(*frame);
                Some(*frame)
            }
            Some((Action::Reorder, _)) => {
                // Held back; a frame already held (two reordered in a row) goes now.
                self.held.replace(*frame)
            }
            Some((Action::Corrupt { bytes }, _)) => Some(self.corrupt(frame, bytes)),
            Some((Action::Freeze, frozen)) => {
                Some(frozen.map_or(*frame, |f| with_data(frame, f.data())))
            }
        };
        if let Some(frame) = sent {
            out.push(frame);
            // A held frame follows the next frame that goes out for another reason.
            if !matches!(decided, Some((Action::Reorder, _))) {
                out.extend(self.held.take());
            }
        }
    }
}

/// A bus whose sends go through fault rules.
pub struct FaultyBus<B> {
    inner: B,
    injector: Injector,
    outgoing: Vec<Frame>,
}

impl<B: Bus> FaultyBus<B> {
    /// Wrap `inner`; `seed` makes probabilities and corruption reproducible.
    pub fn new(inner: B, rules: Vec<Rule>, seed: u64) -> Self {
        FaultyBus {
            inner,
            injector: Injector {
                rules: rules.into_iter().map(|r| (r, None)).collect(),
                rng: fastrand::Rng::with_seed(seed),
                started: Instant::now(),
                delayed: VecDeque::new(),
                held: None,
            },
            outgoing: Vec::new(),
        }
    }
}

/// `frame` with its payload replaced by `data` of the same length.
fn with_data(frame: &Frame, data: &[u8]) -> Frame {
    let rebuilt = match frame {
        Frame::Classic(c) if !c.is_remote() => ClassicFrame::with_dlc(c.id(), c.dlc(), data)
            .map(Frame::Classic)
            .ok(),
        Frame::Fd(f) => FdFrame::new(f.id(), data, f.brs(), f.esi())
            .map(Frame::Fd)
            .ok(),
        _ => None,
    };
    rebuilt.unwrap_or(*frame)
}

fn flush(inner: &mut dyn BusTx, outgoing: &mut Vec<Frame>) -> Result<(), BusError> {
    for frame in outgoing.drain(..) {
        inner.send(&frame)?;
    }
    Ok(())
}

impl<B: Bus> BusTx for FaultyBus<B> {
    fn send(&mut self, frame: &Frame) -> Result<(), BusError> {
        self.injector.apply(frame, &mut self.outgoing);
        flush(&mut self.inner, &mut self.outgoing)
    }
}

impl<B: Bus> BusRx for FaultyBus<B> {
    fn recv(&mut self, timeout: Option<Duration>) -> Result<Option<Received>, BusError> {
        self.injector.due(&mut self.outgoing);
        flush(&mut self.inner, &mut self.outgoing)?;
        self.inner.recv(timeout)
    }

    fn stats(&self) -> Stats {
        self.inner.stats()
    }
}

impl<B: Bus + 'static> Bus for FaultyBus<B> {
    fn set_filtering(&mut self, filtering: Filtering) -> Result<(), BusError> {
        self.inner.set_filtering(filtering)
    }

    fn set_receive_own(&mut self, on: bool) -> Result<(), BusError> {
        self.inner.set_receive_own(on)
    }

    fn set_loopback(&mut self, on: bool) -> Result<(), BusError> {
        self.inner.set_loopback(on)
    }

    fn status(&self) -> Result<Option<BusStatus>, BusError> {
        self.inner.status()
    }

    /// The faults go with the sending half; delayed frames are sent by its later sends.
    fn split(self: Box<Self>) -> (Box<dyn BusTx>, Box<dyn BusRx>) {
        let FaultyBus {
            inner,
            injector,
            outgoing,
        } = *self;
        let (tx, rx) = Box::new(inner).split();
        (
            Box::new(FaultyTx {
                inner: tx,
                injector,
                outgoing,
            }),
            rx,
        )
    }
}

/// The sending half of a split faulty bus.
struct FaultyTx {
    inner: Box<dyn BusTx>,
    injector: Injector,
    outgoing: Vec<Frame>,
}

impl BusTx for FaultyTx {
    fn send(&mut self, frame: &Frame) -> Result<(), BusError> {
        self.injector.apply(frame, &mut self.outgoing);
        flush(self.inner.as_mut(), &mut self.outgoing)
    }
}
