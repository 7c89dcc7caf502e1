//! A profile's roles found in its DBC once, when the profile loads: each role's message (its
//! place among the DBC's messages) and signals (their places in the message). Everything that
//! reads a vehicle by role (the profile's wire, tools that name its signals) takes these
//! places; a name the DBC does not have is refused here, and only here, naming the key.

use alloc::format;
use alloc::string::String;

use bywire_dbc::{Database, Message};

use crate::profile::{Profile, ProfileError, WheelSignals};
use bywire_core::FileError;

/// The command message's roles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CommandBindings {
    /// The message.
    pub message: usize,
    /// Steering angle setpoint.
    pub steering: usize,
    /// Speed setpoint.
    pub velocity: usize,
    /// Brake setpoint.
    pub brake: usize,
    /// Gear.
    pub gear: usize,
    /// Control-mode request.
    pub control_mode: usize,
    /// Steering mode.
    pub steering_mode: usize,
    /// Re-engage request.
    pub engage: usize,
    /// Operator reset.
    pub operator_reset: usize,
    /// Rolling counter.
    pub counter: usize,
    /// Checksum.
    pub checksum: usize,
    /// Turn-indicator request.
    pub turn_indicators: Option<usize>,
    /// Hazard-lights request.
    pub hazard_lights: Option<usize>,
}

/// The state message's roles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StateBindings {
    /// The message.
    pub message: usize,
    /// Steering angle.
    pub steering: usize,
    /// Speed.
    pub velocity: usize,
    /// Control mode.
    pub control_mode: usize,
    /// Steering mode.
    pub steering_mode: usize,
    /// The command counter echoed.
    pub heartbeat_echo: usize,
    /// Rolling counter.
    pub counter: usize,
    /// Checksum.
    pub checksum: usize,
    /// Watchdog level.
    pub watchdog_level: Option<usize>,
    /// E-stop state.
    pub estop_state: Option<usize>,
    /// Warning flag.
    pub warning: Option<usize>,
    /// Driver override flag.
    pub driver_override: Option<usize>,
    /// Gear in use.
    pub gear: Option<usize>,
    /// Steering actuator enabled.
    pub steering_enabled: Option<usize>,
    /// Turn indicators.
    pub turn_indicators: Option<usize>,
    /// Hazard lights.
    pub hazard_lights: Option<usize>,
}

/// Four wheels' signals (FL, FR, RL, RR) in one message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WheelBindings {
    /// The message.
    pub message: usize,
    /// The signals, FL, FR, RL, RR.
    pub signals: [usize; 4],
}

/// The IMU message's roles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImuBindings {
    /// The message.
    pub message: usize,
    /// Yaw rate.
    pub yaw_rate: usize,
    /// Longitudinal acceleration.
    pub accel_x: Option<usize>,
    /// Lateral acceleration.
    pub accel_y: Option<usize>,
}

/// The battery message's roles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BatteryBindings {
    /// The message.
    pub message: usize,
    /// Voltage.
    pub voltage: usize,
    /// Current.
    pub current: Option<usize>,
    /// State of charge.
    pub soc: Option<usize>,
}

/// A message with one request signal (the E-stop).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RequestBindings {
    /// The message.
    pub message: usize,
    /// The request.
    pub request: usize,
}

/// The emergency brake's roles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EmergencyBrakeBindings {
    /// The message.
    pub message: usize,
    /// The request.
    pub request: usize,
    /// The deceleration asked.
    pub deceleration: usize,
}

/// Every role a profile names, found in its DBC.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Bindings {
    /// `[command]`.
    pub command: Option<CommandBindings>,
    /// `[state]`.
    pub state: Option<StateBindings>,
    /// `[wheel_speeds]`.
    pub wheel_speeds: Option<WheelBindings>,
    /// `[wheel_angles]`.
    pub wheel_angles: Option<WheelBindings>,
    /// `[imu]`.
    pub imu: Option<ImuBindings>,
    /// `[battery]`.
    pub battery: Option<BatteryBindings>,
    /// `[estop]`.
    pub estop: Option<RequestBindings>,
    /// `[emergency_brake]`.
    pub emergency_brake: Option<EmergencyBrakeBindings>,
}

/// Finds a profile's names in its DBC, each error naming the profile's key.
struct Finder<'a> {
    file: &'a str,
    db: &'a Database,
}

impl Finder<'_> {
    fn invalid(&self, key: &str, reason: String) -> ProfileError {
        FileError::invalid(self.file, key, reason).into()
    }

    fn message(&self, key: &str, name: &str) -> Result<(usize, &Message), ProfileError> {
        self.db
            .messages
            .iter()
            .enumerate()
            .find(|(_, m)| m.name == name)
            .ok_or_else(|| self.invalid(key, format!("no message '{name}' in the DBC")))
    }

    fn signal(&self, message: &Message, key: &str, name: &str) -> Result<usize, ProfileError> {
        message
            .signals
            .iter()
            .position(|s| s.name == name)
            .ok_or_else(|| {
                self.invalid(
                    key,
                    format!("no signal '{name}' in message '{}'", message.name),
                )
            })
    }

    fn optional(
        &self,
        message: &Message,
        key: &str,
        name: &Option<String>,
    ) -> Result<Option<usize>, ProfileError> {
        name.as_deref()
            .map(|n| self.signal(message, key, n))
            .transpose()
    }

    fn command(&self, p: &Profile) -> Result<Option<CommandBindings>, ProfileError> {
        let Some(c) = &p.command else {
            return Ok(None);
        };
        let (index, m) = self.message("command.message", &c.message)?;
        let signal = |role: &str, name: &str| self.signal(m, &format!("command.{role}"), name);
        let optional =
            |role: &str, name: &Option<String>| self.optional(m, &format!("command.{role}"), name);
        Ok(Some(CommandBindings {
            message: index,
            steering: signal("steering", &c.steering)?,
            velocity: signal("velocity", &c.velocity)?,
            brake: signal("brake", &c.brake)?,
            gear: signal("gear", &c.gear)?,
            control_mode: signal("control_mode", &c.control_mode)?,
            steering_mode: signal("steering_mode", &c.steering_mode)?,
            engage: signal("engage", &c.engage)?,
            operator_reset: signal("operator_reset", &c.operator_reset)?,
            counter: signal("counter", &c.counter)?,
            checksum: signal("checksum", &c.checksum)?,
            turn_indicators: optional("turn_indicators", &c.turn_indicators)?,
            hazard_lights: optional("hazard_lights", &c.hazard_lights)?,
        }))
    }

    fn state(&self, p: &Profile) -> Result<Option<StateBindings>, ProfileError> {
        let Some(s) = &p.state else {
            return Ok(None);
        };
        let (index, m) = self.message("state.message", &s.message)?;
        let signal = |role: &str, name: &str| self.signal(m, &format!("state.{role}"), name);
        let optional =
            |role: &str, name: &Option<String>| self.optional(m, &format!("state.{role}"), name);
        Ok(Some(StateBindings {
            message: index,
            steering: signal("steering", &s.steering)?,
            velocity: signal("velocity", &s.velocity)?,
            control_mode: signal("control_mode", &s.control_mode)?,
            steering_mode: signal("steering_mode", &s.steering_mode)?,
            heartbeat_echo: signal("heartbeat_echo", &s.heartbeat_echo)?,
            counter: signal("counter", &s.counter)?,
            checksum: signal("checksum", &s.checksum)?,
            watchdog_level: optional("watchdog_level", &s.watchdog_level)?,
            estop_state: optional("estop_state", &s.estop_state)?,
            warning: optional("warning", &s.warning)?,
            driver_override: optional("driver_override", &s.driver_override)?,
            gear: optional("gear", &s.gear)?,
            steering_enabled: optional("steering_enabled", &s.steering_enabled)?,
            turn_indicators: optional("turn_indicators", &s.turn_indicators)?,
            hazard_lights: optional("hazard_lights", &s.hazard_lights)?,
        }))
    }

    fn wheels(
        &self,
        role: &str,
        wheels: &Option<WheelSignals>,
    ) -> Result<Option<WheelBindings>, ProfileError> {
        let Some(w) = wheels else {
            return Ok(None);
        };
        let (index, m) = self.message(&format!("{role}.message"), &w.message)?;
        let [fl, fr, rl, rr] = w.signals.as_slice() else {
            return Err(self.invalid(
                &format!("{role}.signals"),
                "four signals: FL, FR, RL, RR".into(),
            ));
        };
        let mut signals = [0; 4];
        for (i, (slot, name)) in signals.iter_mut().zip([fl, fr, rl, rr]).enumerate() {
            *slot = self.signal(m, &format!("{role}.signals[{i}]"), name)?;
        }
        Ok(Some(WheelBindings {
            message: index,
            signals,
        }))
    }

    fn bind(&self, p: &Profile) -> Result<Bindings, ProfileError> {
        let imu = match &p.imu {
            None => None,
            Some(imu) => {
                let (index, m) = self.message("imu.message", &imu.message)?;
                Some(ImuBindings {
                    message: index,
                    yaw_rate: self.signal(m, "imu.yaw_rate", &imu.yaw_rate)?,
                    accel_x: self.optional(m, "imu.accel_x", &imu.accel_x)?,
                    accel_y: self.optional(m, "imu.accel_y", &imu.accel_y)?,
                })
            }
        };
        let battery = match &p.battery {
            None => None,
            Some(b) => {
                let (index, m) = self.message("battery.message", &b.message)?;
                Some(BatteryBindings {
                    message: index,
                    voltage: self.signal(m, "battery.voltage", &b.voltage)?,
                    current: self.optional(m, "battery.current", &b.current)?,
                    soc: self.optional(m, "battery.soc", &b.soc)?,
                })
            }
        };
        let estop = match &p.estop {
            None => None,
            Some(e) => {
                let (index, m) = self.message("estop.message", &e.message)?;
                Some(RequestBindings {
                    message: index,
                    request: self.signal(m, "estop.request", &e.request)?,
                })
            }
        };
        let emergency_brake = match &p.emergency_brake {
            None => None,
            Some(b) => {
                let (index, m) = self.message("emergency_brake.message", &b.message)?;
                Some(EmergencyBrakeBindings {
                    message: index,
                    request: self.signal(m, "emergency_brake.request", &b.request)?,
                    deceleration: self.signal(
                        m,
                        "emergency_brake.deceleration",
                        &b.deceleration,
                    )?,
                })
            }
        };
        Ok(Bindings {
            command: self.command(p)?,
            state: self.state(p)?,
            wheel_speeds: self.wheels("wheel_speeds", &p.wheel_speeds)?,
            wheel_angles: self.wheels("wheel_angles", &p.wheel_angles)?,
            imu,
            battery,
            estop,
            emergency_brake,
        })
    }
}

/// Every role of `profile` (the file `file`) found in `db`; the first name it does not have is
/// refused, naming the key (`command.steering`) and what is missing.
pub(crate) fn bind(profile: &Profile, db: &Database, file: &str) -> Result<Bindings, ProfileError> {
    Finder { file, db }.bind(profile)
}
