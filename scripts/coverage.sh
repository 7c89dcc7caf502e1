#!/usr/bin/env bash
# Line coverage of the vehicle interface's safety logic (the supervisor, the ADS side and their wires).
# Needs `cargo install cargo-tarpaulin` and `rustup component add llvm-tools-preview`: the
# LLVM engine counts lines by source regions (the ptrace engine misses match arms and struct
# fields that run).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo tarpaulin -p bywire-vehicle --engine llvm --skip-clean --target-dir target/tarpaulin --out Stdout \
    --include-files crates/bywire-vehicle/src/supervisor.rs crates/bywire-vehicle/src/ads.rs \
    crates/bywire-vehicle/src/wire.rs "$@"
