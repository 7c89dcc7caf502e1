//! The redundant tug's backup steering: at each corner an electrohydraulic proportional valve
//! in parallel with the orbital valve (as steering units built for GPS steering carry one),
//! metering oil to the same cylinder, driven by a valve driver of its own on the drives bus
//! (nodes 0x31–0x34, spoken to in CiA 402 profile velocity: the wheel rate it meters). A
//! parallel valve is what a real electrohydraulic tug can carry that survives the primary's
//! three failures: a seized motor or valve input leaves the orbital valve closed and the
//! parallel path free; a runaway motor is stopped by switching its drive off; a lost drive
//! leaves the valve closed.
//!
//! Each corner's pair is judged by [`ActuatorPair`] against the rate of the corner's voted
//! angle (the 2-out-of-3 of sensors the primary's loop does not use). The primary is expected
//! to move at the rate its drive's position profile allows — the speed from which its
//! deceleration stops the wheel at the target, beyond a rest band — and its process data are
//! its heartbeat. In the backup's hands the ECU closes the loop on the voted angle itself, by
//! the same law within its valve's reach.

use core::time::Duration;

use bywire_canopen::cia402::{DriveController, Mode, Setpoint, State};
use bywire_canopen::master::{Controlled, Master};
use bywire_core::num::round_to_i32;
use bywire_core::Timestamp;
use bywire_vehicle::backup::{ActuatorPair, Feedback, FeedbackCheck, InCharge};
use bywire_vehicle::bindings::{ActuatorStatusBinding, MeasuredBinding};
use bywire_vehicle::profile::LoadedProfile;

use crate::drives::STEERING_UNITS_PER_DEG;

/// How far a wheel may be from its target before its actuator must move it, degrees: the
/// position loop's rest band, wider than the sensors' noise.
const REST_BAND_DEG: f64 = 0.5;
/// How far past its target a wheel may swing on a step before moving on away from it is
/// wrong, degrees (the drives overshoot a 20° step by up to 1.7°: their motor's lag).
const OVERSHOOT_DEG: f64 = 2.5;
/// The steering drives' profile: 20°/s at most, decelerating at 60°/s² (their dictionary's
/// profile velocity and deceleration).
const PRIMARY_PROFILE: (f64, f64) = (20.0, 60.0);
/// The backup loop's: 18°/s at most (its valve meters up to 20°/s), decelerating at
/// 60°/s².
const BACKUP_PROFILE: (f64, f64) = (18.0, 60.0);
/// The voted angles are sampled this often for the rate...
const SAMPLE_PERIOD: Duration = Duration::from_millis(10);
/// ... and the rate is taken over at least this long: the voted angle moves in steps of
/// 0.1° (the angle modules' resolution), 1°/s over this window, below the check's "still"
/// (over 40 ms a step would be 2.5°/s, and a stuck wheel would seem to move).
const RATE_WINDOW: Duration = Duration::from_millis(100);
/// Samples kept: the window and one period more.
const SAMPLES: usize = 12;

/// One corner's actuators as the profile declares them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SteeringPair {
    /// The primary steering drive's node ID.
    pub primary: u8,
    /// The backup valve driver's node ID.
    pub backup: u8,
    /// How their feedback is judged.
    pub check: FeedbackCheck,
}

/// The four corners' pairs a profile declares (`None`: it declares no actuator pairs), or
/// why the tug's ECU cannot take them: it needs one pair a corner, in corner order, of CANopen
/// drives, each judged by its own corner's voted angle.
pub fn pairs_of(loaded: &LoadedProfile) -> Result<Option<[SteeringPair; 4]>, String> {
    let (Some(section), Some(bindings)) = (
        loaded.profile.fail_operational.as_ref(),
        loaded.bindings.fail_operational.as_ref(),
    ) else {
        return Ok(None);
    };
    if bindings.actuators.is_empty() {
        return Ok(None);
    }
    let mut pairs = Vec::with_capacity(4);
    for (corner, (roles, binding)) in section
        .actuators
        .iter()
        .zip(&bindings.actuators)
        .enumerate()
    {
        let key = format!("fail_operational.actuators[{corner}]");
        match (binding.primary, binding.backup, binding.measured) {
            (
                ActuatorStatusBinding::CanOpen(primary),
                ActuatorStatusBinding::CanOpen(backup),
                MeasuredBinding::VotedRate(voted),
            ) if voted == corner => pairs.push(SteeringPair {
                primary,
                backup,
                check: roles.check(),
            }),
            _ => {
                return Err(format!(
                    "{key}: the tug steers each corner by CANopen drives judged by that corner's voted angle (corners in order FL, FR, RL, RR)"
                ))
            }
        }
    }
    let count = pairs.len();
    pairs
        .try_into()
        .map(Some)
        .map_err(|_| format!("fail_operational.actuators: one pair a corner, four, not {count}"))
}

/// What changed at a corner this step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PairChange {
    /// The actuator now in charge (the backup: the primary failed; neither: the backup too).
    InCharge(InCharge),
    /// The idle backup's driver was stopped by the master: no backup left.
    BackupLost,
}

#[derive(Debug, Clone, Copy)]
struct Corner {
    primary: u8,
    backup: u8,
    pair: ActuatorPair,
    /// The idle backup's loss, once reported.
    backup_lost: bool,
}

/// The four corners' actuator pairs and the voted angles' recent history.
#[derive(Debug, Clone)]
pub struct BackupSteering {
    corners: [Corner; 4],
    /// Voted angles (NaN: no vote) at each sample time, oldest first.
    samples: [(Timestamp, [f64; 4]); SAMPLES],
    /// How many of them were taken (the others are not samples).
    taken: usize,
}

/// The rate toward the target for a wheel `error` degrees from it under the profile
/// `(fastest, deceleration)`: the speed that deceleration stops from within the error (none
/// inside the rest band).
fn profile_rate(error: f64, (fastest, deceleration): (f64, f64)) -> f64 {
    if error.abs() <= REST_BAND_DEG {
        return 0.0;
    }
    libm::sqrt(2.0 * deceleration * error.abs())
        .min(fastest)
        .copysign(error)
}

fn drive(master: &mut Master, node: u8) -> Option<&mut DriveController> {
    match master.controlled(node) {
        Some(Controlled::Drive(d)) => Some(d),
        _ => None,
    }
}

impl BackupSteering {
    /// The pairs FL, FR, RL, RR, the primaries in charge from `now`.
    pub fn new(pairs: [SteeringPair; 4], now: Timestamp) -> Self {
        BackupSteering {
            corners: pairs.map(|p| Corner {
                primary: p.primary,
                backup: p.backup,
                pair: ActuatorPair::new(p.check, now),
                backup_lost: false,
            }),
            samples: [(Timestamp::ZERO, [f64::NAN; 4]); SAMPLES],
            taken: 0,
        }
    }

    /// The backup valve drivers, for the master: hot, enabled at zero rate (a closed valve),
    /// their heartbeats watched.
    pub fn add_drivers(&self, master: &mut Master) {
        for corner in &self.corners {
            crate::drives::add_drive(master, corner.backup, Mode::ProfileVelocity);
        }
    }

    /// The backup valve drivers' node IDs.
    pub fn backup_nodes(&self) -> [u8; 4] {
        self.corners.map(|c| c.backup)
    }

    /// Which actuator steers `corner` (0 FL … 3 RR).
    pub fn in_charge(&self, corner: usize) -> InCharge {
        self.corners
            .get(corner)
            .map_or(InCharge::Neither, |c| c.pair.in_charge())
    }

    /// Whether a stop of drive `node` is this layer's to answer: a primary no longer in
    /// charge, or a backup (idle, its loss is reported as such; in charge, its pair judges it).
    pub fn answers_for(&self, node: u8) -> bool {
        self.corners.iter().any(|c| {
            c.backup == node || (c.primary == node && c.pair.in_charge() != InCharge::Primary)
        })
    }

    /// Keep the voted angles (`None`: no vote) for the rate, once a sample period.
    pub fn sample(&mut self, now: Timestamp, voted: [Option<f64>; 4]) {
        let newest = self.samples.last().map_or(Timestamp::ZERO, |(t, _)| *t);
        if self.taken > 0 && now.saturating_since(newest) < SAMPLE_PERIOD {
            return;
        }
        self.samples.rotate_left(1);
        if let Some(slot) = self.samples.last_mut() {
            *slot = (now, voted.map(|v| v.unwrap_or(f64::NAN)));
        }
        self.taken = self.taken.saturating_add(1).min(SAMPLES);
    }

    /// Each corner's measured rate, °/s: the newest sample against the newest one at least
    /// the window older (`None`: not yet that much history, or no vote in either).
    fn rates(&self) -> [Option<f64>; 4] {
        let mut taken = self.samples.iter().rev().take(self.taken);
        let Some(&(now, newest)) = taken.next() else {
            return [None; 4];
        };
        let Some(&(then, old)) = taken.find(|(t, _)| now.saturating_since(*t) >= RATE_WINDOW)
        else {
            return [None; 4];
        };
        let dt = now.saturating_since(then).as_secs_f64();
        let mut rates = [None; 4];
        for ((rate, new), old) in rates.iter_mut().zip(newest).zip(old) {
            let r = (new - old) / dt;
            *rate = r.is_finite().then_some(r);
        }
        rates
    }

    /// The one step, every ECU poll: judge each corner's actuator in charge at `now` (its
    /// target `targets` and voted angle `voted`, degrees; `steering_on`: the wheels are to be
    /// steered), command the pair on `master`, and say what changed.
    pub fn step(
        &mut self,
        now: Timestamp,
        master: &mut Master,
        (targets, voted): ([f64; 4], [Option<f64>; 4]),
        steering_on: bool,
    ) -> [Option<PairChange>; 4] {
        let rates = self.rates();
        let mut changes = [None; 4];
        for (((corner, change), (target, angle)), rate) in self
            .corners
            .iter_mut()
            .zip(changes.iter_mut())
            .zip(targets.into_iter().zip(voted))
            .zip(rates)
        {
            let before = corner.pair.in_charge();
            let profile = match before {
                InCharge::Primary => PRIMARY_PROFILE,
                InCharge::Backup | InCharge::Neither => BACKUP_PROFILE,
            };
            let asked = match (steering_on, angle) {
                // Swinging past the target, within the overshoot, nothing is asked yet.
                (true, Some(angle))
                    if rate.is_some_and(|r| r * (target - angle) < 0.0)
                        && (target - angle).abs() <= OVERSHOOT_DEG =>
                {
                    0.0
                }
                (true, Some(angle)) => profile_rate(target - angle, profile),
                _ => 0.0,
            };
            let in_charge_node = match before {
                InCharge::Primary => Some(corner.primary),
                InCharge::Backup => Some(corner.backup),
                InCharge::Neither => None,
            };
            // Judged only with a measurement: without a vote the voter's own loss stops the tug.
            // A drive not yet (again) in Operation enabled is not asked to move.
            let feedback = in_charge_node
                .and_then(|node| drive(master, node))
                .zip(rate)
                .map(|(d, measured)| Feedback {
                    demanded: match d.drive_state() {
                        Some(State::OperationEnabled) => asked,
                        _ => 0.0,
                    },
                    measured,
                    drive_fault: d.stopped().is_some(),
                    heartbeat_at: d.last_heard(),
                });
            let after = match feedback {
                Some(feedback) => corner.pair.step(now, feedback),
                None => before,
            };
            if after != before {
                *change = Some(PairChange::InCharge(after));
            }
            // The backup closes the loop on the voted angle; a primary out of charge is off
            // (in charge, the ECU's own commands enable it).
            let backup_rate = match after {
                InCharge::Primary => Some(0.0),
                InCharge::Backup => Some(match (steering_on, angle) {
                    (true, Some(angle)) => profile_rate(target - angle, BACKUP_PROFILE),
                    _ => 0.0,
                }),
                InCharge::Neither => None,
            };
            if after != InCharge::Primary {
                if let Some(d) = drive(master, corner.primary) {
                    d.set_enabled(false);
                }
            }
            if let Some(d) = drive(master, corner.backup) {
                d.set_enabled(backup_rate.is_some());
                d.set_setpoint(Setpoint::Velocity(round_to_i32(
                    backup_rate.unwrap_or(0.0) * STEERING_UNITS_PER_DEG,
                )));
                let idle_lost = after == InCharge::Primary && d.stopped().is_some();
                if idle_lost && !corner.backup_lost && change.is_none() {
                    corner.backup_lost = true;
                    *change = Some(PairChange::BackupLost);
                }
            }
        }
        changes
    }

    /// The primaries in charge again from `now` (a repair at a standstill).
    pub fn reset(&mut self, now: Timestamp) {
        for corner in &mut self.corners {
            corner.pair.reset(now);
            corner.backup_lost = false;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rate_asked_stops_the_wheel_at_its_target_and_is_capped() {
        let profile = (20.0, 60.0);
        assert_eq!(profile_rate(0.4, profile), 0.0);
        assert_eq!(profile_rate(-0.5, profile), 0.0);
        // 1° off at 60°/s²: √120 °/s, which 60°/s² stops within that degree.
        assert!((profile_rate(1.0, profile) - 120f64.sqrt()).abs() < 1e-12);
        assert!((profile_rate(-1.0, profile) + 120f64.sqrt()).abs() < 1e-12);
        assert_eq!(profile_rate(30.0, profile), 20.0);
        assert_eq!(profile_rate(-30.0, profile), -20.0);
    }

    #[test]
    fn the_measured_rate_spans_the_window_and_waits_for_it() {
        let check = FeedbackCheck {
            still: 2.0,
            overrun: 8.0,
            persistence: Duration::from_millis(100),
            heartbeat_timeout: Duration::from_millis(30),
        };
        let pair = SteeringPair {
            primary: 0x11,
            backup: 0x31,
            check,
        };
        let mut steering = BackupSteering::new([pair; 4], Timestamp::ZERO);
        // 10°/s at the front left, still elsewhere, no vote at the rear right; samples every
        // 5 ms are taken every 10 ms.
        for ms in (0u32..=90).step_by(5) {
            let t = f64::from(ms) / 1000.0;
            steering.sample(
                Timestamp::from_millis(u64::from(ms)),
                [Some(10.0 * t), Some(2.0), Some(-1.0), None],
            );
        }
        assert_eq!(steering.rates(), [None; 4], "90 ms is short of the window");
        steering.sample(
            Timestamp::from_millis(100),
            [Some(1.0), Some(2.0), Some(-1.0), None],
        );
        let [fl, fr, rl, rr] = steering.rates();
        assert!((fl.unwrap() - 10.0).abs() < 1e-9, "{fl:?}");
        assert_eq!((fr, rl, rr), (Some(0.0), Some(0.0), None));
    }
}
