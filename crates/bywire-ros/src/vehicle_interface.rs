//! The Autoware vehicle interface for any profile: the ADS-side node ([`Ads`]) on the
//! real-time runner over one or two buses, its command from Autoware's topics and its reports
//! published back.
//!
//! In: `control_cmd` (`Control`), `gear_cmd`, a steering mode (`std_msgs/String`: normal,
//! crab, tank), `cmd_vel` (`Twist`, through the 4WS kinematics), `turn_indicators_cmd` and
//! `hazard_lights_cmd` where the profile's command has them, `emergency_cmd`
//! (`VehicleEmergencyStamped`: the emergency brake at the vehicle's hardest deceleration and a
//! stop, disengaged; its end releases the brake, and driving again takes an engage), and the
//! `ControlModeCommand`
//! service (engage: answered once the vehicle reports autonomous with its watchdog not
//! braking, or `false` after [`VehicleInterfaceConfig::engage_timeout`]; disengage). The
//! operator's E-stop reset is not offered: it stays a deliberate act at the vehicle.
//! Out, at [`VehicleInterfaceConfig::report_period`]: steering, velocity, gear and control-mode
//! status from fresh feedback only (disengaged while the watchdog brakes: see
//! [`crate::autoware_vehicle::control_mode_code`]), the wheels as `JointState` and the steering
//! mode, and the turn-indicator and hazard-light status where the profile's state message has
//! them.
//!
//! Safety is the node's: a command older than the profile's staleness (a stopped publisher) is
//! replaced by a controlled stop; a lost bus degrades to the other; the end of the run (the
//! stop flag) brakes for a second before returning.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use bywire_bus::runner::{Flow, Hooks, Runner};
use bywire_bus::{Bus, BusError};
use bywire_core::node::Port;
use bywire_core::time::earliest;
use bywire_core::Timestamp;
use bywire_secoc::store::FreshnessStore;
use bywire_vehicle::ads::{Ads, AdsCommand, VehicleState};
use bywire_vehicle::command::{ControlMode, SteeringMode};
use bywire_vehicle::profile::{Limits, LoadedProfile};
use bywire_vehicle::secured::Secured;
use bywire_vehicle::wire::ProfileWire;
use ros2_client::RmwRequestId;

use crate::autoware_vehicle::{self as map, Geometry};
use crate::dds::{
    mio1, reliable, wake_on_readiness, Publisher, RosError, RosNode, Server, Subscription,
};
use crate::msg::{
    control_mode, ControlModeReport, ControlModeRequest, ControlModeResponse, DiagnosticArray,
    DiagnosticStatus, GearCommand, GearReport, HazardLightsCommand, HazardLightsReport, Header,
    JointState, KeyValue, SteeringReport, StringMsg, Time, TurnIndicatorsCommand,
    TurnIndicatorsReport, Twist, VehicleEmergencyStamped, VelocityReport,
};

/// The ADS side over a profile's wire, secured when the profile declares `[secoc]`.
pub type AdsSide = Ads<Secured<ProfileWire>>;

/// Messages taken from one input in one pass.
const TAKE_BATCH: usize = 64;
/// How long the end of a run brakes.
const FINAL_BRAKING: Duration = Duration::from_secs(1);

/// Topic and service names (Autoware's), and the rates.
#[derive(Debug, Clone, PartialEq)]
pub struct VehicleInterfaceConfig {
    /// `autoware_control_msgs/Control` in.
    pub control_cmd: String,
    /// `GearCommand` in.
    pub gear_cmd: String,
    /// The steering mode in (`std_msgs/String`).
    pub steering_mode_cmd: String,
    /// `geometry_msgs/Twist` in.
    pub cmd_vel: String,
    /// `TurnIndicatorsCommand` in.
    pub turn_indicators_cmd: String,
    /// `HazardLightsCommand` in.
    pub hazard_lights_cmd: String,
    /// `VehicleEmergencyStamped` in.
    pub emergency_cmd: String,
    /// The `ControlModeCommand` service.
    pub control_mode_request: String,
    /// `SteeringReport` out.
    pub steering_status: String,
    /// `VelocityReport` out.
    pub velocity_status: String,
    /// `GearReport` out.
    pub gear_status: String,
    /// `ControlModeReport` out.
    pub control_mode: String,
    /// The wheels as `JointState` out.
    pub joint_states: String,
    /// The steering mode out (`std_msgs/String`).
    pub steering_mode_status: String,
    /// `TurnIndicatorsReport` out.
    pub turn_indicators_status: String,
    /// `HazardLightsReport` out.
    pub hazard_lights_status: String,
    /// The degradation level and its reason out (`std_msgs/String`: `nominal`,
    /// `minimal-risk (actuator-backup)`), where the profile declares the report.
    pub degradation_status: String,
    /// `diagnostic_msgs/DiagnosticArray` out: the vehicle's state and each bus, every second
    /// and on every change.
    pub diagnostics: String,
    /// Time between reports.
    pub report_period: Duration,
    /// How long an engage request waits for the vehicle to report autonomous.
    pub engage_timeout: Duration,
}

impl Default for VehicleInterfaceConfig {
    fn default() -> Self {
        VehicleInterfaceConfig {
            control_cmd: "/control/command/control_cmd".into(),
            gear_cmd: "/control/command/gear_cmd".into(),
            steering_mode_cmd: "/vehicle/command/steering_mode".into(),
            cmd_vel: "/cmd_vel".into(),
            turn_indicators_cmd: "/control/command/turn_indicators_cmd".into(),
            hazard_lights_cmd: "/control/command/hazard_lights_cmd".into(),
            emergency_cmd: "/control/command/emergency_cmd".into(),
            control_mode_request: "/control/control_mode_request".into(),
            steering_status: "/vehicle/status/steering_status".into(),
            velocity_status: "/vehicle/status/velocity_status".into(),
            gear_status: "/vehicle/status/gear_status".into(),
            control_mode: "/vehicle/status/control_mode".into(),
            joint_states: "/vehicle/status/joint_states".into(),
            steering_mode_status: "/vehicle/status/steering_mode".into(),
            turn_indicators_status: "/vehicle/status/turn_indicators_status".into(),
            hazard_lights_status: "/vehicle/status/hazard_lights_status".into(),
            degradation_status: "/vehicle/status/degradation".into(),
            diagnostics: "/diagnostics".into(),
            report_period: Duration::from_millis(33),
            engage_timeout: Duration::from_secs(2),
        }
    }
}

/// What the caller hears of while the interface runs.
#[derive(Debug, Clone, PartialEq)]
pub enum VehicleEvent {
    /// An input was refused (the last valid command goes on aging).
    Refused(String),
    /// A brake beyond the vehicle's was taken as its hardest.
    Saturated(String),
    /// An engage or disengage request and its answer.
    ModeRequest {
        /// The requested Autoware mode.
        mode: u8,
        /// The answer.
        success: bool,
        /// Why it was refused, if it was.
        why: Option<String>,
    },
    /// A bus failed; the other goes on.
    BusLost(String),
    /// The run is ending: braking.
    Stopping,
    /// Autoware's emergency began (the emergency brake, disengaged) or ended (the brake
    /// released; driving again takes an engage).
    Emergency(bool),
    /// The freshness store cannot keep what is signed next: braking, then the end.
    Freshness(String),
}

/// The line a user reads.
impl std::fmt::Display for VehicleEvent {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            VehicleEvent::Refused(why) => write!(f, "refused: {why}"),
            VehicleEvent::Saturated(why) => f.write_str(why),
            VehicleEvent::ModeRequest { mode, success, why } => {
                let answer = if *success { "done" } else { "refused" };
                write!(f, "control mode request {mode}: {answer}")?;
                match why {
                    Some(why) => write!(f, " ({why})"),
                    None => Ok(()),
                }
            }
            VehicleEvent::BusLost(what) => write!(f, "bus {what}; commanding on the other"),
            VehicleEvent::Stopping => f.write_str("stopping: braking for 1 s"),
            VehicleEvent::Freshness(why) => {
                write!(f, "freshness store: {why}; braking for 1 s")
            }
            VehicleEvent::Emergency(true) => {
                f.write_str("emergency_cmd: emergency brake, disengaged")
            }
            VehicleEvent::Emergency(false) => {
                f.write_str("emergency_cmd cleared: brake released; engage to drive again")
            }
        }
    }
}

struct Inputs {
    control: Subscription<crate::msg::Control>,
    gear: Subscription<GearCommand>,
    steering_mode: Subscription<StringMsg>,
    cmd_vel: Subscription<Twist>,
    mode_request: Server<ControlModeRequest, ControlModeResponse>,
    /// Where the profile's command has turn indicators.
    turn_indicators: Option<Subscription<TurnIndicatorsCommand>>,
    /// Where the profile's command has hazard lights.
    hazard_lights: Option<Subscription<HazardLightsCommand>>,
    emergency: Subscription<VehicleEmergencyStamped>,
}

struct Outputs {
    steering: Publisher<SteeringReport>,
    velocity: Publisher<VelocityReport>,
    gear: Publisher<GearReport>,
    control_mode: Publisher<ControlModeReport>,
    joints: Publisher<JointState>,
    steering_mode: Publisher<StringMsg>,
    /// Where the profile's state message has turn indicators.
    turn_indicators: Option<Publisher<TurnIndicatorsReport>>,
    /// Where the profile's state message has hazard lights.
    hazard_lights: Option<Publisher<HazardLightsReport>>,
    /// Where the profile declares a fail-operational report.
    degradation: Option<Publisher<StringMsg>>,
    diagnostics: Publisher<DiagnosticArray>,
}

/// The interface's side of a run: the hooks of the real-time runner (`run`), or stepped by a
/// simulation that drives the node itself (`after_poll` after each of its steps).
pub struct VehicleInterface<'a> {
    inputs: Inputs,
    outputs: Outputs,
    config: VehicleInterfaceConfig,
    geometry: Option<Geometry>,
    limits: Limits,
    /// Fresh feedback is younger than this.
    fresh: Duration,
    command: AdsCommand,
    /// The steering mode chosen on the steering-mode topic (control_cmd steers in it).
    steering_mode: SteeringMode,
    /// A command has arrived (before it, nothing is sent).
    commanding: bool,
    /// An engage request waiting: its id, since when, until when.
    engage: Option<(RmwRequestId, Timestamp, Timestamp)>,
    /// The command period (engage pulses last one).
    cycle: Duration,
    next_report: Timestamp,
    last_report: Option<Timestamp>,
    drive_rotation: [f64; 4],
    stop: &'a AtomicBool,
    braking_until: Option<Timestamp>,
    buses: Vec<(Port, String)>,
    report: &'a mut dyn FnMut(VehicleEvent),
    /// Where the secured wire's freshness is kept across restarts.
    freshness: Option<FreshnessStore>,
    /// The buses lost, each with its error.
    lost: Vec<(Port, String)>,
    /// The vehicle's name in the diagnostics.
    hardware_id: String,
    /// Autoware's emergency is on: the emergency brake goes on until it ends.
    emergency: bool,
    /// When the diagnostics last went out, and their levels and messages then.
    last_diagnostics: Option<(Timestamp, Vec<(u8, String)>)>,
}

impl VehicleInterface<'_> {
    fn geometry(&self) -> Geometry {
        self.geometry.unwrap_or(Geometry {
            wheelbase: 1.0,
            track: 1.0,
            wheel_diameter: 0.0,
            four_wheel_steer: false,
        })
    }

    /// Take a new command (or refuse it) and hand it to the node.
    fn command(&mut self, ads: &mut AdsSide, now: Timestamp, next: Result<map::Mapped, String>) {
        match next {
            // Held at a stop until the emergency ends.
            Ok(_) if self.emergency => {}
            Ok(map::Mapped { command, warning }) => {
                if let Some(warning) = warning {
                    (self.report)(VehicleEvent::Saturated(warning));
                }
                self.command = command;
                self.commanding = true;
                self.send(ads, now);
            }
            Err(why) => (self.report)(VehicleEvent::Refused(why)),
        }
    }

    fn send(&mut self, ads: &mut AdsSide, now: Timestamp) {
        if !self.commanding || self.braking_until.is_some() {
            return;
        }
        // The vehicle takes an engage on a rising edge, and one edge serves one transition
        // (a watchdog's recovery, then the mode): while a request waits, the bit pulses, high
        // for one command period and low for the next.
        let cycles = now
            .saturating_since(self.engage.map_or(now, |(_, since, _)| since))
            .as_nanos()
            / self.cycle.as_nanos().max(1);
        let command = AdsCommand {
            engage: self.engage.is_some() && cycles.is_multiple_of(2),
            ..self.command
        };
        ads.set_command(now, command);
    }

    fn take_inputs(&mut self, ads: &mut AdsSide, now: Timestamp) {
        let g = self.geometry();
        for _ in 0..TAKE_BATCH {
            let Ok(Some((m, _))) = self.inputs.control.take() else {
                break;
            };
            // A control_cmd steers in the mode chosen on the steering-mode topic (a cmd_vel
            // before it may have chosen another).
            let base = AdsCommand {
                steering_mode: self.steering_mode,
                ..self.command
            };
            let next = map::from_control(&m, base, &g, &self.limits);
            self.command(ads, now, next);
        }
        for _ in 0..TAKE_BATCH {
            let Ok(Some((m, _))) = self.inputs.cmd_vel.take() else {
                break;
            };
            let next =
                map::from_twist(&m, self.command, &g, &self.limits).map(|command| map::Mapped {
                    command,
                    warning: None,
                });
            self.command(ads, now, next);
        }
        for _ in 0..TAKE_BATCH {
            let Ok(Some((m, _))) = self.inputs.gear.take() else {
                break;
            };
            match map::gear_from_code(m.command) {
                // Takes effect with the next command (a gear alone starts nothing).
                Ok(Some(gear)) => self.command.gear = gear,
                Ok(None) => {}
                Err(why) => (self.report)(VehicleEvent::Refused(why)),
            }
        }
        for _ in 0..TAKE_BATCH {
            let Ok(Some((m, _))) = self.inputs.steering_mode.take() else {
                break;
            };
            match m.data.parse::<SteeringMode>() {
                Ok(mode) if mode != SteeringMode::Normal && !g.four_wheel_steer => {
                    (self.report)(VehicleEvent::Refused(format!(
                        "steering mode {mode}: this vehicle has no four-wheel steer"
                    )))
                }
                Ok(mode) => {
                    self.steering_mode = mode;
                    self.command.steering_mode = mode;
                }
                Err(e) => (self.report)(VehicleEvent::Refused(format!("'{}': {e}", m.data))),
            }
        }
        self.take_lights();
        for _ in 0..TAKE_BATCH {
            let Ok(Some((m, _))) = self.inputs.emergency.take() else {
                break;
            };
            self.set_emergency(ads, now, m.emergency);
        }
        for _ in 0..TAKE_BATCH {
            let Ok(Some((id, request))) = self.inputs.mode_request.receive_request() else {
                break;
            };
            self.mode_request(ads, now, id, request.mode);
        }
    }

    /// Lights requested take effect with the next command, as a gear does.
    fn take_lights(&mut self) {
        for _ in 0..TAKE_BATCH {
            let Some(Ok(Some((m, _)))) = self.inputs.turn_indicators.as_mut().map(|s| s.take())
            else {
                break;
            };
            match map::turn_indicators_from_code(m.command) {
                Ok(Some(lights)) => self.command.turn_indicators = lights,
                Ok(None) => {}
                Err(why) => (self.report)(VehicleEvent::Refused(why)),
            }
        }
        for _ in 0..TAKE_BATCH {
            let Some(Ok(Some((m, _)))) = self.inputs.hazard_lights.as_mut().map(|s| s.take())
            else {
                break;
            };
            match map::hazard_lights_from_code(m.command) {
                Ok(Some(on)) => self.command.hazard_lights = on,
                Ok(None) => {}
                Err(why) => (self.report)(VehicleEvent::Refused(why)),
            }
        }
    }

    fn answer(&mut self, id: RmwRequestId, mode: u8, success: bool, why: Option<String>) {
        let _ = self
            .inputs
            .mode_request
            .send_response(id, ControlModeResponse { success });
        (self.report)(VehicleEvent::ModeRequest { mode, success, why });
    }

    fn mode_request(&mut self, ads: &mut AdsSide, now: Timestamp, id: RmwRequestId, mode: u8) {
        match mode {
            control_mode::AUTONOMOUS if self.emergency => {
                let why = Some("emergency_cmd holds: engage once it ends".to_string());
                self.answer(id, mode, false, why);
            }
            control_mode::AUTONOMOUS => {
                self.command.mode = ControlMode::Autonomous;
                // A newer request replaces one still waiting, which is answered now.
                if let Some((old, _, _)) = self.engage.take() {
                    self.answer(old, mode, false, Some("replaced by a newer request".into()));
                }
                self.engage = Some((id, now, now.saturating_add(self.config.engage_timeout)));
                self.send(ads, now);
            }
            control_mode::MANUAL => {
                self.command.mode = ControlMode::Manual;
                if let Some((old, _, _)) = self.engage.take() {
                    self.answer(
                        old,
                        control_mode::AUTONOMOUS,
                        false,
                        Some("disengaged".into()),
                    );
                }
                self.send(ads, now);
                self.answer(id, mode, true, None);
            }
            other => {
                let why = format!("mode {other}: this interface engages (1) and disengages (4)");
                self.answer(id, other, false, Some(why));
            }
        }
    }

    fn watch_engage(&mut self, ads: &AdsSide, now: Timestamp) {
        let Some((id, _, deadline)) = self.engage else {
            return;
        };
        if self.control_mode(ads.state(), now) == control_mode::AUTONOMOUS {
            self.engage = None;
            self.answer(id, control_mode::AUTONOMOUS, true, None);
        } else if now >= deadline {
            self.engage = None;
            let why = ads.blocker(now).map(|b| b.to_string());
            self.answer(id, control_mode::AUTONOMOUS, false, why);
        }
    }

    /// The control mode Autoware is told, from fresh feedback only.
    fn control_mode(&self, state: &VehicleState, now: Timestamp) -> u8 {
        map::control_mode_code(
            state.mode.fresh(now, self.fresh),
            state.watchdog_level.fresh(now, self.fresh),
        )
    }

    /// `/diagnostics`: every second, and at once when a level or message changes.
    fn publish_diagnostics(&mut self, ads: &AdsSide, now: Timestamp) {
        let status = diagnostics(
            ads.state(),
            now,
            self.fresh,
            &self.hardware_id,
            &self.buses,
            &self.lost,
        );
        let summary: Vec<(u8, String)> = status
            .iter()
            .map(|s| (s.level, s.message.clone()))
            .collect();
        let due = match &self.last_diagnostics {
            None => true,
            Some((at, last)) => *last != summary || now.saturating_since(*at) >= DIAGNOSTICS_PERIOD,
        };
        if !due {
            return;
        }
        let array = DiagnosticArray {
            header: Header {
                stamp: Time::now(),
                frame_id: String::new(),
            },
            status,
        };
        // Publishing fails only when DDS is gone; the next report tries again.
        if self.outputs.diagnostics.publish(array).is_ok() {
            self.last_diagnostics = Some((now, summary));
        }
    }

    fn publish_reports(&mut self, ads: &AdsSide, now: Timestamp) {
        let stamp = Time::now();
        let state = ads.state();
        let g = self.geometry();
        let mode = state
            .steering_mode
            .fresh(now, self.fresh)
            .unwrap_or_default();
        // Publishing fails only when DDS is gone; the next report tries again.
        if let Some(steering) = state.steering.fresh(now, self.fresh) {
            let angle = map::tire_angle(steering, mode, &g);
            let _ = self.outputs.steering.publish(SteeringReport {
                stamp,
                steering_tire_angle: to_f32(angle),
            });
        }
        if let Some((vx, vy, omega)) = map::body_velocity(state, now, self.fresh, &g) {
            let _ = self.outputs.velocity.publish(VelocityReport {
                header: Header {
                    stamp,
                    frame_id: "base_link".into(),
                },
                longitudinal_velocity: to_f32(vx),
                lateral_velocity: to_f32(vy),
                heading_rate: to_f32(omega),
            });
        }
        // A vehicle whose state message has no gear: the gear commanded is the best known.
        let gear = state
            .gear
            .fresh(now, self.fresh)
            .or_else(|| state.mode.fresh(now, self.fresh).map(|_| self.command.gear));
        if let Some(gear) = gear {
            let _ = self.outputs.gear.publish(GearReport {
                stamp,
                report: map::gear_code(gear),
            });
        }
        let _ = self.outputs.control_mode.publish(ControlModeReport {
            stamp,
            mode: self.control_mode(state, now),
        });
        if let Some(speeds) = state.wheel_speeds.fresh(now, self.fresh) {
            let dt = self
                .last_report
                .map_or(0.0, |t| now.saturating_since(t).as_secs_f64());
            let radius = g.wheel_diameter / 2.0;
            if radius > 0.0 {
                for (rotation, speed) in self.drive_rotation.iter_mut().zip(speeds) {
                    *rotation += speed / radius * dt;
                }
            }
        }
        if self.geometry.is_some() {
            if let Some(joints) =
                map::joint_state(state, now, self.fresh, &g, &self.drive_rotation, stamp)
            {
                let _ = self.outputs.joints.publish(joints);
            }
        }
        if state.steering_mode.fresh(now, self.fresh).is_some() {
            let _ = self.outputs.steering_mode.publish(StringMsg {
                data: mode.name().to_ascii_lowercase(),
            });
        }
        if let (Some(out), Some(lights)) = (
            &self.outputs.turn_indicators,
            state.turn_indicators.fresh(now, self.fresh),
        ) {
            let _ = out.publish(TurnIndicatorsReport {
                stamp,
                report: map::turn_indicators_code(lights),
            });
        }
        if let (Some(out), Some(on)) = (
            &self.outputs.hazard_lights,
            state.hazard_lights.fresh(now, self.fresh),
        ) {
            let _ = out.publish(HazardLightsReport {
                stamp,
                report: map::hazard_lights_code(on),
            });
        }
        if let (Some(out), Some(level)) = (
            &self.outputs.degradation,
            state.degradation.fresh(now, self.fresh),
        ) {
            let reason = state.degradation_reason.fresh(now, self.fresh).flatten();
            let _ = out.publish(StringMsg {
                data: map::degradation_text(level, reason),
            });
        }
        self.last_report = Some(now);
    }

    /// Autoware's emergency: the emergency brake at the hardest the vehicle may brake and a
    /// stop, disengaged, while it holds (control_cmd and engage requests wait); when it ends
    /// the brake is released but the vehicle stays disengaged, as after an E-stop: driving
    /// again takes an engage.
    fn set_emergency(&mut self, ads: &mut AdsSide, now: Timestamp, emergency: bool) {
        if emergency == self.emergency {
            return;
        }
        self.emergency = emergency;
        (self.report)(VehicleEvent::Emergency(emergency));
        if !emergency {
            ads.release_brake();
            return;
        }
        ads.emergency_brake(now, self.limits.deceleration_m_s2);
        self.command = AdsCommand {
            velocity: 0.0,
            brake: 100.0,
            mode: ControlMode::Manual,
            ..self.command
        };
        if let Some((waiting, _, _)) = self.engage.take() {
            let why = Some("emergency_cmd".to_string());
            self.answer(waiting, control_mode::AUTONOMOUS, false, why);
        }
        self.commanding = true;
        self.send(ads, now);
    }

    fn begin_braking(&mut self, ads: &mut AdsSide, now: Timestamp) {
        (self.report)(VehicleEvent::Stopping);
        ads.safe_stop(now, self.limits.deceleration_m_s2);
        self.braking_until = Some(now.saturating_add(FINAL_BRAKING));
    }
}

/// f64 → f32 for a message field (the values are physical and far inside f32's range).
fn to_f32(value: f64) -> f32 {
    #[allow(clippy::cast_possible_truncation)]
    let narrowed = value as f32;
    narrowed
}

impl Hooks<AdsSide> for VehicleInterface<'_> {
    fn after_poll(&mut self, ads: &mut AdsSide, now: Timestamp) -> Flow {
        if let Some(until) = self.braking_until {
            return if now >= until {
                Flow::Stop
            } else {
                Flow::Continue
            };
        }
        if self.stop.load(Ordering::Relaxed) {
            self.begin_braking(ads, now);
            return Flow::Continue;
        }
        if let (Some(store), Some(table)) = (self.freshness.as_mut(), ads.wire().table()) {
            if let Err(e) = table.reserve_in(store) {
                // What is signed next could not be kept (a restart would reuse it): brake.
                (self.report)(VehicleEvent::Freshness(e.to_string()));
                self.begin_braking(ads, now);
                return Flow::Continue;
            }
        }
        self.take_inputs(ads, now);
        // While an engage waits, every command carries the request.
        if self.engage.is_some() {
            self.send(ads, now);
        }
        self.watch_engage(ads, now);
        if now >= self.next_report {
            self.publish_reports(ads, now);
            self.publish_diagnostics(ads, now);
            self.next_report = self
                .next_report
                .saturating_add(self.config.report_period)
                .max(now);
        }
        Flow::Continue
    }

    fn wake_at(&self) -> Option<Timestamp> {
        let engage = self.engage.map(|(_, _, deadline)| deadline);
        earliest([Some(self.next_report), engage, self.braking_until])
    }

    fn bus_lost(&mut self, _: &mut AdsSide, _: Timestamp, port: Port, error: &BusError) {
        let name = self
            .buses
            .iter()
            .find(|(p, _)| *p == port)
            .map_or("?".to_string(), |(_, n)| n.clone());
        (self.report)(VehicleEvent::BusLost(format!("{name}: {error}")));
        if !self.lost.iter().any(|(p, _)| *p == port) {
            self.lost.push((port, error.to_string()));
        }
    }
}

/// How often `/diagnostics` goes out when nothing changes.
const DIAGNOSTICS_PERIOD: Duration = Duration::from_secs(1);

/// The diagnostics of the vehicle (its state as reported: stale when it reports nothing) and
/// of each bus (lost with its error, or up).
fn diagnostics(
    state: &VehicleState,
    now: Timestamp,
    fresh: Duration,
    hardware_id: &str,
    buses: &[(Port, String)],
    lost: &[(Port, String)],
) -> Vec<DiagnosticStatus> {
    use bywire_vehicle::command::{DegradationLevel, EstopCode, WatchdogLevel};
    let value = |key: &str, value: String| KeyValue {
        key: key.into(),
        value,
    };
    let mode = state.mode.fresh(now, fresh);
    let watchdog = state.watchdog_level.fresh(now, fresh);
    let estop = state.estop_state.fresh(now, fresh);
    let degradation = state.degradation.fresh(now, fresh);
    let reason = state.degradation_reason.fresh(now, fresh).flatten();
    let driver = state.driver_override.fresh(now, fresh);
    let autonomous = mode == Some(ControlMode::Autonomous);
    let (level, message) = match (mode, watchdog, estop) {
        (None, _, _) => (
            DiagnosticStatus::STALE,
            "no state from the vehicle".to_string(),
        ),
        (_, _, Some(e)) if e != EstopCode::Normal => {
            (DiagnosticStatus::ERROR, format!("E-stop: {e}"))
        }
        _ if degradation == Some(DegradationLevel::SafeStop) => (
            DiagnosticStatus::ERROR,
            "degradation: safe stop".to_string(),
        ),
        (_, Some(WatchdogLevel::FullBraking), _) if autonomous => (
            DiagnosticStatus::ERROR,
            "watchdog: full braking".to_string(),
        ),
        (_, Some(w @ (WatchdogLevel::Holding | WatchdogLevel::Decelerating)), _) => {
            (DiagnosticStatus::WARN, format!("watchdog: {w}"))
        }
        _ if matches!(
            degradation,
            Some(DegradationLevel::Degraded | DegradationLevel::MinimalRisk)
        ) =>
        {
            let level = degradation.map_or(String::new(), |d| d.to_string());
            (DiagnosticStatus::WARN, format!("degradation: {level}"))
        }
        _ if driver == Some(true) => (DiagnosticStatus::WARN, "driver override".to_string()),
        (Some(m), _, _) => (DiagnosticStatus::OK, format!("mode: {m}")),
    };
    let or_unknown = |n: Option<String>| n.unwrap_or_else(|| "unknown".into());
    let mut values = vec![
        value("mode", or_unknown(mode.map(|m| m.to_string()))),
        value("watchdog", or_unknown(watchdog.map(|w| w.to_string()))),
        value("estop", or_unknown(estop.map(|e| e.to_string()))),
    ];
    if let Some(d) = degradation {
        values.push(value("degradation", d.to_string()));
        values.push(value(
            "degradation reason",
            reason.map_or("none".to_string(), |r| r.to_string()),
        ));
    }
    if let Some(driver) = driver {
        values.push(value("driver override", driver.to_string()));
    }
    let mut status = vec![DiagnosticStatus {
        level,
        name: "bywire: vehicle".into(),
        message,
        hardware_id: hardware_id.into(),
        values,
    }];
    for (port, name) in buses {
        let (level, message) = match lost.iter().find(|(p, _)| p == port) {
            Some((_, error)) => (DiagnosticStatus::ERROR, format!("lost: {error}")),
            None => (DiagnosticStatus::OK, "up".to_string()),
        };
        status.push(DiagnosticStatus {
            level,
            name: format!("bywire: bus {name}"),
            message,
            hardware_id: name.clone(),
            values: Vec::new(),
        });
    }
    status
}

/// The geometry a profile gives (`None`: the profile has no `[vehicle]`).
pub fn geometry(profile: &LoadedProfile) -> Option<Geometry> {
    let v = profile.profile.vehicle.as_ref()?;
    let four_wheel_steer = profile
        .profile
        .command
        .as_ref()
        .is_some_and(|c| !c.steering_mode.is_empty());
    Some(Geometry {
        wheelbase: v.wheelbase_m,
        track: v.track_m,
        wheel_diameter: v.wheel_diameter_m,
        four_wheel_steer,
    })
}

impl<'a> VehicleInterface<'a> {
    /// The interface for `profile` on `node`, and the ADS-side node it commands through `wire`
    /// (`redundant`: it sends on ports A and B). `stop` begins the final braking; `report`
    /// hears events.
    pub fn new(
        node: &mut RosNode,
        profile: &LoadedProfile,
        wire: Secured<ProfileWire>,
        redundant: bool,
        config: &VehicleInterfaceConfig,
        stop: &'a AtomicBool,
        report: &'a mut dyn FnMut(VehicleEvent),
    ) -> Result<(VehicleInterface<'a>, AdsSide), RosError> {
        let one = reliable(1);
        let command_roles = profile.profile.command.as_ref();
        let state_roles = profile.profile.state.as_ref();
        let inputs = Inputs {
            control: node.subscription(&config.control_cmd, &one)?,
            gear: node.subscription(&config.gear_cmd, &one)?,
            steering_mode: node.subscription(&config.steering_mode_cmd, &one)?,
            cmd_vel: node.subscription(&config.cmd_vel, &one)?,
            mode_request: node.server(
                &config.control_mode_request,
                "autoware_vehicle_msgs",
                "ControlModeCommand",
            )?,
            turn_indicators: match command_roles.and_then(|c| c.turn_indicators.as_ref()) {
                Some(_) => Some(node.subscription(&config.turn_indicators_cmd, &one)?),
                None => None,
            },
            hazard_lights: match command_roles.and_then(|c| c.hazard_lights.as_ref()) {
                Some(_) => Some(node.subscription(&config.hazard_lights_cmd, &one)?),
                None => None,
            },
            emergency: node.subscription(&config.emergency_cmd, &one)?,
        };
        let outputs = Outputs {
            steering: node.publisher(&config.steering_status, &one)?,
            velocity: node.publisher(&config.velocity_status, &one)?,
            gear: node.publisher(&config.gear_status, &one)?,
            control_mode: node.publisher(&config.control_mode, &one)?,
            joints: node.publisher(&config.joint_states, &one)?,
            steering_mode: node.publisher(&config.steering_mode_status, &one)?,
            turn_indicators: match state_roles.and_then(|s| s.turn_indicators.as_ref()) {
                Some(_) => Some(node.publisher(&config.turn_indicators_status, &one)?),
                None => None,
            },
            hazard_lights: match state_roles.and_then(|s| s.hazard_lights.as_ref()) {
                Some(_) => Some(node.publisher(&config.hazard_lights_status, &one)?),
                None => None,
            },
            degradation: match profile
                .profile
                .fail_operational
                .as_ref()
                .and_then(|f| f.report.as_ref())
            {
                Some(_) => Some(node.publisher(&config.degradation_status, &one)?),
                None => None,
            },
            diagnostics: node.publisher(&config.diagnostics, &reliable(10))?,
        };
        let mut ads_config = profile.ads_config();
        ads_config.redundant = redundant;
        let fresh = ads_config.feedback_timeout();
        let interface = VehicleInterface {
            inputs,
            outputs,
            config: config.clone(),
            geometry: geometry(profile),
            limits: profile.profile.limits,
            fresh,
            cycle: ads_config.cycle,
            command: AdsCommand::default(),
            steering_mode: SteeringMode::Normal,
            commanding: false,
            engage: None,
            next_report: Timestamp::ZERO,
            last_report: None,
            drive_rotation: [0.0; 4],
            stop,
            braking_until: None,
            buses: Vec::new(),
            report,
            freshness: None,
            lost: Vec::new(),
            hardware_id: profile.profile.name.clone(),
            last_diagnostics: None,
            emergency: false,
        };
        Ok((interface, Ads::with_wire(ads_config, wire)))
    }

    /// A poll on which every input becomes readable when it has something.
    pub fn readiness(&mut self) -> Result<mio1::Poll, RosError> {
        let io = |e: std::io::Error| RosError::Create(format!("polling the inputs: {e}"));
        let poll = mio1::Poll::new().map_err(io)?;
        let readable = mio1::Interest::READABLE;
        let registry = poll.registry();
        let i = &mut self.inputs;
        registry
            .register(&mut i.control, mio1::Token(0), readable)
            .map_err(io)?;
        registry
            .register(&mut i.gear, mio1::Token(1), readable)
            .map_err(io)?;
        registry
            .register(&mut i.steering_mode, mio1::Token(2), readable)
            .map_err(io)?;
        registry
            .register(&mut i.cmd_vel, mio1::Token(3), readable)
            .map_err(io)?;
        registry
            .register(&mut i.mode_request, mio1::Token(4), readable)
            .map_err(io)?;
        if let Some(lights) = i.turn_indicators.as_mut() {
            registry
                .register(lights, mio1::Token(5), readable)
                .map_err(io)?;
        }
        if let Some(lights) = i.hazard_lights.as_mut() {
            registry
                .register(lights, mio1::Token(6), readable)
                .map_err(io)?;
        }
        registry
            .register(&mut i.emergency, mio1::Token(7), readable)
            .map_err(io)?;
        Ok(poll)
    }
}

/// Run the interface for `profile` through its wire (secured when the profile declares
/// `[secoc]`, its freshness kept in the store when one is given) on `buses` (port A, and B for
/// a redundant pair) until `stop`, then brake for a second. Fails when every bus is lost.
pub fn run(
    node: &mut RosNode,
    profile: &LoadedProfile,
    (wire, freshness): (Secured<ProfileWire>, Option<FreshnessStore>),
    buses: Vec<(Port, String, Box<dyn Bus>)>,
    config: &VehicleInterfaceConfig,
    stop: &AtomicBool,
    report: &mut dyn FnMut(VehicleEvent),
) -> Result<(), RosError> {
    let redundant = buses.len() > 1;
    let (mut interface, mut ads) =
        VehicleInterface::new(node, profile, wire, redundant, config, stop, report)?;
    interface.freshness = freshness;
    let poll = interface.readiness()?;
    interface.buses = buses.iter().map(|(p, n, _)| (*p, n.clone())).collect();
    let mut runner = Runner::new(buses.into_iter().map(|(p, _, b)| (p, b)).collect());
    let done = Arc::new(AtomicBool::new(false));
    let waiter = wake_on_readiness(poll, runner.waker(), Arc::clone(&done));
    // The runner's own stop flag stays clear: the interface's stop brakes first.
    let never = AtomicBool::new(false);
    let result = runner.run(&mut ads, &never, None, &mut interface);
    done.store(true, Ordering::Relaxed);
    let _ = waiter.join();
    result
        .map(|_| ())
        .map_err(|e| RosError::Create(format!("every bus is lost (last: {e})")))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]

    use super::*;
    use bywire_vehicle::ads::Field;
    use bywire_vehicle::command::{DegradationLevel, EstopCode, FaultClass, WatchdogLevel};

    fn at<T>(value: T) -> Field<T> {
        Field {
            value: Some(value),
            at: Some(Timestamp::from_millis(1_000)),
        }
    }

    fn vehicle(
        state: &VehicleState,
        now_ms: u64,
        lost: &[(Port, String)],
    ) -> Vec<DiagnosticStatus> {
        let buses = [(Port(0), "can0".to_string()), (Port(1), "can1".to_string())];
        diagnostics(
            state,
            Timestamp::from_millis(now_ms),
            Duration::from_millis(100),
            "tug",
            &buses,
            lost,
        )
    }

    #[test]
    fn diagnostics_say_stale_ok_warn_and_error_as_the_vehicle_reports() {
        let mut state = VehicleState::default();
        let s = vehicle(&state, 1_000, &[]);
        assert_eq!(s[0].level, DiagnosticStatus::STALE);
        assert_eq!(
            (s[1].level, s[1].name.as_str()),
            (DiagnosticStatus::OK, "bywire: bus can0")
        );
        state.mode = at(ControlMode::Autonomous);
        state.watchdog_level = at(WatchdogLevel::Normal);
        state.estop_state = at(EstopCode::Normal);
        let s = vehicle(&state, 1_050, &[]);
        assert_eq!(
            (s[0].level, s[0].message.as_str()),
            (DiagnosticStatus::OK, "mode: autonomous")
        );
        assert!(s[0].values.contains(&KeyValue {
            key: "watchdog".into(),
            value: "normal".into()
        }));
        // Old news is no news.
        assert_eq!(
            vehicle(&state, 1_200, &[])[0].level,
            DiagnosticStatus::STALE
        );
        state.watchdog_level = at(WatchdogLevel::Decelerating);
        assert_eq!(
            vehicle(&state, 1_050, &[])[0].message,
            "watchdog: decelerating"
        );
        state.watchdog_level = at(WatchdogLevel::FullBraking);
        assert_eq!(
            vehicle(&state, 1_050, &[])[0].level,
            DiagnosticStatus::ERROR
        );
        state.watchdog_level = at(WatchdogLevel::Normal);
        state.degradation = at(DegradationLevel::MinimalRisk);
        state.degradation_reason = at(Some(FaultClass::ActuatorBackup));
        let s = vehicle(&state, 1_050, &[]);
        assert_eq!(
            (s[0].level, s[0].message.as_str()),
            (DiagnosticStatus::WARN, "degradation: minimal-risk")
        );
        assert!(s[0].values.iter().any(|v| v.value == "actuator-backup"));
        state.estop_state = at(EstopCode::Stopped);
        assert_eq!(vehicle(&state, 1_050, &[])[0].message, "E-stop: stopped");
        // A bus lost: its status says why; the other is up.
        let s = vehicle(&state, 1_050, &[(Port(1), "bus-off".into())]);
        assert_eq!(
            (s[2].level, s[2].message.as_str()),
            (DiagnosticStatus::ERROR, "lost: bus-off")
        );
        assert_eq!(s[1].level, DiagnosticStatus::OK);
    }
}
