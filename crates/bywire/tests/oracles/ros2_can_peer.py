"""The peers of `bywire ros2 can`: Cyclone DDS on the ROS 2 topics, python-can on the bus
(udp_multicast, inside lonet.sh). Prints one JSON object with everything each side saw.

usage: ros2_can_peer.py GROUP PORT [NAMESPACE]"""

import json
import sys
import time

import can

from ros2_types import (FdFrame, Frame, Header, ParticipantEntitiesInfo, participant, reader,
                        stamp, take_until, writer)

group, port = sys.argv[1], int(sys.argv[2])
namespace = sys.argv[3] if len(sys.argv) > 3 else ""
topic = lambda name: f"rt{namespace}/{name}"

dp = participant()
from_bus = reader(dp, topic("from_can_bus"), Frame, depth=500)
from_bus_fd = reader(dp, topic("from_can_bus_fd"), FdFrame, depth=500)
to_bus = writer(dp, topic("to_can_bus"), Frame, depth=500)
to_bus_fd = writer(dp, topic("to_can_bus_fd"), FdFrame, depth=500)
graph = reader(dp, "ros_discovery_info", ParticipantEntitiesInfo, depth=1, latched=True)
bus = can.Bus(interface="udp_multicast", channel=group, port=port, fd=True)


def frame_msg(id, data=b"", dlc=None, rtr=False, ext=False, err=False):
    padded = list(data) + [0] * (8 - len(data))
    return Frame(header=Header(stamp=stamp(0), frame_id="py"), id=id, is_rtr=rtr,
                 is_extended=ext, is_error=err, dlc=len(data) if dlc is None else dlc,
                 data=padded)


def fd_msg(id, data, ext=False):
    return FdFrame(header=Header(stamp=stamp(0), frame_id="py"), id=id, is_extended=ext,
                   is_error=False, len=len(data), data=list(data))


def bus_frames(wanted, timeout=10.0):
    got, end = [], time.monotonic() + timeout
    while time.monotonic() < end and not wanted(got):
        m = bus.recv(0.05)
        if m is not None:
            got.append(m)
    return got


def as_dict(m):
    return {"id": m.arbitration_id, "ext": m.is_extended_id, "rtr": m.is_remote_frame,
            "fd": m.is_fd, "brs": m.bitrate_switch, "dlc": m.dlc, "data": m.data.hex()}


# Warm up both ways: DDS discovery takes a moment.
seen = []
for _ in range(200):
    bus.send(can.Message(arbitration_id=0x7F0, data=b"\x01", is_extended_id=False))
    seen = take_until(from_bus, lambda g: any(s.id == 0x7F0 for s in g), timeout=0.05)
    if seen:
        break
if not seen:
    sys.exit("nothing from from_can_bus")
back = []
for _ in range(200):
    to_bus.write(frame_msg(0x7F1, b"\x02"))
    back = bus_frames(lambda g: any(m.arbitration_id == 0x7F1 for m in g), timeout=0.05)
    if any(m.arbitration_id == 0x7F1 for m in back):
        break
else:
    sys.exit("nothing from to_can_bus reached the bus")
time.sleep(0.3)
from_bus.take(N=1000)
from_bus_fd.take(N=1000)
while bus.recv(0.05) is not None:
    pass

# The bus to DDS.
sent = [
    can.Message(arbitration_id=0x123, data=bytes.fromhex("DEADBEEF"), is_extended_id=False),
    can.Message(arbitration_id=0x1ABCDEF0, data=b"\x01\x02", is_extended_id=True),
    can.Message(arbitration_id=0x321, is_remote_frame=True, dlc=3, is_extended_id=False),
    can.Message(arbitration_id=0x456, data=bytes(range(12)), is_fd=True, bitrate_switch=True,
                is_extended_id=False),
    can.Message(arbitration_id=0x18DAF110, data=bytes(range(64)), is_fd=True,
                is_extended_id=True),
    # The bridge's filter (7FE~7FF: all but 0x7FE) keeps this one off DDS.
    can.Message(arbitration_id=0x7FE, data=b"\xfe", is_extended_id=False),
]
for m in sent:
    bus.send(m)
classic = take_until(from_bus, lambda g: len(g) >= 3)
fd = take_until(from_bus_fd, lambda g: len(g) >= 2)

# DDS to the bus: classic, extended, remote, FD; then on each topic a message no frame can
# carry, then a marker, so that whatever a bad message might have sent is on the bus before it.
# (python-can hears its own datagrams: those sent above are drained first.)
while bus.recv(0.1) is not None:
    pass
to_bus.write(frame_msg(0x124, bytes.fromhex("CAFE")))
to_bus.write(frame_msg(0x1ABCDEF1, b"\x09" * 8, ext=True))
to_bus.write(frame_msg(0x322, dlc=5, rtr=True))
to_bus_fd.write(fd_msg(0x457, bytes(range(20))))
to_bus_fd.write(fd_msg(0x1FFFFFFF, bytes(range(48)), ext=True))
to_bus.write(frame_msg(0x800, b"\x01"))
to_bus_fd.write(fd_msg(0x458, bytes(range(9))))
to_bus.write(frame_msg(0x333, b"\x33"))
to_bus_fd.write(fd_msg(0x459, b"\x59"))
received = bus_frames(lambda g: {0x333, 0x459} <= {m.arbitration_id for m in g})
# With loopback on, what the bridge sent is published too (as a second socket sees it).
looped = take_until(from_bus, lambda g: any(s.id == 0x333 for s in g))

nodes = []
for info in take_until(graph, lambda g: any(n.node_name == "socket_can_bridge"
                                            for s in g for n in s.node_entities_info_seq)):
    nodes.extend({"namespace": n.node_namespace, "name": n.node_name,
                  "readers": len(n.reader_gid_seq), "writers": len(n.writer_gid_seq)}
                 for n in info.node_entities_info_seq)

print(json.dumps({
    "classic": [{"id": s.id, "ext": s.is_extended, "rtr": s.is_rtr, "err": s.is_error,
                 "dlc": s.dlc, "data": bytes(s.data).hex(), "frame_id": s.header.frame_id,
                 "stamp": s.header.stamp.sec + s.header.stamp.nanosec / 1e9} for s in classic],
    "fd": [{"id": s.id, "ext": s.is_extended, "len": s.len, "data": bytes(s.data).hex()}
           for s in fd],
    "bus": [as_dict(m) for m in received],
    "looped": [s.id for s in looped],
    "nodes": nodes,
    "wall": time.time(),
}))
