"""bywire.Database against cantools: the corpus's 103,810 cantools vectors, and cantools itself
run beside it on the same payloads (choices, unscaled values, truncated data, errors)."""

from __future__ import annotations

import gzip
import json
import math
import random
from collections import defaultdict

import cantools
import pytest

import bywire
from conftest import CORPUS, TUG_DBC, plain_dict


def same_number(expected, ours) -> bool:
    if isinstance(expected, str):
        return {
            "NaN": isinstance(ours, float) and math.isnan(ours),
            "inf": ours == math.inf,
            "-inf": ours == -math.inf,
        }.get(expected, False)
    if isinstance(expected, float):
        return isinstance(ours, float) and (
            expected == ours and math.copysign(1, expected) == math.copysign(1, ours)
        )
    return type(ours) is int and expected == ours


def vectors_by_file():
    by_file = defaultdict(list)
    with gzip.open(CORPUS / "vectors.jsonl.gz", "rt") as lines:
        for line in lines:
            vector = json.loads(line)
            by_file[vector["file"]].append(vector)
    return by_file


def test_every_corpus_vector_decodes_and_encodes_as_cantools_did():
    checked = decoded = errors = encoded = 0
    problems = []
    for file, vectors in sorted(vectors_by_file().items()):
        db = bywire.Database.load(CORPUS / "dbc" / file)
        infos = {}
        for v in vectors:
            name = v["message"]
            if name not in infos:
                infos[name] = db.message_info(name)
            info = infos[name]
            multiplexed = {s["name"] for s in info["signals"] if s["multiplexer_ids"] is not None}
            payload = bytes.fromhex(v["payload_hex"])
            checked += 1
            expected = v["decoded"] if isinstance(v["decoded"], dict) else v.get("decoded_per_signal")
            if expected is None:
                error = v["decode_error"] or ""
                if error == "DecodeError: unpacking failed" and multiplexed:
                    # cantools refuses some multiplexed layouts bywire decodes (see the
                    # corpus test in bywire-dbc); there is no error to compare.
                    continue
                try:
                    db.decode_message(name, payload, decode_choices=False)
                    problems.append(f"{file} {name} {v['payload_hex']}: cantools '{error}', bywire decoded")
                except bywire.DecodeError as e:
                    errors += 1
                    if f"DecodeError: {e}" != error:
                        problems.append(f"{file} {name}: cantools '{error}', bywire '{e}'")
                continue
            ours = db.decode_message(name, payload, decode_choices=False)
            extra = set(ours) - set(expected)
            # A lone `m` multiplexor: cantools drops the signals it selects; bywire keeps them.
            if set(expected) - set(ours) or not extra <= multiplexed:
                problems.append(f"{file} {name} {v['payload_hex']}: signals {sorted(ours)} vs {sorted(expected)}")
                continue
            decoded += 1
            for signal, value in expected.items():
                if not same_number(value, ours[signal]):
                    problems.append(f"{file} {name}.{signal} {v['payload_hex']}: cantools {value!r}, bywire {ours[signal]!r}")
            # Where cantools dropped signals of a lone `m` (extra), it encodes without them
            # too; bywire needs them: nothing to compare.
            if v.get("reencoded_hex") and not extra:
                values = {k: ours[k] for k in expected}
                again = db.encode_message(name, values, strict=False)
                encoded += 1
                if again.hex() != v["reencoded_hex"]:
                    problems.append(f"{file} {name}: re-encoded cantools {v['reencoded_hex']}, bywire {again.hex()}")
    assert not problems, f"{len(problems)} of {checked} disagree:\n" + "\n".join(problems[:10])
    # The corpus's counts: most vectors decode, some hundred are multiplexer errors.
    assert checked == 103_810
    assert decoded > 90_000 and errors > 200 and encoded > 90_000


CANTOOLS_FILES = [
    TUG_DBC,
    CORPUS / "dbc" / "cantools" / "tests__files__dbc__vehicle.dbc",
    CORPUS / "dbc" / "cantools" / "tests__files__dbc__multiplex_2.dbc",
    CORPUS / "dbc" / "cantools" / "tests__files__dbc__choices.dbc",
    CORPUS / "dbc" / "cantools" / "tests__files__dbc__floating_point.dbc",
    CORPUS / "dbc" / "cantools" / "tests__files__dbc__signed.dbc",
    CORPUS / "dbc" / "opendbc" / "opendbc__dbc__ESR.dbc",
]


@pytest.mark.parametrize("path", CANTOOLS_FILES, ids=lambda p: p.name)
def test_decoding_matches_cantools_with_choices_unscaled_and_truncated(path):
    theirs = cantools.database.load_file(str(path), strict=False)
    ours = bywire.Database.load(path)
    rng = random.Random(path.name)
    compared = 0
    for message in theirs.messages:
        for _ in range(40):
            payload = bytes(rng.getrandbits(8) for _ in range(message.length))
            for options in (
                {},
                {"decode_choices": False},
                {"scaling": False},
                {"scaling": False, "decode_choices": False},
            ):
                try:
                    expected = plain_dict(theirs.decode_message(message.frame_id, payload, **options))
                except cantools.database.DecodeError as e:
                    if "unpacking failed" in str(e):
                        continue
                    with pytest.raises(bywire.DecodeError) as ours_error:
                        ours.decode_message(message.frame_id, payload, **options)
                    assert str(ours_error.value) == str(e)
                    continue
                got = plain_dict(ours.decode_message(message.frame_id, payload, **options))
                assert got == expected, (message.name, payload.hex(), options)
                assert {k: type(v) for k, v in got.items()} == {k: type(v) for k, v in expected.items()}
                compared += 1
            cut = rng.randrange(0, message.length)
            try:
                expected = plain_dict(theirs.decode_message(message.frame_id, payload[:cut], allow_truncated=True))
            except cantools.database.DecodeError:
                continue
            got = plain_dict(ours.decode_message(message.frame_id, payload[:cut], allow_truncated=True))
            assert got == expected, (message.name, payload[:cut].hex(), "truncated")
    assert compared >= 40


def test_wrong_sizes_and_unknown_messages_fail_as_in_cantools():
    theirs = cantools.database.load_file(str(TUG_DBC))
    ours = bywire.Database.load(TUG_DBC)
    for data, options in ((b"\x00" * 3, {}), (b"\x00" * 9, {"allow_excess": False})):
        with pytest.raises(cantools.database.DecodeError) as a:
            theirs.get_message_by_frame_id(0x101).decode(data, **options)
        with pytest.raises(bywire.DecodeError) as b:
            ours.decode_message(0x101, data, **options)
        assert str(a.value) == str(b.value)
    # Excess bytes are cut off by default.
    assert plain_dict(ours.decode_message(0x101, b"\x01" * 12)) == plain_dict(
        theirs.decode_message(0x101, b"\x01" * 12)
    )
    for key in (0x7FF, "NoSuchMessage"):
        with pytest.raises(KeyError) as a:
            theirs.decode_message(key, b"\x00" * 8)
        with pytest.raises(KeyError) as b:
            ours.decode_message(key, b"\x00" * 8)
        assert a.value.args == b.value.args


def test_nan_and_infinity_raise_as_in_cantools_strict_or_not():
    """An integer signal holds no NaN or infinity: cantools raises ValueError and OverflowError
    as Python's int() does (bywire encoded NaN as raw 0)."""
    theirs = cantools.database.load_file(str(TUG_DBC))
    ours = bywire.Database.load(TUG_DBC)
    control = {s.name: 0 for s in theirs.get_message_by_name("AdsToVehicle_Control").signals}
    for value, kind in ((math.nan, ValueError), (math.inf, OverflowError), (-math.inf, OverflowError)):
        for options in ({}, {"strict": False}, {"scaling": False, "strict": False}):
            values = {**control, "VelocityCmd": value}
            with pytest.raises(kind) as a:
                theirs.encode_message("AdsToVehicle_Control", values, **options)
            with pytest.raises(kind) as b:
                ours.encode_message("AdsToVehicle_Control", values, **options)
            assert str(a.value) == str(b.value), options


def test_encoding_matches_cantools_values_padding_and_errors():
    theirs = cantools.database.load_file(str(TUG_DBC))
    ours = bywire.Database.load(TUG_DBC)
    rng = random.Random(7)
    for message in theirs.messages:
        for _ in range(30):
            payload = bytes(rng.getrandbits(8) for _ in range(message.length))
            values = theirs.decode_message(message.frame_id, payload)
            ours_values = ours.decode_message(message.frame_id, payload)
            for options in ({"strict": False}, {"strict": False, "padding": True}, {}):
                try:
                    expected = theirs.encode_message(message.frame_id, values, **options)
                except cantools.database.EncodeError as e:
                    with pytest.raises(bywire.EncodeError) as b:
                        ours.encode_message(message.frame_id, ours_values, **options)
                    assert str(b.value) == str(e)
                    continue
                # Choices given as bywire's NamedSignalValue, and as plain names.
                assert ours.encode_message(message.frame_id, ours_values, **options) == expected
                named = {k: str(v) if hasattr(v, "name") else v for k, v in ours_values.items()}
                assert ours.encode_message(message.frame_id, named, **options) == expected
            raw = theirs.decode_message(message.frame_id, payload, scaling=False, decode_choices=False)
            assert ours.encode_message(message.frame_id, raw, scaling=False, strict=False) == (
                theirs.encode_message(message.frame_id, raw, scaling=False, strict=False)
            )
    control = {s.name: 0 for s in theirs.get_message_by_name("AdsToVehicle_Control").signals}
    cases = [
        {**control, "Unknown": 1},
        {k: v for k, v in control.items() if k != "VelocityCmd"},
        {**control, "VelocityCmd": 1e9},
        {**control, "VelocityCmd": -1e9},
    ]
    for values in cases:
        with pytest.raises(cantools.database.EncodeError) as a:
            theirs.encode_message("AdsToVehicle_Control", values)
        with pytest.raises(bywire.EncodeError) as b:
            ours.encode_message("AdsToVehicle_Control", values)
        assert str(a.value) == str(b.value)
    # A choice the signal does not have.
    with pytest.raises(KeyError) as a:
        theirs.encode_message("AdsToVehicle_Control", {**control, "GearCmd": "NoSuchGear"})
    with pytest.raises(KeyError) as b:
        ours.encode_message("AdsToVehicle_Control", {**control, "GearCmd": "NoSuchGear"})
    assert a.value.args == b.value.args


def test_a_dbc_that_cannot_load_names_its_file_and_line(tmp_path):
    bad = tmp_path / "bad.dbc"
    bad.write_text('VERSION ""\nBO_ 1 M: 8 X\n SG_ A : 0|8@1+ (1,0) [0|0] "" X\nBO_ oops\n')
    with pytest.raises(bywire.ParseError) as e:
        bywire.Database.load(bad, strict=True)
    assert str(e.value).startswith(f"{bad}:4:")
    lenient = bywire.Database.load(bad)
    assert lenient.message_names == ["M"]
    assert lenient.diagnostics and lenient.diagnostics[0].startswith(f"{bad}:4:")
    with pytest.raises(OSError, match="missing.dbc"):
        bywire.Database.load(tmp_path / "missing.dbc")


def test_the_packages_docstring_examples_run():
    import doctest

    results = [doctest.testmod(module, verbose=False) for module in (bywire, bywire.database)]
    assert sum(r.attempted for r in results) > 0
    assert sum(r.failed for r in results) == 0
