//! Redundancy: the same command sent on two buses and voted on at the receiver
//! ([`DualVoter`]), and a 2-out-of-3 voter for a triplicated sensor ([`TripleVoter`]).
//!
//! [`DualVoter`] follows the reference logic: both copies fresh and equal → accept; one fresh
//! and the other timed out → accept the fresh one in degraded mode; both fresh but different,
//! or both timed out → fail (the caller goes to its safe state). Only copies of one command are
//! compared: with a rolling counter, those with the same counter, however far apart they came
//! ([`DualVoter::paired_by`]); without one, those that arrived within the skew window of each
//! other, or equal ones further apart (one command, late on one bus). Until a copy's partner
//! comes the vote is pending, and a copy still waiting when the other bus's last copy times out
//! is taken in degraded mode then ([`DualVoter::stale_at`] says when), not dropped.
//!
//! A bus behind the other: each bus's last eight copies are kept, so a bus more than a cycle
//! behind still has each command compared when its copy comes; a copy that comes over a
//! timeout after its partner arrives stale (its bus is as good as lost), and so does a copy the
//! caller knows to be of a command already taken whose partner is no longer kept
//! ([`DualVoter::receive_behind`]). Beyond that the counter itself cannot tell a bus half its
//! range behind from one ahead: those copies wait for partners that never come, and the
//! caller's safe state follows.

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

/// Copies kept per bus for pairing by counter: a bus up to seven cycles behind the other still
/// finds its partners.
const KEPT: usize = 8;

/// One copy as the voter keeps it.
#[derive(Debug, Clone, Copy)]
struct Kept<T> {
    value: T,
    arrived: Timestamp,
    /// From when it counts as fresh: its arrival, or its partner's when that came over a
    /// timeout before (a copy that late arrives stale: its bus is late, as good as lost);
    /// `None` for a copy stale as it came (of a command taken already, its partner gone).
    since: Option<Timestamp>,
    /// Known to be of a command taken already ([`DualVoter::receive_behind`]).
    behind: bool,
}

/// Votes on one message received on two buses.
#[derive(Debug, Clone, Copy)]
pub struct DualVoter<T> {
    /// A copy older than this is lost.
    pub timeout: Duration,
    /// Without [`paired_by`](Self::paired_by): copies arriving further apart than this are
    /// not compared (unless equal).
    pub skew: Duration,
    /// Each bus's last copies, the newest first (pairing looks past the last only with
    /// `same_command`).
    copies: [[Option<Kept<T>>; KEPT]; 2],
    same_command: Option<fn(&T, &T) -> bool>,
    /// With `same_command`: how far apart a new command's copies may come (at most two
    /// timeouts; see [`pairing_within`](Self::pairing_within)).
    horizon: Option<Duration>,
}

impl<T: Copy + PartialEq> DualVoter<T> {
    /// A voter with nothing received.
    pub fn new(timeout: Duration, skew: Duration) -> Self {
        DualVoter {
            timeout,
            skew,
            copies: [[None; KEPT]; 2],
            same_command: None,
            horizon: None,
        }
    }

    /// Pair copies by `same_command` (equal rolling counters) rather than by arrival time:
    /// copies of one command are compared however far apart they came (a late copy that
    /// contradicts its partner is a disagreement, and one whose partner came over a timeout
    /// before is stale), and copies of two commands never are (the later one waits for its
    /// partner).
    pub fn paired_by(self, same_command: fn(&T, &T) -> bool) -> Self {
        DualVoter {
            same_command: Some(same_command),
            ..self
        }
    }

    /// With [`paired_by`](Self::paired_by): a new command's copies come within `horizon` of
    /// each other, so an older copy with the same counter is of another command. Two timeouts
    /// unless set shorter; a counter that comes round sooner than that (a 1-bit counter, every
    /// second cycle) needs it shorter than its period, or each new command would be compared
    /// with the other bus's copy of the command a period before.
    pub fn pairing_within(self, horizon: Duration) -> Self {
        DualVoter {
            horizon: Some(horizon),
            ..self
        }
    }

    fn kept(&self, channel: Channel) -> &[Option<Kept<T>>; KEPT] {
        let [a, b] = &self.copies;
        match channel {
            Channel::A => a,
            Channel::B => b,
        }
    }

    /// The copy of `value`'s command on `channel`, if it came within the pairing horizon of
    /// `now` (older ones are another command: the counter has come round) or, for a copy known
    /// to be `behind`, if it is kept at all (a counter behind the one taken has not come round).
    fn partner(
        &self,
        channel: Channel,
        value: &T,
        now: Timestamp,
        behind: bool,
    ) -> Option<Kept<T>> {
        let same = self.same_command?;
        let two_timeouts = self.timeout.saturating_mul(2);
        let horizon = self.horizon.map_or(two_timeouts, |h| h.min(two_timeouts));
        self.kept(channel)
            .iter()
            .flatten()
            .find(|c| {
                (behind || now.saturating_since(c.arrived) <= horizon) && same(value, &c.value)
            })
            .copied()
    }

    /// A copy arrived on `channel`.
    pub fn receive(&mut self, channel: Channel, now: Timestamp, value: T) {
        self.keep(channel, now, value, false);
    }

    /// A copy arrived on `channel` of a command at or before the one taken last (the caller
    /// knows it from the counter): compared with its partner while that is kept, and stale as
    /// it comes without one (its bus is further behind than the copies kept reach).
    pub fn receive_behind(&mut self, channel: Channel, now: Timestamp, value: T) {
        self.keep(channel, now, value, true);
    }

    fn keep(&mut self, channel: Channel, now: Timestamp, value: T, behind: bool) {
        let since = match self.partner(channel.other(), &value, now, behind) {
            Some(p) if now.saturating_since(p.arrived) > self.timeout => p.since,
            Some(_) => Some(now),
            None if behind && self.same_command.is_some() => None,
            None => Some(now),
        };
        let copy = Kept {
            value,
            arrived: now,
            since,
            behind,
        };
        let [a, b] = &mut self.copies;
        let kept = match channel {
            Channel::A => a,
            Channel::B => b,
        };
        kept.rotate_right(1);
        if let Some(newest) = kept.first_mut() {
            *newest = Some(copy);
        }
    }

    fn last(&self, channel: Channel) -> Option<Kept<T>> {
        self.kept(channel).first().copied().flatten()
    }

    /// When the last copy from `channel` arrived (`None`: none yet).
    pub fn arrived(&self, channel: Channel) -> Option<Timestamp> {
        self.last(channel).map(|c| c.arrived)
    }

    /// When the last copy from `channel` stops counting as fresh (`None`: none yet).
    pub fn stale_at(&self, channel: Channel) -> Option<Timestamp> {
        self.last(channel).map(|c| {
            c.since.map_or(c.arrived, |since| {
                since
                    .saturating_add(self.timeout)
                    .saturating_add(Duration::from_nanos(1))
            })
        })
    }

    /// The vote at `now`, on the copy that came last: its partner's verdict, or pending
    /// until the partner comes (or degraded, or failed, as the module says).
    pub fn vote(&self, now: Timestamp) -> Vote<T> {
        let (a, b) = (self.last(Channel::A), self.last(Channel::B));
        let latest = match (a, b) {
            (Some(x), Some(y)) if y.arrived > x.arrived => Some((Channel::B, y)),
            (Some(x), _) => Some((Channel::A, x)),
            (None, y) => y.map(|y| (Channel::B, y)),
        };
        // Paired by counter: the copy that came last against its partner, however late
        // (a late copy that contradicts the command taken is a fault all the same).
        let partner = latest.and_then(|(channel, copy)| {
            let partner = self.partner(channel.other(), &copy.value, now, copy.behind)?;
            Some((copy.value, partner.value))
        });
        if partner.is_some_and(|(value, other)| value != other) {
            return Vote::Failed(VoteFailure::Disagree);
        }
        let fresh = |copy: Option<Kept<T>>| {
            copy.filter(|c| {
                c.since
                    .is_some_and(|s| now.saturating_since(s) <= self.timeout)
            })
        };
        match (fresh(a), fresh(b)) {
            (None, None) => Vote::Failed(VoteFailure::BothLost),
            (Some(x), None) => Vote::Degraded {
                value: x.value,
                healthy: Channel::A,
            },
            (None, Some(y)) => Vote::Degraded {
                value: y.value,
                healthy: Channel::B,
            },
            (Some(x), Some(y)) => {
                let paired = if self.same_command.is_some() {
                    partner
                } else {
                    let apart = if x.arrived > y.arrived {
                        x.arrived.saturating_since(y.arrived)
                    } else {
                        y.arrived.saturating_since(x.arrived)
                    };
                    (apart <= self.skew || x.value == y.value).then_some((x.value, y.value))
                };
                match paired {
                    None => Vote::Pending,
                    Some((value, other)) if value == other => Vote::Agreed(value),
                    Some(_) => Vote::Failed(VoteFailure::Disagree),
                }
            }
        }
    }
}

/// Tuning of a [`TripleVoter`] for one signal role.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TripleConfig {
    /// Two readings agree when they differ by at most this (the role's unit).
    pub tolerance: f64,
    /// A channel outvoted this long without a break is latched out.
    pub persistence: Duration,
    /// A channel with no reading for this long is silent, and latched out.
    pub timeout: Duration,
}

/// Why a channel was latched out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ChannelFault {
    /// It disagreed with the other two, which agreed, for the persistence.
    Deviating,
    /// No reading within the timeout.
    Silent,
}

/// One channel's health, as the voter last judged it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ChannelHealth {
    /// Counted in the vote.
    Healthy,
    /// Outvoted since `since`, not yet for the persistence: still counted, its reading not used.
    Suspect {
        /// When the disagreement began.
        since: Timestamp,
    },
    /// Out of the vote until [`TripleVoter::reset`].
    Out(ChannelFault),
}

/// Why a 2-out-of-3 vote has no value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TripleFailure {
    /// Three channels in, no two of them agree.
    NoMajority,
    /// Two channels left (one latched out) and they disagree: which is right cannot be told.
    Disagree,
    /// Fewer than two channels left.
    TooFew,
}

/// The outcome of a 2-out-of-3 vote.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TripleVote {
    /// Three channels in: the median when all agree, else the mean of the two that do.
    Triple(f64),
    /// Two channels left, agreeing: their mean. A second loss leaves no majority.
    Duplex(f64),
    /// No value to trust: the caller goes to its safe state.
    Failed(TripleFailure),
}

impl TripleVote {
    /// The voted value, if there is one.
    pub fn value(self) -> Option<f64> {
        match self {
            TripleVote::Triple(v) | TripleVote::Duplex(v) => Some(v),
            TripleVote::Failed(_) => None,
        }
    }
}

/// A 2-out-of-3 voter over three channels of one quantity (three steering-angle sensors, say).
///
/// Readings come in with [`receive`](Self::receive); [`vote`](Self::vote) is the one
/// transition. With three channels in, a channel that disagrees with the other two while they
/// agree is outvoted (its reading is not used) and, once that has lasted the persistence,
/// latched out; a channel silent for the timeout is latched out at once; a reading that is
/// not finite agrees with nothing. With two left the vote is 2-out-of-2: a disagreement fails
/// it, since nothing says which is right. Latched-out channels stay out until
/// [`reset`](Self::reset), which the caller keeps for a standstill and an operator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TripleVoter {
    config: TripleConfig,
    /// Each channel's last reading and when it came.
    readings: [Option<(f64, Timestamp)>; 3],
    health: [ChannelHealth; 3],
    /// When the voter started: a channel that never speaks is silent a timeout after.
    started: Timestamp,
}

impl TripleVoter {
    /// A voter started at `now` with no readings and every channel healthy.
    pub fn new(config: TripleConfig, now: Timestamp) -> Self {
        TripleVoter {
            config,
            readings: [None; 3],
            health: [ChannelHealth::Healthy; 3],
            started: now,
        }
    }

    /// The tuning.
    pub fn config(&self) -> TripleConfig {
        self.config
    }

    /// A reading from `channel` (0, 1 or 2; others are ignored).
    pub fn receive(&mut self, channel: usize, now: Timestamp, value: f64) {
        if let Some(slot) = self.readings.get_mut(channel) {
            *slot = Some((value, now));
        }
    }

    /// The last reading from `channel` (0, 1 or 2), voted or not.
    pub fn reading(&self, channel: usize) -> Option<f64> {
        self.readings
            .get(channel)
            .copied()
            .flatten()
            .map(|(value, _)| value)
    }

    /// Each channel's health after the last vote.
    pub fn health(&self) -> [ChannelHealth; 3] {
        self.health
    }

    /// Whether `vote`, this voter's last, is a loss: no value because channels disagree or
    /// are out, not because they have yet to speak since start or reset.
    pub fn lost(&self, vote: TripleVote) -> bool {
        match vote {
            TripleVote::Failed(TripleFailure::TooFew) => {
                self.health
                    .iter()
                    .filter(|h| matches!(h, ChannelHealth::Out(_)))
                    .count()
                    >= 2
            }
            TripleVote::Failed(_) => true,
            TripleVote::Triple(_) | TripleVote::Duplex(_) => false,
        }
    }

    /// When the voter next judges on time alone, not on a reading: the earliest instant a
    /// channel still in would be silent, or a suspect channel's persistence ends. A caller
    /// votes when a reading arrives and at this instant, never on a poll of its own, so that
    /// two voters given the same readings (an A/B pair's) latch the same channel at the same
    /// instant whatever else each is polled for.
    pub fn next_deadline(&self) -> Option<Timestamp> {
        let one_ns = Duration::from_nanos(1);
        // Persistence counts only with all three in: two left vote 2-out-of-2.
        let three_in = !self
            .health
            .iter()
            .any(|h| matches!(h, ChannelHealth::Out(_)));
        self.health
            .iter()
            .zip(self.readings)
            .filter_map(|(health, reading)| {
                let heard = reading.map_or(self.started, |(_, at)| at);
                let silent = heard
                    .saturating_add(self.config.timeout)
                    .saturating_add(one_ns);
                match health {
                    ChannelHealth::Out(_) => None,
                    ChannelHealth::Healthy => Some(silent),
                    ChannelHealth::Suspect { since } if three_in => {
                        Some(silent.min(since.saturating_add(self.config.persistence)))
                    }
                    ChannelHealth::Suspect { .. } => Some(silent),
                }
            })
            .min()
    }

    /// Every channel back in, as at start (for the caller's standstill reset).
    pub fn reset(&mut self, now: Timestamp) {
        self.health = [ChannelHealth::Healthy; 3];
        self.readings = [None; 3];
        self.started = now;
    }

    /// The vote at `now`, judging each channel's health on the way.
    pub fn vote(&mut self, now: Timestamp) -> TripleVote {
        let config = self.config;
        let started = self.started;
        // Silence first: a silent channel is out before the others are compared.
        for (health, reading) in self.health.iter_mut().zip(self.readings) {
            let heard = reading.map_or(started, |(_, at)| at);
            if !matches!(health, ChannelHealth::Out(_))
                && now.saturating_since(heard) > config.timeout
            {
                *health = ChannelHealth::Out(ChannelFault::Silent);
            }
        }
        let value = |i: usize| match (self.health.get(i), self.readings.get(i)) {
            (Some(ChannelHealth::Out(_)), _) | (None, _) | (_, None | Some(None)) => None,
            (_, Some(Some((v, _)))) => Some(*v),
        };
        let agree =
            |x: f64, y: f64| x.is_finite() && y.is_finite() && (x - y).abs() <= config.tolerance;
        match (value(0), value(1), value(2)) {
            (Some(a), Some(b), Some(c)) => {
                let (ab, ac, bc) = (agree(a, b), agree(a, c), agree(b, c));
                // The channel that agrees with neither of two that agree, if any.
                let outlier = match (ab, ac, bc) {
                    (true, false, false) => Some(2),
                    (false, true, false) => Some(1),
                    (false, false, true) => Some(0),
                    _ => None,
                };
                if !(ab || ac || bc) {
                    return TripleVote::Failed(TripleFailure::NoMajority);
                }
                for (i, health) in self.health.iter_mut().enumerate() {
                    *health = match (*health, outlier == Some(i)) {
                        (ChannelHealth::Suspect { since }, true)
                            if now.saturating_since(since) >= config.persistence =>
                        {
                            ChannelHealth::Out(ChannelFault::Deviating)
                        }
                        (ChannelHealth::Suspect { since }, true) => {
                            ChannelHealth::Suspect { since }
                        }
                        (ChannelHealth::Healthy, true) if config.persistence.is_zero() => {
                            ChannelHealth::Out(ChannelFault::Deviating)
                        }
                        (ChannelHealth::Healthy, true) => ChannelHealth::Suspect { since: now },
                        (ChannelHealth::Out(fault), _) => ChannelHealth::Out(fault),
                        (_, false) => ChannelHealth::Healthy,
                    };
                }
                TripleVote::Triple(match outlier {
                    Some(0) => (b + c) / 2.0,
                    Some(1) => (a + c) / 2.0,
                    Some(_) => (a + b) / 2.0,
                    // All agree, or the middle one agrees with both ends: the median.
                    None => a.max(b).min(a.min(b).max(c)),
                })
            }
            (Some(x), Some(y), None) | (Some(x), None, Some(y)) | (None, Some(x), Some(y)) => {
                if agree(x, y) {
                    for health in &mut self.health {
                        if let ChannelHealth::Suspect { .. } = health {
                            *health = ChannelHealth::Healthy;
                        }
                    }
                    TripleVote::Duplex((x + y) / 2.0)
                } else {
                    TripleVote::Failed(TripleFailure::Disagree)
                }
            }
            _ => TripleVote::Failed(TripleFailure::TooFew),
        }
    }
}
