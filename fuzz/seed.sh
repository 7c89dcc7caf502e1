#!/usr/bin/env bash
# Seeds the file readers' fuzz targets with real files, written by bywire's own writers from a
# few frames of every kind: from an empty corpus libFuzzer seldom gets past a binary format's
# header (the MF4 target stayed at 95 edges in 2 M runs; seeded, it reached 2,300, and the
# Parquet target found parquet-rs's panics within minutes).
set -euo pipefail
cd "$(dirname "$0")"
bywire() { cargo run -q --manifest-path ../Cargo.toml -p bywire -- "$@"; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# Classic, extended, remote, FD with BRS, an error frame, two channels, both directions.
cat > "$work/frames.log" <<'LOG'
(1700000000.000100) can0 123#DEADBEEF
(1700000000.000200) can1 1ABCDEF0#0102
(1700000000.000300) can0 456#R3
(1700000000.000400) can0 7FF##1AABB
(1700000000.000500) can1 20000080#0000000000000000
(1700000000.000600) can0 100##0001122334455667788
LOG
mkdir -p corpus/candump_log corpus/log_readers corpus/mf4_reader corpus/parquet_reader
cp "$work/frames.log" corpus/candump_log/seed-frames
# log_readers: the first byte picks the format, in the target's order.
index=0
for format in asc trc blf pcapng mcap; do
  bywire log convert "$work/frames.log" "$work/frames.$format" > /dev/null
  { printf "\\x$(printf %02x "$index")"; cat "$work/frames.$format"; } > "corpus/log_readers/seed-$format"
  index=$((index + 1))
done
bywire log convert "$work/frames.log" corpus/mf4_reader/seed-frames.mf4 > /dev/null
for compression in zstd snappy none; do
  bywire log convert "$work/frames.log" "corpus/parquet_reader/seed-$compression.parquet" \
    --compression "$compression" > /dev/null
done
bywire log convert "$work/frames.log" corpus/parquet_reader/seed-us.parquet --time-unit us > /dev/null
# database_formats: the first byte picks the format (2: ARXML); the example system.
mkdir -p corpus/database_formats
{ printf '\x02'; cat ../examples/data/powertrain.arxml; } > corpus/database_formats/seed-powertrain.arxml
echo "seeded: candump_log, log_readers (5 formats), mf4_reader, parquet_reader (4 files), database_formats (ARXML)"
