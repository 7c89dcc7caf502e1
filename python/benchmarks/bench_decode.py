"""db.decode_arrow against cantools' decode_message in a Python loop, on the same frames (one
core; the best of 3 runs of the cantools loop, and of 50 calls of decode_arrow: each takes a
few milliseconds, and its first calls fault in the memory the later ones reuse).

    python3 python/benchmarks/bench_decode.py [FOLDER]
"""

from __future__ import annotations

import pathlib
import sys
import tempfile
import time

import cantools
import pyarrow as pa

import bywire
from common import TUG_DBC, fleet


def best(seconds_of, runs: int = 5) -> float:
    return min(seconds_of() for _ in range(runs))


def main() -> None:
    folder = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else tempfile.mkdtemp(prefix="bywire-bench-"))
    logs = sorted(fleet(folder).glob("vehicle=*/date=*/bus*.*"))
    frames = pa.concat_tables([bywire.read_log(p).read_all() for p in logs])
    frames = frames.combine_chunks()
    ours = bywire.Database.load(TUG_DBC)
    theirs = cantools.database.load_file(str(TUG_DBC))
    ids = frames.column("id").to_pylist()
    datas = frames.column("data").to_pylist()
    known = {m.frame_id for m in theirs.messages}

    def cantools_loop() -> float:
        start = time.perf_counter()
        for frame_id, data in zip(ids, datas):
            if frame_id in known:
                try:
                    theirs.decode_message(frame_id, data)
                except cantools.database.DecodeError:
                    pass  # as decode_arrow counts it
        return time.perf_counter() - start

    def bywire_arrow() -> float:
        start = time.perf_counter()
        ours.decode_arrow(frames)
        return time.perf_counter() - start

    n = frames.num_rows
    a, b = best(cantools_loop, 3), best(bywire_arrow, 50)
    print(f"{n} frames of {len(logs)} logs")
    print(f"cantools decode_message loop: {a:.3f} s, {n / a / 1e6:.3f} M frames/s")
    print(f"bywire decode_arrow:          {b:.3f} s, {n / b / 1e6:.3f} M frames/s")
    print(f"ratio: {a / b:.0f} x")


if __name__ == "__main__":
    main()
