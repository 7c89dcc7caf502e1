//! Degradation levels of a fail-operational vehicle: the rule per fault class a profile
//! declares, the limits each level sets, and the latch that raises the level and never lowers
//! it on its own.
//!
//! A fault a mechanism reports (a sensor channel latched out, the standby ECU taking over,
//! the backup actuator taking over, ...) raises the level to its class's rule; a second,
//! independent fault on top of one that degraded the vehicle is a double fault and ends in
//! [`DegradationLevel::SafeStop`], whatever its own rule. Only a reset at standstill lowers
//! the level. The caller reports each fault once, at the mechanism's edge, and not its
//! consequences (the ECU that took over does not also report its partner lost).

use bywire_core::Timestamp;

use crate::command::{DegradationLevel, FaultClass, SteeringMode};

/// A set of steering modes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SteeringModes(u8);

impl SteeringModes {
    /// Every mode.
    pub const ALL: SteeringModes = SteeringModes(0b111);

    /// Only `modes`.
    pub fn only(modes: &[SteeringMode]) -> Self {
        SteeringModes(modes.iter().fold(0, |set, m| set | (1u8 << m.raw())))
    }

    /// Whether `mode` is in the set.
    pub fn allows(self, mode: SteeringMode) -> bool {
        self.0 & (1u8 << mode.raw()) != 0
    }
}

/// What a degraded level allows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LevelLimits {
    /// Largest speed, m/s.
    pub speed_limit: f64,
    /// The steering modes still allowed (a command for another keeps the current mode).
    pub steering_modes: SteeringModes,
}

/// A vehicle's degradation policy: the level each fault class leads to and the limits of the
/// two levels that keep moving.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DegradationPolicy {
    /// The level of each class, in [`FaultClass::ALL`]'s order.
    rules: [DegradationLevel; FaultClass::ALL.len()],
    /// At [`DegradationLevel::Degraded`].
    pub degraded: LevelLimits,
    /// At [`DegradationLevel::MinimalRisk`], on the way to the next safe stop point.
    pub minimal_risk: LevelLimits,
}

impl Default for DegradationPolicy {
    /// Losing one layer of redundancy in a sensor or the standby degrades; losing the ECU
    /// or the actuator in control to its backup is a minimal-risk manoeuvre; losing the last
    /// of anything is a safe stop.
    fn default() -> Self {
        let mut policy = DegradationPolicy {
            rules: [DegradationLevel::SafeStop; FaultClass::ALL.len()],
            degraded: LevelLimits {
                speed_limit: 2.0,
                steering_modes: SteeringModes::only(&[SteeringMode::Normal, SteeringMode::Crab]),
            },
            minimal_risk: LevelLimits {
                speed_limit: 1.5,
                steering_modes: SteeringModes::only(&[SteeringMode::Normal]),
            },
        };
        policy.set_rule(FaultClass::SensorChannelOut, DegradationLevel::Degraded);
        policy.set_rule(FaultClass::StandbyLost, DegradationLevel::Degraded);
        policy.set_rule(FaultClass::ControlTakeover, DegradationLevel::MinimalRisk);
        policy.set_rule(FaultClass::ActuatorBackup, DegradationLevel::MinimalRisk);
        policy
    }
}

impl DegradationPolicy {
    /// A fail-safe vehicle's: every fault class is a safe stop.
    pub fn fail_safe() -> Self {
        DegradationPolicy {
            rules: [DegradationLevel::SafeStop; FaultClass::ALL.len()],
            ..DegradationPolicy::default()
        }
    }

    fn index(class: FaultClass) -> usize {
        FaultClass::ALL
            .iter()
            .position(|&c| c == class)
            .unwrap_or(0)
    }

    /// The level `class` leads to.
    pub fn rule(&self, class: FaultClass) -> DegradationLevel {
        self.rules
            .get(Self::index(class))
            .copied()
            .unwrap_or(DegradationLevel::SafeStop)
    }

    /// Set the level `class` leads to.
    pub fn set_rule(&mut self, class: FaultClass, level: DegradationLevel) {
        if let Some(rule) = self.rules.get_mut(Self::index(class)) {
            *rule = level;
        }
    }

    /// The limits at `level` (`None` at nominal, where the vehicle's own apply, and at safe
    /// stop, where nothing moves).
    pub fn limits(&self, level: DegradationLevel) -> Option<LevelLimits> {
        match level {
            DegradationLevel::Degraded => Some(self.degraded),
            DegradationLevel::MinimalRisk => Some(self.minimal_risk),
            DegradationLevel::Nominal | DegradationLevel::SafeStop => None,
        }
    }
}

/// One fault a mechanism reported.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Fault {
    /// What was found.
    pub class: FaultClass,
    /// Which instance of the mechanism (the sensor's axle, say): two faults of one class
    /// from two sources are two faults.
    pub source: u8,
    /// When it was found.
    pub at: Timestamp,
}

/// The degradation latch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Degradation {
    policy: DegradationPolicy,
    level: DegradationLevel,
    /// The fault that first raised the level.
    first: Option<Fault>,
    /// A second fault on top of it.
    second: Option<Fault>,
}

impl Degradation {
    /// Nominal, under `policy`.
    pub fn new(policy: DegradationPolicy) -> Self {
        Degradation {
            policy,
            level: DegradationLevel::Nominal,
            first: None,
            second: None,
        }
    }

    /// The policy.
    pub fn policy(&self) -> &DegradationPolicy {
        &self.policy
    }

    /// The level now.
    pub fn level(&self) -> DegradationLevel {
        self.level
    }

    /// The fault that first raised the level.
    pub fn first(&self) -> Option<Fault> {
        self.first
    }

    /// The second fault, if there was one.
    pub fn second(&self) -> Option<Fault> {
        self.second
    }

    /// The fault the level is reported with: the second if there is one, else the first.
    pub fn reason(&self) -> Option<Fault> {
        self.second.or(self.first)
    }

    /// The limits the level sets.
    pub fn limits(&self) -> Option<LevelLimits> {
        self.policy.limits(self.level)
    }

    /// The one transition: `fault` reported; the level from now on. A fault already
    /// reported (same class and source) changes nothing; one whose rule is nominal is a
    /// notice only.
    pub fn report(&mut self, fault: Fault) -> DegradationLevel {
        let known = |f: Option<Fault>| {
            f.is_some_and(|f| f.class == fault.class && f.source == fault.source)
        };
        let rule = self.policy.rule(fault.class);
        if known(self.first) || known(self.second) || rule == DegradationLevel::Nominal {
            return self.level;
        }
        match (self.first, self.second) {
            (None, _) => {
                self.first = Some(fault);
                self.level = self.level.max(rule);
            }
            (Some(_), None) => {
                self.second = Some(fault);
                self.level = DegradationLevel::SafeStop;
            }
            (Some(_), Some(_)) => self.level = DegradationLevel::SafeStop,
        }
        self.level
    }

    /// Back to nominal, only at a standstill: whether it was reset.
    pub fn reset(&mut self, standstill: bool) -> bool {
        if standstill {
            *self = Degradation::new(self.policy);
        }
        standstill
    }
}
