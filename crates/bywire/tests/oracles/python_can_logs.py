"""python-can's reading of log files: for each file, its messages as candump -L frame text
(`ID#DATA`, `ID#R[DLC]`, `ID##FLAGSDATA`, error frames as `ERROR`), with the channel and the
time since the file's first message. Prints one JSON object, keyed by path.

usage: python_can_logs.py FILE..."""

import json
import sys

import can


def text(m):
    if m.is_error_frame:
        return "ERROR"
    ident = f"{m.arbitration_id:08X}" if m.is_extended_id else f"{m.arbitration_id:03X}"
    if m.is_remote_frame:
        return f"{ident}#R{m.dlc if m.dlc else ''}"
    data = bytes(m.data).hex().upper()
    if m.is_fd:
        # CANFD_FDF (4) beside BRS (1) and ESI (2), as candump writes them today.
        flags = 4 | (1 if m.bitrate_switch else 0) | (2 if m.error_state_indicator else 0)
        return f"{ident}##{flags:X}{data}"
    # A classic DLC beyond 8 (python-can keeps it as its FD length): candump's `_DLC`.
    raw_dlc = f"_{can.util.len2dlc(m.dlc):X}" if m.dlc > 8 else ""
    return f"{ident}#{data}{raw_dlc}"


result = {}
for path in sys.argv[1:]:
    messages = list(can.LogReader(path))
    first = messages[0].timestamp if messages else 0.0
    result[path] = [
        {"channel": m.channel, "t": m.timestamp - first, "frame": text(m)} for m in messages
    ]
print(json.dumps(result))
