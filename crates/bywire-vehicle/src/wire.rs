//! How a vehicle's messages look on the wire, behind two traits: [`AdsWire`] (what the ADS
//! side sends and reads) and [`VehicleWire`] (what the vehicle side reads and sends).
//! [`ProfileWire`] speaks any vehicle a profile describes, by role, through the runtime DBC
//! codec; a vehicle crate may implement the traits over structs generated from its DBC
//! (`no_std`, what an ECU build uses) — the reference tug's crate does. The nodes are the same
//! for every wire.

use bywire_core::{Frame, Id, Timestamp};

use crate::command::{
    ControlCommand, ControlMode, DegradationLevel, EstopCode, FaultClass, Gear, SteeringMode,
    TurnIndicators, WatchdogLevel,
};
use crate::redundancy::Channel;

#[cfg(feature = "std")]
pub use crate::profile_wire::{ProfileDuplexWire, ProfileWire};

/// A state (feedback) message, read by role.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StateFeedback {
    /// Its rolling counter.
    pub counter: u64,
    /// Actual steering angle, degrees.
    pub steering: f64,
    /// Actual speed, m/s.
    pub velocity: f64,
    /// Reported control mode.
    pub mode: ControlMode,
    /// Watchdog level, where the vehicle reports one.
    pub watchdog_level: Option<WatchdogLevel>,
    /// E-stop latch state, where reported.
    pub estop_state: Option<EstopCode>,
    /// Warning flag, where reported.
    pub warning: Option<bool>,
    /// Driver override, where reported.
    pub driver_override: Option<bool>,
    /// The gear engaged, where reported.
    pub gear: Option<Gear>,
    /// The steering mode the wheels are in, where reported.
    pub steering_mode: Option<SteeringMode>,
    /// The turn indicators, where reported.
    pub turn_indicators: Option<TurnIndicators>,
    /// The hazard lights, where reported.
    pub hazard_lights: Option<bool>,
    /// The command counter the vehicle echoes.
    pub heartbeat_echo: u64,
    /// Every value within its declared range.
    pub in_range: bool,
}

/// What a received frame is to the ADS side.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Feedback {
    /// Not a feedback message.
    Other,
    /// A feedback message whose checksum or shape is wrong.
    Corrupt,
    /// A secured feedback message that failed verification (forged, replayed, or another
    /// key's): not read at all.
    Unauthenticated,
    /// The state message.
    State(StateFeedback),
    /// Wheel angles FL, FR, RL, RR, degrees, with the counter.
    WheelAngles {
        /// Rolling counter.
        counter: u64,
        /// Angles.
        angles: [f64; 4],
    },
    /// Wheel speeds FL, FR, RL, RR, m/s, with the counter.
    WheelSpeeds {
        /// Rolling counter.
        counter: u64,
        /// Speeds.
        speeds: [f64; 4],
    },
    /// A fail-operational vehicle's degradation report.
    Degradation(DegradationReport),
}

/// How far a fail-operational vehicle has degraded and why, as its degradation report
/// (a message of its own, beside the state message) carries it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DegradationReport {
    /// The level.
    pub level: DegradationLevel,
    /// The fault it is reported with (`None`: nominal, or the message has no reason).
    pub reason: Option<FaultClass>,
}

impl DegradationReport {
    /// The report from its raw level and reason (reason 0: none); `None` if either names
    /// nothing.
    pub fn from_raw(level: u64, reason: u64) -> Option<DegradationReport> {
        Some(DegradationReport {
            level: DegradationLevel::from_raw(level)?,
            reason: match reason {
                0 => None,
                raw => Some(FaultClass::from_raw(raw)?),
            },
        })
    }

    /// The reason as the report carries it (0: none).
    pub fn reason_raw(&self) -> u64 {
        self.reason.map_or(0, FaultClass::raw)
    }
}

/// The widths of the rolling counters both sides check.
pub trait Counters {
    /// Bits of the command's rolling counter.
    fn command_counter_bits(&self) -> u8;
    /// Bits of the state message's rolling counter.
    fn state_counter_bits(&self) -> u8;
}

/// The ADS side's messages on some vehicle's wire.
pub trait AdsWire: Counters {
    /// Bits of the wheel messages' counters.
    fn wheel_counter_bits(&self) -> u8;
    /// The command frame with `counter` and its checksum.
    fn command_frame(&mut self, command: &ControlCommand, counter: u64) -> Option<Frame>;
    /// An emergency-brake frame, if the vehicle has the message.
    fn emergency_brake_frame(&mut self, deceleration: f64, counter: u64) -> Option<Frame>;
    /// Read a received frame.
    fn feedback(&mut self, frame: &Frame) -> Feedback;
    /// A frame the wire itself has to send at `now` (a freshness sync), polled with the
    /// node's own.
    fn pending_frame(&mut self, _now: Timestamp) -> Option<Frame> {
        None
    }
}

/// What a received frame is to the vehicle side.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Incoming {
    /// Not for the vehicle side.
    Other,
    /// The command message: its command (`None` if a value names nothing, e.g. an undefined
    /// steering mode) and counter — or why it is no command at all.
    Command(Result<(Option<ControlCommand>, u64), Rejected>),
    /// The E-stop message (checked): whether the E-stop is requested.
    Estop(bool),
    /// The emergency-brake message (checked): whether braking is requested.
    EmergencyBrake(bool),
    /// A secured message other than the command that failed verification: not read at all.
    Unauthenticated,
}

/// Why a command frame was not read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rejected {
    /// Not the message's shape (length, remote frame).
    Malformed,
    /// The checksum does not match.
    Checksum,
    /// A secured command that failed verification (forged, replayed, or another key's).
    Authentication,
}

/// What the vehicle side reports in its state message.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StateReport {
    /// Actual steering, degrees.
    pub steering: f64,
    /// Actual speed, m/s.
    pub velocity: f64,
    /// Control mode.
    pub mode: ControlMode,
    /// Steering mode in use.
    pub steering_mode: SteeringMode,
    /// Gear in use.
    pub gear: Gear,
    /// Watchdog level 0–4.
    pub watchdog_level: WatchdogLevel,
    /// E-stop latch state code.
    pub estop_state: EstopCode,
    /// Warning flag.
    pub warning: bool,
    /// A driver is overriding.
    pub driver_override: bool,
    /// The steering actuator is enabled.
    pub steering_enabled: bool,
    /// The turn indicators.
    pub turn_indicators: TurnIndicators,
    /// The hazard lights are on.
    pub hazard_lights: bool,
    /// The last accepted command counter, echoed.
    pub heartbeat_echo: u64,
}

/// The vehicle side's messages on some vehicle's wire.
pub trait VehicleWire: Counters {
    /// Read a received frame.
    fn incoming(&mut self, frame: &Frame) -> Incoming;
    /// Whether `id` is the command's identifier (a frame whose bytes are not to be read, as
    /// one that failed authentication, is still known by it).
    fn is_command(&self, id: Id) -> bool;
    /// Read a frame received on `channel`'s bus (a wire that keeps state per bus, as
    /// [`crate::secured::Secured`] does, tells them apart).
    fn incoming_from(&mut self, _channel: Channel, frame: &Frame) -> Incoming {
        self.incoming(frame)
    }
    /// A frame the wire itself has to send at `now` (a freshness sync), polled with the
    /// node's own.
    fn pending_frame(&mut self, _now: Timestamp) -> Option<Frame> {
        None
    }
    /// Stop checking what `off` names of the frames it reads (the command's checksum for
    /// [`Mechanism::E2e`], authentication for [`Mechanism::Secoc`]): a fault-injection
    /// campaign's proof that it would notice (see [`crate::mechanism`]).
    ///
    /// [`Mechanism::E2e`]: crate::mechanism::Mechanism::E2e
    /// [`Mechanism::Secoc`]: crate::mechanism::Mechanism::Secoc
    fn switch_off(&mut self, _off: crate::mechanism::Mechanisms) {}
    /// The state frame with `counter` and its checksum.
    fn state_frame(&mut self, report: &StateReport, counter: u64) -> Option<Frame>;
    /// The wheel-speed frame (FL, FR, RL, RR in m/s) with `counter` and its checksum, where
    /// the vehicle has one.
    fn wheel_speeds_frame(&mut self, speeds: [f64; 4], counter: u64) -> Option<Frame>;
    /// The wheel-angle frame (FL, FR, RL, RR in degrees) with `counter` and its checksum,
    /// where the vehicle has one.
    fn wheel_angles_frame(&mut self, angles: [f64; 4], counter: u64) -> Option<Frame>;
    /// The degradation report with `counter`, where the vehicle is fail-operational and has
    /// the message.
    fn degradation_frame(&mut self, _report: &DegradationReport, _counter: u64) -> Option<Frame> {
        None
    }
}
