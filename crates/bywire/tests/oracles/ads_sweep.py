"""An ADS written against the reference tug with python-can and cantools, sharing no code with
bywire: it engages the vehicle on the bus, sweeps the steering from -40 to +40 degrees in steps
of one degree, reading the actual angle back from VehicleToAds_State, and prints one JSON
object with what it saw. Should its commands come late (a stalled machine) and the vehicle's
watchdog brake, it engages again, and counts the cycles spent braked.

    ads_sweep.py DBC INTERFACE CHANNEL [HOST PORT]   (socketcan vcan0 | socketcand shuttle H P)

Commands go out every 20 ms with their rolling counter and CRC-8 SAE J1850 over the data ID
(the identifier, low byte first) and bytes 0-6, as the DBC's attributes declare; the CRC is
computed here, bit by bit."""
import json
import sys
import time

import can
import cantools

CONTROL, STATE = 0x100, 0x101


def crc8_sae_j1850(data):
    crc = 0xFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc ^ 0xFF


def main():
    db = cantools.database.load_file(sys.argv[1])
    kwargs = {"interface": sys.argv[2], "channel": sys.argv[3]}
    if sys.argv[2] == "socketcand":
        kwargs.update(host=sys.argv[4], port=int(sys.argv[5]))
    bus = can.Bus(**kwargs)
    control = db.get_message_by_frame_id(CONTROL)
    counter = 0
    state = {}
    rejected_state = 0

    def send(steering, engage=False):
        nonlocal counter
        data = bytearray(control.encode({
            "SteeringAngleCmd": steering, "VelocityCmd": 0.0, "BrakeCmd": 0.0,
            "GearCmd": 3, "ControlModeCmd": 1, "SteeringModeCmd": 0,
            "EngageRequest": int(engage), "OperatorReset": 0,
            "HeartbeatCounter": counter, "Checksum": 0}))
        data[7] = crc8_sae_j1850(bytes([CONTROL & 0xFF, CONTROL >> 8]) + bytes(data[:7]))
        bus.send(can.Message(arbitration_id=CONTROL, is_extended_id=False, data=bytes(data)))
        counter = (counter + 1) % 16

    def cycle(steering, engage=False):
        """One 20 ms command cycle; the state frames that arrive meanwhile are read."""
        nonlocal rejected_state
        send(steering, engage)
        end = time.monotonic() + 0.02
        while True:
            left = end - time.monotonic()
            if left <= 0:
                return
            m = bus.recv(left)
            if m is None or m.arbitration_id != STATE:
                continue
            if crc8_sae_j1850(bytes([STATE & 0xFF, STATE >> 8]) + bytes(m.data[:7])) != m.data[7]:
                rejected_state += 1
                continue
            state.update(db.decode_message(STATE, m.data, decode_choices=False))
            state["at"] = time.monotonic()

    # Valid commands for the recovery run, then an engage edge, until the vehicle says autonomous.
    engaged = False
    for k in range(400):
        cycle(0.0, engage=(k >= 15 and k % 10 == 0))
        if state.get("ControlMode") == 1 and state.get("WatchdogLevel") == 0:
            engaged = True
            break
    steps = []
    braked_cycles = 0
    if engaged:
        for target in range(-40, 41):
            reached = None
            deadline = time.monotonic() + 4.0
            while time.monotonic() < deadline:
                # Braked by the watchdog (this machine stalled and a command came late): engage
                # again while the vehicle recovers, as an operator would.
                braked = state.get("WatchdogLevel", 0) != 0
                braked_cycles += braked
                cycle(float(target), engage=braked and braked_cycles % 10 == 0)
                actual = state.get("SteeringAngleActual")
                if actual is not None and abs(actual - target) < 0.15:
                    reached = actual
                    break
            steps.append({"target": target, "actual": state.get("SteeringAngleActual"),
                          "reached": reached is not None, "mode": state.get("ControlMode")})
    bus.shutdown()
    print(json.dumps({"engaged": engaged, "steps": steps, "rejected_state": rejected_state,
                      "braked_cycles": braked_cycles,
                      "last": {k: v for k, v in state.items() if k != "at"}}), flush=True)


main()
