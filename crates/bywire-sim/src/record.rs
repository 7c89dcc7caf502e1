//! What a run records beside its bus logs: the state every 50 ms, the plant's truth every
//! 10 ms, its events, the steering's step and tank-turn responses, each bus's response times
//! by identifier and what the attacks achieved. The tug ([`crate::tug`]) feeds them from its
//! nodes and plants; how each is kept and what counts is decided here.

use bywire_control::kinematics::{Pose, Twist};
use bywire_control::metrics::{step_metrics, MetricsError, StepMetrics};
use bywire_core::{Frame, Id, Timestamp};
use bywire_tug::messages::ControlMode;
use bywire_vehicle::command::SteeringMode;
use bywire_vehicle::redundancy::Channel;
use bywire_vehicle::supervisor::{EstopState, Watchdog};

use crate::event::Happening;
use crate::mission::{ActiveStep, STEP_HOLD};

/// A frame seen on a bus, with its end-of-frame time.
pub type Logged = (Timestamp, Frame);

/// The run's state every 50 ms, for plots.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// When.
    pub t: Timestamp,
    /// Pose.
    pub pose: Pose,
    /// Speed, m/s.
    pub speed: f64,
    /// The ADS's steering command, degrees.
    pub steering_command: f64,
    /// The front-left wheel's target as the vehicle control ECU works it out from the command
    /// (in a tank turn the wheel's own angle, whatever the steering command), degrees.
    pub steering_target: f64,
    /// The front-left wheel's angle, degrees.
    pub steering_actual: f64,
    /// How long each bus (bus 1, 2, 3, 1b) has been busy since the start, ns.
    pub busy_ns: [u64; 4],
}

/// The plant's true state, every 10 ms: what a dataset's ground truth holds beside what the
/// buses show.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthSample {
    /// When.
    pub t: Timestamp,
    /// The true pose.
    pub pose: Pose,
    /// The body's motion: forward and leftward speed (m/s), yaw rate (rad/s).
    pub twist: Twist,
    /// Each wheel's angle (FL, FR, RL, RR), degrees.
    pub wheel_angles_deg: [f64; 4],
    /// Each wheel's rolling speed (FL, FR, RL, RR), m/s.
    pub wheel_speeds: [f64; 4],
    /// The steering mode of the command the ECU follows (`None`: no command yet).
    pub steering_mode: Option<SteeringMode>,
}

/// Each bus's load (bus 1, 2, 3, 1b; 0–1) over windows of `window` consecutive samples of
/// `trace`, stamped at each window's end: what the buses carried over the run.
pub fn windowed_loads(trace: &[Sample], window: usize) -> [Vec<(Timestamp, f64)>; 4] {
    let mut loads: [Vec<(Timestamp, f64)>; 4] = Default::default();
    let ends = trace.iter().step_by(window.max(1));
    for (from, to) in ends.clone().zip(ends.skip(1)) {
        let span = to.t.saturating_since(from.t).as_nanos() as f64;
        if span <= 0.0 {
            continue;
        }
        for (bus, series) in loads.iter_mut().enumerate() {
            let busy = |s: &Sample| s.busy_ns.get(bus).copied().unwrap_or(0);
            let load = busy(to).saturating_sub(busy(from)) as f64 / span;
            series.push((to.t, load));
        }
    }
    loads
}

/// One steering step at a standstill: the ADS's command from `from` to `to` degrees and the
/// front-left wheel's angle every millisecond after it.
#[derive(Debug, Clone, PartialEq)]
pub struct StepResponse {
    /// The angle before, degrees.
    pub from: f64,
    /// The commanded angle, degrees.
    pub to: f64,
    /// Seconds since the command, one a millisecond.
    pub times: Vec<f64>,
    /// The wheel's angle at those times, degrees.
    pub angles: Vec<f64>,
}

impl StepResponse {
    /// Rise, settling, overshoot and steady-state error of this step.
    pub fn metrics(&self) -> Result<StepMetrics, MetricsError> {
        step_metrics(&self.times, &self.angles, self.from, self.to)
    }

    /// The angle's range (largest − smallest) over the second half of the record, degrees: a
    /// wheel that holds its angle has little more than the sensor's noise; one that hunts, the
    /// width of its swing.
    pub fn hold_peak_to_peak(&self) -> f64 {
        let half = self.angles.get(self.angles.len() / 2..).unwrap_or_default();
        let (low, high) = half
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), a| {
                (lo.min(*a), hi.max(*a))
            });
        if half.is_empty() {
            0.0
        } else {
            high - low
        }
    }
}

/// The steering's responses: each step of the step test, and the tank turn.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SteeringRecord {
    /// The step test's responses, one a step.
    pub steps: Vec<StepResponse>,
    /// The tank turn: the front-left wheel every millisecond from the command into tank
    /// steering until the tank turn ends, and when it began.
    pub tank_turn: Option<(Timestamp, StepResponse)>,
    tank_over: bool,
}

impl SteeringRecord {
    /// The front-left wheel's `angle` at `now`: into the step test's current `step` while it
    /// is held, and into the tank turn's record while the vehicle follows a tank-steering
    /// command (`tank`; the first such stretch), which aims the wheel at `tank_target()`
    /// degrees.
    pub(crate) fn note(
        &mut self,
        now: Timestamp,
        angle: f64,
        tank: bool,
        tank_target: impl FnOnce() -> f64,
        step: Option<ActiveStep>,
    ) {
        self.note_tank_turn(now, angle, tank, tank_target);
        let Some(step) = step else {
            return;
        };
        if self.steps.len() == step.index {
            self.steps.push(StepResponse {
                from: step.from,
                to: step.to,
                times: Vec::new(),
                angles: Vec::new(),
            });
        }
        if now >= step.started.saturating_add(STEP_HOLD) {
            return;
        }
        if let Some(response) = self.steps.get_mut(step.index) {
            let since = now.saturating_since(step.started);
            response.times.push(since.as_secs_f64());
            response.angles.push(angle);
        }
    }

    fn note_tank_turn(
        &mut self,
        now: Timestamp,
        angle: f64,
        tank: bool,
        tank_target: impl FnOnce() -> f64,
    ) {
        match &mut self.tank_turn {
            None if tank => {
                self.tank_turn = Some((
                    now,
                    StepResponse {
                        from: angle,
                        to: tank_target(),
                        times: vec![0.0],
                        angles: vec![angle],
                    },
                ));
            }
            Some((started, response)) if tank && !self.tank_over => {
                response
                    .times
                    .push(now.saturating_since(*started).as_secs_f64());
                response.angles.push(angle);
            }
            Some(_) => self.tank_over |= !tank,
            None => {}
        }
    }
}

/// How long one identifier's frames took on a bus: from being queued at the controller to the
/// end of the frame (arbitration, waiting, retransmissions and the frame itself).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ResponseTimes {
    /// The identifier.
    pub id: Id,
    /// Frames sent.
    pub count: u64,
    /// Their summed response times, ns.
    pub total_ns: u64,
    /// The longest, ns.
    pub max_ns: u64,
}

/// What the run saw of the attacks: commands the vehicle took that the ADS never sent, and
/// speeds the ADS took that the tug never had.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SecurityWatch {
    /// Commands the ECU accepted that differ from the ADS's own (by > 5° or > 1 m/s).
    pub foreign_commands: u64,
    /// State frames the ADS accepted whose speed is > 1.5 m/s off the tug's.
    pub false_speeds: u64,
    accepted: u64,
    speed_at: Option<Timestamp>,
}

impl SecurityWatch {
    /// The ECU has now accepted `accepted` commands: when that is one more, `commands` gives
    /// the ADS's own and the one taken, as (steering °, velocity m/s), to be compared.
    pub(crate) fn note_accepted(
        &mut self,
        accepted: u64,
        commands: impl FnOnce() -> Option<[(f64, f64); 2]>,
    ) {
        if accepted == self.accepted {
            return;
        }
        self.accepted = accepted;
        if let Some([own, taken]) = commands() {
            if (own.0 - taken.0).abs() > 5.0 || (own.1 - taken.1).abs() > 1.0 {
                self.foreign_commands += 1;
            }
        }
    }

    /// The ADS's view of the speed, taken `at` (`reported`), beside the tug's `actual()` one.
    pub(crate) fn note_speed(
        &mut self,
        at: Option<Timestamp>,
        reported: Option<f64>,
        actual: impl FnOnce() -> f64,
    ) {
        if at == self.speed_at {
            return;
        }
        self.speed_at = at;
        if reported.is_some_and(|v| (v - actual()).abs() > 1.5) {
            self.false_speeds += 1;
        }
    }
}

/// A bus's response times by identifier, lowest first.
#[derive(Debug, Clone, Default)]
pub(crate) struct ResponseLog {
    pub(crate) times: Vec<ResponseTimes>,
    /// Where each standard identifier's entry is in `times`, plus one (0: none yet), by its
    /// value: every frame on every bus is counted, and a search by identifier would cost more
    /// than the counting. Empty until the first frame.
    standard: Vec<usize>,
}

impl ResponseLog {
    /// One more frame of `id` that took `latency_ns`.
    pub(crate) fn note(&mut self, id: Id, latency_ns: u64) {
        let known = match id {
            Id::Standard(s) => self
                .standard
                .get(usize::from(s.as_raw()))
                .and_then(|at| at.checked_sub(1)),
            Id::Extended(_) => self.times.binary_search_by_key(&id, |t| t.id).ok(),
        };
        let index = known.unwrap_or_else(|| self.insert(id));
        if let Some(t) = self.times.get_mut(index) {
            t.count += 1;
            t.total_ns = t.total_ns.saturating_add(latency_ns);
            t.max_ns = t.max_ns.max(latency_ns);
        }
    }

    /// A new identifier in its place; the standard identifiers' places are worked out again.
    fn insert(&mut self, id: Id) -> usize {
        let index = self
            .times
            .binary_search_by_key(&id, |t| t.id)
            .unwrap_or_else(|at| at);
        self.times.insert(
            index,
            ResponseTimes {
                id,
                count: 0,
                total_ns: 0,
                max_ns: 0,
            },
        );
        self.standard.clear();
        self.standard.resize(0x800, 0);
        for (at, t) in self.times.iter().enumerate() {
            if let Id::Standard(standard) = t.id {
                if let Some(slot) = self.standard.get_mut(usize::from(standard.as_raw())) {
                    *slot = at + 1;
                }
            }
        }
        index
    }
}

/// The supervisor's states as a run's events name them, and what changed since the last look.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SupervisorWatch {
    seen: (Watchdog, EstopState, ControlMode),
    degraded: Option<Channel>,
}

impl Default for SupervisorWatch {
    /// As a supervisor starts: full braking, no E-stop, manual, both buses agreeing.
    fn default() -> Self {
        SupervisorWatch {
            seen: (
                Watchdog::FullBraking,
                EstopState::Normal,
                ControlMode::Manual,
            ),
            degraded: None,
        }
    }
}

impl SupervisorWatch {
    /// The supervisor's watchdog level, E-stop state, mode and redundancy now: each that
    /// changed given to `record`.
    pub(crate) fn note(
        &mut self,
        seen: (Watchdog, EstopState, ControlMode),
        degraded: Option<Channel>,
        mut record: impl FnMut(Happening),
    ) {
        let (watchdog, estop, mode) = self.seen;
        if core::mem::discriminant(&seen.0) != core::mem::discriminant(&watchdog) {
            record(Happening::Watchdog(seen.0));
        }
        if seen.1 != estop {
            record(Happening::Estop(seen.1));
        }
        if seen.2 != mode {
            record(Happening::Mode(seen.2));
        }
        self.seen = seen;
        if degraded != self.degraded {
            self.degraded = degraded;
            record(Happening::Redundancy(degraded));
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use proptest::prelude::*;
    use std::collections::BTreeMap;

    fn identifier() -> impl Strategy<Value = Id> {
        prop_oneof![
            (0u32..0x800).prop_map(|raw| Id::standard(raw).unwrap()),
            (0u32..8).prop_map(|raw| Id::standard(raw).unwrap()),
            (0u32..8).prop_map(|raw| Id::extended(raw << 18 | raw).unwrap()),
            (0u32..0x2000_0000).prop_map(|raw| Id::extended(raw).unwrap()),
        ]
    }

    proptest! {
        /// Each identifier's count, total and longest, lowest identifier first, as a map by
        /// identifier has them, in whatever order new identifiers come.
        #[test]
        fn response_times_are_kept_per_identifier_in_order(
            frames in proptest::collection::vec((identifier(), 0u64..1_000_000), 0..300),
        ) {
            let mut log = ResponseLog::default();
            let mut expected: BTreeMap<Id, (u64, u64, u64)> = BTreeMap::new();
            for (id, latency) in frames {
                log.note(id, latency);
                let e = expected.entry(id).or_default();
                *e = (e.0 + 1, e.1 + latency, e.2.max(latency));
            }
            let got: Vec<(Id, (u64, u64, u64))> = log
                .times
                .iter()
                .map(|t| (t.id, (t.count, t.total_ns, t.max_ns)))
                .collect();
            prop_assert_eq!(got, expected.into_iter().collect::<Vec<_>>());
        }
    }

    fn ms(n: u64) -> Timestamp {
        Timestamp::from_nanos(n * 1_000_000)
    }

    #[test]
    fn a_step_is_recorded_while_held_and_the_tank_turn_only_in_its_first_stretch() {
        let mut record = SteeringRecord::default();
        let step = ActiveStep {
            index: 0,
            from: 0.0,
            to: 10.0,
            started: ms(100),
        };
        let hold = u64::try_from(STEP_HOLD.as_millis()).unwrap();
        for t in [100, 101, 100 + hold - 1, 100 + hold, 100 + hold + 5] {
            record.note(ms(t), 1.0, false, || f64::NAN, Some(step));
        }
        let recorded = record.steps.first().unwrap();
        assert_eq!(record.steps.len(), 1);
        assert_eq!(recorded.times, [0.0, 0.001, (hold - 1) as f64 / 1e3]);
        assert_eq!((recorded.from, recorded.to), (0.0, 10.0));
        assert_eq!(record.tank_turn, None);
        // The tank turn: from its first command on, its target asked once, until it ends;
        // a second stretch of tank steering is not recorded.
        let mut asked = 0;
        for (t, tank) in [(5, false), (6, true), (7, true), (8, false), (9, true)] {
            let target = || {
                asked += 1;
                45.0
            };
            record.note(
                ms(t),
                f64::from(u32::try_from(t).unwrap()),
                tank,
                target,
                None,
            );
        }
        let (started, turn) = record.tank_turn.as_ref().unwrap();
        assert_eq!((*started, asked), (ms(6), 1));
        assert_eq!((turn.from, turn.to), (6.0, 45.0));
        assert_eq!(turn.angles, [6.0, 7.0]);
    }

    #[test]
    fn attacks_count_each_new_command_taken_and_each_new_speed_once() {
        let mut watch = SecurityWatch::default();
        let foreign = || Some([(0.0, 1.0), (5.5, 1.0)]);
        watch.note_accepted(1, foreign);
        // The same count again: not a new command.
        watch.note_accepted(1, foreign);
        watch.note_accepted(2, || Some([(0.0, 1.0), (4.9, 1.9)]));
        watch.note_accepted(3, || Some([(0.0, 1.0), (0.0, 2.5)]));
        watch.note_accepted(4, || None);
        assert_eq!(watch.foreign_commands, 2);
        watch.note_speed(Some(ms(1)), Some(3.0), || 1.0);
        watch.note_speed(Some(ms(1)), Some(3.0), || 1.0);
        watch.note_speed(Some(ms(2)), Some(2.4), || 1.0);
        watch.note_speed(Some(ms(3)), None, || 1.0);
        assert_eq!(watch.false_speeds, 1);
    }

    #[test]
    fn the_supervisors_changes_are_named_once_each() {
        let mut watch = SupervisorWatch::default();
        let mut events = Vec::new();
        let mut note = |watch: &mut SupervisorWatch, seen, degraded| {
            watch.note(seen, degraded, |what| {
                events.push(format!("{} {what}", what.kind()));
            });
        };
        let engaged = (
            Watchdog::Normal,
            EstopState::Normal,
            ControlMode::Autonomous,
        );
        note(&mut watch, engaged, None);
        note(&mut watch, engaged, None);
        note(&mut watch, engaged, Some(Channel::A));
        note(&mut watch, engaged, None);
        assert_eq!(
            events,
            [
                "watchdog normal",
                "mode Autonomous",
                "redundancy bus 1 alone (bus 1b lost)",
                "redundancy both buses agree"
            ]
        );
    }
}
