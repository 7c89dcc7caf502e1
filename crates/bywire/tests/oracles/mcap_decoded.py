"""Checks an MCAP file written by `bywire log convert --dbc` against cantools and JSON Schema.

Arguments: the DBC, the candump log that was converted, the MCAP file. Every JSON message must
be valid against its channel's schema (jsonschema), sit on /<interface>/<message>, and hold
cantools' decode of the frame logged at its log time: numbers equal, `_choice` the choice
name; the raw channel holds every classic frame (mcap-ros2-support decodes it). Prints a
summary.
"""
import json
import math
import sys

import corpus_dbc
import jsonschema
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

dbc, log, path = sys.argv[1:4]
db = corpus_dbc.load(dbc)
by_id = {(m.frame_id, m.is_extended_frame): m for m in reversed(db.messages)}

expected = {}  # (topic, log time) -> (numbers, named)
classic = 0
for ts, channel, ident, extended, payload, fd in corpus_dbc.frames(log):
    classic += not fd
    message = by_id.get((ident, extended))
    if message is None:
        continue
    try:
        numbers = message.decode(payload, decode_choices=False)
        named = message.decode(payload, decode_choices=True)
    except Exception:
        continue
    expected[(f"/{channel}/{message.name}", ts)] = (numbers, named)

seen = raw = 0
validators = {}
with open(path, "rb") as f:
    reader = make_reader(f, decoder_factories=[DecoderFactory()])
    for schema, channel, message in reader.iter_messages():
        if channel.message_encoding == "cdr":
            raw += 1
            continue
        assert channel.message_encoding == "json" and schema.encoding == "jsonschema", channel
        if schema.id not in validators:
            validators[schema.id] = jsonschema.Draft202012Validator(json.loads(schema.data))
        value = json.loads(message.data)
        validators[schema.id].validate(value)
        numbers, named = expected.pop((channel.topic, message.log_time))
        assert set(numbers) == {k for k in value if not k.endswith("_choice")}, (channel.topic, value, numbers)
        for name, want in numbers.items():
            got = value[name]
            if isinstance(want, float) and not math.isfinite(want):
                assert got is None, (name, got)
            else:
                assert got == want and type(got) is type(want), (channel.topic, name, got, want)
            if name + "_choice" in value:
                label = named[name]
                want_label = None if isinstance(label, (int, float)) else str(label)
                assert value[name + "_choice"] == want_label, (name, value[name + "_choice"], want_label)
        seen += 1
assert not expected, ("frames with no JSON message", list(expected)[:5])
assert raw == classic, (raw, classic)
print(f"{seen} JSON messages valid and equal to cantools, {raw} raw frames")
