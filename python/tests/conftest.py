"""Shared paths and helpers for the Python package's tests."""

from __future__ import annotations

import os
import pathlib
import shutil
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
CORPUS = ROOT.parent / "shared" / "corpus"
TUG_DBC = ROOT / "crates" / "bywire-tug" / "dbc" / "reference-tug.dbc"


def plain(value):
    """A decoded value comparable across cantools and bywire: a choice as (raw, name)."""
    if hasattr(value, "name") and hasattr(value, "value"):
        return (value.value, value.name)
    if isinstance(value, float) and value != value:
        return "NaN"
    return value


def plain_dict(decoded: dict) -> dict:
    return {k: plain(v) for k, v in decoded.items()}


def bywire_cli() -> str:
    """The command-line tool built by the workspace's tests (debug), or release, or PATH."""
    for profile in ("debug", "release"):
        path = ROOT / "target" / profile / "bywire"
        if path.exists():
            return str(path)
    found = shutil.which("bywire")
    if found:
        return found
    subprocess.run(["cargo", "build", "-q", "-p", "bywire"], cwd=ROOT, check=True)
    return str(ROOT / "target" / "debug" / "bywire")


@pytest.fixture(scope="session")
def sim_run(tmp_path_factory):
    """One short simulator run (its logs hold every message of the reference tug's DBC)."""
    import bywire.sim

    out = tmp_path_factory.mktemp("sim")
    return bywire.sim.run("apron-loop", seed=5, out=out, max_seconds=15.0)


def env_for_spark() -> dict:
    env = dict(os.environ)
    env["SPARK_LOCAL_IP"] = "127.0.0.1"
    return env


@pytest.fixture(scope="module")
def spark():
    """A local Spark session (two threads) with bywire's data source registered."""
    import sys

    os.environ.update(env_for_spark())
    os.environ["PYSPARK_PYTHON"] = sys.executable
    from pyspark.sql import SparkSession

    import bywire.spark

    session = SparkSession.builder.master("local[2]").config("spark.ui.enabled", "false").getOrCreate()
    bywire.spark.register(session)
    yield session
    session.stop()
