"""Drive the simulated tug over ROS 2 from Python, as Autoware would: engage through the
control-mode service, publish control_cmd at 30 Hz (a gentle left curve at 1.5 m/s), watch the
velocity report and the true pose, then stop and disengage.

Needs `pip install cyclonedds` and `bywire sim --ros2` running (both on the loopback interface:
CYCLONEDDS_URI is set below; give bywire `--dds-interface lo`)."""

import math
import os
import time
from dataclasses import dataclass

os.environ.setdefault("CYCLONEDDS_URI", "<CycloneDDS><Domain><General><Interfaces>"
                      "<NetworkInterface name=\"lo\"/></Interfaces></General></Domain></CycloneDDS>")

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import array, float32, float64, int32, int64, uint8, uint32, uint64
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic


# ROS 2 messages, under their DDS type names (field order as in the .msg files).
@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
class Lateral(IdlStruct, typename="autoware_control_msgs::msg::dds_::Lateral_"):
    stamp: Time
    control_time: Time
    steering_tire_angle: float32
    steering_tire_rotation_rate: float32
    is_defined_steering_tire_rotation_rate: bool


@dataclass
class Longitudinal(IdlStruct, typename="autoware_control_msgs::msg::dds_::Longitudinal_"):
    stamp: Time
    control_time: Time
    velocity: float32
    acceleration: float32
    jerk: float32
    is_defined_acceleration: bool
    is_defined_jerk: bool


@dataclass
class Control(IdlStruct, typename="autoware_control_msgs::msg::dds_::Control_"):
    stamp: Time
    control_time: Time
    lateral: Lateral
    longitudinal: Longitudinal


@dataclass
class VelocityReport(IdlStruct, typename="autoware_vehicle_msgs::msg::dds_::VelocityReport_"):
    header: Header
    longitudinal_velocity: float32
    lateral_velocity: float32
    heading_rate: float32


@dataclass
class Vec3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64
    y: float64
    z: float64


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64
    y: float64
    z: float64
    w: float64


@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Vec3
    orientation: Quaternion


@dataclass
class PoseWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose
    covariance: array[float64, 36]


@dataclass
class Twist(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
    linear: Vec3
    angular: Vec3


@dataclass
class TwistWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::TwistWithCovariance_"):
    twist: Twist
    covariance: array[float64, 36]


@dataclass
class Odometry(IdlStruct, typename="nav_msgs::msg::dds_::Odometry_"):
    header: Header
    child_frame_id: str
    pose: PoseWithCovariance
    twist: TwistWithCovariance


# A service request and reply as rmw_cyclonedds frames them: the client's id and a sequence
# number first.
@dataclass
class ModeRequest(IdlStruct,
                  typename="autoware_vehicle_msgs::srv::dds_::ControlModeCommand_Request_"):
    client: uint64
    sequence: int64
    stamp: Time
    mode: uint8


@dataclass
class ModeReply(IdlStruct,
                typename="autoware_vehicle_msgs::srv::dds_::ControlModeCommand_Response_"):
    client: uint64
    sequence: int64
    success: bool


qos = Qos(Policy.Reliability.Reliable(max_blocking_time=1_000_000_000),
          Policy.Durability.Volatile, Policy.History.KeepLast(10))
dp = DomainParticipant(0)
commands = DataWriter(dp, Topic(dp, "rt/control/command/control_cmd", Control), qos=qos)
requests = DataWriter(dp, Topic(dp, "rq/control/control_mode_requestRequest", ModeRequest), qos=qos)
replies = DataReader(dp, Topic(dp, "rr/control/control_mode_requestReply", ModeReply), qos=qos)
velocity = DataReader(dp, Topic(dp, "rt/vehicle/status/velocity_status", VelocityReport), qos=qos)
pose = DataReader(dp, Topic(dp, "rt/localization/kinematic_state", Odometry), qos=qos)


def now():
    t = time.time_ns()
    return Time(sec=t // 1_000_000_000, nanosec=t % 1_000_000_000)


def command(angle, speed):
    t = now()
    commands.write(Control(
        stamp=t, control_time=t,
        lateral=Lateral(t, t, angle, 0.0, False),
        longitudinal=Longitudinal(t, t, speed, 0.3 if speed > 0 else -1.0, 0.0, True, False)))


def set_mode(mode, sequence):
    """Ask for a control mode (1 autonomous, 4 manual); the answer, or None if none came."""
    for _ in range(100):  # until the service is matched and answers
        requests.write(ModeRequest(client=42, sequence=sequence, stamp=now(), mode=mode))
        for _ in range(60):
            command(0.0, 0.0)  # keep commanding while waiting: a silent ADS is stopped
            for reply in replies.take(N=10):
                if reply.sequence == sequence:
                    return reply.success
            time.sleep(1 / 30)
    return None


print("engaged:", set_mode(1, sequence=1))
for i in range(150):  # five seconds of a left curve at 1.5 m/s
    command(0.15, 1.5)
    time.sleep(1 / 30)
v = [s.longitudinal_velocity for s in velocity.take(N=1000)]
p = pose.take(N=1000)[-1].pose.pose
yaw = 2 * math.atan2(p.orientation.z, p.orientation.w)
print(f"speed {max(v):.2f} m/s; at x={p.position.x:.1f} y={p.position.y:.1f} yaw={yaw:.2f}")
for i in range(90):  # three seconds of stopping
    command(0.0, 0.0)
    time.sleep(1 / 30)
print("disengaged:", set_mode(4, sequence=2))
