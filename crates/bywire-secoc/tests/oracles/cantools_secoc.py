"""SecOC frames by cantools' own framing (cantools.autosar.secoc) with a CMAC-AES-128
authenticator from the `cryptography` package: the independent implementation bywire's
secured frames are compared with.

Reads one case per line on stdin (JSON: key, data_id, payload_length, fv_length, fv_tx_length,
mac_tx_length, freshness, data as hex), writes one line per case: the secured frame cantools
makes from `data`, and whether cantools verifies `data` as it is."""
import json
import sys
import types

from cantools.autosar.secoc import apply_authenticator, verify_authenticator
from cantools.database.can.formats.arxml.secoc_properties import AutosarSecOCProperties
from cryptography.hazmat.primitives import cmac
from cryptography.hazmat.primitives.ciphers import algorithms

for line in sys.stdin:
    case = json.loads(line)
    key = bytes.fromhex(case["key"])
    message = types.SimpleNamespace(
        name="secured",
        autosar=types.SimpleNamespace(
            secoc=AutosarSecOCProperties(
                auth_algorithm_name="CMAC-AES-128",
                freshness_algorithm_name="counter",
                payload_length=case["payload_length"],
                data_id=case["data_id"],
                auth_tx_bit_length=case["mac_tx_length"],
                freshness_bit_length=case["fv_length"],
                freshness_tx_bit_length=case["fv_tx_length"],
            )
        ),
    )

    def authenticator(_message, auth_data, _freshness):
        mac = cmac.CMAC(algorithms.AES(key))
        mac.update(bytes(auth_data))
        return mac.finalize()

    data = bytes.fromhex(case["data"])
    secured = apply_authenticator(data, message, authenticator, case["freshness"])
    verified = verify_authenticator(data, message, authenticator, case["freshness"])
    print(json.dumps({"secured": bytes(secured).hex(), "verified": verified}), flush=True)
