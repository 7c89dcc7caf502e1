"""Inputs for the Python benchmarks: simulator runs' logs of the reference tug (its DBC's real
traffic), as a fleet of vehicles in candump and BLF."""

from __future__ import annotations

import os
import pathlib
import subprocess

import bywire.sim

ROOT = pathlib.Path(__file__).resolve().parents[2]
TUG_DBC = ROOT / "crates" / "bywire-tug" / "dbc" / "reference-tug.dbc"


def cli() -> str:
    for profile in ("release", "debug"):
        path = ROOT / "target" / profile / "bywire"
        if path.exists():
            return str(path)
    subprocess.run(["cargo", "build", "--release", "-q", "-p", "bywire"], cwd=ROOT, check=True)
    return str(ROOT / "target" / "release" / "bywire")


def fleet(folder: pathlib.Path, vehicles: int = 4, seconds: float = 120.0) -> pathlib.Path:
    """vehicle=tugN/date=2026-12-DD/{bus1.log, bus3.blf}: command and sensor buses of one run
    per vehicle, seeded by N (made once, kept in `folder`)."""
    done = folder / "done"
    if done.exists():
        return folder
    for n in range(1, vehicles + 1):
        run = bywire.sim.run("apron-loop", seed=n, out=folder / f"run{n}", max_seconds=seconds)
        target = folder / f"vehicle=tug{n}" / f"date=2026-12-{(n - 1) % 28 + 1:02d}"
        target.mkdir(parents=True, exist_ok=True)
        os.replace(run.bus_logs["bus1"], target / "bus1.log")
        subprocess.run([cli(), "log", "convert", run.bus_logs["bus3"], str(target / "bus3.blf")], check=True, capture_output=True)
    done.write_text("")
    return folder


GM_DBC = ROOT.parent / "shared" / "corpus" / "dbc" / "opendbc" / "opendbc__dbc__gm_global_a_object.dbc"


def gm_messages(rng):
    """cantools' database of GM's object DBC and the messages every random payload of which
    it decodes (59 of them): the benchmarks' float-heavy traffic."""
    import cantools

    db = cantools.database.load_file(str(GM_DBC), strict=False)
    usable = []
    for message in db.messages:
        try:
            for _ in range(20):
                db.decode_message(message.frame_id, rng.randbytes(message.length))
            usable.append(message)
        except cantools.database.DecodeError:
            continue
    return db, usable
