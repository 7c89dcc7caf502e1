"""bywire's KCD and SYM writers read by an independent implementation: DBC files converted by
``bywire dbc convert`` are loaded by canmatrix, and canmatrix's decode of random payloads equals
cantools' decode of the original DBC, signal for signal. And an ARXML system read through
``bywire.database`` as cantools reads it, container frames included."""

from __future__ import annotations

import math
import random
import subprocess

import canmatrix.formats
import cantools
import pytest

from conftest import CORPUS, ROOT, TUG_DBC, bywire_cli

SOURCES = [
    TUG_DBC,
    ROOT / "target" / "cantools-files" / "dbc" / "motohawk.dbc",
    ROOT / "target" / "cantools-files" / "dbc" / "abs.dbc",
    CORPUS / "dbc" / "opendbc" / "opendbc__dbc__gm_global_a_object.dbc",
    CORPUS / "dbc" / "opendbc" / "opendbc__dbc__generator__toyota___toyota_adas_standard.dbc",
]


def number(value) -> float:
    return float(value.value if hasattr(value, "value") else value)


@pytest.mark.parametrize("source", SOURCES, ids=lambda p: p.name)
@pytest.mark.parametrize("extension", ["kcd", "sym"])
def test_canmatrix_decodes_our_kcd_and_sym_as_cantools_decodes_the_dbc(source, extension, tmp_path):
    if not source.exists():
        pytest.fail(f"{source} is missing: run scripts/install-test-deps.sh")
    converted = tmp_path / f"{source.stem}.{extension}"
    subprocess.run([bywire_cli(), "dbc", "convert", str(source), str(converted)], check=True, capture_output=True)
    theirs = cantools.database.load_file(str(source), strict=False)
    matrix = next(iter(canmatrix.formats.loadp(str(converted)).values()))
    frames = {frame.name: frame for frame in matrix.frames}
    rng = random.Random(source.name)
    compared = 0
    for message in theirs.messages:
        if message.is_multiplexed() or message.length > 8:
            continue  # canmatrix's multiplexing and FD readers are not what is compared here
        frame = frames.get(message.name)
        assert frame is not None, f"{converted}: no {message.name} in canmatrix's reading"
        assert frame.arbitration_id.id == message.frame_id
        assert frame.arbitration_id.extended == message.is_extended_frame
        if extension == "sym":
            # canmatrix 1.3.3 takes a symbol's length from format 5.0's DLC= only; 6.0 (what
            # bywire writes, as PCAN's editor and cantools do) says Len=. The layout is compared.
            assert frame.size == 0
            frame.size = message.length
        else:
            assert frame.size == message.length
        for _ in range(8):
            payload = rng.randbytes(message.length)
            expected = theirs.decode_message(message.frame_id, payload, decode_choices=False)
            got = frame.decode(payload)
            if extension == "sym":
                # canmatrix 1.3.3 reads format 5.0's `enum NAME(...)` only, not 6.0's `Enum=`:
                # it drops the signals that name an enum. Those must be the only ones missing.
                with_enum = {s.name for s in message.signals if s.choices}
                assert set(expected) - set(got) <= with_enum, (message.name, sorted(got), sorted(expected))
                expected = {k: v for k, v in expected.items() if k in got}
            assert set(got) == set(expected), (message.name, sorted(got), sorted(expected))
            for name, value in expected.items():
                ours = float(got[name].phys_value)
                assert math.isclose(ours, number(value), rel_tol=1e-9, abs_tol=1e-9), (message.name, name, payload.hex(), ours, value)
            compared += 1
    assert compared > 0


def test_arxml_loads_in_python_as_in_cantools():
    """An AUTOSAR system through ``bywire.database``: the same messages, buses and container
    PDUs as cantools reads, and random container frames unpack and decode alike."""
    import bywire.database

    path = ROOT / "examples" / "data" / "powertrain.arxml"
    ours = bywire.database.load_file(path)
    theirs = cantools.database.load_file(path)
    assert [m.name for m in ours.messages] == [m.name for m in theirs.messages]
    assert [m.bus_name for m in ours.messages] == [m.bus_name for m in theirs.messages]
    container, their_container = ours.get_message_by_name("Bundle"), theirs.get_message_by_name("Bundle")
    assert [(m.name, m.header_id) for m in container.contained_messages] == [
        (m.name, m.header_id) for m in their_container.contained_messages
    ]
    rng = random.Random(58)
    for _ in range(200):
        # Three PDUs of random content behind valid headers: Lights, Steer, Lights.
        beam, steer, beam2 = bytes([rng.getrandbits(2)]), rng.randbytes(6), bytes([rng.getrandbits(2)])
        data = b"\x00\x00\x10\x01" + beam + b"\x00\x00\x20\x06" + steer + b"\x00\x00\x10\x01" + beam2
        decoded = ours.decode_message(0x300, data, decode_containers=True)
        expected = theirs.decode_message(0x300, data, decode_containers=True)
        assert [(m.name, dict(values)) for m, values in decoded] == [(m.name, dict(values)) for m, values in expected]


@pytest.mark.parametrize("name", ["example.cdd", "le-example.cdd", "example-diddatarefs.cdd"])
def test_cdd_dids_decode_and_encode_as_cantools(name):
    """A CANdela CDD through ``bywire.database``: the same DIDs as cantools' diagnostics
    database, random records decoded, and the decoded values encoded, alike."""
    import warnings

    import bywire.database

    path = ROOT / "target" / "cantools-files" / "cdd" / name
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        theirs = cantools.database.load_file(path)
    ours = bywire.database.load_file(path)
    assert [(d.name, d.identifier, d.length) for d in ours.dids] == [(d.name, d.identifier, d.length) for d in theirs.dids]
    rng = random.Random(name)
    for o, t in zip(ours.dids, theirs.dids):
        assert [d.name for d in o.datas] == [d.name for d in t.datas]
        for _ in range(20):
            record = rng.randbytes(o.length)
            decoded, expected = o.decode(record), t.decode(record)
            assert {k: str(v) for k, v in decoded.items()} == {k: str(v) for k, v in expected.items()}, o.name
            assert o.encode(decoded) == t.encode(expected), o.name
