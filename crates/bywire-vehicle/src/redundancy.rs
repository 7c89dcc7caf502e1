//! Redundancy: the same command sent on two buses and voted on at the receiver, and a
//! 2-out-of-3 voter for triplicated sensors.
//!
//! [`DualVoter`] follows the reference logic: both copies fresh and equal → accept; one fresh
//! and the other timed out → accept the fresh one in degraded mode; both fresh but different,
//! or both timed out → fail (the caller goes to its safe state). Only copies of one command are
//! compared: with a rolling counter, those with the same counter, however far apart they came
//! ([`DualVoter::paired_by`]); without one, those that arrived within the skew window of each
//! other, or equal ones further apart (one command, late on one bus). Until a copy's partner
//! comes the vote is pending, and a copy still waiting when the other bus's last copy times out
//! is taken in degraded mode then ([`DualVoter::stale_at`] says when), not dropped.

use core::time::Duration;

use bywire_core::Timestamp;

/// Which bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Channel {
    /// The first bus.
    A,
    /// The second bus.
    B,
}

impl Channel {
    /// The other bus.
    pub const fn other(self) -> Channel {
        match self {
            Channel::A => Channel::B,
            Channel::B => Channel::A,
        }
    }

    /// The node port of this command bus, the same at both ends (the ADS side and the
    /// supervisor): bus A on port 0, bus B on port 1.
    pub const fn port(self) -> bywire_core::node::Port {
        match self {
            Channel::A => bywire_core::node::Port(0),
            Channel::B => bywire_core::node::Port(1),
        }
    }
}

/// Why a vote failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum VoteFailure {
    /// Nothing fresh from either bus.
    BothLost,
    /// Fresh copies that differ.
    Disagree,
}

/// The outcome of a vote.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Vote<T> {
    /// Both copies agree.
    Agreed(T),
    /// Only one bus delivers.
    Degraded {
        /// The value from the healthy bus.
        value: T,
        /// Which bus is healthy.
        healthy: Channel,
    },
    /// The copies arrived too far apart to compare yet.
    Pending,
    /// Go to the safe state.
    Failed(VoteFailure),
}

/// Votes on one message received on two buses.
#[derive(Debug, Clone, Copy)]
pub struct DualVoter<T> {
    /// A copy older than this is lost.
    pub timeout: Duration,
    /// Without [`paired_by`](Self::paired_by): copies arriving further apart than this are
    /// not compared (unless equal).
    pub skew: Duration,
    a: Option<(Timestamp, T)>,
    b: Option<(Timestamp, T)>,
    same_command: Option<fn(&T, &T) -> bool>,
}

impl<T: Copy + PartialEq> DualVoter<T> {
    /// A voter with nothing received.
    pub fn new(timeout: Duration, skew: Duration) -> Self {
        DualVoter {
            timeout,
            skew,
            a: None,
            b: None,
            same_command: None,
        }
    }

    /// Pair copies by `same_command` (equal rolling counters) rather than by arrival time:
    /// copies of one command are compared however far apart they came, and copies of two
    /// commands never are (the later one waits for its partner).
    pub fn paired_by(self, same_command: fn(&T, &T) -> bool) -> Self {
        DualVoter {
            same_command: Some(same_command),
            ..self
        }
    }

    /// A copy arrived on `channel`.
    pub fn receive(&mut self, channel: Channel, now: Timestamp, value: T) {
        match channel {
            Channel::A => self.a = Some((now, value)),
            Channel::B => self.b = Some((now, value)),
        }
    }

    fn last(&self, channel: Channel) -> Option<(Timestamp, T)> {
        match channel {
            Channel::A => self.a,
            Channel::B => self.b,
        }
    }

    /// When the last copy from `channel` arrived (`None`: none yet).
    pub fn arrived(&self, channel: Channel) -> Option<Timestamp> {
        self.last(channel).map(|(at, _)| at)
    }

    /// When the last copy from `channel` stops counting as fresh (`None`: none yet).
    pub fn stale_at(&self, channel: Channel) -> Option<Timestamp> {
        self.arrived(channel).map(|at| {
            at.saturating_add(self.timeout)
                .saturating_add(Duration::from_nanos(1))
        })
    }

    /// The vote at `now`.
    pub fn vote(&self, now: Timestamp) -> Vote<T> {
        let fresh = |copy: Option<(Timestamp, T)>| {
            copy.filter(|(at, _)| now.saturating_since(*at) <= self.timeout)
        };
        match (fresh(self.a), fresh(self.b)) {
            (None, None) => Vote::Failed(VoteFailure::BothLost),
            (Some((_, value)), None) => Vote::Degraded {
                value,
                healthy: Channel::A,
            },
            (None, Some((_, value))) => Vote::Degraded {
                value,
                healthy: Channel::B,
            },
            (Some((ta, va)), Some((tb, vb))) => {
                let apart = if ta > tb {
                    ta.saturating_since(tb)
                } else {
                    tb.saturating_since(ta)
                };
                let one_command = match self.same_command {
                    Some(same) => same(&va, &vb),
                    None => apart <= self.skew || va == vb,
                };
                match (one_command, va == vb) {
                    (false, _) => Vote::Pending,
                    (true, true) => Vote::Agreed(va),
                    (true, false) => Vote::Failed(VoteFailure::Disagree),
                }
            }
        }
    }
}

/// The outcome of a 2-out-of-3 vote.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TwoOfThree {
    /// All three agree: their median.
    Agreed(f64),
    /// Two agree: their mean, and the index of the one outvoted.
    Outvoted {
        /// The voted value.
        value: f64,
        /// The sensor that disagreed (or was not finite).
        outlier: usize,
    },
    /// No two agree.
    Failed,
}

/// Vote on three readings of one quantity: two agree when within `tolerance` of each other.
pub fn two_of_three(readings: [f64; 3], tolerance: f64) -> TwoOfThree {
    let agree = |x: f64, y: f64| x.is_finite() && y.is_finite() && (x - y).abs() <= tolerance;
    let [a, b, c] = readings;
    match (agree(a, b), agree(a, c), agree(b, c)) {
        (true, true, true) => {
            let median = a.max(b).min(a.min(b).max(c));
            TwoOfThree::Agreed(median)
        }
        (true, _, _) => TwoOfThree::Outvoted {
            value: (a + b) / 2.0,
            outlier: 2,
        },
        (_, true, _) => TwoOfThree::Outvoted {
            value: (a + c) / 2.0,
            outlier: 1,
        },
        (_, _, true) => TwoOfThree::Outvoted {
            value: (b + c) / 2.0,
            outlier: 0,
        },
        _ => TwoOfThree::Failed,
    }
}
