#!/usr/bin/env bash
# Malformed RTPS against `bywire ros2 can` at scale (the test suite sends 50,000): seeds captured
# from the node's real exchange with Cyclone DDS, then COUNT mutated datagrams (default
# 1,000,000), the node's memory before, at its peak and after, and whether SIGINT still ends it.
# Needs what scripts/install-test-deps.sh installs; runs itself inside ../shared/tools/lonet.sh.
#   scripts/rtps-flood.sh [COUNT] [SEED]
set -euo pipefail
cd "$(dirname "$0")/.."
if [ -z "${BYWIRE_IN_LONET:-}" ]; then
  exec env BYWIRE_IN_LONET=1 ../shared/tools/lonet.sh "$0" "$@"
fi
count="${1:-1000000}"
seed="${2:-1}"
cargo build -q -p bywire
bywire="$PWD/target/debug/bywire"
oracles="$PWD/crates/bywire/tests/oracles"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
bus="udp:239.74.163.2:43540"
tshark -i lo -f udp -w "$work/discovery.pcapng" 2> "$work/tshark.err" &
capture=$!
until grep -q "Capturing on" "$work/tshark.err" 2>/dev/null; do sleep 0.1; done
"$bywire" ros2 can "$bus" --dds-interface lo > /dev/null 2>&1 &
node=$!
python3 "$oracles/ros2_can_peer.py" 239.74.163.2 43540 > /dev/null
kill -INT "$node"; wait "$node" || true
kill -INT "$capture"; wait "$capture" || true
tshark -r "$work/discovery.pcapng" -T fields -e udp.dstport -e udp.payload > "$work/seeds.txt"
"$bywire" ros2 can "$bus" --dds-interface lo > /dev/null 2>&1 &
node=$!
python3 "$oracles/rtps_flood.py" "$node" "$count" "$seed" "$work/seeds.txt"
start=$(date +%s%N)
kill -INT "$node"; wait "$node" || true
echo "ended $(( ($(date +%s%N) - start) / 1000000 )) ms after SIGINT"
