#!/usr/bin/env bash
# Mutation testing of the vehicle interface's safety logic (the supervisor, the ADS side and their wires):
# every mutant cargo-mutants makes of them must be caught by the vehicle tests.
# Needs `cargo install cargo-mutants`; about 10 minutes on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo mutants -p bywire-vehicle \
    -f crates/bywire-vehicle/src/supervisor.rs -f crates/bywire-vehicle/src/ads.rs \
    -f crates/bywire-vehicle/src/wire.rs \
    --timeout 120 -o target/mutants "$@" -- \
    --test fault_matrix --test ads_side --test redundant_buses \
    --test supervisor_details --test ads_details --test profile_wire --test messages --lib
