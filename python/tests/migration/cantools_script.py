"""A script written against cantools, as its users write them: load databases, walk the
messages and signals, decode and encode (choices, multiplexing, unscaled values), print the
decoded dicts, and handle the errors. The migration test runs it as it is and with its import
line changed to bywire's, and compares what both print.

    cantools_script.py TUG_DBC MOTOHAWK_DBC MULTIPLEX_DBC
"""
import sys

import cantools

tug, motohawk, multiplex = (cantools.database.load_file(p) for p in sys.argv[1:4])

for db in (tug, motohawk, multiplex):
    print(db.version, len(db.messages), [n.name for n in db.nodes])
    for message in db.messages:
        print(message.name, hex(message.frame_id), message.is_extended_frame, message.length,
              message.cycle_time, message.senders, message.is_multiplexed(), message.comment)
        for s in message.signals:
            print("  ", s.name, s.start, s.length, s.byte_order, s.is_signed, s.is_float, s.scale,
                  s.offset, s.minimum, s.maximum, s.unit, s.choices, s.receivers, s.is_multiplexer,
                  s.multiplexer_ids, s.multiplexer_signal, s.initial, s.comment)

# Encode and decode with the message objects and by name and identifier.
example = motohawk.get_message_by_name("ExampleMessage")
data = example.encode({"Temperature": 250.1, "AverageRadius": 3.2, "Enable": 1})
print(data.hex())
decoded = motohawk.decode_message(example.frame_id, data)
print(decoded)
print(decoded["Enable"] == "Enabled", str(decoded["Enable"]), decoded["Enable"].value)
print(motohawk.decode_message("ExampleMessage", data, decode_choices=False))
print(motohawk.decode_message("ExampleMessage", data, scaling=False))
print(motohawk.encode_message("ExampleMessage", {"Temperature": 250.1, "AverageRadius": 3.2, "Enable": "Disabled"}).hex())
# A decoded choice goes back into encode as it came out.
print(motohawk.encode_message("ExampleMessage", decoded).hex())

# Multiplexing: each multiplexer value selects its signals.
message = multiplex.get_message_by_name("Message1")
print(message.signal_tree)
for values in ({"Multiplexor": 8, "BIT_J": 1, "BIT_C": 0, "BIT_G": 1, "BIT_L": 0, "BIT_A": 1, "BIT_K": 0, "BIT_E": 1, "BIT_D": 0, "BIT_B": 1, "BIT_H": 0, "BIT_F": 1},
               {"Multiplexor": 24, "BIT_J": 1, "BIT_C": 0, "BIT_G": 1, "BIT_L": 0, "BIT_A": 1, "BIT_K": 0, "BIT_E": 1, "BIT_D": 0, "BIT_B": 1, "BIT_H": 0, "BIT_F": 1}):
    try:
        encoded = message.encode(values)
        print(encoded.hex(), message.decode(encoded))
    except (cantools.database.EncodeError, KeyError) as error:
        print("encode error", type(error).__name__)

# The tug: a frame of each message, decoded, as a log decoder prints them.
for m in tug.messages:
    payload = bytes((i * 37 + m.frame_id) % 256 for i in range(m.length))
    try:
        print(m.name, tug.decode_message(m.frame_id, payload))
    except cantools.database.DecodeError as error:
        print(m.name, "decode error:", error)

# Errors a script handles.
try:
    tug.get_message_by_name("NoSuchMessage")
except KeyError as error:
    print("KeyError", error)
try:
    motohawk.decode_message(example.frame_id, b"\x00")
except cantools.database.DecodeError as error:
    print("DecodeError", error)
try:
    cantools.database.load_file("no/such/file.dbc")
except FileNotFoundError:
    print("FileNotFoundError")
