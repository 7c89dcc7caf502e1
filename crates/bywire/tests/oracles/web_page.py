"""Drive `bywire web`'s page in a real headless browser (Debian's Chromium through Playwright)
while python-can sends frames cantools encoded on the same udp_multicast bus: the trace's
decoded values and a plotted signal's points are compared with cantools' decoding of what was
sent; the transmit panel sends a raw frame and a message by its signals (which `bywire dump`
sees, checked by the test). Screenshots of the main views go to SHOTS.

usage: web_page.py URL BUS_GROUP BUS_PORT DBC SHOTS
Prints one JSON object: what was compared, and what the page sent.
"""

import json
import sys
import time

import can
import cantools
from playwright.sync_api import sync_playwright

import web_browser

url, group, port, dbc_path, shots = sys.argv[1:6]
port = int(port)
db = cantools.database.load_file(dbc_path)
bus_name = f"udp:{group}:{port}"
state = db.get_message_by_name("VehicleToAds_State")
sensors = db.get_message_by_name("VehicleToAds_Sensors")


def wait(page, expression, what):
    web_browser.wait(page, expression, what, f"{shots}/failed.png")


sent_state = []
with sync_playwright() as p:
    browser, page, errors = web_browser.open_page(p, url)
    wait(page, "document.getElementById('status').textContent === 'connected'", "its connection")
    wait(page, "window.bywire.state.channels.size > 0", "the channels")
    page.evaluate(f"window.bywire.plotSignal({json.dumps(bus_name)}, 'VehicleToAds_State', 'VelocityActual', 'm/s')")
    page.evaluate(f"window.bywire.plotSignal({json.dumps(bus_name)}, 'VehicleToAds_State', 'SteeringAngleActual', 'deg')")

    with can.Bus(interface="udp_multicast", channel=group, port=port, receive_own_messages=False) as bus:
        for i in range(40):
            values = {
                "SteeringAngleActual": -20.0 + i * 1.1,
                "VelocityActual": round(0.2 * i, 2),
                "ControlMode": "Autonomous" if i % 2 else "Manual",
                "SteeringMode": "Crab" if i > 30 else "Normal",
                "Gear": "Drive",
                "WatchdogLevel": 0,
                "EstopState": 0,
                "WarningFlag": 0,
                "DriverOverride": 0,
                "SteeringEnabled": 1,
                "HeartbeatEcho": i % 16,
                "Counter": i % 16,
                "Checksum": 0,
            }
            data = state.encode(values, strict=False)
            sent_state.append(data)
            bus.send(can.Message(arbitration_id=state.frame_id, data=data, is_extended_id=False))
            wheel = {s.name: 0.5 * i for s in sensors.signals if s.name.startswith("WheelSpeed")}
            wheel.update(Counter=i % 16, Checksum=0)
            bus.send(can.Message(arbitration_id=sensors.frame_id, data=sensors.encode(wheel, strict=False), is_extended_id=False))
            time.sleep(0.01)

        wait(page, "window.bywire.series(0)[0].x.length >= 40", "40 plotted points")
        series = page.evaluate("window.bywire.series(0)")
        decoded = [state.decode(d, decode_choices=False) for d in sent_state]
        wanted = {
            "VelocityActual": [d["VelocityActual"] for d in decoded],
            "SteeringAngleActual": [d["SteeringAngleActual"] for d in decoded],
        }
        got = {s["signal"]: s["y"] for s in series}
        assert got == wanted, (got, wanted)

        # The trace's row for the state message: the last frame's values as cantools gives them.
        key = f"{bus_name}/{state.frame_id}/false"
        wait(page, f"window.bywire.state.rows.get({json.dumps(key)}).count === 40", "40 frames counted")
        row = page.evaluate(f"window.bywire.state.rows.get({json.dumps(key)})")
        last_numbers = state.decode(sent_state[-1], decode_choices=False)
        last_named = state.decode(sent_state[-1])
        for name, value in last_numbers.items():
            assert row["decoded"][name] == value, (name, row["decoded"][name], value)
            if name + "_choice" in row["decoded"]:
                assert row["decoded"][name + "_choice"] == str(last_named[name]), name
        assert bytes(row["data"]) == sent_state[-1]
        # What the trace shows (drawn ten times a second) follows.
        wait(page, "window.bywire.rows().some((r) => r[3] === 'VehicleToAds_State' && r[8].includes('Gear: Drive'))",
             "the state message's decoded row")

        # A filter on a signal's value: only the state message's row passes.
        page.fill("#filter", "VelocityActual>5")
        wait(page, "window.bywire.rows().length === 1", "one row through the filter")
        page.fill("#filter", "")
        page.screenshot(path=f"{shots}/trace-and-plots.png")

        # The transmit panel: a raw frame, then a message by its signals.
        wait(page, "!document.getElementById('send-pane').hidden", "the transmit panel")
        page.fill("#send-id", "123")
        page.fill("#send-data", "DE AD BE EF")
        page.click("#send-once")
        page.select_option("#send-message", "AdsToVehicle_Control")
        page.fill("input[data-signal='VelocityCmd']", "1.5")
        page.fill("input[data-signal='SteeringAngleCmd']", "-12.5")
        page.fill("input[data-signal='GearCmd']", "Drive")
        page.click("#send-once")
        wait(page, "document.getElementById('send-said').textContent.startsWith('sent at')", "the send said")
        page.screenshot(path=f"{shots}/transmit.png")
        status = page.evaluate("document.getElementById('status').textContent")
    assert not errors, errors
    browser.close()

print(json.dumps({"points": len(sent_state), "status": status}))
