"""``bywire dataset`` on a sweep of simulator runs: the table opens in pandas and polars, its
grid is regular, its ground truth is the runs' truth.csv, its episodes change where the
steering mode does, and its card describes it."""

from __future__ import annotations

import json
import subprocess

import pandas
import polars
import pyarrow.parquet
import pytest

from conftest import bywire_cli


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("dataset")
    sweep, out = root / "sweep", root / "ds"
    # The apron loop has a tank turn at its end: normal → tank → normal steering.
    subprocess.run(
        [bywire_cli(), "sim", "--sweep", "apron-loop", "--seeds", "1..2", "--payloads", "0,3000",
         "--out", str(sweep)],
        check=True, capture_output=True,
    )
    done = subprocess.run(
        [bywire_cli(), "dataset", "--runs", str(sweep), "--profile", "reference-tug", "--rate", "50",
         "--out", str(out)],
        check=True, capture_output=True, text=True,
    )
    assert "from 4 run(s)" in done.stdout
    return sweep, out


def test_it_opens_in_pandas_and_polars_with_units(dataset):
    _, out = dataset
    frame = pandas.read_parquet(out / "dataset.parquet")
    lazy = polars.read_parquet(out / "dataset.parquet")
    assert lazy.shape == frame.shape
    assert list(lazy.columns) == list(frame.columns)
    assert frame["run"].nunique() == 4
    for column in ("action_steering", "obs_velocity", "obs_velocity_age_s", "truth_x_m",
                   "obs_wheel_angle_fl", "truth_wheel_angle_fl_deg"):
        assert column in frame.columns, column
    schema = pyarrow.parquet.read_schema(out / "dataset.parquet")
    assert schema.field("obs_velocity").metadata == {b"unit": b"m/s"}
    assert schema.field("truth_yaw_rate_rad_s").metadata == {b"unit": b"rad/s"}
    assert schema.field("obs_velocity_age_s").metadata == {b"unit": b"s"}


def test_the_grid_is_regular_and_the_ages_bounded_by_the_message_rate(dataset):
    _, out = dataset
    frame = pandas.read_parquet(out / "dataset.parquet")
    for _, run in frame.groupby("run"):
        steps = run["t_s"].diff().dropna()
        assert steps.min() == pytest.approx(0.02) and steps.max() == pytest.approx(0.02)
        # The state comes every 20 ms: once it has come, its age stays below a period.
        ages = run["obs_velocity_age_s"].dropna()
        assert len(ages) > 100 and ages.max() < 0.02 + 1e-9


def test_ground_truth_is_the_runs_truth_on_the_grid(dataset):
    sweep, out = dataset
    frame = pandas.read_parquet(out / "dataset.parquet")
    for name, run in frame.groupby("run"):
        # round_trip: the numbers as written (pandas' fast parser can be an ulp off).
        truth = pandas.read_csv(sweep / name / "truth.csv", float_precision="round_trip")
        joined = pandas.merge_asof(
            run[["timestamp_s", "truth_x_m", "truth_wheel_speed_rr_m_s"]].sort_values("timestamp_s"),
            truth[["t_s", "x_m", "wheel_speed_rr_m_s"]],
            left_on="timestamp_s", right_on="t_s", direction="backward",
        ).dropna()
        assert len(joined) > 0.9 * len(run)
        assert (joined["truth_x_m"] == joined["x_m"]).all()
        assert (joined["truth_wheel_speed_rr_m_s"] == joined["wheel_speed_rr_m_s"]).all()


def test_episodes_change_where_the_steering_mode_does(dataset):
    _, out = dataset
    frame = pandas.read_parquet(out / "dataset.parquet")
    changes = 0
    for _, run in frame.groupby("run"):
        mode = run["obs_steering_mode"]
        episode = run["episode"]
        changed = mode.ne(mode.shift()) & mode.shift().notna()
        for index in run.index[changed]:
            changes += 1
            assert episode.loc[index] != episode.shift().loc[index], index
        # Within an episode the steering mode never changes.
        assert (run.dropna(subset=["episode"]).groupby("episode")["obs_steering_mode"].nunique() == 1).all()
    assert changes >= 8  # into the tank turn and out, in each of the four runs
    # A split per episode.
    assert (frame.dropna(subset=["episode"]).groupby("episode")["split"].nunique() == 1).all()


def test_the_card_describes_the_table(dataset):
    _, out = dataset
    card = json.loads((out / "card.json").read_text())
    frame = pandas.read_parquet(out / "dataset.parquet")
    assert card["rows"] == len(frame)
    assert card["rate_hz"] == 50
    assert len(card["episodes"]) == frame["episode"].nunique()
    columns = {c["name"]: c for c in card["columns"]}
    assert columns["obs_velocity"]["unit"] == "m/s"
    assert columns["obs_velocity"]["values"] == frame["obs_velocity"].notna().sum()
    assert columns["obs_velocity"]["max"] == frame["obs_velocity"].max()
    assert len(card["sources"]) == 4 * 3  # bus1.log, bus3.log and truth.csv of each run
    assert all(len(s["sha256"]) == 64 for s in card["sources"])
    assert "# Dataset card" in (out / "card.md").read_text()


def test_the_odometry_pose_follows_the_plants_truth_in_every_steering_mode(dataset):
    """The 4WS odometry from the bus's wheel speeds and angles, from each episode's start,
    against the plant's true pose carried into the same frame."""
    import numpy

    _, out = dataset
    frame = pandas.read_parquet(out / "dataset.parquet")
    modes = set()
    for (_, _), episode in frame.dropna(subset=["episode", "odom_x"]).groupby(["run", "episode"]):
        if len(episode) < 50:
            continue
        x0, y0, yaw0 = episode.iloc[0][["truth_x_m", "truth_y_m", "truth_yaw_rad"]]
        dx, dy = episode["truth_x_m"] - x0, episode["truth_y_m"] - y0
        c, s = numpy.cos(yaw0), numpy.sin(yaw0)
        true_x, true_y = c * dx + s * dy, -s * dx + c * dy
        travelled = numpy.hypot(true_x.diff(), true_y.diff()).sum()
        error = numpy.hypot(true_x - episode["odom_x"], true_y - episode["odom_y"])
        assert error.max() <= 0.02 * travelled + 0.1, (travelled, error.max())
        turned = episode["truth_yaw_rad"] - yaw0 - episode["odom_yaw"]
        # Headings compared as angles: a whole turn apart is no error (the truth's yaw wraps).
        assert abs(numpy.angle(numpy.exp(1j * turned.iloc[-1]))) < 0.03
        modes.add(episode["obs_steering_mode"].iloc[0])
    assert modes == {0.0, 1.0, 2.0}  # normal, crab and tank
    schema = pyarrow.parquet.read_schema(out / "dataset.parquet")
    assert schema.field("odom_x").metadata == {b"unit": b"m"}
    assert schema.field("obs_imu_yaw_rate").metadata == {b"unit": b"deg/s"}
    assert schema.field("obs_battery_voltage").metadata == {b"unit": b"V"}
    assert frame["obs_battery_soc"].notna().sum() > 0.9 * len(frame)
