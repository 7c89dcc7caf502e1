//! Exhaustive state-space checks of the supervisor's state machines: from the initial state,
//! every input of an abstract alphabet in every reachable state, each property checked on
//! every transition of the real transition function (`EstopState::next`, `Watchdog::next`,
//! `next_mode`, `CounterChecker::check`, `Arbiter::step`, SecOC's `Receiver::accept`,
//! `DualVoter::vote`), and a planted defect in each found. The latch, the watchdog, the mode
//! and the counter check are finite once their counters are capped and are explored to a fixed
//! point; the A/B pair, the freshness receiver and the two-bus voter keep absolute time or
//! freshness in their state and are explored to a stated depth (100 ms of faults; four
//! messages from five starting points around a wrap of the sent bits; 50 ms of copies).
//!
//! The explorer is a breadth-first search of our own (a few dozen lines) rather than a model
//! checker crate: the machines are small, closed and pure, so a search that keeps each state's
//! parent gives the shortest counterexample as a trace of inputs, and nothing else is needed.
//! Each check writes its figures to `target/evidence/state-space/MACHINE.json`.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use std::collections::HashMap;
use std::fmt::Debug;
use std::hash::Hash;
use std::time::{Duration, Instant};

use bywire_core::e2e::{CounterChecker, CounterStatus};
use bywire_core::Timestamp;
use bywire_vehicle::command::ControlMode;
use bywire_vehicle::supervisor::{
    next_mode, Cascade, EstopInputs, EstopState, ModeInputs, Watchdog, WatchdogEvent,
};

/// What an exploration covered.
#[derive(Debug)]
struct Explored {
    states: usize,
    transitions: u64,
    depth: usize,
    fixed_point: bool,
}

/// The shortest path to a violated property: the inputs from an initial state, and why.
#[derive(Debug)]
struct Counterexample {
    trace: Vec<String>,
    why: String,
}

/// Every state reachable from `initial` under `alphabet`, `check`ed on every transition, to
/// a fixed point or `max_depth`.
fn explore<S, I>(
    initial: &[S],
    alphabet: &[I],
    max_depth: usize,
    step: impl Fn(&S, &I) -> S,
    check: impl Fn(&S, &I, &S) -> Result<(), String>,
) -> Result<Explored, Counterexample>
where
    S: Clone + Eq + Hash + Debug,
    I: Debug,
{
    // Each state once, with how it was first reached: (parent, input).
    let mut states: Vec<(S, Option<(usize, usize)>)> = Vec::new();
    let mut index: HashMap<S, usize> = HashMap::new();
    for s in initial {
        if !index.contains_key(s) {
            index.insert(s.clone(), states.len());
            states.push((s.clone(), None));
        }
    }
    let trace = |states: &[(S, Option<(usize, usize)>)], mut at: usize, last: Option<usize>| {
        let mut inputs: Vec<String> = last
            .map(|i| format!("{:?}", alphabet[i]))
            .into_iter()
            .collect();
        while let Some((parent, input)) = states[at].1 {
            inputs.push(format!("{:?}", alphabet[input]));
            at = parent;
        }
        inputs.push(format!("from {:?}", states[at].0));
        inputs.reverse();
        inputs
    };
    let mut frontier: Vec<usize> = (0..states.len()).collect();
    let mut transitions = 0u64;
    let mut depth = 0;
    while !frontier.is_empty() && depth < max_depth {
        depth += 1;
        let mut next = Vec::new();
        for at in frontier {
            let from = states[at].0.clone();
            for (i, input) in alphabet.iter().enumerate() {
                let to = step(&from, input);
                transitions += 1;
                if let Err(why) = check(&from, input, &to) {
                    return Err(Counterexample {
                        trace: trace(&states, at, Some(i)),
                        why: format!("{why} (into {to:?})"),
                    });
                }
                if !index.contains_key(&to) {
                    index.insert(to.clone(), states.len());
                    states.push((to, Some((at, i))));
                    next.push(states.len() - 1);
                }
            }
        }
        frontier = next;
    }
    Ok(Explored {
        states: states.len(),
        transitions,
        depth,
        fixed_point: frontier.is_empty(),
    })
}

/// Keep a check's figures for the evidence report.
fn record(machine: &str, requirements: &[&str], explored: &Explored, took: Duration) {
    let e = explored;
    common::record_state_space(
        machine,
        requirements,
        (e.states, e.transitions, e.depth, e.fixed_point),
        took,
    );
}

fn bools() -> [bool; 2] {
    [false, true]
}

// --- The E-stop latch -------------------------------------------------------------------

/// The latch and what its properties need of the path: whether an operator reset came since it
/// latched, and evaluations since the chain opened before the brakes were on.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
struct Latch {
    state: EstopState,
    reset_since_latched: bool,
    steps_to_brakes: u8,
}

fn estop_alphabet() -> Vec<EstopInputs> {
    let mut all = Vec::new();
    for active in bools() {
        for operator_reset in bools() {
            for engage in bools() {
                for standstill in bools() {
                    all.push(EstopInputs {
                        active,
                        operator_reset,
                        engage,
                        standstill,
                    });
                }
            }
        }
    }
    all
}

fn explore_latch(
    next: impl Fn(EstopState, EstopInputs) -> EstopState,
) -> Result<Explored, Counterexample> {
    use EstopState::*;
    let initial = Latch {
        state: Normal,
        reset_since_latched: false,
        steps_to_brakes: 0,
    };
    let braking = |s: EstopState| matches!(s, EstopRequested | MotorsDisabled);
    explore(
        &[initial],
        &estop_alphabet(),
        64,
        |l, i| {
            let state = next(l.state, *i);
            Latch {
                state,
                reset_since_latched: match (l.state, state) {
                    (Normal, s) if s != Normal => false,
                    _ => l.reset_since_latched || i.operator_reset,
                },
                steps_to_brakes: if braking(state) {
                    l.steps_to_brakes.saturating_add(1).min(9)
                } else {
                    0
                },
            }
        },
        |from, i, to| {
            // It never leaves its latch without a deliberate operator reset and a re-engage.
            if from.state != Normal && to.state == Normal && !(from.reset_since_latched && i.engage)
            {
                return Err("left the latch without an operator reset and a re-engage".into());
            }
            // A press is never ignored: from normal or any reset stage it latches again.
            let resetting = matches!(
                from.state,
                Normal | OperatorReset | EstopReset | ResetConfirmed
            );
            if i.active && resetting && !matches!(to.state, EstopRequested) {
                return Err("a press was not taken".into());
            }
            // Bounded liveness: the brakes are on within two evaluations of the chain opening.
            if to.steps_to_brakes > 2 {
                return Err("the brakes not applied within two evaluations".into());
            }
            // Once latched, the vehicle is held (motors off, brakes on) in every later state.
            if from.state != Normal && to.state == Normal && i.active {
                return Err("released while the chain is open".into());
            }
            Ok(())
        },
    )
}

/// Verifies: REQ-ES-1.
#[test]
fn the_estop_latch_never_releases_without_the_reset_sequence_in_any_reachable_state() {
    let started = Instant::now();
    let explored = explore_latch(EstopState::next).unwrap_or_else(|c| panic!("{c:#?}"));
    assert!(explored.fixed_point && explored.states >= 8, "{explored:?}");
    record("estop-latch", &["REQ-ES-1"], &explored, started.elapsed());
    // A planted defect: a re-engage releases a stopped vehicle straight away.
    let planted = |s: EstopState, i: EstopInputs| match s {
        EstopState::Stopped if i.engage => EstopState::Normal,
        s => s.next(i),
    };
    let found = explore_latch(planted).unwrap_err();
    assert!(
        found.why.contains("without an operator reset"),
        "{found:#?}"
    );
    assert!(found.trace.len() <= 7, "not the shortest: {found:#?}");
}

// --- The watchdog cascade -------------------------------------------------------------

/// The watchdog and its inputs' history: cycles missed since the last valid command, valid
/// commands in a row since full braking (both capped past what the cascade looks at).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
struct Dog {
    watchdog: Watchdog,
    missed: u32,
    valid_run: u32,
}

#[derive(Debug, Clone, Copy)]
enum DogInput {
    /// A command cycle passes without a valid command.
    Tick,
    Valid {
        engage: bool,
    },
    Disagreement,
}

const CASCADE: Cascade = Cascade {
    hold: 2,
    decelerate: 4,
    recovery_run: 10,
};

fn severity(w: Watchdog) -> u8 {
    match w {
        Watchdog::Normal => 0,
        Watchdog::Holding { .. } => 1,
        Watchdog::Decelerating { .. } => 2,
        Watchdog::Recovering { .. } => 3,
        Watchdog::FullBraking => 4,
    }
}

fn explore_watchdog(
    next: impl Fn(Watchdog, WatchdogEvent) -> Watchdog,
) -> Result<Explored, Counterexample> {
    let alphabet = [
        DogInput::Tick,
        DogInput::Valid { engage: false },
        DogInput::Valid { engage: true },
        DogInput::Disagreement,
    ];
    let cap = CASCADE.decelerate + 3;
    // It starts failed closed: full braking, no command yet.
    let initial = Dog {
        watchdog: Watchdog::FullBraking,
        missed: 0,
        valid_run: 0,
    };
    explore(
        &[initial],
        &alphabet,
        256,
        |d, input| {
            let (event, missed, valid_run) = match input {
                DogInput::Tick => {
                    let missed = (d.missed + 1).min(cap);
                    (WatchdogEvent::Missed(missed), missed, 0)
                }
                DogInput::Valid { engage } => (
                    WatchdogEvent::Valid { engage: *engage },
                    0,
                    (d.valid_run + 1).min(CASCADE.recovery_run + 2),
                ),
                DogInput::Disagreement => (WatchdogEvent::Disagreement, d.missed, 0),
            };
            // A run past the recovery length behaves as that length: capped, so the search
            // closes (the abstraction loses nothing the transition function looks at).
            let watchdog = match next(d.watchdog, event) {
                Watchdog::Recovering { valid_run } => Watchdog::Recovering {
                    valid_run: valid_run.min(CASCADE.recovery_run + 1),
                },
                w => w,
            };
            Dog {
                watchdog,
                missed,
                valid_run,
            }
        },
        |from, input, to| {
            let w = to.watchdog;
            match input {
                DogInput::Tick => {
                    // The level never falls while cycles are missed ...
                    if severity(w) < severity(from.watchdog) {
                        return Err("the level fell while a cycle was missed".into());
                    }
                    // ... and follows the cascade exactly.
                    let full = matches!(
                        from.watchdog,
                        Watchdog::FullBraking | Watchdog::Recovering { .. }
                    );
                    let expected = match to.missed {
                        _ if full => Watchdog::FullBraking,
                        m if m <= CASCADE.hold => Watchdog::Holding { missed: m },
                        m if m <= CASCADE.decelerate => Watchdog::Decelerating { missed: m },
                        _ => Watchdog::FullBraking,
                    };
                    if w != expected {
                        return Err(format!(
                            "{} cycles missed: expected {expected:?}",
                            to.missed
                        ));
                    }
                }
                DogInput::Disagreement if w != Watchdog::FullBraking => {
                    return Err("disagreeing copies did not brake fully".into());
                }
                _ => {}
            }
            // Out of full braking only on a run of valid commands and an engage request.
            let braking = matches!(
                from.watchdog,
                Watchdog::FullBraking | Watchdog::Recovering { .. }
            );
            if braking && w == Watchdog::Normal {
                let engaged = matches!(input, DogInput::Valid { engage: true });
                if !(engaged && to.valid_run > CASCADE.recovery_run) {
                    return Err(format!(
                        "normal again after {} valid commands{}",
                        to.valid_run,
                        if engaged { "" } else { " without an engage" }
                    ));
                }
            }
            Ok(())
        },
    )
}

/// Verifies: REQ-TO-1, REQ-TO-2.
#[test]
fn the_watchdog_follows_its_cascade_and_recovers_only_on_a_run_and_an_engage() {
    let started = Instant::now();
    let explored = explore_watchdog(|w, e| w.next(e, CASCADE)).unwrap_or_else(|c| panic!("{c:#?}"));
    assert!(explored.fixed_point, "{explored:?}");
    record(
        "watchdog",
        &["REQ-TO-1", "REQ-TO-2"],
        &explored,
        started.elapsed(),
    );
    // A planted defect: an engage request recovers at once, without the run.
    let planted = |w: Watchdog, e: WatchdogEvent| match (w, e) {
        (Watchdog::Recovering { .. }, WatchdogEvent::Valid { engage: true }) => Watchdog::Normal,
        _ => w.next(e, CASCADE),
    };
    let found = explore_watchdog(planted).unwrap_err();
    assert!(found.why.contains("normal again after"), "{found:#?}");
    // Another: holding one cycle longer than the cascade says.
    let late = |w: Watchdog, e: WatchdogEvent| match e {
        WatchdogEvent::Missed(3) if !matches!(w, Watchdog::FullBraking) => {
            Watchdog::Holding { missed: 3 }
        }
        _ => w.next(e, CASCADE),
    };
    let found = explore_watchdog(late).unwrap_err();
    assert!(found.why.contains("3 cycles missed"), "{found:#?}");
}

// --- The control mode ---------------------------------------------------------------------

const MODES: [ControlMode; 4] = [
    ControlMode::Manual,
    ControlMode::Autonomous,
    ControlMode::Estop,
    ControlMode::Calibration,
];

fn mode_alphabet() -> Vec<ModeInputs> {
    let mut all = Vec::new();
    for requested in MODES {
        for engage in bools() {
            for driver_input in bools() {
                for estop in bools() {
                    for watchdog_normal in bools() {
                        for standstill in bools() {
                            all.push(ModeInputs {
                                requested,
                                engage,
                                driver_input,
                                estop,
                                watchdog_normal,
                                standstill,
                            });
                        }
                    }
                }
            }
        }
    }
    all
}

fn explore_mode(
    next: impl Fn(ControlMode, ModeInputs) -> ControlMode,
) -> Result<Explored, Counterexample> {
    explore(
        &[ControlMode::Manual],
        &mode_alphabet(),
        16,
        |m, i| next(*m, *i),
        |from, i, to| {
            use ControlMode::*;
            if i.driver_input && *to == Autonomous {
                return Err("autonomous with a driver's input".into());
            }
            if i.estop && *to != Estop {
                return Err("not in E-stop with the latch holding".into());
            }
            if *from != Autonomous
                && *to == Autonomous
                && !(i.requested == Autonomous && i.engage && i.watchdog_normal && !i.estop)
            {
                return Err("autonomous without a request, an engage and a normal watchdog".into());
            }
            if *from == Estop && *to == Autonomous {
                return Err("straight from E-stop to autonomous".into());
            }
            if *to == Calibration && *from != Calibration && !i.standstill {
                return Err("calibration while moving".into());
            }
            Ok(())
        },
    )
}

/// Verifies: REQ-TK-1, REQ-ES-1.
#[test]
fn the_mode_hands_over_to_a_driver_at_once_and_engages_only_when_asked() {
    let started = Instant::now();
    let explored = explore_mode(next_mode).unwrap_or_else(|c| panic!("{c:#?}"));
    assert!(explored.fixed_point && explored.states == 4, "{explored:?}");
    record(
        "control-mode",
        &["REQ-TK-1", "REQ-ES-1"],
        &explored,
        started.elapsed(),
    );
    // A planted defect: a driver's input is ignored while autonomous.
    let planted = |m: ControlMode, i: ModeInputs| match m {
        ControlMode::Autonomous if i.requested == ControlMode::Autonomous && !i.estop => m,
        m => next_mode(m, i),
    };
    let found = explore_mode(planted).unwrap_err();
    assert!(found.why.contains("driver"), "{found:#?}");
}

// --- The E2E counter check ------------------------------------------------------------

/// A receiver's checker and what the sender last sent (the abstract time is a step count).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
struct Receiver {
    last_sent: Option<u8>,
    /// Whether the last frame was taken as new data.
    taken: bool,
    /// 10 ms steps since the last new value (capped).
    quiet: u8,
    /// The value the checker compares with.
    checker_last: Option<u8>,
}

/// One frame: the counter `step`s past the last sent, after `gap` 10 ms steps.
#[derive(Debug, Clone, Copy)]
struct Sent {
    step: u8,
    gap: u8,
}

fn explore_counter(
    check: impl Fn(&mut CounterChecker, Timestamp, u8) -> CounterStatus,
) -> Result<Explored, Counterexample> {
    // A 4-bit counter, up to 2 lost tolerated, 50 ms without a frame is a silence.
    let alphabet: Vec<Sent> = [0u8, 1, 2, 3, 5, 8, 15]
        .into_iter()
        .flat_map(|step| [1u8, 2, 6].map(|gap| Sent { step, gap }))
        .collect();
    let timeout = Duration::from_millis(50);
    // The checker is rebuilt from the abstract state (its last value and when it came), so
    // the search closes: absolute time plays no part in a verdict.
    let rebuild = |r: &Receiver| {
        let mut c = CounterChecker::new(4, 2, timeout);
        if let Some(last) = r.checker_last {
            c.check(Timestamp::ZERO, last);
        }
        c
    };
    explore(
        &[Receiver {
            last_sent: None,
            taken: false,
            quiet: 0,
            checker_last: None,
        }],
        &alphabet,
        64,
        |r, s| {
            let value = r.last_sent.map_or(s.step, |l| (l + s.step) % 16);
            let mut c = rebuild(r);
            let since = u64::from(r.quiet.saturating_add(s.gap)) * 10;
            let status = check(&mut c, Timestamp::from_millis(since), value);
            let taken = matches!(
                status,
                CounterStatus::Initial | CounterStatus::InSequence | CounterStatus::Stale
            );
            Receiver {
                last_sent: Some(value),
                taken,
                // Repeated values keep the staleness clock running from the last new one.
                quiet: if status == CounterStatus::Repeated {
                    r.quiet.saturating_add(s.gap).min(8)
                } else {
                    0
                },
                checker_last: if status == CounterStatus::Repeated {
                    r.checker_last
                } else {
                    Some(value)
                },
            }
        },
        |from, s, to| {
            let stale = u64::from(from.quiet.saturating_add(s.gap)) * 10 > 50;
            let value = to.last_sent.unwrap_or(0);
            // In a live stream a repeated counter is no new data, and only the next value is.
            // (After a silence any value restarts the stream; the supervisor refuses the one
            // it froze on, which its own tests check.)
            let repeat = from.checker_last == Some(value);
            if !stale && repeat && to.taken {
                return Err("a repeated counter was taken as new".into());
            }
            let jumped = from
                .checker_last
                .is_some_and(|last| (value + 16 - last) % 16 != 1);
            if !stale && jumped && to.taken {
                return Err("a counter that jumped was taken".into());
            }
            // The first value, and the next of a live stream, are taken.
            if !stale && !jumped && !repeat && !to.taken {
                return Err("the next value was refused".into());
            }
            Ok(())
        },
    )
}

/// Verifies: REQ-E2E-2.
#[test]
fn the_counter_check_takes_only_the_next_value_of_a_live_stream() {
    let started = Instant::now();
    let explored =
        explore_counter(|c, now, v| c.check(now, v)).unwrap_or_else(|c| panic!("{c:#?}"));
    assert!(explored.fixed_point, "{explored:?}");
    record("e2e-counter", &["REQ-E2E-2"], &explored, started.elapsed());
    // A planted defect: a skip within the tolerance taken as in sequence.
    let planted = |c: &mut CounterChecker, now: Timestamp, v: u8| match c.check(now, v) {
        CounterStatus::Skipped { .. } => CounterStatus::InSequence,
        s => s,
    };
    let found = explore_counter(planted).unwrap_err();
    assert!(found.why.contains("jumped"), "{found:#?}");
}

// --- The A/B arbitration ----------------------------------------------------------------

use bywire_vehicle::arbitration::{Arbiter, ArbiterConfig, ArbiterInputs, Heartbeat, Role, Side};

/// Two arbiters wired as a vehicle wires them (each one's fence line cuts the other's
/// outputs; a fenced side sends no status), the faults so far, and when each side was last
/// heard. Faults persist once they come.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
struct Pair {
    a: Arbiter,
    b: Arbiter,
    step: u32,
    /// Faults per side: [self-test failed, silent (its transceiver), deaf (its receiver)].
    faults: [[bool; 3]; 2],
    /// The active side's outputs disagree with the standby's own.
    disagree: bool,
    /// Each side's last status sent, and when each last heard any traffic (ms).
    status_at: [Option<u32>; 2],
    traffic_at: [Option<u32>; 2],
    /// Steps in a row with neither side's outputs reaching the actuators.
    neither: u32,
}

#[derive(Debug, Clone, Copy)]
enum PairFault {
    Nothing,
    SelfTest(Side),
    Silent(Side),
    Deaf(Side),
    Disagree,
}

/// The redundant tug's timing, and the status period the step stands for.
const ARBITER: ArbiterConfig = ArbiterConfig {
    silence: Duration::from_millis(30),
    disagreement: Duration::from_millis(30),
    deaf: Duration::from_millis(30),
};
const PAIR_STEP_MS: u32 = 10;
/// Steps explored: 100 ms, past the longest takeover (silence, then disagreement) with room.
const PAIR_DEPTH: usize = 10;

fn index(side: Side) -> usize {
    match side {
        Side::A => 0,
        Side::B => 1,
    }
}

fn explore_pair(
    transmits: impl Fn(&Arbiter, bool) -> bool,
    fence_of: impl Fn(&Arbiter) -> bool,
    depth: usize,
) -> Result<Explored, Counterexample> {
    let at = |ms: u32| Timestamp::from_millis(u64::from(ms));
    let initial = Pair {
        a: Arbiter::new(Side::A, ARBITER, Timestamp::ZERO),
        b: Arbiter::new(Side::B, ARBITER, Timestamp::ZERO),
        step: 0,
        faults: [[false; 3]; 2],
        disagree: false,
        status_at: [None; 2],
        traffic_at: [None; 2],
        neither: 0,
    };
    let alphabet = [
        PairFault::Nothing,
        PairFault::SelfTest(Side::A),
        PairFault::SelfTest(Side::B),
        PairFault::Silent(Side::A),
        PairFault::Silent(Side::B),
        PairFault::Deaf(Side::A),
        PairFault::Deaf(Side::B),
        PairFault::Disagree,
    ];
    let faulty = |p: &Pair, side: Side| p.faults[index(side)].iter().any(|f| *f);
    explore(
        &[initial],
        &alphabet,
        depth,
        |p, fault| {
            let mut p = p.clone();
            match fault {
                PairFault::Nothing => {}
                PairFault::SelfTest(s) => p.faults[index(*s)][0] = true,
                PairFault::Silent(s) => p.faults[index(*s)][1] = true,
                PairFault::Deaf(s) => p.faults[index(*s)][2] = true,
                PairFault::Disagree => p.disagree = true,
            }
            p.step += 1;
            let now = p.step * PAIR_STEP_MS;
            // What each side sees, from the step before: the partner's last status, traffic
            // (the ADS's and the drives' frames keep coming unless its receiver is deaf).
            let sides = [(Side::A, p.a), (Side::B, p.b)];
            let fenced = [fence_of(&p.b), fence_of(&p.a)];
            for (side, arbiter) in sides {
                let me = index(side);
                let other = 1 - me;
                let deaf = p.faults[me][2];
                if !deaf {
                    p.traffic_at[me] = Some(now);
                }
                let partner = sides[other].1;
                let heard = if deaf { None } else { p.status_at[other] };
                let inputs = ArbiterInputs {
                    self_test_ok: !p.faults[me][0],
                    partner: heard.map(|t| Heartbeat {
                        role: partner.role(),
                        at: at(t),
                    }),
                    traffic_at: p.traffic_at[me].map(at),
                    outputs_agree: (partner.role() == Role::Active && !deaf).then_some(!p.disagree),
                    fenced: fenced[me],
                };
                let mut arbiter = arbiter;
                arbiter.step(at(now), inputs);
                match side {
                    Side::A => p.a = arbiter,
                    Side::B => p.b = arbiter,
                }
            }
            // Each side's status goes out unless it is fenced or its transceiver is silent.
            let fenced = [fence_of(&p.b), fence_of(&p.a)];
            for ((sent, fenced), faults) in p.status_at.iter_mut().zip(fenced).zip(p.faults) {
                if !fenced && !faults[1] {
                    *sent = Some(now);
                }
            }
            let driving = [
                transmits(&p.a, fenced[0]) && !p.faults[0][1],
                transmits(&p.b, fenced[1]) && !p.faults[1][1],
            ];
            p.neither = if driving.iter().any(|d| *d) {
                0
            } else {
                (p.neither + 1).min(50)
            };
            p
        },
        |_, _, to| {
            let fenced = [fence_of(&to.b), fence_of(&to.a)];
            if transmits(&to.a, fenced[0]) && transmits(&to.b, fenced[1]) {
                return Err("both sides' outputs reach the actuators".into());
            }
            // One fault (a side's self-test, transceiver or receiver, or the active side's
            // outputs wrong): the other side drives within the takeover bound.
            let faults = usize::from(faulty(to, Side::A))
                + usize::from(faulty(to, Side::B))
                + usize::from(to.disagree);
            let bound = u32::try_from((ARBITER.silence + ARBITER.disagreement).as_millis())
                .unwrap()
                / PAIR_STEP_MS
                + 2;
            if faults == 1 && to.neither > bound {
                return Err(format!(
                    "neither side drove for {} steps after one fault",
                    to.neither
                ));
            }
            Ok(())
        },
    )
}

/// Verifies: REQ-AB-1.
#[test]
fn two_control_ecus_never_both_drive_and_one_fault_leaves_one_driving() {
    let started = Instant::now();
    let explored = explore_pair(
        |a, fenced| a.transmits(fenced),
        Arbiter::fences_partner,
        PAIR_DEPTH,
    )
    .unwrap_or_else(|c| panic!("{c:#?}"));
    assert!(explored.states > 1_000, "{explored:?}");
    record(
        "ab-arbitration",
        &["REQ-AB-1"],
        &explored,
        started.elapsed(),
    );
    // A planted defect: the fence line not wired (a side that took over cuts nobody off).
    let found = explore_pair(|a, fenced| a.transmits(fenced), |_| false, PAIR_DEPTH).unwrap_err();
    assert!(found.why.contains("both sides"), "{found:#?}");
}

// --- The SecOC freshness receiver -----------------------------------------------------

/// The receiver's last accepted freshness (the state the verdicts depend on; its counts are
/// not), checked against what was truly signed.
#[cfg(feature = "secoc")]
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
struct Fresh {
    last: u64,
}

/// A message signed with the freshness `delta` past the receiver's last (negative: older),
/// with the vehicle's key or (`forged`) another.
#[cfg(feature = "secoc")]
#[derive(Debug, Clone, Copy)]
struct SignedWith {
    delta: i64,
    forged: bool,
}

#[cfg(feature = "secoc")]
fn explore_freshness(
    accept: impl Fn(&mut bywire_secoc::Receiver, &[u8]) -> Result<u64, bywire_secoc::Rejection>,
) -> Result<Explored, Counterexample> {
    use bywire_secoc::{Authenticator, Key, Receiver};
    // 4 of 64 freshness bits sent (wraps every 16), a window of 20.
    const WINDOW: u64 = 20;
    let layout = layout();
    let auth = auth();
    let forger = Authenticator::new(&Key::new([8; 16]));
    let alphabet: Vec<SignedWith> = [-17i64, -16, -1, 0, 1, 2, 15, 16, 17, 20, 21, 40]
        .into_iter()
        .flat_map(|delta| [false, true].map(|forged| SignedWith { delta, forged }))
        .collect();
    let signed = |fv: u64, forged: bool| {
        let mut data = vec![0u8; layout.secured_length()];
        data[..4].copy_from_slice(&[1, 2, 3, 4]);
        let signer = if forged { &forger } else { &auth };
        signer.sign(&layout, fv, &mut data).unwrap();
        data
    };
    // Around a wrap of the sent bits, and far from zero.
    let initial = [0u64, 14, 15, 16, 1_000].map(|last| Fresh { last });
    explore(
        &initial,
        &alphabet,
        4,
        |f, s| {
            let fv = f.last.saturating_add_signed(s.delta);
            let mut r = Receiver::new(f.last, WINDOW);
            match accept(&mut r, &signed(fv, s.forged)) {
                Ok(accepted) => Fresh { last: accepted },
                Err(_) => f.clone(),
            }
        },
        |from, s, to| {
            let fv = from.last.saturating_add_signed(s.delta);
            if to.last == from.last {
                // Refused: rightly, unless it was genuine, newer and within the window.
                let due = !s.forged && fv > from.last && fv - from.last <= WINDOW;
                return if due {
                    Err("a genuine, newer message within the window was refused".into())
                } else {
                    Ok(())
                };
            }
            if s.forged {
                return Err("a forged message was accepted".into());
            }
            if to.last <= from.last {
                return Err("a freshness value not newer than the last was accepted".into());
            }
            if to.last != fv {
                return Err(format!("accepted as {} what was signed with {fv}", to.last));
            }
            Ok(())
        },
    )
}

/// Verifies: REQ-SEC-1.
#[cfg(feature = "secoc")]
#[test]
fn secoc_freshness_accepts_only_genuine_newer_values_within_the_window() {
    let started = Instant::now();
    let (auth, layout) = (auth(), layout());
    let explored = explore_freshness(|r, data| r.accept(&auth, &layout, data))
        .unwrap_or_else(|c| panic!("{c:#?}"));
    record(
        "secoc-freshness",
        &["REQ-SEC-1"],
        &explored,
        started.elapsed(),
    );
    // A planted defect: a replayed (stale) message accepted as the next value.
    let moved = |r: &mut bywire_secoc::Receiver, data: &[u8]| {
        let last = r.last();
        match r.accept(&auth, &layout, data) {
            Err(bywire_secoc::Rejection::Stale) => Ok(last + 1),
            other => other,
        }
    };
    let found = explore_freshness(moved).unwrap_err();
    assert!(found.why.contains("accepted as"), "{found:#?}");
}

#[cfg(feature = "secoc")]
fn auth() -> bywire_secoc::Authenticator {
    bywire_secoc::Authenticator::new(&bywire_secoc::Key::new([7; 16]))
}

#[cfg(feature = "secoc")]
fn layout() -> bywire_secoc::Layout {
    bywire_secoc::Layout::new(0x100, 4, 64, 4, 28).unwrap()
}

// --- The two-bus command voter --------------------------------------------------------

use bywire_vehicle::redundancy::{Channel, DualVoter, Vote, VoteFailure};

/// A command's copy: its value and rolling counter (2 bits).
type Copy2 = (u8, u8);

/// The voter (known by its debug form: it keeps no hashable state of its own), the step, and
/// the last copy each bus delivered with when.
#[derive(Debug, Clone)]
struct Buses {
    voter: DualVoter<Copy2>,
    key: String,
    step: u32,
    last: [Option<(Copy2, u32)>; 2],
}

impl PartialEq for Buses {
    fn eq(&self, other: &Self) -> bool {
        self.key == other.key && self.step == other.step && self.last == other.last
    }
}
impl Eq for Buses {}
impl Hash for Buses {
    fn hash<H: std::hash::Hasher>(&self, h: &mut H) {
        (&self.key, self.step, self.last).hash(h);
    }
}

/// What each bus carries this step: nothing, the command's copy, or a corrupted copy (the
/// same counter, another value).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Carried {
    Nothing,
    Copy,
    Corrupted,
}

const VOTE_STEP_MS: u32 = 10;
const VOTE_TIMEOUT_MS: u32 = 30;

fn explore_voter(
    vote: impl Fn(&DualVoter<Copy2>, Timestamp) -> Vote<Copy2>,
) -> Result<Explored, Counterexample> {
    let carried = [Carried::Nothing, Carried::Copy, Carried::Corrupted];
    let alphabet: Vec<[Carried; 2]> = carried
        .iter()
        .flat_map(|a| carried.map(|b| [*a, b]))
        .collect();
    let voter = DualVoter::new(
        Duration::from_millis(u64::from(VOTE_TIMEOUT_MS)),
        Duration::from_millis(5),
    )
    .paired_by(|a: &Copy2, b: &Copy2| a.1 == b.1);
    let at = |step: u32| Timestamp::from_millis(u64::from(step * VOTE_STEP_MS));
    explore(
        &[Buses {
            key: format!("{voter:?}"),
            voter,
            step: 0,
            last: [None; 2],
        }],
        &alphabet,
        5,
        |b, input| {
            let mut b = b.clone();
            b.step += 1;
            // The sender's command this step: value 0, the counter counting.
            let counter = u8::try_from(b.step % 4).unwrap();
            for (channel, what) in [(Channel::A, input[0]), (Channel::B, input[1])] {
                let copy = match what {
                    Carried::Nothing => continue,
                    Carried::Copy => (0, counter),
                    Carried::Corrupted => (1, counter),
                };
                b.voter.receive(channel, at(b.step), copy);
                b.last[usize::from(channel == Channel::B)] = Some((copy, b.step));
            }
            b.key = format!("{:?}", b.voter);
            b
        },
        |_, _, to| {
            let now = at(to.step);
            let fresh = |i: usize| {
                to.last[i].filter(|(_, step)| (to.step - step) * VOTE_STEP_MS <= VOTE_TIMEOUT_MS)
            };
            let verdict = vote(&to.voter, now);
            // Never a command its two buses' copies disagree on.
            if let (Some((a, _)), Some((b, _))) = (fresh(0), fresh(1)) {
                if a.1 == b.1 && a != b && !matches!(verdict, Vote::Failed(VoteFailure::Disagree)) {
                    return Err(format!(
                        "copies {a:?} and {b:?} disagree, voted {verdict:?}"
                    ));
                }
            }
            // Agreed: both buses carried that very copy.
            if let Vote::Agreed(v) = verdict {
                let carried = |i: usize| to.last[i].is_some_and(|(c, _)| c == v);
                if !(carried(0) && carried(1)) {
                    return Err(format!("agreed on {v:?}, which not both buses carried"));
                }
            }
            Ok(())
        },
    )
}

/// Verifies: REQ-RED-1.
#[test]
fn the_two_bus_voter_never_passes_copies_that_disagree() {
    let started = Instant::now();
    let explored = explore_voter(|v, now| v.vote(now)).unwrap_or_else(|c| panic!("{c:#?}"));
    record(
        "two-bus-voter",
        &["REQ-RED-1"],
        &explored,
        started.elapsed(),
    );
    // A planted defect: a disagreement passed as the first bus's copy.
    let planted = |v: &DualVoter<Copy2>, now: Timestamp| match v.vote(now) {
        Vote::Failed(VoteFailure::Disagree) => Vote::Degraded {
            value: (1, 0),
            healthy: Channel::A,
        },
        other => other,
    };
    let found = explore_voter(planted).unwrap_err();
    assert!(found.why.contains("disagree"), "{found:#?}");
}
