//! Vehicle profiles: a TOML file that says which messages and signals of a vehicle's DBC play
//! which role, with the rates, timeouts, limits, enum values and watchdog cascade. Loading
//! checks everything against the DBC and names the key at fault.
//!
//! `autoware-can` and `shuttle` (another vehicle's layout) ship here ([`Profile::builtin`]); a vehicle's crate ships its own profile.

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Duration;

use bywire_core::num::Short;
use bywire_core::FileError;
use bywire_dbc::{Database, Message};
use serde::Deserialize;

use crate::ads::{AdsConfig, WheelGeometry};
use crate::bindings::{
    ActuatorPairBindings, ActuatorStatusBinding, BatteryBindings, Bindings, CommandBindings,
    EmergencyBrakeBindings, FailOperationalBindings, ImuBindings, MeasuredBinding, ReportBindings,
    RequestBindings, SignalBinding, StateBindings, StatusBinding, VotedBindings, WheelBindings,
};
use crate::command::{ControlCommand, ControlMode};
use crate::fail_operational::{ActuatorRoles, FailOperationalRoles, MeasuredRoles, SignalRef};
use crate::supervisor::{Cascade, SupervisorConfig};

/// Why a profile did not load.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ProfileError {
    /// Not TOML, or not the profile's shape (the message has the line, column and key), or a
    /// key's value is wrong (the key dotted: `command.steering`).
    #[error(transparent)]
    File(#[from] FileError),
    /// The DBC could not be read or parsed.
    #[error("{file}: dbc: {reason}")]
    Dbc {
        /// The profile.
        file: String,
        /// What went wrong.
        reason: String,
    },
    /// No such built-in profile.
    #[error(
        "no built-in profile '{0}' (reference-tug, reference-tug-redundant, autoware-can, shuttle)"
    )]
    UnknownBuiltin(String),
}

/// The command message's roles.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CommandRoles {
    /// The message.
    pub message: String,
    /// Send period, ms.
    pub period_ms: u64,
    /// Age after which the ADS side replaces a command by a controlled stop, ms.
    pub staleness_ms: u64,
    /// Steering angle setpoint signal.
    pub steering: String,
    /// Speed setpoint signal.
    pub velocity: String,
    /// Brake setpoint signal.
    pub brake: String,
    /// Gear signal.
    pub gear: String,
    /// Control-mode request signal.
    pub control_mode: String,
    /// Steering-mode signal.
    pub steering_mode: String,
    /// Re-engage request signal.
    pub engage: String,
    /// Operator-reset signal.
    pub operator_reset: String,
    /// Rolling counter signal.
    pub counter: String,
    /// Checksum signal.
    pub checksum: String,
    /// Checksum algorithm (`crc8_sae_j1850`, `crc8_h2f`, `xor8`, `sum8`).
    pub checksum_algorithm: String,
    /// Turn-indicator request signal (optional).
    #[serde(default)]
    pub turn_indicators: Option<String>,
    /// Hazard-lights request signal (optional).
    #[serde(default)]
    pub hazard_lights: Option<String>,
}

impl CommandRoles {
    /// The checksum algorithm named (`None`: a name no algorithm has; a loaded profile's
    /// names one).
    pub fn algorithm(&self) -> Option<bywire_dbc::e2e::ChecksumAlgorithm> {
        bywire_dbc::e2e::ChecksumAlgorithm::from_name(&self.checksum_algorithm)
    }
}

/// The state (feedback) message's roles.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StateRoles {
    /// The message.
    pub message: String,
    /// Its period, ms.
    pub period_ms: u64,
    /// Periods after which it is invalid.
    pub timeout_cycles: u32,
    /// Actual steering angle.
    pub steering: String,
    /// Actual speed.
    pub velocity: String,
    /// Reported control mode.
    pub control_mode: String,
    /// Reported steering mode.
    pub steering_mode: String,
    /// Heartbeat echo.
    pub heartbeat_echo: String,
    /// The echo must match one of this many recent commands.
    pub echo_window: u8,
    /// Rolling counter.
    pub counter: String,
    /// Checksum.
    pub checksum: String,
    /// Watchdog level (optional).
    #[serde(default)]
    pub watchdog_level: Option<String>,
    /// E-stop latch state (optional).
    #[serde(default)]
    pub estop_state: Option<String>,
    /// Warning flag (optional).
    #[serde(default)]
    pub warning: Option<String>,
    /// Driver override flag (optional).
    #[serde(default)]
    pub driver_override: Option<String>,
    /// Gear in use (optional).
    #[serde(default)]
    pub gear: Option<String>,
    /// Steering actuator enabled (optional).
    #[serde(default)]
    pub steering_enabled: Option<String>,
    /// Turn indicators as they are (optional).
    #[serde(default)]
    pub turn_indicators: Option<String>,
    /// Hazard lights as they are (optional).
    #[serde(default)]
    pub hazard_lights: Option<String>,
}

/// Per-wheel feedback: wheel speeds (m/s) or wheel angles (degrees).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WheelSignals {
    /// The message.
    pub message: String,
    /// FL, FR, RL, RR.
    pub signals: Vec<String>,
}

/// The IMU's message (observations for datasets and logs).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImuRoles {
    /// The message.
    pub message: String,
    /// Yaw rate (deg/s or rad/s, as the DBC's unit says).
    pub yaw_rate: String,
    /// Longitudinal acceleration.
    #[serde(default)]
    pub accel_x: Option<String>,
    /// Lateral acceleration.
    #[serde(default)]
    pub accel_y: Option<String>,
}

/// The battery's message (observations for datasets and logs).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BatteryRoles {
    /// The message.
    pub message: String,
    /// Pack voltage.
    pub voltage: String,
    /// Pack current.
    #[serde(default)]
    pub current: Option<String>,
    /// State of charge.
    #[serde(default)]
    pub soc: Option<String>,
}

/// The E-stop message.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EstopRoles {
    /// The message.
    pub message: String,
    /// The request signal.
    pub request: String,
}

/// The emergency-brake message and its burst.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EmergencyBrakeRoles {
    /// The message.
    pub message: String,
    /// Frames in the burst.
    pub burst_frames: u32,
    /// Spacing in the burst, ms.
    pub burst_spacing_ms: u64,
    /// Repeat period after it, ms.
    pub repeat_ms: u64,
    /// The brake-request signal.
    #[serde(default = "default_brake_request")]
    pub request: String,
    /// The deceleration signal.
    #[serde(default = "default_brake_deceleration")]
    pub deceleration: String,
}

fn default_brake_request() -> String {
    "BrakeRequest".to_string()
}

fn default_brake_deceleration() -> String {
    "Deceleration".to_string()
}

/// Physical limits.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Limits {
    /// Steering angle, degrees.
    pub steering_deg: f64,
    /// Steering rate, degrees per second.
    pub steering_rate_deg_s: f64,
    /// Speed, m/s.
    pub speed_m_s: f64,
    /// Deceleration, m/s².
    pub deceleration_m_s2: f64,
}

impl Limits {
    /// Refuse a command beyond the vehicle's limits, naming the field: a value the vehicle
    /// would refuse (or a tool would clamp) is never sent as something else.
    pub fn check(&self, c: &ControlCommand) -> Result<(), String> {
        let within = |value: f64, limit: f64| value.is_finite() && value.abs() <= limit;
        if !within(c.steering, self.steering_deg) {
            return Err(format!(
                "steering {}: beyond ±{} degrees",
                Short(c.steering),
                self.steering_deg
            ));
        }
        if !within(c.velocity, self.speed_m_s) {
            return Err(format!(
                "velocity {}: beyond ±{} m/s",
                Short(c.velocity),
                self.speed_m_s
            ));
        }
        if !(c.brake.is_finite() && (0.0..=100.0).contains(&c.brake)) {
            return Err(format!("brake {}: not within 0–100 %", Short(c.brake)));
        }
        Ok(())
    }

    /// What the ADS side sends for `command`, or why it sends nothing: a brake beyond 100 %
    /// taken as 100 % (with the warning), the E-stop mode refused (the vehicle reports it; a
    /// stop is asked for with the emergency brake), every setpoint within the limits.
    pub fn admit(
        &self,
        command: ControlCommand,
    ) -> Result<(ControlCommand, Option<String>), String> {
        let brake = self.brake_request(command.brake)?;
        if command.mode == ControlMode::Estop {
            return Err(
                "mode 'estop' is the vehicle's to report, not to request (send emergency_brake)"
                    .to_string(),
            );
        }
        let taken = ControlCommand {
            brake: brake.value,
            ..command
        };
        self.check(&taken)?;
        Ok((taken, brake.warning))
    }

    /// A brake request, %: one beyond 100 % is a request to brake as hard as the vehicle can,
    /// so it is taken as 100 % with a warning; one below 0 % or not a number is refused.
    pub fn brake_request(&self, brake: f64) -> Result<Saturated, String> {
        if brake.is_nan() || brake < 0.0 {
            return Err(format!("brake {}: not within 0–100 %", Short(brake)));
        }
        Ok(Saturated::at_most(brake, 100.0, "brake", "%"))
    }

    /// An emergency-brake deceleration, m/s²: one beyond the vehicle's largest is a request to
    /// brake as hard as it can, so it is taken as the largest with a warning; zero, a negative
    /// value or not a number asks for no braking the vehicle can do, and is refused.
    pub fn emergency_deceleration(&self, deceleration: f64) -> Result<Saturated, String> {
        if deceleration.is_nan() || deceleration <= 0.0 {
            return Err(format!(
                "emergency_brake {}: a deceleration above 0 m/s² is needed (this vehicle \
                 brakes at up to {} m/s²)",
                Short(deceleration),
                self.deceleration_m_s2
            ));
        }
        Ok(Saturated::at_most(
            deceleration,
            self.deceleration_m_s2,
            "emergency_brake",
            "m/s²",
        ))
    }
}

/// A stop or brake request as the vehicle can carry it out, and the warning to give when it
/// asked for more.
#[derive(Debug, Clone, PartialEq)]
pub struct Saturated {
    /// The value to command.
    pub value: f64,
    /// Set when the request was beyond what the vehicle can do and was taken as its most.
    pub warning: Option<String>,
}

impl Saturated {
    fn at_most(requested: f64, most: f64, field: &str, unit: &str) -> Saturated {
        if requested > most {
            Saturated {
                value: most,
                warning: Some(format!(
                    "{field} {}: beyond this vehicle's {most} {unit}, braking as hard as it can \
                     ({most} {unit})",
                    Short(requested)
                )),
            }
        } else {
            Saturated {
                value: requested,
                warning: None,
            }
        }
    }
}

/// The watchdog cascade.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WatchdogRoles {
    /// Missed cycles that still hold.
    pub hold_cycles: u32,
    /// Missed cycles that still decelerate under control.
    pub decelerate_cycles: u32,
    /// Valid commands before a re-engage is accepted.
    pub recovery_run: u32,
    /// Controlled deceleration, m/s².
    pub controlled_deceleration_m_s2: f64,
}

/// Driver takeover thresholds.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Takeover {
    /// Steering-wheel torque, N·m.
    pub steering_torque_nm: f64,
    /// Pedal travel, 0–1.
    pub pedal: f64,
}

/// Geometry and drive train.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Geometry {
    /// Wheelbase, m.
    pub wheelbase_m: f64,
    /// Track, m.
    pub track_m: f64,
    /// Wheel diameter, m.
    pub wheel_diameter_m: f64,
    /// Motor revolutions per wheel revolution.
    pub gear_ratio: f64,
}

/// The `autoware-can` output's messages.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AutowareRoles {
    /// Angle and rate message.
    pub steering: String,
    /// Velocity and acceleration message.
    pub velocity: String,
    /// Status message.
    pub status: String,
    /// Send period, ms.
    pub period_ms: u64,
    /// `dds-only`, `can-only` or `dds-and-can`.
    pub output: String,
}

/// Authenticated messages (AUTOSAR SecOC, see [`crate::secured`] with the `secoc` feature):
/// the messages as the DBC describes them (8 bytes, counter and CRC) become the authentic
/// payload of a CAN FD frame followed by the freshness and MAC bits.
///
/// ```toml
/// [secoc]
/// messages = ["AdsToVehicle_Control", "EmergencyBrake", "EmergencyStop", "VehicleToAds_State"]
/// profile = "24Bit-CMAC-8Bit-FV"   # or fv_length, fv_tx_length, mac_tx_length (bits)
/// key_id = 1                        # the key's id in the key file given at run time
/// window = 1024                     # freshness values accepted ahead of the last
/// sync_id = 0x0F0                   # the freshness-sync message (optional)
/// ```
///
/// Each message's data ID is its identifier's low 16 bits. A build without the `secoc`
/// feature refuses such a profile, and a key file without the key refuses to start: nothing
/// declared secured is ever sent or read unauthenticated.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SecOcRoles {
    /// The messages secured, by name.
    pub messages: Vec<String>,
    /// An AUTOSAR profile by name, or the three lengths.
    #[serde(default)]
    pub profile: Option<String>,
    /// SecOCFreshnessValueLength, bits.
    #[serde(default)]
    pub fv_length: Option<u32>,
    /// SecOCFreshnessValueTxLength, bits.
    #[serde(default)]
    pub fv_tx_length: Option<u32>,
    /// SecOCAuthInfoTxLength, bits.
    #[serde(default)]
    pub mac_tx_length: Option<u32>,
    /// The key's id in the key file.
    pub key_id: u32,
    /// How far ahead of the last accepted freshness value a new one may be.
    #[serde(default = "default_window")]
    pub window: u64,
    /// The freshness-sync message's 11-bit identifier.
    #[serde(default)]
    pub sync_id: Option<u32>,
}

fn default_window() -> u64 {
    1024
}

/// A vehicle profile.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Profile {
    /// Its name.
    pub name: String,
    /// The DBC, relative to the profile file.
    pub dbc: String,
    /// Bus bitrate, bit/s.
    pub bitrate: u32,
    /// The command message (a vehicle interface).
    pub command: Option<CommandRoles>,
    /// The state message.
    pub state: Option<StateRoles>,
    /// Wheel speeds.
    pub wheel_speeds: Option<WheelSignals>,
    /// Wheel angles (four-wheel-steered vehicles).
    pub wheel_angles: Option<WheelSignals>,
    /// The IMU.
    #[serde(default)]
    pub imu: Option<ImuRoles>,
    /// The battery.
    #[serde(default)]
    pub battery: Option<BatteryRoles>,
    /// E-stop.
    pub estop: Option<EstopRoles>,
    /// Emergency brake.
    pub emergency_brake: Option<EmergencyBrakeRoles>,
    /// Enum mappings: role → name → raw value.
    #[serde(default)]
    pub enums: BTreeMap<String, BTreeMap<String, u64>>,
    /// Limits.
    pub limits: Limits,
    /// Watchdog cascade.
    pub watchdog: Option<WatchdogRoles>,
    /// Takeover thresholds.
    pub takeover: Option<Takeover>,
    /// Geometry.
    pub vehicle: Option<Geometry>,
    /// Autoware output.
    pub autoware: Option<AutowareRoles>,
    /// Authenticated messages.
    #[serde(default)]
    pub secoc: Option<SecOcRoles>,
    /// Redundancy and degradation levels (none: fail-safe only).
    #[serde(default)]
    pub fail_operational: Option<FailOperationalRoles>,
}

/// A profile checked against its DBC.
#[derive(Debug, Clone)]
pub struct LoadedProfile {
    /// The profile.
    pub profile: Profile,
    /// Its DBC.
    pub database: Database,
    /// Its roles, found in its DBC.
    pub bindings: Bindings,
}

/// The profiles this crate ships, with their DBCs (a vehicle's crate ships its own: the
/// reference tug's is `bywire_tug::builtin`).
const BUILTIN: [(&str, &str, &str); 2] = [
    (
        "autoware-can",
        include_str!("../profiles/autoware-can.toml"),
        crate::autoware::DBC,
    ),
    // Not the reference tug: another vehicle's layout (big-endian setpoints, 8-bit counters,
    // XOR checksums, its own enum numbers, a single steered axis with fail-operational
    // steering), for campaigns and fuzzing over a second profile.
    (
        "shuttle",
        include_str!("../profiles/shuttle.toml"),
        include_str!("../profiles/shuttle.dbc"),
    ),
];

impl Profile {
    /// A shipped profile by name, with its shipped DBC.
    pub fn builtin(name: &str) -> Result<LoadedProfile, ProfileError> {
        let (_, text, dbc) = BUILTIN
            .iter()
            .find(|(n, _, _)| *n == name)
            .ok_or_else(|| ProfileError::UnknownBuiltin(name.to_string()))?;
        Self::parse(name, text, |_| Ok((*dbc).to_string()))
    }

    /// A profile file; its DBC is read relative to it.
    pub fn load(path: &Path) -> Result<LoadedProfile, ProfileError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| FileError::syntax(&file, e))?;
        let dir = path.parent().unwrap_or(Path::new("."));
        Self::parse(&file, &text, |dbc| {
            std::fs::read_to_string(dir.join(dbc)).map_err(|e| format!("{dbc}: {e}"))
        })
    }

    /// A profile from text; `read_dbc` fetches the DBC it names.
    pub fn parse(
        file: &str,
        text: &str,
        read_dbc: impl FnOnce(&str) -> Result<String, String>,
    ) -> Result<LoadedProfile, ProfileError> {
        let profile: Profile = toml::from_str(text)
            .map_err(|e| FileError::syntax(file, e.to_string().trim_end().replace('\n', " ")))?;
        let dbc_error = |reason: String| ProfileError::Dbc {
            file: file.to_string(),
            reason,
        };
        let dbc_text = read_dbc(&profile.dbc).map_err(dbc_error)?;
        let format = bywire_dbc::Format::of_file(
            None,
            std::path::Path::new(&profile.dbc),
            dbc_text.as_bytes(),
        );
        let (database, _) =
            bywire_dbc::format::load(dbc_text.as_bytes(), format, bywire_dbc::Mode::Lenient)
                .map_err(|e| dbc_error(format!("{}: {e}", profile.dbc)))?;
        let bindings = bind(&profile, &database, file)?;
        Checker {
            file,
            db: &database,
        }
        .check(&profile, &bindings)?;
        Ok(LoadedProfile {
            profile,
            database,
            bindings,
        })
    }
}

/// The finding of a profile's names in its DBC: each name's place, each error naming the key.
impl Checker<'_> {
    fn message_at(&self, key: &str, name: &str) -> Result<(usize, &Message), ProfileError> {
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

    fn bind_command(&self, p: &Profile) -> Result<Option<CommandBindings>, ProfileError> {
        let Some(c) = &p.command else {
            return Ok(None);
        };
        let (index, m) = self.message_at("command.message", &c.message)?;
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

    fn bind_state(&self, p: &Profile) -> Result<Option<StateBindings>, ProfileError> {
        let Some(s) = &p.state else {
            return Ok(None);
        };
        let (index, m) = self.message_at("state.message", &s.message)?;
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

    fn bind_wheels(
        &self,
        role: &str,
        wheels: &Option<WheelSignals>,
    ) -> Result<Option<WheelBindings>, ProfileError> {
        let Some(w) = wheels else {
            return Ok(None);
        };
        let (index, m) = self.message_at(&format!("{role}.message"), &w.message)?;
        let [fl, fr, rl, rr] = w.signals.as_slice() else {
            return Err(self.invalid(&format!("{role}.signals"), "four signals: FL, FR, RL, RR"));
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

    fn signal_ref(&self, key: &str, r: &SignalRef) -> Result<SignalBinding, ProfileError> {
        let (message, m) = self.message_at(&format!("{key}.message"), &r.message)?;
        Ok(SignalBinding {
            message,
            signal: self.signal(m, &format!("{key}.signal"), &r.signal)?,
        })
    }

    fn status(
        &self,
        key: &str,
        message: &str,
        signal: Option<(&str, &str)>,
    ) -> Result<StatusBinding, ProfileError> {
        let (index, m) = self.message_at(&format!("{key}.message"), message)?;
        let signal = signal
            .map(|(role, name)| self.signal(m, &format!("{key}.{role}"), name))
            .transpose()?;
        Ok(StatusBinding {
            message: index,
            signal,
        })
    }

    /// An actuator's status: its message (and fault signal) found, or its CANopen node ID
    /// in range; one of the two.
    fn actuator_status(
        &self,
        key: &str,
        roles: &ActuatorRoles,
    ) -> Result<ActuatorStatusBinding, ProfileError> {
        match (&roles.message, roles.canopen, &roles.fault) {
            (Some(message), None, fault) => Ok(ActuatorStatusBinding::Message(self.status(
                key,
                message,
                fault.as_deref().map(|f| ("fault", f)),
            )?)),
            (None, Some(node), None) if (1..=127).contains(&node) => {
                Ok(ActuatorStatusBinding::CanOpen(node))
            }
            (None, Some(_), None) => {
                Err(self.invalid(&format!("{key}.canopen"), "a CANopen node ID from 1 to 127"))
            }
            (None, Some(_), Some(_)) => Err(self.invalid(
                &format!("{key}.fault"),
                "a CANopen drive reports its faults itself: give no fault signal",
            )),
            _ => Err(self.invalid(key, "give message (and fault) or canopen, one of them")),
        }
    }

    /// `[fail_operational]`: every name found, every number sensible.
    fn bind_fail_operational(
        &self,
        p: &Profile,
    ) -> Result<Option<FailOperationalBindings>, ProfileError> {
        let Some(f) = &p.fail_operational else {
            return Ok(None);
        };
        f.policy()
            .map_err(|(key, reason)| self.invalid(&key, reason))?;
        let mut bindings = FailOperationalBindings::default();
        for (i, v) in f.voted.iter().enumerate() {
            let key = format!("fail_operational.voted[{i}]");
            let [a, b, c] = v.channels.as_slice() else {
                return Err(self.invalid(&format!("{key}.channels"), "three channels"));
            };
            if !(v.tolerance.is_finite() && v.tolerance >= 0.0) {
                return Err(self.invalid(&format!("{key}.tolerance"), "a tolerance of 0 or more"));
            }
            if v.timeout_ms == 0 {
                return Err(self.invalid(&format!("{key}.timeout_ms"), "a timeout over 0 ms"));
            }
            let mut channels = [SignalBinding {
                message: 0,
                signal: 0,
            }; 3];
            for (n, (slot, r)) in channels.iter_mut().zip([a, b, c]).enumerate() {
                *slot = self.signal_ref(&format!("{key}.channels[{n}]"), r)?;
            }
            bindings.voted.push(VotedBindings { channels });
        }
        if let Some(c) = &f.control {
            let key = "fail_operational.control";
            if c.silence_ms == 0
                || c.deaf_ms == 0
                || !(c.output_tolerance.is_finite() && c.output_tolerance >= 0.0)
            {
                return Err(self.invalid(
                    key,
                    "silence_ms and deaf_ms over 0, output_tolerance 0 or more",
                ));
            }
            bindings.control = Some([
                self.status(&format!("{key}.a"), &c.a.message, Some(("role", &c.a.role)))?,
                self.status(&format!("{key}.b"), &c.b.message, Some(("role", &c.b.role)))?,
            ]);
        }
        for (i, a) in f.actuators.iter().enumerate() {
            let key = format!("fail_operational.actuators[{i}]");
            if !(a.still.is_finite() && a.still > 0.0 && a.overrun.is_finite() && a.overrun >= 0.0)
                || a.heartbeat_timeout_ms == 0
            {
                return Err(self.invalid(
                    &key,
                    "still over 0, overrun 0 or more, heartbeat_timeout_ms over 0",
                ));
            }
            let measured = match &a.measured {
                MeasuredRoles::Signal(r) => {
                    MeasuredBinding::Signal(self.signal_ref(&format!("{key}.measured"), r)?)
                }
                MeasuredRoles::Voted { voted } => MeasuredBinding::VotedRate(
                    f.voted
                        .iter()
                        .position(|v| &v.name == voted)
                        .ok_or_else(|| {
                            self.invalid(
                                &format!("{key}.measured.voted"),
                                format!("no voted quantity named '{voted}'"),
                            )
                        })?,
                ),
            };
            bindings.actuators.push(ActuatorPairBindings {
                primary: self.actuator_status(&format!("{key}.primary"), &a.primary)?,
                backup: self.actuator_status(&format!("{key}.backup"), &a.backup)?,
                measured,
            });
        }
        if let Some(r) = &f.report {
            let key = "fail_operational.report";
            let (message, m) = self.message_at(&format!("{key}.message"), &r.message)?;
            bindings.report = Some(ReportBindings {
                message,
                level: self.signal(m, &format!("{key}.level"), &r.level)?,
                reason: self.optional(m, &format!("{key}.reason"), &r.reason)?,
            });
        }
        Ok(Some(bindings))
    }

    fn bind(&self, p: &Profile) -> Result<Bindings, ProfileError> {
        let imu = match &p.imu {
            None => None,
            Some(imu) => {
                let (index, m) = self.message_at("imu.message", &imu.message)?;
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
                let (index, m) = self.message_at("battery.message", &b.message)?;
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
                let (index, m) = self.message_at("estop.message", &e.message)?;
                Some(RequestBindings {
                    message: index,
                    request: self.signal(m, "estop.request", &e.request)?,
                })
            }
        };
        let emergency_brake = match &p.emergency_brake {
            None => None,
            Some(b) => {
                let (index, m) = self.message_at("emergency_brake.message", &b.message)?;
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
            fail_operational: self.bind_fail_operational(p)?,
            command: self.bind_command(p)?,
            state: self.bind_state(p)?,
            wheel_speeds: self.bind_wheels("wheel_speeds", &p.wheel_speeds)?,
            wheel_angles: self.bind_wheels("wheel_angles", &p.wheel_angles)?,
            imu,
            battery,
            estop,
            emergency_brake,
        })
    }
}

/// Every role of `profile` (the file `file`) found in `db`; the first name it does not have is
/// refused, naming the key (`command.steering`) and what is missing.
fn bind(profile: &Profile, db: &Database, file: &str) -> Result<Bindings, ProfileError> {
    Checker { file, db }.bind(profile)
}

/// Checks a profile against its DBC, each error naming the profile's key.
struct Checker<'a> {
    file: &'a str,
    db: &'a Database,
}

impl Checker<'_> {
    fn invalid(&self, key: &str, reason: impl Into<String>) -> ProfileError {
        FileError::invalid(self.file, key, reason.into()).into()
    }

    fn message(&self, key: &str, name: &str) -> Result<&Message, ProfileError> {
        self.message_at(key, name).map(|(_, m)| m)
    }

    fn positive(&self, key: &str, value: f64) -> Result<(), ProfileError> {
        if value > 0.0 && value.is_finite() {
            Ok(())
        } else {
            Err(self.invalid(key, format!("{value} is not a positive number")))
        }
    }

    /// What the names found (`bindings`) do not settle: numbers, periods, the checksum
    /// algorithm, enum values that fit their signals, the SecOC layouts.
    fn check(&self, p: &Profile, bindings: &Bindings) -> Result<(), ProfileError> {
        if p.bitrate == 0 || p.bitrate > 1_000_000 {
            return Err(self.invalid("bitrate", format!("{} is not a CAN bitrate", p.bitrate)));
        }
        if p.command.is_none() && p.autoware.is_none() {
            return Err(self.invalid("command", "a profile needs [command] or [autoware]"));
        }
        let l = &p.limits;
        self.positive("limits.steering_deg", l.steering_deg)?;
        self.positive("limits.steering_rate_deg_s", l.steering_rate_deg_s)?;
        self.positive("limits.speed_m_s", l.speed_m_s)?;
        self.positive("limits.deceleration_m_s2", l.deceleration_m_s2)?;
        if let (Some(c), Some(b)) = (&p.command, &bindings.command) {
            self.command(p, c, b)?;
        }
        if let Some(s) = &p.state {
            if s.period_ms == 0 || s.timeout_cycles == 0 {
                return Err(self.invalid(
                    "state.timeout_cycles",
                    "period and timeout must be at least 1",
                ));
            }
        }
        if let Some(b) = &p.emergency_brake {
            if b.burst_frames == 0 || b.repeat_ms == 0 {
                return Err(self.invalid(
                    "emergency_brake.burst_frames",
                    "the burst needs frames and a repeat period",
                ));
            }
        }
        self.vehicle(p)?;
        if let Some(a) = &p.autoware {
            self.message("autoware.steering", &a.steering)?;
            self.message("autoware.velocity", &a.velocity)?;
            self.message("autoware.status", &a.status)?;
            a.output
                .parse::<crate::autoware::OutputMode>()
                .map_err(|e| self.invalid("autoware.output", e.to_string()))?;
        }
        if let Some(secoc) = &p.secoc {
            self.secured_layouts(secoc)?;
        }
        Ok(())
    }

    /// The command's period, checksum algorithm, and enum values that fit their signals.
    fn command(
        &self,
        p: &Profile,
        c: &CommandRoles,
        b: &CommandBindings,
    ) -> Result<(), ProfileError> {
        if c.period_ms == 0 {
            return Err(self.invalid("command.period_ms", "must be at least 1"));
        }
        if c.algorithm().is_none() {
            return Err(self.invalid(
                "command.checksum_algorithm",
                format!(
                    "'{}' is not one of crc8_sae_j1850, crc8_h2f, xor8, sum8",
                    c.checksum_algorithm
                ),
            ));
        }
        let message = self.db.messages.get(b.message);
        let width = |signal: Option<usize>| {
            signal
                .and_then(|i| message?.signals.get(i))
                .map(|s| s.length)
        };
        for (role, values) in &p.enums {
            let signal =
                match role.as_str() {
                    "gear" => Some(b.gear),
                    "control_mode" => Some(b.control_mode),
                    "steering_mode" => Some(b.steering_mode),
                    "turn_indicators" => b.turn_indicators,
                    _ => return Err(self.invalid(
                        &format!("enums.{role}"),
                        "not a command role (gear, control_mode, steering_mode, turn_indicators)",
                    )),
                };
            let Some(width) = width(signal) else {
                return Err(self.invalid(
                    &format!("enums.{role}"),
                    format!("not a command role: [command] names no {role} signal"),
                ));
            };
            for (name, value) in values {
                if width < 64 && *value >> width != 0 {
                    return Err(self.invalid(
                        &format!("enums.{role}.{name}"),
                        format!("{value} does not fit the {width}-bit signal"),
                    ));
                }
            }
        }
        Ok(())
    }

    /// The watchdog cascade and the vehicle's geometry.
    fn vehicle(&self, p: &Profile) -> Result<(), ProfileError> {
        if let Some(w) = &p.watchdog {
            if w.hold_cycles == 0 || w.decelerate_cycles < w.hold_cycles {
                return Err(self.invalid(
                    "watchdog.decelerate_cycles",
                    format!(
                        "the cascade needs 1 <= hold_cycles ({}) <= decelerate_cycles ({})",
                        w.hold_cycles, w.decelerate_cycles
                    ),
                ));
            }
            self.positive(
                "watchdog.controlled_deceleration_m_s2",
                w.controlled_deceleration_m_s2,
            )?;
        }
        if let Some(v) = &p.vehicle {
            self.positive("vehicle.wheel_diameter_m", v.wheel_diameter_m)?;
            self.positive("vehicle.gear_ratio", v.gear_ratio)?;
            self.positive("vehicle.wheelbase_m", v.wheelbase_m)?;
            self.positive("vehicle.track_m", v.track_m)?;
        }
        Ok(())
    }

    /// Each secured message's identifier and layout.
    #[cfg(feature = "secoc")]
    fn secured_layouts(
        &self,
        s: &SecOcRoles,
    ) -> Result<Vec<(bywire_core::Id, bywire_secoc::Layout)>, ProfileError> {
        let lengths = match (&s.profile, s.fv_length, s.fv_tx_length, s.mac_tx_length) {
            (Some(name), None, None, None) => {
                let p = bywire_secoc::profile(name).ok_or_else(|| {
                    let known: Vec<&str> = bywire_secoc::PROFILES.iter().map(|p| p.name).collect();
                    self.invalid(
                        "secoc.profile",
                        format!("'{name}' is not a SecOC profile ({})", known.join(", ")),
                    )
                })?;
                (p.fv_length, p.fv_tx_length, p.mac_tx_length)
            }
            (None, Some(fv), Some(tx), Some(mac)) => (fv, tx, mac),
            _ => {
                return Err(self.invalid(
                    "secoc",
                    "give profile, or fv_length, fv_tx_length and mac_tx_length",
                ))
            }
        };
        if s.messages.is_empty() || s.messages.len() > crate::secured::MAX_SECURED {
            return Err(self.invalid(
                "secoc.messages",
                format!("1 to {} messages", crate::secured::MAX_SECURED),
            ));
        }
        if s.window == 0 {
            return Err(self.invalid("secoc.window", "must be at least 1"));
        }
        let mut layouts = Vec::new();
        for (i, name) in s.messages.iter().enumerate() {
            let key = format!("secoc.messages[{i}]");
            let m = self.message(&key, name)?;
            let id = if m.extended {
                bywire_core::Id::extended(m.raw_id())
            } else {
                bywire_core::Id::standard(m.raw_id())
            }
            .map_err(|e| self.invalid(&key, e.to_string()))?;
            let data_id = u16::try_from(m.raw_id() & 0xFFFF).unwrap_or(0);
            let length = usize::try_from(m.size).unwrap_or(usize::MAX);
            let layout =
                bywire_secoc::Layout::new(data_id, length, lengths.0, lengths.1, lengths.2)
                    .map_err(|e| self.invalid(&key, format!("{name}: {e}")))?;
            if layouts.iter().any(|(other, _)| *other == id) {
                return Err(self.invalid(&key, format!("'{name}' is listed twice")));
            }
            layouts.push((id, layout));
        }
        if let Some(sync) = s.sync_id {
            let taken = self
                .db
                .messages
                .iter()
                .any(|m| m.raw_id() == sync && !m.extended);
            if sync > 0x7FF || taken {
                return Err(self.invalid(
                    "secoc.sync_id",
                    format!("0x{sync:X} is not a free 11-bit identifier of the DBC"),
                ));
            }
        }
        Ok(layouts)
    }

    #[cfg(not(feature = "secoc"))]
    fn secured_layouts(&self, _: &SecOcRoles) -> Result<(), ProfileError> {
        Err(self.invalid(
            "secoc",
            "this build has no SecOC (the `secoc` feature): refusing to run unauthenticated",
        ))
    }
}

impl LoadedProfile {
    /// The profile's wire as a node speaks it: secured by its key from `keys` when the profile
    /// declares `[secoc]` (the keys then required), as it is otherwise (keys then refused: they
    /// would secure nothing the user meant).
    #[cfg(feature = "secoc")]
    pub fn wire_with_keys(
        &self,
        keys: Option<&bywire_secoc::keys::KeyFile>,
        next: u64,
    ) -> Result<crate::secured::Secured<crate::wire::ProfileWire>, ProfileError> {
        let invalid = |reason: &str| {
            ProfileError::from(FileError::invalid(&self.profile.name, "secoc", reason))
        };
        match (keys, &self.profile.secoc) {
            (Some(keys), Some(_)) => self.secured_wire(keys, next),
            (None, Some(_)) => Err(invalid(
                "the profile secures its messages: give its key file (--key-file)",
            )),
            (Some(_), None) => Err(invalid(
                "a key file was given but the profile declares no [secoc]",
            )),
            (None, None) => Ok(crate::secured::Secured::plain(
                crate::wire::ProfileWire::new(self)?,
            )),
        }
    }

    /// The profile's wire with its `[secoc]` messages secured by its key from `keys` (see
    /// [`LoadedProfile::secured_table`]); the plain wire when it secures nothing.
    #[cfg(feature = "secoc")]
    pub fn secured_wire(
        &self,
        keys: &bywire_secoc::keys::KeyFile,
        next: u64,
    ) -> Result<crate::secured::Secured<crate::wire::ProfileWire>, ProfileError> {
        let wire = crate::wire::ProfileWire::unsecured(self)?;
        Ok(match self.secured_table(keys, next)? {
            Some(table) => crate::secured::Secured::new(wire, table),
            None => crate::secured::Secured::plain(wire),
        })
    }

    /// The table securing the profile's `[secoc]` messages with its key from `keys`, this
    /// node's frames signed from freshness `next` on (1 for a new key, the persisted value
    /// after a restart); `None` when the profile secures nothing. A missing key is an error:
    /// the caller must not start.
    #[cfg(feature = "secoc")]
    pub fn secured_table(
        &self,
        keys: &bywire_secoc::keys::KeyFile,
        next: u64,
    ) -> Result<Option<crate::secured::SecuredTable>, ProfileError> {
        let Some(s) = &self.profile.secoc else {
            return Ok(None);
        };
        let checker = Checker {
            file: &self.profile.name,
            db: &self.database,
        };
        let key = keys.key(s.key_id).ok_or_else(|| {
            checker.invalid(
                "secoc.key_id",
                format!(
                    "key {} is not in the key file: refusing to start unauthenticated",
                    s.key_id
                ),
            )
        })?;
        let mut table = crate::secured::SecuredTable::new(key, s.window);
        for (id, layout) in checker.secured_layouts(s)? {
            table
                .secure(id, layout, next)
                .map_err(|e| checker.invalid("secoc.messages", e.to_string()))?;
        }
        if let Some(sync) = s.sync_id {
            let id = bywire_core::Id::standard(sync)
                .map_err(|e| checker.invalid("secoc.sync_id", e.to_string()))?;
            let sync = crate::secured::SyncMessage {
                id,
                data_id: u16::try_from(sync).unwrap_or(0),
            };
            table = table
                .with_sync(sync)
                .map_err(|e| checker.invalid("secoc.sync_id", e.to_string()))?;
        }
        Ok(Some(table))
    }

    /// The supervisor's configuration from this profile (defaults where it is silent).
    pub fn supervisor_config(&self) -> SupervisorConfig {
        let p = &self.profile;
        let mut c = SupervisorConfig {
            steering_range: p.limits.steering_deg,
            steering_rate: p.limits.steering_rate_deg_s,
            speed_limit: p.limits.speed_m_s,
            ..SupervisorConfig::default()
        };
        if let Some(command) = &p.command {
            c.cycle = Duration::from_millis(command.period_ms);
        }
        if let Some(w) = &p.watchdog {
            c.cascade = Cascade {
                hold: w.hold_cycles,
                decelerate: w.decelerate_cycles,
                recovery_run: w.recovery_run,
            };
            c.controlled_deceleration = w.controlled_deceleration_m_s2;
        }
        if let Some(t) = &p.takeover {
            c.takeover_torque = t.steering_torque_nm;
            c.takeover_pedal = t.pedal;
        }
        if let Some(v) = &p.vehicle {
            c.gear_ratio = v.gear_ratio;
            c.wheel_diameter = v.wheel_diameter_m;
        }
        // Checked when the profile loaded, so it is there whenever the section is.
        c.degradation = p.fail_operational.as_ref().and_then(|f| f.policy().ok());
        c
    }

    /// The ADS side's configuration from this profile.
    pub fn ads_config(&self) -> AdsConfig {
        let p = &self.profile;
        let mut c = AdsConfig::default();
        if let Some(command) = &p.command {
            c.cycle = Duration::from_millis(command.period_ms);
            c.staleness = Duration::from_millis(command.staleness_ms);
        }
        if let Some(s) = &p.state {
            c.feedback_timeout_cycles = s.timeout_cycles;
            c.echo_window = s.echo_window;
        }
        if let Some(b) = &p.emergency_brake {
            c.brake_burst_spacing = Duration::from_millis(b.burst_spacing_ms);
            c.brake_repeat = Duration::from_millis(b.repeat_ms);
        }
        c.wheels = p.vehicle.as_ref().map(|v| WheelGeometry {
            wheelbase: v.wheelbase_m,
            track: v.track_m,
        });
        c
    }
}
