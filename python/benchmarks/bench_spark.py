"""Spark: a fleet's logs (candump and BLF) decoded into the partitioned Parquet data lake, by
bywire's data source and the way it is done without it (python-can's readers and cantools'
decode_message in mapInPandas over the file paths), same Spark, same files, same output.

    python3 python/benchmarks/bench_spark.py [FOLDER] [--cores 1,2]

Run it inside ../shared/tools/lonet.sh (Spark binds loopback only there).
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


def timed(what, job) -> float:
    start = time.perf_counter()
    rows = job()
    seconds = time.perf_counter() - start
    print(f"  {what}: {seconds:.2f} s ({rows} rows)")
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("folder", nargs="?")
    parser.add_argument("--cores", default="1,2")
    args = parser.parse_args()
    folder = pathlib.Path(args.folder or tempfile.mkdtemp(prefix="bywire-bench-"))
    logs = sorted(fleet(folder).glob("vehicle=*/date=*/bus*.*"))
    out = pathlib.Path(tempfile.mkdtemp(prefix="bywire-lake-"))
    dbc = str(TUG_DBC)
    for cores in (int(c) for c in args.cores.split(",")):
        spark = (
            SparkSession.builder.master(f"local[{cores}]")
            .config("spark.ui.enabled", "false")
            .config("spark.sql.shuffle.partitions", str(cores))
            .getOrCreate()
        )
        bywire.spark.register(spark)
        print(f"local[{cores}], {len(logs)} files, {sum(p.stat().st_size for p in logs) / 1e6:.1f} MB")

        def ours():
            df = spark.read.format("bywire").option("dbc", dbc).option("output", "signals").load(str(folder / "vehicle=*" / "date=*" / "bus*.*"))
            df.write.mode("overwrite").partitionBy("vehicle", "date", "message").parquet(str(out / "bywire"))
            return spark.read.parquet(str(out / "bywire")).count()

        def theirs():
            rows = [(str(p), p.parent.parent.name.split("=")[1], p.parent.name.split("=")[1]) for p in logs]
            paths = spark.createDataFrame(rows, "path string, vehicle string, date string").repartition(len(rows))
            df = paths.mapInPandas(with_python_can(dbc), LONG)
            df.write.mode("overwrite").partitionBy("vehicle", "date", "message").parquet(str(out / "python-can"))
            return spark.read.parquet(str(out / "python-can")).count()

        ours()  # warm: the executors' Python workers start
        a = min(timed("bywire data source", ours) for _ in range(3))
        b = timed("python-can + cantools in mapInPandas", theirs)
        print(f"  ratio: {b / a:.1f} x")
        spark.stop()
    shutil.rmtree(out, ignore_errors=True)


if __name__ == "__main__":
    main()
