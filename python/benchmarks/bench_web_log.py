"""A 1 GB log on `bywire web`'s page: the time to its first plot.

python3 python/benchmarks/bench_web_log.py [--gigabytes 1] [--bywire target/dist/bywire]

Writes a candump log of the reference tug's vehicle bus (its messages in turn, values moving)
of the size asked, serves it with `bywire web -I`, then times what the page asks when the log
is chosen and a signal clicked: the summary (the log read once) and the signal over the whole
log, decimated on the server to 2,000 points. The log is kept in target/ for the next run.
"""

import argparse
import json
import os
import subprocess
import time
import urllib.request

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
parser = argparse.ArgumentParser()
parser.add_argument("--gigabytes", type=float, default=1.0)
parser.add_argument("--bywire", default=os.path.join(ROOT, "target/dist/bywire"))
args = parser.parse_args()

path = os.path.join(ROOT, f"target/web-bench-{args.gigabytes:g}GB.log")
wanted = int(args.gigabytes * 1e9)
if not os.path.exists(path) or os.path.getsize(path) < wanted:
    ids = ["000", "001", "100", "101", "102", "103", "104", "105", "110", "120"]
    with open(path + ".part", "w") as out:
        written, i = 0, 0
        while written < wanted:
            lines = []
            for _ in range(10_000):
                t = 1_765_000_000 + i * 0.0002
                lines.append(f"({t:.6f}) bus1 {ids[i % len(ids)]}#{(i * 2654435761) & 0xFFFFFFFFFFFFFFFF:016X}\n")
                i += 1
            block = "".join(lines)
            out.write(block)
            written += len(block)
    os.replace(path + ".part", path)

dbc = os.path.join(ROOT, "examples/data/reference-tug.dbc")
web = subprocess.Popen(
    [args.bywire, "web", "-I", path, "--db", dbc, "--listen", "127.0.0.1:0"],
    stdout=subprocess.PIPE, text=True,
)
address = web.stdout.readline().split("http://")[1].split("/")[0]


def get(what):
    request = urllib.request.Request(f"http://{address}/api/logs/{what}", headers={"X-Bywire": "1"})
    with urllib.request.urlopen(request, timeout=600) as answer:
        return json.loads(answer.read())


started = time.time()
summary = get("summary?log=0")
summed = time.time() - started
query = f"series?log=0&bus=bus1&message=VehicleToAds_State&signal=VelocityActual&from_ns={summary['start_ns']}&to_ns={summary['end_ns']}&points=2000"
started = time.time()
series = get(query)
plotted = time.time() - started
web.send_signal(2)
web.wait(timeout=10)
size = os.path.getsize(path)
print(json.dumps({
    "log_bytes": size,
    "frames": summary["frames"],
    "summary_s": round(summed, 2),
    "series_s": round(plotted, 2),
    "time_to_first_plot_s": round(summed + plotted, 2),
    "read_mb_per_s": round(size / 1e6 / summed),
    "points": len(series["x"]),
    "samples": series["samples"],
}, indent=1))
