#!/usr/bin/env bash
# Line and branch coverage of the safety core, with a gate: fails below 95 % of lines.
#   scripts/coverage.sh            measure, write target/coverage/summary.{json,md}, gate
#   COVERAGE_MIN=97 scripts/coverage.sh
# The scope is the code a vehicle runs: bywire-vehicle's control path and the profile that
# declares it, bywire-secoc, bywire-core's E2E checks and the tug's ECU. Its tools
# (acceptance checks, replay, fuzz) run from the command line and are tested there.
#
# Measured by rustc's own instrumentation (`-C instrument-coverage`) and LLVM's tools of the
# same version as rustc's LLVM (Debian's llvm-22: `apt-get install llvm-22`). Branch
# coverage is rustc's `-Z coverage-options=branch`, an unstable option: the stable toolchain
# is let use it for this build only (RUSTC_BOOTSTRAP=1). MC/DC is not measurable with this
# toolchain (rustc removed its MC/DC instrumentation). Unit-test modules at the end of a file
# are not counted.
set -euo pipefail
cd "$(dirname "$0")/.."
llvm_bin=${LLVM_BIN:-/usr/lib/llvm-22/bin}
out=target/coverage
rm -rf "$out/profraw"
mkdir -p "$out/profraw"
export RUSTC_BOOTSTRAP=1
export RUSTFLAGS="-C instrument-coverage -Z coverage-options=branch"
export LLVM_PROFILE_FILE="$PWD/$out/profraw/%p-%m.profraw"
export CARGO_TARGET_DIR="$PWD/$out/build"
packages=(-p bywire-vehicle -p bywire-secoc -p bywire-core -p bywire-tug -p bywire-sim)
cargo test -q "${packages[@]}" --all-features --no-fail-fast "$@"
"$llvm_bin/llvm-profdata" merge -sparse "$out"/profraw/*.profraw -o "$out/merged.profdata"
objects=()
while IFS= read -r binary; do
    objects+=(-object "$binary")
done < <(cargo test -q "${packages[@]}" --all-features --no-run --message-format=json 2>/dev/null |
    python3 -c 'import json,sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m.get("executable"):
        print(m["executable"])')
"$llvm_bin/llvm-cov" export -format=lcov -instr-profile "$out/merged.profdata" "${objects[@]}" \
    >"$out/coverage.lcov"
python3 scripts/coverage_summary.py "$out/coverage.lcov" "$out" "${COVERAGE_MIN:-95}"
