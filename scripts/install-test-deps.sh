#!/usr/bin/env bash
# Installs the independent implementations the tests compare against (from the package
# registries) and prepares the SocketCAN VM. Safe to run again.
set -euo pipefail
cd "$(dirname "$0")/.."
export DEBIAN_FRONTEND=noninteractive
SUDO=""
[ "$(id -u)" = 0 ] || SUDO=sudo
# sigrok-cli: CAN bit-level decoder oracle; tmux: drives the terminal views end to end;
# can-utils: the SocketCAN peers the VM tests copy in (installed here, once, because test
# binaries start several VMs at a time and apt cannot run twice at once); tshark: Wireshark's
# reader, the peer of the pcapng logs; llvm-22: LLVM's coverage tools of rustc's LLVM version
# (scripts/coverage.sh); xz-utils: canmatrix's test files ship packed (crates/bywire-dbc/tests/canmatrix).
if ! command -v sigrok-cli >/dev/null || ! command -v tmux >/dev/null || ! command -v candump >/dev/null \
  || ! command -v tshark >/dev/null || ! [ -x /usr/lib/llvm-22/bin/llvm-cov ] || ! command -v xz >/dev/null; then
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends sigrok-cli tmux can-utils tshark llvm-22 xz-utils >/dev/null
fi
# The udp: tests send bursts of 500 datagrams; the receive buffer they need is capped by
# net.core.rmem_max (global, not settable inside the test's network namespace).
if [ "$(cat /proc/sys/net/core/rmem_max)" -lt 4194304 ]; then
  $SUDO sysctl -qw net.core.rmem_max=4194304
fi
# python-can + msgpack + pyserial: the udp_multicast, socketcand and slcan peer; canopen: the
# CANopen peer (master, LocalNode slave, CiA 402 node).
python3 -m pip install -q --disable-pip-version-check python-can==4.6.1 msgpack pyserial canopen==2.4.1
# mcap + mcap-ros2-support: the MCAP peer (ROS 2 can_msgs/msg/Frame in CDR).
python3 -m pip install -q --disable-pip-version-check mcap==1.6.0 mcap-ros2-support==0.6.0 jsonschema==4.26.0
# rosbag2 folders (metadata.yaml + MCAP) as ROS 2's own tools read and write them.
python3 -m pip install -q --disable-pip-version-check rosbags==0.11.9
# asammdf: the MF4 peer (python-can's MF4 reader and writer are asammdf's; its bus logging
# extraction decodes our files with a DBC).
python3 -m pip install -q --disable-pip-version-check asammdf==8.6.10
# pyarrow, polars, DuckDB and pandas: the Parquet peers (and the README's walk-through into pandas).
python3 -m pip install -q --disable-pip-version-check pyarrow==26.0.1 polars==2.1.0 duckdb==2.0.1 "pandas>=2.2,<3"
# cyclonedds: the DDS of ROS 2's default middleware, the peer of `bywire ros2` (binary wheel with
# the C library; its types declared under ROS 2's names).
python3 -m pip install -q --disable-pip-version-check cyclonedds==11.0.1
# can-isotp + udsoncan: the UDS tester of `bywire uds serve` (pure Python, on python-can).
python3 -m pip install -q --disable-pip-version-check can-isotp==2.0.7 udsoncan==1.26.1
# crccheck: CRC-15/CAN oracle; autosar-e2e: AUTOSAR E2E profile oracle; cantools: DBC decode.
python3 -m pip install -q --disable-pip-version-check crccheck==1.3.1 autosar-e2e==1.0.0 cantools==45.1.0
# cryptography: the CMAC-AES-128 under cantools' SecOC framing, the peer of bywire-secoc.
python3 -m pip install -q --disable-pip-version-check cryptography==48.0.0
# The Python package's tests: pytest; pyspark (local mode) runs on Java 17; pandas below 3, which
# pyspark 4.3 does not fully support. `pip install .` fetches maturin itself.
python3 -m pip install -q --disable-pip-version-check pytest==9.2.0 pyspark==4.3.0
if ! command -v java >/dev/null; then
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends default-jre-headless >/dev/null
fi
# Real Linux SocketCAN (and SJA1000 controllers) in a VM: this machine's kernel has no CAN.
../shared/tools/canvm.sh prepare
# python-can and cantools for Debian's Python inside the VM (tests include the folder there): an
# ADS written with them drives `bywire vehicle` over the kernel's vcan.
python3 -m pip install -q --disable-pip-version-check --upgrade --target target/vm-python python-can==4.6.1 cantools==45.1.0
# cantools' own test databases (its source release's tests/files: KCD, SYM, ARXML, CDD), read
# by our readers beside cantools'; canmatrix reads our KCD and SYM output.
python3 -m pip install -q --disable-pip-version-check canmatrix==1.3.3
if [ ! -d target/cantools-files ]; then
  sdist="$(mktemp -d)"
  python3 -m pip download -q --disable-pip-version-check --no-deps --no-binary :all: cantools==45.1.0 -d "$sdist"
  mkdir -p target/cantools-files
  tar xzf "$sdist"/cantools-45.1.0.tar.gz -C target/cantools-files --strip-components=3 cantools-45.1.0/tests/files/
  rm -rf "$sdist"
fi
# cantools' own database tests, run against bywire.database (python/tests/test_cantools_suite.py):
# its test_database.py beside its files, and the package that test imports.
python3 -m pip install -q --disable-pip-version-check parameterized==0.9.0
if [ ! -f target/cantools-tests/tests/test_database.py ]; then
  sdist="$(mktemp -d)"
  python3 -m pip download -q --disable-pip-version-check --no-deps --no-binary :all: cantools==45.1.0 -d "$sdist"
  mkdir -p target/cantools-tests/tests
  tar xzf "$sdist"/cantools-45.1.0.tar.gz -C target/cantools-tests/tests --strip-components=2 \
    cantools-45.1.0/tests/test_database.py cantools-45.1.0/tests/__init__.py
  ln -sfn ../../cantools-files target/cantools-tests/tests/files
  rm -rf "$sdist"
fi
# python-can's own test logs (its source release's test/data), read by our readers beside its.
if [ ! -d target/python-can-data ]; then
  sdist="$(mktemp -d)"
  python3 -m pip download -q --disable-pip-version-check --no-deps --no-binary :all: python-can==4.6.1 -d "$sdist"
  mkdir -p target/python-can-data
  tar xzf "$sdist"/python_can-4.6.1.tar.gz -C target/python-can-data --strip-components=3 python_can-4.6.1/test/data/
  rm -rf "$sdist"
fi
# The web page's tests: Debian's Chromium, driven by Playwright (which uses it, not a browser
# of its own); Foxglove's WebSocket client in Node (`@foxglove/ws-protocol`, with `ws`) and its
# message schemas (`@foxglove/schemas`), which the simulated tug's pose is validated against.
if ! command -v chromium >/dev/null || ! command -v node >/dev/null; then
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends chromium nodejs npm >/dev/null
fi
python3 -m pip install -q --disable-pip-version-check playwright==1.49.0
if [ ! -d target/node/node_modules/@foxglove/schemas ]; then
  mkdir -p target/node
  npm install --silent --no-audit --no-fund --prefix target/node @foxglove/ws-protocol@0.8.0 @foxglove/schemas@2.1.0 ws@8.18.3 >/dev/null
fi
