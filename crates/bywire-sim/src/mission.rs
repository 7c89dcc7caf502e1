//! The built-in ADS: a [`Mission`] (the route with its speeds, stops, a crab stand approach, a
//! tank turn at the end, a steering step test first) driving the ADS side of the wire, as one
//! node ([`AdsDriver`]). It drives from what an ADS knows — its own odometry from the
//! vehicle's wheel speeds and angles, the speed the vehicle reports — never the plant's true
//! pose.

use std::collections::VecDeque;

use core::time::Duration;

use bywire_control::kinematics::{four_wheel, Motion, Point, Pose, WheelState};
use bywire_control::path::{Geometry, Lookahead, Path, PurePursuit};
use bywire_core::node::{Node, Port};
use bywire_core::time::earliest;
use bywire_core::{Frame, Timestamp};
use bywire_tug::secured::TugWire;
use bywire_vehicle::ads::{Ads, AdsCommand, AdsConfig};
use bywire_vehicle::command::{
    ControlMode, DegradationLevel, EstopCode, Gear, SteeringMode, WatchdogLevel,
};

/// How long each steering step of the step test is held.
pub const STEP_HOLD: Duration = Duration::from_secs(3);
/// The ADS plans every command cycle.
const PLAN_PERIOD: Duration = Duration::from_millis(20);
/// Events kept for the caller; more are dropped.
const EVENT_CAPACITY: usize = 64;

/// The mission's gentle deceleration toward a stop or a lower speed, m/s².
const GENTLE: f64 = 0.5;

/// The crab approach's speed, m/s: a stand is approached slowly, and the wheels turn to the
/// crab angle at the approach's start without the tug running ahead of them.
const CRAB_SPEED: f64 = 1.0;

/// The speed from which braking at [`GENTLE`] over `distance` (m) ends at `v_next` (m/s):
/// v² = v_next² + 2·a·d.
fn approach(v_next: f64, distance: f64) -> f64 {
    libm::sqrt(v_next * v_next + 2.0 * GENTLE * distance.max(0.0))
}

/// What the mission asks for.
#[derive(Debug, Clone, PartialEq)]
pub struct MissionParams {
    /// The route, m (at least two points).
    pub route: Vec<Point>,
    /// Cruising speed, m/s.
    pub speed: f64,
    /// Speeds along the route: (from this many metres on, m/s), by distance.
    pub speeds: Vec<(f64, f64)>,
    /// Stops along the route: (at this many metres, for this long), by distance.
    pub stops: Vec<(f64, Duration)>,
    /// The last this many metres of the route in crab (0: none).
    pub crab_final_m: f64,
    /// At the end, a tank turn in place by this many degrees (+ left; 0: none).
    pub tank_turn_deg: f64,
    /// The step test: angles (degrees) stepped to in turn at a standstill, each held for
    /// [`STEP_HOLD`], before it drives.
    pub steering_steps: Vec<f64>,
    /// The tug's wheelbase and track, m.
    pub wheelbase: f64,
    /// Track, m.
    pub track: f64,
    /// Safe stop points along the route, m by distance: where a minimal-risk manoeuvre ends.
    pub safe_stops: Vec<f64>,
    /// The speed limits of the degraded and minimal-risk levels, m/s (a fail-safe tug
    /// reports no level and never uses them).
    pub degraded_speeds: (f64, f64),
}

/// How far the stand at the end of `apron-loop` lies to the side of the service road, m: the
/// crab approach's sideways travel.
pub const STAND_OFFSET: f64 = 2.5;

/// The built-in `apron-loop` route: out along the stand row, a 15 m turn, back along the
/// service road, and the last 10 m to a stand 2.5 m to the side (about 117 m), which the tug
/// reaches in crab.
pub fn apron_loop() -> Vec<Point> {
    let mut points: Vec<Point> = (0..=40)
        .map(|x| Point {
            x: f64::from(x),
            y: 0.0,
        })
        .collect();
    let arc = |cx: f64, cy: f64, from: f64, points: &mut Vec<Point>| {
        for k in 1..=24 {
            let a = from + f64::from(k) / 24.0 * core::f64::consts::PI;
            points.push(Point {
                x: cx + 15.0 * libm::cos(a),
                y: cy + 15.0 * libm::sin(a),
            });
        }
    };
    // A half circle to the left brings the route back parallel, 30 m over.
    arc(40.0, 15.0, -core::f64::consts::FRAC_PI_2, &mut points);
    for x in (20..40).rev() {
        points.push(Point {
            x: f64::from(x),
            y: 30.0,
        });
    }
    // Ten metres on a slant to the stand, in 1 m steps.
    let along = libm::sqrt(100.0 - STAND_OFFSET * STAND_OFFSET);
    for k in 1..=10 {
        let share = f64::from(k) / 10.0;
        points.push(Point {
            x: 20.0 - along * share,
            y: 30.0 - STAND_OFFSET * share,
        });
    }
    points
}

/// The built-in `service-loop` route: 160 m out along a service road, a 15 m turn, and
/// 160 m back (about 367 m), for runs that stop and start again along the way.
pub fn service_loop() -> Vec<Point> {
    let mut points: Vec<Point> = (0..=160)
        .step_by(2)
        .map(|x| Point {
            x: f64::from(x),
            y: 0.0,
        })
        .collect();
    for k in 1..=24 {
        let a = -core::f64::consts::FRAC_PI_2 + f64::from(k) / 24.0 * core::f64::consts::PI;
        points.push(Point {
            x: 160.0 + 15.0 * libm::cos(a),
            y: 15.0 + 15.0 * libm::sin(a),
        });
    }
    for x in (0..160).rev().step_by(2) {
        points.push(Point {
            x: f64::from(x),
            y: 30.0,
        });
    }
    points
}

/// The part of the mission under way, as the live view, the events, the report and the
/// plot name it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// Waiting for the vehicle to report autonomous mode.
    Engaging,
    /// The steering step test at a standstill.
    StepTest,
    /// Driving the route in normal steering (stops included).
    Cruise,
    /// The last metres to the stand in crab, the heading held.
    CrabApproach,
    /// The tank turn in place at the end of the route.
    TankTurn,
    /// Standing at the end of the route.
    Stop,
}

impl Phase {
    /// Its name.
    pub fn name(self) -> &'static str {
        match self {
            Phase::Engaging => "engaging",
            Phase::StepTest => "step test",
            Phase::Cruise => "cruise",
            Phase::CrabApproach => "crab approach",
            Phase::TankTurn => "tank turn",
            Phase::Stop => "stop",
        }
    }
}

impl core::fmt::Display for Phase {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// Something the mission did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MissionEvent {
    /// A new phase began.
    Phase(Phase),
    /// The steering mode it asks for changed.
    SteeringMode(SteeringMode),
    /// It stopped at a stop, for a dwell.
    Stop {
        /// Where, m along the route.
        at: f64,
        /// For how long.
        dwell: Duration,
    },
    /// It left a stop.
    Depart {
        /// Where, m along the route.
        at: f64,
    },
    /// The vehicle reported a minimal-risk level: it drives on at the level's limit to this
    /// safe stop point (m along the route; `None`: none ahead, it stops as soon as it can).
    MinimalRisk {
        /// The safe stop point.
        stop_at: Option<f64>,
    },
    /// It stopped at the end of a minimal-risk manoeuvre, here (m along the route).
    MinimalRiskStop {
        /// Where, as the ADS reckons it.
        at: f64,
    },
    /// The vehicle reported nominal again (after a repair): the mission resumes.
    Resume,
}

impl MissionEvent {
    /// The event's kind, as run reports name it.
    pub fn kind(&self) -> &'static str {
        match self {
            MissionEvent::Phase(_) => "phase",
            MissionEvent::SteeringMode(_) => "steering_mode",
            MissionEvent::Stop { .. } => "stop",
            MissionEvent::Depart { .. } => "depart",
            MissionEvent::MinimalRisk { .. } => "minimal_risk",
            MissionEvent::MinimalRiskStop { .. } => "minimal_risk_stop",
            MissionEvent::Resume => "resume",
        }
    }
}

impl core::fmt::Display for MissionEvent {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            MissionEvent::Phase(phase) => write!(f, "{phase}"),
            MissionEvent::SteeringMode(mode) => write!(f, "{mode:?}"),
            MissionEvent::Stop { at, dwell } => {
                write!(f, "at {at:.1} m for {:.1} s", dwell.as_secs_f64())
            }
            MissionEvent::Depart { at } => write!(f, "from the stop at {at:.1} m"),
            MissionEvent::MinimalRisk { stop_at: Some(at) } => {
                write!(f, "to the safe stop point at {at:.1} m")
            }
            MissionEvent::MinimalRisk { stop_at: None } => {
                f.write_str("no safe stop point ahead: stopping as soon as it can")
            }
            MissionEvent::MinimalRiskStop { at } => write!(f, "stopped at {at:.1} m"),
            MissionEvent::Resume => f.write_str("nominal again: the mission resumes"),
        }
    }
}

/// The step of the step test being commanded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActiveStep {
    /// Its index in the steps.
    pub index: usize,
    /// The angle before, degrees.
    pub from: f64,
    /// The commanded angle, degrees.
    pub to: f64,
    /// When it was first commanded.
    pub started: Timestamp,
}

/// The route the follower steers along before the crab approach: the route up to where the
/// crab approach begins, then straight on (`crab_final_m` of 0: the route). Aiming no further
/// than that, the tug reaches the crab approach on the road's heading and the crab makes the
/// sideways move, not an early turn.
fn approach_route(route: &[Point], crab_final_m: f64) -> Vec<Point> {
    let Some(path) = Path::new(route) else {
        return route.to_vec();
    };
    let crab_start = path.length() - crab_final_m;
    if crab_final_m <= 0.0 || crab_start <= 1.0 {
        return route.to_vec();
    }
    let (before, at) = (
        path.at_station(crab_start - 1.0),
        path.at_station(crab_start),
    );
    let mut walked = 0.0;
    let mut points: Vec<Point> = route.first().copied().into_iter().collect();
    for pair in route.windows(2) {
        if let [a, b] = pair {
            walked += libm::hypot(b.x - a.x, b.y - a.y);
            if walked >= crab_start {
                break;
            }
            points.push(*b);
        }
    }
    // On past the crab approach's start along the road's direction, further than any
    // lookahead.
    points.push(at);
    points.push(Point {
        x: at.x + 20.0 * (at.x - before.x),
        y: at.y + 20.0 * (at.y - before.y),
    });
    points
}

/// The route and what to do along it, planned from the ADS's own estimate.
pub struct Mission {
    params: MissionParams,
    /// The route the follower steers along until the crab approach ([`approach_route`]).
    approach: Vec<Point>,
    follower: PurePursuit,
    /// The route's length, m (the route does not change).
    route_length: f64,
    /// The route's segment the tug was last found on (where the next projection looks first).
    last_segment: Option<usize>,
    /// Each wheel's angle for a tank turn (constant: the tug's geometry).
    tank_angles: [WheelState; 4],
    stop_index: usize,
    dwell_until: Option<Timestamp>,
    step: Option<ActiveStep>,
    tank: Option<(f64, f64)>,
    tank_done: bool,
    remaining: f64,
    steering_mode: SteeringMode,
    phase: Phase,
    /// A minimal-risk manoeuvre under way: where it ends (m along the route; the station
    /// where it began plus the braking distance when no safe stop point is ahead), and
    /// whether it has ended there.
    minimal_risk: Option<(f64, bool)>,
}

/// What the ADS knows of the vehicle when it plans.
#[derive(Debug, Clone, Copy)]
struct Known {
    /// Its pose estimate.
    pose: Pose,
    /// The speed the vehicle reports, m/s.
    speed: f64,
    /// The wheel angles it reports, degrees.
    angles: Option<[f64; 4]>,
    /// The degradation level it reports (a fail-operational vehicle).
    level: Option<DegradationLevel>,
}

/// One plan: the command's steering, speed and steering mode.
struct Plan {
    steering: f64,
    velocity: f64,
    mode: SteeringMode,
}

impl Mission {
    /// A mission along `params.route`.
    pub fn new(params: MissionParams) -> Mission {
        Mission {
            follower: PurePursuit {
                lookahead: Lookahead {
                    min: 3.0,
                    max: 8.0,
                    time: 1.5,
                },
                geometry: Geometry::CounterPhase {
                    wheelbase: params.wheelbase,
                    rear_ratio: 1.0,
                },
                max_steer: 35f64.to_radians(),
            },
            tank_angles: four_wheel(params.wheelbase, params.track).inverse(
                Motion::Tank { yaw_rate: 1.0 }.twist(),
                &[WheelState::default(); 4],
            ),
            route_length: Path::new(&params.route).map_or(0.0, |path| path.length()),
            approach: approach_route(&params.route, params.crab_final_m),
            last_segment: None,
            params,
            stop_index: 0,
            dwell_until: None,
            step: None,
            tank: None,
            tank_done: false,
            remaining: f64::INFINITY,
            steering_mode: SteeringMode::Normal,
            phase: Phase::Engaging,
            minimal_risk: None,
        }
    }

    /// The safe stop point a minimal-risk manoeuvre begun at `station` at `speed` ends at:
    /// the first one it can reach braking gently ([`GENTLE`]), or as soon as it can.
    fn safe_stop_ahead(&self, station: f64, speed: f64) -> (f64, bool) {
        let braking = speed * speed / (2.0 * GENTLE);
        match self
            .params
            .safe_stops
            .iter()
            .find(|&&at| at >= station + braking)
        {
            Some(&at) => (at, true),
            None => (station + braking, false),
        }
    }

    /// The degradation level the vehicle reports, applied: the speed cap it sets, and a
    /// minimal-risk manoeuvre begun, ended or (nominal again) given up. Returns the cap.
    fn degrade(
        &mut self,
        level: Option<DegradationLevel>,
        station: f64,
        speed: f64,
        events: &mut dyn FnMut(MissionEvent),
    ) -> f64 {
        let (degraded, minimal) = self.params.degraded_speeds;
        match level {
            None | Some(DegradationLevel::Nominal) => {
                if self.minimal_risk.take().is_some() {
                    events(MissionEvent::Resume);
                }
                f64::INFINITY
            }
            Some(DegradationLevel::Degraded) => degraded,
            Some(DegradationLevel::MinimalRisk) => {
                let (stop_at, ended) = match self.minimal_risk {
                    Some(manoeuvre) => manoeuvre,
                    None => {
                        let (at, safe) = self.safe_stop_ahead(station, speed);
                        events(MissionEvent::MinimalRisk {
                            stop_at: safe.then_some(at),
                        });
                        (at, false)
                    }
                };
                let ended = ended || (stop_at - station < 0.3 && speed.abs() < 0.05);
                if ended && self.minimal_risk.is_some_and(|(_, was)| !was) {
                    events(MissionEvent::MinimalRiskStop { at: station });
                }
                self.minimal_risk = Some((stop_at, ended));
                if ended {
                    0.0
                } else {
                    minimal.min(approach(0.0, stop_at - station))
                }
            }
            Some(DegradationLevel::SafeStop) => 0.0,
        }
    }

    /// The route's start pose: at its first point, facing its second.
    pub fn start_pose(&self) -> Pose {
        match self.params.route.as_slice() {
            [a, b, ..] => Pose {
                x: a.x,
                y: a.y,
                yaw: libm::atan2(b.y - a.y, b.x - a.x),
            },
            _ => Pose::default(),
        }
    }

    /// What remains of the route from where the ADS thinks it is, m.
    pub fn remaining(&self) -> f64 {
        self.remaining
    }

    /// The tank turn asked for is made (or none was asked for).
    pub fn tank_done(&self) -> bool {
        self.params.tank_turn_deg == 0.0 || self.tank_done
    }

    /// The phase under way.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// The step of the step test now being commanded.
    pub fn active_step(&self) -> Option<ActiveStep> {
        self.step
    }

    /// The ADS's speed at `station` (`remaining` to go): the speed of the route there,
    /// slowing in time for lower speeds ahead, for the next stop and for the end
    /// ([`approach`]); nothing while it dwells at a stop.
    fn speed_target(
        &mut self,
        now: Timestamp,
        station: f64,
        remaining: f64,
        speed: f64,
        events: &mut dyn FnMut(MissionEvent),
    ) -> f64 {
        let speeds = &self.params.speeds;
        let here = speeds
            .iter()
            .rev()
            .find(|(from, _)| *from <= station)
            .map_or(self.params.speed, |(_, v)| *v);
        let crab = if self.params.crab_final_m > 0.0 {
            approach(CRAB_SPEED, remaining - self.params.crab_final_m)
        } else {
            f64::INFINITY
        };
        let target = speeds.iter().filter(|(from, _)| *from > station).fold(
            here.min(approach(0.0, remaining)).min(crab),
            |v, (from, next)| v.min(approach(*next, from - station)),
        );
        let Some(&(at, dwell)) = self.params.stops.get(self.stop_index) else {
            return target;
        };
        match self.dwell_until {
            Some(until) if now < until => 0.0,
            Some(_) => {
                self.dwell_until = None;
                self.stop_index += 1;
                events(MissionEvent::Depart { at });
                target
            }
            None if at - station < 0.3 && speed.abs() < 0.05 => {
                self.dwell_until = Some(now.saturating_add(dwell));
                events(MissionEvent::Stop { at, dwell });
                0.0
            }
            None => target.min(approach(0.0, at - station)),
        }
    }

    /// The step test's angle while it runs.
    fn step_target(&mut self, now: Timestamp, engaged: Timestamp) -> Option<f64> {
        let index =
            usize::try_from(now.saturating_since(engaged).as_nanos() / STEP_HOLD.as_nanos())
                .ok()?;
        let Some(&to) = self.params.steering_steps.get(index) else {
            self.step = None;
            return None;
        };
        if self.step.is_none_or(|s| s.index != index) {
            let from = index
                .checked_sub(1)
                .and_then(|before| self.params.steering_steps.get(before))
                .copied()
                .unwrap_or(0.0);
            self.step = Some(ActiveStep {
                index,
                from,
                to,
                started: now,
            });
        }
        Some(to)
    }

    /// The tank turn at the end of the route: the wheel speed to command while it runs.
    fn tank_turn(
        &mut self,
        remaining: f64,
        yaw: f64,
        speed: f64,
        angles: Option<[f64; 4]>,
    ) -> Option<f64> {
        let wanted = self.params.tank_turn_deg.to_radians();
        if wanted == 0.0 || self.tank_done || remaining >= 0.3 {
            return None;
        }
        let (last_yaw, turned) = match self.tank {
            Some(tank) => tank,
            None if speed.abs() < 0.01 => (yaw, 0.0),
            None => return None,
        };
        let turned = turned + libm::remainder(yaw - last_yaw, 2.0 * core::f64::consts::PI);
        self.tank = Some((yaw, turned));
        let left = wanted - turned;
        if libm::fabs(left) < 0.5f64.to_radians() {
            self.tank_done = true;
            return None;
        }
        // The wheels turn to their tank angles first (as the vehicle reports them), then the
        // tug rotates.
        let aligned = angles.is_some_and(|angles| {
            angles
                .iter()
                .zip(&self.tank_angles)
                .all(|(a, t)| libm::fabs(a - t.angle.to_degrees()) < 3.0)
        });
        if !aligned {
            return Some(0.0);
        }
        let radius = libm::hypot(self.params.wheelbase / 2.0, self.params.track / 2.0);
        // Slow to a stop on the heading: ω² = 2·α·θ with a gentle 0.3 rad/s².
        let rate = libm::sqrt(2.0 * 0.3 * libm::fabs(left)).min(0.5);
        Some(libm::copysign(rate * radius, left))
    }

    /// The command from what the ADS knows of the vehicle; `engaged` is when the vehicle
    /// first followed.
    fn plan(
        &mut self,
        now: Timestamp,
        known: &Known,
        engaged: Option<Timestamp>,
        events: &mut dyn FnMut(MissionEvent),
    ) -> Plan {
        let Known {
            pose,
            speed,
            angles,
            level,
        } = *known;
        let crab = self.remaining < self.params.crab_final_m;
        let (steering, remaining, station) = match Path::new(&self.params.route) {
            Some(path) => {
                let here = Point {
                    x: pose.x,
                    y: pose.y,
                };
                let projection = path.project_near(here, self.last_segment);
                self.last_segment = Some(projection.segment);
                let steering = if crab {
                    // The stand approach in crab: every wheel toward the point a lookahead
                    // ahead on the route, the heading held.
                    let ahead =
                        path.at_station(projection.station + self.follower.lookahead.at(speed));
                    let bearing = libm::atan2(ahead.y - pose.y, ahead.x - pose.x) - pose.yaw;
                    libm::atan2(libm::sin(bearing), libm::cos(bearing))
                        .clamp(-self.follower.max_steer, self.follower.max_steer)
                        .to_degrees()
                } else {
                    // Up to where the crab begins the approach route is the route, station for
                    // station: the route's projection serves it.
                    let approach = Path::new(&self.approach).unwrap_or(path);
                    self.follower
                        .steer_from(pose, speed, &approach, &projection)
                        .front
                        .to_degrees()
                };
                (
                    steering,
                    self.route_length - projection.station,
                    projection.station,
                )
            }
            None => (0.0, 0.0, 0.0),
        };
        self.remaining = remaining;
        let cap = self.degrade(level, station, speed, events);
        let target = self
            .speed_target(now, station, remaining, speed, events)
            .min(cap);
        let degraded = cap.is_finite();
        let velocity = if remaining < 0.3 || engaged.is_none() {
            0.0
        } else {
            target
        };
        // The step test comes first, the tank turn last; after it the tug stands in normal
        // mode.
        let step = engaged.and_then(|at| self.step_target(now, at));
        // Degraded, the special manoeuvres wait: normal steering, no tank turn.
        let tank = if engaged.is_some() && !degraded {
            self.tank_turn(remaining, pose.yaw, speed, angles)
        } else {
            None
        };
        let (steering, velocity, mode) = match (step, tank) {
            (Some(angle), _) => (angle, 0.0, SteeringMode::Normal),
            (None, Some(wheel_speed)) => (0.0, wheel_speed, SteeringMode::Tank),
            (None, None) if crab && !self.tank_done && !degraded => {
                (steering, velocity, SteeringMode::Crab)
            }
            (None, None) => (steering, velocity, SteeringMode::Normal),
        };
        if mode != self.steering_mode {
            self.steering_mode = mode;
            events(MissionEvent::SteeringMode(mode));
        }
        let at_end = remaining < 0.3;
        let phase = match (engaged, step, mode) {
            (None, _, _) => Phase::Engaging,
            (Some(_), Some(_), _) => Phase::StepTest,
            (Some(_), None, SteeringMode::Tank) => Phase::TankTurn,
            (Some(_), None, SteeringMode::Crab) => Phase::CrabApproach,
            // At the end, waiting to stand still before the tank turn is part of it.
            (Some(_), None, SteeringMode::Normal) if at_end && !self.tank_done() && !degraded => {
                Phase::TankTurn
            }
            (Some(_), None, SteeringMode::Normal) if at_end => Phase::Stop,
            (Some(_), None, SteeringMode::Normal) => Phase::Cruise,
        };
        if phase != self.phase {
            self.phase = phase;
            events(MissionEvent::Phase(phase));
        }
        Plan {
            steering,
            velocity,
            mode,
        }
    }
}

/// The built-in ADS as a node: the ADS side of the wire on bus 1 and bus 1b (ports
/// [`Ads::PORT_A`] and [`Ads::PORT_B`]), and the mission planning its commands every cycle.
pub struct AdsDriver {
    ads: Ads<TugWire>,
    mission: Mission,
    next_plan: Timestamp,
    cycles: u32,
    engaged_at: Option<Timestamp>,
    resetting: bool,
    planning: bool,
    steering_command: f64,
    events: VecDeque<(Timestamp, MissionEvent)>,
}

impl AdsDriver {
    /// An ADS driving `mission` through `wire`, its odometry starting at the route's start.
    pub fn new(config: AdsConfig, mission: Mission, wire: TugWire) -> AdsDriver {
        let mut ads = Ads::with_wire(
            AdsConfig {
                redundant: true,
                ..config
            },
            wire,
        );
        ads.reset_odometry(mission.start_pose());
        AdsDriver {
            ads,
            mission,
            next_plan: Timestamp::ZERO,
            cycles: 0,
            engaged_at: None,
            resetting: false,
            planning: true,
            steering_command: 0.0,
            events: VecDeque::with_capacity(EVENT_CAPACITY),
        }
    }

    /// The ADS side (its view of the vehicle, its counts).
    pub fn ads(&self) -> &Ads<TugWire> {
        &self.ads
    }

    /// The mission.
    pub fn mission(&self) -> &Mission {
        &self.mission
    }

    /// When the vehicle first reported autonomous mode.
    pub fn engaged_at(&self) -> Option<Timestamp> {
        self.engaged_at
    }

    /// The steering angle last commanded, degrees.
    pub fn steering_command(&self) -> f64 {
        self.steering_command
    }

    /// The operator presses the reset (edges every half second) until the vehicle reports the
    /// E-stop latch clear and follows again.
    pub fn operator_reset(&mut self) {
        self.resetting = true;
    }

    /// Stop planning (another ADS takes over the bus).
    pub fn stop_planning(&mut self) {
        self.planning = false;
    }

    /// Whether events wait to be taken.
    pub fn has_events(&self) -> bool {
        !self.events.is_empty()
    }

    /// The oldest event not yet taken.
    pub fn next_event(&mut self) -> Option<(Timestamp, MissionEvent)> {
        self.events.pop_front()
    }

    fn plan(&mut self, now: Timestamp) {
        let state = *self.ads.state();
        let pose = state
            .odometry
            .value
            .unwrap_or_else(|| self.mission.start_pose());
        let speed = state.velocity.value.unwrap_or(0.0);
        let angles = state.wheel_angles.value;
        let events = &mut self.events;
        let mut record = |event| {
            if events.len() < EVENT_CAPACITY {
                events.push_back((now, event));
            }
        };
        let known = Known {
            pose,
            speed,
            angles,
            level: state.degradation.value,
        };
        let plan = self.mission.plan(now, &known, self.engaged_at, &mut record);
        // Engage is an edge, taken once the vehicle's recovery run is complete: request it
        // every tenth cycle until the vehicle reports autonomous mode (or, awaiting re-engage
        // after full braking, again).
        self.cycles = self.cycles.wrapping_add(1);
        let autonomous = state.mode.value == Some(ControlMode::Autonomous);
        let awaiting = state.watchdog_level.value == Some(WatchdogLevel::AwaitingEngage);
        let engage = self.ads.feedback_alive(now)
            && (!autonomous || awaiting)
            && self.cycles.is_multiple_of(10);
        if autonomous && self.engaged_at.is_none() {
            self.engaged_at = Some(now);
        }
        self.steering_command = plan.steering;
        // The operator presses reset (an edge, every half second) while the latch is stopped
        // or waiting for the confirming press, until the vehicle reports it clear.
        let estop = state.estop_state.value;
        if estop == Some(EstopCode::Normal) && self.resetting && autonomous {
            self.resetting = false;
        }
        let operator_reset = self.resetting
            && estop.is_some_and(EstopCode::awaits_operator_reset)
            && self.cycles.is_multiple_of(25);
        let command = AdsCommand {
            steering: plan.steering,
            velocity: plan.velocity,
            brake: if plan.velocity == 0.0 { 30.0 } else { 0.0 },
            gear: Gear::Drive,
            mode: ControlMode::Autonomous,
            steering_mode: plan.mode,
            engage,
            operator_reset,
            ..AdsCommand::default()
        };
        let _ = self.ads.set_command(now, command);
    }
}

impl Node for AdsDriver {
    fn on_frame(&mut self, now: Timestamp, port: Port, frame: &Frame) {
        Node::on_frame(&mut self.ads, now, port, frame);
    }

    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        if self.planning && now >= self.next_plan {
            self.next_plan = now.saturating_add(PLAN_PERIOD);
            self.plan(now);
        }
        if self.planning {
            Node::poll(&mut self.ads, now, out);
        }
    }

    fn next_deadline(&self) -> Option<Timestamp> {
        if !self.planning {
            return None;
        }
        earliest([Node::next_deadline(&self.ads), Some(self.next_plan)])
    }
}
