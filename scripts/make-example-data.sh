#!/usr/bin/env bash
# The README's example data (examples/data/), made from this checkout: a paced commands.jsonl
# for `bywire bridge`, and logs of the simulated tug's vehicle bus (candump, Vector BLF and
# ASC) from a fixed seed and start time, so the same checkout makes the same files.
set -euo pipefail
cd "$(dirname "$0")/.."
data=examples/data
# Any build gives the same files (the simulator's arithmetic is the same in debug and release).
bywire=${BYWIRE:-target/release/bywire}
[ -n "${BYWIRE:-}" ] || cargo build -q --release -p bywire
run=$(mktemp -d)
trap 'rm -rf "$run"' EXIT
# Twenty simulated seconds of the apron loop: engaging, the steering step test, driving off.
"$bywire" sim --fast --seed 7 --start-time 2026-12-07T08:00:00Z --max-seconds 20 --out "$run" > /dev/null
cp "$run/bus1.log" "$data/candump.log"
"$bywire" log convert "$data/candump.log" "$data/drive.blf"
"$bywire" log convert "$data/candump.log" "$data/drive.asc"
# Commands at 20 Hz: autonomous mode asked for a second, then engage (an edge, twice), a
# gentle drive with a steering sweep, and a stop; the end of input brakes (--estop-on-eof).
python3 - "$data/commands.jsonl" <<'PY'
import json, math, sys
lines = []
for k in range(200):
    t = k * 0.05
    line = {"at_s": round(t, 2)}
    if t < 2.0:
        line.update(velocity=0.0, brake=30.0, gear="drive", mode="autonomous")
        if k in (20, 30):
            line["engage"] = True
    elif t < 8.0:
        line.update(velocity=1.5, brake=0.0, steering=round(10.0 * math.sin((t - 2.0) * math.pi / 3.0), 2))
    else:
        line.update(velocity=0.0, brake=30.0, steering=0.0)
    lines.append(json.dumps(line))
open(sys.argv[1], "w").write("\n".join(lines) + "\n")
PY
# The tug's profile with its command path secured (SecOC), and a demonstration key (public).
{ cat crates/bywire-tug/profiles/reference-tug.toml
  printf '\n# The command path authenticated (AUTOSAR SecOC, CMAC-AES-128).\n[secoc]\n'
  printf 'messages = ["AdsToVehicle_Control", "EmergencyBrake", "VehicleToAds_State", "VehicleToAds_Sensors", "VehicleToAds_WheelAngles"]\n'
  printf 'fv_length = 64\nfv_tx_length = 8\nmac_tx_length = 24\nkey_id = 1\nsync_id = 0x0F0\n'
} > "$data/secured.toml"
echo "1 2b7e151628aed2a6abf7158809cf4f3c" > "$data/demo.keys"
# A CANopen bus for `bywire ros2 canopen`, as ros2_canopen's bus.yml says it, in TOML.
cat > "$data/bus.toml" <<'TOML'
[master]
node_id = 1
bitrate = 1_000_000

[node.wheel]
id = 2
profile = "cia402"
driver = "cia402"
mode = "profile_position"
heartbeat_timeout_ms = 300
TOML
ls -l "$data"
