"""udsoncan (with can-isotp, on python-can's udp_multicast inside lonet.sh) as the tester of
`bywire uds serve`: sessions, DIDs read and written, a refused read, DTCs by status mask,
ClearDTC, TesterPresent and ECUReset. Prints one JSON object of the answers.

usage: udsoncan_client.py GROUP PORT"""

import json
import sys

import can
import isotp
import udsoncan
from udsoncan.client import Client
from udsoncan.connections import PythonIsoTpConnection
from udsoncan.exceptions import NegativeResponseException

group, port = sys.argv[1], int(sys.argv[2])
bus = can.Bus(interface="udp_multicast", channel=group, port=port)
address = isotp.Address(isotp.AddressingMode.Normal_11bits, txid=0x7E0, rxid=0x7E8)
stack = isotp.CanStack(bus, address=address, params={"tx_padding": 0x55})
config = dict(udsoncan.configs.default_client_config)
config["data_identifiers"] = {
    0xF190: udsoncan.AsciiCodec(17),
    0xF195: udsoncan.AsciiCodec(5),
    0x0101: ">H",
    0x1234: ">H",
    0x0202: ">B",
}
# bywire's demonstration key: each seed byte XOR 0x5A, plus the level.
# udsoncan adopts the server's P2 (50 ms) with no margin for the transport; ISO 14229-2 adds
# one, as bywire's own tester does. A Python ISO-TP stack on a loaded machine can take longer
# than 50 ms to pass an answer on, so the tester keeps its own 1 s (P2* still 5 s).
config["use_server_timing"] = False
config["p2_timeout"] = 1
config["security_algo"] = lambda level, seed, params: bytes(((b ^ 0x5A) + level) & 0xFF for b in seed)
out = {}
with Client(PythonIsoTpConnection(stack), request_timeout=3, config=config) as client:
    r = client.change_session(3)
    out["session"] = [r.service_data.session_echo, r.service_data.p2_server_max,
                      r.service_data.p2_star_server_max]
    r = client.read_data_by_identifier([0xF190, 0xF195])
    out["dids"] = {f"{k:04X}": v for k, v in r.service_data.values.items()}
    client.write_data_by_identifier(0x0101, 0x1234)
    out["written"] = client.read_data_by_identifier(0x0101).service_data.values[0x0101]
    try:
        client.read_data_by_identifier(0x1234)
        out["refused"] = None
    except NegativeResponseException as e:
        out["refused"] = e.response.code
    r = client.get_dtc_by_status_mask(0xFF)
    out["dtcs"] = [[f"{d.id:06X}", d.status.get_byte_as_int()] for d in r.service_data.dtcs]
    out["failing"] = [f"{d.id:06X}" for d in client.get_dtc_by_status_mask(0x01).service_data.dtcs]
    client.clear_dtc(0xFFFFFF)
    out["after_clear"] = len(client.get_dtc_by_status_mask(0xFF).service_data.dtcs)
    try:
        client.write_data_by_identifier(0x0202, 9)
        out["locked_write"] = None
    except NegativeResponseException as e:
        out["locked_write"] = e.response.code
    client.unlock_security_access(1)
    client.write_data_by_identifier(0x0202, 9)
    out["secured"] = client.read_data_by_identifier(0x0202).service_data.values[0x0202]
    # A routine that runs 300 ms: udsoncan waits through the response-pending answer.
    client.start_routine(0x0203)
    out["routine"] = list(client.get_routine_result(0x0203).service_data.routine_status_record)
    client.tester_present()
    out["reset"] = client.ecu_reset(1).service_data.reset_type_echo
# A functional TesterPresent (one frame on 0x7DF), answered physically on 0x7E8.
while bus.recv(0.05) is not None:
    pass
bus.send(can.Message(arbitration_id=0x7DF, data=[0x02, 0x3E, 0x00], is_extended_id=False))
answer = None
for _ in range(40):
    m = bus.recv(0.05)
    if m is not None and m.arbitration_id == 0x7E8:
        answer = m.data.hex()
        break
out["functional"] = answer
print(json.dumps(out))
