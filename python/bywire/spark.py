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

:func:`decode` decodes a frames DataFrame with ``mapInArrow``. :func:`write_lake` writes the
partitioned data lake the example above writes, with bywire writing the Parquet files on the
executors (the rows do not pass through Spark: several times faster), committed as Spark
commits a job::

    bywire.spark.write_lake(spark, "logs/**/*.blf", "vehicle.dbc", "lake", mode="overwrite")
"""

from __future__ import annotations

import glob
import os
import re
import shutil
import uuid
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
    value, in the frames' order; absent multiplexed signals are no rows)."""
    batch = _one_batch(table)
    if batch is None:
        return None
    long = bywire._native.signals_long(batch, message, vehicle, date)
    return long if long.num_rows else None


def _one_batch(table: pa.RecordBatch | pa.Table) -> pa.RecordBatch | None:
    if isinstance(table, pa.RecordBatch):
        return table
    batches = table.combine_chunks().to_batches()
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


# The data lake written by bywire on the executors ----------------------------------------------

@dataclass
class LakeSummary:
    """What :func:`write_lake` wrote: the files (relative to the lake) and their rows."""

    files: list[str]
    rows: int


def partition_folder(column: str, value: str | None) -> str:
    """``column=value`` as Spark names a partition's folder (null and escaped characters
    included)."""
    return bywire._native.partition_folder(column, value)


def write_lake(
    spark,
    path: str,
    dbc: str,
    lake: str,
    *,
    mode: str = "errorifexists",
    path_pattern: str | None = None,
    compression: str = "snappy",
    split_mb: float = 256.0,
    batch_rows: int = bywire.BATCH_ROWS,
    open_files: int = 256,
) -> LakeSummary:
    """Decode the logs ``path`` names (as the data source's ``path``) into the data lake
    ``lake``: Parquet partitioned by ``vehicle``, ``date`` and ``message``, one row a signal
    value (``ts, channel, signal, value``), the lake
    ``signals.write.partitionBy("vehicle", "date", "message").parquet(lake)`` gives and
    ``spark.read.parquet(lake)`` reads — written by bywire on the executors, without the rows
    passing through Spark. Files (and the ranges of big candump logs) are grouped into tasks
    as Spark's file sources group them (:func:`pack`).

    Committed as Spark commits a job: each task writes under ``lake/_temporary/JOB`` (a file
    under a hidden name until it is whole), and only when every task has succeeded are the
    files moved into place and ``_SUCCESS`` written; a failed job leaves the lake as it was.
    ``mode``: ``errorifexists`` (a lake with files is refused before any work), ``overwrite``
    (the old lake's files are removed once the new ones are ready), ``append`` or
    ``ignore``. ``compression``: ``snappy`` (Spark's), ``zstd``, ``gzip`` or ``none``.
    ``open_files``: files a task holds a descriptor of at once (a DBC of many messages over
    many days would otherwise hold one per message and day); past it the least recently
    written file is closed, and opened again to append. A task writes one file a folder.
    The logs and the lake must be where every executor can reach them (a shared file
    system)."""
    mode = mode.lower()
    if mode not in ("errorifexists", "error", "overwrite", "append", "ignore"):
        raise ValueError(f"mode={mode}: errorifexists, overwrite, append or ignore")
    if compression.lower() not in ("snappy", "zstd", "gzip", "none"):
        raise ValueError(f"compression={compression}: snappy, zstd, gzip or none")
    if not 1 <= open_files <= 4096:
        raise ValueError(f"open_files={open_files}: 1 to 4096")
    settings = _Settings.of({"output": "signals", "dbc": dbc, "split_mb": split_mb, "batch_rows": batch_rows})
    bywire.Database.load(dbc)  # a DBC that does not load is named here, not on an executor
    # Executors may not share the driver's working directory.
    dbc, lake = os.path.abspath(dbc), os.path.abspath(lake)
    files = [os.path.abspath(f) for f in files_of(path)]
    if not files:
        raise FileNotFoundError(f"{path}: no files")
    existing = [e for e in os.listdir(lake) if e != "_temporary"] if os.path.isdir(lake) else []
    if existing and mode in ("errorifexists", "error"):
        raise FileExistsError(f"{lake}: the lake exists (mode overwrite, append or ignore)")
    if existing and mode == "ignore":
        return LakeSummary([], 0)
    parts = [(p.path, p.byte_range) for f in files for p in split(f, settings.split_bytes)]
    tasks = pack(parts, *_packing(spark, len(parts)))
    job = uuid.uuid4().hex
    staging = os.path.join(lake, "_temporary", job)
    os.makedirs(staging)
    write = _lake_task(parts, tasks, dbc, staging, job, path_pattern, compression.lower(), batch_rows, open_files)
    try:
        written = _run_tasks(spark, len(tasks), write)
        if mode == "overwrite":
            for entry in existing:
                target = os.path.join(lake, entry)
                if os.path.isdir(target):
                    shutil.rmtree(target)
                else:
                    os.remove(target)
        _commit(staging, lake, {file for file, _ in written})
        with open(os.path.join(lake, "_SUCCESS"), "w"):
            pass
    finally:
        shutil.rmtree(staging, ignore_errors=True)
        try:
            os.rmdir(os.path.join(lake, "_temporary"))
        except OSError:
            pass  # another job's staging is there
    return LakeSummary(sorted(file for file, _ in written), sum(rows for _, rows in written))


def _run_tasks(spark, count: int, write: Callable[[int], list[tuple[str, int]]]) -> list[tuple[str, int]]:
    """``write`` run for each task index on the executors, one Spark task each: what they
    return, gathered. Through the RDD API where there is a SparkContext (a job of it starts
    about 60 ms sooner than a DataFrame's, measured), through ``mapInArrow`` on Spark
    Connect."""
    try:
        context = spark.sparkContext
    except Exception:  # Spark Connect has no SparkContext
        context = None
    if context is not None:
        return context.parallelize(range(count), count).flatMap(write).collect()

    def run(batches: Iterator[pa.RecordBatch]) -> Iterator[pa.RecordBatch]:
        for batch in batches:
            for task in batch.column(0).to_pylist():
                files = write(task)
                yield pa.RecordBatch.from_pydict(
                    {"file": [f for f, _ in files], "rows": [n for _, n in files]},
                    schema=pa.schema([("file", pa.string()), ("rows", pa.int64())]),
                )

    rows = spark.range(count, numPartitions=count).mapInArrow(run, "file string, rows long").collect()
    return [(row.file, row.rows) for row in rows]


def _commit(staging: str, lake: str, written: set[str]) -> None:
    """Move the job's files (``written``, relative paths) from ``staging`` into ``lake``. What
    else is in ``staging`` (an attempt killed before it could clean up) is left there. A
    folder the lake does not have yet moves in whole, with one rename, not file by file."""
    for folder, _, files in os.walk(staging):
        for name in files:
            if os.path.relpath(os.path.join(folder, name), staging).replace(os.sep, "/") not in written:
                os.remove(os.path.join(folder, name))

    def move(source: str, target: str) -> None:
        with os.scandir(source) as entries:
            for entry in entries:
                destination = os.path.join(target, entry.name)
                if not entry.is_dir(follow_symlinks=False):
                    os.replace(entry.path, destination)
                    continue
                if not os.path.exists(destination):
                    try:
                        os.replace(entry.path, destination)
                        continue
                    except OSError:
                        pass  # made meanwhile (another job's): filled below
                os.makedirs(destination, exist_ok=True)
                move(entry.path, destination)

    move(staging, lake)


def pack(
    parts: list[tuple[str, tuple[int, int] | None]], max_bytes: int, open_cost: int, parallelism: int
) -> list[list[int]]:
    """The parts (``(path, byte range)``) grouped into tasks as Spark's file sources group
    files (``spark.sql.files.maxPartitionBytes`` and ``openCostInBytes``): small files share a
    task, so that a folder of many small logs does not pay a task's start for each, and there
    are still enough tasks for every core. Each group: the parts' indexes."""

    def size(index: int) -> int:
        path, byte_range = parts[index]
        return byte_range[1] - byte_range[0] if byte_range else os.path.getsize(path)

    sizes = [size(index) for index in range(len(parts))]
    total = sum(sizes) + open_cost * len(parts)
    most = min(max_bytes, max(open_cost, total // max(1, parallelism)))
    tasks: list[list[int]] = []
    current: list[int] = []
    current_size = 0
    for index in sorted(range(len(parts)), key=lambda i: (-sizes[i], i)):
        if current and current_size + sizes[index] > most:
            tasks.append(current)
            current, current_size = [], 0
        current.append(index)
        current_size += sizes[index] + open_cost
    if current:
        tasks.append(current)
    return tasks


def _packing(spark, parts: int) -> tuple[int, int, int]:
    """Spark's settings for :func:`pack` (a session without a SparkContext: a task a part)."""
    max_bytes = _bytes(spark.conf.get("spark.sql.files.maxPartitionBytes", "128m"))
    open_cost = _bytes(spark.conf.get("spark.sql.files.openCostInBytes", "4m"))
    try:
        parallelism = spark.sparkContext.defaultParallelism
    except Exception:  # Spark Connect has no SparkContext
        return max_bytes, 0, parts
    return max_bytes, open_cost, parallelism


def _bytes(text: str) -> int:
    """A Spark size (``134217728b``, ``128m``, ``4MB``) in bytes."""
    text = text.strip().lower().removesuffix("b")
    scale = {"k": 1 << 10, "m": 1 << 20, "g": 1 << 30, "t": 1 << 40}.get(text[-1:], 1)
    return int(float(text.rstrip("kmgt")) * scale)


def _lake_task(parts, tasks, dbc, staging, job, pattern, compression, batch_rows, open_files):
    """What each task runs, given its index: its parts decoded into files under ``staging``
    (bywire writes them: ``bywire._native.write_lake_files``), named by task and job as Spark
    names a task's files; ``(file, rows)`` for each."""

    def write(task: int) -> list[tuple[str, int]]:
        db = bywire.Database.load(dbc)
        labelled = [(path, byte_range, *path_labels(path, pattern)) for path, byte_range in (parts[i] for i in tasks[task])]
        return bywire._native.write_lake_files(
            db._native, labelled, staging, f"part-{task:05d}-{job}", compression, batch_rows, open_files
        )

    return write
