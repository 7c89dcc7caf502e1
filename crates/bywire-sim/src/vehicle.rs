//! A simulated vehicle for any profile: the real supervisor reading the profile's wire, in
//! front of a simple plant, as one node. An ADS developer (or a test written against a vehicle)
//! runs against it without a vehicle — on the real-time runner over any bus (`bywire vehicle`,
//! `bywire bridge --with-vehicle`) or on the simulated runner.
//!
//! The plant is deliberately plain, but not a toy: steering follows the actuator's (already
//! rate-limited) setpoint through a first-order lag; speed follows the setpoint within an
//! acceleration limit and brakes at the profile's deceleration scaled by the brake demand; the
//! vehicle stops and holds when the motors are disabled. The supervisor's state frame goes out
//! at its period, and the wheel speeds and angles (where the profile has them; the angles the
//! steering mode gives the plant's one angle) at the same period. The
//! E-stop latch and operator reset are the supervisor's own: an E-stop frame latches it, and
//! only the command's operator-reset sequence and a re-engage release it.

use core::time::Duration;

use bywire_control::kinematics::{four_wheel, Swerve, WheelState};
use bywire_core::node::{Node, Port};
use bywire_core::time::earliest;
use bywire_core::{Frame, Timestamp};
use bywire_vehicle::mechanism::Mechanisms;
use bywire_vehicle::supervisor::{Actuators, Supervisor, SupervisorConfig};
use bywire_vehicle::wire::VehicleWire;

/// The plant's tuning.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlantParams {
    /// Steering lag's time constant.
    pub steering_lag: Duration,
    /// Largest acceleration, m/s².
    pub acceleration: f64,
    /// Deceleration at 100 % brake, m/s².
    pub braking: f64,
    /// Deceleration when coasting with the motors off, m/s².
    pub coasting: f64,
    /// The plant's step.
    pub step: Duration,
}

impl Default for PlantParams {
    fn default() -> Self {
        PlantParams {
            steering_lag: Duration::from_millis(100),
            acceleration: 1.0,
            braking: 4.0,
            coasting: 0.5,
            step: Duration::from_millis(5),
        }
    }
}

/// What the plant is doing.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlantState {
    /// Speed, m/s (negative in reverse).
    pub speed: f64,
    /// Steering angle, degrees.
    pub steering: f64,
    /// Distance travelled, m.
    pub distance: f64,
}

/// The supervisor and a plant, as one node on the supervisor's ports.
#[derive(Debug, Clone)]
pub struct SimulatedVehicle<W: VehicleWire> {
    supervisor: Supervisor<W>,
    params: PlantParams,
    plant: PlantState,
    last_step: Option<Timestamp>,
    report_period: Duration,
    next_report: Timestamp,
    wheel_counter: u64,
    redundant: bool,
    /// Where the wheels are.
    wheels: Swerve<4>,
    /// The wheels' last angles and speeds.
    wheel_states: [WheelState; 4],
}

impl<W: VehicleWire> SimulatedVehicle<W> {
    /// A vehicle whose supervisor reads `wire` with `config`, reporting wheel speeds every
    /// `report_period`.
    pub fn new(
        config: SupervisorConfig,
        wire: W,
        params: PlantParams,
        report_period: Duration,
    ) -> Self {
        SimulatedVehicle {
            redundant: config.redundancy.is_some(),
            supervisor: Supervisor::with_wire(config, wire),
            params,
            plant: PlantState::default(),
            last_step: None,
            report_period: report_period.max(Duration::from_millis(1)),
            next_report: Timestamp::ZERO,
            wheel_counter: 0,
            wheels: four_wheel(DEFAULT_WHEELBASE, DEFAULT_TRACK),
            wheel_states: [WheelState::default(); 4],
        }
    }

    /// The vehicle's wheelbase and track (m), for its wheel angles.
    pub fn with_geometry(mut self, wheelbase: f64, track: f64) -> Self {
        self.wheels = four_wheel(wheelbase, track);
        self
    }

    /// The supervisor (its watchdog, latch, mode, counts).
    pub fn supervisor(&self) -> &Supervisor<W> {
        &self.supervisor
    }

    /// The supervisor, to give it driver inputs.
    pub fn supervisor_mut(&mut self) -> &mut Supervisor<W> {
        &mut self.supervisor
    }

    /// What the plant is doing.
    pub fn plant(&self) -> PlantState {
        self.plant
    }

    /// Advance the plant to `now` in whole steps of `params.step`.
    fn step_plant(&mut self, now: Timestamp) {
        let Some(last) = self.last_step else {
            self.last_step = Some(now);
            return;
        };
        let step = self.params.step.max(Duration::from_micros(100));
        let due = now.saturating_since(last).as_nanos() / step.as_nanos().max(1);
        let steps = u32::try_from(due)
            .unwrap_or(u32::MAX)
            .min(MAX_CATCH_UP_STEPS);
        if steps == 0 {
            return;
        }
        let actuators = self.supervisor.actuators(now);
        for _ in 0..steps {
            self.plant = plant_step(self.plant, &actuators, &self.params, step.as_secs_f64());
        }
        // After a long pause (a stalled host) the plant does not replay it all.
        self.last_step = Some(if steps == MAX_CATCH_UP_STEPS {
            now
        } else {
            last.saturating_add(step.saturating_mul(steps))
        });
        self.supervisor
            .set_feedback(self.plant.speed, self.plant.steering);
    }
}

/// The geometry assumed without a profile's `[vehicle]` (the reference tug's).
const DEFAULT_WHEELBASE: f64 = 3.2;
/// Its track, m.
const DEFAULT_TRACK: f64 = 1.8;

/// The most plant steps taken at once.
const MAX_CATCH_UP_STEPS: u32 = 1_000;

/// One step of the plant under the actuators' outputs.
pub fn plant_step(state: PlantState, a: &Actuators, p: &PlantParams, dt: f64) -> PlantState {
    let lag = p.steering_lag.as_secs_f64().max(1e-3);
    let target_steering = if a.steering_enabled {
        a.steering
    } else {
        state.steering
    };
    let steering = state.steering + (target_steering - state.steering) * (dt / lag).min(1.0);
    let speed = state.speed;
    let toward = |target: f64, rate: f64| {
        let change = (target - speed).clamp(-rate * dt, rate * dt);
        speed + change
    };
    let speed = if a.brake > 0.0 || !a.motors_enabled {
        let rate = if a.brake > 0.0 {
            p.braking * (a.brake / 100.0).clamp(0.0, 1.0)
        } else {
            p.coasting
        };
        toward(0.0, rate)
    } else {
        toward(a.velocity, p.acceleration)
    };
    let speed = if speed.is_finite() { speed } else { 0.0 };
    let steering = if steering.is_finite() { steering } else { 0.0 };
    PlantState {
        speed,
        steering,
        distance: state.distance + speed.abs() * dt,
    }
}

impl<W: VehicleWire> Node for SimulatedVehicle<W> {
    fn on_frame(&mut self, now: Timestamp, port: Port, frame: &Frame) {
        self.step_plant(now);
        Node::on_frame(&mut self.supervisor, now, port, frame);
    }

    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        self.step_plant(now);
        Node::poll(&mut self.supervisor, now, out);
        if now >= self.next_report {
            self.next_report = now.saturating_add(self.report_period);
            // Each wheel as the steering mode moves it at the plant's speed and angle.
            let mode = self.supervisor.actuators(now).steering_mode;
            self.wheel_states = mode.wheel_states(
                self.plant.speed,
                self.plant.steering.to_radians(),
                &self.wheels,
                &self.wheel_states,
            );
            let speeds = self.wheel_states.map(|w| w.speed);
            let angles = self.wheel_states.map(|w| w.angle.to_degrees());
            let wire = self.supervisor.wire_mut();
            let frames = [
                wire.wheel_speeds_frame(speeds, self.wheel_counter),
                wire.wheel_angles_frame(angles, self.wheel_counter),
            ];
            for frame in frames.into_iter().flatten() {
                out(Supervisor::<W>::PORT_A, frame);
                if self.redundant {
                    out(Supervisor::<W>::PORT_B, frame);
                }
            }
            self.wheel_counter = self.wheel_counter.wrapping_add(1);
        }
    }

    fn next_deadline(&self) -> Option<Timestamp> {
        let plant = self
            .last_step
            .map_or(Timestamp::ZERO, |t| t.saturating_add(self.params.step));
        earliest([
            Node::next_deadline(&self.supervisor),
            Some(self.next_report),
            Some(plant),
        ])
    }
}

impl SimulatedVehicle<bywire_vehicle::secured::Secured<bywire_vehicle::wire::ProfileWire>> {
    /// The vehicle a profile describes, on one bus or (`redundant`) two: its supervisor
    /// configured by the profile (voting on the two buses' copies, a bus lost once its copy is
    /// half a cycle overdue), braking at the profile's deceleration, reporting at its state
    /// period.
    pub fn from_profile(
        profile: &bywire_vehicle::profile::LoadedProfile,
        wire: bywire_vehicle::secured::Secured<bywire_vehicle::wire::ProfileWire>,
        redundant: bool,
    ) -> Self {
        Self::from_profile_without(profile, wire, redundant, Mechanisms::NONE)
    }

    /// The same vehicle with the mechanisms `disabled` switched off in its supervisor: a
    /// fault-injection campaign's proof that its cells would notice one missing.
    pub fn from_profile_without(
        profile: &bywire_vehicle::profile::LoadedProfile,
        wire: bywire_vehicle::secured::Secured<bywire_vehicle::wire::ProfileWire>,
        redundant: bool,
        disabled: Mechanisms,
    ) -> Self {
        let mut config = profile.supervisor_config();
        config.disabled = disabled;
        if redundant {
            config.redundancy = Some(bywire_vehicle::supervisor::Redundancy::for_cycle(
                config.cycle,
            ));
        }
        let params = PlantParams {
            braking: profile.profile.limits.deceleration_m_s2,
            ..PlantParams::default()
        };
        let period = profile
            .profile
            .state
            .as_ref()
            .map_or(config.cycle, |s| Duration::from_millis(s.period_ms));
        let vehicle = SimulatedVehicle::new(config, wire, params, period);
        match &profile.profile.vehicle {
            Some(v) => vehicle.with_geometry(v.wheelbase_m, v.track_m),
            None => vehicle,
        }
    }
}
