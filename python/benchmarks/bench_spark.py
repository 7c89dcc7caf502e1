"""Spark: a fleet's logs (candump and BLF) decoded into the partitioned Parquet data lake, same
Spark, same files, same lake, three ways: bywire's data source with Spark's Parquet writer,
bywire.spark.write_lake (bywire writes the lake on the executors), and the way it is done
without bywire (python-can's readers and cantools' decode_message in mapInPandas over the
file paths). Each job is timed from its start to its lake being committed; the lakes' rows are
counted afterwards and must agree.

    python3 python/benchmarks/bench_spark.py [FOLDER] [--cores 1,2] [--vehicles 4]

Run it inside ../shared/tools/lonet.sh (Spark binds loopback only there). A fleet is made once
in FOLDER (for another size, another folder).
"""

from __future__ import annotations

import argparse
import os
import pathlib
import shutil
import sys
import tempfile
import time

import pandas as pd

from common import TUG_DBC, fleet

os.environ.setdefault("SPARK_LOCAL_IP", "127.0.0.1")
os.environ.setdefault("PYSPARK_PYTHON", sys.executable)

from pyspark.sql import SparkSession  # noqa: E402

import bywire.spark  # noqa: E402

LONG = "ts timestamp, vehicle string, date string, channel string, message string, signal string, value double"


def with_python_can(dbc: str):
    """mapInPandas over rows of (path, vehicle, date): python-can reads, cantools decodes."""

    def run(frames):
        import can
        import cantools

        db = cantools.database.load_file(dbc)
        for paths in frames:
            for path, vehicle, date in paths.itertuples(index=False):
                rows = {k: [] for k in ("ts", "vehicle", "date", "channel", "message", "signal", "value")}
                for m in can.LogReader(path):
                    try:
                        message = db.get_message_by_frame_id(m.arbitration_id)
                        values = message.decode(m.data, decode_choices=False)
                    except (KeyError, cantools.database.DecodeError):
                        continue
                    for signal, value in values.items():
                        rows["ts"].append(m.timestamp)
                        rows["vehicle"].append(vehicle)
                        rows["date"].append(date)
                        rows["channel"].append(str(m.channel))
                        rows["message"].append(message.name)
                        rows["signal"].append(signal)
                        rows["value"].append(float(value))
                frame = pd.DataFrame(rows)
                micros = (frame["ts"] * 1e6).round().astype("int64")
                frame["ts"] = pd.to_datetime(micros, unit="us", utc=True)
                yield frame

    return run


def timed(what, job, lake: pathlib.Path, count) -> float:
    start = time.perf_counter()
    job()
    seconds = time.perf_counter() - start
    print(f"  {what}: {seconds:.2f} s ({count(lake)} rows)", flush=True)
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("folder", nargs="?")
    parser.add_argument("--cores", default="1,2")
    parser.add_argument("--vehicles", type=int, default=4, help="the fleet's size, when it is made")
    args = parser.parse_args()
    folder = pathlib.Path(args.folder or tempfile.mkdtemp(prefix="bywire-bench-"))
    logs = sorted(fleet(folder, vehicles=args.vehicles).glob("vehicle=*/date=*/bus*.*"))
    pattern = str(folder / "vehicle=*" / "date=*" / "bus*.*")
    out = pathlib.Path(tempfile.mkdtemp(prefix="bywire-lake-"))
    dbc = str(TUG_DBC)
    for cores in (int(c) for c in args.cores.split(",")):
        spark = (
            SparkSession.builder.master(f"local[{cores}]")
            .config("spark.ui.enabled", "false")
            .config("spark.sql.shuffle.partitions", str(cores))
            .getOrCreate()
        )
        spark.sparkContext.setLogLevel("ERROR")
        bywire.spark.register(spark)
        count = lambda lake: spark.read.parquet(str(lake)).count()  # noqa: E731
        print(f"local[{cores}], {len(logs)} files, {sum(p.stat().st_size for p in logs) / 1e6:.1f} MB", flush=True)

        def data_source():
            df = spark.read.format("bywire").option("dbc", dbc).option("output", "signals").load(pattern)
            df.write.mode("overwrite").partitionBy("vehicle", "date", "message").parquet(str(out / "data-source"))

        def write_lake():
            bywire.spark.write_lake(spark, pattern, dbc, str(out / "write-lake"), mode="overwrite")

        def theirs():
            rows = [(str(p), p.parent.parent.name.split("=")[1], p.parent.name.split("=")[1]) for p in logs]
            paths = spark.createDataFrame(rows, "path string, vehicle string, date string").repartition(len(rows))
            df = paths.mapInPandas(with_python_can(dbc), LONG)
            df.write.mode("overwrite").partitionBy("vehicle", "date", "message").parquet(str(out / "python-can"))

        data_source()  # warm: the JVM's code and the executors' Python workers
        write_lake()
        a = min(timed("bywire data source + Spark's writer", data_source, out / "data-source", count) for _ in range(3))
        b = min(timed("bywire.spark.write_lake", write_lake, out / "write-lake", count) for _ in range(3))
        c = timed("python-can + cantools in mapInPandas", theirs, out / "python-can", count)
        print(f"  ratio, data source: {c / a:.1f} x; write_lake: {c / b:.1f} x", flush=True)
        spark.stop()
    shutil.rmtree(out, ignore_errors=True)


if __name__ == "__main__":
    main()
