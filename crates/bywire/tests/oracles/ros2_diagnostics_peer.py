"""A diagnostics listener for `bywire ros2 vehicle`, on Cyclone DDS as `diagnostic_aggregator`
would subscribe to `/diagnostics`: for `seconds` (no command sent), every DiagnosticArray, and
the statuses of the last one. Prints one JSON object.

usage: ros2_diagnostics_peer.py SECONDS"""

import json
import sys
import time

from ros2_types import DiagnosticArray, participant, reader

seconds = float(sys.argv[1])
dp = participant()
diagnostics = reader(dp, "rt/diagnostics", DiagnosticArray, depth=100)
arrays = []
# Wait for the first (discovery), then listen for the given time.
first = time.monotonic() + 15
while time.monotonic() < first and not arrays:
    arrays.extend((time.monotonic(), a) for a in diagnostics.take(N=100))
    time.sleep(0.01)
if not arrays:
    sys.exit("no /diagnostics")
end = time.monotonic() + seconds
while time.monotonic() < end:
    arrays.extend((time.monotonic(), a) for a in diagnostics.take(N=100))
    time.sleep(0.01)
start = arrays[0][0]
last = arrays[-1][1]
print(json.dumps({
    "count": len(arrays),
    "span": arrays[-1][0] - start,
    "levels": [[s.level for s in a.status] for _, a in arrays],
    "last": [{"level": s.level, "name": s.name, "message": s.message,
              "hardware_id": s.hardware_id,
              "values": {v.key: v.value for v in s.values}} for s in last.status],
}))
