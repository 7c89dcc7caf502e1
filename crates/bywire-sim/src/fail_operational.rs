//! The redundant tug's record of each injected fault or fault pair (of its ECUs, its voted
//! angle sensors and its steering actuators), as `metrics.json`
//! lists them under `fail_operational`: when the fault was found and taken over, the level
//! the vehicle reached, how well it kept to the route while degraded, and where it stopped
//! against the safe stop point it aimed for. Read from the run's events and true states.

use bywire_control::kinematics::Point;
use bywire_control::path::Path;
use bywire_core::Timestamp;
use bywire_vehicle::arbitration::Side;
use bywire_vehicle::backup::InCharge;
use bywire_vehicle::command::DegradationLevel;
use serde::Serialize;

use crate::event::{Happening, SimEvent};
use crate::fault::Fault;
use crate::mission::MissionEvent;
use crate::record::TruthSample;
use crate::report::seconds;

/// Below this speed the tug counts as stopped, m/s.
const STOPPED: f64 = 0.02;

/// One injected fault or fault pair.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FailOperationalRecord {
    /// The fault, or the two (`EcuSilent(A) + EcuSilent(B)`).
    pub fault: String,
    /// A second fault on top of the first.
    pub double: bool,
    /// When it was injected (the second of a pair), s into the run.
    pub injected_s: f64,
    /// From the fault to the vehicle's reaction: its level raised, or (a pair) neither ECU
    /// left in control, s.
    pub detected_s: Option<f64>,
    /// From the fault to the standby ECU in control, or the backup valve steering, s
    /// (`None`: nothing took over).
    pub takeover_s: Option<f64>,
    /// The level reached, by name: a pair leaves neither ECU in control, the drives' own
    /// safe stop.
    pub level: String,
    /// The largest distance from the route between the fault and the stop, m.
    pub max_cross_track_m: f64,
    /// The tug stopped before the repair.
    pub stopped: bool,
    /// How far from the safe stop point it aimed for it stopped, m (`None`: it stopped
    /// where it was, or aimed for none).
    pub stop_distance_to_safe_point_m: Option<f64>,
    /// From the fault to standstill, s.
    pub stop_speed_reached_s: Option<f64>,
}

/// The faults the redundant tug's layers answer: of its ECUs, its voted angle sensors and
/// its steering actuators.
fn is_layer_fault(fault: &Fault) -> bool {
    matches!(fault, Fault::SteeringActuator { .. })
        || (fault.needs_redundancy() && *fault != Fault::Repair)
}

fn since(from: Timestamp, to: Timestamp) -> f64 {
    to.saturating_since(from).as_secs_f64()
}

/// One open case: its faults and when each came.
struct Case<'a> {
    faults: Vec<(Timestamp, Fault)>,
    events: Vec<&'a SimEvent>,
}

impl FailOperationalRecord {
    /// Every case of the run: a fault of an ECU opens one, a second on top makes it a pair,
    /// the repair (or the run's end) closes it.
    pub fn all(events: &[SimEvent], truth: &[TruthSample], route: &[Point]) -> Vec<Self> {
        let mut records = Vec::new();
        let mut case: Option<Case<'_>> = None;
        for event in events {
            match &event.what {
                Happening::Fault(fault) if is_layer_fault(fault) => {
                    case.get_or_insert_with(|| Case {
                        faults: Vec::new(),
                        events: Vec::new(),
                    })
                    .faults
                    .push((event.t, *fault));
                }
                Happening::Fault(Fault::Repair) => {
                    if let Some(open) = case.take() {
                        records.push(Self::of(&open, event.t, truth, route));
                    }
                }
                _ => {
                    if let Some(open) = case.as_mut() {
                        open.events.push(event);
                    }
                }
            }
        }
        let end = truth.last().map_or(Timestamp::ZERO, |s| s.t);
        records.extend(case.map(|open| Self::of(&open, end, truth, route)));
        records
    }

    fn of(case: &Case<'_>, end: Timestamp, truth: &[TruthSample], route: &[Point]) -> Self {
        let double = case.faults.len() > 1;
        let injected = case.faults.last().map_or(end, |(t, _)| *t);
        let after = |t: Timestamp| t >= injected;
        let first = |what: &dyn Fn(&Happening) -> bool| {
            case.events
                .iter()
                .find(|e| after(e.t) && what(&e.what))
                .map(|e| e.t)
        };
        // Neither ECU in control, or a corner steered by nothing, is the pair's end; a single
        // fault's takeover gap is not.
        let neither = if double {
            first(&|h| {
                matches!(
                    h,
                    Happening::Control(None)
                        | Happening::Steering {
                            in_charge: InCharge::Neither,
                            ..
                        }
                )
            })
        } else {
            None
        };
        let raised = first(
            &|h| matches!(h, Happening::Degradation(level, _) if *level != DegradationLevel::Nominal),
        );
        let takeover = if double {
            None
        } else {
            first(&|h| {
                matches!(
                    h,
                    Happening::Control(Some(Side::B))
                        | Happening::Steering {
                            in_charge: InCharge::Backup,
                            ..
                        }
                )
            })
        };
        // A single fault is found when the standby takes over or the level rises.
        let detected = match (neither, takeover, raised) {
            (Some(t), _, _) => Some(t),
            (None, Some(a), Some(b)) => Some(a.min(b)),
            (None, a, b) => a.or(b),
        };
        let reported = case
            .events
            .iter()
            .filter_map(|e| match e.what {
                Happening::Degradation(level, _) => Some(level),
                _ => None,
            })
            .max();
        let level = match (neither, reported) {
            (Some(_), _) => DegradationLevel::SafeStop,
            (None, Some(level)) => level,
            (None, None) => DegradationLevel::Nominal,
        };
        let aimed = case.events.iter().find_map(|e| match e.what {
            Happening::Mission(MissionEvent::MinimalRisk { stop_at }) => stop_at,
            _ => None,
        });
        let path = Path::new(route);
        let during = truth
            .iter()
            .filter(|s| s.t >= case.faults.first().map_or(end, |(t, _)| *t) && s.t <= end);
        // The stop the fault led to: the first standstill once the tug moved after it (a fault
        // injected at a standstill), or at once if it never moved.
        let speed = |s: &TruthSample| libm::hypot(s.twist.vx, s.twist.vy);
        let after = truth.iter().filter(|s| s.t > injected && s.t <= end);
        let moved = after.clone().find(|s| speed(s) >= STOPPED).map(|s| s.t);
        let stop = after
            .filter(|s| moved.is_none_or(|moved| s.t > moved))
            .find(|s| speed(s) < STOPPED);
        // Where a true pose lies against the route.
        let on_route = |s: &TruthSample| {
            let here = Point {
                x: s.pose.x,
                y: s.pose.y,
            };
            path.as_ref().map(|path| path.project(here))
        };
        let max_cross_track_m = during
            .take_while(|s| stop.is_none_or(|stop| s.t <= stop.t))
            .filter_map(|s| on_route(s).map(|p| p.offset.abs()))
            .fold(0.0, f64::max);
        // A pair stops where it is: no safe stop point to measure against.
        let stop_distance_to_safe_point_m = match (stop, aimed, double) {
            (Some(stop), Some(aimed), false) => on_route(stop).map(|p| (p.station - aimed).abs()),
            _ => None,
        };
        FailOperationalRecord {
            fault: case
                .faults
                .iter()
                .map(|(_, f)| f.to_string())
                .collect::<Vec<_>>()
                .join(" + "),
            double,
            injected_s: seconds(injected),
            detected_s: detected.map(|t| since(injected, t)),
            takeover_s: takeover.map(|t| since(injected, t)),
            level: level.to_string(),
            max_cross_track_m,
            stopped: stop.is_some(),
            stop_distance_to_safe_point_m,
            stop_speed_reached_s: stop.map(|s| since(injected, s.t)),
        }
    }
}
