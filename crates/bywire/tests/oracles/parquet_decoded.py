"""Checks a decoded Parquet dataset written by `bywire log convert --dbc` against cantools.

Arguments: the DBC, the candump log that was converted, the dataset's directory. Every frame
of the log is decoded with cantools (numbers, and separately the value descriptions); every
message's table is read with pyarrow and with polars, and each row must equal cantools'
decode of the same frame: same rows in the same order, every signal equal (integers exactly,
floats to the bit), every `_choice` column equal to cantools' choice name. DuckDB reads every
row as pyarrow does. Prints a summary.
"""
import math
import pathlib
import sys

import corpus_dbc
import duckdb
import polars
import pyarrow.parquet as pq

dbc, log, root = sys.argv[1], sys.argv[2], pathlib.Path(sys.argv[3])
db = corpus_dbc.load(dbc)
by_id = {}
for m in db.messages:
    by_id.setdefault((m.frame_id, m.is_extended_frame), m)

expected = {}  # message name -> list of (ts_ns, channel, numbers, choices)
for ts, channel, ident, extended, payload, _ in corpus_dbc.frames(log):
    message = by_id.get((ident, extended))
    if message is None:
        continue
    try:
        numbers = message.decode(payload, decode_choices=False)
        named = message.decode(payload, decode_choices=True)
    except Exception:
        continue  # cantools cannot decode it: it must not be a row either
    expected.setdefault(message.name, []).append((ts, channel, numbers, named))


def same(a, b):
    if isinstance(b, float) or isinstance(a, float):
        return (math.isnan(a) and math.isnan(b)) or float(a) == float(b)
    return a == b


written = sorted(p.name.removeprefix("message=") for p in root.iterdir())
assert written == sorted(expected), ("tables cantools has no rows for", sorted(set(written) ^ set(expected)))
tables = checked = 0
for name, rows in expected.items():
    directory = root / f"message={name}"
    table = pq.read_table(directory)
    frame = polars.read_parquet(directory / "*.parquet")
    assert table.num_rows == len(rows) == frame.height, (name, table.num_rows, len(rows), frame.height)
    assert str(table.schema.field("ts").type) == "timestamp[ns, tz=UTC]", table.schema
    columns = table.to_pydict()
    ts = table.column("ts").cast("int64").to_pylist()
    names = table.column_names[1:]
    quoted = ", ".join('"' + n.replace('"', '""') + '"' for n in names)
    ducks = duckdb.execute(f"SELECT epoch_ns(ts), {quoted} FROM read_parquet(?)", [str(directory / "*.parquet")]).fetchall()
    assert len(ducks) == len(rows), (name, len(ducks), len(rows))
    for i, duck in enumerate(ducks):
        arrow = (ts[i], *(columns[n][i] for n in names))
        assert all(a == d or (isinstance(a, float) and isinstance(d, float) and same(a, d)) for a, d in zip(arrow, duck)), (name, i, arrow, duck)
    message = db.get_message_by_name(name)
    for i, (when, channel, numbers, named) in enumerate(rows):
        assert ts[i] == when, (name, i, ts[i], when)
        assert columns["channel"][i] == channel, (name, i)
        for signal in message.signals:
            got = columns[signal.name][i]
            if signal.name not in numbers:
                assert got is None, (name, signal.name, i, got)
                continue
            want = numbers[signal.name]
            assert same(got, want), (name, signal.name, i, got, want)
            kind = table.schema.field(signal.name).type
            assert (str(kind) == "int64" or str(kind) == "uint64") == isinstance(want, int), (name, signal.name, kind, want)
            if signal.choices:
                label = named[signal.name]
                want_label = str(label) if not isinstance(label, (int, float)) else None
                assert columns[signal.name + "_choice"][i] == want_label, (name, signal.name, i, columns[signal.name + "_choice"][i], want_label)
            checked += 1
    tables += 1
print(f"{tables} tables, {sum(len(r) for r in expected.values())} rows, {checked} values agree")
