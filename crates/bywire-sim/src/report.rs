//! A run's report: what `bywire sim` writes as `metrics.json` (and what a caller of the
//! library reads without it) — the events in time order, the tracking error, the steering
//! steps' figures, the command-to-echo latency, the buses' loads and frame counts, the
//! battery, the supervisor's counts.

use core::time::Duration;

use serde::Serialize;

use bywire_core::Timestamp;

use crate::attacker::Attacker;
use crate::event::{Happening, SimEvent};
use crate::fail_operational::FailOperationalRecord;
use crate::mission::{MissionEvent, Phase};
use crate::record::{ResponseTimes, StepResponse, TruthSample};
use crate::tug::Tug;

/// One event of the run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EventRecord {
    /// When, s.
    pub t_s: f64,
    /// What kind (`watchdog`, `estop`, `fault`, `engaged`, `arrived`, ...).
    pub kind: String,
    /// The detail.
    pub detail: String,
}

/// The route tracking error (the true pose against the route), m.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Tracking {
    /// Largest.
    pub max: f64,
    /// Mean.
    pub mean: f64,
}

/// One steering step's figures, or why there are none.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum StepRecord {
    /// Measured.
    Measured {
        /// From, degrees.
        from_deg: f64,
        /// To, degrees.
        to_deg: f64,
        /// Rise time (10–90 %), s (`None`: it never rose that far).
        rise_s: Option<f64>,
        /// Settling time (2 %), s.
        settling_s: f64,
        /// Settling time (5 %), s.
        settling_5_s: f64,
        /// Overshoot, %.
        overshoot_percent: f64,
        /// Steady-state error, degrees.
        steady_state_error_deg: f64,
    },
    /// Not measurable.
    Failed {
        /// From, degrees.
        from_deg: f64,
        /// To, degrees.
        to_deg: f64,
        /// Why.
        error: String,
    },
}

impl StepRecord {
    /// The figures of one recorded step.
    pub fn of(step: &StepResponse) -> StepRecord {
        match step.metrics() {
            Ok(m) => StepRecord::Measured {
                from_deg: step.from,
                to_deg: step.to,
                rise_s: m.rise_time,
                settling_s: m.settling_time_2,
                settling_5_s: m.settling_time_5,
                overshoot_percent: m.overshoot_percent,
                steady_state_error_deg: m.steady_state_error,
            },
            Err(e) => StepRecord::Failed {
                from_deg: step.from,
                to_deg: step.to,
                error: e.to_string(),
            },
        }
    }
}

/// The front-left wheel through the tank turn.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TankTurnRecord {
    /// Its step into the tank angle (settling as for the steering steps).
    #[serde(flatten)]
    pub step: StepRecord,
    /// Its angle's range over the second half of the turn, degrees: the sensor's noise when it
    /// holds, the swing when it hunts.
    pub hold_peak_to_peak_deg: f64,
    /// How long the turn took, s.
    pub duration_s: f64,
}

/// One phase of the mission: from when to when, s (the last ends with the run).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PhaseRecord {
    /// Its name (`step test`, `cruise`, `crab approach`, `tank turn`, `stop`).
    pub name: &'static str,
    /// When it began.
    pub from_s: f64,
    /// When the next began, or the run ended.
    pub to_s: f64,
}

impl PhaseRecord {
    /// The phases of `events`, a run that ended at `end`.
    pub fn all(events: &[SimEvent], end: Timestamp) -> Vec<PhaseRecord> {
        let starts: Vec<(Timestamp, Phase)> = events
            .iter()
            .filter_map(|e| match e.what {
                Happening::Mission(MissionEvent::Phase(phase)) => Some((e.t, phase)),
                _ => None,
            })
            .collect();
        let ends = starts.iter().skip(1).map(|(t, _)| *t).chain([end]);
        starts
            .iter()
            .zip(ends)
            .map(|((from, phase), to)| PhaseRecord {
                name: phase.name(),
                from_s: seconds(*from),
                to_s: seconds(to),
            })
            .collect()
    }
}

/// The crab approach as the plant made it: how far the tug moved sideways and forward of the
/// heading it held, and how much that heading changed.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CrabRecord {
    /// Sideways (+ left of the heading at its start), m.
    pub lateral_m: f64,
    /// Along the heading, m.
    pub forward_m: f64,
    /// The heading's change, degrees (0: held).
    pub heading_change_deg: f64,
    /// The front-left wheel's largest angle, degrees.
    pub max_wheel_angle_deg: f64,
    /// How long it took, s.
    pub duration_s: f64,
}

impl CrabRecord {
    /// The first crab approach among `phases`, from the plant's `truth`.
    pub fn of(phases: &[PhaseRecord], truth: &[TruthSample]) -> Option<CrabRecord> {
        let phase = phases
            .iter()
            .find(|p| p.name == Phase::CrabApproach.name())?;
        let during: Vec<&TruthSample> = truth
            .iter()
            .filter(|s| (phase.from_s..=phase.to_s).contains(&seconds(s.t)))
            .collect();
        let (first, last) = (during.first()?, during.last()?);
        let (dx, dy) = (last.pose.x - first.pose.x, last.pose.y - first.pose.y);
        let (sin, cos) = (libm::sin(first.pose.yaw), libm::cos(first.pose.yaw));
        let turned = libm::remainder(last.pose.yaw - first.pose.yaw, 2.0 * core::f64::consts::PI);
        Some(CrabRecord {
            lateral_m: -dx * sin + dy * cos,
            forward_m: dx * cos + dy * sin,
            heading_change_deg: turned.to_degrees(),
            max_wheel_angle_deg: during
                .iter()
                .filter_map(|s| s.wheel_angles_deg.first())
                .fold(
                    0.0,
                    |max: f64, a| if a.abs() > max.abs() { *a } else { max },
                ),
            duration_s: phase.to_s - phase.from_s,
        })
    }
}

/// Latencies as nearest-rank percentiles, ms.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Percentiles {
    /// How many.
    pub count: usize,
    /// Median.
    pub p50: Option<f64>,
    /// 95th percentile.
    pub p95: Option<f64>,
    /// 99th percentile.
    pub p99: Option<f64>,
    /// Largest.
    pub max: Option<f64>,
}

impl Percentiles {
    /// Of `latencies`.
    pub fn of(latencies: &[Duration]) -> Percentiles {
        let mut sorted: Vec<f64> = latencies.iter().map(|d| d.as_secs_f64() * 1e3).collect();
        sorted.sort_by(f64::total_cmp);
        // Nearest rank: the ceil(percent/100 · n)-th value, in integers.
        let rank = |percent: usize| {
            let index = percent.saturating_mul(sorted.len()).div_ceil(100);
            sorted.get(index.saturating_sub(1)).copied()
        };
        Percentiles {
            count: sorted.len(),
            p50: rank(50),
            p95: rank(95),
            p99: rank(99),
            max: sorted.last().copied(),
        }
    }
}

/// A value for each of the tug's buses.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PerBus<T> {
    /// Bus 1.
    pub bus1: T,
    /// Bus 2.
    pub bus2: T,
    /// Bus 3.
    pub bus3: T,
    /// Bus 1b.
    pub bus1b: T,
}

/// The supervisor's command counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct SupervisorCounts {
    /// Valid commands.
    pub accepted: u64,
    /// Checksum failures.
    pub checksum: u64,
    /// Repeated counters.
    pub repeated: u64,
    /// Skipped counters.
    pub skipped: u64,
    /// Out-of-range setpoints.
    pub out_of_range: u64,
    /// Redundant copies that disagreed.
    pub disagreements: u64,
    /// Secured commands that failed verification.
    pub authentication: u64,
    /// Other secured frames (E-stop, emergency brake) that failed verification.
    pub unauthenticated: u64,
}

/// What the attacks achieved, and what the secured variant refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct SecurityCounts {
    /// The secured variant ran.
    pub secoc: bool,
    /// Frames the attacker sent.
    pub attacker_frames: u64,
    /// Commands the ECU took that the ADS never sent.
    pub foreign_commands: u64,
    /// State frames the ADS took whose speed the tug never had.
    pub false_speeds: u64,
    /// Feedback frames the ADS refused as unauthenticated.
    pub ads_authentication: u64,
    /// The ECU's verifications: accepted, and refused by reason.
    pub ecu_accepted: u64,
    /// Refused: the MAC is wrong (forged).
    pub ecu_mac: u64,
    /// Refused: authentic but not fresh (replayed).
    pub ecu_stale: u64,
    /// Refused: not a secured frame's shape.
    pub ecu_malformed: u64,
    /// Refused: beyond the freshness window.
    pub ecu_window: u64,
}

/// A run's report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunReport {
    /// The scenario's name.
    pub scenario: String,
    /// The seed.
    pub seed: u64,
    /// The logs' time of the run's start, ns since the Unix epoch (event times are from it).
    pub start_time_ns: u64,
    /// Simulated time, s.
    pub sim_seconds: f64,
    /// The route was completed.
    pub completed: bool,
    /// What happened, in time order.
    pub events: Vec<EventRecord>,
    /// The tracking error.
    pub tracking_error_m: Tracking,
    /// The step test's steps.
    pub steering_steps: Vec<StepRecord>,
    /// The mission's phases in turn.
    pub phases: Vec<PhaseRecord>,
    /// The crab approach (`None`: the run made none).
    pub crab_approach: Option<CrabRecord>,
    /// The tank turn's front-left wheel, from its angle before to its tank angle (`None`: the
    /// run made no tank turn).
    pub tank_turn: Option<TankTurnRecord>,
    /// Command to heartbeat echo, as the ADS measured it.
    pub echo_latency_ms: Percentiles,
    /// Each bus's load over the run, 0–1.
    pub bus_load: PerBus<f64>,
    /// Frames each bus carried.
    pub frames: PerBus<usize>,
    /// Each bus's response times by identifier: from queued at the controller to the end of
    /// the frame (`bywire latency --predict` bounds them from a DBC).
    pub response_times_us: PerBus<Vec<ResponseRecord>>,
    /// The battery's state of charge at the end.
    pub battery_soc: f64,
    /// The supervisor's counts.
    pub supervisor: SupervisorCounts,
    /// The attacks' outcome and the verifications.
    pub security: SecurityCounts,
    /// The DTCs the vehicle control ECU holds at the end, as a tester reads them.
    pub dtcs: Vec<DtcRecord>,
    /// The redundant tug's ECU faults and fault pairs, one record each (none on the tug with
    /// one ECU).
    pub fail_operational: Vec<FailOperationalRecord>,
    /// Wall-clock time the run took, s.
    pub wall_seconds: f64,
}

/// One identifier's response times on a bus.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ResponseRecord {
    /// The identifier in hex, as candump writes it.
    pub id: String,
    /// Frames sent.
    pub frames: u64,
    /// Mean response time, µs.
    pub mean: f64,
    /// Longest response time, µs.
    pub max: f64,
}

impl ResponseRecord {
    fn all(times: &[ResponseTimes]) -> Vec<ResponseRecord> {
        times
            .iter()
            .map(|t| ResponseRecord {
                id: match t.id {
                    bywire_core::Id::Standard(_) => format!("{:03X}", t.id.as_raw()),
                    bywire_core::Id::Extended(_) => format!("{:08X}", t.id.as_raw()),
                },
                frames: t.count,
                mean: t.total_ns as f64 / t.count.max(1) as f64 / 1e3,
                max: t.max_ns as f64 / 1e3,
            })
            .collect()
    }
}

/// One DTC of the ECU's memory.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct DtcRecord {
    /// The DTC, 24 bits in hex (as UDS carries it).
    pub dtc: String,
    /// Its SAE J2012 form.
    pub code: String,
    /// Its name.
    pub name: String,
    /// Its status byte.
    pub status: u8,
    /// The status bits set, by their ISO 14229-1 names.
    pub status_bits: Vec<&'static str>,
}

impl DtcRecord {
    /// The ECU's DTC memory.
    pub fn all(tug: &Tug) -> Vec<DtcRecord> {
        let names: std::collections::BTreeMap<u32, String> =
            bywire_tug::diagnostics::dtc_names().into_iter().collect();
        let Some(ecu) = tug.vehicle_control_ecu() else {
            return Vec::new();
        };
        ecu.diagnostics()
            .server()
            .dtcs()
            .map(|(dtc, status)| DtcRecord {
                dtc: format!("{dtc:06X}"),
                code: bywire_diag::describe::dtc_code(dtc),
                name: names.get(&dtc).cloned().unwrap_or_default(),
                status,
                status_bits: bywire_diag::describe::status_bits(status),
            })
            .collect()
    }
}

impl SecurityCounts {
    /// The run's counts so far.
    pub fn of(tug: &Tug) -> SecurityCounts {
        let table = tug.ecu().and_then(|e| e.wire().table());
        let verified = table.map(|t| t.stats().frames).unwrap_or_default();
        SecurityCounts {
            secoc: table.is_some(),
            attacker_frames: tug.attacker().map_or(0, Attacker::sent),
            foreign_commands: tug.security.foreign_commands,
            false_speeds: tug.security.false_speeds,
            ads_authentication: tug
                .ads()
                .map(|a| a.ads().stats().authentication)
                .unwrap_or_default(),
            ecu_accepted: verified.accepted,
            ecu_mac: verified.mac,
            ecu_stale: verified.stale,
            ecu_malformed: verified.malformed,
            ecu_window: verified.window,
        }
    }
}

/// A run's time in seconds, as reports write it.
pub(crate) fn seconds(t: Timestamp) -> f64 {
    t.as_nanos() as f64 / 1e9
}

impl RunReport {
    /// The report of `tug`'s run so far, its logs' clock starting at `start` (since the Unix
    /// epoch).
    pub fn of(
        tug: &Tug,
        scenario: &str,
        seed: u64,
        start: Timestamp,
        completed: bool,
        wall: Duration,
    ) -> Self {
        let errors = &tug.tracking_errors;
        let max = errors.iter().copied().fold(0.0, f64::max);
        let mean = if errors.is_empty() {
            0.0
        } else {
            errors.iter().sum::<f64>() / errors.len() as f64
        };
        let mut events: Vec<EventRecord> = tug
            .engaged_at()
            .map(|at| EventRecord {
                t_s: seconds(at),
                kind: "engaged".into(),
                detail: "the vehicle reports autonomous mode".into(),
            })
            .into_iter()
            .chain(tug.events.iter().map(|e| EventRecord {
                t_s: seconds(e.t),
                kind: e.kind().into(),
                detail: e.what.to_string(),
            }))
            .collect();
        // Stable: events of one instant keep their order.
        events.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
        if completed {
            events.push(EventRecord {
                t_s: seconds(tug.now()),
                kind: "arrived".into(),
                detail: "stopped at the end of the route".into(),
            });
        }
        let steering_steps = tug.steering.steps.iter().map(StepRecord::of).collect();
        let tank_turn = tug
            .steering
            .tank_turn
            .as_ref()
            .map(|(_, response)| TankTurnRecord {
                step: StepRecord::of(response),
                hold_peak_to_peak_deg: response.hold_peak_to_peak(),
                duration_s: response.times.last().copied().unwrap_or(0.0),
            });
        let phases = PhaseRecord::all(&tug.events, tug.now());
        let crab_approach = CrabRecord::of(&phases, &tug.truth);
        let [bus1, bus2, bus3, bus1b] = tug.bus_loads();
        let stats = tug.ecu().map(|e| e.stats()).unwrap_or_default();
        RunReport {
            scenario: scenario.to_string(),
            seed,
            start_time_ns: start.as_nanos(),
            sim_seconds: seconds(tug.now()),
            completed,
            events,
            tracking_error_m: Tracking { max, mean },
            steering_steps,
            phases,
            crab_approach,
            tank_turn,
            echo_latency_ms: Percentiles::of(&tug.echo_latencies),
            bus_load: PerBus {
                bus1,
                bus2,
                bus3,
                bus1b,
            },
            frames: PerBus {
                bus1: tug.bus1_log.len(),
                bus2: tug.bus2_log.len(),
                bus3: tug.bus3_log.len(),
                bus1b: tug.bus1b_log.len(),
            },
            response_times_us: {
                let [bus1, bus2, bus3, bus1b] =
                    tug.response_times().map(|(_, t)| ResponseRecord::all(t));
                PerBus {
                    bus1,
                    bus2,
                    bus3,
                    bus1b,
                }
            },
            battery_soc: tug.soc(),
            supervisor: SupervisorCounts {
                accepted: stats.accepted,
                checksum: stats.checksum,
                repeated: stats.repeated,
                skipped: stats.skipped,
                out_of_range: stats.out_of_range,
                disagreements: stats.disagreements,
                authentication: stats.authentication,
                unauthenticated: stats.unauthenticated,
            },
            security: SecurityCounts::of(tug),
            dtcs: DtcRecord::all(tug),
            fail_operational: FailOperationalRecord::all(&tug.events, &tug.truth, tug.route()),
            wall_seconds: wall.as_secs_f64(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_are_nearest_rank() {
        let latencies: Vec<Duration> = (1..=100).map(Duration::from_millis).collect();
        let p = Percentiles::of(&latencies);
        assert_eq!(
            (p.count, p.p50, p.p95, p.p99, p.max),
            (100, Some(50.0), Some(95.0), Some(99.0), Some(100.0))
        );
        assert_eq!(Percentiles::of(&[]).p50, None);
    }
}
