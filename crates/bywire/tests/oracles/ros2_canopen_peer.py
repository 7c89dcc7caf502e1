"""The ROS 2 side of `bywire ros2 canopen` on Cyclone DDS, as a ros2_canopen user would call
it: init, velocity mode, targets (topic and service), halt and recover, then (after the test
kills the drive) the heartbeat loss. Prints one JSON object per phase on stdout.

usage: ros2_canopen_peer.py NAME (then reads 'lost' on stdin before the last phase)"""

import json
import sys
import time

from ros2_types import (Float64, JointState, ServiceClient, StringMsg, TargetRequest,
                        TargetResponse, TriggerRequest, TriggerResponse, participant, reader,
                        writer)

name = sys.argv[1]
dp = participant()
trigger = {s: ServiceClient(dp, f"/{name}/{s}", TriggerRequest, TriggerResponse)
           for s in ["init", "velocity_mode", "halt", "recover"]}
target_service = ServiceClient(dp, f"/{name}/target", TargetRequest, TargetResponse)
target_topic = writer(dp, f"rt/{name}/target", Float64)
joints = reader(dp, f"rt/{name}/joint_states", JointState, depth=100)
nmt = reader(dp, f"rt/{name}/nmt_state", StringMsg, depth=100)
drive_state = reader(dp, f"rt/{name}/drive_state", StringMsg, depth=100)


def latest(r, timeout=5.0):
    end = time.monotonic() + timeout
    got = None
    while time.monotonic() < end and got is None:
        samples = r.take(N=100)
        if samples:
            got = samples[-1]
        time.sleep(0.01)
    return got


def settled(r, want, timeout=5.0):
    """The topic's last text once it reads `want`, or after `timeout` whatever it last read: a
    service's reply can arrive before the state sample it caused."""
    end = time.monotonic() + timeout
    last = None
    while time.monotonic() < end:
        samples = r.take(N=100)
        if samples:
            last = samples[-1].data
            if last == want:
                break
        time.sleep(0.01)
    return last


def velocity_after(seconds):
    time.sleep(seconds)
    joints.take(N=1000)
    j = latest(joints)
    return j.velocity[0] if j else None


def call(service, **fields):
    reply = trigger[service].call(**fields, structure_needs_at_least_one_member=0)
    return None if reply is None else {"success": reply.success, "message": reply.message}


out = {"init": call("init"), "velocity_mode": call("velocity_mode")}
out["nmt"] = settled(nmt, "operational")
out["state"] = settled(drive_state, "operation enabled")
for _ in range(20):
    target_topic.write(Float64(data=1000.0))
    time.sleep(0.05)
out["velocity_topic"] = velocity_after(1.5)
reply = target_service.call(target=-500.0)
out["target_service"] = reply.success if reply else None
out["velocity_service"] = velocity_after(1.5)
out["halt"] = call("halt")
time.sleep(0.3)
drive_state.take(N=1000)
out["halted_state"] = latest(drive_state).data
out["velocity_halted"] = velocity_after(1.0)
out["recover"] = call("recover")
print(json.dumps(out), flush=True)

sys.stdin.readline()  # the drive has been killed
time.sleep(1.0)
nmt.take(N=1000)
drive_state.take(N=1000)
print(json.dumps({"nmt": latest(nmt).data, "state": latest(drive_state).data}), flush=True)
