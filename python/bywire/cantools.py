"""cantools' top level over bywire: a script written for cantools runs with one line changed,
``import bywire.cantools as cantools``, and every ``cantools.database.…`` (or ``cantools.db.…``)
reaches :mod:`bywire.database`. Only the database part: cantools' command line, its plotter and
its C code generator are not mirrored (bywire's command line does their work)."""

from __future__ import annotations

from . import database
from . import database as db
from .database import Error as Error

__all__ = ["database", "db", "Error"]
