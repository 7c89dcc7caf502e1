#!/usr/bin/env bash
# Mutation testing of the safety core: the vehicle interface's control path, SecOC, the E2E
# checks. Every mutant cargo-mutants makes of them should be caught by their crates' tests.
#   scripts/mutants.sh                    every mutant (about 1,330; ~6 h on 2 cores)
#   scripts/mutants.sh --shard 0/5 --sharding round-robin   a fifth, spread over every file
#   scripts/mutants.sh --in-diff FILE     only the lines a diff touches (what CI runs)
# Needs `cargo install cargo-mutants`. Results in target/mutants/mutants.out (caught.txt,
# missed.txt, timeout.txt, unviable.txt); scripts/evidence.sh reads them.
set -euo pipefail
cd "$(dirname "$0")/.."
files=()
for f in supervisor ads wire redundancy arbitration backup degradation command secured autoware \
    profile_wire mechanism; do
    files+=(-f "crates/bywire-vehicle/src/$f.rs")
done
files+=(-f crates/bywire-secoc/src/lib.rs -f 'crates/bywire-core/src/e2e/*.rs')
cargo mutants -p bywire-vehicle -p bywire-secoc -p bywire-core --all-features "${files[@]}" \
    --timeout 180 -o "${MUTANTS_OUT:-target/mutants}" "$@"
