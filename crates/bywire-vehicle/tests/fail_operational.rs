//! The fail-operational mechanisms checked over their whole (bounded) state spaces: the
//! 2-out-of-3 voter against an independent statement of its rules, the A/B arbitration over
//! every interleaving of two sides, lost heartbeats and single faults, the actuator pair and
//! the degradation latch over every short sequence of what they can be told.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    missing_docs
)]

mod common;

use std::collections::HashSet;
use std::time::Duration;

use bywire_core::Timestamp;
use bywire_vehicle::arbitration::{
    Arbiter, ArbiterConfig, ArbiterInputs, Heartbeat, OutReason, Role, Side, TakeoverReason,
};
use bywire_vehicle::backup::{ActuatorFault, ActuatorPair, Feedback, FeedbackCheck, InCharge};
use bywire_vehicle::command::{DegradationLevel, FaultClass, SteeringMode};
use bywire_vehicle::degradation::{Degradation, DegradationPolicy, Fault, SteeringModes};
use bywire_vehicle::redundancy::{
    ChannelFault, ChannelHealth, TripleConfig, TripleFailure, TripleVote, TripleVoter,
};

fn ms(t: u64) -> Timestamp {
    Timestamp::from_millis(t)
}

// ---------------------------------------------------------------- the 2-out-of-3 voter

/// What one channel does in one step of the model.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Reading {
    /// The true value.
    Good,
    /// Far from it (stuck, drifted, or a second agreeing pair elsewhere).
    Off,
    /// Nothing this step.
    Silent,
}

const GOOD: f64 = 10.0;
const OFF: f64 = 12.0;
const TRIPLE: TripleConfig = TripleConfig {
    tolerance: 0.5,
    persistence: Duration::from_millis(20),
    timeout: Duration::from_millis(25),
};
const TRIPLE_STEP: u64 = 10;

/// The model's own account of one channel: its last reading and when, and whether it is in.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Channel {
    last: Option<(f64, Timestamp)>,
    out: Option<ChannelFault>,
    /// Since when it has been the lone dissenter from an agreeing pair.
    dissenting_since: Option<Timestamp>,
}

/// The rules of `TripleVoter`'s documentation, stated again from scratch: one step of the
/// reference model, returning the vote it expects.
fn reference_vote(channels: &mut [Channel; 3], now: Timestamp, started: Timestamp) -> TripleVote {
    for c in channels.iter_mut() {
        let heard = c.last.map_or(started, |(_, at)| at);
        if c.out.is_none() && now.saturating_since(heard) > TRIPLE.timeout {
            c.out = Some(ChannelFault::Silent);
        }
    }
    let agree =
        |x: f64, y: f64| x.is_finite() && y.is_finite() && (x - y).abs() <= TRIPLE.tolerance;
    let live: Vec<(usize, f64)> = channels
        .iter()
        .enumerate()
        .filter(|(_, c)| c.out.is_none())
        .filter_map(|(i, c)| c.last.map(|(v, _)| (i, v)))
        .collect();
    match live.len() {
        3 => {
            let v = [live[0].1, live[1].1, live[2].1];
            let agrees_with = |i: usize| (0..3).filter(|&j| j != i && agree(v[i], v[j])).count();
            if (0..3).all(|i| agrees_with(i) == 0) {
                return TripleVote::Failed(TripleFailure::NoMajority);
            }
            let dissenter = (0..3).find(|&i| {
                agrees_with(i) == 0 && (0..3).filter(|&j| j != i).all(|j| agrees_with(j) == 1)
            });
            for (i, c) in channels.iter_mut().enumerate() {
                if dissenter == Some(i) {
                    let since = *c.dissenting_since.get_or_insert(now);
                    if now.saturating_since(since) >= TRIPLE.persistence {
                        c.out = Some(ChannelFault::Deviating);
                        c.dissenting_since = None;
                    }
                } else {
                    c.dissenting_since = None;
                }
            }
            match dissenter {
                Some(d) => {
                    let pair: Vec<f64> = (0..3).filter(|&i| i != d).map(|i| v[i]).collect();
                    TripleVote::Triple((pair[0] + pair[1]) / 2.0)
                }
                None => {
                    let mut sorted = v;
                    sorted.sort_by(f64::total_cmp);
                    TripleVote::Triple(sorted[1])
                }
            }
        }
        2 => {
            for c in channels.iter_mut() {
                c.dissenting_since = None;
            }
            let (x, y) = (live[0].1, live[1].1);
            if agree(x, y) {
                TripleVote::Duplex((x + y) / 2.0)
            } else {
                TripleVote::Failed(TripleFailure::Disagree)
            }
        }
        _ => TripleVote::Failed(TripleFailure::TooFew),
    }
}

fn same_vote(a: TripleVote, b: TripleVote) -> bool {
    match (a, b) {
        (TripleVote::Triple(x), TripleVote::Triple(y))
        | (TripleVote::Duplex(x), TripleVote::Duplex(y)) => (x - y).abs() < 1e-12,
        (x, y) => x == y,
    }
}

/// How many steps the 2-out-of-3 voter is explored to.
const DEPTH_2OO3: u64 = 7;

/// Every sequence of `DEPTH` steps (each channel good, off or silent at each) voted by
/// `vote` and checked against the rules: the states (voter and model) and transitions
/// explored, or the first violation.
fn explore_2oo3(
    vote_with: impl Fn(&mut TripleVoter, Timestamp) -> TripleVote,
) -> Result<(usize, u64), String> {
    // A reading that is not a number disagrees with everything, as `Off` does with `Good`;
    // the test below has one.
    const ALPHABET: [Reading; 3] = [Reading::Good, Reading::Off, Reading::Silent];
    let started = ms(0);
    let mut level = vec![(
        TripleVoter::new(TRIPLE, started),
        [Channel {
            last: None,
            out: None,
            dissenting_since: None,
        }; 3],
    )];
    let mut checked = 0u64;
    let mut states = 1usize;
    for depth in 1..=DEPTH_2OO3 {
        let now = ms(depth * TRIPLE_STEP);
        let mut next = Vec::new();
        let mut seen = HashSet::new();
        for (voter, model) in &level {
            for inputs in 0..ALPHABET.len().pow(3) {
                let mut voter = *voter;
                let mut model = *model;
                let readings = [inputs % 3, (inputs / 3) % 3, inputs / 9].map(|i| ALPHABET[i]);
                for (i, reading) in readings.iter().enumerate() {
                    let value = match reading {
                        Reading::Good => GOOD,
                        Reading::Off => OFF,
                        Reading::Silent => continue,
                    };
                    voter.receive(i, now, value);
                    model[i].last = Some((value, now));
                }
                let before = voter.health();
                let vote = vote_with(&mut voter, now);
                let expected = reference_vote(&mut model, now, started);
                if !same_vote(vote, expected) {
                    return Err(format!(
                        "at {now:?} after {readings:?}: voted {vote:?}, the rules say {expected:?}"
                    ));
                }
                for (i, (was, is)) in before.iter().zip(voter.health()).enumerate() {
                    // Out is for good; in or out agrees with the model.
                    if let ChannelHealth::Out(fault) = was {
                        assert_eq!(is, ChannelHealth::Out(*fault));
                    }
                    assert_eq!(
                        matches!(is, ChannelHealth::Out(_))
                            .then(|| model[i].out)
                            .flatten(),
                        match is {
                            ChannelHealth::Out(f) => Some(f),
                            _ => None,
                        }
                    );
                    assert_eq!(model[i].out.is_some(), matches!(is, ChannelHealth::Out(_)));
                }
                // The value, when there is one, is the reading of two channels still in.
                if let Some(v) = vote.value() {
                    let backing = (0..3)
                        .filter(|&i| model[i].out.is_none())
                        .filter(|&i| {
                            model[i]
                                .last
                                .is_some_and(|(r, _)| (r - v).abs() <= TRIPLE.tolerance)
                        })
                        .count();
                    if backing < 2 {
                        return Err(format!("{v} backed by {backing} channels"));
                    }
                }
                // Without a new reading the health holds until the voter's deadline and
                // changes at it: a voter polled for nothing else latches exactly then.
                if let Some(deadline) = voter.next_deadline() {
                    assert!(deadline > now, "{deadline:?} not after {now:?}");
                    let just_before = Timestamp::from_nanos(deadline.as_nanos() - 1);
                    let mut early = voter;
                    early.vote(just_before);
                    assert_eq!(
                        early.health(),
                        voter.health(),
                        "changed before {deadline:?}"
                    );
                    let mut due = voter;
                    due.vote(deadline);
                    assert_ne!(due.health(), voter.health(), "nothing at {deadline:?}");
                } else {
                    assert!(voter
                        .health()
                        .iter()
                        .all(|h| matches!(h, ChannelHealth::Out(_))));
                }
                checked += 1;
                if seen.insert(format!("{voter:?}{model:?}")) {
                    next.push((voter, model));
                }
            }
        }
        states += next.len();
        level = next;
    }
    Ok((states, checked))
}

/// Verifies: REQ-VOT-1.
#[test]
fn the_2oo3_voter_follows_its_rules_over_every_sequence_of_seven_steps() {
    let started_at = std::time::Instant::now();
    let (states, checked) = explore_2oo3(|voter, now| voter.vote(now)).unwrap();
    assert!(checked > 100_000, "only {checked} transitions");
    common::record_state_space(
        "2oo3-voter",
        &["REQ-VOT-1"],
        (states, checked, usize::try_from(DEPTH_2OO3).unwrap(), false),
        started_at.elapsed(),
    );
}

/// Verifies: REQ-VOT-1.
#[test]
fn a_planted_defect_in_the_2oo3_voter_is_found() {
    // A planted defect: two channels left and disagreeing, the first one's reading is trusted.
    let found = explore_2oo3(|voter, now| match voter.vote(now) {
        TripleVote::Failed(TripleFailure::Disagree) => {
            let first_in = (0..3).find(|&i| !matches!(voter.health()[i], ChannelHealth::Out(_)));
            match first_in.and_then(|i| voter.reading(i)) {
                Some(reading) => TripleVote::Duplex(reading),
                None => TripleVote::Failed(TripleFailure::Disagree),
            }
        }
        vote => vote,
    })
    .unwrap_err();
    assert!(found.contains("the rules say Failed(Disagree)"), "{found}");
}

/// Verifies: REQ-VOT-1.
#[test]
fn a_channel_that_dissents_for_the_persistence_is_latched_out_and_a_silent_one_at_once() {
    let mut voter = TripleVoter::new(TRIPLE, ms(0));
    assert_eq!(voter.reading(1), None, "nothing read yet");
    voter.receive(1, ms(0), 9.5);
    assert_eq!(voter.reading(1), Some(9.5));
    for t in (0..=20).step_by(10) {
        let expected = if t == 0 {
            ChannelHealth::Healthy
        } else {
            ChannelHealth::Suspect { since: ms(0) }
        };
        assert_eq!(voter.health()[2], expected);
        voter.receive(0, ms(t), 10.0);
        voter.receive(1, ms(t), 10.1);
        voter.receive(2, ms(t), 14.0);
        let vote = voter.vote(ms(t));
        assert!(same_vote(vote, TripleVote::Triple(10.05)), "{vote:?}");
    }
    assert_eq!(
        voter.health()[2],
        ChannelHealth::Out(ChannelFault::Deviating)
    );
    // Back in agreement, it stays out; two left vote 2-out-of-2.
    voter.receive(2, ms(50), 10.0);
    voter.receive(0, ms(50), 10.0);
    voter.receive(1, ms(50), 10.0);
    assert_eq!(voter.vote(ms(50)), TripleVote::Duplex(10.0));
    // Channel 1 goes quiet: after the timeout it is out and one channel is too few.
    voter.receive(0, ms(80), 10.0);
    assert_eq!(
        voter.vote(ms(80)),
        TripleVote::Failed(TripleFailure::TooFew)
    );
    assert_eq!(voter.health()[1], ChannelHealth::Out(ChannelFault::Silent));
    voter.reset(ms(100));
    assert_eq!(voter.health(), [ChannelHealth::Healthy; 3]);
    // A reading that is not a number is outvoted like any other dissenter.
    for (i, value) in [10.0, 10.2, f64::NAN].into_iter().enumerate() {
        voter.receive(i, ms(110), value);
    }
    assert_eq!(voter.vote(ms(110)), TripleVote::Triple(10.1));
    assert_eq!(voter.health()[2], ChannelHealth::Suspect { since: ms(110) });
    voter.receive(2, ms(110), f64::INFINITY);
    voter.receive(1, ms(110), f64::NAN);
    assert_eq!(
        voter.vote(ms(110)),
        TripleVote::Failed(TripleFailure::NoMajority)
    );
}

// ---------------------------------------------------------------- A/B arbitration

/// One tick of the arbitration model: both sides step once, heartbeats every tick.
const TICK: u64 = 5;
const ARBITER: ArbiterConfig = ArbiterConfig {
    silence: Duration::from_millis(20),
    disagreement: Duration::from_millis(15),
    deaf: Duration::from_millis(20),
};
/// Heartbeats lost in a row that must never cause a takeover (silence covers four ticks).
const TOLERATED_LOSSES: u8 = 3;
/// The longest time with neither side in control under one fault (and up to the tolerated
/// losses): the silence timeout and three ticks, as the model finds it. The worst case: A's
/// receiver fails just after a frame, A steps out a timeout and a tick later, and B takes
/// over one to two ticks after that, as the steps fall.
const TAKEOVER_BOUND: Duration = Duration::from_millis(20 + 3 * TICK);

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum SingleFault {
    /// A stops: no heartbeat, no outputs.
    ACrash,
    /// A's self-test fails.
    ASelfTest,
    /// A computes a wrong output (B's comparison disagrees from then on).
    AWrongOutput,
    /// A's receiver fails: A hears neither B nor anything else.
    ADeaf,
    /// B stops.
    BCrash,
    /// B's self-test fails.
    BSelfTest,
    /// B's receiver fails: B hears neither A nor anything else.
    BDeaf,
}

const FAULTS: [SingleFault; 7] = [
    SingleFault::ACrash,
    SingleFault::ASelfTest,
    SingleFault::AWrongOutput,
    SingleFault::ADeaf,
    SingleFault::BCrash,
    SingleFault::BSelfTest,
    SingleFault::BDeaf,
];

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
struct World {
    a: Arbiter,
    b: Arbiter,
    /// A's last heartbeat as B received it, and B's as A received it.
    a_heard_by_b: Option<Heartbeat>,
    b_heard_by_a: Option<Heartbeat>,
    /// When each side last received anything (the ADS's commands come every tick).
    traffic_at_a: Option<Timestamp>,
    traffic_at_b: Option<Timestamp>,
    fault: Option<(SingleFault, Timestamp)>,
    /// A's heartbeats lost in a row on the way to B (counted up to one past the tolerance).
    losses: u8,
    /// More were lost in a row than the tolerance at some point.
    lossy: bool,
    /// Since when neither side's outputs reach the actuators.
    neither_since: Option<Timestamp>,
}

impl World {
    fn new() -> World {
        World {
            a: Arbiter::new(Side::A, ARBITER, ms(0)),
            b: Arbiter::new(Side::B, ARBITER, ms(0)),
            a_heard_by_b: None,
            b_heard_by_a: None,
            traffic_at_a: None,
            traffic_at_b: None,
            fault: None,
            losses: 0,
            lossy: false,
            neither_since: None,
        }
    }

    fn has(&self, fault: SingleFault) -> bool {
        self.fault.is_some_and(|(f, _)| f == fault)
    }

    fn alive(&self, side: Side) -> bool {
        !self.has(match side {
            Side::A => SingleFault::ACrash,
            Side::B => SingleFault::BCrash,
        })
    }

    /// Whose outputs reach the actuators: a side's own role, cut by its partner's fence.
    fn transmitting(&self) -> (bool, bool) {
        (
            self.alive(Side::A) && self.a.transmits(self.b.fences_partner()),
            self.alive(Side::B) && self.b.transmits(self.a.fences_partner()),
        )
    }

    /// Who is in control: transmitting, and hearing the commands it acts on.
    fn in_control(&self) -> (bool, bool) {
        let (a, b) = self.transmitting();
        (
            a && !self.has(SingleFault::ADeaf),
            b && !self.has(SingleFault::BDeaf),
        )
    }

    fn step_a(&mut self, now: Timestamp, lost: bool) {
        if !self.alive(Side::A) {
            return;
        }
        if !self.has(SingleFault::ADeaf) {
            self.traffic_at_a = Some(now);
        }
        let role = self.a.step(
            now,
            ArbiterInputs {
                self_test_ok: !self.has(SingleFault::ASelfTest),
                partner: self.b_heard_by_a,
                traffic_at: self.traffic_at_a,
                outputs_agree: None,
                fenced: self.b.fences_partner(),
            },
        );
        if lost {
            self.losses = (self.losses + 1).min(TOLERATED_LOSSES + 1);
            self.lossy |= self.losses > TOLERATED_LOSSES;
        } else if !self.has(SingleFault::BDeaf) {
            self.losses = 0;
            self.a_heard_by_b = Some(Heartbeat { role, at: now });
        }
    }

    fn step_b(&mut self, now: Timestamp) {
        if !self.alive(Side::B) {
            return;
        }
        let deaf = self.has(SingleFault::BDeaf);
        if !deaf {
            self.traffic_at_b = Some(now);
        }
        let a_transmits = self.transmitting().0;
        let role = self.b.step(
            now,
            ArbiterInputs {
                self_test_ok: !self.has(SingleFault::BSelfTest),
                partner: self.a_heard_by_b,
                traffic_at: self.traffic_at_b,
                outputs_agree: (a_transmits && !deaf).then(|| !self.has(SingleFault::AWrongOutput)),
                fenced: self.a.fences_partner(),
            },
        );
        if !self.has(SingleFault::ADeaf) {
            self.b_heard_by_a = Some(Heartbeat { role, at: now });
        }
    }
}

/// Verifies: REQ-AB-1.
#[test]
fn never_both_in_control_never_neither_too_long_over_every_interleaving() {
    const DEPTH: u64 = 28;
    let mut level: HashSet<World> = HashSet::from([World::new()]);
    let mut transitions = 0u64;
    let mut takeovers = HashSet::new();
    let mut longest = Duration::ZERO;
    for tick in 1..=DEPTH {
        let now = ms(tick * TICK);
        let mut next = HashSet::new();
        for world in &level {
            let faults: Vec<Option<SingleFault>> = match world.fault {
                Some(_) => vec![None],
                None => std::iter::once(None).chain(FAULTS.map(Some)).collect(),
            };
            for fault in faults {
                for a_first in [true, false] {
                    for lost in [false, true] {
                        let mut w = *world;
                        if let Some(f) = fault {
                            w.fault = Some((f, now));
                        }
                        if a_first {
                            w.step_a(now, lost);
                            w.step_b(now);
                        } else {
                            w.step_b(now);
                            w.step_a(now, lost);
                        }
                        let (a, b) = w.transmitting();
                        assert!(!(a && b), "both transmitting at {now:?}: {w:?}");
                        let (a, b) = w.in_control();
                        w.neither_since = match (a || b, w.neither_since) {
                            (true, _) => None,
                            (false, since) => Some(since.unwrap_or(now)),
                        };
                        // Lost heartbeats beyond the tolerance are a fault of their own:
                        // with another on top, neither may be left (the actuators' safe stop).
                        let single = !(w.lossy && w.fault.is_some());
                        if let Some(since) = w.neither_since.filter(|_| single) {
                            longest = longest.max(now.saturating_since(since));
                            assert!(
                                now.saturating_since(since) <= TAKEOVER_BOUND,
                                "neither in control since {since:?} at {now:?}: {w:?}"
                            );
                        }
                        // Without a fault and with no more than the tolerated losses in a row,
                        // A stays in control and B stands by.
                        if w.fault.is_none() && !w.lossy {
                            assert_eq!(
                                (w.a.role(), w.b.role()),
                                (Role::Active, Role::Standby),
                                "{w:?}"
                            );
                        }
                        // A wrong output is taken over from within the disagreement time.
                        if let Some((SingleFault::AWrongOutput, at)) = w.fault {
                            if now.saturating_since(at)
                                > ARBITER.disagreement + Duration::from_millis(TICK)
                            {
                                assert!(b && !a, "B has not taken over from a wrong A: {w:?}");
                            }
                        }
                        if let Some(reason) = w.b.took_over() {
                            takeovers.insert((w.fault.map(|(f, _)| f), reason));
                        }
                        transitions += 1;
                        next.insert(w);
                    }
                }
            }
        }
        level = next;
    }
    // The model reaches every kind of takeover, and a deaf standby steps out.
    for reason in [
        TakeoverReason::PartnerSilent,
        TakeoverReason::PartnerReportedOut,
        TakeoverReason::OutputsDisagree,
    ] {
        assert!(
            takeovers.iter().any(|&(_, r)| r == reason),
            "{reason:?} never reached"
        );
    }
    assert!(takeovers.contains(&(Some(SingleFault::ACrash), TakeoverReason::PartnerSilent)));
    assert!(level
        .iter()
        .any(|w| w.b.role() == Role::Out(OutReason::Deaf) && w.a.role() == Role::Active));
    assert_eq!(longest, TAKEOVER_BOUND, "the bound is not tight");
    assert!(transitions > 100_000, "only {transitions} transitions");
}

/// Verifies: REQ-AB-1.
#[test]
fn the_taken_over_side_is_fenced_and_stays_out() {
    let mut a = Arbiter::new(Side::A, ARBITER, ms(0));
    let mut b = Arbiter::new(Side::B, ARBITER, ms(0));
    let beat = |role, at| Some(Heartbeat { role, at });
    let quiet = ArbiterInputs {
        self_test_ok: true,
        partner: None,
        traffic_at: None,
        outputs_agree: None,
        fenced: false,
    };
    assert_eq!(
        b.step(
            ms(10),
            ArbiterInputs {
                partner: beat(Role::Out(OutReason::SelfTest), ms(10)),
                traffic_at: Some(ms(10)),
                ..quiet
            }
        ),
        Role::Active
    );
    assert!(b.fences_partner());
    assert_eq!(
        a.step(
            ms(12),
            ArbiterInputs {
                fenced: true,
                ..quiet
            }
        ),
        Role::Out(OutReason::Fenced)
    );
    assert_eq!(a.step(ms(14), quiet), Role::Out(OutReason::Fenced));
    assert!(!a.transmits(false));
    a.reset(ms(20));
    assert_eq!(a.role(), Role::Active);
}

// ---------------------------------------------------------------- primary and backup actuator

const CHECK: FeedbackCheck = FeedbackCheck {
    still: 1.0,
    overrun: 5.0,
    persistence: Duration::from_millis(30),
    heartbeat_timeout: Duration::from_millis(50),
};
const ACTUATOR_STEP: u64 = 10;

/// Faster than demanded by exactly the overrun is still tracking; beyond it, a runaway.
#[test]
fn an_actuator_at_the_overrun_tracks_and_one_past_it_runs_away() {
    for (excess, switches) in [(CHECK.overrun, false), (CHECK.overrun + 0.01, true)] {
        let mut pair = ActuatorPair::new(CHECK, ms(0));
        for t in (0..=100).step_by(10) {
            pair.step(
                ms(t),
                Feedback {
                    demanded: 10.0,
                    measured: 10.0 + excess,
                    drive_fault: false,
                    heartbeat_at: Some(ms(t)),
                },
            );
        }
        assert_eq!(
            pair.primary_failed().map(|(fault, _)| fault),
            switches.then_some(ActuatorFault::Runaway),
            "{excess}"
        );
        assert_eq!(pair.check(), CHECK);
    }
    assert_eq!(
        CHECK.bound(ActuatorFault::HeartbeatLost),
        CHECK.heartbeat_timeout
    );
    assert_eq!(CHECK.bound(ActuatorFault::Runaway), CHECK.persistence);
}

/// A mode named twice in a profile's list is allowed once, not toggled off.
#[test]
fn a_steering_mode_listed_twice_is_still_allowed() {
    let modes = SteeringModes::only(&[SteeringMode::Normal, SteeringMode::Normal]);
    assert!(modes.allows(SteeringMode::Normal));
    assert!(!modes.allows(SteeringMode::Crab));
}

/// What the actuator in charge does in one step of the model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Behaviour {
    Follows,
    Stuck,
    Reversed,
    RunsAway,
    ReportsFault,
    Mute,
}

const BEHAVIOURS: [Behaviour; 6] = [
    Behaviour::Follows,
    Behaviour::Stuck,
    Behaviour::Reversed,
    Behaviour::RunsAway,
    Behaviour::ReportsFault,
    Behaviour::Mute,
];

fn feedback(
    behaviour: Behaviour,
    demanded: f64,
    now: Timestamp,
    heartbeat: Option<Timestamp>,
) -> Feedback {
    let measured = match behaviour {
        Behaviour::Follows | Behaviour::ReportsFault | Behaviour::Mute => demanded,
        Behaviour::Stuck => 0.0,
        Behaviour::Reversed => -demanded,
        Behaviour::RunsAway => demanded + 20.0,
    };
    Feedback {
        demanded,
        measured,
        drive_fault: behaviour == Behaviour::ReportsFault,
        heartbeat_at: if behaviour == Behaviour::Mute {
            heartbeat
        } else {
            Some(now)
        },
    }
}

/// Verifies: REQ-ACT-1.
#[test]
fn the_actuator_pair_switches_exactly_when_a_fault_has_lasted_its_bound() {
    // State: the pair, the heartbeat last heard, and since when the actuator in charge has
    // misbehaved (and how); every sequence of behaviours over 9 steps.
    type State = (u64, ActuatorPair, Option<Timestamp>, Option<Timestamp>);
    let mut level: Vec<State> = vec![(0, ActuatorPair::new(CHECK, ms(0)), Some(ms(0)), None)];
    let mut seen_switches = HashSet::new();
    for depth in 1..=9u64 {
        let now = ms(depth * ACTUATOR_STEP);
        let mut next: Vec<State> = Vec::new();
        let mut seen = HashSet::new();
        for &(_, pair, heartbeat, misbehaving_since) in &level {
            for &behaviour in &BEHAVIOURS {
                for demanded in [0.0, 10.0] {
                    let mut pair = pair;
                    let before = pair.in_charge();
                    let fb = feedback(behaviour, demanded, now, heartbeat);
                    let after = pair.step(now, fb);
                    // Which fault this step shows, stated independently.
                    let shows = match behaviour {
                        Behaviour::Follows => None,
                        Behaviour::Stuck if demanded == 0.0 => None,
                        Behaviour::Reversed if demanded == 0.0 => None,
                        Behaviour::Stuck => Some(ActuatorFault::NoMotion),
                        Behaviour::Reversed => Some(ActuatorFault::WrongDirection),
                        Behaviour::RunsAway => Some(ActuatorFault::Runaway),
                        Behaviour::ReportsFault => Some(ActuatorFault::DriveFault),
                        Behaviour::Mute => heartbeat
                            .filter(|h| now.saturating_since(*h) > CHECK.heartbeat_timeout)
                            .map(|_| ActuatorFault::HeartbeatLost),
                    };
                    let since = shows.map(|_| misbehaving_since.unwrap_or(now));
                    let due = match shows {
                        Some(f @ (ActuatorFault::DriveFault | ActuatorFault::HeartbeatLost)) => {
                            Some(f)
                        }
                        Some(f)
                            if since
                                .is_some_and(|s| now.saturating_since(s) >= CHECK.persistence) =>
                        {
                            Some(f)
                        }
                        _ => None,
                    };
                    let expected = match (before, due) {
                        (InCharge::Primary, Some(_)) => InCharge::Backup,
                        (InCharge::Backup, Some(_)) => InCharge::Neither,
                        (in_charge, _) => in_charge,
                    };
                    assert_eq!(
                        after, expected,
                        "{behaviour:?} demanding {demanded} at {now:?} from {pair:?}"
                    );
                    if before != after {
                        seen_switches.insert((before, due));
                    }
                    let heartbeat = if behaviour == Behaviour::Mute && before == after {
                        heartbeat
                    } else {
                        Some(now)
                    };
                    let since = if before == after { since } else { None };
                    let state = (depth, pair, heartbeat, since);
                    if seen.insert(format!("{state:?}")) {
                        next.push(state);
                    }
                }
            }
        }
        level = next;
    }
    for fault in [
        ActuatorFault::NoMotion,
        ActuatorFault::WrongDirection,
        ActuatorFault::Runaway,
        ActuatorFault::DriveFault,
        ActuatorFault::HeartbeatLost,
    ] {
        assert!(
            seen_switches.contains(&(InCharge::Primary, Some(fault))),
            "{fault:?}"
        );
        assert!(
            seen_switches.contains(&(InCharge::Backup, Some(fault))),
            "{fault:?}"
        );
    }
}

/// Verifies: REQ-ACT-1.
#[test]
fn a_backup_that_fails_too_leaves_neither_in_charge_until_reset() {
    let mut pair = ActuatorPair::new(CHECK, ms(0));
    let stuck = |now| feedback(Behaviour::Stuck, 10.0, now, Some(now));
    for t in (0..=30).step_by(10) {
        pair.step(ms(t), stuck(ms(t)));
    }
    assert_eq!(pair.in_charge(), InCharge::Backup);
    assert_eq!(
        pair.primary_failed(),
        Some((ActuatorFault::NoMotion, ms(30)))
    );
    assert_eq!(
        pair.step(
            ms(40),
            feedback(Behaviour::ReportsFault, 0.0, ms(40), Some(ms(40)))
        ),
        InCharge::Neither
    );
    assert_eq!(
        pair.step(
            ms(50),
            feedback(Behaviour::Follows, 10.0, ms(50), Some(ms(50)))
        ),
        InCharge::Neither
    );
    pair.reset(ms(60));
    assert_eq!(pair.in_charge(), InCharge::Primary);
}

// ---------------------------------------------------------------- degradation

/// Verifies: REQ-FO-1.
#[test]
fn the_degradation_latch_rises_by_rule_and_a_second_fault_is_a_safe_stop() {
    let policy = DegradationPolicy::default();
    let faults: Vec<(FaultClass, u8)> = FaultClass::ALL
        .iter()
        .flat_map(|&class| [(class, 0), (class, 1)])
        .collect();
    // Every sequence of up to three reports.
    let mut sequences: Vec<Vec<(FaultClass, u8)>> = vec![vec![]];
    for _ in 0..3 {
        sequences = sequences
            .iter()
            .flat_map(|s| faults.iter().map(move |&f| [s.clone(), vec![f]].concat()))
            .collect();
        for sequence in &sequences {
            let mut latch = Degradation::new(policy);
            let mut distinct: Vec<(FaultClass, u8)> = Vec::new();
            let mut previous = DegradationLevel::Nominal;
            for (i, &(class, source)) in sequence.iter().enumerate() {
                let level = latch.report(Fault {
                    class,
                    source,
                    at: ms(i as u64),
                });
                if !distinct.contains(&(class, source))
                    && policy.rule(class) != DegradationLevel::Nominal
                {
                    distinct.push((class, source));
                }
                let expected = match distinct.as_slice() {
                    [] => DegradationLevel::Nominal,
                    [(first, _)] => policy.rule(*first),
                    _ => DegradationLevel::SafeStop,
                };
                assert_eq!(level, expected, "{sequence:?}");
                assert!(level >= previous, "the level fell: {sequence:?}");
                previous = level;
            }
            assert_eq!(
                latch.first().map(|f| (f.class, f.source)),
                distinct.first().copied()
            );
            // Not at a standstill: refused, the level kept.
            assert!(!latch.reset(false));
            assert_eq!(latch.level(), previous);
            latch.reset(true);
            assert_eq!(latch.level(), DegradationLevel::Nominal);
        }
    }
}

/// Verifies: REQ-FO-1.
#[test]
fn each_level_sets_its_limits() {
    let mut policy = DegradationPolicy::default();
    policy.set_rule(FaultClass::StandbyLost, DegradationLevel::Nominal);
    let mut latch = Degradation::new(policy);
    assert_eq!(latch.limits(), None);
    let fault = |class| Fault {
        class,
        source: 0,
        at: ms(0),
    };
    // A notice only: still nominal.
    assert_eq!(
        latch.report(fault(FaultClass::StandbyLost)),
        DegradationLevel::Nominal
    );
    assert_eq!(
        latch.report(fault(FaultClass::ActuatorBackup)),
        DegradationLevel::MinimalRisk
    );
    let limits = latch.limits().unwrap();
    assert!(limits.steering_modes.allows(SteeringMode::Normal));
    assert!(!limits.steering_modes.allows(SteeringMode::Tank));
    assert_eq!(
        latch.reason().map(|f| f.class),
        Some(FaultClass::ActuatorBackup)
    );
    assert_eq!(
        latch.report(fault(FaultClass::SensorChannelOut)),
        DegradationLevel::SafeStop
    );
    assert_eq!(
        latch.reason().map(|f| f.class),
        Some(FaultClass::SensorChannelOut)
    );
    assert_eq!(latch.limits(), None);
}

// ---------------------------------------------------------------- a profile's section

mod shuttle {
    //! The shuttle (not the tug) declares its redundancy in its profile; each mechanism runs
    //! on frames its DBC encodes, read back through the profile's bindings.

    use super::*;
    use bywire_core::{Frame, Id};
    use bywire_dbc::codec::{Decoded, Value};
    use bywire_dbc::decoder::Decoder;
    use bywire_vehicle::bindings::{MeasuredBinding, SignalBinding, StatusBinding};
    use bywire_vehicle::profile::{LoadedProfile, Profile};

    fn shuttle() -> LoadedProfile {
        Profile::load(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("profiles/shuttle.toml"),
        )
        .unwrap()
    }

    /// The message at `message` with its signal `signal` at `value` (the others 0).
    fn frame(decoder: &Decoder, message: usize, signal: usize, value: f64) -> Frame {
        let (m, codec) = decoder.message_at(message).unwrap();
        let mut values = vec![Some(Value::Int(0)); codec.signal_count()];
        values[signal] = Some(Value::Float(value));
        let mut payload = [0u8; 8];
        let size = codec.encode(&values, &mut payload).unwrap();
        Frame::classic(Id::standard(m.id).unwrap(), &payload[..size]).unwrap()
    }

    /// The signal `signal` of message `message` in `frame`, if the frame is that message.
    fn read(decoder: &Decoder, message: usize, signal: usize, frame: &Frame) -> Option<Decoded> {
        let mut values = Vec::new();
        let (index, _, decoded) = decoder.decode_into(frame, &mut values)?;
        decoded.ok()?;
        (index == message).then(|| values[signal])?
    }

    fn at(decoder: &Decoder, b: SignalBinding, frame: &Frame) -> Option<f64> {
        read(decoder, b.message, b.signal, frame).map(|d| d.physical.as_f64())
    }

    fn status(decoder: &Decoder, b: StatusBinding, value: f64) -> Frame {
        frame(decoder, b.message, b.signal.unwrap(), value)
    }

    #[test]
    fn its_section_loads_with_its_own_rules_and_limits() {
        let loaded = shuttle();
        let section = loaded.profile.fail_operational.as_ref().unwrap();
        let policy = section.policy().unwrap();
        assert_eq!(
            policy.rule(FaultClass::StandbyLost),
            DegradationLevel::Nominal
        );
        assert_eq!(
            policy.rule(FaultClass::ControlTakeover),
            DegradationLevel::MinimalRisk
        );
        assert_eq!(policy.degraded.speed_limit, 3.0);
        assert!(!policy.degraded.steering_modes.allows(SteeringMode::Crab));
        let bindings = loaded.bindings.fail_operational.as_ref().unwrap();
        assert_eq!(bindings.voted.len(), 1);
        assert_eq!(bindings.actuators.len(), 1);
        assert!(bindings.control.is_some());
        // A profile without the section has no redundancy.
        assert!(Profile::builtin("autoware-can")
            .unwrap()
            .bindings
            .fail_operational
            .is_none());
    }

    #[test]
    fn a_wrong_name_or_number_in_the_section_is_refused_naming_its_key() {
        let (toml, dbc) = (
            std::fs::read_to_string(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/profiles/shuttle.toml"
            ))
            .unwrap(),
            std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/profiles/shuttle.dbc"))
                .unwrap(),
        );
        for (from, to, expected) in [
            (
                "signal = \"Angle2\"",
                "signal = \"Angle9\"",
                "fail_operational.voted[0].channels[1].signal: no signal 'Angle9'",
            ),
            (
                "role = \"VcuB_Role\"",
                "role = \"Role\"",
                "fail_operational.control.b.role: no signal 'Role'",
            ),
            (
                "standby-lost = \"nominal\"",
                "standby-lost = \"fine\"",
                "fail_operational.rules.standby-lost: not a degradation level",
            ),
            (
                "standby-lost = \"nominal\"",
                "sensor-gone = \"nominal\"",
                "fail_operational.rules.sensor-gone: not a fault class",
            ),
            (
                "steering_modes = [\"normal\"]\n\n[fail_operational.minimal_risk]",
                "steering_modes = [\"sideways\"]\n\n[fail_operational.minimal_risk]",
                "fail_operational.degraded.steering_modes: not a steering mode",
            ),
            (
                "tolerance = 0.5",
                "tolerance = -0.5",
                "fail_operational.voted[0].tolerance",
            ),
            (
                "silence_ms = 30",
                "silence_ms = 30\ndeaf_ms = 0",
                "fail_operational.control: silence_ms and deaf_ms over 0",
            ),
            (
                "heartbeat_timeout_ms = 50",
                "heartbeat_timeout_ms = 0",
                "fail_operational.actuators[0]: still over 0",
            ),
            (
                "    { message = \"Shuttle_SteerAngle3\", signal = \"Angle3\" },\n",
                "",
                "fail_operational.voted[0].channels: three channels",
            ),
            (
                "message = \"SteerMotorB_Status\"",
                "message = \"SteerMotorC_Status\"",
                "fail_operational.actuators[0].backup.message: no message",
            ),
            (
                "backup = { message = \"SteerMotorB_Status\", fault = \"SteerB_Fault\" }",
                "backup = { canopen = 0 }",
                "fail_operational.actuators[0].backup.canopen: a CANopen node ID from 1 to 127",
            ),
            (
                "backup = { message = \"SteerMotorB_Status\", fault = \"SteerB_Fault\" }",
                "backup = { canopen = 0x31, fault = \"SteerB_Fault\" }",
                "fail_operational.actuators[0].backup.fault: a CANopen drive reports",
            ),
            (
                "backup = { message = \"SteerMotorB_Status\", fault = \"SteerB_Fault\" }",
                "backup = { message = \"SteerMotorB_Status\", canopen = 0x31 }",
                "fail_operational.actuators[0].backup: give message (and fault) or canopen",
            ),
            (
                "measured = { message = \"Shuttle_SteerRate\", signal = \"SteerRate\" }",
                "measured = { voted = \"rear-angle\" }",
                "fail_operational.actuators[0].measured.voted: no voted quantity named 'rear-angle'",
            ),
        ] {
            assert!(toml.contains(from), "{from}");
            let edited = toml.replacen(from, to, 1);
            let err = Profile::parse("shuttle.toml", &edited, |_| Ok(dbc.clone()))
                .unwrap_err()
                .to_string();
            assert!(err.contains(expected), "{err} lacks {expected}");
        }
    }

    #[test]
    fn its_degradation_report_goes_both_ways_and_a_level_that_names_nothing_is_refused() {
        use bywire_vehicle::wire::{
            AdsWire, DegradationReport, Feedback, ProfileWire, VehicleWire,
        };
        let loaded = shuttle();
        let mut wire = ProfileWire::new(&loaded).unwrap();
        for &level in DegradationLevel::ALL {
            for reason in std::iter::once(None).chain(FaultClass::ALL.iter().copied().map(Some)) {
                let report = DegradationReport { level, reason };
                let frame = wire.degradation_frame(&report, 0).unwrap();
                assert_eq!(wire.feedback(&frame), Feedback::Degradation(report));
            }
        }
        // Reason 7 is no fault class.
        let report = bywire_vehicle::bindings::SignalBinding {
            message: loaded
                .bindings
                .fail_operational
                .as_ref()
                .unwrap()
                .report
                .unwrap()
                .message,
            signal: loaded
                .bindings
                .fail_operational
                .as_ref()
                .unwrap()
                .report
                .unwrap()
                .reason
                .unwrap(),
        };
        let decoder = Decoder::new(loaded.database.clone());
        let bad = frame(&decoder, report.message, report.signal, 7.0);
        assert_eq!(wire.feedback(&bad), Feedback::Corrupt);
        // A vehicle without the report sends none.
        let mut tug = ProfileWire::new(&bywire_tug::profile().unwrap()).unwrap();
        let nominal = DegradationReport {
            level: DegradationLevel::Nominal,
            reason: None,
        };
        assert_eq!(tug.degradation_frame(&nominal, 0), None);
    }

    #[test]
    fn each_mechanism_runs_on_its_frames() {
        let loaded = shuttle();
        let decoder = Decoder::new(loaded.database.clone());
        let section = loaded.profile.fail_operational.clone().unwrap();
        let bindings = loaded.bindings.fail_operational.clone().unwrap();
        let mut latch = Degradation::new(section.policy().unwrap());

        // The angle sensors: the third drifts off; after the persistence it is out, the
        // vehicle degraded, and the vote carries on 2-out-of-2.
        let voted = bindings.voted[0];
        let mut voter = TripleVoter::new(section.voted[0].config(), ms(0));
        for t in (0..=60).step_by(10) {
            let readings = [5.0, 5.1, if t >= 10 { 9.0 } else { 5.0 }];
            for (channel, (b, value)) in voted.channels.iter().zip(readings).enumerate() {
                let f = frame(&decoder, b.message, b.signal, value);
                voter.receive(channel, ms(t), at(&decoder, *b, &f).unwrap());
            }
            voter.vote(ms(t));
        }
        assert_eq!(
            voter.health()[2],
            ChannelHealth::Out(ChannelFault::Deviating)
        );
        assert_eq!(
            latch.report(Fault {
                class: FaultClass::SensorChannelOut,
                source: 0,
                at: ms(50)
            }),
            DegradationLevel::Degraded
        );

        // The VCUs: A's status stops; B, hearing other traffic, takes over and fences A.
        let [a_status, b_status] = bindings.control.unwrap();
        let mut b = Arbiter::new(Side::B, section.control.as_ref().unwrap().config(), ms(0));
        let mut heard = None;
        for t in (0..=100).step_by(10) {
            if t <= 40 {
                let f = status(&decoder, a_status, f64::from(Role::Active.raw()));
                let role = read(&decoder, a_status.message, a_status.signal.unwrap(), &f).unwrap();
                heard = Some(Heartbeat {
                    role: Role::from_raw(role.raw),
                    at: ms(t),
                });
            }
            let inputs = ArbiterInputs {
                self_test_ok: true,
                partner: heard,
                traffic_at: Some(ms(t)),
                outputs_agree: Some(true),
                fenced: false,
            };
            if b.step(ms(t), inputs) == Role::Active {
                assert_eq!(t, 80, "silence is 30 ms after the last status at 40 ms");
                break;
            }
        }
        assert!(b.fences_partner());
        let echoed = status(&decoder, b_status, f64::from(b.role().raw()));
        assert_eq!(
            read(
                &decoder,
                b_status.message,
                b_status.signal.unwrap(),
                &echoed
            )
            .map(|d| Role::from_raw(d.raw)),
            Some(Role::Active)
        );

        // The steering motor: demanded 10°/s, measured 0 (stuck) for the persistence: the
        // backup winding takes over; a second fault on top is a safe stop.
        let pair_roles = &section.actuators[0];
        let MeasuredBinding::Signal(rate) = bindings.actuators[0].measured else {
            panic!("the shuttle's rate is a signal");
        };
        let mut pair = ActuatorPair::new(pair_roles.check(), ms(0));
        for t in (0..=40).step_by(10) {
            let f = frame(&decoder, rate.message, rate.signal, 0.0);
            let measured = at(&decoder, rate, &f).unwrap();
            pair.step(
                ms(t),
                Feedback {
                    demanded: 10.0,
                    measured,
                    drive_fault: false,
                    heartbeat_at: Some(ms(t)),
                },
            );
        }
        assert_eq!(pair.in_charge(), InCharge::Backup);
        assert_eq!(
            latch.report(Fault {
                class: FaultClass::ActuatorBackup,
                source: 0,
                at: ms(40)
            }),
            DegradationLevel::SafeStop
        );
        assert_eq!(
            latch.first().map(|f| f.class),
            Some(FaultClass::SensorChannelOut)
        );
    }
}

// ---------------------------------------------------------------- a duplicated supervisor

mod duplex {
    //! The shuttle's supervisor duplicated (A in control, B in hot standby) on its bus with
    //! the ADS side: B takes over from a crashed or self-failing A without the vehicle
    //! braking, the ADS sees the level, and the halves' outputs never share the bus.

    use super::*;
    use bywire_core::node::Port;
    use bywire_net::network::{Network, NodeHandle};
    use bywire_net::sim::BusEvent;
    use bywire_vehicle::ads::{Ads, AdsCommand};
    use bywire_vehicle::arbitration::FencedPair;
    use bywire_vehicle::command::{ControlMode, Gear};
    use bywire_vehicle::supervisor::{Supervisor, Watchdog};
    use bywire_vehicle::wire::{ProfileDuplexWire, ProfileWire};

    type Pair = FencedPair<Supervisor<ProfileWire>, ProfileDuplexWire>;

    struct Rig {
        net: Network,
        ads: NodeHandle<Ads<ProfileWire>>,
        pair: NodeHandle<Pair>,
        /// Each half's bus endpoint.
        endpoints: [bywire_net::sim::NodeId; 2],
        /// Non-status frames on the bus by sender: (ms, from B).
        sent: Vec<(u64, bool)>,
        command: AdsCommand,
    }

    impl Rig {
        fn new() -> Rig {
            Rig::with(|_| {})
        }

        fn with(adjust: impl Fn(&mut bywire_vehicle::supervisor::SupervisorConfig)) -> Rig {
            let (pair, loaded) = common::vehicles::duplicated_shuttle_with(adjust);
            let wire = ProfileWire::new(&loaded).unwrap();
            let mut net = Network::new();
            let bus = net.add_bus("bus", 500_000, None);
            let ads = net.add_node(Ads::with_wire(loaded.ads_config(), wire.clone()));
            let pair = net.add_node(pair);
            net.wire(ads.key(), Port::MAIN, bus).unwrap();
            let a = net.wire(pair.key(), Port::MAIN, bus).unwrap();
            let b = net.wire(pair.key(), Pair::b_port(Port::MAIN), bus).unwrap();
            Rig {
                net,
                ads,
                pair,
                endpoints: [a, b],
                sent: Vec::new(),
                command: AdsCommand {
                    velocity: 4.0,
                    gear: Gear::Drive,
                    mode: ControlMode::Autonomous,
                    ..AdsCommand::default()
                },
            }
        }

        fn pair(&self) -> &Pair {
            self.net.node(self.pair).unwrap()
        }

        fn in_control(&self) -> Option<Side> {
            self.pair().in_control()
        }

        /// `n` 50 ms command cycles (`engage` on the first), the plant following whichever
        /// half is in control (neither: the brakes).
        fn cycles(&mut self, n: u32, engage: bool) {
            for k in 0..n {
                let now = self.net.now();
                let command = AdsCommand {
                    engage: engage && k == 0,
                    ..self.command
                };
                self.net
                    .node_mut(self.ads)
                    .unwrap()
                    .set_command(now, command);
                for _ in 0..50 {
                    self.net.run_for(Duration::from_millis(1));
                    let t = self.net.now();
                    let (status_a, status_b) = (0x520, 0x521);
                    let bus = self.net.bus_mut(0).unwrap();
                    for event in bus.drain_events() {
                        if let BusEvent::Transmitted { node, id, end, .. } = event {
                            let status = [status_a, status_b].contains(&id.as_raw());
                            if !status && self.endpoints.contains(&node) {
                                self.sent
                                    .push((end.as_nanos() / 1_000_000, node == self.endpoints[1]));
                            }
                        }
                    }
                    let speed = {
                        let pair = self.pair();
                        match pair.in_control() {
                            Some(side) => common_plant(&pair.half(side).node().actuators(t)),
                            None => 0.0,
                        }
                    };
                    let mut pair = self.net.node_mut(self.pair).unwrap();
                    for side in [Side::A, Side::B] {
                        let a = pair.half(side).node().actuators(t);
                        pair.half_mut(side)
                            .node_mut()
                            .set_feedback(speed, a.steering);
                    }
                }
            }
        }
    }

    /// The vehicle reaches its setpoint within a cycle (the suites' instant plant).
    fn common_plant(a: &bywire_vehicle::supervisor::Actuators) -> f64 {
        if a.motors_enabled && a.brake == 0.0 {
            a.velocity
        } else {
            0.0
        }
    }

    fn engaged() -> Rig {
        engaged_with(Rig::new())
    }

    fn engaged_with(mut rig: Rig) -> Rig {
        rig.cycles(12, false);
        rig.cycles(1, true);
        rig.cycles(2, false);
        for side in [Side::A, Side::B] {
            let supervisor = rig.pair().half(side).node();
            assert_eq!(supervisor.watchdog(), Watchdog::Normal, "{side:?}");
            assert_eq!(supervisor.mode(), ControlMode::Autonomous, "{side:?}");
        }
        assert_eq!(
            rig.in_control(),
            Some(Side::A),
            "{:?} {:?}",
            rig.pair().half(Side::A).arbiter(),
            rig.pair().half(Side::B).arbiter()
        );
        rig
    }

    /// The halves' outputs (other than their status) never both on the bus: B's first comes
    /// after A's last.
    fn never_both(rig: &Rig) {
        let first_b = rig.sent.iter().find(|(_, b)| *b).map(|(t, _)| *t);
        let last_a = rig.sent.iter().rev().find(|(_, b)| !*b).map(|(t, _)| *t);
        if let (Some(first_b), Some(last_a)) = (first_b, last_a) {
            assert!(
                last_a <= first_b,
                "A sent at {last_a} ms, B from {first_b} ms"
            );
        }
    }

    /// Verifies: REQ-AB-1.
    #[test]
    fn b_takes_over_from_a_crashed_a_and_the_vehicle_drives_on_degraded() {
        let mut rig = engaged();
        let crashed = rig.net.now();
        rig.net.node_mut(rig.pair).unwrap().power(Side::A, false);
        // Over the silence, the next command, and B's next state period.
        rig.cycles(3, false);
        assert_eq!(rig.in_control(), Some(Side::B));
        let b = rig.pair().half(Side::B);
        assert_eq!(
            b.arbiter().took_over(),
            Some(bywire_vehicle::arbitration::TakeoverReason::PartnerSilent)
        );
        let supervisor = b.node();
        assert_eq!(supervisor.watchdog(), Watchdog::Normal);
        assert_eq!(
            supervisor.degradation().level(),
            DegradationLevel::MinimalRisk
        );
        let taken_at = supervisor.degradation().first().unwrap().at;
        // The shuttle's silence is 30 ms; B takes over with the next frame it hears after it
        // (the ADS's commands come every 50 ms on this bus, nothing else does).
        let took = taken_at.saturating_since(crashed);
        assert!(took <= Duration::from_millis(30 + 50), "{took:?}");
        // Driving on at the level's limit, and the ADS told.
        let a = supervisor.actuators(rig.net.now());
        assert!(
            a.motors_enabled && a.brake == 0.0 && a.velocity == 1.5,
            "{a:?}"
        );
        let ads = rig.net.node(rig.ads).unwrap().state();
        assert_eq!(ads.degradation.value, Some(DegradationLevel::MinimalRisk));
        assert_eq!(
            ads.degradation_reason.value,
            Some(Some(FaultClass::ControlTakeover))
        );
        never_both(&rig);
        // B lost too: neither is in control, the vehicle stops.
        rig.net.node_mut(rig.pair).unwrap().power(Side::B, false);
        rig.cycles(1, false);
        assert_eq!(rig.in_control(), None);
    }

    /// Verifies: REQ-AB-1.
    #[test]
    fn the_half_in_control_reports_its_standby_lost_once_and_drives_on() {
        // The shuttle takes a lost standby as a notice; here its latch records it.
        let mut rig = engaged_with(Rig::with(|config| {
            if let Some(policy) = config.degradation.as_mut() {
                policy.set_rule(FaultClass::StandbyLost, DegradationLevel::Degraded);
            }
        }));
        rig.net.node_mut(rig.pair).unwrap().power(Side::B, false);
        rig.cycles(4, false);
        assert_eq!(rig.in_control(), Some(Side::A));
        let a = rig.pair().half(Side::A);
        assert_eq!(a.arbiter().took_over(), None);
        let degradation = a.node().degradation();
        assert_eq!(
            degradation.first().map(|f| f.class),
            Some(FaultClass::StandbyLost)
        );
        assert_eq!(degradation.second(), None, "reported once");
        let actuators = a.node().actuators(rig.net.now());
        assert!(
            actuators.motors_enabled && actuators.brake == 0.0,
            "{actuators:?}"
        );
    }

    /// Verifies: REQ-AB-1.
    #[test]
    fn a_failing_its_self_test_hands_over_at_its_next_status() {
        let mut rig = engaged();
        let failed = rig.net.now();
        rig.net
            .node_mut(rig.pair)
            .unwrap()
            .half_mut(Side::A)
            .set_self_test(false);
        rig.cycles(1, false);
        assert_eq!(rig.in_control(), Some(Side::B));
        let b = rig.pair().half(Side::B);
        assert_eq!(
            b.arbiter().took_over(),
            Some(bywire_vehicle::arbitration::TakeoverReason::PartnerReportedOut)
        );
        let taken_at = b.node().degradation().first().unwrap().at;
        assert!(
            taken_at.saturating_since(failed) <= Duration::from_millis(15),
            "{taken_at:?}"
        );
        assert_eq!(
            rig.pair().half(Side::A).arbiter().role(),
            Role::Out(OutReason::SelfTest)
        );
        never_both(&rig);
    }

    #[test]
    fn a_standby_lost_degrades_by_the_profiles_rule_and_a_keeps_control() {
        let mut rig = engaged();
        rig.net.node_mut(rig.pair).unwrap().power(Side::B, false);
        rig.cycles(2, false);
        assert_eq!(rig.in_control(), Some(Side::A));
        let supervisor = rig.pair().half(Side::A).node();
        // The shuttle's rule for a lost standby is nominal: a notice only.
        assert_eq!(supervisor.degradation().level(), DegradationLevel::Nominal);
        let a = supervisor.actuators(rig.net.now());
        assert_eq!(a.velocity, 4.0);
    }
}

/// The halves' output comparison on a bare pair: two outputs per poll, each compared under
/// its own identifier.
mod output_comparison {
    use super::*;
    use bywire_core::node::{Node, Port};
    use bywire_core::{Frame, Id};
    use bywire_net::network::Network;
    use bywire_vehicle::arbitration::{Degrades, Duplex, DuplexWire, FencedPair, TakeoverReason};

    /// Sends two outputs every 10 ms: 0x10 with its own byte, 0x11 always the same.
    #[derive(Debug, Clone)]
    struct Emitter {
        first: u8,
        next: Timestamp,
    }

    impl Node for Emitter {
        fn on_frame(&mut self, _: Timestamp, _: Port, _: &Frame) {}
        /// Times its own transmissions (as the ADS's emergency burst does).
        fn on_sent(&mut self, _: Timestamp, _: Port, _: &Frame) -> bool {
            true
        }
        fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
            if now >= self.next {
                self.next = now.saturating_add(Duration::from_millis(10));
                out(Port::MAIN, frame(0x10, self.first));
                out(Port::MAIN, frame(0x11, 7));
            }
        }
        fn next_deadline(&self) -> Option<Timestamp> {
            Some(self.next)
        }
    }

    impl Degrades for Emitter {
        fn report_fault(&mut self, _: Fault) {}
    }

    fn frame(id: u32, byte: u8) -> Frame {
        Frame::classic(Id::standard(id).unwrap(), &[byte]).unwrap()
    }

    /// Status frames 0x500 (A) and 0x501 (B) carrying the role; outputs 0x10 and 0x11 compared.
    #[derive(Debug, Clone, Copy)]
    struct BareWire;

    impl DuplexWire for BareWire {
        fn status_port(&self) -> Port {
            Port::MAIN
        }
        fn status_period(&self) -> Duration {
            Duration::from_millis(10)
        }
        fn status_frame(&mut self, side: Side, role: Role, _: u8) -> Option<Frame> {
            Some(frame(0x500 + u32::from(side == Side::B), role.raw()))
        }
        fn partner_status(&mut self, side: Side, frame: &Frame) -> Option<Role> {
            let partner = 0x500 + u32::from(side == Side::A);
            (frame.id()?.as_raw() == partner).then(|| Role::from_raw(u64::from(frame.data()[0])))
        }
        fn agree(&self, _: Port, mine: &Frame, theirs: &Frame) -> Option<bool> {
            matches!(mine.id()?.as_raw(), 0x10 | 0x11).then(|| mine.data() == theirs.data())
        }
    }

    fn run(a_first: u8) -> FencedPair<Emitter, BareWire> {
        let config = ArbiterConfig {
            silence: Duration::from_millis(30),
            disagreement: Duration::from_millis(30),
            // Nothing but the halves on this bus: the half in control hears no one.
            deaf: Duration::from_secs(1),
        };
        let half = |side, first| {
            let node = Emitter {
                first,
                next: Timestamp::ZERO,
            };
            Duplex::new(side, config, node, BareWire, Timestamp::ZERO)
        };
        let mut net = Network::new();
        let bus = net.add_bus("bus", 500_000, None);
        let pair = net.add_node(FencedPair::new(half(Side::A, a_first), half(Side::B, 1)));
        net.wire(pair.key(), Port::MAIN, bus).unwrap();
        let b_port = FencedPair::<Emitter, BareWire>::b_port(Port::MAIN);
        net.wire(pair.key(), b_port, bus).unwrap();
        net.run_for(Duration::from_millis(200));
        net.node(pair).unwrap().clone()
    }

    /// Verifies: REQ-AB-1.
    #[test]
    fn a_standby_takes_over_when_the_first_of_two_outputs_disagrees() {
        let mut agreeing = run(1);
        assert_eq!(agreeing.in_control(), Some(Side::A));
        // The pair asks to be polled when a half needs it, not at once; a transmit
        // confirmation reaches the half's node.
        assert!(agreeing.next_deadline().is_some_and(|d| d >= ms(200)));
        assert!(agreeing.on_sent(ms(200), Port::MAIN, &frame(0x10, 1)));
        assert_eq!(agreeing.half(Side::B).arbiter().took_over(), None);
        let disagreeing = run(2);
        eprintln!(
            "{:?}\n{:?} {}",
            disagreeing.half(Side::A).arbiter(),
            disagreeing.half(Side::B).arbiter(),
            disagreeing.is_off(Side::B)
        );
        assert_eq!(disagreeing.in_control(), Some(Side::B));
        assert_eq!(
            disagreeing.half(Side::B).arbiter().took_over(),
            Some(TakeoverReason::OutputsDisagree)
        );
        // Repaired and reset at a standstill: the power-on roles, the comparison forgotten.
        let mut reset = disagreeing;
        for side in [Side::A, Side::B] {
            reset.half_mut(side).reset(ms(300));
        }
        assert_eq!(reset.half(Side::A).arbiter().role(), Role::Active);
        assert_eq!(reset.half(Side::B).arbiter().role(), Role::Standby);
        assert_eq!(reset.half(Side::B).arbiter().took_over(), None);
        // B no longer fences A from the next poll on.
        reset.poll(ms(300), &mut |_, _| {});
        assert_eq!(reset.in_control(), Some(Side::A));
    }
}
