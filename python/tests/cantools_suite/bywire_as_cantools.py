"""A pytest plugin that runs cantools' own database tests against bywire: after cantools is
imported (its internals, which some tests call directly, stay cantools'), the names a test
reaches through ``cantools.database`` are bywire.database's."""

from __future__ import annotations

import sys
import types

import cantools
import cantools.database
import cantools.database.can as real_can

import bywire.database as ours
import bywire.database.errors as our_errors


class _Can(types.ModuleType):
    """``cantools.database.can``: bywire's classes, cantools' formats and helpers."""

    def __getattr__(self, name: str) -> object:
        return getattr(real_can, name)


can = _Can("cantools.database.can")
for name in ("Database", "Message", "Signal", "Node", "Bus"):
    setattr(can, name, getattr(ours, name))

ours.can = can  # type: ignore[attr-defined]
ours.utils = cantools.database.utils  # type: ignore[attr-defined]
ours.conversion = cantools.database.conversion  # type: ignore[attr-defined]
sys.modules["cantools.database"] = ours
sys.modules["cantools.database.errors"] = our_errors
cantools.database = ours  # type: ignore[attr-defined]
