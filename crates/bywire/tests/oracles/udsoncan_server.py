"""A UDS server built on udsoncan's request parser and response encoder (with can-isotp, on
python-can's udp_multicast inside lonet.sh), for `bywire uds` to diagnose: sessions with P2
50 ms / P2* 2000 ms, two DIDs, a writable DID behind the extended session and security
access (the demonstration key), DTCs with a snapshot and extended data, ClearDTC, a routine
answered through response pending, ECUReset, TesterPresent, ControlDTCSetting,
CommunicationControl, and NRCs for the rest. Prints "ready", then one line per request.

usage: udsoncan_server.py GROUP PORT"""

import os
import struct
import sys
import time

import can
import isotp
from udsoncan import Request, Response
from udsoncan.services import (ClearDiagnosticInformation, CommunicationControl,
                               ControlDTCSetting, DiagnosticSessionControl, ECUReset,
                               ReadDataByIdentifier, ReadDTCInformation, RoutineControl,
                               SecurityAccess, TesterPresent, WriteDataByIdentifier)

group, port = sys.argv[1], int(sys.argv[2])
bus = can.Bus(interface="udp_multicast", channel=group, port=port)
address = isotp.Address(isotp.AddressingMode.Normal_11bits, txid=0x7E8, rxid=0x7E0)
stack = isotp.CanStack(bus, address=address, params={"tx_padding": 0xCC, "blocking_send": False})
stack.start()

dids = {0xF190: b"UDSONCAN000000042", 0x0101: b"\x12\x34", 0xDD01: b"\x00\x00"}
# DTC → (status, snapshot DD01 value, occurrences)
dtcs = {0xC07300: (0x2F, b"\x01\x2C", 3), 0x512300: (0x2E, b"\x00\x00", 1)}
session, unlocked, seed = 1, False, b""
Code = Response.Code


def answer(service, data=b"", code=Code.PositiveResponse):
    stack.send(Response(service=service, code=code, data=data).get_payload())


def refuse(service, code):
    answer(service, code=code)


print("ready", flush=True)
while True:
    payload = stack.recv(block=True, timeout=0.05)
    if payload is None:
        continue
    request = Request.from_payload(payload)
    service, sub, data = request.service, request.subfunction, bytes(request.data or b"")
    print(f"request {payload.hex()}", flush=True)
    if service is DiagnosticSessionControl:
        session, unlocked = sub, False
        answer(service, bytes([sub]) + struct.pack(">HH", 50, 200))
    elif service is ReadDataByIdentifier:
        out = b""
        for i in range(0, len(data), 2):
            did = struct.unpack(">H", data[i:i + 2])[0]
            if did not in dids:
                refuse(service, Code.RequestOutOfRange)
                break
            out += data[i:i + 2] + dids[did]
        else:
            answer(service, out)
    elif service is WriteDataByIdentifier:
        did = struct.unpack(">H", data[:2])[0]
        if did != 0x0101:
            refuse(service, Code.RequestOutOfRange)
        elif session != 3:
            refuse(service, Code.ConditionsNotCorrect)
        elif not unlocked:
            refuse(service, Code.SecurityAccessDenied)
        else:
            dids[did] = data[2:]
            answer(service, data[:2])
    elif service is SecurityAccess:
        if session == 1:
            refuse(service, Code.ServiceNotSupportedInActiveSession)
        elif sub % 2 == 1:
            seed = os.urandom(4)
            answer(service, bytes([sub]) + seed)
        elif data == bytes(((b ^ 0x5A) + sub - 1) & 0xFF for b in seed):
            unlocked = True
            answer(service, bytes([sub]))
        else:
            refuse(service, Code.InvalidKey)
    elif service is ReadDTCInformation:
        if sub == 0x01:
            mask = data[0]
            count = sum(1 for s, _, _ in dtcs.values() if s & mask)
            answer(service, bytes([sub, 0xFF, 0x01]) + struct.pack(">H", count))
        elif sub == 0x02:
            mask = data[0]
            out = bytes([sub, 0xFF])
            for dtc, (status, _, _) in sorted(dtcs.items()):
                if status & mask:
                    out += dtc.to_bytes(3, "big") + bytes([status])
            answer(service, out)
        elif sub in (0x04, 0x06):
            dtc = int.from_bytes(data[:3], "big")
            if dtc not in dtcs:
                refuse(service, Code.RequestOutOfRange)
                continue
            status, snapshot, count = dtcs[dtc]
            head = bytes([sub]) + data[:3] + bytes([status])
            if sub == 0x04:
                answer(service, head + bytes([0x01, 0x01, 0xDD, 0x01]) + snapshot)
            else:
                answer(service, head + bytes([0x01, count]))
        else:
            refuse(service, Code.SubFunctionNotSupported)
    elif service is ClearDiagnosticInformation:
        dtcs.clear()
        answer(service)
    elif service is RoutineControl:
        routine = data[:2]
        if routine != b"\x02\x03":
            refuse(service, Code.RequestOutOfRange)
        elif sub == 1:
            refuse(service, Code.RequestCorrectlyReceived_ResponsePending)
            time.sleep(0.3)
            answer(service, bytes([sub]) + routine + b"\x00")
        elif sub == 3:
            answer(service, bytes([sub]) + routine + b"\x2A")
        else:
            answer(service, bytes([sub]) + routine + b"\x00")
    elif service is ECUReset:
        session, unlocked = 1, False
        answer(service, bytes([sub]))
    elif service is TesterPresent:
        if not request.suppress_positive_response:
            answer(service, b"\x00")
    elif service in (ControlDTCSetting, CommunicationControl):
        if session == 1:
            refuse(service, Code.ServiceNotSupportedInActiveSession)
        else:
            answer(service, bytes([sub]))
    else:
        stack.send(bytes([0x7F, payload[0], Code.ServiceNotSupported]))
