"""An Autoware stand-in for `bywire ros2 vehicle`, on Cyclone DDS: publishes control_cmd at
40 Hz, engages through the ControlModeCommand service (rmw_cyclonedds's request header), reads
the vehicle's reports (first for a second before any command), stops publishing (the vehicle
must stop), then disengages. Midway, Autoware's emergency while driving: the tug stops,
disengaged, stays so when the emergency ends, and drives again once engaged. Prints one
JSON object of what it saw. With `lights`, also commands the turn indicators and hazard
lights and reads their status (a profile that has them). Before its readings of the driving
and the tank turn it waits until the vehicle drives (or turns) as told, engaging again should a
stall of this machine have let the vehicle's watchdog brake.

usage: ros2_vehicle_peer.py [lights]"""

import json
import sys
import threading
import time

from ros2_types import (Control, ControlModeCommandRequest, ControlModeCommandResponse,
                        ControlModeReport, GearCommand, GearReport, HazardLightsCommand,
                        HazardLightsReport, JointState, SteeringReport, StringMsg,
                        TurnIndicatorsCommand, TurnIndicatorsReport, Twist, Vector3,
                        VehicleEmergencyStamped, VelocityReport, control, participant, reader,
                        stamp, writer)

lights = sys.argv[1:] == ["lights"]
degradation = sys.argv[1:] == ["degradation"]

dp = participant()
control_cmd = writer(dp, "rt/control/command/control_cmd", Control, depth=1)
gear_cmd = writer(dp, "rt/control/command/gear_cmd", GearCommand, depth=1)
steering_mode_cmd = writer(dp, "rt/vehicle/command/steering_mode", StringMsg, depth=1)
cmd_vel = writer(dp, "rt/cmd_vel", Twist, depth=1)
emergency_cmd = writer(dp, "rt/control/command/emergency_cmd", VehicleEmergencyStamped, depth=1)
requests = writer(dp, "rq/control/control_mode_requestRequest", ControlModeCommandRequest)
replies = reader(dp, "rr/control/control_mode_requestReply", ControlModeCommandResponse)
topics = {
    "steering": ("rt/vehicle/status/steering_status", SteeringReport),
    "velocity": ("rt/vehicle/status/velocity_status", VelocityReport),
    "gear": ("rt/vehicle/status/gear_status", GearReport),
    "mode": ("rt/vehicle/status/control_mode", ControlModeReport),
    "joints": ("rt/vehicle/status/joint_states", JointState),
    "steering_mode": ("rt/vehicle/status/steering_mode", StringMsg),
}
if lights:
    turn_cmd = writer(dp, "rt/control/command/turn_indicators_cmd", TurnIndicatorsCommand,
                      depth=1)
    hazard_cmd = writer(dp, "rt/control/command/hazard_lights_cmd", HazardLightsCommand,
                        depth=1)
    topics["turn"] = ("rt/vehicle/status/turn_indicators_status", TurnIndicatorsReport)
    topics["hazard"] = ("rt/vehicle/status/hazard_lights_status", HazardLightsReport)
if degradation:
    topics["degradation"] = ("rt/vehicle/status/degradation", StringMsg)
readers = {k: reader(dp, name, kind, depth=100) for k, (name, kind) in topics.items()}
seen = {k: [] for k in topics}  # (time, sample)
lock = threading.Lock()
publishing = threading.Event()  # set once the reports before any command are counted
running = True
last_command = [0.0]


turning_on_the_spot = threading.Event()


def publish():
    while running:
        if turning_on_the_spot.is_set():
            cmd_vel.write(Twist(linear=Vector3(0.0, 0.0, 0.0), angular=Vector3(0.0, 0.0, 0.3)))
        elif publishing.is_set():
            now = time.time_ns()
            control_cmd.write(control(0.1, 0.0, 1.5, 0.5, now))
            last_command[0] = time.monotonic()
        time.sleep(0.025)


def collect():
    while running:
        for k, r in readers.items():
            for s in r.take(N=100):
                with lock:
                    seen[k].append((time.monotonic(), s))
        time.sleep(0.005)


def latest(kind):
    with lock:
        return seen[kind][-1][1] if seen[kind] else None


def wait_for(condition, timeout):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if condition():
            return True
        time.sleep(0.01)
    return False


def keep_driving(condition, timeout):
    """Waits for `condition` while driving. Should this machine stall the vehicle interface past
    the vehicle's watchdog, the vehicle brakes, as it must, and drives again only once engaged:
    this engages again every 2 s, as an operator would."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if wait_for(condition, min(2.0, end - time.monotonic())):
            return True
        call(1, timeout=1.0)
    return False


def steady(read, tolerance, timeout):
    """Waits until each value `read` returns moves by no more than `tolerance` over half a
    second (the wheels at their angle, the tug at its speed), for at most `timeout`."""
    end = time.monotonic() + timeout
    before = read()
    while time.monotonic() < end:
        time.sleep(0.5)
        now = read()
        if all(abs(a - b) <= tolerance for a, b in zip(before, now)):
            return True
        before = now
    return False


def moving():
    return latest("velocity") is not None and latest("velocity").longitudinal_velocity > 1.45


sequence = [0]


def call(mode, timeout=5.0):
    sequence[0] += 1
    requests.write(ControlModeCommandRequest(client_guid=0x1234_5678_9ABC_DEF0,
                                             sequence_number=sequence[0], stamp=stamp(0),
                                             mode=mode))
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        for reply in replies.take(N=10):
            if reply.sequence_number == sequence[0]:
                return reply.success
        time.sleep(0.01)
    return None


threads = [threading.Thread(target=publish), threading.Thread(target=collect)]
for t in threads:
    t.start()
result = {}
try:
    if not wait_for(lambda: latest("mode") is not None, 15):
        sys.exit("no control_mode report")
    # At bring-up, before any command: every report already flows (Autoware's controller
    # wants the steering angle before it commands anything).
    with lock:
        counts_before = {k: len(v) for k, v in seen.items()}
    time.sleep(1.0)
    with lock:
        result["before_commands_per_second"] = {k: len(v) - counts_before[k]
                                                for k, v in seen.items()}
    publishing.set()
    for _ in range(5):
        gear_cmd.write(GearCommand(stamp=stamp(0), command=2))
        time.sleep(0.05)
    result["mode_before"] = latest("mode").mode
    # The service's reader must be matched before a request counts: retry until answered.
    answer = None
    for _ in range(10):
        answer = call(1, timeout=3.0)
        if answer is not None:
            break
    result["engaged"] = answer
    wait_for(lambda: latest("mode") is not None and latest("mode").mode == 1, 5)
    result["mode_engaged"] = latest("mode").mode
    keep_driving(moving, 8)
    # Rates over one second of driving.
    with lock:
        counts_before = {k: len(v) for k, v in seen.items()}
    time.sleep(1.0)
    with lock:
        result["per_second"] = {k: len(v) - counts_before[k] for k, v in seen.items()}
    if lights:
        # Autoware's codes: turn 1 off, 2 left, 3 right; hazard 1 off, 2 on. Each pair is
        # sent at 10 Hz, as Autoware does, until the status shows it (or 3 s).
        result["lights"] = []
        for turn, hazard in [(2, 1), (3, 2), (1, 1)]:
            def shown():
                t, h = latest("turn"), latest("hazard")
                return t is not None and h is not None and (t.report, h.report) == (turn, hazard)
            end = time.monotonic() + 3.0
            while time.monotonic() < end and not shown():
                turn_cmd.write(TurnIndicatorsCommand(stamp=stamp(0), command=turn))
                hazard_cmd.write(HazardLightsCommand(stamp=stamp(0), command=hazard))
                time.sleep(0.1)
            result["lights"].append([latest("turn").report, latest("hazard").report])
        # A code Autoware does not have is refused; the lights stay as they are.
        turn_cmd.write(TurnIndicatorsCommand(stamp=stamp(0), command=7))
        time.sleep(0.3)
        result["after_bad_code"] = latest("turn").report
    if degradation:
        result["degradation"] = latest("degradation").data
    keep_driving(moving, 8)
    v, s, g = latest("velocity"), latest("steering"), latest("gear")
    j, sm = latest("joints"), latest("steering_mode")
    result["driving"] = {"velocity": v.longitudinal_velocity, "lateral": v.lateral_velocity,
                         "heading_rate": v.heading_rate, "frame_id": v.header.frame_id,
                         "tire_angle": s.steering_tire_angle, "gear": g.report,
                         "joints": list(j.name), "positions": list(j.position),
                         "joint_velocities": list(j.velocity), "steering_mode": sm.data}
    # Unit mistakes and wrapped angles, one at a time between valid commands: each refused
    # (3.0 rad would have become -4.1 degrees at the wheels). Then a deceleration beyond the
    # vehicle's: a stop at full brake, and driving again.
    for bad in [(3.0, 0.0, 1.5, 0.5), (0.1, 30.0, 1.5, 0.5), (0.1, 0.0, 18.0, 0.5),
                (0.1, 0.0, 1.5, 1e30)]:
        publishing.clear()
        time.sleep(0.03)
        control_cmd.write(control(*bad, time.time_ns()))
        time.sleep(0.03)
        publishing.set()
        time.sleep(0.05)
    # Half a second of it: each a stop at full brake (4 m/s^2), the tug well below 1.5 m/s.
    publishing.clear()
    time.sleep(0.03)
    for _ in range(20):
        control_cmd.write(control(0.1, 0.0, 1.5, -1e30, time.time_ns()))
        time.sleep(0.025)
    publishing.set()
    lowest = [latest("velocity").longitudinal_velocity]

    def slowed():
        lowest[0] = min(lowest[0], latest("velocity").longitudinal_velocity)
        return lowest[0] < 1.0

    wait_for(slowed, 3)
    result["braked_to"] = lowest[0]
    keep_driving(moving, 10)
    # Autoware's emergency while driving, sent at 10 Hz as vehicle_cmd_gate does (control_cmd
    # goes on): the tug stops and is disengaged; the emergency's end does not resume driving.
    emergency_sent = time.monotonic()
    end = emergency_sent + 8.0
    while time.monotonic() < end and not (latest("mode").mode == 4
                                          and latest("velocity").longitudinal_velocity < 0.05):
        emergency_cmd.write(VehicleEmergencyStamped(stamp=stamp(0), emergency=True))
        time.sleep(0.1)
    with lock:
        slowing = [t for t, v in seen["velocity"]
                   if t > emergency_sent and v.longitudinal_velocity < 1.4]
        manual = [t for t, m in seen["mode"] if t > emergency_sent and m.mode == 4]
    result["emergency"] = {"slowing_after": slowing[0] - emergency_sent if slowing else None,
                           "manual_after": manual[0] - emergency_sent if manual else None,
                           "velocity": latest("velocity").longitudinal_velocity,
                           "refused_engage": call(1)}
    for _ in range(5):
        emergency_cmd.write(VehicleEmergencyStamped(stamp=stamp(0), emergency=False))
        time.sleep(0.1)
    time.sleep(0.5)
    result["emergency"]["mode_after"] = latest("mode").mode
    result["emergency"]["velocity_after"] = latest("velocity").longitudinal_velocity
    # Engaged again, it drives on.
    for _ in range(10):
        if call(1, timeout=3.0):
            break
    keep_driving(moving, 10)
    # Crab on our steering-mode topic: the same control_cmd now moves the tug sideways too.
    def steering_mode_is(mode):
        return latest("steering_mode") is not None and latest("steering_mode").data == mode

    for mode in ["crab", "normal"]:
        for _ in range(5):
            steering_mode_cmd.write(StringMsg(data=mode))
            time.sleep(0.05)
        keep_driving(lambda: steering_mode_is(mode) and moving(), 5)
        steady(lambda: (latest("velocity").lateral_velocity,
                        latest("steering").steering_tire_angle), 0.005, 5)
        v = latest("velocity")
        result[mode] = {"steering_mode": latest("steering_mode").data,
                        "lateral": v.lateral_velocity, "heading_rate": v.heading_rate,
                        "tire_angle": latest("steering").steering_tire_angle}
    # cmd_vel instead of control_cmd: a turn on the spot becomes a tank turn.
    turning_on_the_spot.set()
    time.sleep(3.0)
    keep_driving(lambda: latest("velocity").heading_rate > 0.25, 5)
    v = latest("velocity")
    result["tank"] = {"steering_mode": latest("steering_mode").data,
                      "heading_rate": v.heading_rate, "longitudinal": v.longitudinal_velocity}
    turning_on_the_spot.clear()
    keep_driving(lambda: steering_mode_is("normal") and moving(), 10)
    # A stopped publisher: the vehicle slows within the staleness and stops.
    publishing.clear()
    stopped_at = last_command[0]
    time.sleep(0.05)
    wait_for(lambda: latest("velocity").longitudinal_velocity < 0.05, 8)
    with lock:
        after = [(t - stopped_at, x.longitudinal_velocity) for t, x in seen["velocity"]
                 if t > stopped_at]
    result["after_stop"] = after
    publishing.set()
    time.sleep(0.3)
    result["disengaged"] = call(4)
    wait_for(lambda: latest("mode").mode == 4, 5)
    result["mode_after"] = latest("mode").mode
    result["refused_mode"] = call(2)
finally:
    running = False
    for t in threads:
        t.join()
print(json.dumps(result))
