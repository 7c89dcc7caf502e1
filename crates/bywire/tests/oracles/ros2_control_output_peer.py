"""The peers of `bywire ros2 control-output`: Cyclone DDS publishes Autoware Control commands,
python-can reads the bus (udp_multicast, inside lonet.sh) and cantools decodes the frames with
autoware-can.dbc; in the DDS modes the republished commands are read back. Prints one JSON
object.

usage: ros2_control_output_peer.py GROUP PORT DBC"""

import json
import math
import sys
import time

import can
import cantools

from ros2_types import Control, control, participant, reader, take_until, writer

group, port, dbc = sys.argv[1], int(sys.argv[2]), sys.argv[3]
db = cantools.database.load_file(dbc)
dp = participant()
commands = writer(dp, "rt/control/trajectory_follower/control_cmd", Control, depth=1)
republished = reader(dp, "rt/control/command/control_cmd", Control, depth=100)
bus = can.Bus(interface="udp_multicast", channel=group, port=port)


def frames_until(wanted, timeout):
    got, end = [], time.monotonic() + timeout
    while time.monotonic() < end and not wanted(got):
        m = bus.recv(0.05)
        if m is not None:
            got.append(m)
    return got


# Warm up: the subscription must be matched before a reliable depth-1 writer's sample counts.
# A command is sent until something shows it arrived (a frame in the CAN modes, a republished
# sample in the DDS-only mode).
for _ in range(200):
    commands.write(control(0.0, 0.0, 0.0, 0.0, 1))
    if frames_until(lambda g: len(g) > 0, 0.05) or republished.take(N=10):
        break
else:
    sys.exit("the control output never answered")
time.sleep(0.3)
while bus.recv(0.1) is not None:
    pass
republished.take(N=1000)

sent = [
    (0.25, -0.5, 2.5, -1.25, 1_700_000_000_123_000_000),
    (-0.75, 0.125, -1.0, 0.5, 1_700_000_000_223_000_000),
    (math.nan, 0.0, 1.0, 0.0, 1_700_000_000_323_000_000),   # refused: not finite
    (0.0, 0.0, math.inf, 0.0, 1_700_000_000_423_000_000),   # refused: not finite
    (1.5, 0.0, 1.0, 0.0, 1_700_000_000_523_000_000),        # refused: beyond the angle limit
    (0.5, 0.0, 3.0, 0.25, 1_700_000_000_623_000_000),
    (0.125, 0.0, 1.5, -1e30, 1_700_000_000_723_000_000),     # braking harder than it can: a stop
]
for command in sent:
    commands.write(control(*command))
    time.sleep(0.05)
frames = frames_until(lambda g: False, 1.0)
back = take_until(republished, lambda g: len(g) >= 4, timeout=1.0)

print(json.dumps({
    "frames": [{"id": m.arbitration_id, "data": m.data.hex(),
                "signals": db.decode_message(m.arbitration_id, m.data)} for m in frames],
    "republished": [{"angle": s.lateral.steering_tire_angle, "velocity": s.longitudinal.velocity,
                     "sec": s.stamp.sec} for s in back],
}, default=str))
