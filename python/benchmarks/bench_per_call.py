"""One call at a time, as a cantools user calls it: ``db.decode_message``, ``message.decode``
and ``db.encode_message`` of bywire.database beside cantools', on the same frames in one run
(one core, the best of 5 passes over the frames for each):

- the reference tug's real traffic (simulator logs of its DBC);
- random payloads of a float-heavy DBC of the corpus (GM's object DBC), the messages every
  payload of which decodes in both.

    python3 python/benchmarks/bench_per_call.py [FOLDER]
"""

from __future__ import annotations

import pathlib
import random
import sys
import tempfile
import time
from collections.abc import Callable

import cantools
import pyarrow as pa

import bywire
import bywire.database
from common import GM_DBC, TUG_DBC, fleet, gm_messages

FRAMES = 100_000


def best(seconds_of: Callable[[], float], runs: int = 5) -> float:
    return min(seconds_of() for _ in range(runs))


def timed_calls(call: Callable[[int, object], object], inputs: list[tuple[int, object]]) -> Callable[[], float]:
    """A pass calling ``call(frame_id, x)`` (a bound method, as a user holds it) per input."""

    def run() -> float:
        start = time.perf_counter()
        for frame_id, x in inputs:
            call(frame_id, x)
        return time.perf_counter() - start

    return run


def timed_methods(inputs: list[tuple[Callable[[bytes], object], bytes]]) -> Callable[[], float]:
    """A pass calling each message's own ``decode`` on its payload."""

    def run() -> float:
        start = time.perf_counter()
        for decode, data in inputs:
            decode(data)
        return time.perf_counter() - start

    return run


def compare(title: str, dbc: pathlib.Path, frames: list[tuple[int, bytes]]) -> None:
    theirs = cantools.database.load_file(str(dbc), strict=False)
    ours = bywire.database.load_file(dbc, strict=False)
    frames = [(i, d) for i, d in frames if i in {m.frame_id for m in theirs.messages}]
    values = [(i, theirs.decode_message(i, d)) for i, d in frames]
    n = len(frames)
    print(f"{title}: {n} frames, {len(set(i for i, _ in frames))} messages")
    rows = [
        ("db.decode_message", timed_calls(theirs.decode_message, frames), timed_calls(ours.decode_message, frames)),
        (
            "message.decode",
            timed_methods([(theirs.get_message_by_frame_id(i).decode, d) for i, d in frames]),
            timed_methods([(ours.get_message_by_frame_id(i).decode, d) for i, d in frames]),
        ),
        ("db.encode_message", timed_calls(theirs.encode_message, values), timed_calls(ours.encode_message, values)),
    ]
    for name, cantools_pass, bywire_pass in rows:
        a, b = best(cantools_pass), best(bywire_pass)
        print(f"  {name:18} cantools {a / n * 1e6:6.2f} µs/call   bywire {b / n * 1e6:6.2f} µs/call   {a / b:5.1f} x")


def tug_frames(folder: pathlib.Path) -> list[tuple[int, bytes]]:
    logs = sorted(fleet(folder).glob("vehicle=*/date=*/bus*.*"))
    table = pa.concat_tables([bywire.read_log(p).read_all() for p in logs])
    ids, datas = table.column("id").to_pylist(), table.column("data").to_pylist()
    return list(zip(ids, datas))[:FRAMES]


def gm_frames() -> list[tuple[int, bytes]]:
    rng = random.Random(7)
    _, usable = gm_messages(rng)
    frames = []
    for _ in range(FRAMES):
        message = rng.choice(usable)
        frames.append((message.frame_id, rng.randbytes(message.length)))
    return frames


def main() -> None:
    folder = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else tempfile.mkdtemp(prefix="bywire-bench-"))
    compare("reference tug, simulated traffic", TUG_DBC, tug_frames(folder))
    compare("GM object DBC, random payloads", GM_DBC, gm_frames())


if __name__ == "__main__":
    main()
