//! `bywire log convert` against the peers of each format: python-can 4.6.1's ASC, BLF and TRC
//! readers and writers, can-utils' `log2asc` and `asc2log`, tshark and text2pcap — frame for
//! frame (identifier, flags, data,
//! channel, direction, time to the format's resolution), classic, extended, remote, CAN FD with
//! BRS/ESI and error frames.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use common::Scratch;

use std::path::{Path, PathBuf};
use std::process::Command;

use bywire_core::Frame;
use bywire_log::LogRecord;

/// One frame of every kind, on two interfaces, at sub-millisecond times.
const FRAMES: &str = "\
(1700000000.123456) can0 123#DEADBEEF
(1700000000.223457) can1 1ABCDEF0#0102
(1700000000.323458) can0 123#R
(1700000000.333459) can0 456#R3
(1700000000.423460) can0 20000080#0000000000000000
(1700000000.523461) can0 123##711223344556677889900AABB
(1700000000.623462) can0 7FF#
(1700000000.723463) can1 1FFFFFFF##6DEADBEEF
(1700000000.823464) can1 000#0001020304050607
";

fn scratch(name: &str) -> Scratch {
    Scratch::new(&format!("logfmt-{name}"))
}

/// The test frames as a candump log and as `bywire log convert` made them into another file.
struct Converted {
    /// The scratch folder holding both.
    dir: Scratch,
    /// The candump log (`in.log`).
    log: PathBuf,
    /// The converted file.
    out: PathBuf,
    /// What the command said.
    said: String,
}

/// The test frames converted into `file` in scratch folder `name`.
fn converted(name: &str, file: &str) -> Converted {
    let dir = scratch(name);
    let (log, out) = (dir.join("in.log"), dir.join(file));
    std::fs::write(&log, FRAMES).unwrap();
    let said = bywire(&[
        "log",
        "convert",
        log.to_str().unwrap(),
        out.to_str().unwrap(),
    ]);
    Converted {
        dir,
        log,
        out,
        said,
    }
}

fn bywire(args: &[&str]) -> String {
    let (code, out, err) = common::bywire(args, "");
    assert_eq!(code, 0, "bywire {args:?}: {err}");
    out
}

/// `bywire log convert INPUT OUTPUT --dbc DBC` and `extra` options: what it said.
fn convert_decoded(input: &Path, output: &Path, dbc: &Path, extra: &[&str]) -> String {
    let mut args = vec![
        "log",
        "convert",
        input.to_str().unwrap(),
        output.to_str().unwrap(),
        "--dbc",
        dbc.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    bywire(&args)
}

fn records(path: &Path) -> Vec<LogRecord> {
    let file = std::fs::File::open(path).unwrap();
    bywire_log::Reader::new(std::io::BufReader::new(file))
        .collect::<Result<_, _>>()
        .unwrap()
}

fn original() -> Vec<LogRecord> {
    bywire_log::Reader::new(FRAMES.as_bytes())
        .collect::<Result<_, _>>()
        .unwrap()
}

fn python(script: &str, args: &[&Path]) -> String {
    let mut command = Command::new("python3");
    command.arg("-c").arg(script);
    python_output(command, args)
}

/// Run `tests/oracles/NAME` (as a file, so it imports the oracles' shared `corpus_dbc`).
fn oracle(name: &str, args: &[&Path]) -> String {
    let mut command = Command::new("python3");
    command.arg(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/oracles")
            .join(name),
    );
    python_output(command, args)
}

fn python_output(mut command: Command, args: &[&Path]) -> String {
    let out = command
        .args(args)
        // ASC dates are local time to python-can: make its local time UTC, as ours.
        .env("TZ", "UTC")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// What python-can's `writer` class (ASCWriter, BLFWriter, TRCWriter) makes of `FRAMES`, as we
/// read it back.
fn written_by_python_can(writer: &str, extension: &str) -> Vec<LogRecord> {
    let dir = scratch(&format!("python-{extension}"));
    let (log, theirs, back) = (
        dir.join("in.log"),
        dir.join(format!("py.{extension}")),
        dir.join("back.log"),
    );
    std::fs::write(&log, FRAMES).unwrap();
    let script = format!(
        "import can, sys\nwith can.{writer}(sys.argv[2]) as w:\n    for m in can.CanutilsLogReader(sys.argv[1]):\n        w.on_message_received(m)\n"
    );
    python(&script, &[&log, &theirs]);
    bywire(&[
        "log",
        "convert",
        theirs.to_str().unwrap(),
        back.to_str().unwrap(),
    ]);
    records(&back)
}

/// python-can compares two logs message by message (its candump reader on one side, its ASC,
/// MF4 or BLF reader, as the third argument says, on the other).
const COMPARE: &str = r#"
import can, sys
if sys.argv[3] == "asc":
    ours = list(can.ASCReader(sys.argv[1], relative_timestamp=False))
elif sys.argv[3] == "mf4":
    ours = list(can.MF4Reader(sys.argv[1]))
else:
    ours = list(can.BLFReader(sys.argv[1]))
theirs = list(can.CanutilsLogReader(sys.argv[2]))
assert len(ours) == len(theirs), (len(ours), len(theirs))
for a, b in zip(ours, theirs):
    assert a.is_error_frame == b.is_error_frame, (a, b)
    # (An error frame's identifier and its flags mean nothing in either format.)
    fields = [] if a.is_error_frame else ["arbitration_id", "is_extended_id", "is_remote_frame",
              "is_fd", "bitrate_switch", "error_state_indicator"]
    for f in fields:
        assert getattr(a, f) == getattr(b, f), (f, a, b)
    if not a.is_error_frame:
        assert a.dlc == b.dlc and bytes(a.data) == bytes(b.data), (a, b)
        assert a.is_rx, a
    assert abs(a.timestamp - b.timestamp) < 1e-6, (a.timestamp, b.timestamp)
    # (python-can's candump reader gives error frames no channel.)
    assert b.channel is None or a.channel == int(b.channel[-1]), (a.channel, b.channel)
print("same", len(ours))
"#;

#[test]
fn python_can_reads_our_asc_frame_for_frame() {
    let Converted {
        dir: _dir,
        log,
        out: asc,
        said,
    } = converted("ours", "out.asc");
    assert_eq!(
        said.trim(),
        format!("9 frames written to {}", asc.display())
    );
    assert_eq!(
        python(COMPARE, &[&asc, &log, Path::new("asc")]).trim(),
        "same 9"
    );
}

#[test]
fn we_read_python_cans_asc_frame_for_frame() {
    let (got, wanted) = (written_by_python_can("ASCWriter", "asc"), original());
    assert_eq!(got.len(), wanted.len());
    for (g, w) in got.iter().zip(&wanted) {
        assert_eq!(g.frame, w.frame);
        assert_eq!(g.interface, w.interface);
        // python-can dates its trigger block to the millisecond and counts from the first
        // frame's exact time: what it wrote reads back within a millisecond.
        let drift = g.timestamp.as_nanos().abs_diff(w.timestamp.as_nanos());
        assert!(drift < 1_000_000, "{drift} ns: {g:?} {w:?}");
    }
    // And the times between frames to the microsecond.
    let first = (got[0].timestamp.as_nanos(), wanted[0].timestamp.as_nanos());
    for (g, w) in got.iter().zip(&wanted) {
        let (a, b) = (
            g.timestamp.as_nanos() - first.0,
            w.timestamp.as_nanos() - first.1,
        );
        assert!(a.abs_diff(b) < 1_000, "{a} vs {b}");
    }
}

/// can-utils dates its files to the second (and `asc2log` cannot read the date back on this
/// machine: it falls back to the current time), so times are compared from the first frame.
fn same_frames_and_spacing(got: &[LogRecord], wanted: &[LogRecord]) {
    assert_eq!(got.len(), wanted.len());
    let first = (got[0].timestamp.as_nanos(), wanted[0].timestamp.as_nanos());
    for (g, w) in got.iter().zip(wanted) {
        assert_eq!(g.frame, w.frame, "{g:?} {w:?}");
        assert_eq!(g.interface, w.interface);
        let (a, b) = (
            g.timestamp.as_nanos() - first.0,
            w.timestamp.as_nanos() - first.1,
        );
        assert!(a.abs_diff(b) < 1_000, "{a} vs {b}");
    }
}

#[test]
fn can_utils_log2asc_and_asc2log_agree_with_us() {
    let dir = scratch("can-utils");
    let (log, theirs, back) = (
        dir.join("in.log"),
        dir.join("log2asc.asc"),
        dir.join("back.log"),
    );
    std::fs::write(&log, FRAMES).unwrap();
    let out = Command::new("log2asc")
        .args([
            "-I",
            log.to_str().unwrap(),
            "-O",
            theirs.to_str().unwrap(),
            "can0",
            "can1",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    bywire(&[
        "log",
        "convert",
        theirs.to_str().unwrap(),
        back.to_str().unwrap(),
    ]);
    same_frames_and_spacing(&records(&back), &original());
    // The other way: asc2log reads what we write.
    let (ours, theirs_back) = (dir.join("ours.asc"), dir.join("asc2log.log"));
    bywire(&[
        "log",
        "convert",
        log.to_str().unwrap(),
        ours.to_str().unwrap(),
    ]);
    let out = Command::new("asc2log")
        .args([
            "-I",
            ours.to_str().unwrap(),
            "-O",
            theirs_back.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    same_frames_and_spacing(&records(&theirs_back), &original());
}

#[test]
fn log_cat_and_stats_read_asc_and_bad_lines_name_their_place() {
    let Converted {
        dir, log, out: asc, ..
    } = converted("cat", "in.asc");
    // `log cat` of the ASC gives the candump lines back (the format is sniffed).
    assert_eq!(bywire(&["log", "cat", asc.to_str().unwrap()]), FRAMES);
    let stats = bywire(&["log", "stats", asc.to_str().unwrap()]);
    assert!(stats.contains("9"), "{stats}");
    let broken = dir.join("broken.asc");
    let mut text = std::fs::read_to_string(&asc).unwrap();
    text = text.replace("d 4 DE AD BE EF", "d 4 DE AD");
    std::fs::write(&broken, text).unwrap();
    let out_path = dir.join("never.log");
    let (code, _, err) = common::bywire(
        &[
            "log",
            "convert",
            broken.to_str().unwrap(),
            out_path.to_str().unwrap(),
        ],
        "",
    );
    assert_eq!(code, 1);
    assert!(
        err.contains("broken.asc: line 7, column")
            && err.contains("4 data bytes expected, 2 found"),
        "{err}"
    );
    assert!(!out_path.exists(), "nothing half-written");
    let (code, _, err) = common::bywire(
        &[
            "log",
            "convert",
            log.to_str().unwrap(),
            dir.join("x.mdf").to_str().unwrap(),
        ],
        "",
    );
    assert_eq!(code, 1);
    assert!(err.contains("give --format"), "{err}");
}

#[test]
fn python_can_reads_our_trc_frame_for_frame() {
    let Converted {
        dir: _dir,
        log,
        out: trc,
        ..
    } = converted("trc-ours", "out.trc");
    let compared = python(
        r#"
import can, sys
ours = list(can.TRCReader(sys.argv[1]))
# python-can reads no error frames from TRC (we write them as ER lines).
theirs = [m for m in can.CanutilsLogReader(sys.argv[2]) if not m.is_error_frame]
assert len(ours) == len(theirs), (len(ours), len(theirs))
for a, b in zip(ours, theirs):
    for f in ["arbitration_id", "is_extended_id", "is_remote_frame", "is_fd", "bitrate_switch",
              "error_state_indicator"]:
        assert getattr(a, f) == getattr(b, f), (f, a, b)
    assert bytes(a.data) == bytes(b.data), (a, b)
    # (python-can's TRC reader gives an FD frame's DLC code, not its length, as dlc.)
    assert a.is_fd or a.dlc == b.dlc, (a, b)
    assert a.is_rx, a
    assert abs(a.timestamp - b.timestamp) < 1e-6, (a.timestamp, b.timestamp)
    # (and the bus number, from 1, as its channel)
    assert a.channel == int(b.channel[-1]) + 1, (a.channel, b.channel)
print("same", len(ours))
"#,
        &[&trc, &log],
    );
    assert_eq!(compared.trim(), "same 8");
}

#[test]
fn we_read_python_cans_trc_frame_for_frame() {
    // python-can's TRC writer takes classic data frames only (it leaves out the others).
    let wanted: Vec<LogRecord> = original()
        .into_iter()
        .filter(|r| !r.frame.is_fd() && !r.frame.is_remote() && !r.frame.is_error())
        .collect();
    let got = written_by_python_can("TRCWriter", "trc");
    assert_eq!(got.len(), wanted.len());
    for (g, w) in got.iter().zip(&wanted) {
        assert_eq!(g.frame, w.frame);
        assert_eq!(g.interface, w.interface);
        // Its start time is a float of days: the microsecond survives.
        let drift = g.timestamp.as_nanos().abs_diff(w.timestamp.as_nanos());
        assert!(drift <= 1_000, "{drift} ns: {g:?} {w:?}");
    }
}

/// tshark's fields for every frame of a capture: time, interface, identifier, flags, length,
/// BRS/ESI and data.
fn tshark_fields(capture: &Path) -> Vec<Vec<String>> {
    let out = Command::new("tshark")
        .args(["--disable-protocol", "autosar-nm", "-r"])
        .arg(capture)
        .args(["-T", "fields", "-E", "separator=|"])
        .args([
            "-e",
            "frame.time_epoch",
            "-e",
            "frame.interface_name",
            "-e",
            "can.id",
            "-e",
            "can.flags.xtd",
            "-e",
            "can.flags.rtr",
            "-e",
            "can.flags.err",
            "-e",
            "can.len",
            "-e",
            "canfd.flags.brs",
            "-e",
            "canfd.flags.esi",
            "-e",
            "data.data",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| l.split('|').map(str::to_string).collect())
        .collect()
}

#[test]
fn tshark_reads_our_pcapng_frame_for_frame() {
    let Converted {
        dir: _dir,
        out: capture,
        ..
    } = converted("pcapng-ours", "out.pcapng");
    let rows = tshark_fields(&capture);
    let wanted = original();
    assert_eq!(rows.len(), wanted.len());
    for (row, w) in rows.iter().zip(&wanted) {
        let nanos = w.timestamp.as_nanos();
        assert_eq!(
            row[0],
            format!("{}.{:09}", nanos / 1_000_000_000, nanos % 1_000_000_000)
        );
        assert_eq!(row[1], w.interface);
        let flag = |on: bool| if on { "1" } else { "0" };
        if w.frame.is_error() {
            assert_eq!(row[5], "1", "{row:?}");
            continue;
        }
        let id = w.frame.id().unwrap();
        assert_eq!(row[2], id.as_raw().to_string(), "{row:?}");
        assert_eq!(row[3], flag(id.is_extended()), "{row:?}");
        // (a remote frame's length is the DLC it requests)
        let length = if w.frame.is_remote() {
            usize::from(w.frame.dlc().as_raw())
        } else {
            w.frame.data().len()
        };
        assert_eq!(row[6], length.to_string(), "{row:?}");
        if let bywire_core::Frame::Fd(fd) = &w.frame {
            assert_eq!(
                (row[7].as_str(), row[8].as_str()),
                (flag(fd.brs()), flag(fd.esi()))
            );
        } else {
            assert_eq!(row[4], flag(w.frame.is_remote()), "{row:?}");
        }
        if !w.frame.is_remote() {
            let hex: String = w.frame.data().iter().map(|b| format!("{b:02x}")).collect();
            assert_eq!(row[9], hex, "{row:?}");
        }
    }
}

#[test]
fn we_read_a_capture_text2pcap_writes() {
    let dir = scratch("pcapng-theirs");
    let (hex, capture, back) = (
        dir.join("hex.txt"),
        dir.join("t2p.pcapng"),
        dir.join("back.log"),
    );
    // SocketCAN packets as the link type defines them (identifier word big-endian), typed out
    // independently of our writer: 123#DEADBEEF, 1ABCDEF0#0102 (EFF), 456#R3 (RTR), and an FD
    // frame 7FF##3 with BRS and ESI and 12 bytes (canfd_frame, 72 bytes).
    let fd_data = "11 22 33 44 55 66 77 88 99 00 aa bb";
    let fd_pad = vec!["00"; 52].join(" ");
    std::fs::write(
        &hex,
        format!(
            "0000  00 00 01 23 04 00 00 00 de ad be ef 00 00 00 00\n\n\
             0000  9a bc de f0 02 00 00 00 01 02 00 00 00 00 00 00\n\n\
             0000  40 00 04 56 03 00 00 00 00 00 00 00 00 00 00 00\n\n\
             0000  00 00 07 ff 0c 07 00 00 {fd_data} {fd_pad}\n"
        ),
    )
    .unwrap();
    let out = Command::new("text2pcap")
        .args(["-q", "-l", "227", "-N", "vcan5"])
        .args([&hex, &capture])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    bywire(&[
        "log",
        "convert",
        capture.to_str().unwrap(),
        back.to_str().unwrap(),
    ]);
    let got: Vec<String> = records(&back)
        .iter()
        .map(|r| format!("{} {}", r.interface, r.frame))
        .collect();
    let fd = bywire_core::Frame::fd(
        bywire_core::Id::standard(0x7FF).unwrap(),
        &[
            0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77, 0x88, 0x99, 0, 0xAA, 0xBB,
        ],
        true,
        true,
    )
    .unwrap();
    assert_eq!(
        got,
        [
            "vcan5 123#DEADBEEF".to_string(),
            "vcan5 1ABCDEF0#0102".to_string(),
            "vcan5 456#R3".to_string(),
            format!("vcan5 {fd}"),
        ]
    );
}

#[test]
fn python_can_and_tshark_read_our_blf_frame_for_frame() {
    let Converted {
        dir: _dir,
        log,
        out: blf,
        ..
    } = converted("blf-ours", "out.blf");
    assert_eq!(
        python(COMPARE, &[&blf, &log, Path::new("blf")]).trim(),
        "same 9"
    );
    // Wireshark reads BLF too (its 4.0 reader passes over error objects): the same frames,
    // times to the nanosecond, channels as CAN-1 and CAN-2.
    let rows = tshark_fields(&blf);
    let wanted: Vec<LogRecord> = original()
        .into_iter()
        .filter(|r| !r.frame.is_error())
        .collect();
    assert_eq!(rows.len(), wanted.len(), "{rows:?}");
    for (row, w) in rows.iter().zip(&wanted) {
        let nanos = w.timestamp.as_nanos();
        assert_eq!(
            row[0],
            format!("{}.{:09}", nanos / 1_000_000_000, nanos % 1_000_000_000)
        );
        let channel: u32 = w.interface.trim_start_matches("can").parse().unwrap();
        assert_eq!(row[1], format!("CAN-{}", channel + 1));
        if let Some(id) = w.frame.id() {
            assert_eq!(row[2], id.as_raw().to_string(), "{row:?}");
        }
        if !w.frame.is_remote() && !w.frame.is_error() {
            let hex: String = w.frame.data().iter().map(|b| format!("{b:02x}")).collect();
            assert_eq!(row[9], hex, "{row:?}");
        }
    }
}

#[test]
fn we_read_python_cans_blf_frame_for_frame() {
    let (got, wanted) = (written_by_python_can("BLFWriter", "blf"), original());
    assert_eq!(got.len(), wanted.len());
    for (g, w) in got.iter().zip(&wanted) {
        if w.frame.is_error() {
            // BLF's error object keeps no SocketCAN class: a bus error.
            assert!(g.frame.is_error(), "{g:?}");
        } else {
            assert_eq!(g.frame, w.frame);
        }
        // (python-can gives error frames no channel: channel 1.)
        if !w.frame.is_error() {
            assert_eq!(g.interface, w.interface);
        }
        // python-can counts from a start it truncated to the millisecond, in nanoseconds.
        let drift = g.timestamp.as_nanos().abs_diff(w.timestamp.as_nanos());
        assert!(drift <= 1_000, "{drift} ns: {g:?} {w:?}");
    }
}

#[test]
fn python_can_reads_our_mf4_frame_for_frame() {
    let Converted {
        dir: _dir,
        log,
        out: mf4,
        ..
    } = converted("mf4-ours", "out.mf4");
    // (python-can's MF4 reader is asammdf's: both read it.)
    assert_eq!(
        python(COMPARE, &[&mf4, &log, Path::new("mf4")]).trim(),
        "same 9"
    );
}

#[test]
fn we_read_python_cans_mf4_frame_for_frame() {
    // python-can's default: data blocks zipped and transposed (asammdf writes them).
    let (got, wanted) = (written_by_python_can("MF4Writer", "mf4"), original());
    assert_eq!(got.len(), wanted.len());
    for (g, w) in got.iter().zip(&wanted) {
        match (&g.frame, &w.frame) {
            // python-can's candump reader keeps no SocketCAN error class: it writes ID 0, and
            // we read back an error frame with no class.
            (Frame::Error(e), Frame::Error(_)) => assert_eq!(e.class_bits(), 0, "{g:?}"),
            (got, wanted) => assert_eq!(got, wanted),
        }
        assert_eq!(g.interface, w.interface);
        // python-can counts in seconds (a double) from the time it opened the file.
        let drift = g.timestamp.as_nanos().abs_diff(w.timestamp.as_nanos());
        assert!(drift <= 2_000, "{drift} ns: {g:?} {w:?}");
    }
}

/// asammdf's bus logging extraction decodes the frames of our MF4 with a DBC as `bywire decode`
/// decodes them, signal for signal.
#[test]
fn asammdf_decodes_our_mf4_as_bywire_decode_does() {
    let dir = scratch("mf4-asammdf");
    let dbc = common::corpus("cantools/tests__files__dbc__motohawk.dbc");
    let (log, mf4) = (dir.join("in.log"), dir.join("out.mf4"));
    // Bytes from a small generator: every signal takes many values.
    let mut state = 12345u32;
    let text: String = (0..300u32)
        .map(|i| {
            let data: String = (0..8)
                .map(|_| {
                    state = state.wrapping_mul(1_103_515_245).wrapping_add(12_345);
                    format!("{:02X}", state >> 24)
                })
                .collect();
            format!("(1700000000.{:06}) can0 1F0#{data}\n", i * 1000)
        })
        .collect();
    std::fs::write(&log, &text).unwrap();
    bywire(&[
        "log",
        "convert",
        log.to_str().unwrap(),
        mf4.to_str().unwrap(),
    ]);
    let ours = bywire(&["decode", &dbc, "--json", "-I", mf4.to_str().unwrap()]);
    let ours_path = dir.join("ours.jsonl");
    std::fs::write(&ours_path, ours).unwrap();
    let compared = python(
        r#"
import json, sys
from asammdf import MDF
mdf = MDF(sys.argv[1])
decoded = mdf.extract_bus_logging({"CAN": [(sys.argv[2], 0)]})
df = decoded.to_dataframe(raw=True)
ours = [json.loads(line) for line in open(sys.argv[3])]
assert len(df) == len(ours) == 300, (len(df), len(ours))
names = sorted(ours[0]["signals"])
assert sorted(df.columns) == names, (df.columns, names)
for row, mine in zip(df.itertuples(index=False), ours):
    for name in names:
        theirs, value = getattr(row, name), mine["signals"][name]
        if isinstance(value, float) and name != "Enable":
            # asammdf gives raw values here: scale them as the DBC says.
            continue
        assert theirs == value, (name, theirs, value)
scaled = decoded.to_dataframe()
for row, mine in zip(scaled.itertuples(index=False), ours):
    for name in names:
        theirs, value = getattr(row, name), mine["signals"][name]
        if isinstance(theirs, bytes):
            continue
        assert abs(theirs - value) < 1e-9, (name, theirs, value)
print("same", len(ours))
"#,
        &[&mf4, Path::new(&dbc), &ours_path],
    );
    assert_eq!(compared.trim(), "same 300");
}

/// `log convert --dbc` into MF4: beside the frames, one channel group a message, which
/// asammdf reads as cantools decodes the same frames (values, value names, units), while the
/// frames still read back whole.
#[test]
fn decoded_mf4_channel_groups_read_by_asammdf_as_cantools_decodes() {
    let dir = scratch("mf4-decoded");
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/data");
    let (log, dbc) = (root.join("candump.log"), root.join("reference-tug.dbc"));
    let mf4 = dir.join("decoded.mf4");
    let said = convert_decoded(&log, &mf4, &dbc, &[]);
    assert!(said.contains("6200 frames"), "{said}");
    let stats = bywire(&["log", "stats", mf4.to_str().unwrap()]);
    assert!(stats.starts_with("6200 frames"), "{stats}");
    let compared = python(
        r#"
import sys, warnings
warnings.simplefilter("ignore")
import cantools, can
from asammdf import MDF
mdf = MDF(sys.argv[1])
db = cantools.database.load_file(sys.argv[3])
expected = {}
for msg in can.CanutilsLogReader(sys.argv[2]):
    try:
        m = db.get_message_by_frame_id(msg.arbitration_id)
    except KeyError:
        continue
    expected.setdefault(m.name, []).append(m.decode(msg.data))
seen = 0
for index, group in enumerate(mdf.groups):
    name = group.channel_group.acq_name
    if name not in expected:
        continue
    message = db.get_message_by_name(name)
    df = mdf.get_group(index)
    assert len(df) == len(expected[name]), (name, len(df), len(expected[name]))
    for channel in group.channels[1:]:
        signal = message.get_signal_by_name(channel.name)
        assert (channel.unit or None) == signal.unit, (channel.name, channel.unit, signal.unit)
    for row, want in zip(df.itertuples(index=False), expected[name]):
        for key, value in want.items():
            got = getattr(row, key)
            if isinstance(got, bytes):
                assert got.decode() == str(value), (name, key, got, value)
            else:
                assert abs(got - float(value)) < 1e-9, (name, key, got, value)
    seen += 1
assert seen == len(expected), (seen, sorted(expected))
print("same", seen)
"#,
        &[&mf4, &log, &dbc],
    );
    assert!(compared.trim().starts_with("same "), "{compared}");
}

/// The commands that read logs take any format: `decode -I` of a BLF gives what `decode` of the
/// candump text gives, and `play -I` of an ASC replays the same lines.
#[test]
fn decode_and_play_read_every_format() {
    let dir = scratch("any-format");
    let dbc = common::corpus("cantools/tests__files__dbc__motohawk.dbc");
    let log = dir.join("in.log");
    let text: String = (0..20u32)
        .map(|i| {
            format!(
                "(1700000000.{:06}) can0 1F0#{:02X}{:02X}000000000000\n",
                i * 1000,
                i * 7 % 256,
                i
            )
        })
        .collect();
    std::fs::write(&log, &text).unwrap();
    let (code, from_text, err) = common::bywire(&["decode", &dbc, "--single-line"], &text);
    assert_eq!(code, 0, "{err}");
    for extension in ["blf", "asc", "trc", "pcapng", "mf4"] {
        let converted = dir.join(format!("in.{extension}"));
        bywire(&[
            "log",
            "convert",
            log.to_str().unwrap(),
            converted.to_str().unwrap(),
        ]);
        let from_file = bywire(&[
            "decode",
            &dbc,
            "--single-line",
            "-I",
            converted.to_str().unwrap(),
        ]);
        assert_eq!(from_file, from_text, "{extension}");
        let played = bywire(&[
            "play",
            "-I",
            converted.to_str().unwrap(),
            "stdout=can0",
            "--speed",
            "1000",
        ]);
        // (with the direction the format keeps, as candump -x shows it)
        let without_direction: String = played
            .lines()
            .map(|l| format!("{}\n", l.trim_end_matches(" R")))
            .collect();
        assert_eq!(without_direction, text, "{extension}");
    }
}

/// `log convert` merges its inputs by time, keeps and renames channels, and cuts a time range.
#[test]
fn convert_merges_inputs_and_selects_channels_and_time() {
    let dir = scratch("merge");
    let (a, b, merged) = (dir.join("a.log"), dir.join("b.asc"), dir.join("merged.log"));
    std::fs::write(
        &a,
        "(100.000000) can0 100#01\n(102.000000) can0 100#03\n(104.000000) can2 200#05\n",
    )
    .unwrap();
    let other = dir.join("b.log");
    std::fs::write(
        &other,
        "(101.000000) can1 101#02\n(103.000000) can1 101#04\n",
    )
    .unwrap();
    bywire(&[
        "log",
        "convert",
        other.to_str().unwrap(),
        b.to_str().unwrap(),
    ]);
    let said = bywire(&[
        "log",
        "convert",
        a.to_str().unwrap(),
        b.to_str().unwrap(),
        merged.to_str().unwrap(),
        "--channel",
        "can0",
        "--channel",
        "can1=vcan9",
        "--from",
        "1",
        "--to",
        "3",
    ]);
    assert!(
        said.contains("3 frames written") && said.contains("2 left out"),
        "{said}"
    );
    assert_eq!(
        std::fs::read_to_string(&merged).unwrap(),
        "(0000000101.000000) vcan9 101#02\n(0000000102.000000) can0 100#03\n(0000000103.000000) vcan9 101#04\n"
    );
    let (code, _, err) = common::bywire(&["log", "convert", a.to_str().unwrap(), "-", "x.log"], "");
    assert_eq!(code, 1);
    assert!(err.contains("can only be the one input"), "{err}");
    let (code, _, err) = common::bywire(
        &[
            "log",
            "convert",
            a.to_str().unwrap(),
            "x.log",
            "--from",
            "5",
            "--to",
            "1",
        ],
        "",
    );
    assert_eq!(code, 1);
    assert!(err.contains("--to 1 is before --from 5"), "{err}");
}

/// MCAP as ROS 2 records ros2_socketcan: the `mcap` and `mcap-ros2-support` packages decode
/// our `can_msgs/msg/Frame` messages against our schema, and we read the bag they write.
#[test]
fn mcap_ros2_reads_our_frames_and_we_read_theirs() {
    let Converted {
        dir,
        out: ours,
        said,
        ..
    } = converted("mcap", "ours.mcap");
    let (theirs, back) = (dir.join("theirs.mcap"), dir.join("back.log"));
    assert!(
        said.contains("7 frames written") && said.contains("2 CAN FD frames left out"),
        "{said}"
    );
    let read = python(
        r#"
import sys
from mcap_ros2.reader import read_ros2_messages
for m in read_ros2_messages(sys.argv[1]):
    f = m.ros_msg
    print(m.channel.topic, m.schema.name, f.header.stamp.sec, f.header.stamp.nanosec, f.header.frame_id,
          f.id, int(f.is_rtr), int(f.is_extended), int(f.is_error), f.dlc, bytes(f.data).hex(), m.log_time_ns)
"#,
        &[&ours],
    );
    let wanted: Vec<LogRecord> = original()
        .into_iter()
        .filter(|r| !r.frame.is_fd())
        .collect();
    let lines: Vec<&str> = read.lines().collect();
    assert_eq!(lines.len(), wanted.len(), "{read}");
    for (line, w) in lines.iter().zip(&wanted) {
        let f: Vec<&str> = line.split(' ').collect();
        let nanos = w.timestamp.as_nanos();
        assert_eq!(
            f[..3],
            [
                "/from_can_bus",
                "can_msgs/msg/Frame",
                &(nanos / 1_000_000_000).to_string()
            ]
        );
        assert_eq!(f[3], (nanos % 1_000_000_000).to_string());
        assert_eq!(f[4], w.interface);
        assert_eq!(f[11], nanos.to_string(), "log time");
        if w.frame.is_error() {
            assert_eq!(f[8], "1");
            continue;
        }
        let id = w.frame.id().unwrap();
        assert_eq!(f[5], id.as_raw().to_string(), "{line}");
        assert_eq!(
            (f[6], f[7]),
            (
                if w.frame.is_remote() { "1" } else { "0" },
                if id.is_extended() { "1" } else { "0" }
            )
        );
        assert_eq!(f[9], w.frame.dlc().as_raw().to_string(), "{line}");
        let mut data = [0u8; 8];
        for (slot, b) in data.iter_mut().zip(w.frame.data()) {
            *slot = *b;
        }
        assert_eq!(
            f[10],
            data.iter().map(|b| format!("{b:02x}")).collect::<String>(),
            "{line}"
        );
    }
    // They write a bag of frames with the same schema; we read it.
    let schema = dir.join("schema.msg");
    std::fs::write(&schema, "std_msgs/Header header\nuint32 id\nbool is_rtr\nbool is_extended\nbool is_error\nuint8 dlc\nuint8[8] data\n================================================================================\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n================================================================================\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n").unwrap();
    python(
        r#"
import sys
from mcap.writer import CompressionType
from mcap_ros2.writer import Writer
schema_text = open(sys.argv[2]).read()
with open(sys.argv[1], "wb") as f:
    # (uncompressed: this build has no zstd or lz4, whose crates build C code)
    w = Writer(f, compression=CompressionType.NONE)
    schema = w.register_msgdef("can_msgs/msg/Frame", schema_text)
    for i, (can_id, ext, rtr, data) in enumerate([(0x123, False, False, b"\xde\xad\xbe\xef"), (0x1abcdef0, True, False, b"\x01\x02"), (0x456, False, True, b"")]):
        t = 1700000000_000000000 + i * 1_000_000
        w.write_message("/from_can_bus", schema, {
            "header": {"stamp": {"sec": t // 10**9, "nanosec": t % 10**9}, "frame_id": "can1"},
            "id": can_id, "is_rtr": rtr, "is_extended": ext, "is_error": False,
            "dlc": 3 if rtr else len(data), "data": list(data.ljust(8, b"\0"))}, log_time=t, publish_time=t)
    w.finish()
"#,
        &[&theirs, &schema],
    );
    bywire(&[
        "log",
        "convert",
        theirs.to_str().unwrap(),
        back.to_str().unwrap(),
    ]);
    assert_eq!(
        std::fs::read_to_string(&back).unwrap(),
        "(1700000000.000000) can1 123#DEADBEEF\n(1700000000.001000) can1 1ABCDEF0#0102\n(1700000000.002000) can1 456#R3\n"
    );
}

#[test]
fn pyarrow_polars_and_duckdb_read_our_parquet_and_we_read_theirs() {
    let Converted {
        dir,
        out: ours,
        said,
        ..
    } = converted("parquet", "ours.parquet");
    let theirs = dir.join("theirs.parquet");
    assert!(said.starts_with("9 frames written"), "{said}");
    let read = python(
        r#"
import sys
import duckdb
import polars
import pyarrow.parquet as pq
t = pq.read_table(sys.argv[1])
print(";".join(f"{f.name}:{f.type}" for f in t.schema))
assert polars.read_parquet(sys.argv[1]).height == t.num_rows
# DuckDB reads every row as pyarrow does, times to the nanosecond.
columns = t.column_names[1:]
ducks = duckdb.execute(f"SELECT epoch_ns(ts), {', '.join(columns)} FROM read_parquet(?)", [sys.argv[1]]).fetchall()
arrows = zip(t.column("ts").cast("int64").to_pylist(), *(t.column(c).to_pylist() for c in columns))
assert ducks == list(arrows), ducks
for r in t.to_pylist():
    ts = int(r["ts"].timestamp()) * 10**9 + r["ts"].microsecond * 1000
    flags = "".join("1" if r[k] else "0" for k in ("extended", "remote", "error", "fd", "brs", "esi"))
    print(ts, r["channel"], r["id"], flags, r["dir"], r["dlc"], r["data"].hex())
"#,
        &[&ours],
    );
    let mut lines = read.lines();
    assert_eq!(
        lines.next().unwrap(),
        "ts:timestamp[ns, tz=UTC];channel:dictionary<values=string, indices=int32, ordered=0>;id:uint32;extended:bool;remote:bool;error:bool;fd:bool;brs:bool;esi:bool;dir:dictionary<values=string, indices=int32, ordered=0>;dlc:uint8;data:binary"
    );
    let rows: Vec<&str> = lines.collect();
    let wanted = original();
    assert_eq!(rows.len(), wanted.len(), "{read}");
    for (row, w) in rows.iter().zip(&wanted) {
        let f: Vec<&str> = row.split(' ').collect();
        let frame = &w.frame;
        let (id, extended) = match frame.id() {
            Some(id) => (id.as_raw(), id.is_extended()),
            None => (frame.socketcan_id() & 0x1FFF_FFFF, false),
        };
        let brs_esi = match frame {
            bywire_core::Frame::Fd(f) => (f.brs(), f.esi()),
            _ => (false, false),
        };
        let flags: String = [
            extended,
            frame.is_remote(),
            frame.is_error(),
            frame.is_fd(),
            brs_esi.0,
            brs_esi.1,
        ]
        .iter()
        .map(|b| if *b { '1' } else { '0' })
        .collect();
        let data: String = if frame.is_remote() {
            String::new()
        } else {
            frame.data().iter().map(|b| format!("{b:02x}")).collect()
        };
        assert_eq!(
            f,
            [
                w.timestamp.as_nanos().to_string().as_str(),
                w.interface.as_str(),
                &id.to_string(),
                &flags,
                "None",
                &frame.dlc().as_raw().to_string(),
                &data
            ],
            "{row}"
        );
    }
    // A table pyarrow writes in its own way (microseconds, plain strings, directions, no DLC
    // column) reads back as the frames it holds.
    python(
        r#"
import sys
import pyarrow as pa, pyarrow.parquet as pq
t = pa.table({
    "ts": pa.array([1700000000123456, 1700000000223457, 1700000000323458], pa.timestamp("us", tz="UTC")),
    "channel": ["can0", "can1", "can0"],
    "id": pa.array([0x123, 0x1ABCDEF0, 0x7FF], pa.uint32()),
    "extended": [False, True, False],
    "fd": [False, False, True],
    "brs": [False, False, True],
    "dir": ["rx", "tx", None],
    "data": [b"\xde\xad\xbe\xef", b"\x01\x02", bytes(range(12))],
})
pq.write_table(t, sys.argv[1], compression="zstd")
"#,
        &[&theirs],
    );
    let cat = bywire(&["log", "cat", theirs.to_str().unwrap()]);
    assert_eq!(
        cat,
        "(1700000000.123456) can0 123#DEADBEEF\n(1700000000.223457) can1 1ABCDEF0#0102\n(1700000000.323458) can0 7FF##5000102030405060708090A0B\n"
    );
    let directions: Vec<Option<char>> = bywire_log::format::Format::Parquet
        .file_reader(std::fs::File::open(&theirs).unwrap())
        .map(|r| r.unwrap().direction)
        .collect();
    assert_eq!(directions, [Some('R'), Some('T'), None]);
    // Parquet needs a file: standard input is refused, saying why.
    let (code, _, err) = common::bywire(
        &["log", "cat"],
        &String::from_utf8_lossy(&std::fs::read(&ours).unwrap()),
    );
    assert_ne!(code, 0);
    assert!(
        err.contains("Parquet file can only be read from a file"),
        "{err}"
    );
}

#[test]
fn decoded_parquet_agrees_with_cantools_through_pyarrow_and_polars() {
    // Real DBCs: a vehicle's powertrain (331 messages, FD), VW's (choices in UTF-8, a
    // multiplexed VIN), cantools' multiplexed choices, floats and an ABS unit.
    for (file, rounds) in [
        ("opendbc/opendbc__dbc__ford_lincoln_base_pt.dbc", 8),
        ("opendbc/opendbc__dbc__vw_mlb.dbc", 12),
        ("cantools/tests__files__dbc__multiplex_choices.dbc", 60),
        ("cantools/tests__files__dbc__floating_point.dbc", 40),
        ("cantools/tests__files__dbc__abs.dbc", 20),
    ] {
        let dbc = PathBuf::from(common::corpus(file));
        let dir = scratch(&format!("decoded-{}", file.replace('/', "_")));
        let (log, dataset) = (dir.join("traffic.log"), dir.join("dataset"));
        let traffic = oracle(
            "dbc_traffic.py",
            &[&dbc, Path::new(&rounds.to_string()), Path::new("7")],
        );
        std::fs::write(&log, traffic).unwrap();
        let said = convert_decoded(&log, &dataset, &dbc, &[]);
        assert!(said.contains("rows in"), "{said}");
        let agreed = oracle("parquet_decoded.py", &[&dbc, &log, &dataset]);
        assert!(agreed.contains("values agree"), "{file}: {agreed}");
        // Written again into the same, now full, directory: refused, and nothing changed.
        let (code, _, err) = common::bywire(
            &[
                "log",
                "convert",
                log.to_str().unwrap(),
                dataset.to_str().unwrap(),
                "--dbc",
                dbc.to_str().unwrap(),
            ],
            "",
        );
        assert_ne!(code, 0);
        assert!(err.contains("exists and is not empty"), "{err}");
    }
}

/// The page codecs of every column chunk of the Parquet files at `path` (a file or a
/// directory), and their rows, as pyarrow reads them.
const PARQUET_CODECS: &str = "
import pathlib, sys
import pyarrow.parquet as pq
root = pathlib.Path(sys.argv[1])
files = [root] if root.is_file() else sorted(root.rglob('*.parquet'))
codecs, rows = set(), 0
for f in files:
    meta = pq.ParquetFile(f).metadata
    rows += meta.num_rows
    for g in range(meta.num_row_groups):
        for c in range(meta.num_columns):
            codecs.add(meta.row_group(g).column(c).compression)
print(' '.join(sorted(codecs)), rows)
";

#[test]
fn parquet_pages_are_compressed_as_asked_and_pyarrow_reads_them() {
    let dbc = PathBuf::from(common::corpus("opendbc/opendbc__dbc__vw_mlb.dbc"));
    let dir = scratch("compression");
    let log = dir.join("traffic.log");
    let traffic = oracle("dbc_traffic.py", &[&dbc, Path::new("4"), Path::new("11")]);
    std::fs::write(&log, &traffic).unwrap();
    let frames = traffic.lines().count();
    // Decoded tables, snappy: pyarrow and polars read cantools' values from them.
    let dataset = dir.join("snappy");
    convert_decoded(&log, &dataset, &dbc, &["--compression", "snappy"]);
    let agreed = oracle("parquet_decoded.py", &[&dbc, &log, &dataset]);
    assert!(agreed.contains("values agree"), "{agreed}");
    let rows = agreed
        .split(" tables, ")
        .nth(1)
        .and_then(|r| r.split(' ').next());
    let codecs = python(PARQUET_CODECS, &[&dataset]);
    assert_eq!(codecs.trim(), format!("SNAPPY {}", rows.unwrap()));
    // `decode --parquet` takes the same option.
    let decoded = dir.join("decoded");
    bywire(&[
        "decode",
        dbc.to_str().unwrap(),
        "-I",
        log.to_str().unwrap(),
        "--parquet",
        decoded.to_str().unwrap(),
        "--compression",
        "none",
    ]);
    let codecs = python(PARQUET_CODECS, &[&decoded]);
    assert_eq!(codecs.trim(), format!("UNCOMPRESSED {}", rows.unwrap()));
    // Raw frames, uncompressed and by default: every frame back, zstd unless asked.
    for (option, codec) in [(Some("none"), "UNCOMPRESSED"), (None, "ZSTD")] {
        let (raw, back) = (dir.join("frames.parquet"), dir.join("back.log"));
        let mut args = vec![
            "log",
            "convert",
            log.to_str().unwrap(),
            raw.to_str().unwrap(),
        ];
        args.extend(option.iter().flat_map(|o| ["--compression", o]));
        bywire(&args);
        assert_eq!(
            python(PARQUET_CODECS, &[&raw]).trim(),
            format!("{codec} {frames}")
        );
        bywire(&[
            "log",
            "convert",
            raw.to_str().unwrap(),
            back.to_str().unwrap(),
        ]);
        assert_eq!(records(&back), records(&log));
        std::fs::remove_file(&raw).unwrap();
    }
    // Another format has no pages to compress: refused, nothing written.
    let asc = dir.join("traffic.asc");
    let (code, _, err) = common::bywire(
        &[
            "log",
            "convert",
            log.to_str().unwrap(),
            asc.to_str().unwrap(),
            "--compression",
            "snappy",
        ],
        "",
    );
    assert_ne!(code, 0);
    assert!(err.contains("--compression is for Parquet output"), "{err}");
    assert!(!asc.exists());
}

#[test]
fn decoded_datasets_partition_by_channel_and_date_as_hive_readers_expect() {
    let dbc = PathBuf::from(common::corpus(
        "cantools/tests__files__dbc__multiplex_choices.dbc",
    ));
    let dir = scratch("partitioned");
    let (log, dataset) = (dir.join("traffic.log"), dir.join("lake"));
    // Two days, two channels.
    std::fs::write(
        &log,
        "(1700000000.000000) can0 00123456#2003000000000000\n(1700000001.000000) can1 00123456#2003000000000000\n(1700086400.000000) can1 00123456#2003000000000000\n",
    )
    .unwrap();
    let said = convert_decoded(&log, &dataset, &dbc, &["--partition", "channel,date"]);
    assert!(said.contains("3 rows in 1 table, 3 files"), "{said}");
    let read = python(
        r#"
import sys, pyarrow.dataset as ds
d = ds.dataset(sys.argv[1], format="parquet", partitioning="hive")
t = d.to_table().sort_by("ts")
print(sorted(f.name for f in t.schema))
for r in t.to_pylist():
    print(r["message"], r["channel"], r["date"], r["Multiplexor"], r["Multiplexor_choice"])
"#,
        &[&dataset],
    );
    let mut lines = read.lines();
    let columns = lines.next().unwrap();
    assert!(
        columns.contains("'channel'")
            && columns.contains("'date'")
            && columns.contains("'message'"),
        "{columns}"
    );
    assert_eq!(
        lines.collect::<Vec<_>>(),
        [
            "Message1 can0 2023-11-14 8 MULTIPLEXOR_8",
            "Message1 can1 2023-11-14 8 MULTIPLEXOR_8",
            "Message1 can1 2023-11-15 8 MULTIPLEXOR_8",
        ]
    );
}

#[test]
fn decoded_mcap_channels_hold_cantools_values_valid_against_their_schemas() {
    // (Foxglove, which cannot run here, plots JSON channels with a JSON Schema: the mcap and
    // jsonschema packages check that layout instead.)
    for file in [
        "opendbc/opendbc__dbc__vw_mlb.dbc",
        "opendbc/opendbc__dbc__ford_lincoln_base_pt.dbc",
        "cantools/tests__files__dbc__floating_point.dbc",
    ] {
        let dbc = PathBuf::from(common::corpus(file));
        let dir = scratch(&format!("mcap-decoded-{}", file.replace('/', "_")));
        let (log, bag) = (dir.join("traffic.log"), dir.join("decoded.mcap"));
        let traffic = oracle("dbc_traffic.py", &[&dbc, Path::new("6"), Path::new("3")]);
        std::fs::write(&log, traffic).unwrap();
        convert_decoded(&log, &bag, &dbc, &[]);
        let checked = oracle("mcap_decoded.py", &[&dbc, &log, &bag]);
        assert!(
            checked.contains("valid and equal to cantools"),
            "{file}: {checked}"
        );
    }
}

#[test]
fn decode_writes_csv_and_parquet_from_any_format_as_cantools_decodes() {
    let dbc = PathBuf::from(common::corpus("opendbc/opendbc__dbc__vw_mlb.dbc"));
    let dir = scratch("decode-out");
    let (log, blf, dataset) = (
        dir.join("traffic.log"),
        dir.join("traffic.blf"),
        dir.join("dataset"),
    );
    let traffic = oracle("dbc_traffic.py", &[&dbc, Path::new("4"), Path::new("11")]);
    std::fs::write(&log, traffic).unwrap();
    bywire(&[
        "log",
        "convert",
        log.to_str().unwrap(),
        blf.to_str().unwrap(),
    ]);
    // Parquet from a BLF: the same tables as from the candump log, checked against cantools.
    let said = bywire(&[
        "decode",
        dbc.to_str().unwrap(),
        "-I",
        blf.to_str().unwrap(),
        "--parquet",
        dataset.to_str().unwrap(),
    ]);
    assert!(said.contains("rows in"), "{said}");
    let agreed = oracle("parquet_decoded.py", &[&dbc, &log, &dataset]);
    assert!(agreed.contains("values agree"), "{agreed}");
    // From the candump log, a file and standard input (its records lent on the way, lines
    // that are not log lines passed over): the same tables.
    let noted = dir.join("noted.log");
    let text = format!(
        "# recorded on the test bench\n{}not a log line\n",
        std::fs::read_to_string(&log).unwrap()
    );
    std::fs::write(&noted, &text).unwrap();
    let (from_file, from_stdin) = (dir.join("from-file"), dir.join("from-stdin"));
    let said_file = bywire(&[
        "decode",
        dbc.to_str().unwrap(),
        "-I",
        noted.to_str().unwrap(),
        "--parquet",
        from_file.to_str().unwrap(),
    ]);
    let (code, said_stdin, err) = common::bywire(
        &[
            "decode",
            dbc.to_str().unwrap(),
            "--parquet",
            from_stdin.to_str().unwrap(),
        ],
        &text,
    );
    assert_eq!(code, 0, "{err}");
    for (said_here, output) in [(&said_file, &from_file), (&said_stdin, &from_stdin)] {
        let rows = |s: &str| s.split("; ").nth(1).map(str::to_string);
        assert_eq!(rows(said_here), rows(&said), "{said_here}");
        let agreed = oracle("parquet_decoded.py", &[&dbc, &log, output]);
        assert!(agreed.contains("values agree"), "{agreed}");
    }
    // CSV from the BLF: one row per signal, values and choices as cantools gives them.
    let csv = dir.join("decoded.csv");
    std::fs::write(
        &csv,
        bywire(&[
            "decode",
            dbc.to_str().unwrap(),
            "-I",
            blf.to_str().unwrap(),
            "--csv",
        ]),
    )
    .unwrap();
    let compared = python(
        r##"
import csv, sys, cantools
db = cantools.database.load_file(sys.argv[1], strict=False, encoding="utf-8")
expected = []
for line in open(sys.argv[2]):
    stamp, channel, frame = line.split()
    ident, data = frame.split("#", 1)
    m = db.get_message_by_frame_id(int(ident, 16))
    payload = bytes.fromhex(data[2:] if data.startswith("#") else data)
    try:
        numbers = m.decode(payload, decode_choices=False)
        named = m.decode(payload)
    except Exception:
        continue
    for s in m.signals:
        if s.name in numbers:
            label = named[s.name]
            choice = "" if isinstance(label, (int, float)) else str(label)
            expected.append((stamp.strip("()"), channel, m.name, s.name, numbers[s.name], choice, s.unit or ""))
# (cantools orders a message's signals by start bit, bywire as the DBC lists them)
rows = sorted(csv.DictReader(open(sys.argv[3])), key=lambda r: (r["ts"], r["signal"]))
expected.sort(key=lambda e: (e[0], e[3]))
assert len(rows) == len(expected), (len(rows), len(expected))
for row, (ts, channel, message, signal, value, choice, unit) in zip(rows, expected):
    assert row["ts"][:len(ts)] == ts and row["channel"] == channel and row["message"] == message, (row, ts)
    assert row["signal"] == signal and row["choice"] == choice and row["unit"] == unit, (row, signal, choice)
    assert (float(row["value"]) == float(value)) and (row["value"] == str(value)), (row, value)
print(len(rows), "rows agree")
"##,
        &[&dbc, &log, &csv],
    );
    assert!(compared.contains("rows agree"), "{compared}");
}

#[test]
fn the_readmes_pandas_walk_through_runs_as_written() {
    let readme =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../README.md"))
            .unwrap();
    let start = readme
        .find("<!-- walkthrough: parquet -->\n```python\n")
        .unwrap();
    let script = &readme[start..];
    let script = &script[script.find("```python\n").unwrap() + 10
        ..script.find("```\n<!-- end walkthrough -->").unwrap()];
    let dbc = Path::new(env!("CARGO_MANIFEST_DIR")).join("../bywire-tug/dbc/reference-tug.dbc");
    let dir = scratch("walkthrough");
    let traffic = oracle("dbc_traffic.py", &[&dbc, Path::new("50"), Path::new("5")]);
    std::fs::write(dir.join("drive.log"), traffic).unwrap();
    let at = |name: &str| dir.join(name).to_str().unwrap().to_string();
    bywire(&["log", "convert", &at("drive.log"), &at("drive.blf")]);
    // The README's commands, as written.
    bywire(&[
        "log",
        "convert",
        &at("drive.blf"),
        &at("drive-lake"),
        "--dbc",
        dbc.to_str().unwrap(),
        "--partition",
        "channel,date",
    ]);
    bywire(&["log", "convert", &at("drive.blf"), &at("frames.parquet")]);
    // The script as written, then an exit without the interpreter's teardown: on a loaded
    // machine pyarrow's thread pool can abort that teardown (`terminate called without an
    // active exception`) after the script has done all its work, which is what is checked.
    let script = format!("{script}\nimport os, sys\nsys.stdout.flush()\nos._exit(0)\n");
    let out = Command::new("python3")
        .arg("-c")
        .arg(script)
        .current_dir(&dir)
        .output()
        .unwrap();
    let printed = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{printed}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        printed.contains("VelocityActual")
            && printed.contains("ControlMode_choice")
            && printed.contains("2023-11-14"),
        "{printed}"
    );
}

/// A raw frames' file on which parquet-rs panics while decoding (its delta header's first
/// value made an 11-byte varint): `log cat` says what is wrong and where, as an error, with no
/// panic message and no crash.
#[test]
fn a_file_parquet_rs_panics_on_is_an_error_without_a_panic_message() {
    let dir = scratch("parquet-panic");
    let (log, table) = (dir.join("in.log"), dir.join("frames.parquet"));
    let six = "(1700000000.000001) can0 010#01\n".repeat(6);
    std::fs::write(&log, six).unwrap();
    let said = bywire(&[
        "log",
        "convert",
        log.to_str().unwrap(),
        table.to_str().unwrap(),
        "--compression",
        "none",
    ]);
    assert!(said.starts_with("6 frames written"), "{said}");
    let mut bytes = std::fs::read(&table).unwrap();
    // The `ts` page's delta header: a two-byte block size, 4 miniblocks, 6 values, then the
    // first value.
    let header = bytes
        .windows(4)
        .position(|w| w[0] == 0x80 && w[2..] == [0x04, 0x06])
        .unwrap();
    bytes[header + 4..header + 15].fill(0xFF);
    std::fs::write(&table, &bytes).unwrap();
    let (code, out, err) = common::bywire(&["log", "cat", table.to_str().unwrap()], "");
    assert_eq!(code, 1, "{out}{err}");
    assert!(
        err.contains("row 0") && err.contains("malformed page"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");
}

/// python-can's own test logs (`test/data` of its 4.6.1 source release, fetched from PyPI by
/// `scripts/install-test-deps.sh`), each read by python-can's `LogReader` and by
/// `bywire log cat`: the same frames in the same order, each on the same channel at the same
/// time since the first. The departures, each for a reason:
/// - `single_frame.asc` holds 64 data bytes on a classic line (`d 40` in a hex file):
///   python-can keeps 8 of them with a DLC of 64; bywire reads the CAN FD frame of 64 bytes
///   that is the only frame such a length can be.
/// - `test_CanMessage.blf`, `test_CanMessage2.blf`, `test_CanFdMessage.blf` and
///   `test_CanFdMessage64.blf` hold made-up identifiers (0x4444444 or 0x5555555) marked
///   standard, which no CAN frame can carry: bywire passes over them with a warning naming the
///   byte (it once cut them to 11 bits without a word); python-can keeps them.
///
/// Every other log is read as python-can reads it.
#[test]
fn python_cans_test_logs_read_as_python_can_reads_them() {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target/python-can-data");
    let mut logs: Vec<PathBuf> = std::fs::read_dir(&data)
        .unwrap_or_else(|e| panic!("{}: {e} (run scripts/install-test-deps.sh)", data.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| {
            let name = p.file_name().unwrap().to_str().unwrap();
            [".asc", ".blf", ".trc", ".asc.gz", ".mf4", ".log"]
                .iter()
                .any(|e| name.ends_with(e))
        })
        .collect();
    logs.sort();
    assert!(logs.len() >= 25, "{logs:?}");
    let mut args = vec![format!("{}/python_can_logs.py", common::oracles())];
    args.extend(logs.iter().map(|p| p.to_str().unwrap().to_string()));
    let out = Command::new("python3").args(&args).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let theirs: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let left_out = [
        "test_CanMessage.blf",
        "test_CanMessage2.blf",
        "test_CanFdMessage.blf",
        "test_CanFdMessage64.blf",
    ];
    for log in &logs {
        let path = log.to_str().unwrap();
        let name = log.file_name().unwrap().to_str().unwrap();
        let (code, cat, err) = common::bywire(&["log", "cat", path], "");
        assert_eq!(code, 0, "{name}: {err}");
        // (channel, seconds since the first frame, frame text; error frames as ERROR).
        let ours: Vec<(String, f64, String)> = cat
            .lines()
            .map(|line| {
                let (time, rest) = line[1..].split_once(") ").unwrap();
                let (interface, frame) = rest.split_once(' ').unwrap();
                let id = u32::from_str_radix(frame.split('#').next().unwrap(), 16).unwrap();
                let frame = if frame.len() > 9 && id & 0x2000_0000 != 0 {
                    "ERROR".to_string()
                } else {
                    frame.to_string()
                };
                (interface.to_string(), time.parse::<f64>().unwrap(), frame)
            })
            .collect();
        if left_out.contains(&name) {
            assert!(ours.is_empty(), "{name}: {ours:?}");
            assert!(err.contains("above 0x7FF (passed over)"), "{name}: {err}");
            continue;
        }
        let theirs = theirs[path].as_array().unwrap();
        assert_eq!(ours.len(), theirs.len(), "{name}: {cat}\n{theirs:?}");
        // python-can numbers TRC buses from 1, ASC and BLF channels from 0.
        let first_bus = u64::from(name.ends_with(".trc"));
        for ((interface, time, frame), m) in ours.iter().zip(theirs) {
            let channel = m["channel"].as_u64().unwrap_or(first_bus) - first_bus;
            assert_eq!(*interface, format!("can{channel}"), "{name}: {m}");
            let since = time - ours[0].1;
            assert!(
                (since - m["t"].as_f64().unwrap()).abs() < 2e-6,
                "{name}: {since} {m}"
            );
            let expected = m["frame"].as_str().unwrap();
            if name == "single_frame.asc" {
                let all: String = (0..64u8).map(|b| format!("{b:02X}")).collect();
                assert_eq!(*frame, format!("00000123##4{all}"), "{name}");
                assert_eq!(expected, "00000123#0001020304050607_F", "{name}");
            } else {
                assert_eq!(frame, expected, "{name}");
            }
        }
    }
}

/// rosbag2 folders as `ros2 bag` writes and reads them: the `rosbags` package reads the bag we
/// write (metadata and every message, deserialized by its own CDR reader), and we read the bag
/// it writes (its MCAP storage).
#[test]
fn rosbags_reads_our_rosbag2_folder_and_we_read_its() {
    let dir = scratch("rosbag2");
    let (log, bag) = (dir.join("in.log"), dir.join("drive"));
    std::fs::write(&log, FRAMES).unwrap();
    let said = bywire(&[
        "log",
        "convert",
        log.to_str().unwrap(),
        bag.to_str().unwrap(),
        "--format",
        "rosbag2",
    ]);
    assert!(said.contains("7 frames written"), "{said}");
    let read = python(
        r#"
import sys
from pathlib import Path
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore, get_types_from_msg
store = get_typestore(Stores.ROS2_HUMBLE)
with Reader(Path(sys.argv[1])) as r:
    (c,) = r.connections
    print(r.message_count, c.topic, c.msgtype, c.msgcount, r.start_time, r.end_time)
    store.register(get_types_from_msg("std_msgs/Header header\nuint32 id\nbool is_rtr\nbool is_extended\nbool is_error\nuint8 dlc\nuint8[8] data\n", "can_msgs/msg/Frame"))
    for conn, t, raw in r.messages():
        f = store.deserialize_cdr(raw, conn.msgtype)
        print(t, f.header.stamp.sec * 10**9 + f.header.stamp.nanosec, f.header.frame_id, f.id,
              int(f.is_rtr), int(f.is_extended), int(f.is_error), f.dlc, bytes(f.data).hex())
"#,
        &[&bag],
    );
    let wanted: Vec<LogRecord> = original()
        .into_iter()
        .filter(|r| !r.frame.is_fd())
        .collect();
    let mut lines = read.lines();
    let head: Vec<&str> = lines.next().unwrap().split(' ').collect();
    let (first, last) = (
        wanted[0].timestamp.as_nanos(),
        wanted.last().unwrap().timestamp.as_nanos(),
    );
    assert_eq!(
        head,
        [
            "7",
            "/from_can_bus",
            "can_msgs/msg/Frame",
            "7",
            &first.to_string(),
            &(last + 1).to_string()
        ],
        "{read}"
    );
    for (line, w) in lines.zip(&wanted) {
        let f: Vec<&str> = line.split(' ').collect();
        let nanos = w.timestamp.as_nanos().to_string();
        assert_eq!(
            (f[0], f[1], f[2]),
            (nanos.as_str(), nanos.as_str(), w.interface.as_str())
        );
        if !w.frame.is_error() {
            let id = w.frame.id().unwrap();
            assert_eq!(f[3], id.as_raw().to_string(), "{line}");
            let mut data = [0u8; 8];
            for (slot, b) in data.iter_mut().zip(w.frame.data()) {
                *slot = *b;
            }
            let hex: String = data.iter().map(|b| format!("{b:02x}")).collect();
            assert_eq!(f[8], hex, "{line}");
        }
    }
    // Our bag reads back as a log; an existing folder is not overwritten.
    let back = dir.join("back.log");
    bywire(&[
        "log",
        "convert",
        bag.to_str().unwrap(),
        back.to_str().unwrap(),
    ]);
    let direct = dir.join("direct.log");
    bywire(&[
        "log",
        "convert",
        dir.join("drive/drive_0.mcap").to_str().unwrap(),
        direct.to_str().unwrap(),
    ]);
    assert_eq!(
        std::fs::read_to_string(&back).unwrap(),
        std::fs::read_to_string(&direct).unwrap()
    );
    let (code, _, err) = common::bywire(
        &[
            "log",
            "convert",
            log.to_str().unwrap(),
            bag.to_str().unwrap(),
            "--format",
            "rosbag2",
        ],
        "",
    );
    assert!(
        code != 0 && err.contains("exists and is not empty"),
        "{err}"
    );
    // rosbags writes a bag (MCAP storage, its latest metadata version); we read it.
    let theirs = dir.join("theirs");
    python(
        r#"
import sys
from pathlib import Path
from rosbags.rosbag2 import Writer, StoragePlugin
from rosbags.typesys import Stores, get_typestore, get_types_from_msg
store = get_typestore(Stores.ROS2_HUMBLE)
store.register(get_types_from_msg("std_msgs/Header header\nuint32 id\nbool is_rtr\nbool is_extended\nbool is_error\nuint8 dlc\nuint8[8] data\n", "can_msgs/msg/Frame"))
Frame = store.types["can_msgs/msg/Frame"]
Header = store.types["std_msgs/msg/Header"]
Time = store.types["builtin_interfaces/msg/Time"]
import numpy as np
with Writer(Path(sys.argv[1]), version=9, storage_plugin=StoragePlugin.MCAP) as w:
    conn = w.add_connection("/from_can_bus", "can_msgs/msg/Frame", typestore=store)
    for i, (can_id, ext, data) in enumerate([(0x123, False, b"\xde\xad\xbe\xef"), (0x1abcdef0, True, b"\x01\x02")]):
        t = 1700000000_000000000 + i * 1_000_000
        msg = Frame(header=Header(stamp=Time(sec=t // 10**9, nanosec=t % 10**9), frame_id="can1"),
                    id=can_id, is_rtr=False, is_extended=ext, is_error=False, dlc=len(data),
                    data=np.frombuffer(data.ljust(8, b"\0"), dtype=np.uint8))
        w.write(conn, t, store.serialize_cdr(msg, "can_msgs/msg/Frame"))
"#,
        &[&theirs],
    );
    let from_theirs = dir.join("from-theirs.log");
    bywire(&[
        "log",
        "convert",
        theirs.to_str().unwrap(),
        from_theirs.to_str().unwrap(),
    ]);
    assert_eq!(
        std::fs::read_to_string(&from_theirs).unwrap(),
        "(1700000000.000000) can1 123#DEADBEEF\n(1700000000.001000) can1 1ABCDEF0#0102\n"
    );
}

/// Interface names that no channel number gives (`bus1`, `front`) survive `log convert` into
/// ASC, TRC, BLF and MF4 and back, while python-can reads the same files frame for frame.
#[test]
fn interface_names_survive_every_channel_numbered_format() {
    const NAMED: &str = "\
(1700000000.100000) bus1 123#01
(1700000000.200000) front 124#02
(1700000000.300000) can0 125#03
(1700000000.400000) bus1 126#04
";
    let dir = scratch("names");
    let log = dir.join("in.log");
    std::fs::write(&log, NAMED).unwrap();
    let wanted: Vec<LogRecord> = bywire_log::Reader::new(NAMED.as_bytes())
        .collect::<Result<_, _>>()
        .unwrap();
    for extension in ["asc", "trc", "blf", "mf4"] {
        let out = dir.join(format!("named.{extension}"));
        bywire(&[
            "log",
            "convert",
            log.to_str().unwrap(),
            out.to_str().unwrap(),
        ]);
        let (_, back) = bywire_log::format::Format::open_file(&out).unwrap();
        let back: Vec<LogRecord> = back.collect::<Result<_, _>>().unwrap();
        let names: Vec<&str> = back.iter().map(|r| r.interface.as_str()).collect();
        assert_eq!(names, ["bus1", "front", "can0", "bus1"], "{extension}");
        for (g, w) in back.iter().zip(&wanted) {
            assert_eq!(g.frame, w.frame, "{extension}");
        }
        let said = python(
            r#"
import can, sys
reader = {"asc": lambda p: can.ASCReader(p, relative_timestamp=False), "trc": can.TRCReader,
          "blf": can.BLFReader, "mf4": can.MF4Reader}[sys.argv[2]]
print([bytes(m.data).hex() for m in reader(sys.argv[1])])
"#,
            &[&out, Path::new(extension)],
        );
        assert_eq!(said.trim(), "['01', '02', '03', '04']", "{extension}");
    }
}
