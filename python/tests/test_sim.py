"""bywire.sim.run: the same run as ``bywire sim --fast`` (byte for byte), deterministic for a
seed, and errors for what cannot run."""

from __future__ import annotations

import json
import subprocess

import pytest

import bywire
import bywire.sim
from conftest import bywire_cli

# The logs' clock at the start: 2026-12-07T08:00:00Z.
START = 1_796_630_400


def test_a_run_writes_the_same_logs_as_the_command_line(tmp_path):
    ours = bywire.sim.run("apron-loop", seed=11, out=tmp_path / "py", max_seconds=8.0, start_time=START)
    subprocess.run(
        [bywire_cli(), "sim", "--fast", "--seed", "11", "--max-seconds", "8", "--out", str(tmp_path / "cli"),
         "--start-time", "2026-12-07T08:00:00Z"],
        check=True,
        capture_output=True,
    )
    for bus, path in ours.bus_logs.items():
        assert (tmp_path / "cli" / f"{bus}.log").read_bytes() == open(path, "rb").read(), bus
    cli = json.loads((tmp_path / "cli" / "metrics.json").read_text())
    for key in ("start_time_ns", "sim_seconds", "completed", "frames", "bus_load", "tracking_error_m", "events"):
        assert ours.report[key] == cli[key], key
    assert ours.report["sim_seconds"] == pytest.approx(8.0)
    assert sorted(ours.bus_logs) == ["bus1", "bus1b", "bus2", "bus3"]
    # The ground truth too, and it opens in pandas and polars alike.
    truth = tmp_path / "py" / "truth.csv"
    assert str(truth) in ours.files
    assert (tmp_path / "cli" / "truth.csv").read_bytes() == truth.read_bytes()
    import pandas
    import polars

    frame = pandas.read_csv(truth)
    assert len(frame) == 800 and frame["t_s"].iloc[-1] == pytest.approx(START + 8.0)
    assert ours.report["start_time_ns"] == START * 10**9
    assert set(frame["steering_mode"].dropna()) <= {"normal", "crab", "tank"}
    assert polars.read_csv(truth).columns == list(frame.columns)


def test_seeds_and_payloads_change_the_run(tmp_path):
    a = bywire.sim.run(seed=1, out=tmp_path / "a", max_seconds=4.0, start_time=START)
    b = bywire.sim.run(seed=1, out=tmp_path / "b", max_seconds=4.0, start_time=START)
    c = bywire.sim.run(seed=2, out=tmp_path / "c", max_seconds=4.0, start_time=START)
    read = lambda run: open(run.bus_logs["bus3"], "rb").read()  # noqa: E731
    assert read(a) == read(b)
    assert read(a) != read(c)
    assert a.report["seed"] == 1 and c.report["seed"] == 2


def test_what_cannot_run_is_an_error(tmp_path):
    with pytest.raises(bywire.ScenarioError, match="no-such-scenario"):
        bywire.sim.run("no-such-scenario", out=tmp_path)
    with pytest.raises(bywire.ScenarioError, match="payload"):
        bywire.sim.run(payload=99_999.0, out=tmp_path)
    with pytest.raises(bywire.ScenarioError, match="max_seconds"):
        bywire.sim.run(max_seconds=float("nan"), out=tmp_path)
    with pytest.raises(bywire.ScenarioError, match="start_time -1"):
        bywire.sim.run(start_time=-1.0, out=tmp_path)
    bad = tmp_path / "bad.toml"
    bad.write_text("name = 3\n")
    with pytest.raises(bywire.ScenarioError, match="bad.toml"):
        bywire.sim.run(str(bad), out=tmp_path)
