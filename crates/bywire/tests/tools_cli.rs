//! The can-utils-style commands on the host: arguments, errors that name what is wrong, DBC
//! encoding against cantools, log replay to standard output, generated traffic, and decoding
//! of logs built from corpus DBCs compared with `cantools decode`.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::path::Path;
use std::process::Command;

mod common;

use common::{bywire, corpus, Scratch};

const MOTOHAWK: &str = "cantools/tests__files__dbc__motohawk.dbc";

fn fails_with(args: &[&str], input: &str, needle: &str) {
    let (code, _, err) = bywire(args, input);
    assert_eq!(code, 1, "{args:?}: {err}");
    assert!(
        err.contains(needle),
        "{args:?}: expected '{needle}' in: {err}"
    );
}

#[test]
fn bad_input_names_the_problem() {
    fails_with(
        &["send", "virtual:t", "12G#00"],
        "",
        "frame '12G#00': column 3: 'G' is not a hex digit",
    );
    fails_with(
        &["send", "virtual:t", "123#0"],
        "",
        "column 6: data ends in half a byte",
    );
    fails_with(
        &["send", "virtual:t", "123#00", "124#00"],
        "",
        "expected one frame",
    );
    fails_with(
        &["send", "nosuch:x", "123#00"],
        "",
        "unknown bus scheme 'nosuch'",
    );
    let m = corpus(MOTOHAWK);
    fails_with(
        &["send", "virtual:t", "--dbc", &m, "Nope"],
        "",
        "no message 'Nope'",
    );
    fails_with(
        &["send", "virtual:t", "--dbc", &m, "ExampleMessage", "Nope=1"],
        "",
        "has no signal 'Nope'",
    );
    fails_with(
        &[
            "send",
            "virtual:t",
            "--dbc",
            &m,
            "ExampleMessage",
            "Temperature",
        ],
        "",
        "is not SIGNAL=VALUE",
    );
    fails_with(
        &[
            "send",
            "virtual:t",
            "--dbc",
            &m,
            "ExampleMessage",
            "Temperature=hot",
        ],
        "",
        "'hot' is not a number",
    );
    fails_with(
        &[
            "send",
            "virtual:t",
            "--dbc",
            &m,
            "ExampleMessage",
            "Temperature=9999",
        ],
        "",
        "signal Temperature: value 9999 is outside [229.52, 270.47]",
    );
    fails_with(&["dump", "vcan0,12G:7FF"], "", "filter '12G:7FF'");
    fails_with(&["dump", "nosuch:x"], "", "bus 'nosuch:x'");
    // Compression is for a Parquet log file only, refused before any file is made.
    let blf = std::env::temp_dir().join(format!("bywire-refused-{}.blf", std::process::id()));
    let blf = blf.to_str().unwrap();
    for args in [
        &["dump", "virtual:c", "-f", blf, "--compression", "snappy"][..],
        &["dump", "virtual:c", "--compression", "none"][..],
    ] {
        fails_with(args, "", "--compression is for Parquet output");
    }
    assert!(!Path::new(blf).exists());
    // A time unit is for Parquet output only, raw or decoded, refused before any file is made.
    let mcap = blf.replace(".blf", ".mcap");
    for args in [
        &[
            "log",
            "convert",
            "in.log",
            &mcap,
            "--dbc",
            &m,
            "--time-unit",
            "us",
        ][..],
        &["log", "convert", "in.log", &mcap, "--time-unit", "us"][..],
        &["dump", "virtual:c", "-f", blf, "--time-unit", "us"][..],
    ] {
        fails_with(args, "", "--time-unit is for Parquet output");
    }
    assert!(!Path::new(&mcap).exists());
    assert!(!Path::new(blf).exists());
    fails_with(
        &["dump", "-L", "--dbc", &m, "virtual:t"],
        "",
        "--dbc decodes on screen",
    );
    fails_with(
        &["gen", "virtual:t", "-I", "XYZ"],
        "",
        "-I 'XYZ': expected r, i or a hex value",
    );
    fails_with(
        &["gen", "virtual:t", "-I", "800"],
        "",
        "above the 7FF limit",
    );
    // A numeric option out of range is a usage error (exit 2) naming it.
    let (code, _, err) = bywire(&["gen", "virtual:t", "-g", "inf"], "");
    assert!(
        code == 2 && err.contains("-g") && err.contains("not a finite number"),
        "{err}"
    );
    fails_with(&["busload", "virtual:t"], "", "expected BUS@BITRATE");
    fails_with(&["busload", "virtual:t@0"], "", "bitrate '0'");
    fails_with(&["play", "vcan0"], "", "assignment 'vcan0'");
    fails_with(&["play", "-l", "x"], "", "-l 'x'");
    // A bad line in a file stops the replay before anything is sent, naming the line.
    let dir = Scratch::new("play");
    let log = dir.join("bad.log");
    std::fs::write(&log, "(1.000000) can0 123#00\n(1.500000) can0 12G#01\n").unwrap();
    let (code, out, err) = bywire(&["play", "-I", log.to_str().unwrap(), "stdout=can0"], "");
    assert_eq!(code, 1);
    assert!(out.is_empty(), "nothing is played: {out}");
    assert!(
        err.contains("line 2, column 19: frame: 'G' is not a hex digit"),
        "{err}"
    );
    // Usage errors exit 2.
    let (code, _, _) = bywire(&["dump"], "");
    assert_eq!(code, 2);
}

#[test]
fn send_encodes_like_cantools() {
    let m = corpus(MOTOHAWK);
    let (code, out, err) = bywire(
        &[
            "send",
            "virtual:t",
            "-v",
            "--dbc",
            &m,
            "ExampleMessage",
            "Temperature=250.1",
            "AverageRadius=0.5",
            "Enable=Enabled",
        ],
        "",
    );
    assert_eq!(code, 0, "{err}");
    let script = format!(
        "import cantools\ndb = cantools.database.load_file('{m}')\n\
         m = db.get_message_by_name('ExampleMessage')\n\
         print('1F0#' + m.encode({{'Temperature': 250.1, 'AverageRadius': 0.5, 'Enable': 'Enabled'}}).hex().upper())"
    );
    let theirs = Command::new("python3")
        .args(["-c", &script])
        .output()
        .unwrap();
    assert!(
        theirs.status.success(),
        "{}",
        String::from_utf8_lossy(&theirs.stderr)
    );
    assert_eq!(out, String::from_utf8(theirs.stdout).unwrap());
}

#[test]
fn play_to_stdout_keeps_lines_and_skips_other_text() {
    let input =
        "(1.000000) can0 123#00\nnot a log line\n(1.000100) can0 124#01\n(1.000200) can1 125#02\n\
                 (1.000300) can0 1ABCDEF0##5AA\n(1.000400) can0 20000080#0000000000000000\n";
    let (code, out, err) = bywire(&["play", "stdout=can0"], input);
    assert_eq!(code, 0, "{err}");
    assert_eq!(
        out,
        "(0000000001.000000) can0 123#00\n(0000000001.000100) can0 124#01\n\
         (0000000001.000300) can0 1ABCDEF0##5AA\n(0000000001.000400) can0 20000080#0000000000000000\n"
    );
    // Twice, ignoring timestamps, stopping after 5 frames (looping needs a file).
    let dir = Scratch::new("loop");
    let log = dir.join("loop.log");
    std::fs::write(&log, input).unwrap();
    let file = log.to_str().unwrap();
    let (code, out, _) = bywire(
        &[
            "play",
            "-I",
            file,
            "stdout=can0",
            "-l",
            "2",
            "-t",
            "-g",
            "0",
            "-n",
            "5",
        ],
        "",
    );
    assert_eq!(code, 0);
    assert_eq!(out.lines().count(), 5);
    let (code, out, _) = bywire(
        &[
            "play",
            "-I",
            file,
            "stdout=can0",
            "-l",
            "2",
            "-t",
            "-g",
            "0",
        ],
        "",
    );
    assert_eq!(code, 0);
    assert_eq!(out.lines().count(), 8);
    fails_with(
        &["play", "stdout=can0", "-l", "2"],
        input,
        "-l needs a file",
    );
}

#[test]
fn play_paces_by_the_timestamps_and_the_speed_factor() {
    let input = "(10.000000) can0 123#00\n(10.400000) can0 124#01\n";
    let started = std::time::Instant::now();
    let (code, _, _) = bywire(&["play", "stdout=can0"], input);
    assert_eq!(code, 0);
    let real = started.elapsed();
    let started = std::time::Instant::now();
    let (code, _, _) = bywire(&["play", "stdout=can0", "--speed", "4"], input);
    assert_eq!(code, 0);
    let fast = started.elapsed();
    // 0.4 s of log; 0.1 s at four times the speed (process start-up adds a little to both).
    assert!(real.as_secs_f64() >= 0.4, "{real:?}");
    assert!(
        fast.as_secs_f64() >= 0.1 && fast < real,
        "{fast:?} vs {real:?}"
    );
}

#[test]
fn gen_modes() {
    let (code, out, err) = bywire(
        &[
            "gen",
            "virtual:t",
            "-n",
            "4",
            "-v",
            "-I",
            "123",
            "-L",
            "2",
            "-D",
            "i",
            "-g",
            "0",
        ],
        "",
    );
    assert_eq!(code, 0, "{err}");
    let frames: Vec<&str> = out.split_whitespace().filter(|w| w.contains('#')).collect();
    assert_eq!(frames, ["123#0000", "123#0100", "123#0200", "123#0300"]);
    // Incrementing IDs and lengths, extended.
    let (_, out, _) = bywire(
        &[
            "gen",
            "virtual:t",
            "-n",
            "3",
            "-v",
            "-e",
            "-I",
            "i",
            "-L",
            "i",
            "-D",
            "AABBCCDDEEFF0011",
            "-g",
            "0",
        ],
        "",
    );
    let frames: Vec<&str> = out.split_whitespace().filter(|w| w.contains('#')).collect();
    assert_eq!(frames, ["00000000#", "00000001#AA", "00000002#AABB"]);
    // FD with BRS, random but seeded: the same seed gives the same frames.
    let args = [
        "gen",
        "virtual:t",
        "-n",
        "20",
        "-v",
        "-f",
        "-b",
        "-g",
        "0",
        "--seed",
        "7",
    ];
    let (_, a, _) = bywire(&args, "");
    let (_, b, _) = bywire(&args, "");
    assert_eq!(a, b);
    for frame in a.split_whitespace().filter(|w| w.contains('#')) {
        let f: bywire_core::Frame = frame.parse().unwrap();
        assert!(f.is_fd() && frame.contains("##5"), "{frame}");
    }
    // From a DBC: the message at its cycle time with counters and checksums.
    let dbc = format!(
        "{}/../bywire-tug/dbc/reference-tug.dbc",
        env!("CARGO_MANIFEST_DIR")
    );
    let (code, out, err) = bywire(&["gen", "virtual:t", "--dbc", &dbc, "-n", "30", "-v"], "");
    assert_eq!(code, 0, "{err}");
    let frames: Vec<bywire_core::Frame> = out
        .split_whitespace()
        .filter(|w| w.contains('#'))
        .map(|w| w.parse().unwrap())
        .collect();
    assert_eq!(frames.len(), 30);
    // The first round sends every cyclic message once; each one is sealed (CRC correct).
    let ids: std::collections::BTreeSet<u32> =
        frames.iter().map(|f| f.id().unwrap().as_raw()).collect();
    assert!(ids.contains(&0x100) && ids.contains(&0x101), "{ids:?}");
    for f in &frames {
        let payload: [u8; 8] = f.data().try_into().unwrap();
        assert!(
            bywire_tug::messages::is_sealed(f.id().unwrap().as_raw(), &payload),
            "{f}"
        );
    }
}

/// Every message of some corpus DBCs with seeded random payloads, as a candump log, decoded by
/// us and by `cantools decode --single-line`: the same signals with the same values.
#[test]
fn decode_agrees_with_cantools_on_logs_from_corpus_dbcs() {
    let files = [
        "cantools/tests__files__dbc__motohawk.dbc",
        "cantools/tests__files__dbc__vehicle.dbc",
        "cantools/tests__files__dbc__choices.dbc",
        "cantools/tests__files__dbc__multiplex_2.dbc",
        "cantools/tests__files__dbc__signed.dbc",
        "cantools/tests__files__dbc__floating_point.dbc",
        "opendbc/opendbc__dbc__ESR.dbc",
        "opendbc/opendbc__dbc__FORD_CADS.dbc",
        "opendbc/opendbc__dbc__acura_ilx_2016_nidec.dbc",
    ];
    let mut rng = fastrand::Rng::with_seed(42);
    let mut compared = 0;
    for file in files {
        let path = corpus(file);
        let db = bywire_dbc::parse(&std::fs::read(&path).unwrap(), bywire_dbc::Mode::Lenient)
            .unwrap()
            .0;
        let mut log = String::new();
        // VECTOR__INDEPENDENT_SIG_MSG (ID 0x40000000) is a container, not a frame.
        for m in db
            .messages
            .iter()
            .filter(|m| m.size <= 8 && m.id <= 0x1FFF_FFFF)
        {
            for _ in 0..3 {
                let data: String = (0..m.size).map(|_| format!("{:02X}", rng.u8(..))).collect();
                let id = if m.extended {
                    format!("{:08X}", m.id)
                } else {
                    format!("{:03X}", m.id)
                };
                log += &format!("(1600000000.000000) can0 {id}#{data}\n");
            }
        }
        let (code, ours, err) = bywire(&["decode", &path, "--single-line"], &log);
        assert_eq!(code, 0, "{file}: {err}");
        let (code, theirs, err) = common::run_with_input(
            Command::new("python3").args(["-m", "cantools", "decode", "--single-line", &path]),
            &log,
        );
        assert_eq!(code, 0, "{file}: {err}");
        assert_eq!(ours.lines().count(), theirs.lines().count(), "{file}");
        for (o, t) in ours.lines().zip(theirs.lines()) {
            // Frames neither can decode (e.g. a multiplexer value that selects nothing) are
            // errors on both sides, in each tool's words.
            if is_error(t) {
                assert!(is_error(o), "{file}\nbywire:   {o}\ncantools: {t}");
            } else {
                assert_eq!(items(o), items(t), "{file}\nbywire:   {o}\ncantools: {t}");
            }
            compared += 1;
        }
    }
    assert!(compared > 100, "{compared}");
}

fn is_error(line: &str) -> bool {
    line.split_once(" :: ")
        .is_some_and(|(_, d)| !d.ends_with(')'))
}

/// The items after `::` of a single-line decode, as a set (cantools orders them differently).
fn items(line: &str) -> std::collections::BTreeSet<String> {
    let Some((_, decoded)) = line.split_once(" :: ") else {
        return std::iter::once(line.to_string()).collect();
    };
    let inner = decoded.split_once('(').map_or(decoded, |(_, i)| i);
    let inner = inner.strip_suffix(')').unwrap_or(inner);
    inner.split(", ").map(str::to_string).collect()
}

#[test]
fn plot_writes_png_and_svg_and_nothing_on_errors() {
    let dir = Scratch::new("plot");
    let dbc = dir.join("motor.dbc");
    std::fs::write(
        &dbc,
        "VERSION \"\"\nBU_: ECU\nBO_ 291 Motor: 4 ECU\n SG_ Rpm : 0|16@1+ (1,0) [0|2000] \"rpm\" X\n \
         SG_ Current : 16|16@1+ (0.1,-50) [-50|50] \"A\" X\nBO_ 292 Other: 2 ECU\n SG_ Rpm : 0|16@1+ (1,0) [0|9] \"\" X\n",
    )
    .unwrap();
    let log: String = (0..200u32)
        .map(|i| {
            format!(
                "({}.{:06}) can0 123#{:02X}{:02X}E803\n",
                1000 + i / 50,
                i % 50 * 20_000,
                i % 256,
                i / 256
            )
        })
        .collect();
    let dbc = dbc.to_str().unwrap();
    let png = dir.join("motor.png");
    let (code, _, err) = bywire(
        &[
            "plot",
            dbc,
            "Motor.Rpm",
            "Current",
            "--width",
            "640",
            "--height",
            "480",
            "-o",
            png.to_str().unwrap(),
        ],
        &log,
    );
    assert_eq!(code, 0, "{err}");
    let bytes = std::fs::read(&png).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    assert_eq!(&bytes[12..16], b"IHDR");
    let width = u32::from_be_bytes(bytes[16..20].try_into().unwrap());
    let height = u32::from_be_bytes(bytes[20..24].try_into().unwrap());
    assert_eq!((width, height), (640, 480));
    let svg = dir.join("motor.svg");
    // Plots `signals` in panels to the SVG; its text.
    let panels = |signals: &[&str]| {
        let mut args = vec!["plot", dbc];
        args.extend_from_slice(signals);
        args.extend(["--subplots", "-o", svg.to_str().unwrap()]);
        let (code, _, err) = bywire(&args, &log);
        assert_eq!(code, 0, "{err}");
        std::fs::read_to_string(&svg).unwrap()
    };
    let text = panels(&["Motor.Rpm", "Current"]);
    assert!(
        text.starts_with("<svg")
            && text.contains("Motor.Rpm [rpm]")
            && text.contains("Motor.Current [A]")
    );
    assert!(text.contains("time [s]"));
    // Patterns, as cantools plot takes them: every signal of Motor, once though named twice.
    let text = panels(&["Motor.*", "*Curr?nt"]);
    assert!(text.contains("Motor.Rpm [rpm]") && text.contains("Motor.Current [A]"));
    assert_eq!(text.matches("Motor.Current [A]").count(), 1, "one panel");
    // Lines that cannot be read are reported with their numbers and skipped, not silently.
    let mut dirty = log.clone().into_bytes();
    dirty.extend_from_slice(b"(1010.000000) can0 123#GG\n(1010.1) can0 123#\xff\xfe\n");
    dirty.extend(std::iter::repeat_n(b'x', 70_000));
    dirty.extend_from_slice(b"\nnot a log line\n(1011.000000) can0 123#0100E803\n");
    let dirty_log = dir.join("dirty.log");
    std::fs::write(&dirty_log, &dirty).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_bywire"))
        .args(["plot", dbc, "Motor.Rpm", "-o", png.to_str().unwrap(), "-I"])
        .arg(&dirty_log)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    let name = dirty_log.display().to_string();
    for (line, what) in [(201, "hex digit"), (202, "UTF-8"), (203, "longer")] {
        assert!(
            err.lines()
                .any(|l| l.starts_with(&format!("{name}: line {line}")) && l.contains(what)),
            "line {line} ({what}): {err}"
        );
    }
    assert_eq!(err.lines().count(), 3, "{err}");
    std::fs::remove_file(&dirty_log).unwrap();
    // Errors name the problem and leave no file, not even a temporary one.
    let bad = dir.join("bad.png");
    let b = bad.to_str().unwrap();
    fails_with(
        &["plot", dbc, "Nope", "-o", b],
        &log,
        "signal 'Nope' is not in the DBC",
    );
    fails_with(
        &["plot", dbc, "Rpm", "-o", b],
        &log,
        "is in 2 messages; name one as MESSAGE.SIGNAL (Motor, Other)",
    );
    fails_with(
        &["plot", dbc, "*Voltage*", "-o", b],
        &log,
        "no signal in the DBC matches '*Voltage*'",
    );
    fails_with(
        &["plot", dbc, "Other.Rpm", "-o", b],
        &log,
        "none of the signals appears in the 200 frames",
    );
    fails_with(
        &[
            "plot",
            dbc,
            "Current",
            "-o",
            dir.join("x.jpg").to_str().unwrap(),
        ],
        &log,
        "must end in .png or .svg",
    );
    let left: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n != "motor.dbc" && n != "motor.png" && n != "motor.svg")
        .collect();
    assert!(left.is_empty(), "{left:?}");
}

#[test]
fn log_cat_and_stats() {
    let input = "(1.000000) can0 123#00\n(1.010000) can0 123#01\n(1.020000) can1 1ABCDEF0##5AA\n\
                 (1.030000) can0 123#R2\n(1.040000) can0 20000080#0000000000000000\n";
    let (code, out, err) = bywire(&["log", "stats"], input);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.starts_with("5 frames (1 FD, 1 remote, 1 error) over 0.040000 s"),
        "{out}"
    );
    assert!(
        out.contains("can0       123            2         10.000"),
        "{out}"
    );
    assert!(out.contains("can0       123 R          1"), "{out}");
    let (_, out, _) = bywire(&["log", "cat", "--filter", "123:7FF"], input);
    assert_eq!(out, "(0000000001.000000) can0 123#00\n(0000000001.010000) can0 123#01\n(0000000001.030000) can0 123#R2\n");
    let (_, out, _) = bywire(
        &["log", "cat", "--screen", "--filter", "1ABCDEF0:1FFFFFFF"],
        input,
    );
    assert_eq!(out, " (0000000001.020000)  can1  1ABCDEF0  [01]  AA\n");
    let (_, out, _) = bywire(
        &["log", "cat", "--nanoseconds"],
        "(1.5 ) x\n(1.000000001) can0 123#00\n",
    );
    assert!(out.is_empty());
    fails_with(
        &["log", "cat"],
        "(1.000000) can0 123#00\n(1.5) can0 12#00\n",
        "standard input: line 2, column 12: frame",
    );
    let (_, out, _) = bywire(
        &["log", "cat", "--nanoseconds"],
        "(1.000000001) can0 123#00\n",
    );
    assert_eq!(out, "(0000000001.000000001) can0 123#00\n");
    fails_with(
        &["log", "cat", "--filter", "12G:7FF"],
        "",
        "filter '12G:7FF'",
    );
}

/// `log stats` reads a file again from its start after sniffing its format, and a pipe given
/// as a path (which cannot seek) on from what was peeked at: the counts are the same.
#[test]
fn log_stats_of_a_file_a_pipe_and_standard_input_agree() {
    let mut input = String::new();
    for i in 0..20_000u32 {
        let id = [0x123, 0x1F0, 0x7FF][usize::try_from(i % 3).unwrap()];
        input.push_str(&format!(
            "({}.{:06}) can{} {id:03X}#{:016X}\n",
            1_700_000_000 + i / 1000,
            (i % 1000) * 1000,
            i % 2,
            u64::from(i) * 0x9E37_79B9
        ));
    }
    let dir = Scratch::new("stats");
    let log = dir.join("in.log");
    std::fs::write(&log, &input).unwrap();
    let (code, from_file, err) = bywire(&["log", "stats", log.to_str().unwrap()], "");
    assert_eq!(code, 0, "{err}");
    assert!(
        from_file.starts_with("20000 frames (0 FD, 0 remote, 0 error) over 19.999000 s"),
        "{from_file}"
    );
    assert!(
        from_file.contains("  can0: 10000 frames\n  can1: 10000 frames\n"),
        "{from_file}"
    );
    let (_, from_stdin, _) = bywire(&["log", "stats"], &input);
    let (_, from_pipe_path, err) = bywire(&["log", "stats", "/dev/stdin"], &input);
    assert_eq!(from_stdin, from_file);
    assert_eq!(from_pipe_path, from_file, "{err}");
}

/// `log cat` writes files in blocks and standard input line by line: the same lines either
/// way, and a bad line ends it with what came before it written.
#[test]
fn log_cat_of_a_file_writes_what_standard_input_does() {
    let mut input: String = (0..5_000u32)
        .map(|i| {
            format!(
                "({}.{:06}) can0 {:03X}#{:08X}\n",
                1 + i / 1000,
                i % 1000,
                i % 0x800,
                i
            )
        })
        .collect();
    input.push_str("(9.000000) can0 12#00\n(9.100000) can0 123#00\n");
    let dir = Scratch::new("cat");
    let log = dir.join("in.log");
    std::fs::write(&log, &input).unwrap();
    let (code, from_file, err) = bywire(&["log", "cat", log.to_str().unwrap()], "");
    assert_ne!(code, 0);
    assert!(err.contains("line 5001, column 17"), "{err}");
    let (_, from_stdin, _) = bywire(&["log", "cat"], &input);
    assert_eq!(from_file.lines().count(), 5_000);
    assert_eq!(from_file, from_stdin);
    assert!(
        from_file.ends_with("(0000000005.000999) can0 387#00001387\n"),
        "{}",
        &from_file[from_file.len() - 80..]
    );
}

#[test]
fn every_help_ends_with_examples_and_a_closed_pipe_is_success() {
    for command in [
        &[][..],
        &["dump"],
        &["send"],
        &["gen"],
        &["play"],
        &["busload"],
        &["sniff"],
        &["monitor"],
        &["plot"],
        &["log"],
        &["log", "cat"],
        &["log", "stats"],
        &["decode"],
        &["dbc"],
        &["wire"],
        &["bittiming"],
        &["bridge"],
    ] {
        let mut args = command.to_vec();
        args.push("--help");
        let (code, out, _) = bywire(&args, "");
        assert_eq!(code, 0, "{args:?}");
        let examples = out
            .split("Examples:\n")
            .nth(1)
            .unwrap_or_else(|| panic!("{args:?}: {out}"));
        assert!(
            examples.lines().next().unwrap().contains("bywire "),
            "{args:?}: {out}"
        );
    }
    // 200,000 lines into `log cat`, whose reader stops after one.
    let script = format!(
        "yes '(1.000000) can0 123#00' | head -200000 | {} log cat | head -1; echo \"${{PIPESTATUS[2]}}\"",
        env!("CARGO_BIN_EXE_bywire")
    );
    let out = Command::new("bash").args(["-c", &script]).output().unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    assert_eq!(text, "(0000000001.000000) can0 123#00\n0\n");
}

#[test]
fn terminal_views_report_bad_input_before_taking_the_terminal() {
    fails_with(&["sniff", "nosuch:x"], "", "unknown bus scheme 'nosuch'");
    fails_with(&["sniff", "vcan0,1:2:3"], "", "filter '1:2:3'");
    fails_with(&["sniff"], "", "no bus given");
    fails_with(
        &["monitor", "/nonexistent.dbc", "virtual:t"],
        "",
        "cannot read /nonexistent.dbc",
    );
    fails_with(
        &["sniff", "-I", "/nonexistent.log"],
        "",
        "cannot open /nonexistent.log",
    );
    // Without a terminal the views say so instead of drawing.
    let m = corpus(MOTOHAWK);
    fails_with(&["monitor", &m, "virtual:t"], "", "needs a terminal");
}

/// Two bywire processes share a `udp:` bus (python-can's udp_multicast format) inside
/// `../shared/tools/lonet.sh`, where the multicast cannot leave the machine.
#[test]
fn dump_and_send_across_processes_over_udp() {
    let bin = env!("CARGO_BIN_EXE_bywire");
    let lonet = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/tools/lonet.sh"
    );
    let script = format!(
        "{bin} dump -T 1500 front=udp:ipv4 > /tmp/udp-dump-$$.txt & P=$!\n\
         for i in $(seq 20); do {bin} send udp:ipv4 7FE#00; sleep 0.1; [ -s /tmp/udp-dump-$$.txt ] && break; done\n\
         {bin} send udp:ipv4 123#DEADBEEF; {bin} send udp:ipv4 1ABCDEF0##5AA\n\
         wait $P; grep -v 7FE /tmp/udp-dump-$$.txt; rm -f /tmp/udp-dump-$$.txt"
    );
    let out = Command::new(lonet)
        .args(["bash", "-c", &script])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(
        lines.last().copied(),
        Some("  front  1ABCDEF0  [01]  AA"),
        "{text}"
    );
    assert!(text.contains("  front  123   [4]  DE AD BE EF\n"), "{text}");
}

/// `bywire serve` on a virtual bus, python-can's socketcand interface as two clients, and a raw
/// TCP client for the BCM cyclic `add` (its period measured) and malformed commands.
#[test]
fn serve_lets_socketcand_clients_share_a_bus() {
    let (server, address) = start_serve(
        "exec \"$BYWIRE\" serve virtual:served --listen 127.0.0.1:0",
        &[],
    );
    let port = address.rsplit(':').next().unwrap();
    let script = format!(
        r#"
import can, socket, time
a = can.Bus(interface="socketcand", host="127.0.0.1", port={port}, channel="served")
b = can.Bus(interface="socketcand", host="127.0.0.1", port={port}, channel="served")
time.sleep(0.3)
a.send(can.Message(arbitration_id=0x123, is_extended_id=False, data=b"\xde\xad\xbe\xef"))
a.send(can.Message(arbitration_id=0x1abcdef0, is_extended_id=True, data=b""))
for _ in range(2):
    m = b.recv(2)
    print("frame", hex(m.arbitration_id), m.is_extended_id, m.data.hex())
s = socket.create_connection(("127.0.0.1", {port}))
print("greeting", s.recv(100).decode())
s.sendall(b"< echo >")
print("before open", s.recv(100).decode())
s.sendall(b"< open served >")
print("open", s.recv(100).decode())
s.sendall(b"< echo >< bogus >< send 12G 0 >< send 123 3 1 2 >< " + b"x" * 300 + b" >< echo >")
time.sleep(0.3)
print("replies", s.recv(1000).decode())
s.sendall(b"< add 0 20000 321 2 aa bb >")
times = []
start = time.time()
while time.time() - start < 1.0:
    m = b.recv(0.5)
    if m is not None and m.arbitration_id == 0x321:
        times.append(m.timestamp)
        assert m.data == b"\xaa\xbb"
s.sendall(b"< delete 321 >")
time.sleep(0.2)
while b.recv(0.05) is not None:
    pass
print("cyclic", len(times), (times[-1] - times[0]) / (len(times) - 1))
print("after delete", b.recv(0.3))
"#
    );
    let out = Command::new("python3")
        .args(["-c", &script])
        .output()
        .unwrap();
    let (status, _) = stop_serve(server);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(status.success());
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], "frame 0x123 False deadbeef");
    assert_eq!(lines[1], "frame 0x1abcdef0 True ");
    assert_eq!(lines[2], "greeting < hi >");
    assert_eq!(lines[3], "before open < error open a bus first >");
    assert_eq!(lines[4], "open < ok >");
    assert_eq!(
        lines[5],
        "replies < echo >< error unknown or malformed command 'bogus' >< error '12G' is not a hex ID >\
         < error length 3 with 2 data bytes (0 to 8, and equal) >< error command too long (at most 256 bytes) >< echo >"
    );
    // 20 ms cyclic frames for one second, measured by their receive times.
    let cyclic: Vec<&str> = lines[6].split_whitespace().collect();
    let count: usize = cyclic[1].parse().unwrap();
    let period: f64 = cyclic[2].parse().unwrap();
    assert!((40..=55).contains(&count), "{}", lines[6]);
    assert!((period - 0.020).abs() < 0.002, "{}", lines[6]);
    assert_eq!(lines[7], "after delete None");
}

#[test]
fn serve_refuses_remote_listening_without_asking() {
    fails_with(
        &["serve", "virtual:x", "--listen", "0.0.0.0:29999"],
        "",
        "add --allow-remote",
    );
    fails_with(&["serve", "nosuch:x"], "", "unknown bus scheme");
}

/// `bywire serve` started by `shell` (a shell command line ending in the serve command); the
/// child and the address it listens on.
fn start_serve(shell: &str, env: &[(&str, &str)]) -> (std::process::Child, String) {
    let mut server = Command::new("sh")
        .args(["-c", shell])
        .env("BYWIRE", env!("CARGO_BIN_EXE_bywire"))
        .envs(env.iter().copied())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = String::new();
    std::io::BufRead::read_line(
        &mut std::io::BufReader::new(server.stdout.as_mut().unwrap()),
        &mut first,
    )
    .unwrap();
    let address = first
        .trim()
        .strip_suffix(" (socketcand)")
        .and_then(|l| l.rsplit(' ').next())
        .unwrap_or_else(|| panic!("{first}"))
        .to_string();
    (server, address)
}

/// Interrupt `server` and return its exit status and what it printed after its first line.
fn stop_serve(mut server: std::process::Child) -> (std::process::ExitStatus, String) {
    let _ = Command::new("kill")
        .args(["-INT", &server.id().to_string()])
        .status();
    let mut rest = String::new();
    std::io::Read::read_to_string(server.stdout.as_mut().unwrap(), &mut rest).unwrap();
    (server.wait().unwrap(), rest)
}

/// One socketcand message from `stream` ("" once the server closed it).
fn message(stream: &mut std::io::BufReader<std::net::TcpStream>) -> String {
    let mut got = Vec::new();
    let _ = std::io::BufRead::read_until(stream, b'>', &mut got);
    String::from_utf8_lossy(&got).trim().to_string()
}

fn connect(address: &str) -> (std::io::BufReader<std::net::TcpStream>, std::net::TcpStream) {
    let stream = std::net::TcpStream::connect(address).unwrap();
    stream
        .set_read_timeout(Some(std::time::Duration::from_secs(5)))
        .unwrap();
    let writer = stream.try_clone().unwrap();
    (std::io::BufReader::new(stream), writer)
}

#[test]
fn serve_keeps_the_token_off_the_command_line_and_other_hosts_behind_one() {
    use std::io::Write;
    fails_with(
        &["serve", "virtual:x", "--token", "s3cret-token"],
        "",
        "--token: a token on the command line is visible to every user of this host",
    );
    fails_with(
        &[
            "serve",
            "virtual:x",
            "--listen",
            "0.0.0.0:0",
            "--allow-remote",
        ],
        "",
        "--allow-remote: other hosts may reach this server only with a token",
    );
    let dir = Scratch::new("serve-token");
    let short = dir.join("short");
    std::fs::write(&short, "abc\n").unwrap();
    fails_with(
        &[
            "serve",
            "virtual:x",
            "--token-file",
            short.to_str().unwrap(),
        ],
        "",
        "at least 8 characters",
    );
    let (code, _, err) = bywire(&["serve", "virtual:x", "--max-clients", "0"], "");
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--max-clients"), "{err}");
    let good = dir.join("token");
    std::fs::write(&good, "correct-horse\n").unwrap();
    for (shell, env) in [
        (
            format!(
                "exec \"$BYWIRE\" serve virtual:tok --listen 127.0.0.1:0 --token-file {}",
                good.display()
            ),
            vec![],
        ),
        (
            "exec \"$BYWIRE\" serve virtual:tok --listen 127.0.0.1:0".to_string(),
            vec![("BYWIRE_SERVE_TOKEN", "correct-horse")],
        ),
    ] {
        let (server, address) = start_serve(&shell, &env);
        let (mut reader, mut writer) = connect(&address);
        assert_eq!(message(&mut reader), "< hi >");
        writer.write_all(b"< open tok >").unwrap();
        assert_eq!(
            message(&mut reader),
            "< error authenticate first with: auth TOKEN >"
        );
        assert_eq!(message(&mut reader), "", "closed after the refusal");
        let (mut reader, mut writer) = connect(&address);
        assert_eq!(message(&mut reader), "< hi >");
        writer
            .write_all(b"< auth correct-horse >< open tok >")
            .unwrap();
        assert_eq!(message(&mut reader), "< ok >");
        assert_eq!(message(&mut reader), "< ok >");
        let (status, rest) = stop_serve(server);
        assert!(status.success());
        assert!(rest.contains("failed authentications 1"), "{rest}");
    }
}

/// With descriptors for only a few clients, a crowd of connections makes `accept` fail with
/// "too many open files": the server waits, counts it and goes on serving.
#[test]
fn serve_survives_running_out_of_descriptors() {
    use std::io::Write;
    let (server, address) = start_serve(
        "ulimit -n 40 && exec \"$BYWIRE\" serve virtual:fds --listen 127.0.0.1:0",
        &[],
    );
    let crowd: Vec<std::net::TcpStream> = (0..60)
        .map(|_| std::net::TcpStream::connect(&address).unwrap())
        .collect();
    std::thread::sleep(std::time::Duration::from_millis(800));
    drop(crowd);
    std::thread::sleep(std::time::Duration::from_millis(1000));
    let (mut reader, mut writer) = connect(&address);
    assert_eq!(message(&mut reader), "< hi >");
    writer.write_all(b"< open fds >< echo >").unwrap();
    assert_eq!(message(&mut reader), "< ok >");
    assert_eq!(message(&mut reader), "< echo >");
    drop((reader, writer));
    let (status, rest) = stop_serve(server);
    assert!(status.success(), "{rest}");
    let errors: u64 = rest
        .rsplit("accept errors ")
        .next()
        .and_then(|n| n.trim().parse().ok())
        .unwrap_or_else(|| panic!("{rest}"));
    assert!(errors > 0, "{rest}");
}

#[test]
fn slcan_adapter_answers_on_its_terminal() {
    let mut adapter = Command::new(env!("CARGO_BIN_EXE_bywire"))
        .args(["slcan-adapter", "virtual:slcan-cli"])
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut path = String::new();
    std::io::BufRead::read_line(
        &mut std::io::BufReader::new(adapter.stdout.as_mut().unwrap()),
        &mut path,
    )
    .unwrap();
    let script = r#"
import serial, sys
port = serial.Serial(sys.argv[1], timeout=2)
for command in [b"V\r", b"S6\r", b"O\r", b"S6\r", b"t1230\r", b"xyz\r", b"C\r"]:
    port.write(command)
    reply = b""
    while not reply.endswith((b"\r", b"\x07")):
        reply += port.read(1)
    print(repr(reply))
"#;
    let out = Command::new("python3")
        .args(["-c", script, path.trim()])
        .output()
        .unwrap();
    let _ = Command::new("kill")
        .args(["-INT", &adapter.id().to_string()])
        .status();
    assert!(adapter.wait().unwrap().success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        text.lines().collect::<Vec<_>>(),
        [
            "b'V1013\\r'",
            "b'\\r'",
            "b'\\r'",
            "b'\\x07'",
            "b'z\\r'",
            "b'\\x07'",
            "b'\\r'"
        ]
    );
}

/// The opt-in discovery beacon, read by python-can's `detect_beacon`.
#[test]
fn serve_beacon_is_found_by_python_can() {
    let port = 29_500 + u16::try_from(std::process::id() % 100).unwrap();
    let beacon_port = 42_100 + u16::try_from(std::process::id() % 100).unwrap();
    let mut server = Command::new(env!("CARGO_BIN_EXE_bywire"))
        .args([
            "serve",
            "virtual:beaconed",
            "--listen",
            &format!("127.0.0.1:{port}"),
            "--name",
            "vcan7",
            "--beacon",
            "--beacon-to",
            &format!("127.0.0.1:{beacon_port}"),
        ])
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let script = format!(
        "import can.interfaces.socketcand.socketcand as s\n\
         s.DEFAULT_SOCKETCAND_DISCOVERY_PORT = {beacon_port}\n\
         print(s.detect_beacon(4000))"
    );
    let out = Command::new("python3")
        .args(["-c", &script])
        .output()
        .unwrap();
    let _ = Command::new("kill")
        .args(["-INT", &server.id().to_string()])
        .status();
    assert!(server.wait().unwrap().success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        text.contains("'host': '127.0.0.1'") && text.contains(&format!("'port': {port}")),
        "{text}"
    );
    assert!(text.contains("'channel': 'vcan7'"), "{text}");
}

/// A line longer than any log line (or not UTF-8) is reported with its number and skipped;
/// the lines around it are read (`decode`, `log stats`).
#[test]
fn an_overlong_or_binary_line_is_skipped_with_its_number() {
    let dbc = common::corpus("cantools/tests__files__dbc__motohawk.dbc");
    let input = format!(
        "(1.000000) can0 1F0#A5B6D90000000000\n{}\n(2.000000) can0 1F0#A5B6D90000000000\n",
        "x".repeat(200_000)
    );
    let (code, out, err) = bywire(&["decode", &dbc], &input);
    assert_eq!(code, 0, "{err}");
    assert_eq!(out.matches("ExampleMessage(").count(), 2, "{out}");
    assert!(err.contains("stdin:2: skipped: 200000 bytes"), "{err}");
    let dir = Scratch::new("long-line");
    let log = dir.join("long.log");
    let mut bytes = input.into_bytes();
    bytes.extend(b"(3.000000) can0 1F0#\xff\n");
    std::fs::write(&log, bytes).unwrap();
    let (_, out, err) = bywire(&["log", "stats", log.to_str().unwrap()], "");
    assert!(
        err.contains("line 2") && err.contains("longer than a log line"),
        "{out}{err}"
    );
    assert!(
        err.contains("line 4") && err.contains("not UTF-8"),
        "{out}{err}"
    );
}

/// Each column chunk's codec in a Parquet file, its rows, and its `ts` column's type, as
/// pyarrow reads them.
fn parquet_summary(path: &Path) -> String {
    let script = "
import sys
import pyarrow.parquet as pq
file = pq.ParquetFile(sys.argv[1])
meta = file.metadata
codecs = {meta.row_group(g).column(c).compression
          for g in range(meta.num_row_groups) for c in range(meta.num_columns)}
print(' '.join(sorted(codecs)), meta.num_rows, file.schema_arrow.field('ts').type)
";
    let read = Command::new("python3")
        .args(["-c", script])
        .arg(path)
        .output()
        .unwrap();
    assert!(read.status.success(), "{read:?}");
    String::from_utf8_lossy(&read.stdout).trim().to_string()
}

/// Each frame sent on `bus` by `bywire send`.
fn send_each(bus: &str, frames: &[&str]) {
    for frame in frames {
        let (code, _, err) = bywire(&["send", bus, frame], "");
        assert_eq!(code, 0, "{err}");
    }
}

/// `dump -f FILE` logs in the format the extension names and finishes the file whichever way
/// the dump ends: after `-n` frames (BLF; Parquet, its pages compressed and its times in the
/// unit asked, as pyarrow reads them), or on Ctrl-C (MCAP, whose summary comes last); `record`
/// compresses a Parquet log as asked too.
#[test]
fn dump_logs_to_any_format_and_finishes_the_file() {
    let (server, address) = start_serve(
        "exec \"$BYWIRE\" serve virtual:dumplog --listen 127.0.0.1:0",
        &[],
    );
    let bus = format!("socketcand:{address}/dumplog");
    let dir = Scratch::new("dump-formats");
    let frames = ["123#DEADBEEF", "1ABCDEF0#0102", "7FF#"];
    let cases = [
        ("out.blf", true, None),
        ("out.mcap", false, None),
        ("out.parquet", true, Some("snappy")),
    ];
    for (file, by_count, compression) in cases {
        let path = dir.join(file);
        let mut args = vec![
            "dump".to_string(),
            bus.clone(),
            "-f".into(),
            path.display().to_string(),
        ];
        if by_count {
            args.extend(["-n".to_string(), "3".to_string()]);
        }
        if let Some(codec) = compression {
            args.extend(["--compression".to_string(), codec.to_string()]);
            args.extend(["--time-unit".to_string(), "us".to_string()]);
        }
        let mut dump = Command::new(env!("CARGO_BIN_EXE_bywire"))
            .args(&args)
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(700));
        send_each(&bus, &frames);
        std::thread::sleep(std::time::Duration::from_millis(500));
        if !by_count {
            let _ = Command::new("kill")
                .args(["-INT", &dump.id().to_string()])
                .status();
        }
        assert!(dump.wait().unwrap().success(), "{file}");
        let (code, text, err) = bywire(&["log", "cat", path.to_str().unwrap()], "");
        assert_eq!(code, 0, "{file}: {err}");
        let got: Vec<&str> = text
            .lines()
            .map(|l| l.rsplit(' ').next().unwrap())
            .collect();
        assert_eq!(got, frames, "{file}: {text}");
        if let Some(codec) = compression {
            let expected = format!("{} 3 timestamp[us, tz=UTC]", codec.to_uppercase());
            assert_eq!(parquet_summary(&path), expected);
        }
    }
    // `record --format parquet` takes the same option.
    let recorded = dir.join("recorded");
    let mut record = Command::new(env!("CARGO_BIN_EXE_bywire"))
        .args([
            "record",
            &bus,
            "--format",
            "parquet",
            "--compression",
            "none",
        ])
        .args(["--duration", "3s", "--quiet", "--name", "run", "--out"])
        .arg(&recorded)
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1_000));
    send_each(&bus, &frames);
    assert!(record.wait().unwrap().success());
    let files: Vec<_> = std::fs::read_dir(&recorded)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "parquet"))
        .collect();
    assert_eq!(files.len(), 1, "{files:?}");
    assert_eq!(
        parquet_summary(&files[0]),
        "UNCOMPRESSED 3 timestamp[ns, tz=UTC]"
    );
    let _ = stop_serve(server);
}

/// An operating system's error is said once: errors whose message carries it no longer give
/// it again as their source ("No such file or directory (os error 2): No such file or
/// directory (os error 2)").
#[test]
fn an_os_error_is_said_once() {
    let (code, _, err) = bywire(
        &[
            "bridge",
            "--profile",
            "reference-tug",
            "virtual:os-error",
            "--key-file",
            "/nonexistent/bywire.key",
            "--freshness-file",
            "/nonexistent/bywire.fv",
        ],
        "",
    );
    assert_eq!(code, 1);
    assert_eq!(err.matches("(os error 2)").count(), 1, "{err}");
    let (code, _, err) = bywire(&["dump", "socketcan:bywire-none0"], "");
    assert_eq!(code, 1);
    assert_eq!(err.matches("(os error").count(), 1, "{err}");
}

/// `log convert --dbc` to a name with an extension no format has is refused, pointing to CSV's
/// command: `dec.csv` silently became a folder of Parquet files.
#[test]
fn a_decoded_conversion_to_an_unknown_extension_is_refused() {
    let dir = Scratch::new("convert-csv");
    let log = dir.join("drive.log");
    std::fs::write(&log, "(1700000000.000000) can0 123#11\n").unwrap();
    let dbc = dir.join("v.dbc");
    std::fs::write(
        &dbc,
        "VERSION \"\"\nBU_: X\nBO_ 291 M: 1 X\n SG_ S : 0|8@1+ (1,0) [0|0] \"\" X\n",
    )
    .unwrap();
    let out = dir.join("dec.csv");
    let convert = |extra: &[&str]| {
        let mut args = vec![
            "log",
            "convert",
            log.to_str().unwrap(),
            out.to_str().unwrap(),
            "--dbc",
            dbc.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        bywire(&args, "")
    };
    let (code, _, err) = convert(&[]);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("not .csv; for CSV: bywire decode"), "{err}");
    assert!(!out.exists());
    // A folder name, or --format parquet, still writes the dataset.
    let (code, said, err) = convert(&["--format", "parquet"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.is_dir());
    // Counts in words: one row, not "1 rows in 1 tables, 1 files".
    assert!(said.contains("1 row in 1 table, 1 file"), "{said}");
}

/// A frame sent on a bus that lives inside the sending process is heard by nobody else: said,
/// with the buses other processes hear (it succeeded without a word).
#[test]
fn sending_on_an_in_process_bus_says_nobody_else_hears_it() {
    let (code, _, err) = bywire(&["send", "virtual:alone", "123#11"], "");
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("virtual:alone is a bus inside this process: no other process hears it"),
        "{err}"
    );
    // A bus of another process (here a server that is not there) is not said to be.
    let (code, _, err) = bywire(&["send", "socketcand:127.0.0.1:1/bus", "123#11"], "");
    assert_eq!(code, 1, "{err}");
    assert!(!err.contains("inside this process"), "{err}");
}
