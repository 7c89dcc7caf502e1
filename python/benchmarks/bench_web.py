"""`bywire web` at 10,000 frames/s: does the page keep up?

Run inside lonet (multicast): ../shared/tools/lonet.sh python3 python/benchmarks/bench_web.py
[--rate 10000] [--seconds 10] [--bywire target/dist/bywire]

`bywire gen` sends bursts of 10 frames every millisecond (identifiers counting up, so the
reference tug's database decodes some of them) onto a udp bus that `bywire web` watches with the
database; Debian's Chromium shows the page in fixed mode with one signal plotted. Reported:
the rate the server counted, what the page received of it, what the server's per-client queue
dropped, how far behind the bus the page was at the end (the newest frame's time against the
clock), and the page's longest stall between two animation frames.
"""

import argparse
import json
import os
import subprocess
import sys
import time

from playwright.sync_api import sync_playwright

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
parser = argparse.ArgumentParser()
parser.add_argument("--rate", type=int, default=10_000)
parser.add_argument("--seconds", type=float, default=10.0)
parser.add_argument("--bywire", default=os.path.join(ROOT, "target/dist/bywire"))
args = parser.parse_args()

bus = "udp:239.74.163.9:43700"
dbc = os.path.join(ROOT, "examples/data/reference-tug.dbc")
web = subprocess.Popen(
    [args.bywire, "web", bus, "--db", dbc, "--listen", "127.0.0.1:0", "--bitrate", "1000000"],
    stdout=subprocess.PIPE, text=True,
)
address = web.stdout.readline().split("http://")[1].split("/")[0]

with sync_playwright() as p:
    browser = p.chromium.launch(executable_path="/usr/bin/chromium", args=["--no-sandbox"])
    page = browser.new_context(bypass_csp=True, viewport={"width": 1400, "height": 900}).new_page()
    page.goto(f"http://{address}/")
    page.wait_for_function("document.getElementById('status').textContent === 'connected'")
    page.wait_for_function("window.bywire.state.channels.size > 0")
    page.evaluate(f"window.bywire.plotSignal({json.dumps(bus)}, 'VehicleToAds_State', 'VelocityActual', 'm/s')")
    # The page's longest gap between animation frames while the traffic runs.
    page.evaluate("""() => { window.maxGap = 0; let last = performance.now();
        const tick = (t) => { window.maxGap = Math.max(window.maxGap, t - last); last = t; requestAnimationFrame(tick); };
        requestAnimationFrame(tick); }""")
    frames = int(args.rate * args.seconds)
    burst = 10
    gap_ms = burst * 1000 / args.rate
    started = time.time()
    subprocess.run(
        [args.bywire, "gen", bus, "-g", str(gap_ms), "-c", str(burst), "-n", str(frames), "-I", "i", "-L", "8", "-D", "i"],
        check=True, stdout=subprocess.DEVNULL,
    )
    sent_in = time.time() - started
    # Until the page has everything the server counted (or 5 s pass).
    deadline = time.time() + 5
    while time.time() < deadline:
        got = page.evaluate("window.bywire.state.received")
        if got >= frames:
            break
        time.sleep(0.1)
    lag = page.evaluate("Date.now() / 1000 - Math.max(...[...window.bywire.state.rows.values()].map((r) => r.time))")
    received = page.evaluate("window.bywire.state.received")
    gap = page.evaluate("window.maxGap")
    stats = page.evaluate("[...window.bywire.state.stats.values()]")
    browser.close()

web.send_signal(2)
tail = web.communicate(timeout=10)[0]
print(json.dumps({
    "frames_sent": frames,
    "sent_in_s": round(sent_in, 2),
    "rate_sent": round(frames / sent_in),
    "server_counted": stats[0]["frames"] if stats else None,
    "page_received": received,
    "server_said": tail.strip(),
    "page_behind_bus_s_at_end": round(lag, 3),
    "longest_animation_gap_ms": round(gap, 1),
}, indent=1))
