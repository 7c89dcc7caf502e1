"""Spark in local mode (local[2], bound to loopback): the data source's frames and signals,
``decode`` through mapInArrow, and the two example jobs, checked against python-can's readers and
cantools' decode of the same frames."""

from __future__ import annotations

import decimal
import math
import os
import shutil
import subprocess
import sys
from collections import Counter

import can
import cantools
import pyarrow.dataset as ds
import pyarrow.parquet as pq
import pyspark  # noqa: F401  (installed by scripts/install-test-deps.sh; missing, the tests fail)
import pytest

from conftest import CORPUS, ROOT, TUG_DBC, bywire_cli, env_for_spark


@pytest.fixture(scope="module")
def fleet(sim_run, tmp_path_factory):
    """Logs of two vehicles on two days: candump and BLF."""
    root = tmp_path_factory.mktemp("fleet")
    one = root / "vehicle=tug1" / "date=2026-12-01"
    two = root / "vehicle=tug2" / "date=2026-12-02"
    one.mkdir(parents=True)
    two.mkdir(parents=True)
    (one / "bus1.log").write_bytes(open(sim_run.bus_logs["bus1"], "rb").read())
    subprocess.run([bywire_cli(), "log", "convert", sim_run.bus_logs["bus3"], str(two / "bus3.blf")], check=True, capture_output=True)
    return root


def cantools_rows(fleet) -> list[tuple]:
    """(vehicle, date, channel, message, signal, value) for every signal of every frame, as
    python-can reads the files and cantools decodes them."""
    db = cantools.database.load_file(str(TUG_DBC))
    rows = []
    for path in sorted(fleet.rglob("*.*")):
        vehicle = path.parent.parent.name.split("=")[1]
        date = path.parent.name.split("=")[1]
        for m in can.LogReader(str(path)):
            try:
                message = db.get_message_by_frame_id(m.arbitration_id)
            except KeyError:
                continue
            for signal, value in message.decode(m.data, decode_choices=False).items():
                rows.append((vehicle, date, round(m.timestamp, 6), message.name, signal, float(value)))
    return rows


def test_signals_equal_cantools_row_for_row(spark, fleet):
    df = spark.read.format("bywire").option("dbc", str(TUG_DBC)).option("output", "signals").load(str(fleet / "**" / "*.*"))
    assert df.rdd.getNumPartitions() == 2  # one partition a file
    ours = [
        (r.vehicle, r.date, round(r.ts.timestamp(), 6), r.message, r.signal, r.value)
        for r in df.collect()
    ]
    assert Counter(ours) == Counter(cantools_rows(fleet))


def test_frames_and_decode_through_map_in_arrow(spark, fleet):
    import bywire.spark

    frames = spark.read.format("bywire").load(str(fleet))
    expected = sum(1 for p in fleet.rglob("*.*") for _ in can.LogReader(str(p)))
    assert frames.count() == expected
    assert {r.vehicle for r in frames.select("vehicle").distinct().collect()} == {"tug1", "tug2"}
    decoded = frames.mapInArrow(bywire.spark.decode(str(TUG_DBC)), bywire.spark.SIGNALS_SCHEMA)
    direct = spark.read.format("bywire").option("dbc", str(TUG_DBC)).option("output", "signals").load(str(fleet))
    key = lambda r: (r.vehicle, r.date, r.ts, r.message, r.signal, r.value)  # noqa: E731
    assert Counter(map(key, decoded.collect())) == Counter(map(key, direct.collect()))
    wide = spark.read.format("bywire").option("dbc", str(TUG_DBC)).option("output", "wide").option("message", "VehicleToAds_State").load(str(fleet))
    states = [r for r in cantools_rows(fleet) if r[3] == "VehicleToAds_State" and r[4] == "Gear"]
    assert wide.count() == len(states)
    assert Counter(r.Gear for r in wide.collect()) == Counter(r[5] for r in states)


def test_a_big_candump_log_is_split_into_partitions(spark, fleet):
    candump = next(fleet.rglob("*.log"))
    whole = spark.read.format("bywire").load(str(candump))
    split = spark.read.format("bywire").option("split_mb", "0.05").load(str(candump))
    assert whole.rdd.getNumPartitions() == 1
    assert split.rdd.getNumPartitions() == -(-candump.stat().st_size // 50_000)
    key = lambda r: (r.ts, r.id, r.data)  # noqa: E731
    assert Counter(map(key, split.collect())) == Counter(map(key, whole.collect()))


def test_bad_options_are_named(spark, fleet):
    with pytest.raises(Exception, match="output=signals needs option dbc"):
        spark.read.format("bywire").option("output", "signals").load(str(fleet)).count()
    with pytest.raises(Exception, match="no files"):
        spark.read.format("bywire").load(str(fleet / "nothing-here" / "*.log")).count()


def lake_rows(spark, lake) -> Counter:
    """The lake as Spark reads it: (vehicle, date, message, ts, channel, signal, value)."""
    return Counter(
        (r.vehicle, str(r.date), r.message, r.ts, r.channel, r.signal, r.value)
        for r in spark.read.parquet(str(lake)).collect()
    )


def partition_folders(lake) -> set:
    return {p.parent.relative_to(lake) for p in lake.rglob("*.parquet")}


def test_write_lake_gives_the_lake_spark_writes(spark, fleet, tmp_path):
    import bywire.spark

    ours = tmp_path / "ours"
    summary = bywire.spark.write_lake(spark, str(fleet), str(TUG_DBC), str(ours))
    through_spark = tmp_path / "spark"
    signals = spark.read.format("bywire").option("dbc", str(TUG_DBC)).option("output", "signals").load(str(fleet))
    signals.write.partitionBy("vehicle", "date", "message").parquet(str(through_spark))
    rows = lake_rows(spark, ours)
    assert rows == lake_rows(spark, through_spark)
    assert sum(rows.values()) == summary.rows == len(cantools_rows(fleet))
    assert partition_folders(ours) == partition_folders(through_spark)
    assert sorted(str(p.relative_to(ours)) for p in ours.rglob("*.parquet")) == summary.files
    assert (ours / "_SUCCESS").exists() and not (ours / "_temporary").exists()
    # Against cantools too, row for row (times as the data source's test rounds them).
    by_cantools = Counter(cantools_rows(fleet))
    assert Counter((v, d, round(ts.timestamp(), 6), m, s, x) for v, d, m, ts, _, s, x in rows.elements()) == Counter(
        (v, str(d), t, m, s, x) for v, d, t, m, s, x in by_cantools.elements()
    )


def test_write_lake_commits_all_or_nothing(spark, fleet, tmp_path):
    import bywire.spark

    lake = tmp_path / "lake"
    first = bywire.spark.write_lake(spark, str(fleet), str(TUG_DBC), str(lake))
    before = sorted(p.relative_to(lake) for p in lake.rglob("*") if p.is_file())
    with pytest.raises(FileExistsError, match="the lake exists"):
        bywire.spark.write_lake(spark, str(fleet), str(TUG_DBC), str(lake))
    assert bywire.spark.write_lake(spark, str(fleet), str(TUG_DBC), str(lake), mode="ignore").rows == 0
    # A log that breaks mid-file fails the job: the old lake stays as it was, nothing is left
    # staged, and the error names the file.
    broken = tmp_path / "broken" / "vehicle=tug3" / "date=2026-12-03"
    broken.mkdir(parents=True)
    good = next(fleet.rglob("*.log")).read_bytes()
    cut = good.index(b"\n", len(good) // 2) + 1
    (broken / "bus1.log").write_bytes(good[:cut] + b"(12.5) can0 12#\xff\n" + good[cut:])
    shutil.copytree(fleet / "vehicle=tug1", tmp_path / "broken" / "vehicle=tug1")
    with pytest.raises(Exception, match="bus1.log"):
        bywire.spark.write_lake(spark, str(tmp_path / "broken"), str(TUG_DBC), str(lake), mode="overwrite")
    assert sorted(p.relative_to(lake) for p in lake.rglob("*") if p.is_file()) == before
    assert not (lake / "_temporary").exists()
    # Append adds a job's files beside the others; overwrite replaces them.
    appended = bywire.spark.write_lake(spark, str(fleet), str(TUG_DBC), str(lake), mode="append")
    assert sum(lake_rows(spark, lake).values()) == first.rows + appended.rows
    only = bywire.spark.write_lake(spark, str(fleet / "vehicle=tug1"), str(TUG_DBC), str(lake), mode="overwrite")
    assert sorted(str(p.relative_to(lake)) for p in lake.rglob("*.parquet")) == only.files
    assert {r.vehicle for r in spark.read.parquet(str(lake)).select("vehicle").distinct().collect()} == {"tug1"}


def test_write_lake_keeps_few_files_open(spark, fleet, tmp_path):
    import bywire.spark

    everything = tmp_path / "everything"
    bywire.spark.write_lake(spark, str(fleet), str(TUG_DBC), str(everything))
    # One open file a task: each folder's file is finished before the next is opened.
    few = tmp_path / "few"
    bywire.spark.write_lake(spark, str(fleet), str(TUG_DBC), str(few), open_files=1)
    assert partition_folders(few) == partition_folders(everything)
    assert lake_rows(spark, few) == lake_rows(spark, everything)
    with pytest.raises(ValueError, match="open_files=0"):
        bywire.spark.write_lake(spark, str(fleet), str(TUG_DBC), str(tmp_path / "none"), open_files=0)


def comparable(value):
    """A cell as both readers can agree on it: Spark's decimal(20,0) of an unsigned column as
    an integer, NaN as text, binary as bytes."""
    if isinstance(value, (bytes, bytearray)):
        return bytes(value)
    if isinstance(value, decimal.Decimal):
        return int(value)
    if isinstance(value, float) and math.isnan(value):
        return "nan"
    return value


@pytest.mark.parametrize(
    "dbc, seed",
    [
        (TUG_DBC, None),
        # Multiplexed signals (nulls), choices, a 64-bit unsigned signal's neighbours and floats.
        (CORPUS / "dbc" / "opendbc" / "opendbc__dbc__vw_mlb.dbc", 7),
        (CORPUS / "dbc" / "cantools" / "tests__files__dbc__multiplex_choices.dbc", 11),
        (CORPUS / "dbc" / "cantools" / "tests__files__dbc__floating_point.dbc", 13),
    ],
    ids=["tug", "vw_mlb", "multiplex_choices", "floating_point"],
)
def test_spark_reads_the_decoded_tables_as_pyarrow_does(spark, fleet, tmp_path, dbc, seed):
    # The decoded tables (bywire's own Parquet encoding: delta-encoded times and integers,
    # dictionary keys) read by Spark's Parquet reader, table by table, equal pyarrow's reading
    # of them (which the Rust tests hold equal to cantools). Spark reads nanosecond times only
    # as numbers; written with --time-unit us, it reads them as times.
    if seed is None:
        log = next(fleet.rglob("bus1.log"))
    else:
        log = tmp_path / "traffic.log"
        traffic = subprocess.run(
            [sys.executable, str(ROOT / "crates" / "bywire" / "tests" / "oracles" / "dbc_traffic.py"), str(dbc), "20", str(seed)],
            check=True,
            capture_output=True,
        )
        log.write_bytes(traffic.stdout)
    nanos, micros = tmp_path / "nanos", tmp_path / "micros"
    for dataset, unit in [(nanos, "ns"), (micros, "us")]:
        subprocess.run(
            [bywire_cli(), "log", "convert", str(log), str(dataset), "--dbc", str(dbc), "--time-unit", unit],
            check=True,
            capture_output=True,
        )
    tables = sorted(p.parent.relative_to(nanos) for p in nanos.rglob("*.parquet"))
    assert tables
    assert tables == sorted(p.parent.relative_to(micros) for p in micros.rglob("*.parquet"))
    for table in tables:
        ours = arrow_rows(nanos / table)
        # The same rows in microseconds, each time floored.
        assert arrow_rows(micros / table) == Counter((row[0] // 1000, *row[1:]) for row in ours.elements())
        spark.conf.set("spark.sql.legacy.parquet.nanosAsLong", "true")
        try:
            assert spark_rows(spark, nanos / table, as_time=False) == ours, table
        finally:
            spark.conf.unset("spark.sql.legacy.parquet.nanosAsLong")
        assert spark_rows(spark, micros / table, as_time=True) == arrow_rows(micros / table), table


def test_spark_reads_raw_frames_in_microseconds_as_times(spark, fleet, tmp_path):
    # The raw frames' table (one row a frame) written with --time-unit us: Spark reads its
    # times as timestamps, every row as pyarrow reads it, and the times are the nanosecond
    # file's floored.
    log = next(fleet.rglob("bus1.log"))
    tables = {}
    for unit in ["ns", "us"]:
        tables[unit] = tmp_path / unit
        tables[unit].mkdir()
        subprocess.run(
            [bywire_cli(), "log", "convert", str(log), str(tables[unit] / "frames.parquet"), "--time-unit", unit],
            check=True,
            capture_output=True,
        )
    ours = arrow_rows(tables["ns"])
    assert sum(ours.values()) > 1000
    micros = arrow_rows(tables["us"])
    assert micros == Counter((row[0] // 1000, *row[1:]) for row in ours.elements())
    assert spark_rows(spark, tables["us"], as_time=True) == micros


def arrow_rows(table) -> Counter:
    """A table's rows as pyarrow reads them, ts as the integer it holds."""
    ours = pq.read_table(table)
    columns = ours.column_names
    assert columns[0] == "ts"
    return Counter(
        tuple(comparable(v) for v in row)
        for row in zip(ours.column("ts").cast("int64").to_pylist(), *(ours.column(c).to_pylist() for c in columns[1:]))
    )


def spark_rows(spark, table, as_time) -> Counter:
    """A table's rows as Spark reads them; `as_time`: ts read as a time, given in microseconds."""
    from pyspark.sql import functions

    frame = spark.read.parquet(str(table))
    assert frame.columns == pq.read_schema(next(table.glob("*.parquet"))).names, table
    if as_time:
        assert frame.schema["ts"].dataType.typeName() == "timestamp", frame.schema
        frame = frame.withColumn("ts", functions.unix_micros("ts"))
    return Counter(tuple(comparable(v) for v in row) for row in frame.collect())


def test_lake_files_are_read_by_pyarrow_as_written(fleet, tmp_path):
    import bywire.spark

    # One task's files, written by bywire (not pyarrow nor Spark), read back by pyarrow's
    # Hive-partitioned dataset: every signal value cantools decodes, in its folder.
    db = bywire.Database.load(str(TUG_DBC))
    logs = sorted(fleet.rglob("bus*.*"))
    parts = [(str(p), None, *bywire.spark.path_labels(str(p), None)) for p in logs]
    for compression, extension in [("snappy", ".snappy"), ("zstd", ".zstd"), ("gzip", ".gz"), ("none", "")]:
        staging = tmp_path / compression
        written = bywire._native.write_lake_files(db._native, parts, str(staging), "part-00007-job", compression)
        assert sorted(str(p.relative_to(staging)) for p in staging.rglob("*") if p.is_file()) == sorted(f for f, _ in written)
        assert all(f.endswith(f"/part-00007-job.c000{extension}.parquet") for f, _ in written)
        table = ds.dataset(str(staging), format="parquet", partitioning="hive").to_table()
        assert table.num_rows == sum(n for _, n in written)
        rows = Counter(
            (v, str(d), round(ts.timestamp(), 6), m, s, x)
            for v, d, m, ts, s, x in zip(
                *(table.column(c).to_pylist() for c in ("vehicle", "date", "message", "ts", "signal", "value"))
            )
        )
        assert rows == Counter((v, str(d), t, m, s, x) for v, d, t, m, s, x in cantools_rows(fleet)), compression
    with pytest.raises(ValueError, match="compression lz4"):
        bywire._native.write_lake_files(db._native, parts, str(tmp_path / "x"), "p", "lz4")


def test_a_commit_moves_only_the_job_s_files_and_new_folders_whole(tmp_path):
    import bywire.spark

    staging, lake = tmp_path / "staging", tmp_path / "lake"
    for file in ["v=a/m=x/part-0.parquet", "v=b/m=y/part-0.parquet", "v=b/m=y/.part-1.parquet.9.inprogress"]:
        (staging / file).parent.mkdir(parents=True, exist_ok=True)
        (staging / file).write_text(file)
    (lake / "v=b" / "m=z").mkdir(parents=True)
    (lake / "v=b" / "m=z" / "old.parquet").write_text("old")
    bywire.spark._commit(str(staging), str(lake), {"v=a/m=x/part-0.parquet", "v=b/m=y/part-0.parquet"})
    files = sorted(str(p.relative_to(lake)) for p in lake.rglob("*") if p.is_file())
    # The job's two files in place, the lake's own file kept, a killed attempt's file not moved.
    assert files == ["v=a/m=x/part-0.parquet", "v=b/m=y/part-0.parquet", "v=b/m=z/old.parquet"]
    assert (lake / "v=a" / "m=x" / "part-0.parquet").read_text() == "v=a/m=x/part-0.parquet"


def test_write_lake_dates_rows_by_their_day_without_one_in_the_path(spark, fleet, tmp_path):
    import datetime

    import bywire.spark

    logs = tmp_path / "logs" / "tug9"
    logs.mkdir(parents=True)
    candump = next(fleet.rglob("*.log"))
    (logs / "bus1.log").write_bytes(candump.read_bytes())
    lake = tmp_path / "lake"
    bywire.spark.write_lake(spark, str(tmp_path / "logs"), str(TUG_DBC), str(lake), path_pattern="{vehicle}/*.log")
    days = Counter(
        datetime.datetime.fromtimestamp(m.timestamp, datetime.timezone.utc).strftime("%Y-%m-%d")
        for m in can.LogReader(str(candump))
        for _ in range(len(cantools.database.load_file(str(TUG_DBC)).get_message_by_frame_id(m.arbitration_id).signals))
    )
    table = spark.read.parquet(str(lake))
    assert {r.vehicle for r in table.select("vehicle").distinct().collect()} == {"tug9"}
    assert Counter(str(r.date) for r in table.select("date").collect()) == days


def test_partition_folders_are_named_as_spark_names_them(spark, tmp_path):
    import bywire.spark

    values = ["tug 1", "a:b=c", "50%/x", "#hash?", "caf\u00e9[1]^{2}", "quote'\"", "tab\tend", None, ""]
    df = spark.createDataFrame([(v, 1) for v in values], "k string, v int")
    df.write.partitionBy("k").parquet(str(tmp_path / "spark"))
    written = {p.name for p in (tmp_path / "spark").iterdir() if p.name.startswith("k=")}
    assert written == {bywire.spark.partition_folder("k", v) for v in values}


def test_small_files_share_a_task_as_in_spark_file_sources(tmp_path):
    import bywire.spark

    sizes = [10, 300, 20, 700, 5]
    parts = []
    for n, size in enumerate(sizes):
        path = tmp_path / f"f{n}.log"
        path.write_bytes(b"x" * size)
        parts.append((str(path), None))
    parts.append((str(tmp_path / "f1.log"), (100, 400)))  # a range: its length counts
    # 1335 bytes + 6 x 50 (the open cost) = 1635, over 2 cores: at most 817 a task, filled
    # biggest first, each part counted with its open cost.
    tasks = bywire.spark.pack(parts, max_bytes=10_000, open_cost=50, parallelism=2)
    assert sorted(i for t in tasks for i in t) == list(range(len(parts)))
    assert tasks == [[3], [1, 5, 2, 0], [4]]
    assert bywire.spark.pack(parts, max_bytes=100, open_cost=50, parallelism=1) == [[3], [1], [5], [2, 0], [4]]


@pytest.mark.parametrize("writer", ["bywire", "spark"])
def test_the_data_lake_example(fleet, tmp_path, writer):
    out = tmp_path / "lake"
    subprocess.run(
        [sys.executable, str(ROOT / "examples" / "spark_data_lake.py"), str(fleet), str(TUG_DBC), str(out), "--writer", writer],
        check=True,
        env={**env_for_spark(), "PYSPARK_PYTHON": sys.executable},
        capture_output=True,
    )
    lake = ds.dataset(str(out), format="parquet", partitioning="hive").to_table()
    ours = [
        (r["vehicle"], str(r["date"]), round(r["ts"].timestamp(), 6), r["message"], r["signal"], r["value"])
        for r in lake.to_pylist()
    ]
    assert Counter(ours) == Counter(cantools_rows(fleet))
    partitions = {p.relative_to(out).parts[:3] for p in out.rglob("*.parquet")}
    assert ("vehicle=tug1", "date=2026-12-01", "message=VehicleToAds_State") in partitions


def test_the_sweep_example(tmp_path):
    import bywire
    import bywire.sim

    out = tmp_path / "sweep"
    subprocess.run(
        [sys.executable, str(ROOT / "examples" / "spark_sim_sweep.py"), str(out), "--seeds", "1..2", "--payloads", "0,1500", "--seconds", "3"],
        check=True,
        env={**env_for_spark(), "PYSPARK_PYTHON": sys.executable},
        capture_output=True,
    )
    table = ds.dataset(str(out), format="parquet", partitioning="hive").to_table()
    # Partition values come back as text where pyarrow cannot tell their type (0.0).
    runs = Counter((int(r["seed"]), float(r["payload"])) for r in table.select(["seed", "payload"]).to_pylist())
    assert set(runs) == {(1, 0.0), (1, 1500.0), (2, 0.0), (2, 1500.0)}
    # A run on an executor gives what the same run gives here.
    local = bywire.sim.run("apron-loop", 2, out=tmp_path / "local", payload=1500.0, max_seconds=3)
    db = bywire.Database.load(TUG_DBC)
    values = 0
    for bus in ("bus1", "bus3"):
        for table_ in db.decode_log(local.bus_logs[bus]).values():
            signals = [c for c in table_.column_names if c not in ("ts", "channel") and not c.endswith("_choice")]
            values += sum(table_.num_rows - table_.column(c).null_count for c in signals)
    assert runs[(2, 1500.0)] == values


def test_spark_finds_the_data_source_without_register(fleet):
    """pyspark 4 looks up `pyspark_*` packages at start-up: a fresh session reads
    format("bywire") with no call to bywire.spark.register."""
    script = (
        "import sys\n"
        "from pyspark.sql import SparkSession\n"
        "spark = SparkSession.builder.master('local[1]').config('spark.ui.enabled', 'false').getOrCreate()\n"
        "print(spark.read.format('bywire').load(sys.argv[1]).count())\n"
        "spark.stop()\n"
    )
    env = {**os.environ, **env_for_spark(), "PYSPARK_PYTHON": sys.executable}
    run = subprocess.run([sys.executable, "-c", script, str(fleet / "vehicle=tug1" / "date=2026-12-01" / "bus1.log")],
                         capture_output=True, text=True, env=env, timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    frames = sum(1 for _ in can.LogReader(str(fleet / "vehicle=tug1" / "date=2026-12-01" / "bus1.log")))
    assert int(run.stdout.strip().splitlines()[-1]) == frames
