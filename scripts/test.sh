#!/usr/bin/env bash
# The whole test suite: the workspace's tests (VM and lonet tests included), then the Python
# package built from this checkout and its pytest suite (Spark in local mode), inside a private
# network namespace so Spark binds nothing but loopback.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo test --workspace --all-features
python3 -m pip install -q --disable-pip-version-check .
../shared/tools/lonet.sh env SPARK_LOCAL_IP=127.0.0.1 PYSPARK_PYTHON="$(command -v python3)" \
  python3 -m pytest -q python/tests
