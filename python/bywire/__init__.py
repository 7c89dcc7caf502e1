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
from collections.abc import Iterable, Iterator, Mapping
from typing import Any

import pyarrow as pa

from . import _native
from ._native import DecodeError, EncodeError, Error, LogError, ParseError, ScenarioError
from ._values import NamedSignalValue

__all__ = [
    "Database",
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


class Database:
    r"""A DBC database. The common calls of cantools' ``Database`` with the same arguments,
    values and errors (``decode_message``, ``encode_message``, ``get_message_by_name``...),
    and Arrow decoding (``decode_arrow``, ``decode_log``).

    Where two messages share a frame identifier or a name, the lookups here find the last, as
    cantools does (bywire's command line decodes with the first and says so when loading).

    >>> db = Database.load_string('''
    ... BO_ 256 Speed: 2 ECU
    ...  SG_ Kph : 0|16@1+ (0.01,0) [0|655.35] "km/h" Vector__XXX
    ... ''')
    >>> db.encode_message("Speed", {"Kph": 12.5})
    b'\xe2\x04'
    >>> db.decode_message(256, b'\xe2\x04')
    {'Kph': 12.5}
    """

    def __init__(self, native: _native.Database) -> None:
        self._db = native

    @classmethod
    def load(cls, path: str | os.PathLike[str], strict: bool = False) -> Database:
        """Load a DBC file. Lenient unless ``strict``: what cantools rejects but a reasonable
        engineer accepts loads, each problem listed in :attr:`diagnostics`. A file that
        cannot be loaded raises :class:`ParseError` naming the file, line and column."""
        return cls(_native.Database.load(os.fspath(path), strict))

    @classmethod
    def load_string(cls, text: str, strict: bool = False) -> Database:
        """Load DBC text."""
        return cls(_native.Database.load_string(text, strict))

    @property
    def diagnostics(self) -> list[str]:
        """The problems found while loading, ``FILE:LINE:COLUMN: what``."""
        return self._db.diagnostics

    @property
    def message_names(self) -> list[str]:
        """The messages' names, in the file's order."""
        return self._db.message_names

    def message_info(self, frame_id_or_name: int | str) -> dict[str, Any]:
        """A message's description: name, frame_id, is_extended_frame, length, cycle_time,
        senders and its signals."""
        return self._db.message_info(frame_id_or_name)

    def decode_message(
        self,
        frame_id_or_name: int | str,
        data: bytes,
        decode_choices: bool = True,
        scaling: bool = True,
        decode_containers: bool = False,
        allow_truncated: bool = False,
        allow_excess: bool = True,
    ) -> dict[str, int | float | NamedSignalValue]:
        """Decode ``data`` as cantools does: ``{signal: value}``; :class:`DecodeError` for
        data of the wrong size or an unknown multiplexer value, ``KeyError`` for an unknown
        message."""
        return self._db.decode_message(
            frame_id_or_name,
            data,
            decode_choices,
            scaling,
            decode_containers,
            allow_truncated,
            allow_excess,
        )

    def encode_message(
        self,
        frame_id_or_name: int | str,
        data: Mapping[str, int | float | str | NamedSignalValue],
        scaling: bool = True,
        padding: bool = False,
        strict: bool = True,
    ) -> bytes:
        """Encode signal values as cantools does (``strict``: every needed signal, no other,
        each within its range; choices by name)."""
        return self._db.encode_message(frame_id_or_name, dict(data), scaling, padding, strict)

    def decode_arrow(self, frames: pa.RecordBatch | pa.Table) -> DecodedLog:
        """Decode a batch or table of frames (:func:`read_log`'s layout; ``id`` may be any
        integer type, ``channel`` plain strings, flags left out are false) into one table per
        message: ``ts``, ``channel``, one typed column per signal (int64 where the signal's
        values are whole numbers, else float64; null where a multiplexed signal is absent) and
        ``NAME_choice`` beside each signal with value descriptions."""
        batches = frames.to_batches() if isinstance(frames, pa.Table) else [frames]
        return self._decode_all(batches)

    def decode_log(self, path: str | os.PathLike[str], batch_rows: int = BATCH_ROWS) -> DecodedLog:
        """Decode every frame of the log at ``path``: one table per message, as
        :meth:`decode_arrow` gives them."""
        return self._decode_all(read_log(path, batch_rows))

    def iter_decoded(
        self, frames: Iterable[pa.RecordBatch]
    ) -> Iterator[tuple[str, pa.RecordBatch]]:
        """Decode a stream of frame batches: ``(message, batch)`` pairs as they come (memory
        bounded by one input batch)."""
        for batch in frames:
            decoded, _, _ = self._db.decode_arrow(_native_frames(batch))
            yield from decoded

    def _decode_all(self, frames: Iterable[pa.RecordBatch]) -> DecodedLog:
        out = DecodedLog()
        out.unknown, out.undecodable = 0, {}
        parts: dict[str, list[pa.RecordBatch]] = {}
        for batch in frames:
            decoded, unknown, undecodable = self._db.decode_arrow(_native_frames(batch))
            out.unknown += unknown
            for name, (count, why) in undecodable.items():
                before = out.undecodable.get(name, (0, why))
                out.undecodable[name] = (before[0] + count, before[1])
            for name, part in decoded:
                parts.setdefault(name, []).append(part)
        for name, batches in parts.items():
            out[name] = pa.Table.from_batches(batches)
        return out

    def __repr__(self) -> str:
        return repr(self._db)


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
