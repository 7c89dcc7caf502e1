"""AUTOSAR E2E Profile 1 and 2 protection by the `autosar-e2e` package (a C implementation
independent of bywire). Reads JSON lines {profile, data_hex, data_id | data_id_list, mode?} and
prints, per line, the protected bytes as hex after `count` protect calls."""
import json
import sys

from e2e import p01, p02

MODES = {"both": p01.E2E_P01_DATAID_BOTH, "alt": p01.E2E_P01_DATAID_ALT,
         "low": p01.E2E_P01_DATAID_LOW, "nibble": p01.E2E_P01_DATAID_NIBBLE}

for line in sys.stdin:
    case = json.loads(line)
    data = bytearray.fromhex(case["data_hex"])
    out = []
    for _ in range(case["count"]):
        if case["profile"] == 1:
            if case["mode"] == "nibble":
                data[1] = (data[1] & 0x0F) | (((case["data_id"] >> 8) & 0x0F) << 4)
            p01.e2e_p01_protect(data, case["data_id"], data_id_mode=MODES[case["mode"]],
                                increment_counter=False)
            out.append(data.hex())
            counter = (data[1] & 0x0F) + 1
            data[1] = (data[1] & 0xF0) | (0 if counter == 15 else counter)
        else:
            p02.e2e_p02_protect(data, bytes(case["data_id_list"]), increment_counter=True)
            out.append(data.hex())
    print(json.dumps(out))
