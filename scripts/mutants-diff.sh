#!/usr/bin/env bash
# Mutation testing of the safety core's changed lines only, as CI runs it: the mutants
# cargo-mutants makes of the lines changed since MUTANTS_BASE (default: ten commits back) in
# the files scripts/mutants.sh covers. Fails if one survives that is not listed as
# equivalent in requirements/equivalent-mutants.toml. At most MUTANTS_MAX (default 8) run:
# more are sampled evenly (and the output says so). Mutates the checkout in place and builds
# in its target directory (cargo-mutants puts every file back), so run it on a clean tree.
set -euo pipefail
cd "$(dirname "$0")/.."
base=${MUTANTS_BASE:-HEAD~10}
max=${MUTANTS_MAX:-8}
git rev-parse -q --verify "$base^{commit}" >/dev/null || base=$(git rev-list --max-parents=0 HEAD)
mkdir -p target
git diff "$base" -- crates/bywire-vehicle/src crates/bywire-secoc/src crates/bywire-core/src/e2e \
    >target/mutants-diff.patch
# Equivalent mutants, as exact-name patterns.
excluded=()
while IFS= read -r pattern; do
    excluded+=(--exclude-re "$pattern")
done < <(python3 -c 'import re, tomllib
for m in tomllib.load(open("requirements/equivalent-mutants.toml", "rb")).get("mutant", []):
    print("^" + re.escape(m["name"]) + "$")')
common=(--in-diff target/mutants-diff.patch "${excluded[@]}")
count=$(scripts/mutants.sh "${common[@]}" --list | grep -c . || true)
echo "mutants-diff: $count mutants on the lines changed since $base"
if [ "$count" -eq 0 ]; then
    exit 0
fi
shard=()
if [ "$count" -gt "$max" ]; then
    shards=$(((count + max - 1) / max))
    echo "mutants-diff: running one in $shards of them (shard 0/$shards, round-robin)"
    shard=(--shard "0/$shards" --sharding round-robin)
fi
scripts/mutants.sh "${common[@]}" "${shard[@]}" --in-place --baseline=skip
