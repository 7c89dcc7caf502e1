"""Logs on `bywire web`'s page, in Debian's Chromium (Playwright): every log (one per format,
all converted from one candump log) opens with the candump log's frame count; a signal plotted
from the candump log has cantools' values of every frame of its message; playing and stepping
fill the trace with decoded frames; an export of the whole log reads back in python-can with
every frame. A screenshot of the view goes to SHOTS.

usage: web_logs.py URL CANDUMP_LOG DBC SHOTS
"""

import json
import sys
import tempfile
import time
import urllib.request

import can
import cantools
from playwright.sync_api import sync_playwright

import web_browser

url, candump, dbc_path, shots = sys.argv[1:5]
db = cantools.database.load_file(dbc_path)
state = db.get_message_by_name("VehicleToAds_State")
frames = list(can.CanutilsLogReader(candump))
wanted = [state.decode(bytes(m.data), decode_choices=False)["VelocityActual"]
          for m in frames if m.arbitration_id == state.frame_id]


def wait(page, expression, what):
    web_browser.wait(page, expression, what, f"{shots}/failed-logs.png")


with sync_playwright() as p:
    browser, page, errors = web_browser.open_page(p, url)
    wait(page, "document.querySelectorAll('#log-select option').length > 1", "the logs")
    names = page.evaluate("[...document.querySelectorAll('#log-select option')].slice(1).map((o) => o.textContent)")
    counts = {}
    for index, name in enumerate(names):
        page.select_option("#log-select", str(index))
        wait(page, f"window.bywire.player.summary && window.bywire.player.summary.log === {index}", f"{name}'s summary")
        counts[name] = page.evaluate("window.bywire.player.summary.frames")
    assert all(n == len(frames) for n in counts.values()), (counts, len(frames))

    # The candump log: a signal over the whole log, every value (fewer than the points asked).
    first = names.index("candump.log")
    page.select_option("#log-select", str(first))
    wait(page, f"window.bywire.player.summary && window.bywire.player.summary.log === {first}", "the summary")
    page.evaluate("window.bywire.plotSignal('logs', 'VehicleToAds_State', 'VelocityActual', 'm/s')")
    wait(page, "window.bywire.series(0)[0].x.length > 0", "the log's series")
    series = page.evaluate("window.bywire.series(0)[0]")
    assert series["y"] == wanted, (series["y"][:10], wanted[:10])
    assert series["samples"] == len(wanted)

    # Play, then pause; then step one frame.
    page.select_option("#log-speed", "1")
    page.click("#log-play")
    # (The trace is drawn ten times a second: what it shows follows what the page holds.)
    wait(page, "window.bywire.rows().some((r) => r[3] === 'VehicleToAds_State' && r[8].includes('VelocityActual'))",
         "a decoded frame played into the trace")
    page.click("#log-play")
    before = page.evaluate("window.bywire.state.received")
    page.click("#log-step")
    wait(page, f"window.bywire.state.received === {before} + 1", "one frame stepped")
    page.screenshot(path=f"{shots}/logs.png")
    assert not errors, errors

    # A log of the user's, uploaded through the page: it opens as the others.
    page.set_input_files("#log-upload", candump)
    wait(page, f"window.bywire.player.summary && window.bywire.player.summary.log === {len(names)}", "the uploaded log")
    assert page.evaluate("window.bywire.player.summary.frames") == len(frames)

    # The whole log exported as BLF (the page's request, made here as it makes it).
    page.select_option("#log-select", str(first))
    wait(page, f"window.bywire.player.summary && window.bywire.player.summary.log === {first}", "the summary")
    summary = page.evaluate("window.bywire.player.summary")
    browser.close()

query = f"log={first}&from_ns={summary['start_ns']}&to_ns={summary['end_ns']}&format=blf"
request = urllib.request.Request(url.rstrip("/") + "/api/logs/export?" + query, headers={"X-Bywire": "1"})
with urllib.request.urlopen(request) as answer, tempfile.NamedTemporaryFile(suffix=".blf") as out:
    out.write(answer.read())
    out.flush()
    exported = list(can.BLFReader(out.name))
assert len(exported) == len(frames), (len(exported), len(frames))
assert [bytes(m.data) for m in exported] == [bytes(m.data) for m in frames]
print(json.dumps({"logs": counts, "points": len(wanted)}))
