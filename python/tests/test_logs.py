"""bywire.read_log against python-can's readers: files python-can writes in every format it
writes (candump, ASC, BLF, TRC, MF4 through asammdf) read by both, frame for frame; pcapng,
MCAP and Parquet written by bywire's converter from the candump file; bad files fail with the
file and place named."""

from __future__ import annotations

import subprocess

import can
import pyarrow as pa
import pytest

import bywire
from conftest import bywire_cli


def messages() -> list[can.Message]:
    """Classic standard and extended, remote, CAN FD with and without BRS/ESI, in both
    directions, on two channels."""
    out = []
    t = 1_700_000_000.0
    for i in range(60):
        kind = i % 6
        t += 0.001 + i * 1e-5
        common = dict(timestamp=round(t, 6), channel=i % 2, is_rx=(i % 3 != 0))
        if kind == 0:
            out.append(can.Message(arbitration_id=0x100 + i, data=bytes([i, 1, 2]), is_extended_id=False, **common))
        elif kind == 1:
            out.append(can.Message(arbitration_id=0x1ABCDE00 + i, data=bytes(range(8)), is_extended_id=True, **common))
        elif kind == 2:
            out.append(can.Message(arbitration_id=0x200 + i, is_remote_frame=True, dlc=4, is_extended_id=False, **common))
        elif kind == 3:
            out.append(can.Message(arbitration_id=0x300 + i, data=bytes(range(12)), is_fd=True, bitrate_switch=True, is_extended_id=False, **common))
        elif kind == 4:
            out.append(can.Message(arbitration_id=0x18DA00F1, data=bytes(range(64)), is_fd=True, bitrate_switch=False, error_state_indicator=True, is_extended_id=True, **common))
        else:
            out.append(can.Message(arbitration_id=0x7FF, data=b"", is_extended_id=False, **common))
    return out


def write(path, frames) -> None:
    with can.Logger(str(path)) as logger:
        for message in frames:
            logger.on_message_received(message)


def python_can_frames(path) -> list[dict]:
    rows = []
    # ASC: absolute times, as bywire gives them (python-can's default is from the first frame).
    options = {"relative_timestamp": False} if str(path).endswith(".asc") else {}
    for m in can.LogReader(str(path), **options):
        if m.is_error_frame:
            continue
        rows.append(
            dict(
                id=m.arbitration_id,
                extended=m.is_extended_id,
                remote=m.is_remote_frame,
                fd=m.is_fd,
                brs=m.bitrate_switch,
                esi=m.error_state_indicator,
                data=b"" if m.is_remote_frame else bytes(m.data),
                ts=m.timestamp,
            )
        )
    return rows


def bywire_frames(path) -> list[dict]:
    table = bywire.read_log(path, batch_rows=7).read_all()
    assert table.schema == bywire.frames_schema()
    rows = []
    for r in table.to_pylist():
        if r["error"]:
            continue
        rows.append(
            dict(
                id=r["id"],
                extended=r["extended"],
                remote=r["remote"],
                fd=r["fd"],
                brs=r["brs"],
                esi=r["esi"],
                data=r["data"],
                ts=r["ts"].timestamp(),
            )
        )
    return rows


def assert_same(ours: list[dict], theirs: list[dict], resolution: float) -> None:
    assert len(ours) == len(theirs) > 0
    for a, b in zip(ours, theirs):
        at, bt = a.pop("ts"), b.pop("ts")
        assert a == b
        assert abs(at - bt) <= resolution, (at, bt)


@pytest.mark.parametrize(
    "suffix, resolution",
    [(".log", 1e-6), (".asc", 1e-6), (".blf", 1e-6), (".trc", 1e-6), (".mf4", 1e-6)],
)
def test_read_log_gives_what_python_can_reads(tmp_path, suffix, resolution):
    path = tmp_path / f"frames{suffix}"
    frames = messages()
    if suffix == ".trc":
        # TRC 2.1 has no remote frames python-can writes back.
        frames = [m for m in frames if not m.is_remote_frame]
    write(path, frames)
    theirs = python_can_frames(path)
    ours = bywire_frames(path)
    assert_same(ours, theirs, resolution)


@pytest.mark.parametrize("suffix", [".pcapng", ".mcap", ".parquet", ".blf", ".mf4"])
def test_read_log_reads_what_bywire_converts(tmp_path, suffix):
    source = tmp_path / "source.log"
    write(source, messages())
    target = tmp_path / f"converted{suffix}"
    subprocess.run([bywire_cli(), "log", "convert", str(source), str(target)], check=True, capture_output=True)
    expected = python_can_frames(source)
    if suffix == ".mcap":
        # ROS 2's can_msgs/msg/Frame is classic CAN: the converter leaves CAN FD frames out.
        expected = [f for f in expected if not f["fd"]]
    assert_same(bywire_frames(target), expected, 1e-6)


def test_direction_and_channel_come_through(tmp_path):
    path = tmp_path / "frames.asc"
    write(path, messages())
    table = bywire.read_log(path).read_all()
    theirs = [m for m in can.LogReader(str(path)) if not m.is_error_frame]
    directions = table.column("dir").to_pylist()
    assert directions == ["rx" if m.is_rx else "tx" for m in theirs]
    # Two channels, named as the ASC file numbers them.
    assert len(set(table.column("channel").to_pylist())) == 2


def test_a_truncated_blf_names_the_file_and_keeps_what_came_before(tmp_path):
    good = tmp_path / "good.blf"
    write(good, messages())
    data = good.read_bytes()
    bad = tmp_path / "bad.blf"
    bad.write_bytes(data[: len(data) - 40])
    reader = bywire.read_log(bad, batch_rows=1)
    read = 0
    with pytest.raises(bywire.LogError, match="bad.blf"):
        for batch in reader:
            read += batch.num_rows
    bad.write_bytes(data[:200] + b"\xff" * 300 + data[500:])
    with pytest.raises(bywire.LogError, match=r"bad\.blf.*offset|bad\.blf.*byte"):
        bywire.read_log(bad).read_all()


def test_a_bad_candump_line_is_named(tmp_path):
    path = tmp_path / "bad.log"
    path.write_text("(1.000000) can0 123#11\n(1.000100) can0 12X#11\n")
    with pytest.raises(bywire.LogError, match="bad.log.*line 2"):
        bywire.read_log(path).read_all()
    with pytest.raises(OSError, match="missing.log"):
        bywire.read_log(tmp_path / "missing.log")
    with pytest.raises(ValueError):
        bywire.read_log(path, batch_rows=0)


def test_a_parquet_page_the_decoder_panics_on_is_a_log_error_without_a_panic_message(tmp_path, capfd):
    """parquet-rs panics on an over-long varint in a delta header: the reader takes that as the
    file's error, and nothing about a panic reaches stderr."""
    source = tmp_path / "six.log"
    source.write_text("(1700000000.000001) can0 010#01\n" * 6)
    table = tmp_path / "bad.parquet"
    subprocess.run(
        [bywire_cli(), "log", "convert", str(source), str(table), "--compression", "none"],
        check=True,
        capture_output=True,
    )
    data = bytearray(table.read_bytes())
    # The `ts` page's delta header: a two-byte block size, 4 miniblocks, 6 values, then the
    # first value, made an 11-byte varint.
    header = next(i for i in range(len(data) - 3) if data[i] == 0x80 and data[i + 2 : i + 4] == b"\x04\x06")
    data[header + 4 : header + 15] = b"\xff" * 11
    table.write_bytes(bytes(data))
    capfd.readouterr()
    with pytest.raises(bywire.LogError, match=r"bad\.parquet.*malformed page"):
        bywire.read_log(table).read_all()
    assert "panicked" not in capfd.readouterr().err


def test_batches_stream_with_the_rows_asked_for(tmp_path):
    path = tmp_path / "frames.log"
    write(path, messages())
    sizes = [b.num_rows for b in bywire.read_log(path, batch_rows=16)]
    assert sizes == [16, 16, 16, 12]
    assert isinstance(bywire.read_log(path), pa.RecordBatchReader)


def test_byte_ranges_of_a_candump_log_read_every_frame_once(tmp_path):
    path = tmp_path / "frames.log"
    write(path, messages())
    whole = bywire.read_log(path).read_all()
    size = path.stat().st_size
    for parts in (1, 2, 3, 7, 50):
        bounds = [size * i // parts for i in range(parts + 1)]
        pieces = [bywire.read_log(path, byte_range=(a, b)).read_all() for a, b in zip(bounds, bounds[1:])]
        # The same rows (each piece's channel dictionary is its own).
        assert [row for piece in pieces for row in piece.to_pylist()] == whole.to_pylist()
    blf = tmp_path / "frames.blf"
    write(blf, messages())
    with pytest.raises(ValueError, match="byte ranges"):
        bywire.read_log(blf, byte_range=(0, 100))
