"""Malformed RTPS to a DDS node: datagrams captured from real discovery traffic (a seed file of
`PORT HEX` lines, as `tshark -T fields -e udp.dstport -e udp.payload` writes them), mutated —
bit flips, submessage lengths of 0/0x7FFF/0xFFFF, truncations, made-up GUID prefixes — and
sent to the domain's discovery multicast and the node's unicast ports on loopback. The node's
resident memory is read from /proc as it goes. Prints one JSON object. Run inside lonet.sh.

usage: rtps_flood.py PID COUNT SEED SEEDFILE"""

import json
import random
import socket
import struct
import sys
import time

pid, count, seed, seed_file = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
rng = random.Random(seed)
seeds = [bytes.fromhex(line.split()[1]) for line in open(seed_file)
         if len(line.split()) == 2 and line.split()[1].startswith("52545053")]
if not seeds:
    sys.exit("no RTPS datagrams in the seed file")
# Domain 0: discovery multicast, the first participant's metatraffic and user unicast ports.
targets = [("239.255.0.1", 7400), ("127.0.0.1", 7410), ("127.0.0.1", 7411)]
out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
out.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))


def rss_mb():
    for line in open(f"/proc/{pid}/status"):
        if line.startswith("VmRSS"):
            return int(line.split()[1]) / 1024
    return 0.0


def submessages(d):
    at, found = 20, []
    while at + 4 <= len(d):
        found.append(at)
        n = struct.unpack_from("<H" if d[at + 1] & 1 else ">H", d, at + 2)[0]
        if n == 0:
            break
        at += 4 + n
    return found


def mutated():
    d = bytearray(rng.choice(seeds))
    kind = rng.randrange(4)
    if kind == 0:
        for _ in range(rng.randint(1, 4)):
            p = rng.randrange(len(d))
            d[p] ^= 1 << rng.randrange(8)
    elif kind == 1 and submessages(d):
        at = rng.choice(submessages(d))
        struct.pack_into("<H" if d[at + 1] & 1 else ">H", d, at + 2,
                         rng.choice([0, 0x7FFF, 0xFFFF]))
    elif kind == 2:
        d = d[:rng.randrange(20, len(d))]
    else:
        for p in range(8, 20):
            d[p] = rng.randrange(256)
    return bytes(d)


start = rss_mb()
peak = start
for i in range(count):
    out.sendto(mutated(), rng.choice(targets))
    if i % 2000 == 1999:
        # Paced a little, so that the node's receive buffers are not the only thing tested.
        time.sleep(0.02)
        peak = max(peak, rss_mb())
time.sleep(0.5)
end = rss_mb()
print(json.dumps({"sent": count, "start_mb": start, "peak_mb": max(peak, end), "end_mb": end}))
