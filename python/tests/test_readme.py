"""The README's Python blocks run as written: the section "Python and Spark", each indented
block in turn (pandas from the repository's root; Spark's from a folder holding a fleet's
logs under `logs/vehicle=…/date=…/` and the DBC, as the blocks name them)."""

from __future__ import annotations

import shutil
import subprocess
import sys

from conftest import ROOT, env_for_spark


def blocks() -> list[str]:
    """The section's indented blocks, in order."""
    text = (ROOT / "README.md").read_text()
    section = text.split("### Python and Spark\n", 1)[1].split("\n## ", 1)[0]
    found, block = [], []
    for line in section.split("\n") + [""]:
        if line.startswith("    "):
            block.append(line[4:])
        elif block and line.strip() == "":
            found.append("\n".join(block))
            block = []
    return found


def test_the_section_has_a_pandas_block_and_spark_blocks():
    found = blocks()
    assert len(found) == 3, found
    assert "decode_log" in found[0] and "register(spark)" in found[1] and "write_lake" in found[2]


def test_the_pandas_block_runs_from_the_root(capsys, monkeypatch):
    monkeypatch.chdir(ROOT)
    exec(blocks()[0], {})
    printed = capsys.readouterr().out
    assert "VelocityActual" in printed and "Gear_choice" in printed


def test_the_spark_blocks_write_their_lake(tmp_path):
    """In a Python of their own started in the folder the blocks name their paths from (Spark
    resolves a relative path from where it started), with a local session as `spark`."""
    logs = tmp_path / "logs" / "vehicle=tug1" / "date=2026-12-07"
    logs.mkdir(parents=True)
    shutil.copy(ROOT / "examples" / "data" / "drive.blf", logs / "drive.blf")
    shutil.copy(ROOT / "examples" / "data" / "reference-tug.dbc", tmp_path / "reference-tug.dbc")
    _, spark_block, lake_block = blocks()
    script = "\n".join([
        "import pathlib, shutil",
        "from pyspark.sql import SparkSession",
        'spark = SparkSession.builder.master("local[2]").config("spark.ui.enabled", "false").getOrCreate()',
        spark_block,
        'found = sorted(str(p) for p in pathlib.Path("lake").rglob("*.parquet"))',
        'assert any(p.startswith("lake/vehicle=tug1/date=2026-12-07/message=VehicleToAds_State") for p in found), found',
        'shutil.rmtree("lake")',
        lake_block,
        'assert pathlib.Path("lake/_SUCCESS").exists() and any(pathlib.Path("lake").rglob("*.parquet"))',
        'spark.stop()',
        'print("lakes written")',
    ])
    env = {**env_for_spark(), "PYSPARK_PYTHON": sys.executable}
    done = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert done.returncode == 0 and "lakes written" in done.stdout, done.stderr[-3000:]
