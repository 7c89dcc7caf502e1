//! `bywire decode` and `bywire dbc dump` as a user runs them, on corpus files.
// Tests fail by panicking; helpers outside #[test] functions may unwrap too.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::process::Command;

mod common;

use common::{corpus, Scratch};

fn run(args: &[&str], input: &str) -> (i32, String, String) {
    common::bywire(args, input)
}

const MOTOHAWK: &str = "cantools/tests__files__dbc__motohawk.dbc";

/// The items after `::` of a single-line decode, as a set.
fn items(line: &str) -> std::collections::BTreeSet<String> {
    let decoded = line.split(" :: ").nth(1).unwrap();
    let inner = decoded.split_once('(').unwrap().1.trim_end_matches(')');
    inner.split(", ").map(str::to_string).collect()
}

#[test]
fn decode_agrees_with_cantools_decode() {
    let frames = [
        "(1600000000.000000) vcan0 1F0#A5B6D90000000000",
        "(1600000000.000000) vcan0 1F0#0000000000000000",
        "(1600000000.000000) vcan0 1F0#FFFFFFFFFFFFFFFF",
        "(1600000000.000000) vcan0 1F0#7F12C40000000000",
    ];
    let input = frames.join("\n") + "\n";
    let (code, ours, err) = run(&["decode", &corpus(MOTOHAWK), "--single-line"], &input);
    assert_eq!(code, 0, "{err}");
    let (code, theirs, err) = common::run_with_input(
        Command::new("python3").args([
            "-m",
            "cantools",
            "decode",
            "--single-line",
            &corpus(MOTOHAWK),
        ]),
        &input,
    );
    assert_eq!(
        code, 0,
        "cantools is installed (scripts/install-test-deps.sh): {err}"
    );
    assert_eq!(theirs.lines().count(), frames.len(), "{theirs}");
    // The same text: signals in cantools' order (by start bit in network order; motohawk's
    // big-endian signals are not listed so in the file).
    assert_eq!(ours, theirs);
}

#[test]
fn decode_reads_the_screen_form_and_passes_other_lines_through() {
    let input = "(1600000000.000000) vcan0 1F0#A5B6D90000000000\n  vcan0  1F0   [8]  A5 B6 D9 00 00 00 00 00\nhello\n";
    let (code, out, _) = run(&["decode", &corpus(MOTOHAWK), "--single-line"], input);
    assert_eq!(code, 0);
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(items(lines[0]), items(lines[1]));
    assert_eq!(lines[2], "hello");
}

#[test]
fn decode_json_objects_and_errors() {
    let input = "(0.0) vcan0 1F0#A5B6D90000000000\n(0.0) vcan0 1F0#A5B6\n(0.0) vcan0 123#00\n";
    let (code, out, _) = run(&["decode", &corpus(MOTOHAWK), "--json"], input);
    assert_eq!(code, 0);
    let objects: Vec<serde_json::Value> = out
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(objects[0]["id"], 0x1F0);
    assert_eq!(objects[0]["extended"], false);
    assert_eq!(objects[0]["name"], "ExampleMessage");
    assert_eq!(objects[0]["signals"]["Enable"], 1);
    assert_eq!(objects[0]["signals"]["AverageRadius"], 1.8);
    assert!(objects[1]["error"]
        .as_str()
        .unwrap()
        .contains("2 bytes, but the message has 8"));
    assert_eq!(objects[2]["error"], "unknown message");
}

/// Output is written in blocks but never held while the input waits: a frame piped in from a
/// live bus is decoded before the next one comes (stdin stays open throughout).
#[test]
fn decode_answers_each_line_of_a_live_pipe() {
    use std::io::{BufRead, Write};
    let mut child = Command::new(env!("CARGO_BIN_EXE_bywire"))
        .args(["decode", &corpus(MOTOHAWK), "--json"])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let (lines, answers) = std::sync::mpsc::channel();
    let stdout = child.stdout.take().unwrap();
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(stdout).lines() {
            if lines.send(line.unwrap()).is_err() {
                break;
            }
        }
    });
    for data in ["A5B6D90000000000", "0000000000000000", "FFFFFFFFFFFFFFFF"] {
        writeln!(stdin, "(1600000000.000000) vcan0 1F0#{data}").unwrap();
        stdin.flush().unwrap();
        let answer = answers
            .recv_timeout(std::time::Duration::from_secs(20))
            .expect("no answer while the input stays open");
        let object: serde_json::Value = serde_json::from_str(&answer).unwrap();
        assert_eq!(object["name"], "ExampleMessage", "{answer}");
    }
    drop(stdin);
    assert!(child.wait().unwrap().success());
}

/// Many lines through standard input (blocks of output, lines lent from the input's buffer)
/// give what the same log gives read as a file with `-I`.
#[test]
fn decode_of_standard_input_equals_decode_of_the_file() {
    let mut log = String::new();
    for n in 0..20_000u32 {
        let data = format!("{:016X}", u64::from(n).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        let id = if n % 3 == 0 { "123" } else { "1F0" };
        log.push_str(&format!(
            "({}.{:06}) vcan{} {id}#{data}\n",
            1_600_000_000 + n / 1000,
            n % 1000,
            n % 2
        ));
    }
    let dir = Scratch::new("decode-stdin");
    let file = dir.join("in.log");
    std::fs::write(&file, &log).unwrap();
    let (code, piped, err) = run(&["decode", &corpus(MOTOHAWK), "--json"], &log);
    assert_eq!(code, 0, "{err}");
    let (code, read, err) = run(
        &[
            "decode",
            &corpus(MOTOHAWK),
            "--json",
            "-I",
            file.to_str().unwrap(),
        ],
        "",
    );
    assert_eq!(code, 0, "{err}");
    assert_eq!(piped.lines().count(), 20_000);
    assert_eq!(piped, read);
}

#[test]
fn dump_is_lenient_by_default_and_strict_on_request() {
    // cantools refuses this file (a signal comment without a signal name).
    let broken = corpus("opendbc_generated/acura_ilx_2016_can_generated.dbc");
    let (code, out, err) = run(&["dbc", "dump", &broken], "");
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("Name:       STEERING_CONTROL"), "{out}");
    assert!(
        err.contains("signal comment without a signal name"),
        "{err}"
    );
    assert!(err
        .lines()
        .next()
        .unwrap()
        .starts_with(&format!("{broken}:")));
    let (code, _, err) = run(&["dbc", "dump", "--strict", &broken], "");
    assert_eq!(code, 1);
    let position = err
        .trim_start_matches("error: ")
        .trim_start_matches(&broken);
    assert!(
        position.starts_with(':')
            && position[1..]
                .split(':')
                .next()
                .unwrap()
                .parse::<u32>()
                .unwrap()
                > 0,
        "{err}"
    );
}

#[test]
fn dump_draws_the_layout() {
    let (code, out, _) = run(&["dbc", "dump", &corpus(MOTOHAWK)], "");
    assert_eq!(code, 0);
    assert!(out.contains("       0 |>C >B  B  B  B  B  B >A |"), "{out}");
    assert!(out.contains("      A = Temperature"));
}

#[test]
fn lint_reports_positions_and_fails_on_errors() {
    // A corpus file with overlapping signals (cantools refuses it in strict mode).
    let file = corpus("opendbc/opendbc__dbc__generator__honda___steering_control_c.dbc");
    let (code, out, _) = run(&["dbc", "lint", &file], "");
    assert_eq!(code, 1);
    let overlap = out
        .lines()
        .find(|l| l.contains("[overlap]"))
        .expect("an overlap finding");
    let position: Vec<&str> = overlap.trim_start_matches(&file).splitn(4, ':').collect();
    assert!(
        position[1].parse::<u32>().unwrap() > 0 && position[2].parse::<u32>().unwrap() > 0,
        "{overlap}"
    );
    let (code, _, _) = run(&["dbc", "lint", &corpus(MOTOHAWK)], "");
    assert_eq!(code, 0);
}

#[test]
fn convert_dbc_to_json_and_back() {
    let dir = Scratch::new("convert");
    let (json, dbc) = (dir.join("m.json"), dir.join("m.dbc"));
    let (code, _, err) = run(
        &["dbc", "convert", &corpus(MOTOHAWK), json.to_str().unwrap()],
        "",
    );
    assert_eq!(code, 0, "{err}");
    let value: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(value["messages"][0]["name"], "ExampleMessage");
    assert_eq!(value["messages"][0]["signals"][0]["factor"], 0.01);
    let (code, _, err) = run(
        &[
            "dbc",
            "convert",
            json.to_str().unwrap(),
            dbc.to_str().unwrap(),
        ],
        "",
    );
    assert_eq!(code, 0, "{err}");
    let (_, from_original, _) = run(&["dbc", "dump", &corpus(MOTOHAWK)], "");
    let (_, from_converted, _) = run(&["dbc", "dump", dbc.to_str().unwrap()], "");
    // The same but for the first line, which names the file.
    let after_name = |dump: &str| dump.split_once('\n').map(|(_, rest)| rest.to_string());
    assert_eq!(after_name(&from_original), after_name(&from_converted));
    // Through JSON and back, a file's numbers are exactly what they were: 0.39215686274509803
    // (1/2.55) in VW's MLB file once came back as 0.392156862745098.
    let vw = corpus("opendbc/opendbc__dbc__vw_mlb.dbc");
    let direct = dir.join("direct.dbc");
    for (from, to) in [
        (vw.as_str(), json.to_str().unwrap()),
        (json.to_str().unwrap(), dbc.to_str().unwrap()),
        (vw.as_str(), direct.to_str().unwrap()),
    ] {
        let (code, _, err) = run(&["dbc", "convert", from, to], "");
        assert_eq!(code, 0, "{err}");
    }
    let through_json = std::fs::read_to_string(&dbc).unwrap();
    assert!(through_json.contains("(0.39215686274509803,0)"));
    assert_eq!(through_json, std::fs::read_to_string(&direct).unwrap());
    // A bad output name fails without leaving a file.
    let (code, _, err) = run(
        &[
            "dbc",
            "convert",
            &corpus(MOTOHAWK),
            dir.join("m.txt").to_str().unwrap(),
        ],
        "",
    );
    assert_eq!(code, 1);
    assert!(err.contains("must end in .dbc, .kcd, .sym or .json"));
    assert!(!dir.join("m.txt").exists() && !dir.join("m.partial").exists());
    // Broken JSON names its line and column.
    std::fs::write(&json, "{\n  \"version\": 3\n}").unwrap();
    let (code, _, err) = run(
        &[
            "dbc",
            "convert",
            json.to_str().unwrap(),
            dbc.to_str().unwrap(),
        ],
        "",
    );
    assert_eq!(code, 1);
    assert!(err.contains("m.json:2:"), "{err}");
}

#[test]
fn gen_rust_prints_a_module() {
    let (code, out, _) = run(&["dbc", "gen-rust", &corpus(MOTOHAWK)], "");
    assert_eq!(code, 0);
    assert!(
        out.contains("pub struct ExampleMessage(pub [u8; 8]);"),
        "{out}"
    );
    assert!(out.contains("pub fn set_temperature(&mut self, value: f64) -> Result<(), OutOfRange>"));
}

/// A file the parser reports errors in (a 99-bit signal, a duplicate identifier) fails lint
/// with those errors counted, and is not converted (nothing written).
#[test]
fn parser_errors_fail_lint_and_convert() {
    let dir = Scratch::new("parse-errors");
    let dbc = dir.join("broken.dbc");
    std::fs::write(
        &dbc,
        "BO_ 100 A: 8 X\n SG_ Wide : 0|99@1+ (1,0) [0|0] \"\" X\nBO_ 100 B: 8 X\n SG_ S : 0|8@1+ (1,0) [0|0] \"\" X\n",
    )
    .unwrap();
    let path = dbc.to_str().unwrap();
    let (code, _, err) = common::bywire(&["dbc", "lint", path], "");
    assert_eq!(code, 1, "{err}");
    assert!(
        err.contains("error(s)") && !err.contains(" 0 error"),
        "{err}"
    );
    let json = dir.join("broken.json");
    let (code, _, err) = common::bywire(&["dbc", "convert", path, json.to_str().unwrap()], "");
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("not converted"), "{err}");
    assert!(!json.exists() && !dir.join("broken.partial").exists());
}

/// Value descriptions are looked up by the raw value, as cantools does, not by the physical
/// one: Ford's `ActChrgStrtDay_No_Actl` (offset 1) with raw 30 is 31 days, while "Invalid"
/// belongs to raw 31 (regression: the text output printed "Invalid").
#[test]
fn value_descriptions_match_the_raw_value_as_cantools_does() {
    let dbc = common::corpus("opendbc/opendbc__dbc__ford_lincoln_base_pt.dbc");
    let log = "(1.000000) can0 473#00000000001E0000\n(2.000000) can0 473#00000000001F0000\n";
    let (code, ours, err) = common::bywire(&["decode", &dbc], log);
    assert_eq!(code, 0, "{err}");
    let mut cantools = std::process::Command::new("python3")
        .args(["-m", "cantools", "decode", &dbc])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::io::Write::write_all(cantools.stdin.as_mut().unwrap(), log.as_bytes()).unwrap();
    let theirs = String::from_utf8(cantools.wait_with_output().unwrap().stdout).unwrap();
    // The same signal lines, whatever their order.
    let lines = |text: &str| {
        let mut v: Vec<String> = text
            .lines()
            .filter(|l| l.starts_with("    "))
            .map(|l| l.trim().trim_end_matches(',').to_string())
            .collect();
        v.sort();
        v
    };
    assert_eq!(lines(&ours), lines(&theirs));
    assert!(ours.contains("ActChrgStrtDay_No_Actl: 31 days"), "{ours}");
    assert!(
        ours.contains("ActChrgStrtDay_No_Actl: Invalid"),
        "raw 31: {ours}"
    );
}

/// A signal name used twice in one message: a warning with its position when the DBC loads,
/// and both values in the output (text and JSON; JSON names the second `NAME#2`).
#[test]
fn a_signal_name_used_twice_keeps_both_values() {
    let dir = Scratch::new("dup-signal");
    let dbc = dir.join("dup.dbc");
    std::fs::write(
        &dbc,
        "VERSION \"\"\nBU_: A\nBO_ 291 M: 2 A\n SG_ S : 0|8@1+ (1,0) [0|255] \"\" A\n SG_ S : 8|8@1+ (1,0) [0|255] \"\" A\n",
    )
    .unwrap();
    let dbc = dbc.to_str().unwrap();
    let input = "(1.000000) can0 123#0A0B\n";
    let (code, out, err) = run(&["decode", dbc, "--json"], input);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("dup.dbc:5:"), "{err}");
    let value: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!(value["signals"], serde_json::json!({"S": 10, "S#2": 11}));
    let (_, out, _) = run(&["decode", dbc, "--single-line"], input);
    assert!(out.contains("M(S: 10, S: 11)"), "{out}");
}

/// KCD and SYM through the command line: a DBC converted to each (what it cannot say named on
/// stderr), every command reading the result by its extension, `--db-format` forcing a reader.
#[test]
fn kcd_and_sym_convert_and_decode_like_the_dbc() {
    let dir = Scratch::new("dbc-formats");
    let frames = "(1.000000) can0 1F0#A5E0C8FF12345678\n(1.100000) can0 1F0#0000000000000000\n";
    let (code, from_dbc, err) = run(&["decode", &corpus(MOTOHAWK)], frames);
    assert_eq!(code, 0, "{err}");
    for extension in ["kcd", "sym"] {
        let converted = dir.join(format!("motohawk.{extension}"));
        let (code, _, err) = run(
            &[
                "dbc",
                "convert",
                &corpus(MOTOHAWK),
                converted.to_str().unwrap(),
            ],
            "",
        );
        assert_eq!(code, 0, "{err}");
        // SYM has no nodes; KCD says all motohawk.dbc says.
        assert_eq!(
            err.contains("left out what SYM cannot say: 2 nodes"),
            extension == "sym",
            "{err}"
        );
        let (code, decoded, err) = run(&["decode", converted.to_str().unwrap()], frames);
        assert_eq!(code, 0, "{err}");
        assert_eq!(decoded, from_dbc, "{extension}");
        // Named otherwise, the file is still found by its content, or by --db-format.
        let renamed = dir.join(format!("motohawk-{extension}.db"));
        std::fs::copy(&converted, &renamed).unwrap();
        let (_, decoded, _) = run(&["decode", renamed.to_str().unwrap()], frames);
        assert_eq!(decoded, from_dbc, "{extension} by content");
        // dump says which reader read it.
        let (code, dumped, err) = run(&["dbc", "dump", renamed.to_str().unwrap()], "");
        assert_eq!(code, 0, "{err}");
        let said = format!("({}, 1 messages)", extension.to_uppercase());
        assert!(dumped.lines().next().unwrap().ends_with(&said), "{dumped}");
        let (_, decoded, _) = run(
            &[
                "--db-format",
                extension,
                "decode",
                renamed.to_str().unwrap(),
            ],
            frames,
        );
        assert_eq!(decoded, from_dbc, "{extension} forced");
    }
    let (code, _, err) = run(
        &["--db-format", "xls", "dbc", "dump", &corpus(MOTOHAWK)],
        "",
    );
    assert_eq!(code, 2);
    assert!(
        err.contains("not a database format (dbc, kcd, sym, arxml, cdd)"),
        "{err}"
    );
    // A DBC forced to be read as ARXML: the XML error, with its position.
    let (code, _, err) = run(
        &["--db-format", "arxml", "dbc", "dump", &corpus(MOTOHAWK)],
        "",
    );
    assert_eq!(code, 1);
    assert!(err.contains(":1:1: error: not well-formed XML"), "{err}");
}
