"""A simulation sweep on Spark: scenario × seed × payload, each run on an executor by
bywire.sim.run, its command and sensor buses decoded with the tug's DBC, all written as one
Parquet dataset (long-form signals with the run's scenario, seed and payload).

    python3 examples/spark_sim_sweep.py OUT [--seeds 1..4] [--payloads 0,2000] [--seconds 20] [--master local[2]]
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
from collections.abc import Iterator

import pyarrow as pa
from pyspark.sql import SparkSession

import bywire
import bywire.sim
import bywire.spark

TUG_DBC = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "crates", "bywire-tug", "dbc", "reference-tug.dbc")
SCHEMA = bywire.spark.SIGNALS_SCHEMA + ", scenario string, seed bigint, payload double"


def run_all(dbc: str, seconds: float) -> callable:
    """The executors' work: a run per parameter row, decoded into long-form signals."""

    def run(batches: Iterator[pa.RecordBatch]) -> Iterator[pa.RecordBatch]:
        db = bywire.Database.load(dbc)
        for batch in batches:
            for params in batch.to_pylist():
                result = bywire.sim.run(params["scenario"], params["seed"], payload=params["payload"], max_seconds=seconds)
                try:
                    for bus in ("bus1", "bus3"):
                        frames = bywire.read_log(result.bus_logs[bus])
                        for name, table in db.iter_decoded(frames):
                            long = bywire.spark.signals_long(name, table, f"sim-{params['seed']}", None)
                            if long is None:
                                continue
                            n = long.num_rows
                            yield pa.RecordBatch.from_arrays(
                                [*long.columns, pa.array([params["scenario"]] * n), pa.array([params["seed"]] * n, pa.int64()), pa.array([params["payload"]] * n, pa.float64())],
                                names=[*long.schema.names, "scenario", "seed", "payload"],
                            )
                finally:
                    shutil.rmtree(result.out, ignore_errors=True)

    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out")
    parser.add_argument("--scenarios", default="apron-loop")
    parser.add_argument("--seeds", default="1..4", help="A..B, inclusive")
    parser.add_argument("--payloads", default="0,2000", help="kg, comma-separated")
    parser.add_argument("--seconds", type=float, default=20.0, help="simulated seconds per run at most")
    parser.add_argument("--dbc", default=TUG_DBC)
    parser.add_argument("--master", default="local[2]")
    args = parser.parse_args()
    first, last = (int(x) for x in args.seeds.split(".."))
    grid = [
        {"scenario": s, "seed": seed, "payload": float(p)}
        for s in args.scenarios.split(",")
        for seed in range(first, last + 1)
        for p in args.payloads.split(",")
    ]

    os.environ.setdefault("SPARK_LOCAL_IP", "127.0.0.1")
    os.environ.setdefault("PYSPARK_PYTHON", sys.executable)
    spark = SparkSession.builder.master(args.master).appName("bywire sweep").config("spark.ui.enabled", "false").getOrCreate()
    # One run per partition: the runs spread over the executors' cores.
    params = spark.createDataFrame(grid, "scenario string, seed bigint, payload double").repartition(len(grid))
    signals = params.mapInArrow(run_all(os.path.abspath(args.dbc), args.seconds), SCHEMA)
    signals.write.mode("overwrite").partitionBy("scenario", "seed", "payload", "message").parquet(args.out)
    print(f"{len(grid)} runs, {spark.read.parquet(args.out).count()} signal values written to {args.out}")
    spark.stop()


if __name__ == "__main__":
    main()
