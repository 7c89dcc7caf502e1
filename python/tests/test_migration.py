"""Moving from cantools: a cantools script runs unchanged but for its import line and prints
the same; values cross between the two libraries both ways; the errors are the ones cantools
users catch; the package is a product (version, console script, stubs)."""

from __future__ import annotations

import ast
import importlib.metadata
import subprocess
import sys
from pathlib import Path

import cantools
import pytest

import bywire
import bywire.database
from bywire import _native
from conftest import ROOT, TUG_DBC

HERE = Path(__file__).parent
FILES = ROOT / "target" / "cantools-files" / "dbc"


def test_a_cantools_script_prints_the_same_with_bywire_imported_instead(tmp_path):
    script = (HERE / "migration" / "cantools_script.py").read_text()
    ours = tmp_path / "with_bywire.py"
    ours.write_text(script.replace("\nimport cantools\n", "\nimport bywire.cantools as cantools\n", 1))
    args = [str(TUG_DBC), str(FILES / "motohawk.dbc"), str(FILES / "multiplex.dbc")]
    theirs = subprocess.run([sys.executable, str(HERE / "migration" / "cantools_script.py"), *args],
                            capture_output=True, text=True, check=True)
    mine = subprocess.run([sys.executable, str(ours), *args], capture_output=True, text=True, check=True)
    assert len(theirs.stdout.splitlines()) > 100
    assert mine.stdout == theirs.stdout


def test_decoded_values_cross_between_the_libraries_both_ways():
    theirs = cantools.database.load_file(str(TUG_DBC))
    ours = bywire.database.load_file(TUG_DBC)
    payload = bytes.fromhex("0000000000c00300")
    a = theirs.decode_message("VehicleToAds_State", payload)
    b = ours.decode_message("VehicleToAds_State", payload)
    assert list(a) == list(b)  # cantools' order
    assert a == b and b == a
    choice = next(k for k, v in a.items() if hasattr(v, "name"))
    assert a[choice] == b[choice] and b[choice] == a[choice] and b[choice] == str(a[choice])
    # Each library's encoder takes the other's decoded dict.
    assert ours.encode_message("VehicleToAds_State", a) == theirs.encode_message("VehicleToAds_State", b)
    # A NamedSignalValue whose number is not its name's is refused, as cantools does.
    wrong = type(a[choice])(a[choice].value + 1, a[choice].name)
    with pytest.raises(bywire.database.EncodeError, match="Invalid 'NamedSignalValue'"):
        ours.encode_message("VehicleToAds_State", {**a, choice: wrong})


def test_the_errors_are_the_ones_cantools_users_catch(tmp_path):
    with pytest.raises(FileNotFoundError):
        bywire.database.load_file(tmp_path / "missing.dbc")
    bad = tmp_path / "bad.dbc"
    bad.write_text("BO_ 1 M: 8 X\n SG_ A : 0|8@1+ (1,0) [0|0] \"\" X\n SG_ B : 4|8@1+ (1,0) [0|0] \"\" X\n")
    with pytest.raises(bywire.database.Error, match="A and B"):
        bywire.database.load_file(bad)  # strict, as cantools: overlapping signals
    assert len(bywire.database.load_file(bad, strict=False).messages) == 1
    with pytest.raises(bywire.database.UnsupportedDatabaseFormatError):
        bywire.database.load_string("<NotKcd/>")
    db = bywire.database.load_file(TUG_DBC)
    with pytest.raises(KeyError):
        db.get_message_by_name("Nope")
    with pytest.raises(KeyError):
        db.decode_message(0x7FF, b"")
    with pytest.raises(bywire.database.DecodeError, match="Wrong data size"):
        db.decode_message(0x101, b"\x00")
    # Extended identifiers: above 0x7FF or forced, as cantools looks them up.
    assert db.get_message_by_frame_id(0x101).name == "VehicleToAds_State"
    with pytest.raises(KeyError):
        db.get_message_by_frame_id(0x101, force_extended_id=True)


def test_a_changed_database_writes_and_decodes_what_was_changed():
    db = bywire.database.load_file(TUG_DBC)
    message = db.get_message_by_name("VehicleToAds_State")
    message.signals[0].scale = 2
    message.cycle_time = 40
    db.refresh()
    again = bywire.database.load_string(db.as_dbc_string())
    same = again.get_message_by_name("VehicleToAds_State")
    assert same.cycle_time == 40 and same.get_signal_by_name(message.signals[0].name).scale == 2
    assert again.decode_message(0x101, bytes(8)) == db.decode_message(0x101, bytes(8))
    assert bywire.database.load_string(db.as_kcd_string()).get_message_by_name("VehicleToAds_State").length == 8
    assert db.is_similar(again, include_format_specifics=False)


def test_the_package_is_a_product():
    assert bywire.__version__ == importlib.metadata.version("bywire")
    metadata = importlib.metadata.metadata("bywire")
    assert "MIT" in (metadata.get("License-Expression") or metadata.get("License") or "")
    assert bywire.sim.run and bywire.spark and bywire.database.load_file
    entry = [e for e in importlib.metadata.entry_points(group="can.interface") if e.name == "bywire"]
    assert entry and entry[0].load().__name__ == "BywireBus"
    # Every public name of the native module has a stub.
    stubs = ast.parse((Path(bywire.__file__).parent / "_native.pyi").read_text())
    stubbed = {node.name for node in stubs.body if isinstance(node, (ast.ClassDef, ast.FunctionDef))}
    public = {name for name in dir(_native) if not name.startswith("_")}
    assert public <= stubbed, sorted(public - stubbed)
