"""The log commands against their peers, on the same file in one run (one core for each):
`bywire log convert` against python-can's `can.logconvert` (BLF, ASC, MF4), `bywire decode
--json` against `python -m cantools decode`, and `bywire log stats`'s reading speed.

    python3 python/benchmarks/bench_logs.py [FRAMES] [DBC]

The input is random traffic of the DBC's messages (their identifiers and lengths, random
payloads, 100 µs apart on two interfaces), written once as a candump log. Each bywire figure is
the best of 5 runs, each peer figure the best of 2. Needs the CLI as it ships
(`cargo build --profile dist -p bywire`), python-can and cantools; does not need the package.
"""

from __future__ import annotations

import os
import pathlib
import random
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[2]
FORD = ROOT.parent / "shared" / "corpus" / "dbc" / "opendbc" / "opendbc__dbc__ford_lincoln_base_pt.dbc"
CLI = ROOT / "target" / "dist" / "bywire"


def candump_log(path: pathlib.Path, dbc: pathlib.Path, frames: int) -> None:
    import cantools

    db = cantools.database.load_file(str(dbc), strict=False)
    messages = [(m.frame_id, m.is_extended_frame, m.length) for m in db.messages if m.length <= 8]
    rng = random.Random(1)
    with path.open("w") as out:
        for n in range(frames):
            frame_id, extended, length = rng.choice(messages)
            ident = f"{frame_id:08X}" if extended else f"{frame_id:03X}"
            data = rng.randbytes(length).hex().upper()
            stamp = 1_700_000_000_000_000 + n * 100
            out.write(f"({stamp // 1_000_000}.{stamp % 1_000_000:06d}) can{n % 2} {ident}#{data}\n")


def seconds(command: list[str], runs: int) -> float:
    best = float("inf")
    for _ in range(runs):
        start = time.perf_counter()
        subprocess.run(command, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        best = min(best, time.perf_counter() - start)
    return best


def main() -> None:
    frames = int(sys.argv[1]) if len(sys.argv) > 1 else 200_000
    dbc = pathlib.Path(sys.argv[2]) if len(sys.argv) > 2 else FORD
    if not CLI.exists():
        sys.exit(f"{CLI}: build it first (cargo build --profile dist -p bywire)")
    folder = pathlib.Path(tempfile.mkdtemp(prefix="bywire-bench-logs-"))
    log = folder / "in.log"
    candump_log(log, dbc, frames)
    size = log.stat().st_size
    print(f"{frames} frames, {size / 1e6:.1f} MB of candump, {dbc.name}")
    # One core for both sides.
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})

    rows = []
    for ext in ("blf", "asc", "mf4"):
        ours = seconds([str(CLI), "log", "convert", str(log), str(folder / f"ours.{ext}")], 5)
        theirs = seconds([sys.executable, "-m", "can.logconvert", str(log), str(folder / f"theirs.{ext}")], 2)
        rows.append((f"candump -> {ext.upper()} vs can.logconvert", ours, theirs))
    ours = seconds(
        ["sh", "-c", f"{CLI} decode --json {dbc} < {log} > /dev/null"], 5
    )
    theirs = seconds(
        ["sh", "-c", f"{sys.executable} -m cantools decode --no-strict {dbc} < {log} > /dev/null"], 2
    )
    rows.append(("decode --json vs cantools decode", ours, theirs))
    for name, a, b in rows:
        print(f"{name:40} bywire {a:7.3f} s   peer {b:7.3f} s   {b / a:6.1f} x")
    stats = seconds([str(CLI), "log", "stats", str(log)], 5)
    print(f"{'log stats (reading)':40} bywire {stats:7.3f} s   {size / stats / 1e6:6.0f} MB/s")


if __name__ == "__main__":
    main()
