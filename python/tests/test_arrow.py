"""Decoded Arrow tables against cantools: every frame of a simulator run decoded by
``decode_arrow`` / ``decode_log`` equals cantools' ``decode_message`` of the same frame, signal
for signal, with typed columns."""

from __future__ import annotations

import subprocess

import can
import cantools
import pyarrow as pa
import pytest

import bywire
from conftest import TUG_DBC, bywire_cli


@pytest.fixture(scope="module")
def both():
    return bywire.Database.load(TUG_DBC), cantools.database.load_file(str(TUG_DBC))


def test_every_decoded_row_equals_cantools(both, sim_run):
    ours, theirs = both
    log = sim_run.bus_logs["bus1"]
    tables = ours.decode_log(log)
    frames = [m for m in can.LogReader(log)]
    by_message: dict[str, list[can.Message]] = {}
    for m in frames:
        try:
            name = theirs.get_message_by_frame_id(m.arbitration_id).name
        except KeyError:
            continue
        by_message.setdefault(name, []).append(m)
    assert set(tables) == set(by_message)
    assert tables.unknown == len(frames) - sum(len(v) for v in by_message.values())
    for name, table in tables.items():
        rows = table.to_pylist()
        assert len(rows) == len(by_message[name])
        message = theirs.get_message_by_name(name)
        for row, frame in zip(rows, by_message[name]):
            assert abs(row["ts"].timestamp() - frame.timestamp) < 1e-6
            values = message.decode(frame.data, decode_choices=False)
            named = message.decode(frame.data)
            for signal, value in values.items():
                assert row[signal] == value, (name, signal)
                assert type(row[signal]) is type(value), (name, signal)
                if signal + "_choice" in row:
                    choice = named[signal]
                    assert row[signal + "_choice"] == (choice.name if hasattr(choice, "name") else None)


def test_columns_are_typed(both, sim_run):
    ours, _ = both
    table = ours.decode_log(sim_run.bus_logs["bus1"])["VehicleToAds_State"]
    schema = table.schema
    assert schema.field("ts").type == pa.timestamp("ns", tz="UTC")
    assert schema.field("HeartbeatEcho").type == pa.int64()
    assert schema.field("VelocityActual").type == pa.float64()
    assert pa.types.is_dictionary(schema.field("Gear_choice").type)


def test_decode_arrow_takes_batches_tables_and_widened_columns(both, sim_run):
    ours, _ = both
    frames = bywire.read_log(sim_run.bus_logs["bus3"]).read_all()
    whole = ours.decode_arrow(frames)
    # As Spark or pandas hand them: id int64, dlc int16, plain strings, microseconds.
    widened = frames.cast(
        pa.schema(
            [
                pa.field(f.name, {"id": pa.int64(), "dlc": pa.int16(), "channel": pa.string(), "dir": pa.string(), "ts": pa.timestamp("us", tz="UTC")}.get(f.name, f.type), f.nullable)
                for f in frames.schema
            ]
        )
    )
    again = ours.decode_arrow(widened)
    assert set(whole) == set(again) and whole
    for name in whole:
        assert whole[name].drop_columns(["channel"]).equals(again[name].drop_columns(["channel"]))
    streamed = {}
    for name, batch in ours.iter_decoded(bywire.read_log(sim_run.bus_logs["bus3"], batch_rows=1000)):
        streamed[name] = streamed.get(name, 0) + batch.num_rows
    assert streamed == {name: t.num_rows for name, t in whole.items()}


def test_a_blf_decodes_as_its_candump_source(both, sim_run, tmp_path):
    ours, _ = both
    blf = tmp_path / "bus1.blf"
    subprocess.run([bywire_cli(), "log", "convert", sim_run.bus_logs["bus1"], str(blf)], check=True, capture_output=True)
    a, b = ours.decode_log(sim_run.bus_logs["bus1"]), ours.decode_log(blf)
    assert set(a) == set(b)
    for name in a:
        assert a[name].drop_columns(["channel"]).equals(b[name].drop_columns(["channel"]))


def test_the_readme_example_gives_a_pandas_frame(sim_run):
    db = bywire.Database.load(TUG_DBC)
    tables = db.decode_log(sim_run.bus_logs["bus1"])
    df = tables["VehicleToAds_State"].to_pandas()
    assert len(df) > 100 and "SteeringAngleActual" in df.columns
    assert str(df["ts"].dtype) == "datetime64[ns, UTC]"
