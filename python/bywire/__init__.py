"""bywire from Python: DBC decoding and encoding as cantools does it, CAN logs of every
format (candump, ASC, BLF, TRC, pcapng, MF4, MCAP, Parquet) as Arrow record batches, whole
logs decoded into one Arrow table per message, and the simulated tug (:mod:`bywire.sim`).
Spark reads logs through :mod:`bywire.spark`.

Decode a log into pandas::

    import bywire
    db = bywire.Database.load("vehicle.dbc")
    tables = db.decode_log("drive.blf")
    df = tables["VehicleToAds_State"].to_pandas()
"""

from __future__ import annotations

import os
from importlib import metadata as _metadata
from collections.abc import Iterable, Iterator, Mapping
from typing import Any

import pyarrow as pa

from . import _native
from ._native import DecodeError, EncodeError, Error, LogError, ParseError, ScenarioError
from ._values import NamedSignalValue

# The native exceptions say where they live, so that they pickle (multiprocessing, Spark).
for _error in (DecodeError, EncodeError, Error, LogError, ParseError, ScenarioError):
    _error.__module__ = "bywire._native"

__all__ = [
    "Database",
    "__version__",
    "database",
    "sim",
    "spark",
    "DecodeError",
    "DecodedLog",
    "EncodeError",
    "Error",
    "LogError",
    "NamedSignalValue",
    "ParseError",
    "ScenarioError",
    "frames_schema",
    "read_log",
]

#: Rows of a batch from :func:`read_log` unless asked otherwise.
BATCH_ROWS = 65_536


def frames_schema() -> pa.Schema:
    """The schema of :func:`read_log`'s batches: ``ts`` (timestamp ns, UTC), ``channel``,
    ``id`` (uint32), ``extended``, ``remote``, ``error``, ``fd``, ``brs``, ``esi`` (bool),
    ``dir`` (``rx``/``tx``/null), ``dlc`` (uint8), ``data`` (binary)."""
    return _native.LogBatches.schema()


def read_log(
    path: str | os.PathLike[str],
    batch_rows: int = BATCH_ROWS,
    byte_range: tuple[int, int] | None = None,
) -> pa.RecordBatchReader:
    """The frames of the log at ``path`` as a stream of Arrow record batches (the format is
    sniffed from the content). A log that turns out bad part way raises :class:`LogError`
    naming the file and the line or byte offset, after the batches read before it.

    ``byte_range=(start, end)`` reads only the lines that start in those bytes of a candump
    log: the ranges of a split read every frame exactly once (how Spark splits big logs)."""
    batches = _native.LogBatches(os.fspath(path), batch_rows, byte_range)
    return pa.RecordBatchReader.from_batches(frames_schema(), batches)


class DecodedLog(dict):
    """Decoded tables by message name, with what could not be decoded: ``unknown`` (frames
    of no message in the DBC) and ``undecodable`` (``{message: (count, why)}``)."""

    unknown: int
    undecodable: dict[str, tuple[int, str]]


def _decode_all_batches(native: _native.Database, frames: pa.RecordBatch | pa.Table) -> DecodedLog:
    batches = frames.to_batches() if isinstance(frames, pa.Table) else [frames]
    return _decode_all(native, batches)


def _decode_log(native: _native.Database, path: str | os.PathLike[str], batch_rows: int) -> DecodedLog:
    return _decode_all(native, read_log(path, batch_rows))


def _iter_decoded(native: _native.Database, frames: Iterable[pa.RecordBatch]) -> Iterator[tuple[str, pa.RecordBatch]]:
    for batch in frames:
        decoded, _, _ = native.decode_arrow(_native_frames(batch))
        yield from decoded


def _decode_all(native: _native.Database, frames: Iterable[pa.RecordBatch]) -> DecodedLog:
    out = DecodedLog()
    out.unknown, out.undecodable = 0, {}
    parts: dict[str, list[pa.RecordBatch]] = {}
    for batch in frames:
        decoded, unknown, undecodable = native.decode_arrow(_native_frames(batch))
        out.unknown += unknown
        for name, (count, why) in undecodable.items():
            before = out.undecodable.get(name, (0, why))
            out.undecodable[name] = (before[0] + count, before[1])
        for name, part in decoded:
            parts.setdefault(name, []).append(part)
    for name, batches in parts.items():
        out[name] = pa.Table.from_batches(batches)
    return out


def _native_frames(batch: pa.RecordBatch) -> pa.RecordBatch:
    """A frames batch with the column types the decoder reads (Spark and pandas widen
    ``id`` and ``dlc`` to signed integers)."""
    schema = batch.schema
    columns, fields = [], []
    for field, column in zip(schema, batch.columns):
        target = {"id": pa.uint32(), "dlc": pa.uint8()}.get(field.name)
        if target is not None and field.type != target:
            column = column.cast(target)
            field = pa.field(field.name, target, field.nullable)
        columns.append(column)
        fields.append(field)
    return pa.RecordBatch.from_arrays(columns, schema=pa.schema(fields))


# The cantools-shaped database is the package's Database; sim and spark (whose pyspark parts
# load only when used) come with `import bywire`.
from . import database, sim, spark  # noqa: E402
from .database import Database  # noqa: E402

try:
    __version__ = _metadata.version("bywire")
except _metadata.PackageNotFoundError:  # run from a source tree without installing
    __version__ = "0.0.0"
