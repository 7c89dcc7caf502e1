//! The vehicle control ECU's plausibility check of its steering sensors. Each corner's
//! potentiometer has two tracks: the first feeds the steering drive's position loop (its
//! position actual reaches the ECU on bus 2), the second comes over bus 3 from the I/O node.
//! Tracks that disagree by more than the tolerance for the debounce time, or second tracks
//! gone silent as long, latch a steering fault on that corner; only the operator's reset, with
//! the tracks agreeing again, clears it. Sans-IO, time passed in, no allocation.

use core::time::Duration;

use bywire_core::time::earliest;
use bywire_core::Timestamp;

/// The corners' names, in the order of the arrays here.
pub const CORNERS: [&str; 4] = ["FL", "FR", "RL", "RR"];

/// Why a corner's steering fault latched.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SteeringFault {
    /// The two tracks disagree: (first, second), degrees.
    Disagree {
        /// Which corner.
        corner: usize,
        /// The first track, as the drive reports it.
        first: f64,
        /// The second track, from the I/O node.
        second: f64,
    },
    /// No fresh second track.
    SecondTrackSilent {
        /// Which corner (the first checked).
        corner: usize,
    },
}

impl SteeringFault {
    /// The corner at fault.
    pub fn corner(self) -> usize {
        match self {
            SteeringFault::Disagree { corner, .. }
            | SteeringFault::SecondTrackSilent { corner } => corner,
        }
    }
}

impl core::fmt::Display for SteeringFault {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let name = CORNERS.get(self.corner()).copied().unwrap_or("?");
        match self {
            SteeringFault::Disagree { first, second, .. } => write!(
                f,
                "{name}: the steering sensor's tracks disagree ({first:.1}° / {second:.1}°)"
            ),
            SteeringFault::SecondTrackSilent { .. } => {
                write!(f, "{name}: the steering sensor's second track is silent")
            }
        }
    }
}

/// The check, for four corners.
#[derive(Debug, Clone, PartialEq)]
pub struct SteeringPlausibility {
    /// Tracks further apart than this disagree, degrees.
    pub tolerance_deg: f64,
    /// How long a disagreement lasts before it latches.
    pub debounce: Duration,
    /// A second-track report older than this is no report.
    pub silence: Duration,
    second: Option<(Timestamp, [f64; 4])>,
    bad_since: [Option<Timestamp>; 4],
    faulted: Option<SteeringFault>,
    /// [`Self::next_deadline`], worked out when the state changes (a runner asks for it far
    /// more often).
    deadline: Option<Timestamp>,
}

impl Default for SteeringPlausibility {
    /// The reference tug's values: 3°, 100 ms, 50 ms (five missed 10 ms reports).
    fn default() -> Self {
        SteeringPlausibility {
            tolerance_deg: 3.0,
            debounce: Duration::from_millis(100),
            silence: Duration::from_millis(50),
            second: None,
            bad_since: [None; 4],
            faulted: None,
            deadline: None,
        }
    }
}

impl SteeringPlausibility {
    /// The I/O node's report of the second tracks arrived.
    pub fn second_tracks(&mut self, now: Timestamp, angles: [f64; 4]) {
        self.second = Some((now, angles));
        self.deadline = self.work_out_deadline();
    }

    /// The latched fault, if any.
    pub fn faulted(&self) -> Option<SteeringFault> {
        self.faulted
    }

    /// Compare the first tracks (from the drives) with the second; returns the fault the
    /// moment it latches.
    pub fn check(&mut self, now: Timestamp, first: [f64; 4]) -> Option<SteeringFault> {
        let fault = self.judge(now, first);
        self.deadline = self.work_out_deadline();
        fault
    }

    /// [`Self::check`]'s transition.
    fn judge(&mut self, now: Timestamp, first: [f64; 4]) -> Option<SteeringFault> {
        if self.faulted.is_some() {
            return None;
        }
        let fresh = self
            .second
            .filter(|(at, _)| now.saturating_since(*at) <= self.silence)
            .map(|(_, angles)| angles);
        for (corner, (since, first)) in self.bad_since.iter_mut().zip(first).enumerate() {
            let second = fresh.and_then(|angles| angles.get(corner).copied());
            // Not finite compares as disagreeing: fail closed.
            let fault = match second {
                Some(second) if libm::fabs(first - second) <= self.tolerance_deg => None,
                Some(second) => Some(SteeringFault::Disagree {
                    corner,
                    first,
                    second,
                }),
                None => Some(SteeringFault::SecondTrackSilent { corner }),
            };
            match (fault, *since) {
                (None, _) => *since = None,
                (Some(_), None) => *since = Some(now),
                (Some(fault), Some(from)) if now.saturating_since(from) >= self.debounce => {
                    self.faulted = Some(fault);
                    return Some(fault);
                }
                (Some(_), Some(_)) => {}
            }
        }
        None
    }

    /// When the check next changes on time alone, with the same tracks: a disagreement's
    /// debounce over, or the second tracks' report growing silent. A caller checks when
    /// either track arrives and at this instant, never on a poll for something else, so that
    /// two ECUs given the same frames latch at the same instant.
    pub fn next_deadline(&self) -> Option<Timestamp> {
        self.deadline
    }

    fn work_out_deadline(&self) -> Option<Timestamp> {
        if self.faulted.is_some() {
            return None;
        }
        let debounced = self
            .bad_since
            .iter()
            .flatten()
            .map(|since| since.saturating_add(self.debounce))
            .min();
        let silent = self.second.map(|(at, _)| {
            at.saturating_add(self.silence)
                .saturating_add(Duration::from_nanos(1))
        });
        earliest([debounced, silent])
    }

    /// The operator's reset: clears the latch when every corner's tracks agree now (and the
    /// second tracks are fresh). Returns whether the latch is clear.
    pub fn reset(&mut self, now: Timestamp, first: [f64; 4]) -> bool {
        let fresh = self
            .second
            .filter(|(at, _)| now.saturating_since(*at) <= self.silence);
        let agree = fresh.is_some_and(|(_, second)| {
            first
                .iter()
                .zip(second)
                .all(|(a, b)| libm::fabs(a - b) <= self.tolerance_deg)
        });
        if agree {
            self.faulted = None;
            self.bad_since = [None; 4];
            self.deadline = self.work_out_deadline();
        }
        self.faulted.is_none()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(ms: u64) -> Timestamp {
        Timestamp::from_nanos(ms * 1_000_000)
    }

    /// Feed second tracks every 10 ms and check every millisecond from `from` to `to`;
    /// returns the first fault with its time.
    fn run(
        p: &mut SteeringPlausibility,
        from: u64,
        to: u64,
        first: [f64; 4],
        second: Option<[f64; 4]>,
    ) -> Option<(u64, SteeringFault)> {
        for ms in from..to {
            if let (Some(second), 0) = (second, ms % 10) {
                p.second_tracks(at(ms), second);
            }
            if let Some(fault) = p.check(at(ms), first) {
                return Some((ms, fault));
            }
        }
        None
    }

    /// Checked only when a track arrives and at the check's own deadline, it latches the
    /// same fault at the same instant as checked every 100 µs, over tracks that wander in and
    /// out of the tolerance and second-track reports that pause.
    #[test]
    fn checking_at_arrivals_and_deadlines_is_checking_all_the_time() {
        let mut state = 0x9E37_79B9_u32;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state
        };
        let mut latched = 0;
        for _ in 0..200 {
            let (mut always, mut gated) = (
                SteeringPlausibility::default(),
                SteeringPlausibility::default(),
            );
            let mut first = [0.0; 4];
            let (mut fault_always, mut fault_gated) = (None, None);
            // Checked once at the start, as at an ECU's first poll: silence counts from it.
            let mut arrived = true;
            // Each run's offset between the tracks: from well within the tolerance to well
            // beyond it, the noise taking it across.
            let offset = 2.0 + f64::from(next() % 30) / 10.0;
            for tick in 0..20_000u64 {
                let now = Timestamp::from_nanos(tick * 100_000);
                // A drive's position every 1 ms, the I/O node's report every 10 ms (but for
                // pauses), each wandering around the tolerance.
                if tick % 10 == 3 {
                    let noise = f64::from(next() % 100) / 100.0 - 0.5;
                    first = [0.0, offset + noise, 0.0, 0.0];
                    arrived = true;
                }
                if tick % 100 == 7 && next() % 16 != 0 {
                    let second = [0.0, f64::from(next() % 100) / 100.0 - 0.5, 0.0, 0.0];
                    always.second_tracks(now, second);
                    gated.second_tracks(now, second);
                    arrived = true;
                }
                if let Some(f) = always.check(now, first) {
                    fault_always.get_or_insert((tick, f));
                }
                let due = gated.next_deadline().is_some_and(|d| d <= now);
                if arrived || due {
                    arrived = false;
                    if let Some(f) = gated.check(now, first) {
                        fault_gated.get_or_insert((tick, f));
                    }
                }
            }
            assert_eq!(fault_gated, fault_always);
            latched += usize::from(fault_always.is_some());
        }
        assert!(latched > 20, "only {latched} runs latched");
    }

    #[test]
    fn agreeing_tracks_and_brief_disagreements_pass() {
        let mut p = SteeringPlausibility::default();
        let straight = [0.0, 0.0, 0.0, 0.0];
        assert_eq!(
            run(&mut p, 0, 500, straight, Some([2.9, -2.9, 0.1, 0.0])),
            None
        );
        // 99 ms of disagreement, then agreement: no fault.
        assert_eq!(
            run(&mut p, 500, 599, straight, Some([0.0, 0.0, 3.5, 0.0])),
            None
        );
        assert_eq!(run(&mut p, 599, 900, straight, Some(straight)), None);
        assert_eq!(p.faulted(), None);
    }

    #[test]
    fn a_lasting_disagreement_latches_at_the_debounce_time() {
        let mut p = SteeringPlausibility::default();
        let first = [0.0, 0.0, 5.0, 0.0];
        let (when, fault) = run(&mut p, 0, 1_000, first, Some([0.0, 0.0, -2.0, 0.0])).unwrap();
        assert_eq!(when, 100);
        assert_eq!(
            fault,
            SteeringFault::Disagree {
                corner: 2,
                first: 5.0,
                second: -2.0
            }
        );
        assert_eq!(
            fault.to_string(),
            "RL: the steering sensor's tracks disagree (5.0° / -2.0°)"
        );
        // Latched: agreement alone does not clear it, the reset does only while they agree.
        assert_eq!(run(&mut p, 1_000, 1_100, [0.0; 4], Some([0.0; 4])), None);
        assert_eq!(p.faulted(), Some(fault));
        assert!(!p.reset(at(1_100), [0.0, 0.0, 9.0, 0.0]));
        assert!(p.reset(at(1_100), [0.0; 4]));
        assert_eq!(p.faulted(), None);
    }

    #[test]
    fn a_silent_second_track_or_a_non_finite_reading_fails_closed() {
        let mut p = SteeringPlausibility::default();
        // Nothing ever: silent from the start, latched after the debounce time.
        let (when, fault) = run(&mut p, 0, 1_000, [0.0; 4], None).unwrap();
        assert_eq!(
            (when, fault),
            (100, SteeringFault::SecondTrackSilent { corner: 0 })
        );
        assert!(!p.reset(at(2_000), [0.0; 4]), "no fresh report: no reset");
        let mut p = SteeringPlausibility::default();
        let (_, fault) = run(&mut p, 0, 1_000, [0.0, f64::NAN, 0.0, 0.0], Some([0.0; 4])).unwrap();
        assert_eq!(fault.corner(), 1);
        // Reports that stop: silent 50 ms after the last, latched 100 ms later.
        let mut p = SteeringPlausibility::default();
        assert_eq!(run(&mut p, 0, 200, [0.0; 4], Some([0.0; 4])), None);
        let (when, _) = run(&mut p, 200, 1_000, [0.0; 4], None).unwrap();
        assert_eq!(when, 190 + 51 + 100);
    }
}
