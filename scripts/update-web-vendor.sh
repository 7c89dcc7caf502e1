#!/usr/bin/env bash
# The page's vendored libraries (crates/bywire-web/assets/vendor/), fetched from npm unchanged.
set -euo pipefail
cd "$(dirname "$0")/.."
vendor=crates/bywire-web/assets/vendor
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
(cd "$work" && npm pack --silent uplot@1.6.32 > /dev/null && tar xzf uplot-1.6.32.tgz)
cp "$work/package/dist/uPlot.iife.min.js" "$work/package/dist/uPlot.min.css" "$vendor/"
cp "$work/package/LICENSE" "$vendor/LICENSE.uPlot"
