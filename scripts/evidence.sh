#!/usr/bin/env bash
# Evidence for the safety core, gathered into evidence/report.json and evidence/report.md:
#  1. the exhaustive state-space checks (each machine's states, transitions, bound,
#     requirements; a planted defect in each found),
#  2. back-to-back testing against the executable specification (BACK_TO_BACK_CASES
#     sequences, a million by default, in release),
#  3. line and branch coverage with its gate (scripts/coverage.sh),
#  4. mutation testing: the outcome of the last scripts/mutants.sh run (in target/mutants, or
#     MUTANTS_OUT; or MUTANTS_RUNS, mutants.out folders separated by colons, a later run's outcome
#     for a mutant replacing an earlier one's), survivors each with why it is equivalent
#     (requirements/equivalent-mutants.toml);
#     EVIDENCE_MUTANTS=sample runs a fifth of the mutants first (~1 h), =all every one (~6 h),
#  5. the core-only build (no std, no allocator),
#  6. the lint table.
# About 25 minutes on 2 cores without the mutation run.
set -euo pipefail
cd "$(dirname "$0")/.."
rm -rf target/evidence
back_to_back_cases=${BACK_TO_BACK_CASES:-1000000}
mutants_out=${MUTANTS_OUT:-target/mutants}
# Coverage first: its instrumented run records the state-space figures too, and the plain
# runs below then replace them with uninstrumented timings.
scripts/coverage.sh
cargo test -q -p bywire-vehicle --all-features --test state_space
cargo test -q -p bywire-vehicle --all-features --test fail_operational 2oo3
started=$(date +%s)
# The million only here, in release: coverage.sh runs the suite's 2,000.
BACK_TO_BACK_CASES=$back_to_back_cases cargo test -q --release -p bywire-vehicle --all-features \
    --test back_to_back
back_to_back_seconds=$(($(date +%s) - started))
cargo test -q -p bywire --test lints
core_only=failed
cargo build -q --manifest-path core-only/Cargo.toml --locked && core_only=built
case "${EVIDENCE_MUTANTS:-}" in
    sample) MUTANTS_OUT=$mutants_out scripts/mutants.sh --shard 0/5 --sharding round-robin || true ;;
    all) MUTANTS_OUT=$mutants_out scripts/mutants.sh || true ;;
esac
mkdir -p evidence
BACK_TO_BACK_CASES=$back_to_back_cases BACK_TO_BACK_SECONDS=$back_to_back_seconds CORE_ONLY=$core_only \
    MUTANTS=${MUTANTS_RUNS:-$mutants_out/mutants.out} \
    python3 scripts/evidence_report.py
