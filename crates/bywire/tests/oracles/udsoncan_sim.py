"""udsoncan (with can-isotp, on python-can's socketcand interface) as the tester of the
simulated tug's vehicle control ECU, served by `bywire sim --serve`: its DTCs with status
bits, the E-stop's snapshot, its occurrence counts, the VIN and odometer, ClearDTC, and the
DTCs after it. Prints one JSON object.

usage: udsoncan_sim.py HOST PORT"""

import json
import sys

import can
import isotp
import udsoncan
from udsoncan.client import Client
from udsoncan.connections import PythonIsoTpConnection

host, port = sys.argv[1], int(sys.argv[2])
bus = can.Bus(interface="socketcand", host=host, port=port, channel="bus1")
address = isotp.Address(isotp.AddressingMode.Normal_11bits, txid=0x7E0, rxid=0x7E8)
stack = isotp.CanStack(bus, address=address, params={"tx_padding": 0xAA})
config = dict(udsoncan.configs.default_client_config)
config["data_identifiers"] = {
    0xF190: udsoncan.AsciiCodec(17),
    0x0301: ">I",
    0xDD00: ">I",
    0xDD01: ">h",
    0xDD02: ">h",
}
config["extended_data_size"] = 1
out = {}
with Client(PythonIsoTpConnection(stack), request_timeout=5, config=config) as client:
    r = client.get_dtc_by_status_mask(0xFF)
    out["dtcs"] = {f"{d.id:06X}": d.status.get_byte_as_int() for d in r.service_data.dtcs}
    failing = client.get_dtc_by_status_mask(0x01).service_data.dtcs
    out["failing"] = sorted(f"{d.id:06X}" for d in failing)
    r = client.get_dtc_snapshot_by_dtc_number(0x500000, record_number=1)
    snapshot = {f"{s.did:04X}": s.data for s in r.service_data.dtcs[0].snapshots}
    out["estop_snapshot"] = snapshot
    r = client.get_dtc_extended_data_by_dtc_number(0xD00103, record_number=1)
    out["full_braking_occurrences"] = list(r.service_data.dtcs[0].extended_data[0].raw_data)
    r = client.read_data_by_identifier([0xF190, 0x0301])
    out["vin"] = r.service_data.values[0xF190]
    out["odometer_m"] = r.service_data.values[0x0301]
    client.clear_dtc(0xFFFFFF)
    after = client.get_dtc_by_status_mask(0xFF).service_data.dtcs
    out["after_clear"] = {f"{d.id:06X}": d.status.get_byte_as_int() for d in after}
bus.shutdown()
print(json.dumps(out))
