"""The simulated tug from Python: a scenario run as fast as possible, its bus logs (candump)
and report written into a folder."""

from __future__ import annotations

import json
import os
import tempfile
import time
from dataclasses import dataclass, field
from typing import Any

from . import _native

#: The scenarios built in (a TOML file's path works too).
SCENARIOS = ("apron-loop", "fault-tour")


@dataclass
class Run:
    """A finished run: its report (the CLI's metrics.json: sim_seconds, completed, events,
    tracking error, steering steps, bus loads...), the folder, and the files written there
    (bus1.log, bus2.log, bus3.log, bus1b.log, metrics.json)."""

    report: dict[str, Any]
    out: str
    files: list[str] = field(default_factory=list)

    @property
    def bus_logs(self) -> dict[str, str]:
        """Each bus's log file by bus name."""
        return {
            os.path.splitext(os.path.basename(f))[0]: f for f in self.files if f.endswith(".log")
        }


def run(
    scenario: str = "apron-loop",
    seed: int = 1,
    out: str | os.PathLike[str] | None = None,
    payload: float | None = None,
    secoc: bool = False,
    max_seconds: float = 300.0,
    start_time: float | None = None,
) -> Run:
    """Run ``scenario`` (built in, or a TOML file) with ``seed`` as fast as possible, as
    ``bywire sim --fast`` does (the same seed and ``start_time`` give the same logs, byte for
    byte). ``payload`` in kg replaces the scenario's; ``start_time`` is the logs' time at the
    start, Unix seconds (default: now); ``out`` defaults to a new temporary folder."""
    folder = os.fspath(out) if out is not None else tempfile.mkdtemp(prefix="bywire-sim-")
    if start_time is None:
        start_time = time.time()
    report, files = _native.run_sim(scenario, seed, folder, payload, secoc, max_seconds, start_time)
    return Run(report=json.loads(report), out=folder, files=list(files))
