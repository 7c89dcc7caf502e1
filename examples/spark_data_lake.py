"""A folder of CAN logs from several vehicles (any format, e.g. logs/vehicle=tug1/date=2026-12-01/
drive.blf) decoded on Spark into a Parquet data lake partitioned by vehicle, date and message.

    python3 examples/spark_data_lake.py LOGS DBC OUT [--pattern '{vehicle}/{date}/*'] [--master local[2]]
                                          [--writer bywire|spark]

The logs are read and decoded on the executors by bywire; the rows are long-form signals (ts,
vehicle, date, channel, message, signal, value). With ``--writer bywire`` (the default) bywire
also writes the lake on the executors (bywire.spark.write_lake); with ``--writer spark`` the
rows go through Spark's DataFrame writer (the data source, one partition a file).
"""

from __future__ import annotations

import argparse
import os
import sys

from pyspark.sql import SparkSession

import bywire.spark


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("logs", help="a folder of logs, a file, or a glob (** crosses folders)")
    parser.add_argument("dbc")
    parser.add_argument("out", help="the data lake's folder (replaced)")
    parser.add_argument("--pattern", help="where vehicle and date are in a path, e.g. '{vehicle}/{date}/*'")
    parser.add_argument("--master", default="local[2]")
    parser.add_argument("--writer", choices=("bywire", "spark"), default="bywire")
    args = parser.parse_args()

    # Local mode binds loopback only; executors run this same Python.
    os.environ.setdefault("SPARK_LOCAL_IP", "127.0.0.1")
    os.environ.setdefault("PYSPARK_PYTHON", sys.executable)
    spark = (
        SparkSession.builder.master(args.master)
        .appName("bywire data lake")
        .config("spark.ui.enabled", "false")
        .getOrCreate()
    )
    if args.writer == "bywire":
        bywire.spark.write_lake(spark, args.logs, args.dbc, args.out, mode="overwrite", path_pattern=args.pattern)
    else:
        bywire.spark.register(spark)
        reader = spark.read.format("bywire").option("dbc", args.dbc).option("output", "signals")
        if args.pattern:
            reader = reader.option("path_pattern", args.pattern)
        signals = reader.load(args.logs)
        signals.write.mode("overwrite").partitionBy("vehicle", "date", "message").parquet(args.out)
    rows = spark.read.parquet(args.out).count()
    print(f"{rows} signal values written to {args.out}")
    spark.stop()


if __name__ == "__main__":
    main()
