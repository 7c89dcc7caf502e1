//! The ROS 2 messages bywire speaks, as serde structs whose fields are in the order of their
//! `.msg` definitions: CDR has no field names, so the order *is* the wire format. Each type
//! names its ROS 2 package and type ([`RosType`]); DDS sees `pkg::msg::dds_::Type_`.
//!
//! Constants the `.msg` files declare (gear codes, control modes, …) are given next to the
//! type that carries them.

use serde::{Deserialize, Serialize};

/// A message type's ROS 2 name.
pub trait RosType {
    /// The package, e.g. `can_msgs`.
    const PACKAGE: &'static str;
    /// The type, e.g. `Frame`.
    const NAME: &'static str;
}

macro_rules! ros_type {
    ($type:ty, $package:literal, $name:literal) => {
        impl RosType for $type {
            const PACKAGE: &'static str = $package;
            const NAME: &'static str = $name;
        }
    };
}

/// `builtin_interfaces/msg/Time`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Time {
    /// Seconds (since the Unix epoch for wall-clock stamps).
    pub sec: i32,
    /// Nanoseconds within the second.
    pub nanosec: u32,
}
ros_type!(Time, "builtin_interfaces", "Time");

impl Time {
    /// A stamp from nanoseconds; beyond 2038 the seconds saturate (as `int32` must).
    pub fn from_nanos(nanos: u64) -> Time {
        Time {
            sec: i32::try_from(nanos / 1_000_000_000).unwrap_or(i32::MAX),
            nanosec: u32::try_from(nanos % 1_000_000_000).unwrap_or(0),
        }
    }

    /// Now on the wall clock, as ROS 2 stamps messages.
    pub fn now() -> Time {
        let since_epoch = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap_or_default();
        Time::from_nanos(u64::try_from(since_epoch.as_nanos()).unwrap_or(u64::MAX))
    }

    /// Nanoseconds; a negative time is zero.
    pub fn as_nanos(self) -> u64 {
        match u64::try_from(self.sec) {
            Ok(sec) => sec
                .saturating_mul(1_000_000_000)
                .saturating_add(u64::from(self.nanosec.min(999_999_999))),
            Err(_) => 0,
        }
    }
}

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Header {
    /// When.
    pub stamp: Time,
    /// The frame of reference; for CAN messages, the bus.
    pub frame_id: String,
}
ros_type!(Header, "std_msgs", "Header");

/// `can_msgs/msg/Frame` (ros2_socketcan's classic frames).
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct CanFrame {
    /// Stamp and bus.
    pub header: Header,
    /// The identifier (11 or 29 bits); for an error frame, the SocketCAN error class bits.
    pub id: u32,
    /// A remote frame.
    pub is_rtr: bool,
    /// A 29-bit identifier.
    pub is_extended: bool,
    /// An error frame.
    pub is_error: bool,
    /// The data length code (0–8; up to 15 as SocketCAN's `len8_dlc` carries it).
    pub dlc: u8,
    /// The data, zero beyond the length.
    pub data: [u8; 8],
}
ros_type!(CanFrame, "can_msgs", "Frame");

/// `ros2_socketcan_msgs/msg/FdFrame`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct FdFrame {
    /// Stamp and bus.
    pub header: Header,
    /// The identifier.
    pub id: u32,
    /// A 29-bit identifier.
    pub is_extended: bool,
    /// An error frame.
    pub is_error: bool,
    /// The data length in bytes (0–64, one of CAN FD's lengths).
    pub len: u8,
    /// The data (`uint8[<=64]`).
    pub data: Vec<u8>,
}
ros_type!(FdFrame, "ros2_socketcan_msgs", "FdFrame");

/// `autoware_control_msgs/msg/Lateral`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Lateral {
    /// When the command was made.
    pub stamp: Time,
    /// When it is meant to act.
    pub control_time: Time,
    /// Steering tire angle, rad (positive left).
    pub steering_tire_angle: f32,
    /// Its rate, rad/s.
    pub steering_tire_rotation_rate: f32,
    /// Whether the rate means anything.
    pub is_defined_steering_tire_rotation_rate: bool,
}
ros_type!(Lateral, "autoware_control_msgs", "Lateral");

/// `autoware_control_msgs/msg/Longitudinal`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Longitudinal {
    /// When the command was made.
    pub stamp: Time,
    /// When it is meant to act.
    pub control_time: Time,
    /// Velocity, m/s (negative in reverse).
    pub velocity: f32,
    /// Acceleration, m/s².
    pub acceleration: f32,
    /// Jerk, m/s³.
    pub jerk: f32,
    /// Whether the acceleration means anything.
    pub is_defined_acceleration: bool,
    /// Whether the jerk means anything.
    pub is_defined_jerk: bool,
}
ros_type!(Longitudinal, "autoware_control_msgs", "Longitudinal");

/// `autoware_control_msgs/msg/Control`: the controller's final command.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Control {
    /// When the command was made.
    pub stamp: Time,
    /// When it is meant to act.
    pub control_time: Time,
    /// Steering.
    pub lateral: Lateral,
    /// Speed.
    pub longitudinal: Longitudinal,
}
ros_type!(Control, "autoware_control_msgs", "Control");

/// `autoware_vehicle_msgs/msg/SteeringReport`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct SteeringReport {
    /// When.
    pub stamp: Time,
    /// Steering tire angle, rad.
    pub steering_tire_angle: f32,
}
ros_type!(SteeringReport, "autoware_vehicle_msgs", "SteeringReport");

/// `autoware_vehicle_msgs/msg/VelocityReport`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct VelocityReport {
    /// Stamp and frame (`base_link`).
    pub header: Header,
    /// Along the vehicle, m/s.
    pub longitudinal_velocity: f32,
    /// Across it, m/s (crab steering makes it non-zero).
    pub lateral_velocity: f32,
    /// Yaw rate, rad/s.
    pub heading_rate: f32,
}
ros_type!(VelocityReport, "autoware_vehicle_msgs", "VelocityReport");

/// Gear codes of `GearCommand` and `GearReport` (the ones a tug has).
pub mod gear {
    /// No command.
    pub const NONE: u8 = 0;
    /// Neutral.
    pub const NEUTRAL: u8 = 1;
    /// Drive.
    pub const DRIVE: u8 = 2;
    /// Reverse.
    pub const REVERSE: u8 = 20;
    /// Park.
    pub const PARK: u8 = 22;
}

/// `autoware_vehicle_msgs/msg/GearCommand`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct GearCommand {
    /// When.
    pub stamp: Time,
    /// A [`gear`] code.
    pub command: u8,
}
ros_type!(GearCommand, "autoware_vehicle_msgs", "GearCommand");

/// `autoware_vehicle_msgs/msg/GearReport`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct GearReport {
    /// When.
    pub stamp: Time,
    /// A [`gear`] code.
    pub report: u8,
}
ros_type!(GearReport, "autoware_vehicle_msgs", "GearReport");

/// Control modes of `ControlModeReport` and the `ControlModeCommand` service.
pub mod control_mode {
    /// No command (the service ignores it).
    pub const NO_COMMAND: u8 = 0;
    /// The ADS drives.
    pub const AUTONOMOUS: u8 = 1;
    /// The ADS steers only.
    pub const AUTONOMOUS_STEER_ONLY: u8 = 2;
    /// The ADS controls the speed only.
    pub const AUTONOMOUS_VELOCITY_ONLY: u8 = 3;
    /// A driver (or operator) drives.
    pub const MANUAL: u8 = 4;
    /// Disengaged (report only).
    pub const DISENGAGED: u8 = 5;
    /// Not ready (report only).
    pub const NOT_READY: u8 = 6;
}

/// `autoware_vehicle_msgs/msg/ControlModeReport`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct ControlModeReport {
    /// When.
    pub stamp: Time,
    /// A [`control_mode`] code.
    pub mode: u8,
}
ros_type!(
    ControlModeReport,
    "autoware_vehicle_msgs",
    "ControlModeReport"
);

/// Codes of the turn-indicator messages.
pub mod turn_indicators {
    /// No command.
    pub const NO_COMMAND: u8 = 0;
    /// Off.
    pub const DISABLE: u8 = 1;
    /// Left.
    pub const ENABLE_LEFT: u8 = 2;
    /// Right.
    pub const ENABLE_RIGHT: u8 = 3;
}

/// `autoware_vehicle_msgs/msg/TurnIndicatorsCommand`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct TurnIndicatorsCommand {
    /// When.
    pub stamp: Time,
    /// A [`turn_indicators`] code.
    pub command: u8,
}
ros_type!(
    TurnIndicatorsCommand,
    "autoware_vehicle_msgs",
    "TurnIndicatorsCommand"
);

/// `autoware_vehicle_msgs/msg/TurnIndicatorsReport`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct TurnIndicatorsReport {
    /// When.
    pub stamp: Time,
    /// A [`turn_indicators`] code (not `NO_COMMAND`).
    pub report: u8,
}
ros_type!(
    TurnIndicatorsReport,
    "autoware_vehicle_msgs",
    "TurnIndicatorsReport"
);

/// Codes of the hazard-light messages.
pub mod hazard_lights {
    /// No command.
    pub const NO_COMMAND: u8 = 0;
    /// Off.
    pub const DISABLE: u8 = 1;
    /// On.
    pub const ENABLE: u8 = 2;
}

/// `autoware_vehicle_msgs/msg/HazardLightsCommand`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct HazardLightsCommand {
    /// When.
    pub stamp: Time,
    /// A [`hazard_lights`] code.
    pub command: u8,
}
ros_type!(
    HazardLightsCommand,
    "autoware_vehicle_msgs",
    "HazardLightsCommand"
);

/// `tier4_vehicle_msgs/msg/VehicleEmergencyStamped`: Autoware's emergency (`emergency_cmd`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct VehicleEmergencyStamped {
    /// When.
    pub stamp: Time,
    /// Stop as hard as the vehicle can.
    pub emergency: bool,
}
ros_type!(
    VehicleEmergencyStamped,
    "tier4_vehicle_msgs",
    "VehicleEmergencyStamped"
);

/// `autoware_vehicle_msgs/msg/HazardLightsReport`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct HazardLightsReport {
    /// When.
    pub stamp: Time,
    /// A [`hazard_lights`] code (not `NO_COMMAND`).
    pub report: u8,
}
ros_type!(
    HazardLightsReport,
    "autoware_vehicle_msgs",
    "HazardLightsReport"
);

/// The request of the `autoware_vehicle_msgs/srv/ControlModeCommand` service.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct ControlModeRequest {
    /// When.
    pub stamp: Time,
    /// A [`control_mode`] code (`AUTONOMOUS` engages, `MANUAL` disengages).
    pub mode: u8,
}

/// The response of `ControlModeCommand`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct ControlModeResponse {
    /// Whether the vehicle took the request.
    pub success: bool,
}

/// `geometry_msgs/msg/Vector3`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}
ros_type!(Vector3, "geometry_msgs", "Vector3");

/// `geometry_msgs/msg/Twist`: `cmd_vel` for robot-style stacks.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Twist {
    /// m/s in the vehicle frame (x forward, y left).
    pub linear: Vector3,
    /// rad/s (z: yaw rate).
    pub angular: Vector3,
}
ros_type!(Twist, "geometry_msgs", "Twist");

/// `sensor_msgs/msg/JointState`: the per-wheel truth (steer angles and drive speeds).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct JointState {
    /// Stamp and frame.
    pub header: Header,
    /// Joint names.
    pub name: Vec<String>,
    /// Positions (rad for steering joints).
    pub position: Vec<f64>,
    /// Velocities (rad/s of the wheel for drive joints).
    pub velocity: Vec<f64>,
    /// Efforts (empty when unknown).
    pub effort: Vec<f64>,
}
ros_type!(JointState, "sensor_msgs", "JointState");

/// `geometry_msgs/msg/Point`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Point {
    /// x, m.
    pub x: f64,
    /// y, m.
    pub y: f64,
    /// z, m.
    pub z: f64,
}
ros_type!(Point, "geometry_msgs", "Point");

/// `geometry_msgs/msg/Quaternion`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}
ros_type!(Quaternion, "geometry_msgs", "Quaternion");

impl Quaternion {
    /// A rotation of `yaw` rad about z.
    pub fn from_yaw(yaw: f64) -> Quaternion {
        Quaternion {
            x: 0.0,
            y: 0.0,
            z: libm::sin(yaw / 2.0),
            w: libm::cos(yaw / 2.0),
        }
    }
}

/// `geometry_msgs/msg/Pose`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose {
    /// Position.
    pub position: Point,
    /// Orientation.
    pub orientation: Quaternion,
}
ros_type!(Pose, "geometry_msgs", "Pose");

/// A 6×6 covariance (`float64[36]`, row-major). Serde derives arrays of up to 32: the 36
/// values are two arrays back to back, which CDR writes exactly as one (no padding between
/// `f64`s).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Covariance {
    /// Values 0–31.
    pub head: [f64; 32],
    /// Values 32–35.
    pub tail: [f64; 4],
}

/// `geometry_msgs/msg/PoseWithCovariance`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    /// The pose.
    pub pose: Pose,
    /// Its covariance.
    pub covariance: Covariance,
}
ros_type!(PoseWithCovariance, "geometry_msgs", "PoseWithCovariance");

/// `geometry_msgs/msg/TwistWithCovariance`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct TwistWithCovariance {
    /// The twist.
    pub twist: Twist,
    /// Its covariance.
    pub covariance: Covariance,
}
ros_type!(TwistWithCovariance, "geometry_msgs", "TwistWithCovariance");

/// `nav_msgs/msg/Odometry`: the simulated vehicle's true pose (Autoware's
/// `/localization/kinematic_state`).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Odometry {
    /// Stamp and the world frame (`map`).
    pub header: Header,
    /// The body frame (`base_link`).
    pub child_frame_id: String,
    /// Where the body is.
    pub pose: PoseWithCovariance,
    /// How it moves, in the body frame.
    pub twist: TwistWithCovariance,
}
ros_type!(Odometry, "nav_msgs", "Odometry");

/// `std_msgs/msg/Float64` (a drive's target topic).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Float64 {
    /// The value.
    pub data: f64,
}
ros_type!(Float64, "std_msgs", "Float64");

/// `std_msgs/msg/String` (the steering-mode topic of ours: `normal`, `crab`, `tank`).
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct StringMsg {
    /// The text.
    pub data: String,
}
ros_type!(StringMsg, "std_msgs", "String");

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stamps_split_nanoseconds_and_saturate() {
        let t = Time::from_nanos(1_700_000_000_123_456_789);
        assert_eq!((t.sec, t.nanosec), (1_700_000_000, 123_456_789));
        assert_eq!(t.as_nanos(), 1_700_000_000_123_456_789);
        assert_eq!(Time::from_nanos(u64::MAX).sec, i32::MAX);
        assert_eq!(
            Time {
                sec: -5,
                nanosec: 7
            }
            .as_nanos(),
            0
        );
    }
}

/// `diagnostic_msgs/msg/KeyValue`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct KeyValue {
    /// What is reported.
    pub key: String,
    /// Its value.
    pub value: String,
}
ros_type!(KeyValue, "diagnostic_msgs", "KeyValue");

/// `diagnostic_msgs/msg/DiagnosticStatus`: one component's level and state.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    /// [`DiagnosticStatus::OK`], `WARN`, `ERROR` or `STALE`.
    pub level: u8,
    /// The component (`diagnostic_aggregator` groups by its prefix).
    pub name: String,
    /// What is wrong, or the state in a few words.
    pub message: String,
    /// The hardware it is about.
    pub hardware_id: String,
    /// Details.
    pub values: Vec<KeyValue>,
}
ros_type!(DiagnosticStatus, "diagnostic_msgs", "DiagnosticStatus");

impl DiagnosticStatus {
    /// Working.
    pub const OK: u8 = 0;
    /// Working with a warning.
    pub const WARN: u8 = 1;
    /// Not working.
    pub const ERROR: u8 = 2;
    /// Nothing heard from it.
    pub const STALE: u8 = 3;
}

/// `diagnostic_msgs/msg/DiagnosticArray`, as `/diagnostics` carries it.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct DiagnosticArray {
    /// When.
    pub header: Header,
    /// One status per component.
    pub status: Vec<DiagnosticStatus>,
}
ros_type!(DiagnosticArray, "diagnostic_msgs", "DiagnosticArray");
