"""python-can over bywire's buses (``interface="bywire"``): python-can's own Bus API, Notifier,
listeners, loggers and periodic sending on bywire buses, against bywire's tools on the other
end — in this process on a virtual bus (the command line run by the native module), and in
another process over UDP multicast (the ``bywire`` console script) — and an ADS test in the
shape an ADS developer writes against ``bywire vehicle``."""

from __future__ import annotations

import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import can
import pytest
from crccheck.crc import Crc8SaeJ1850

import bywire
import bywire.database
from bywire import _native
from conftest import TUG_DBC

CONTROL, STATE = 0x100, 0x101


def bywire_command() -> str:
    """The console script installed with the package (beside this interpreter)."""
    here = Path(sys.executable).parent / "bywire"
    found = str(here) if here.exists() else shutil.which("bywire")
    assert found, "the bywire console script is not installed"
    return found


def in_process(*args: str) -> threading.Thread:
    """The command line run by the native module in a thread of this process (so that it
    shares this process's virtual buses)."""
    thread = threading.Thread(target=_native.run_cli, args=(["bywire", *args],), daemon=True)
    thread.start()
    return thread


def test_the_interface_is_found_by_name_and_sends_and_receives_every_kind_of_frame():
    with can.Bus(interface="bywire", channel="virtual:kinds") as a, can.Bus(
        interface="bywire", channel="virtual:kinds", receive_own_messages=True
    ) as b:
        sent = [
            can.Message(arbitration_id=0x123, data=b"\x01\x02", is_extended_id=False),
            can.Message(arbitration_id=0x1ABCDEF0, data=bytes(8), is_extended_id=True),
            can.Message(arbitration_id=0x7FF, is_remote_frame=True, dlc=3, is_extended_id=False),
            can.Message(arbitration_id=0x42, data=bytes(range(12)), is_fd=True, bitrate_switch=True, is_extended_id=False),
        ]
        before = time.time()
        for message in sent:
            a.send(message)
        got = [b.recv(2.0) for _ in sent]
        for theirs, ours in zip(sent, got):
            assert ours is not None
            assert ours.equals(theirs, timestamp_delta=None, check_channel=False, check_direction=False), (theirs, ours)
            assert ours.is_rx and ours.channel == "virtual:kinds"
            assert before - 1 <= ours.timestamp <= time.time() + 1  # Unix seconds, as python-can's
        b.send(can.Message(arbitration_id=0x55, data=b"\x55", is_extended_id=False))
        own = b.recv(2.0)
        assert own is not None and own.arbitration_id == 0x55 and not own.is_rx
        with pytest.raises(can.CanOperationError):
            a.send(can.Message(arbitration_id=0x800, data=b"", is_extended_id=False))
    with pytest.raises(can.CanInitializationError):
        can.Bus(interface="bywire", channel="nosuch:bus")


def test_filters_notifier_listeners_logger_and_periodic_sending(tmp_path):
    log = tmp_path / "seen.asc"
    with can.Bus(interface="bywire", channel="virtual:periodic") as sender, can.Bus(
        interface="bywire", channel="virtual:periodic", can_filters=[{"can_id": 0x10, "can_mask": 0x7FF, "extended": False}]
    ) as receiver:
        reader = can.BufferedReader()
        logger = can.Logger(str(log))
        notifier = can.Notifier(receiver, [reader, logger])
        sender.send(can.Message(arbitration_id=0x11, data=b"\x00", is_extended_id=False))  # filtered out
        task = sender.send_periodic(can.Message(arbitration_id=0x10, data=b"\xaa\x01", is_extended_id=False), 0.005)
        got = [reader.get_message(5.0) for _ in range(20)]
        task.stop()
        notifier.stop()
        logger.stop()
    assert all(m is not None and m.arbitration_id == 0x10 and bytes(m.data) == b"\xaa\x01" for m in got)
    stamps = [m.timestamp for m in got]
    assert stamps == sorted(stamps)
    # python-can's ASC writer's file, read by bywire: at least the 20 frames seen, all of 0x10.
    frames = bywire.read_log(log).read_all()
    assert frames.num_rows >= 20
    assert set(frames.column("id").to_pylist()) == {0x10}


def test_bywire_tools_in_this_process_on_a_virtual_bus(tmp_path):
    # bywire gen sends, python-can receives every frame, in order.
    with can.Bus(interface="bywire", channel="virtual:tools-gen") as bus:
        gen = in_process("gen", "virtual:tools-gen", "-n", "500", "-g", "1", "-I", "321", "-L", "4", "-D", "i")
        got = [bus.recv(5.0) for _ in range(500)]
        gen.join(10)
    assert all(m is not None and m.arbitration_id == 0x321 and m.dlc == 4 for m in got)
    assert [m.data[0] for m in got] == [i % 256 for i in range(500)]
    # python-can sends until bywire dump has logged 5 frames and exited.
    out = tmp_path / "dump.log"
    with can.Bus(interface="bywire", channel="virtual:tools-dump") as bus:
        dump = in_process("dump", "virtual:tools-dump", "-n", "5", "-f", str(out))
        task = bus.send_periodic(can.Message(arbitration_id=0x1F334455, data=b"\xde\xad", is_extended_id=True), 0.01)
        dump.join(30)
        task.stop()
    assert not dump.is_alive()
    lines = out.read_text().splitlines()
    assert len(lines) == 5 and all(line.endswith(" virtual:tools-dump 1F334455#DEAD") for line in lines), lines


def test_bywire_tools_in_another_process_over_udp_multicast():
    group = "udp:239.74.163.2:43217"
    dump = subprocess.Popen([bywire_command(), "dump", group, "-n", "3", "-L"], stdout=subprocess.PIPE, text=True)
    try:
        with can.Bus(interface="bywire", channel=group) as bus:
            task = bus.send_periodic(can.Message(arbitration_id=0x2A, data=b"\x01\x02\x03", is_extended_id=False), 0.01)
            out, _ = dump.communicate(timeout=60)
            task.stop()
            # And the other way: bywire gen in its own process, python-can receiving.
            gen = subprocess.run(
                [bywire_command(), "gen", group, "-n", "50", "-g", "1", "-I", "77", "-L", "2", "-D", "i"],
                check=True, timeout=60,
            )
            assert gen.returncode == 0
            got = []
            while (m := bus.recv(2.0)) is not None:
                if m.arbitration_id == 0x77:
                    got.append(m)
    finally:
        dump.kill()
    lines = out.splitlines()
    assert len(lines) == 3 and all(line.endswith("02A#010203") for line in lines), lines
    assert [m.data[0] for m in got] == list(range(50))


def crc8_sae_j1850(data: bytes) -> int:
    """The reference tug's E2E checksum, by crccheck (an implementation independent of bywire)."""
    return Crc8SaeJ1850.calc(data)


def test_steering_range_of_the_simulated_tug_over_python_can():
    """An ADS test as its developer writes it: python-can and a database, the simulated tug
    (`bywire vehicle`) in another process; engage, then each steering target is reached."""
    group = "udp:239.74.163.2:43219"
    vehicle = subprocess.Popen(
        [bywire_command(), "vehicle", "--profile", "reference-tug", group, "--rate", "0", "--duration", "300"],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )
    db = bywire.database.load_file(TUG_DBC)
    control = db.get_message_by_frame_id(CONTROL)
    state: dict = {}
    counter = 0
    try:
        with can.Bus(interface="bywire", channel=group) as bus:

            def cycle(steering: float, engage: bool = False) -> None:
                nonlocal counter
                data = bytearray(control.encode({
                    "SteeringAngleCmd": steering, "VelocityCmd": 0.0, "BrakeCmd": 0.0, "GearCmd": 3,
                    "ControlModeCmd": 1, "SteeringModeCmd": 0, "EngageRequest": int(engage),
                    "OperatorReset": 0, "HeartbeatCounter": counter, "Checksum": 0}))
                data[7] = crc8_sae_j1850(bytes([CONTROL & 0xFF, CONTROL >> 8]) + bytes(data[:7]))
                bus.send(can.Message(arbitration_id=CONTROL, is_extended_id=False, data=bytes(data)))
                counter = (counter + 1) % 16
                end = time.monotonic() + 0.02
                while (left := end - time.monotonic()) > 0:
                    m = bus.recv(left)
                    if m is not None and m.arbitration_id == STATE:
                        state.update(db.decode_message(STATE, m.data, decode_choices=False))

            for k in range(1500):
                braked = state.get("WatchdogLevel", 0) != 0
                cycle(0.0, engage=k >= 15 and k % 10 == 0)
                if state.get("ControlMode") == 1 and not braked:
                    break
            assert state.get("ControlMode") == 1, state
            for target in range(-40, 41, 10):
                reached = False
                for k in range(400):
                    cycle(float(target), engage=state.get("WatchdogLevel", 0) != 0 and k % 10 == 0)
                    if abs(state.get("SteeringAngleActual", 1e9) - target) < 0.15:
                        reached = True
                        break
                assert reached, (target, state)
    finally:
        vehicle.send_signal(signal.SIGINT)
        _, errors = vehicle.communicate(timeout=30)
    assert vehicle.returncode == 0, errors


def test_the_console_script_is_the_command_line():
    run = subprocess.run([bywire_command(), "--version"], capture_output=True, text=True, check=True)
    assert run.stdout.startswith(f"bywire {bywire.__version__} ")
    bad = subprocess.run([bywire_command(), "no-such-command"], capture_output=True, text=True)
    assert bad.returncode == 2 and "unrecognized subcommand" in bad.stderr
    decoded = subprocess.run(
        [bywire_command(), "decode", str(TUG_DBC)], input="(0.0) vcan0 101#0000000000000000\n",
        capture_output=True, text=True, check=True,
    )
    assert "VehicleToAds_State" in decoded.stdout
