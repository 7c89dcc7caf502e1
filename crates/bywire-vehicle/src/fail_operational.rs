//! A profile's `[fail_operational]` section: the redundancy a vehicle carries and what each
//! loss of it leads to, as the configurations of the mechanisms ([`TripleVoter`]s,
//! [`Arbiter`]s, [`ActuatorPair`]s and the [`Degradation`] latch) take them. A profile without
//! the section declares no redundancy, and its vehicle is fail-safe as before: every fault
//! ends in the supervisor's safe state.
//!
//! ```toml
//! [fail_operational.rules]          # the level per fault class (others keep the default)
//! sensor-channel-out = "degraded"
//! control-takeover = "minimal-risk"
//!
//! [fail_operational.degraded]       # and likewise [fail_operational.minimal_risk]
//! speed_limit_m_s = 2.0
//! steering_modes = ["normal", "crab"]
//!
//! [[fail_operational.voted]]        # a quantity read three times, voted 2-out-of-3
//! name = "front-axle-angle"
//! channels = [{ message = "AngleF", signal = "A" }, { message = "AngleF", signal = "B" },
//!             { message = "AngleF2", signal = "C" }]
//! tolerance = 1.0
//! persistence_ms = 30
//! timeout_ms = 50
//!
//! [fail_operational.control]        # two control ECUs, A active, B in hot standby
//! a = { message = "VcuA_Status", role = "Role" }
//! b = { message = "VcuB_Status", role = "Role" }
//! silence_ms = 30
//! disagreement_ms = 30
//! output_tolerance = 2.0
//!
//! [fail_operational.report]         # the level and reason, for the ADS side
//! message = "VcuDegradation"
//! level = "Level"
//! reason = "Reason"
//!
//! [[fail_operational.actuators]]    # an actuator and its backup
//! name = "steering"
//! primary = { message = "SteerP_Status", fault = "Fault" }
//! backup = { message = "SteerB_Status", fault = "Fault" }
//! measured = { message = "SteerRate", signal = "Rate" }
//! still = 0.5
//! overrun = 10.0
//! persistence_ms = 40
//! heartbeat_timeout_ms = 50
//!
//! [[fail_operational.actuators]]    # CiA 402 drives, judged by a voted angle's rate
//! name = "front-steering"
//! primary = { canopen = 0x21 }
//! backup = { canopen = 0x31 }
//! measured = { voted = "front-axle-angle" }
//! still = 2.0
//! overrun = 8.0
//! persistence_ms = 80
//! heartbeat_timeout_ms = 30
//! ```
//!
//! [`TripleVoter`]: crate::redundancy::TripleVoter
//! [`Arbiter`]: crate::arbitration::Arbiter
//! [`ActuatorPair`]: crate::backup::ActuatorPair
//! [`Degradation`]: crate::degradation::Degradation

use std::collections::BTreeMap;
use std::time::Duration;

use serde::Deserialize;

use crate::arbitration::ArbiterConfig;
use crate::backup::FeedbackCheck;
use crate::command::{DegradationLevel, FaultClass, SteeringMode};
use crate::degradation::{DegradationPolicy, LevelLimits, SteeringModes};
use crate::redundancy::TripleConfig;

/// A message and one of its signals.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SignalRef {
    /// The message.
    pub message: String,
    /// The signal.
    pub signal: String,
}

/// What a degraded level allows.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LevelRoles {
    /// Largest speed, m/s.
    pub speed_limit_m_s: f64,
    /// The steering modes still allowed, by name.
    pub steering_modes: Vec<String>,
}

/// A quantity read by three sensors and voted 2-out-of-3.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VotedRoles {
    /// Its name in reports.
    pub name: String,
    /// The three channels.
    pub channels: Vec<SignalRef>,
    /// Two readings agree within this (the signal's unit).
    pub tolerance: f64,
    /// Outvoted this long, a channel is out.
    pub persistence_ms: u64,
    /// Silent this long, a channel is out.
    pub timeout_ms: u64,
}

/// One control ECU's status message.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EcuRoles {
    /// The message (its arrival is the ECU's heartbeat).
    pub message: String,
    /// The signal carrying its role (`Role::raw`'s numbering).
    pub role: String,
}

/// Two control ECUs, A active and B in hot standby.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControlRoles {
    /// ECU A's status.
    pub a: EcuRoles,
    /// ECU B's status.
    pub b: EcuRoles,
    /// The partner is silent after this long.
    pub silence_ms: u64,
    /// Outputs may disagree this long before the standby takes over.
    pub disagreement_ms: u64,
    /// How far the active side's outputs may be from the standby's own before they disagree
    /// (the command's units).
    pub output_tolerance: f64,
    /// How often each sends its status, ms.
    #[serde(default = "default_status_period")]
    pub status_period_ms: u64,
    /// No frame at all for this long is a half's own receiver failed, ms (longer than the
    /// longest gap between the frames it hears).
    #[serde(default = "default_deaf")]
    pub deaf_ms: u64,
}

fn default_deaf() -> u64 {
    100
}

fn default_status_period() -> u64 {
    10
}

/// Where one actuator's status comes from: a message of the profile's DBC, or a CiA 402
/// drive on a CANopen bus. Give `message` or `canopen`, not both.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ActuatorRoles {
    /// The message (its arrival is the actuator's heartbeat).
    pub message: Option<String>,
    /// The signal that reports a fault of the actuator's own (non-zero: a fault).
    pub fault: Option<String>,
    /// A CiA 402 drive's node ID: its process data are its heartbeat, its Fault state and
    /// emergencies its faults.
    pub canopen: Option<u8>,
}

/// What measures the rate the actuator pair is judged by: a signal, or the rate of change
/// of a quantity the section votes (`{ voted = "angle-fl" }`), an independent measurement
/// by construction.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(untagged)]
pub enum MeasuredRoles {
    /// A signal carrying the rate.
    Signal(SignalRef),
    /// The rate of a voted quantity.
    Voted {
        /// The voted quantity's name.
        voted: String,
    },
}

/// An actuator and its backup.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ActuatorPairRoles {
    /// Its name in reports.
    pub name: String,
    /// The primary's status.
    pub primary: ActuatorRoles,
    /// The backup's status.
    pub backup: ActuatorRoles,
    /// The rate an independent sensor measures.
    pub measured: MeasuredRoles,
    /// Rates below this are no motion.
    pub still: f64,
    /// Faster than demanded by more than this is a runaway.
    pub overrun: f64,
    /// A tracking fault counts once it lasts this long.
    pub persistence_ms: u64,
    /// The heartbeat is lost after this long.
    pub heartbeat_timeout_ms: u64,
}

/// The degradation report the vehicle sends beside its state message.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReportRoles {
    /// The message (its counter and checksum as its DBC declares them).
    pub message: String,
    /// The level (`DegradationLevel::raw`'s numbering).
    pub level: String,
    /// The fault class it is reported with (`FaultClass::raw`'s numbering, 0 for none).
    pub reason: Option<String>,
}

/// The `[fail_operational]` section.
#[derive(Debug, Clone, PartialEq, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct FailOperationalRoles {
    /// The level per fault class, by name (`sensor-channel-out = "degraded"`).
    #[serde(default)]
    pub rules: BTreeMap<String, String>,
    /// The degraded level's limits.
    pub degraded: Option<LevelRoles>,
    /// The minimal-risk level's limits.
    pub minimal_risk: Option<LevelRoles>,
    /// Voted sensors.
    #[serde(default)]
    pub voted: Vec<VotedRoles>,
    /// Duplicated control ECUs.
    pub control: Option<ControlRoles>,
    /// Actuators with a backup.
    #[serde(default)]
    pub actuators: Vec<ActuatorPairRoles>,
    /// The degradation report (none: the ADS side is not told).
    pub report: Option<ReportRoles>,
}

/// A key of the section and why its value is wrong.
pub type KeyError = (String, String);

impl FailOperationalRoles {
    /// The degradation policy: the default's, with the section's rules and limits over it.
    pub fn policy(&self) -> Result<DegradationPolicy, KeyError> {
        let mut policy = DegradationPolicy::default();
        for (class, level) in &self.rules {
            let key = format!("fail_operational.rules.{class}");
            let class: FaultClass = class
                .parse()
                .map_err(|e: crate::command::UnknownName| (key.clone(), e.to_string()))?;
            let level: DegradationLevel = level
                .parse()
                .map_err(|e: crate::command::UnknownName| (key.clone(), e.to_string()))?;
            policy.set_rule(class, level);
        }
        for (name, roles, slot) in [
            ("degraded", &self.degraded, &mut policy.degraded),
            ("minimal_risk", &self.minimal_risk, &mut policy.minimal_risk),
        ] {
            if let Some(roles) = roles {
                *slot = roles.limits(&format!("fail_operational.{name}"))?;
            }
        }
        Ok(policy)
    }
}

impl LevelRoles {
    fn limits(&self, key: &str) -> Result<LevelLimits, KeyError> {
        if !(self.speed_limit_m_s.is_finite() && self.speed_limit_m_s >= 0.0) {
            return Err((
                format!("{key}.speed_limit_m_s"),
                "a speed of 0 m/s or more".into(),
            ));
        }
        let modes = self
            .steering_modes
            .iter()
            .map(|m| m.parse::<SteeringMode>())
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| (format!("{key}.steering_modes"), e.to_string()))?;
        Ok(LevelLimits {
            speed_limit: self.speed_limit_m_s,
            steering_modes: SteeringModes::only(&modes),
        })
    }
}

impl VotedRoles {
    /// The voter's tuning.
    pub fn config(&self) -> TripleConfig {
        TripleConfig {
            tolerance: self.tolerance,
            persistence: Duration::from_millis(self.persistence_ms),
            timeout: Duration::from_millis(self.timeout_ms),
        }
    }
}

impl ControlRoles {
    /// The arbitration's timing.
    pub fn config(&self) -> ArbiterConfig {
        ArbiterConfig {
            silence: Duration::from_millis(self.silence_ms),
            disagreement: Duration::from_millis(self.disagreement_ms),
            deaf: Duration::from_millis(self.deaf_ms),
        }
    }
}

impl ActuatorPairRoles {
    /// The feedback check.
    pub fn check(&self) -> FeedbackCheck {
        FeedbackCheck {
            still: self.still,
            overrun: self.overrun,
            persistence: Duration::from_millis(self.persistence_ms),
            heartbeat_timeout: Duration::from_millis(self.heartbeat_timeout_ms),
        }
    }
}
