"""cantools' reading of database files, one JSON line per file: its messages and signals, and
what it decodes from random frames of every message (or the error that stopped it loading)."""
import json
import random
import sys
import warnings

import cantools


def number(value):
    return None if value is None else float(value)


def signal(s):
    return {
        "name": s.name,
        "start": s.start,
        "length": s.length,
        "big_endian": s.byte_order == "big_endian",
        "signed": s.is_signed,
        "float": s.is_float,
        "scale": float(s.scale),
        "offset": float(s.offset),
        "minimum": number(s.minimum),
        "maximum": number(s.maximum),
        "unit": s.unit or "",
        "choices": {str(k): str(v) for k, v in (s.choices or {}).items()},
        "multiplexer": getattr(s, "is_multiplexer", False),
        "multiplexer_ids": getattr(s, "multiplexer_ids", None) or [],
    }


def decoded(message, rng):
    out = []
    for _ in range(32):
        data = bytes(rng.getrandbits(8) for _ in range(message.length))
        try:
            values = message.decode(data, decode_choices=False)
            out.append([data.hex(), {k: float(v) for k, v in values.items()}])
        except Exception as error:  # cantools raises several kinds for a frame it cannot decode
            out.append([data.hex(), None])
    return out


def did(d, rng):
    """A CDD's DID in the shape of a message: its identifier, length, data and decodes."""
    out = []
    for _ in range(32):
        data = bytes(rng.getrandbits(8) for _ in range(d.length))
        try:
            values = d.decode(data, decode_choices=False)
            out.append([data.hex(), {k: float(v) for k, v in values.items()}])
        except Exception:  # a DID cantools cannot decode
            out.append([data.hex(), None])
    return {
        "name": d.name, "frame_id": d.identifier, "extended": False, "fd": False, "length": d.length,
        "cycle_time": None, "senders": [], "comment": None,
        "signals": [signal(s) | {"multiplexer": False, "multiplexer_ids": []} for s in d.datas],
        "frames": out, "contained": [], "container": False,
    }


warnings.simplefilter("ignore", DeprecationWarning)
for path in sys.argv[1:]:
    if path.endswith(".cdd"):
        try:
            db = cantools.database.load_file(path)
        except Exception as error:
            print(json.dumps({"file": path, "error": f"{type(error).__name__}: {error}"}))
            continue
        rng = random.Random(path)
        print(json.dumps({"file": path, "messages": [did(d, rng) for d in db.dids]}))
        continue
    try:
        db = cantools.database.load_file(path, strict=False)
    except Exception as error:
        print(json.dumps({"file": path, "error": f"{type(error).__name__}: {error}"}))
        continue
    rng = random.Random(path)

    def message(m, frame_id):
        return {
            "name": m.name,
            "frame_id": frame_id,
            "extended": bool(m.is_extended_frame),
            "fd": bool(m.is_fd),
            "length": m.length,
            "cycle_time": m.cycle_time,
            "senders": list(m.senders),
            "comment": m.comment,
            "signals": [signal(s) for s in m.signals],
            # A container decodes only into its PDUs, which are listed with their header IDs.
            "frames": [] if m.is_container else decoded(m, rng),
            "contained": [message(c, c.header_id) for c in m.contained_messages or []],
            "container": bool(m.is_container),
        }

    messages = [message(m, m.frame_id) for m in db.messages]
    print(json.dumps({"file": path, "messages": messages}))
