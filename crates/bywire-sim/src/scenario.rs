//! Scenarios: a route, the tug's load and road, and what happens on the way — built in
//! (`apron-loop`, `fault-tour`, `fail-operational`) or read from a TOML file with errors
//! naming the key:
//!
//! ```toml
//! name = "stand-approach"
//! route = "apron-loop"          # or "service-loop", or: waypoints = [[0, 0], [40, 0]]
//! speed = 3.0                   # m/s
//! crab_final_m = 10.0           # the last metres in crab, heading held (a stand approach)
//! tank_turn_deg = 180           # at the end, a tank turn in place (+ left)
//! steering_steps = [10, -10, 0] # before departure, steering steps at a standstill, 3 s each
//! speeds = [[40, 1.5], [80, 3]] # from 40 m on 1.5 m/s, from 80 m on 3 m/s
//! stops = [[60, 5]]             # stop at 60 m for 5 s
//! payload = 2000                # kg, 0–4500
//! grade = 0.02                  # rise over run
//! secoc = true                  # the secured variant: commands authenticated, CAN FD
//! redundant = true              # the redundant tug: two control ECUs, degradation levels
//! safe_stops = [55, 120]        # safe stop points, m along the route (minimal-risk stops)
//!
//! [[event]]
//! at_s = 8.0
//! fault = "ads_silence"         # ads_silence, estop, operator_reset, drive_silence,
//! duration_s = 1.0              # sensor_fault, corrupt_commands, duplicate_commands,
//!                               # delay_commands, driver_takeover, ecu_bus_off, bus_off,
//!                               # redundant_bus_loss, corrupt_frames, duplicate_frames,
//!                               # delay_frames, forge_commands, replay_commands,
//!                               # forge_state, flood (an attacker on bus 1),
//!                               # ecu_silent, ecu_wrong_output, ecu_babble,
//!                               # angle_sensor, repair (the redundant tug's),
//!                               # steering_stuck, steering_runaway, steering_drive_lost
//! # drive_silence: node = 0x22; sensor_fault: corner = 0..3, sensor = "stuck" | "drift" |
//! # "open", value = angle (stuck) or rate (drift); delay_commands: delay_ms = 15;
//! # corrupt_frames, duplicate_frames, delay_frames: bus = "bus2", id = 0x721 (and delay_ms);
//! # bus_off (of the node sending id on bus): bus = "bus2", id = 0x723;
//! # ecu_silent, ecu_wrong_output, ecu_babble: ecu = "A" or "B"; angle_sensor: corner,
//! # module = "B" | "C", sensor = "stuck" | "drift" | "open" | "silent", value;
//! # steering_stuck, steering_runaway, steering_drive_lost: corner (the primary's), and
//! # backup = true for the redundant tug's backup valve
//! ```

use core::time::Duration;

use bywire_control::kinematics::Point;
use bywire_core::{FileError, Timestamp};
use serde::Deserialize;

use bywire_vehicle::arbitration::Side;

use crate::attacker::Attack;
use crate::fault::{ActuatorFailure, Fault};
use crate::mission::{apron_loop, service_loop};
use crate::steering::SensorFault;
use crate::tug::{Tug, TugBus, TugParams, DRIVE_NODES, STEERING_NODES};
use bywire_net::sim::Tamper;

/// A scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    /// Its name.
    pub name: String,
    /// What the tug is given: route, speeds, stops, manoeuvres, payload and road (the seed is
    /// the run's: see [`Scenario::params`]).
    pub tug: TugParams,
    /// Faults and operator actions: (at, fault, for how long).
    pub events: Vec<(Duration, Fault, Option<Duration>)>,
}

/// Why a scenario file was refused: the file, and what its reader said or the key whose value
/// is wrong, as every configuration file says it.
pub type ScenarioError = bywire_core::FileError;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScenario {
    name: Option<String>,
    route: Option<String>,
    waypoints: Option<Vec<[f64; 2]>>,
    #[serde(default = "default_speed")]
    speed: f64,
    #[serde(default)]
    crab_final_m: f64,
    #[serde(default)]
    tank_turn_deg: f64,
    #[serde(default)]
    steering_steps: Vec<f64>,
    #[serde(default)]
    speeds: Vec<[f64; 2]>,
    #[serde(default)]
    stops: Vec<[f64; 2]>,
    #[serde(default)]
    payload: f64,
    #[serde(default)]
    grade: f64,
    #[serde(default)]
    secoc: bool,
    #[serde(default)]
    redundant: bool,
    #[serde(default)]
    safe_stops: Vec<f64>,
    #[serde(default)]
    event: Vec<RawEvent>,
}

fn default_speed() -> f64 {
    3.0
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawEvent {
    at_s: f64,
    fault: String,
    duration_s: Option<f64>,
    node: Option<u8>,
    corner: Option<usize>,
    sensor: Option<String>,
    value: Option<f64>,
    delay_ms: Option<u64>,
    bus: Option<String>,
    id: Option<u16>,
    ecu: Option<String>,
    module: Option<String>,
    backup: Option<bool>,
}

impl Scenario {
    /// A built-in scenario by name: `apron-loop` (the route, nothing happens) or `fault-tour`
    /// (the route with an ADS silence, an E-stop and its reset, a drive cut off and the reset,
    /// bus 1b lost, a stuck steering sensor, corrupted, duplicated and delayed commands, a
    /// driver's takeover, the ECU's controller going bus-off, and an attacker on bus 1:
    /// forged commands, replayed commands, a forged speed, a flood of 0x000) or
    /// `fail-operational` (the redundant tug on the service loop, safe stop points every
    /// 20 m: ECU A silent, computing a wrong setpoint and babbling, each alone and then with
    /// ECU B falling silent on top, a repair at a standstill after each).
    pub fn builtin(name: &str) -> Option<Scenario> {
        let s = Duration::from_secs;
        let ms = Duration::from_millis;
        let events = match name {
            "apron-loop" => Vec::new(),
            "fail-operational" => fail_operational_events(),
            "fault-tour" => vec![
                (s(8), Fault::AdsSilence, Some(s(1))),
                (s(12), Fault::RedundantBusLoss, Some(s(1))),
                (s(16), Fault::Estop, Some(s(2))),
                (s(24), Fault::OperatorReset, None),
                (s(32), Fault::DriveSilence(DRIVE_NODES[1]), Some(s(1))),
                (s(38), Fault::OperatorReset, None),
                (
                    s(46),
                    Fault::SensorFault(2, SensorFault::Stuck(5.0)),
                    Some(s(3)),
                ),
                (ms(49_500), Fault::OperatorReset, None),
                (s(50), Fault::CorruptCommands, Some(ms(50))),
                (s(51), Fault::DuplicateCommands, Some(ms(100))),
                (s(52), Fault::DriverTakeover, Some(ms(500))),
                (s(54), Fault::DelayCommands(15), Some(s(1))),
                (s(56), Fault::EcuBusOff, None),
                (
                    s(57),
                    Fault::BusOff {
                        bus: TugBus::Bus2,
                        id: 0x723,
                    },
                    None,
                ),
                (s(58), Fault::Attack(Attack::ForgeCommands), Some(s(1))),
                (s(60), Fault::Attack(Attack::ReplayCommands), Some(s(1))),
                (s(62), Fault::Attack(Attack::ForgeState), Some(s(1))),
                (s(64), Fault::Attack(Attack::Flood), Some(ms(500))),
                (s(66), Fault::OperatorReset, None),
            ],
            _ => return None,
        };
        let apron_loop = name == "apron-loop";
        if name == "fail-operational" {
            return Some(Scenario {
                name: name.to_string(),
                tug: TugParams {
                    route: service_loop(),
                    redundant: true,
                    // Stands and kerbs along the service road, every 20 m, none in the bend
                    // (160–207 m) but at its ends.
                    safe_stops: (1..19)
                        .map(|k| f64::from(k) * 20.0)
                        .filter(|at| *at != 180.0)
                        .collect(),
                    ..TugParams::default()
                },
                events,
            });
        }
        Some(Scenario {
            name: name.to_string(),
            tug: TugParams {
                crab_final_m: 10.0,
                tank_turn_deg: if apron_loop { 180.0 } else { 0.0 },
                steering_steps: if apron_loop {
                    vec![10.0, -10.0, 0.0]
                } else {
                    Vec::new()
                },
                ..TugParams::default()
            },
            events,
        })
    }

    /// Read a scenario file's text; `file` names it in errors.
    pub fn parse(text: &str, file: &str) -> Result<Scenario, ScenarioError> {
        let raw: RawScenario = toml::from_str(text).map_err(|e| ScenarioError::Syntax {
            file: file.to_string(),
            message: e.to_string().trim_end().to_string(),
        })?;
        let invalid = |key: &str, reason: String| FileError::invalid(file, key, reason);
        let route = route(&raw, &invalid)?;
        check_numbers(&raw, &invalid)?;
        let length: f64 = route
            .windows(2)
            .map(|w| match w {
                [a, b] => (b.x - a.x).hypot(b.y - a.y),
                _ => 0.0,
            })
            .sum();
        along(
            "speeds",
            &raw.speeds,
            length,
            &|v| v > 0.0 && v <= 8.0,
            "a speed the tug drives (0–8 m/s)",
            &invalid,
        )?;
        along(
            "stops",
            &raw.stops,
            length,
            &|s| s > 0.0 && s <= 3_600.0,
            "a stop's length (0–3600 s)",
            &invalid,
        )?;
        let speeds = raw.speeds.iter().map(|[at, v]| (*at, *v)).collect();
        let stops = raw
            .stops
            .iter()
            .map(|[at, s]| (*at, Duration::from_secs_f64(*s)))
            .collect();
        let mut safe_stops = raw.safe_stops.clone();
        if let Some(i) = safe_stops
            .iter()
            .position(|at| !(at.is_finite() && *at >= 0.0 && *at <= length))
        {
            return Err(invalid(
                &format!("safe_stops[{i}]"),
                format!("a point along the route (0–{length:.1} m)"),
            ));
        }
        safe_stops.sort_by(f64::total_cmp);
        let events = raw
            .event
            .iter()
            .enumerate()
            .map(|(i, e)| event(i, e, &invalid))
            .collect::<Result<Vec<_>, _>>()?;
        // A fault of a layer the plain tug does not have would change nothing: refused.
        if !raw.redundant {
            if let Some(i) = events.iter().position(|(_, f, _)| f.needs_redundancy()) {
                return Err(invalid(
                    &format!("event[{i}].fault"),
                    "a fault of the redundant tug's: give redundant = true".to_string(),
                ));
            }
        }
        Ok(Scenario {
            name: raw.name.unwrap_or_else(|| file.to_string()),
            tug: TugParams {
                seed: TugParams::default().seed,
                payload: raw.payload,
                grade: raw.grade,
                route,
                speed: raw.speed,
                crab_final_m: raw.crab_final_m,
                tank_turn_deg: raw.tank_turn_deg,
                steering_steps: raw.steering_steps,
                speeds,
                stops,
                secoc: raw.secoc,
                redundant: raw.redundant,
                safe_stops,
            },
            events,
        })
    }

    /// What a tug driving this scenario is given, with `seed` and `payload` (kg; the
    /// scenario's own unless a run overrides it).
    pub fn params(&self, seed: u64, payload: f64) -> TugParams {
        TugParams {
            seed,
            payload,
            ..self.tug.clone()
        }
    }

    /// Drive `tug` through the scenario as fast as possible until the route is done (`true`)
    /// or the simulated time reaches `limit` (`false`).
    pub fn run_fast(&self, tug: &mut Tug, limit: Timestamp) -> bool {
        loop {
            self.step(tug);
            if tug.arrived() {
                return true;
            }
            if tug.now() >= limit {
                return false;
            }
        }
    }

    /// One step of `tug`, with what the scenario injects in it (events after the step's
    /// start, at or before its end).
    pub fn step(&self, tug: &mut Tug) {
        let before = tug.now();
        tug.step();
        self.inject_due(tug, before);
    }

    /// One millisecond with `ads` in the built-in ADS's place ([`Tug::step_with_ads`]), the
    /// scenario's faults injected on time as in [`Scenario::step`].
    pub fn step_with_ads(&self, tug: &mut Tug, ads: &mut dyn bywire_core::node::Node) {
        let before = tug.now();
        tug.step_with_ads(ads);
        self.inject_due(tug, before);
    }

    /// Inject the events due after `before` up to the tug's time.
    fn inject_due(&self, tug: &mut Tug, before: Timestamp) {
        let now = tug.now();
        for (at, fault, duration) in &self.events {
            let at = Timestamp::ZERO.saturating_add(*at);
            if at > before && at <= now {
                tug.inject(*fault, *duration);
            }
        }
    }
}

/// The `fail-operational` scenario's faults, each alone: ECU A silent, computing a wrong
/// setpoint, babbling; an angle sensor stuck, drifting, silent; a primary steering actuator
/// running away, its drive lost, stuck. Then each again with a second on top 3 s later: ECU B
/// falling silent, a second sensor of the corner stuck the other way, or the corner's backup
/// valve's driver lost. A repair at a standstill after each. A stuck actuator shows only when
/// its wheel is asked to turn: it seizes while the tug stands at a safe stop point before the
/// wheels must turn — the bend's entry (160 m: each case before it ends at the next point, 20 m
/// on) alone, its exit (200 m, where that case ends) with a second fault.
fn fail_operational_events() -> Vec<(Duration, Fault, Option<Duration>)> {
    let ms = Duration::from_millis;
    let sensor = |corner, module, fault| Fault::AngleSensor {
        corner,
        module,
        fault,
    };
    let sensors = [
        sensor(0, 1, SensorFault::Stuck(8.0)),
        sensor(1, 0, SensorFault::Drift(2.0)),
        sensor(2, 1, SensorFault::Silent),
    ];
    // The second sensor of the same corner, stuck the other way.
    let second = |fault: Fault| match fault {
        Fault::AngleSensor { corner, module, .. } => {
            sensor(corner, 1 - module, SensorFault::Stuck(-8.0))
        }
        other => other,
    };
    let singles = [
        Fault::EcuSilent(Side::A),
        Fault::EcuWrongOutput(Side::A),
        Fault::EcuBabble(Side::A),
    ];
    let actuator = |corner, backup, failure| Fault::SteeringActuator {
        corner,
        backup,
        failure,
    };
    // The stuck primary last: it shows only when its wheel is asked to turn, so it seizes
    // while the tug stands at the safe stop point before the bend (160 m: each case before
    // it ends at the next point, 20 m on), and the bend asks at once.
    let actuators = [
        actuator(1, false, ActuatorFailure::Runaway),
        actuator(2, false, ActuatorFailure::DriveLost),
        actuator(0, false, ActuatorFailure::Stuck),
    ];
    // The same corner's backup valve driver lost.
    let backup_lost = |fault: Fault| match fault {
        Fault::SteeringActuator { corner, .. } => {
            actuator(corner, true, ActuatorFailure::DriveLost)
        }
        other => other,
    };
    // A stuck actuator seizes at a standstill, when the tug stands after the last repair:
    // the others come 3 s into the drive.
    let stuck = |fault: &Fault| {
        matches!(
            fault,
            Fault::SteeringActuator {
                failure: ActuatorFailure::Stuck,
                ..
            }
        )
    };
    let mut events = Vec::new();
    // The next case's start, and the standstill before it.
    let (mut at, mut standing) = (ms(5_000), ms(10));
    let mut single = |events: &mut Vec<_>, fault: Fault| {
        // Time to reach the next safe stop point at the minimal-risk speed (from the bend's
        // entry, 40 m on: no stand in the bend); the part mended just before its repair.
        let (injected, window) = if stuck(&fault) {
            (standing, ms(30_000))
        } else {
            (at, ms(18_000))
        };
        events.push((injected, fault, Some(window - ms(500))));
        events.push((injected + window, Fault::Repair, None));
        standing = injected + window + ms(10);
        at = injected + window + ms(3_000);
    };
    let [runaway, drive_lost, stuck_primary] = actuators;
    for fault in singles.into_iter().chain(sensors).chain(actuators) {
        single(&mut events, fault);
    }
    let mut double = |events: &mut Vec<_>, first: Fault, second| {
        let injected = if stuck(&first) { standing } else { at };
        events.push((injected, first, Some(ms(9_500))));
        events.push((injected + ms(3_000), second, Some(ms(6_500))));
        events.push((injected + ms(10_000), Fault::Repair, None));
        // The drives the master stopped when neither ECU was in control: acknowledged
        // again once their faults have cleared.
        events.push((injected + ms(11_000), Fault::OperatorReset, None));
        standing = injected + ms(11_010);
        at = injected + ms(14_000);
    };
    // The stuck primary first: it shows in the bend it stands in.
    double(&mut events, stuck_primary, backup_lost(stuck_primary));
    for fault in singles {
        double(&mut events, fault, Fault::EcuSilent(Side::B));
    }
    for fault in sensors {
        double(&mut events, fault, second(fault));
    }
    for fault in [runaway, drive_lost] {
        double(&mut events, fault, backup_lost(fault));
    }
    events
}

/// A key's value is wrong: the error, the file named by the caller.
type Invalid<'a> = dyn Fn(&str, String) -> ScenarioError + 'a;

/// The route: the built-in one, or the waypoints given.
fn route(raw: &RawScenario, invalid: &Invalid<'_>) -> Result<Vec<Point>, ScenarioError> {
    Ok(match (raw.route.as_deref(), &raw.waypoints) {
        (Some(_), Some(_)) => {
            return Err(invalid(
                "waypoints",
                "give route or waypoints, not both".to_string(),
            ))
        }
        (Some("apron-loop") | None, None) => apron_loop(),
        (Some("service-loop"), None) => service_loop(),
        (Some(other), None) => {
            return Err(invalid(
                "route",
                format!("'{other}' is not a built-in route (apron-loop, service-loop)"),
            ))
        }
        (None, Some(points)) => {
            if points.len() < 2 || points.iter().flatten().any(|v| !v.is_finite()) {
                return Err(invalid(
                    "waypoints",
                    "at least two points of finite coordinates".to_string(),
                ));
            }
            points.iter().map(|[x, y]| Point { x: *x, y: *y }).collect()
        }
    })
}

/// The numbers that have ranges: speed, the crab and tank turn, the steering steps, payload
/// and grade.
fn check_numbers(raw: &RawScenario, invalid: &Invalid<'_>) -> Result<(), ScenarioError> {
    if !(raw.speed > 0.0 && raw.speed <= 8.0) {
        return Err(invalid(
            "speed",
            format!("{} is not a speed the tug drives (0–8 m/s)", raw.speed),
        ));
    }
    if !(0.0..=1_000.0).contains(&raw.crab_final_m) {
        return Err(invalid(
            "crab_final_m",
            format!("{} is not a length of route (0–1000 m)", raw.crab_final_m),
        ));
    }
    if !(-720.0..=720.0).contains(&raw.tank_turn_deg) {
        return Err(invalid(
            "tank_turn_deg",
            format!(
                "{} is not a turn of at most two rounds (±720°)",
                raw.tank_turn_deg
            ),
        ));
    }
    if let Some((i, angle)) = raw
        .steering_steps
        .iter()
        .enumerate()
        .find(|(_, a)| !(-40.0..=40.0).contains(*a))
    {
        return Err(invalid(
            &format!("steering_steps[{i}]"),
            format!("{angle} is not a wheel angle (−40° … 40°)"),
        ));
    }
    if raw.steering_steps.len() > 100 {
        return Err(invalid("steering_steps", "at most 100 steps".to_string()));
    }
    if !(0.0..=4_500.0).contains(&raw.payload) {
        return Err(invalid(
            "payload",
            format!("{} kg is not 0–4500 kg", raw.payload),
        ));
    }
    if !(-0.2..=0.2).contains(&raw.grade) {
        return Err(invalid(
            "grade",
            format!("{} is not a grade (−0.2 … 0.2)", raw.grade),
        ));
    }
    Ok(())
}

/// Pairs of (distance along the route, value): each on the route, after the one before, its
/// value `valid` (else `what` it must be).
fn along(
    key: &str,
    pairs: &[[f64; 2]],
    length: f64,
    valid: &dyn Fn(f64) -> bool,
    what: &str,
    invalid: &Invalid<'_>,
) -> Result<(), ScenarioError> {
    let mut last = f64::NEG_INFINITY;
    for (i, [at, value]) in pairs.iter().enumerate() {
        if !(0.0..=length).contains(at) || *at <= last {
            return Err(invalid(
                &format!("{key}[{i}]"),
                format!("{at} m is not on the route (0–{length:.1} m) after the one before"),
            ));
        }
        if !valid(*value) {
            return Err(invalid(
                &format!("{key}[{i}]"),
                format!("{value} is not {what}"),
            ));
        }
        last = *at;
    }
    Ok(())
}

/// An `[[event]]`: when, which fault, for how long.
fn event(
    i: usize,
    e: &RawEvent,
    invalid: &Invalid<'_>,
) -> Result<(Duration, Fault, Option<Duration>), ScenarioError> {
    let key = |field: &str| format!("event[{i}].{field}");
    if !(e.at_s >= 0.0 && e.at_s < 86_400.0) {
        return Err(invalid(
            &key("at_s"),
            format!("{} is not a time in a run", e.at_s),
        ));
    }
    let duration = match e.duration_s {
        Some(d) if d > 0.0 && d < 86_400.0 => Some(Duration::from_secs_f64(d)),
        Some(d) => {
            return Err(invalid(
                &key("duration_s"),
                format!("{d} is not a duration"),
            ))
        }
        None => None,
    };
    // The frames a fault aims at: a bus and an identifier sent on it.
    let bus_and_id = |kind: &str| -> Result<(TugBus, u16), ScenarioError> {
        let bus = e.bus.as_deref().and_then(TugBus::named).ok_or_else(|| {
            invalid(
                &key("bus"),
                format!("{kind} needs bus = \"bus1\", \"bus2\", \"bus3\" or \"bus1b\""),
            )
        })?;
        let id = e
            .id
            .filter(|id| *id <= 0x7FF)
            .ok_or_else(|| invalid(&key("id"), format!("{kind} needs id, an 11-bit identifier")))?;
        Ok((bus, id))
    };
    let corner = |kind: &str| {
        e.corner.filter(|c| *c < 4).ok_or_else(|| {
            invalid(
                &key("corner"),
                format!("{kind} needs corner 0 (FL) … 3 (RR)"),
            )
        })
    };
    let fault = match e.fault.as_str() {
        "ads_silence" => Fault::AdsSilence,
        "estop" => Fault::Estop,
        "operator_reset" => Fault::OperatorReset,
        "drive_silence" => {
            let node = e.node.ok_or_else(|| invalid(&key("node"), "drive_silence needs the node ID".to_string()))?;
            if !DRIVE_NODES.contains(&node) && !STEERING_NODES.contains(&node) {
                return Err(invalid(&key("node"), format!("0x{node:02X} is not a drive (steering 0x11–0x14, wheels 0x21–0x24)")));
            }
            Fault::DriveSilence(node)
        }
        "sensor_fault" => {
            let corner = corner("sensor_fault")?;
            let value = e.value.unwrap_or(0.0);
            let sensor = match e.sensor.as_deref() {
                Some("stuck") => SensorFault::Stuck(value),
                Some("drift") => SensorFault::Drift(value),
                Some("open") => SensorFault::OpenCircuit,
                other => return Err(invalid(&key("sensor"), format!("{other:?} is not stuck, drift or open"))),
            };
            Fault::SensorFault(corner, sensor)
        }
        "angle_sensor" => {
            let corner = corner("angle_sensor")?;
            let module = match e.module.as_deref() {
                Some("B" | "b") => 0,
                Some("C" | "c") => 1,
                _ => return Err(invalid(&key("module"), "angle_sensor needs module = \"B\" or \"C\" (the redundant tug's)".to_string())),
            };
            let value = e.value.unwrap_or(0.0);
            let fault = match e.sensor.as_deref() {
                Some("stuck") => SensorFault::Stuck(value),
                Some("drift") => SensorFault::Drift(value),
                Some("open") => SensorFault::OpenCircuit,
                Some("silent") => SensorFault::Silent,
                other => return Err(invalid(&key("sensor"), format!("{other:?} is not stuck, drift, open or silent"))),
            };
            Fault::AngleSensor { corner, module, fault }
        }
        kind @ ("steering_stuck" | "steering_runaway" | "steering_drive_lost") => Fault::SteeringActuator {
            corner: corner(kind)?,
            backup: e.backup.unwrap_or(false),
            failure: match kind {
                "steering_stuck" => ActuatorFailure::Stuck,
                "steering_runaway" => ActuatorFailure::Runaway,
                _ => ActuatorFailure::DriveLost,
            },
        },
        "corrupt_commands" => Fault::CorruptCommands,
        "duplicate_commands" => Fault::DuplicateCommands,
        "delay_commands" => Fault::DelayCommands(e.delay_ms.ok_or_else(|| invalid(&key("delay_ms"), "delay_commands needs delay_ms".to_string()))?),
        "driver_takeover" => Fault::DriverTakeover,
        "ecu_bus_off" => Fault::EcuBusOff,
        "bus_off" => {
            let (bus, id) = bus_and_id("bus_off")?;
            Fault::BusOff { bus, id }
        }
        "redundant_bus_loss" => Fault::RedundantBusLoss,
        "forge_commands" => Fault::Attack(Attack::ForgeCommands),
        "replay_commands" => Fault::Attack(Attack::ReplayCommands),
        "forge_state" => Fault::Attack(Attack::ForgeState),
        "flood" => Fault::Attack(Attack::Flood),
        kind @ ("ecu_silent" | "ecu_wrong_output" | "ecu_babble") => {
            let side = match e.ecu.as_deref() {
                Some("A" | "a") => Side::A,
                Some("B" | "b") => Side::B,
                _ => return Err(invalid(&key("ecu"), format!("{kind} needs ecu = \"A\" or \"B\" (the redundant tug's)"))),
            };
            match kind {
                "ecu_silent" => Fault::EcuSilent(side),
                "ecu_wrong_output" => Fault::EcuWrongOutput(side),
                _ => Fault::EcuBabble(side),
            }
        }
        "repair" => Fault::Repair,
        kind @ ("corrupt_frames" | "duplicate_frames" | "delay_frames") => {
            let (bus, id) = bus_and_id(kind)?;
            let tamper = match kind {
                "corrupt_frames" => Tamper::FlipBit,
                "duplicate_frames" => Tamper::Duplicate,
                _ => Tamper::Delay(Duration::from_millis(e.delay_ms.ok_or_else(|| invalid(&key("delay_ms"), "delay_frames needs delay_ms".to_string()))?)),
            };
            Fault::TamperFrames { bus, id, tamper }
        }
        other => return Err(invalid(&key("fault"), format!("'{other}' is not a fault (ads_silence, estop, operator_reset, drive_silence, sensor_fault, corrupt_commands, duplicate_commands, delay_commands, driver_takeover, ecu_bus_off, bus_off, redundant_bus_loss, corrupt_frames, duplicate_frames, delay_frames, forge_commands, replay_commands, forge_state, flood, ecu_silent, ecu_wrong_output, ecu_babble, angle_sensor, steering_stuck, steering_runaway, steering_drive_lost, repair)"))),
    };
    Ok((Duration::from_secs_f64(e.at_s), fault, duration))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_redundant_scenario_reads_its_safe_stops_and_ecu_faults_and_mistakes_name_the_key() {
        let text = "route = \"service-loop\"\nredundant = true\nsafe_stops = [60, 20]\n\n[[event]]\nat_s = 5\nfault = \"ecu_wrong_output\"\necu = \"A\"\n\n[[event]]\nat_s = 9\nfault = \"repair\"\n\n[[event]]\nat_s = 10\nfault = \"steering_runaway\"\ncorner = 2\nbackup = true\n\n[[event]]\nat_s = 11\nfault = \"angle_sensor\"\ncorner = 1\nmodule = \"C\"\nsensor = \"silent\"\n";
        let scenario = Scenario::parse(text, "r.toml").unwrap();
        assert!(scenario.tug.redundant);
        assert_eq!(scenario.tug.safe_stops, [20.0, 60.0]);
        assert_eq!(scenario.tug.route, service_loop());
        assert_eq!(scenario.events[0].1, Fault::EcuWrongOutput(Side::A));
        assert_eq!(scenario.events[1].1, Fault::Repair);
        assert_eq!(
            scenario.events[2].1,
            Fault::SteeringActuator {
                corner: 2,
                backup: true,
                failure: ActuatorFailure::Runaway
            }
        );
        assert_eq!(
            scenario.events[3].1,
            Fault::AngleSensor {
                corner: 1,
                module: 1,
                fault: SensorFault::Silent
            }
        );
        let plain = Scenario::parse(&text.replace("redundant = true", ""), "r.toml").unwrap_err();
        assert!(
            plain
                .to_string()
                .contains("event[0].fault: a fault of the redundant tug's"),
            "{plain}"
        );
        for (bad, expected) in [
            ("safe_stops = [60, 20]", "safe_stops = [60, 900]"),
            ("ecu = \"A\"", "ecu = \"C\""),
        ] {
            let err = Scenario::parse(&text.replace(bad, expected), "r.toml").unwrap_err();
            let key = if bad.starts_with("safe") {
                "safe_stops[1]"
            } else {
                "event[0].ecu"
            };
            assert!(err.to_string().contains(&format!("r.toml: {key}")), "{err}");
        }
    }

    #[test]
    fn a_scenario_file_reads_with_its_events_and_mistakes_name_the_key() {
        let text = "name = \"approach\"\nwaypoints = [[0, 0], [20, 0], [20, 10]]\nspeed = 2.0\npayload = 4000\ngrade = 0.03\n\n[[event]]\nat_s = 5\nfault = \"sensor_fault\"\ncorner = 1\nsensor = \"drift\"\nvalue = 0.5\nduration_s = 2\n\n[[event]]\nat_s = 9.5\nfault = \"drive_silence\"\nnode = 0x22\n";
        let scenario = Scenario::parse(text, "s.toml").unwrap();
        assert_eq!(scenario.name, "approach");
        assert_eq!(scenario.tug.route.len(), 3);
        assert_eq!(
            (scenario.tug.speed, scenario.tug.payload, scenario.tug.grade),
            (2.0, 4_000.0, 0.03)
        );
        assert_eq!(
            scenario.events,
            [
                (
                    Duration::from_secs(5),
                    Fault::SensorFault(1, SensorFault::Drift(0.5)),
                    Some(Duration::from_secs(2))
                ),
                (
                    Duration::from_millis(9_500),
                    Fault::DriveSilence(0x22),
                    None
                ),
            ]
        );
        let error = |text: &str| Scenario::parse(text, "s.toml").unwrap_err().to_string();
        assert_eq!(
            error("[[event]]\nat_s = 1\nfault = \"meteor\"\n")
                .split(':')
                .take(2)
                .collect::<Vec<_>>(),
            ["s.toml", " event[0].fault"]
        );
        assert!(
            error("[[event]]\nat_s = 1\nfault = \"drive_silence\"\nnode = 0x30\n")
                .contains("event[0].node: 0x30 is not a drive")
        );
        assert!(error("payload = 9000\n").contains("payload: 9000 kg"));
        assert!(error("crab_final_m = -1\n").contains("crab_final_m: -1 is not a length"));
        assert!(error("tank_turn_deg = 900\n").contains("tank_turn_deg: 900 is not a turn"));
        assert!(error("stops = [[10, 5], [5, 5]]\n").contains("stops[1]: 5 m is not on the route"));
        assert!(error("speeds = [[10, 9]]\n").contains("speeds[0]: 9 is not a speed"));
        assert!(
            error("[[event]]\nat_s = 1\nfault = \"delay_frames\"\nbus = \"bus9\"\nid = 1\n")
                .contains("event[0].bus: delay_frames needs bus")
        );
        assert!(
            error("[[event]]\nat_s = 1\nfault = \"bus_off\"\nbus = \"bus2\"\n")
                .contains("event[0].id: bus_off needs id")
        );
        let bus_off = Scenario::parse(
            "[[event]]\nat_s = 1\nfault = \"bus_off\"\nbus = \"bus2\"\nid = 0x723\n",
            "b.toml",
        )
        .unwrap();
        assert_eq!(
            bus_off.events.first().map(|e| e.1),
            Some(Fault::BusOff {
                bus: TugBus::Bus2,
                id: 0x723
            })
        );
        let tamper = Scenario::parse("[[event]]\nat_s = 1\nfault = \"delay_frames\"\nbus = \"bus2\"\nid = 0x721\ndelay_ms = 300\nduration_s = 1\n", "d.toml").unwrap();
        assert_eq!(
            tamper.events.first().map(|e| e.1),
            Some(Fault::TamperFrames {
                bus: TugBus::Bus2,
                id: 0x721,
                tamper: Tamper::Delay(Duration::from_millis(300))
            })
        );
        let timed = Scenario::parse(
            "route = \"apron-loop\"\nspeeds = [[40, 1.5]]\nstops = [[60, 5]]\n",
            "t.toml",
        )
        .unwrap();
        assert_eq!(timed.tug.speeds, [(40.0, 1.5)]);
        assert_eq!(timed.tug.stops, [(60.0, Duration::from_secs(5))]);
        assert!(error("steering_steps = [5, 45]\n")
            .contains("steering_steps[1]: 45 is not a wheel angle"));
        assert!(error("waypoints = [[0, 0]]\n").contains("waypoints: at least two points"));
        assert!(error("speeed = 2\n").contains("unknown field `speeed`"));
        assert!(Scenario::builtin("fault-tour").is_some_and(|s| s.events.len() == 19));
    }
}
