"""What the log oracles share: a DBC loaded with cantools as bywire reads its text (UTF-8, or
cp1252 when it is not valid UTF-8), and the frames of a candump log."""
import cantools


def load(dbc):
    try:
        open(dbc, encoding="utf-8").read()
        encoding = "utf-8"
    except UnicodeDecodeError:
        encoding = "cp1252"
    return cantools.database.load_file(dbc, strict=False, encoding=encoding)


def frames(log):
    """Each line of a candump log as (time in ns, channel, identifier, extended, payload, fd)."""
    for line in open(log):
        stamp, channel, frame = line.split()
        seconds, fraction = stamp.strip("()").split(".")
        ts = int(seconds) * 1_000_000_000 + int(fraction.ljust(9, "0"))
        ident, data = frame.split("#", 1)
        fd = data.startswith("#")
        payload = bytes.fromhex(data[2:] if fd else data)
        yield ts, channel, int(ident, 16), len(ident) == 8, payload, fd
