"""Loading a large AUTOSAR system description: ``bywire.database.load_file`` beside
``cantools.database.load_file`` on the same ARXML file in one run (the best of 3 loads each),
and ``bywire dbc lint`` (the command line's load) beside both. The file is made here: an
AUTOSAR 4 system of FRAMES frames, each a PDU of 8 signals with its own system signal, linear
or text-table compu method and unit (about 10 MB at the default 1,000 frames), which both
read to the same messages and signals.

    python3 python/benchmarks/bench_arxml.py [FRAMES]
"""

from __future__ import annotations

import pathlib
import subprocess
import sys
import tempfile
import time

import cantools

import bywire.database
from common import cli


def system(frames: int) -> str:
    """An AUTOSAR 4 system of ``frames`` CAN frames of 8 signals each."""
    triggerings, can_frames, pdus, signals, system_signals, compu = [], [], [], [], [], []
    for f in range(frames):
        triggerings.append(
            f"<CAN-FRAME-TRIGGERING><SHORT-NAME>T{f}</SHORT-NAME>"
            f'<FRAME-REF DEST="CAN-FRAME">/Frames/F{f}</FRAME-REF>'
            f"<CAN-ADDRESSING-MODE>EXTENDED</CAN-ADDRESSING-MODE><IDENTIFIER>{0x1000 + f}</IDENTIFIER>"
            f"</CAN-FRAME-TRIGGERING>"
        )
        can_frames.append(
            f"<CAN-FRAME><SHORT-NAME>F{f}</SHORT-NAME><DESC><L-2 L=\"EN\">Frame {f}.</L-2></DESC>"
            f"<FRAME-LENGTH>8</FRAME-LENGTH><PDU-TO-FRAME-MAPPINGS><PDU-TO-FRAME-MAPPING>"
            f"<SHORT-NAME>M{f}</SHORT-NAME><PDU-REF DEST=\"I-SIGNAL-I-PDU\">/Pdus/P{f}</PDU-REF>"
            f"<START-POSITION>0</START-POSITION></PDU-TO-FRAME-MAPPING></PDU-TO-FRAME-MAPPINGS></CAN-FRAME>"
        )
        mappings = []
        for s in range(8):
            name = f"S{f}_{s}"
            mappings.append(
                f"<I-SIGNAL-TO-I-PDU-MAPPING><SHORT-NAME>{name}M</SHORT-NAME>"
                f'<I-SIGNAL-REF DEST="I-SIGNAL">/Signals/{name}</I-SIGNAL-REF>'
                f"<PACKING-BYTE-ORDER>{'MOST-SIGNIFICANT-BYTE-FIRST' if s % 2 else 'MOST-SIGNIFICANT-BYTE-LAST'}</PACKING-BYTE-ORDER>"
                f"<START-POSITION>{s * 8 + (7 if s % 2 else 0)}</START-POSITION></I-SIGNAL-TO-I-PDU-MAPPING>"
            )
            signals.append(
                f"<I-SIGNAL><SHORT-NAME>{name}</SHORT-NAME><INIT-VALUE><NUMERICAL-VALUE-SPECIFICATION>"
                f"<VALUE>0</VALUE></NUMERICAL-VALUE-SPECIFICATION></INIT-VALUE><LENGTH>8</LENGTH>"
                f'<NETWORK-REPRESENTATION-PROPS><SW-DATA-DEF-PROPS-VARIANTS><SW-DATA-DEF-PROPS-CONDITIONAL>'
                f'<BASE-TYPE-REF DEST="SW-BASE-TYPE">/Types/{"sint8" if s % 3 == 0 else "uint8"}</BASE-TYPE-REF>'
                f"</SW-DATA-DEF-PROPS-CONDITIONAL></SW-DATA-DEF-PROPS-VARIANTS></NETWORK-REPRESENTATION-PROPS>"
                f'<SYSTEM-SIGNAL-REF DEST="SYSTEM-SIGNAL">/SystemSignals/{name}</SYSTEM-SIGNAL-REF></I-SIGNAL>'
            )
            system_signals.append(
                f"<SYSTEM-SIGNAL><SHORT-NAME>{name}</SHORT-NAME><DESC><L-2 L=\"EN\">Signal {s} of frame {f}.</L-2></DESC>"
                f"<PHYSICAL-PROPS><SW-DATA-DEF-PROPS-VARIANTS><SW-DATA-DEF-PROPS-CONDITIONAL>"
                f'<COMPU-METHOD-REF DEST="COMPU-METHOD">/CompuMethods/{name}</COMPU-METHOD-REF>'
                f'<UNIT-REF DEST="UNIT">/Units/U{s}</UNIT-REF>'
                f"</SW-DATA-DEF-PROPS-CONDITIONAL></SW-DATA-DEF-PROPS-VARIANTS></PHYSICAL-PROPS></SYSTEM-SIGNAL>"
            )
            if s % 4 == 3:
                scales = "".join(
                    f"<COMPU-SCALE><LOWER-LIMIT>{v}</LOWER-LIMIT><UPPER-LIMIT>{v}</UPPER-LIMIT>"
                    f"<COMPU-CONST><VT>State{v}</VT></COMPU-CONST></COMPU-SCALE>"
                    for v in range(4)
                )
                compu.append(
                    f"<COMPU-METHOD><SHORT-NAME>{name}</SHORT-NAME><CATEGORY>TEXTTABLE</CATEGORY>"
                    f"<COMPU-INTERNAL-TO-PHYS><COMPU-SCALES>{scales}</COMPU-SCALES></COMPU-INTERNAL-TO-PHYS></COMPU-METHOD>"
                )
            else:
                compu.append(
                    f"<COMPU-METHOD><SHORT-NAME>{name}</SHORT-NAME><CATEGORY>LINEAR</CATEGORY>"
                    f"<COMPU-INTERNAL-TO-PHYS><COMPU-SCALES><COMPU-SCALE><LOWER-LIMIT>0</LOWER-LIMIT>"
                    f"<UPPER-LIMIT>100</UPPER-LIMIT><COMPU-RATIONAL-COEFFS><COMPU-NUMERATOR><V>{s}</V><V>0.5</V>"
                    f"</COMPU-NUMERATOR><COMPU-DENOMINATOR><V>1</V></COMPU-DENOMINATOR></COMPU-RATIONAL-COEFFS>"
                    f"</COMPU-SCALE></COMPU-SCALES></COMPU-INTERNAL-TO-PHYS></COMPU-METHOD>"
                )
        pdus.append(
            f"<I-SIGNAL-I-PDU><SHORT-NAME>P{f}</SHORT-NAME><LENGTH>8</LENGTH>"
            f"<I-SIGNAL-TO-PDU-MAPPINGS>{''.join(mappings)}</I-SIGNAL-TO-PDU-MAPPINGS></I-SIGNAL-I-PDU>"
        )

    def package(name: str, elements: list[str]) -> str:
        return f"<AR-PACKAGE><SHORT-NAME>{name}</SHORT-NAME><ELEMENTS>\n" + "\n".join(elements) + "\n</ELEMENTS></AR-PACKAGE>"

    cluster = (
        "<CAN-CLUSTER><SHORT-NAME>Bus</SHORT-NAME><CAN-CLUSTER-VARIANTS><CAN-CLUSTER-CONDITIONAL>"
        "<BAUDRATE>500000</BAUDRATE><PHYSICAL-CHANNELS><CAN-PHYSICAL-CHANNEL><SHORT-NAME>Channel</SHORT-NAME>"
        "<FRAME-TRIGGERINGS>\n" + "\n".join(triggerings) + "\n</FRAME-TRIGGERINGS></CAN-PHYSICAL-CHANNEL>"
        "</PHYSICAL-CHANNELS></CAN-CLUSTER-CONDITIONAL></CAN-CLUSTER-VARIANTS></CAN-CLUSTER>"
    )
    units = [f"<UNIT><SHORT-NAME>U{s}</SHORT-NAME><DISPLAY-NAME>unit{s}</DISPLAY-NAME></UNIT>" for s in range(8)]
    types = [
        f"<SW-BASE-TYPE><SHORT-NAME>{n}</SHORT-NAME><BASE-TYPE-SIZE>8</BASE-TYPE-SIZE>"
        f"<BASE-TYPE-ENCODING>{e}</BASE-TYPE-ENCODING></SW-BASE-TYPE>"
        for n, e in (("uint8", "NONE"), ("sint8", "2C"))
    ]
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n<AUTOSAR xmlns="http://autosar.org/schema/r4.0">\n<AR-PACKAGES>\n'
        + "\n".join(
            [
                package("Clusters", [cluster]),
                package("Frames", can_frames),
                package("Pdus", pdus),
                package("Signals", signals),
                package("SystemSignals", system_signals),
                package("CompuMethods", compu),
                package("Units", units),
                package("Types", types),
            ]
        )
        + "\n</AR-PACKAGES>\n</AUTOSAR>\n"
    )


def best(load, runs: int = 3) -> float:
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        load()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    frames = int(sys.argv[1]) if len(sys.argv) > 1 else 1000
    with tempfile.TemporaryDirectory() as folder:
        path = pathlib.Path(folder) / "system.arxml"
        path.write_text(system(frames))
        size = path.stat().st_size / 1e6
        ours = bywire.database.load_file(path)
        theirs = cantools.database.load_file(path)
        assert len(ours.messages) == len(theirs.messages) == frames
        assert sum(len(m.signals) for m in ours.messages) == sum(len(m.signals) for m in theirs.messages)
        probe = bytes(range(8))
        for m in ours.messages[:50]:
            assert dict(m.decode(probe)) == dict(theirs.get_message_by_name(m.name).decode(probe)), m.name
        t_bywire = best(lambda: bywire.database.load_file(path))
        t_cantools = best(lambda: cantools.database.load_file(path))
        command = [cli(), "dbc", "lint", str(path)]
        t_cli = best(lambda: subprocess.run(command, check=True, capture_output=True))
        print(f"{path.name}: {size:.1f} MB, {frames} frames, {frames * 8} signals")
        print(f"  cantools.database.load_file  {t_cantools:7.3f} s")
        print(f"  bywire.database.load_file    {t_bywire:7.3f} s   {t_cantools / t_bywire:5.1f} x")
        print(f"  bywire dbc lint (process)    {t_cli:7.3f} s   {t_cantools / t_cli:5.1f} x")


if __name__ == "__main__":
    main()
