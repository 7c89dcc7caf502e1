"""cantools' reading of database files, one JSON line per file: its messages and signals, and
what it decodes from random frames of every message (or the error that stopped it loading)."""
import json
import random
import sys

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
        "multiplexer": s.is_multiplexer,
        "multiplexer_ids": s.multiplexer_ids or [],
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


for path in sys.argv[1:]:
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
