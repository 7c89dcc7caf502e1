"""Writes a candump log of a DBC's traffic: every message of the DBC (as cantools loads it),
`rounds` times, with random payloads of the message's length, on can0 and can1 in turn.

Arguments: the DBC, the number of rounds, the seed. Prints the log on standard output.
"""
import random
import sys

import corpus_dbc

dbc, rounds, seed = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
db = corpus_dbc.load(dbc)
rng = random.Random(seed)
nanos = 1_700_000_000_000_000_000
for round in range(rounds):
    for message in db.messages:
        nanos += 137_000
        data = bytes(rng.getrandbits(8) for _ in range(message.length))
        ident = f"{message.frame_id:08X}" if message.is_extended_frame else f"{message.frame_id:03X}"
        separator = "##1" if message.length > 8 else "#"
        print(f"({nanos // 10**9}.{nanos % 10**9 // 1000:06d}) can{round % 2} {ident}{separator}{data.hex().upper()}")
