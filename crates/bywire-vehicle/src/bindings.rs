//! A profile's roles found in its DBC once, when the profile loads
//! (`LoadedProfile::bindings`): each role's message (its place among the DBC's messages) and
//! signals (their places in the message). Everything that reads a vehicle by role (the
//! profile's wire, tools that name its signals) takes these places; a name the DBC does not
//! have is refused when the profile loads, and only then, naming the key.

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

/// One signal of one message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SignalBinding {
    /// The message.
    pub message: usize,
    /// The signal.
    pub signal: usize,
}

/// A status message whose arrival is a heartbeat, with an optional signal in it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StatusBinding {
    /// The message.
    pub message: usize,
    /// The signal (a control ECU's role; an actuator's fault flag).
    pub signal: Option<usize>,
}

/// A quantity's three sensors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VotedBindings {
    /// The channels.
    pub channels: [SignalBinding; 3],
}

/// Where an actuator's status comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ActuatorStatusBinding {
    /// A status message of the profile's DBC.
    Message(StatusBinding),
    /// A CiA 402 drive at this node ID.
    CanOpen(u8),
}

/// What measures an actuator pair's rate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MeasuredBinding {
    /// A signal carrying it.
    Signal(SignalBinding),
    /// The rate of change of the voted quantity at this index of `voted`.
    VotedRate(usize),
}

/// An actuator and its backup.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ActuatorPairBindings {
    /// The primary's status.
    pub primary: ActuatorStatusBinding,
    /// The backup's status.
    pub backup: ActuatorStatusBinding,
    /// The measured rate.
    pub measured: MeasuredBinding,
}

/// The degradation report's roles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReportBindings {
    /// The message.
    pub message: usize,
    /// The level.
    pub level: usize,
    /// The fault class it is reported with.
    pub reason: Option<usize>,
}

/// The `[fail_operational]` section's roles, in the section's order.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct FailOperationalBindings {
    /// Each voted quantity.
    pub voted: Vec<VotedBindings>,
    /// The two control ECUs' status messages (their role signals always bound), A then B.
    pub control: Option<[StatusBinding; 2]>,
    /// Each actuator pair.
    pub actuators: Vec<ActuatorPairBindings>,
    /// The degradation report.
    pub report: Option<ReportBindings>,
}

/// Every role a profile names, found in its DBC.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
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
    /// `[fail_operational]`.
    pub fail_operational: Option<FailOperationalBindings>,
}
