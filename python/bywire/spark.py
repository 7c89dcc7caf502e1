"""bywire in Spark (pyspark 4's Python data source API): logs of any format read on the
executors, raw or decoded, one partition per file.

::

    import bywire.spark
    bywire.spark.register(spark)
    signals = (spark.read.format("bywire")
               .option("dbc", "vehicle.dbc")
               .option("output", "signals")            # or "frames", or "wide" with "message"
               .load("logs/**/*.blf"))
    signals.write.partitionBy("vehicle", "date", "message").parquet("lake")

Options:

- ``path`` (what ``load`` is given): a file, a folder (every file below it) or a glob (``**``
  crosses folders). The files must be where every executor can read them (a shared file
  system, as for any local-path source).
- ``output``: ``frames`` (one row a frame), ``signals`` (long: one row a signal value,
  ``ts, vehicle, date, channel, message, signal, value``) or ``wide`` (one row a frame of the
  message named by ``message``, one column a signal; choices as ``NAME_choice``).
- ``dbc``: the DBC file (``signals`` and ``wide``).
- ``path_pattern``: where the vehicle and date are in a file's path, e.g.
  ``{vehicle}/{date}/*.blf``; without it, Hive-style segments ``vehicle=...`` and
  ``date=...`` are used. A row without a date from the path gets its frame's UTC day.
- ``batch_rows``: rows read at a time (65536).
- ``split_mb``: candump logs bigger than this (256 MB) are read in ranges of this size, one
  partition each (other formats: one partition a file).

:func:`decode` decodes a frames DataFrame with ``mapInArrow``.
"""

from __future__ import annotations

import glob
import os
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import pyarrow as pa
import pyarrow.compute as pc

import bywire

#: Long-format decoded signals.
SIGNALS_SCHEMA = (
    "ts timestamp, vehicle string, date string, channel string, message string, "
    "signal string, value double"
)
#: Raw frames, with where they came from.
FRAMES_SCHEMA = (
    "ts timestamp, vehicle string, date string, channel string, id bigint, extended boolean, "
    "remote boolean, error boolean, fd boolean, brs boolean, esi boolean, dir string, "
    "dlc smallint, data binary"
)

_TIMESTAMP = pa.timestamp("us", tz="UTC")


def register(spark) -> None:
    """Make ``spark.read.format("bywire")`` available in this session."""
    spark.dataSource.register(BywireDataSource)


def files_of(path: str) -> list[str]:
    """The files a ``path`` option names: itself, every file below a folder, or a glob's
    matches (sorted, so partitions are numbered the same each time)."""
    if os.path.isfile(path):
        return [path]
    if os.path.isdir(path):
        found = glob.glob(os.path.join(path, "**", "*"), recursive=True)
    else:
        found = glob.glob(path, recursive=True)
    return sorted(f for f in found if os.path.isfile(f))


def path_labels(path: str, pattern: str | None) -> tuple[str | None, str | None]:
    """The vehicle and date a file's path gives (see the module's ``path_pattern``)."""
    if pattern:
        regex = ""
        for part in re.split(r"(\{vehicle\}|\{date\}|\*\*|\*)", pattern):
            regex += {
                "{vehicle}": r"(?P<vehicle>[^/]+)",
                "{date}": r"(?P<date>[^/]+)",
                "**": r".*",
                "*": r"[^/]*",
            }.get(part, re.escape(part))
        match = re.search(regex + "$", path.replace(os.sep, "/"))
        if not match:
            return None, None
        groups = match.groupdict()
        return groups.get("vehicle"), groups.get("date")
    vehicle = re.search(r"(?:^|/)vehicle=([^/]+)", path)
    date = re.search(r"(?:^|/)date=([^/]+)", path)
    return (vehicle.group(1) if vehicle else None, date.group(1) if date else None)


def _days(ts: pa.Array) -> pa.Array:
    """Each timestamp's UTC day, ``YYYY-MM-DD``."""
    return pc.strftime(ts.cast(_TIMESTAMP), format="%Y-%m-%d")


def _labels(rows: int, ts: pa.Array, vehicle: str | None, date: str | None):
    vehicles = pa.array([vehicle] * rows, pa.string())
    dates = pa.array([date] * rows, pa.string()) if date is not None else _days(ts)
    return vehicles, dates


def frames_for_spark(batch: pa.RecordBatch, vehicle: str | None, date: str | None) -> pa.RecordBatch:
    """A frames batch in :data:`FRAMES_SCHEMA`'s types (Spark has no unsigned integers nor
    dictionary strings)."""
    ts = batch.column("ts").cast(_TIMESTAMP)
    vehicles, dates = _labels(batch.num_rows, ts, vehicle, date)
    plain = lambda name: batch.column(name).cast(pa.string())  # noqa: E731
    return pa.RecordBatch.from_arrays(
        [
            ts,
            vehicles,
            dates,
            plain("channel"),
            batch.column("id").cast(pa.int64()),
            *(batch.column(f) for f in ("extended", "remote", "error", "fd", "brs", "esi")),
            plain("dir"),
            batch.column("dlc").cast(pa.int16()),
            batch.column("data"),
        ],
        names=[
            "ts", "vehicle", "date", "channel", "id", "extended", "remote", "error", "fd",
            "brs", "esi", "dir", "dlc", "data",
        ],
    )


def signals_long(
    message: str, table: pa.RecordBatch | pa.Table, vehicle: str | None, date: str | None
) -> pa.RecordBatch | None:
    """One message's decoded table in :data:`SIGNALS_SCHEMA`'s long form (one row per signal
    value; absent multiplexed signals are no rows)."""
    ts = table.column("ts").cast(_TIMESTAMP)
    channel = table.column("channel").cast(pa.string())
    vehicles, dates = _labels(table.num_rows, ts, vehicle, date)
    parts = []
    for name in table.column_names:
        if name in ("ts", "channel") or name.endswith("_choice"):
            continue
        values = table.column(name)
        present = pc.is_valid(values)
        rows = len(values) - values.null_count
        parts.append(
            pa.table(
                {
                    "ts": pc.filter(ts, present),
                    "vehicle": pc.filter(vehicles, present),
                    "date": pc.filter(dates, present),
                    "channel": pc.filter(channel, present),
                    "message": pa.array([message] * rows, pa.string()),
                    "signal": pa.array([name] * rows, pa.string()),
                    "value": pc.filter(values, present).cast(pa.float64()),
                }
            )
        )
    if not parts:
        return None
    combined = pa.concat_tables(parts).combine_chunks()
    batches = combined.to_batches()
    return batches[0] if batches else None


def wide_schema(db: bywire.Database, message: str) -> str:
    """The ``wide`` output's schema for ``message``: every signal as a double, choices as
    strings."""
    info = db.message_info(message)
    columns = ["ts timestamp", "vehicle string", "date string", "channel string"]
    for signal in info["signals"]:
        columns.append(f"`{signal['name']}` double")
        if signal["choices"]:
            columns.append(f"`{signal['name']}_choice` string")
    return ", ".join(columns)


def signals_wide(
    table: pa.RecordBatch | pa.Table, schema_names: list[str], vehicle: str | None, date: str | None
) -> pa.RecordBatch:
    """One message's decoded table in the ``wide`` output's types."""
    ts = table.column("ts").cast(_TIMESTAMP)
    vehicles, dates = _labels(table.num_rows, ts, vehicle, date)
    columns = [ts, vehicles, dates, table.column("channel").cast(pa.string())]
    for name in schema_names[4:]:
        column = table.column(name)
        columns.append(column.cast(pa.string() if name.endswith("_choice") else pa.float64()))
    if isinstance(table, pa.Table):
        columns = [c.combine_chunks() if isinstance(c, pa.ChunkedArray) else c for c in columns]
    return pa.RecordBatch.from_arrays(columns, names=schema_names)


@dataclass
class _Settings:
    output: str
    dbc: str | None
    message: str | None
    pattern: str | None
    batch_rows: int
    split_bytes: int

    @classmethod
    def of(cls, options) -> _Settings:
        output = options.get("output", "frames").lower()
        if output not in ("frames", "signals", "wide"):
            raise ValueError(f"option output={output}: frames, signals or wide")
        dbc = options.get("dbc")
        if output != "frames" and not dbc:
            raise ValueError(f"option output={output} needs option dbc (the DBC file)")
        message = options.get("message")
        if output == "wide" and not message:
            raise ValueError("option output=wide needs option message (the message's name)")
        batch_rows = int(options.get("batch_rows", bywire.BATCH_ROWS))
        split_mb = float(options.get("split_mb", 256))
        if not split_mb > 0:
            raise ValueError(f"option split_mb={split_mb}: more than 0")
        split_bytes = max(1, int(split_mb * 1e6))
        return cls(output, dbc, message, options.get("path_pattern"), batch_rows, split_bytes)


try:
    from pyspark.sql.datasource import DataSource, DataSourceReader, InputPartition
except ImportError:  # pragma: no cover - pyspark is optional
    DataSource = DataSourceReader = InputPartition = object  # type: ignore[misc,assignment]


class FilePartition(InputPartition):  # type: ignore[misc]
    """One log file, or the lines starting in a byte range of a big candump log."""

    def __init__(self, path: str, byte_range: tuple[int, int] | None = None) -> None:
        self.path = path
        self.byte_range = byte_range


def split(path: str, split_bytes: int) -> list[FilePartition]:
    """A file's partitions: candump logs bigger than ``split_bytes`` in ranges of that size
    (each line read by exactly one), any other file whole."""
    size = os.path.getsize(path)
    if size <= split_bytes or bywire._native.LogBatches(path, 1).format != "candump":
        return [FilePartition(path)]
    return [
        FilePartition(path, (start, min(start + split_bytes, size)))
        for start in range(0, size, split_bytes)
    ]


class BywireDataSource(DataSource):  # type: ignore[misc]
    """``spark.read.format("bywire")``: see the module's documentation for the options."""

    @classmethod
    def name(cls) -> str:
        return "bywire"

    def schema(self) -> str:
        settings = _Settings.of(self.options)
        if settings.output == "frames":
            return FRAMES_SCHEMA
        if settings.output == "signals":
            return SIGNALS_SCHEMA
        return wide_schema(bywire.Database.load(settings.dbc), settings.message)

    def reader(self, schema) -> BywireReader:
        return BywireReader(dict(self.options), schema.fieldNames())


class BywireReader(DataSourceReader):  # type: ignore[misc]
    """Reads one file per partition on the executors."""

    def __init__(self, options: dict, names: list[str]) -> None:
        self.options = options
        self.names = names
        self.settings = _Settings.of(options)

    def partitions(self) -> list[FilePartition]:
        path = self.options.get("path")
        if not path:
            raise ValueError('no path: spark.read.format("bywire").load(PATH)')
        files = files_of(path)
        if not files:
            raise FileNotFoundError(f"{path}: no files")
        return [part for f in files for part in split(f, self.settings.split_bytes)]

    def read(self, partition: FilePartition) -> Iterator[pa.RecordBatch]:
        settings = self.settings
        vehicle, date = path_labels(partition.path, settings.pattern)
        frames = bywire.read_log(partition.path, settings.batch_rows, partition.byte_range)
        if settings.output == "frames":
            for batch in frames:
                yield frames_for_spark(batch, vehicle, date)
            return
        db = bywire.Database.load(settings.dbc)
        yield from _decoded(db, frames, settings, self.names, vehicle, date)


def _decoded(db, frames, settings: _Settings, names, vehicle, date) -> Iterator[pa.RecordBatch]:
    for name, table in db.iter_decoded(frames):
        if settings.output == "signals":
            long = signals_long(name, table, vehicle, date)
            if long is not None:
                yield long
        elif name == settings.message:
            yield signals_wide(table, names, vehicle, date)


def decode(
    dbc: str, output: str = "signals", message: str | None = None
) -> Callable[[Iterator[pa.RecordBatch]], Iterator[pa.RecordBatch]]:
    """A function for ``frames.mapInArrow(bywire.spark.decode(dbc), bywire.spark.SIGNALS_SCHEMA)``
    that decodes a frames DataFrame (the ``frames`` output) into long-form signals, or
    ``output="wide"`` with ``message`` into that message's wide rows (schema:
    :func:`wide_schema`)."""
    settings = _Settings.of({"output": output, "dbc": dbc, "message": message or ""})

    def run(batches: Iterator[pa.RecordBatch]) -> Iterator[pa.RecordBatch]:
        db = bywire.Database.load(dbc)
        names = wide_schema(db, message).split(", ") if output == "wide" else []
        names = [n.split(" ")[0].strip("`") for n in names]
        for batch in batches:
            # One (vehicle, date) at a time: decoded rows carry only ts and channel.
            keys = set(zip(batch.column("vehicle").to_pylist(), batch.column("date").to_pylist()))
            for vehicle, date in sorted(keys, key=lambda k: (str(k[0]), str(k[1]))):
                mask = pc.and_(
                    _equal_or_null(batch.column("vehicle"), vehicle),
                    _equal_or_null(batch.column("date"), date),
                )
                part = batch.filter(mask)
                yield from _decoded(db, [part], settings, names, vehicle, date)

    return run


def _equal_or_null(column: pa.Array, value) -> pa.Array:
    if value is None:
        return pc.is_null(column)
    return pc.fill_null(pc.equal(column, value), False)
