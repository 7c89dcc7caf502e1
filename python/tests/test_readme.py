"""The README's Python blocks run as written: the section "Python and Spark", each indented
block in turn (pandas from the repository's root; Spark's from a folder holding a fleet's
logs under `logs/vehicle=…/date=…/` and the DBC, as the blocks name them)."""

from __future__ import annotations

import os
import shutil

import pytest

from conftest import ROOT


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


def test_the_spark_blocks_write_their_lake(spark, tmp_path, monkeypatch):
    logs = tmp_path / "logs" / "vehicle=tug1" / "date=2026-12-07"
    logs.mkdir(parents=True)
    shutil.copy(ROOT / "examples" / "data" / "drive.blf", logs / "drive.blf")
    shutil.copy(ROOT / "examples" / "data" / "reference-tug.dbc", tmp_path / "reference-tug.dbc")
    monkeypatch.chdir(tmp_path)
    _, spark_block, lake_block = blocks()
    exec(spark_block, {"spark": spark})
    written = sorted(p.relative_to(tmp_path / "lake") for p in (tmp_path / "lake").rglob("*.parquet"))
    assert any(str(p).startswith("vehicle=tug1/date=2026-12-07/message=VehicleToAds_State") for p in written), written
    shutil.rmtree(tmp_path / "lake")
    exec(lake_block, {"spark": spark, "bywire": __import__("bywire.spark")})
    assert (tmp_path / "lake" / "_SUCCESS").exists()
    assert any((tmp_path / "lake").rglob("*.parquet"))
