"""ROS 2 message types for Cyclone DDS (Python), declared under their ROS 2 DDS type names, so a
Cyclone participant talks to ROS 2 nodes (and to bywire) as an rclpy node on rmw_cyclonedds
would. Field order is the .msg order: CDR carries no names.

Always run with CYCLONEDDS_URI bound to the loopback interface (see participant())."""

import os
import time
from dataclasses import dataclass

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import array, float32, float64, int32, int64, sequence, uint8, uint32, uint64
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

LOOPBACK = ("<CycloneDDS><Domain><General><Interfaces><NetworkInterface name=\"lo\"/>"
            "</Interfaces></General></Domain></CycloneDDS>")


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
class Frame(IdlStruct, typename="can_msgs::msg::dds_::Frame_"):
    header: Header
    id: uint32
    is_rtr: bool
    is_extended: bool
    is_error: bool
    dlc: uint8
    data: array[uint8, 8]


@dataclass
class FdFrame(IdlStruct, typename="ros2_socketcan_msgs::msg::dds_::FdFrame_"):
    header: Header
    id: uint32
    is_extended: bool
    is_error: bool
    len: uint8
    data: sequence[uint8, 64]


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
class SteeringReport(IdlStruct, typename="autoware_vehicle_msgs::msg::dds_::SteeringReport_"):
    stamp: Time
    steering_tire_angle: float32


@dataclass
class VelocityReport(IdlStruct, typename="autoware_vehicle_msgs::msg::dds_::VelocityReport_"):
    header: Header
    longitudinal_velocity: float32
    lateral_velocity: float32
    heading_rate: float32


@dataclass
class GearCommand(IdlStruct, typename="autoware_vehicle_msgs::msg::dds_::GearCommand_"):
    stamp: Time
    command: uint8


@dataclass
class GearReport(IdlStruct, typename="autoware_vehicle_msgs::msg::dds_::GearReport_"):
    stamp: Time
    report: uint8


@dataclass
class TurnIndicatorsCommand(IdlStruct,
                            typename="autoware_vehicle_msgs::msg::dds_::TurnIndicatorsCommand_"):
    stamp: Time
    command: uint8


@dataclass
class TurnIndicatorsReport(IdlStruct,
                           typename="autoware_vehicle_msgs::msg::dds_::TurnIndicatorsReport_"):
    stamp: Time
    report: uint8


@dataclass
class HazardLightsCommand(IdlStruct,
                          typename="autoware_vehicle_msgs::msg::dds_::HazardLightsCommand_"):
    stamp: Time
    command: uint8


@dataclass
class VehicleEmergencyStamped(IdlStruct,
                              typename="tier4_vehicle_msgs::msg::dds_::VehicleEmergencyStamped_"):
    stamp: Time
    emergency: bool


@dataclass
class HazardLightsReport(IdlStruct,
                         typename="autoware_vehicle_msgs::msg::dds_::HazardLightsReport_"):
    stamp: Time
    report: uint8


@dataclass
class ControlModeReport(IdlStruct, typename="autoware_vehicle_msgs::msg::dds_::ControlModeReport_"):
    stamp: Time
    mode: uint8


@dataclass
class JointState(IdlStruct, typename="sensor_msgs::msg::dds_::JointState_"):
    header: Header
    name: sequence[str]
    position: sequence[float64]
    velocity: sequence[float64]
    effort: sequence[float64]


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64
    y: float64
    z: float64


@dataclass
class Twist(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
    linear: Vector3
    angular: Vector3


@dataclass
class StringMsg(IdlStruct, typename="std_msgs::msg::dds_::String_"):
    data: str


@dataclass
class KeyValue(IdlStruct, typename="diagnostic_msgs::msg::dds_::KeyValue_"):
    key: str
    value: str


@dataclass
class DiagnosticStatus(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticStatus_"):
    level: uint8
    name: str
    message: str
    hardware_id: str
    values: sequence[KeyValue]


@dataclass
class DiagnosticArray(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticArray_"):
    header: Header
    status: sequence[DiagnosticStatus]


# rmw_cyclonedds puts a request header (the client's GUID as a number, a sequence number) in
# front of a service's request and response.
@dataclass
class ControlModeCommandRequest(
        IdlStruct, typename="autoware_vehicle_msgs::srv::dds_::ControlModeCommand_Request_"):
    client_guid: uint64
    sequence_number: int64
    stamp: Time
    mode: uint8


@dataclass
class ControlModeCommandResponse(
        IdlStruct, typename="autoware_vehicle_msgs::srv::dds_::ControlModeCommand_Response_"):
    client_guid: uint64
    sequence_number: int64
    success: bool


@dataclass
class Gid(IdlStruct, typename="rmw_dds_common::msg::dds_::Gid_"):
    data: array[uint8, 16]


@dataclass
class NodeEntitiesInfo(IdlStruct, typename="rmw_dds_common::msg::dds_::NodeEntitiesInfo_"):
    node_namespace: str
    node_name: str
    reader_gid_seq: sequence[Gid]
    writer_gid_seq: sequence[Gid]


@dataclass
class ParticipantEntitiesInfo(
        IdlStruct, typename="rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_"):
    gid: Gid
    node_entities_info_seq: sequence[NodeEntitiesInfo]


def participant(domain=0):
    os.environ["CYCLONEDDS_URI"] = LOOPBACK
    return DomainParticipant(domain)


def qos(depth=10, latched=False):
    durability = Policy.Durability.TransientLocal if latched else Policy.Durability.Volatile
    return Qos(Policy.Reliability.Reliable(max_blocking_time=1_000_000_000), durability,
               Policy.History.KeepLast(depth))


def reader(dp, name, kind, depth=10, latched=False):
    return DataReader(dp, Topic(dp, name, kind), qos=qos(depth, latched))


def writer(dp, name, kind, depth=10):
    return DataWriter(dp, Topic(dp, name, kind), qos=qos(depth))


def take_until(reader, wanted, timeout=10.0):
    """Samples from `reader` until `wanted(samples so far)` or the timeout; returns them all."""
    got = []
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        got.extend(reader.take(N=256))
        if wanted(got):
            return got
        time.sleep(0.005)
    return got


def stamp(nanos):
    return Time(sec=nanos // 1_000_000_000, nanosec=nanos % 1_000_000_000)


def control(angle, rate, velocity, acceleration, nanos):
    """An Autoware Control command with these setpoints, stamped `nanos`."""
    t = stamp(nanos)
    return Control(
        stamp=t, control_time=t,
        lateral=Lateral(stamp=t, control_time=t, steering_tire_angle=angle,
                        steering_tire_rotation_rate=rate,
                        is_defined_steering_tire_rotation_rate=True),
        longitudinal=Longitudinal(stamp=t, control_time=t, velocity=velocity,
                                  acceleration=acceleration, jerk=0.0,
                                  is_defined_acceleration=True, is_defined_jerk=False))


@dataclass
class Float64(IdlStruct, typename="std_msgs::msg::dds_::Float64_"):
    data: float64


@dataclass
class TriggerRequest(IdlStruct, typename="std_srvs::srv::dds_::Trigger_Request_"):
    client_guid: uint64
    sequence_number: int64
    structure_needs_at_least_one_member: uint8


@dataclass
class TriggerResponse(IdlStruct, typename="std_srvs::srv::dds_::Trigger_Response_"):
    client_guid: uint64
    sequence_number: int64
    success: bool
    message: str


@dataclass
class TargetRequest(IdlStruct, typename="canopen_interfaces::srv::dds_::COTargetDouble_Request_"):
    client_guid: uint64
    sequence_number: int64
    target: float64


@dataclass
class TargetResponse(IdlStruct, typename="canopen_interfaces::srv::dds_::COTargetDouble_Response_"):
    client_guid: uint64
    sequence_number: int64
    success: bool


class ServiceClient:
    """A ROS 2 service client as rmw_cyclonedds frames its calls (request header first)."""

    def __init__(self, dp, name, request, response):
        self.requests = writer(dp, f"rq{name}Request", request)
        self.replies = reader(dp, f"rr{name}Reply", response)
        self.request = request
        self.sequence = 0

    def call(self, timeout=5.0, **fields):
        """The reply, retrying until the service is matched; None if none came."""
        self.sequence += 1
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            self.requests.write(self.request(client_guid=77, sequence_number=self.sequence,
                                             **fields))
            until = min(end, time.monotonic() + 0.5)
            while time.monotonic() < until:
                for reply in self.replies.take(N=10):
                    if reply.sequence_number == self.sequence:
                        return reply
                time.sleep(0.01)
        return None
