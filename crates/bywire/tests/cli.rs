//! The command line as a user runs it.
// Tests fail by panicking; helpers outside #[test] functions may unwrap too.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

fn bywire(args: &[&str]) -> (i32, String, String) {
    common::bywire(args, "")
}

fn json(args: &[&str]) -> serde_json::Value {
    let (code, out, err) = bywire(args);
    assert_eq!(code, 0, "{err}");
    serde_json::from_str(&out).unwrap()
}

#[test]
fn wire_json_has_the_documented_keys() {
    let j = json(&["wire", "000#", "--bitrate", "500000", "--json"]);
    assert_eq!(
        j["bits"],
        "00000100000100000100000100000100000100001011111111"
    );
    assert_eq!(j["length_bits"], 50);
    assert_eq!(j["stuff_bits"], 6);
    assert_eq!(j["crc"], 0);
    assert_eq!(j["time_ns"], 100_000.0);
    let j = json(&[
        "wire",
        "123##1DEADBEEF",
        "--bitrate",
        "500000",
        "--dbitrate",
        "2000000",
        "--json",
    ]);
    let len = j["length_bits"].as_u64().unwrap() as usize;
    assert_eq!(j["bits"].as_str().unwrap().len(), len);
    assert_eq!(j["crc_width"], 17);
    assert_eq!(j["fixed_stuff_bits"], 6);
    assert!(j["time_ns"].as_f64().unwrap() < len as f64 * 2000.0);
}

#[test]
fn wire_human_output_marks_stuff_bits() {
    let (code, out, _) = bywire(&["wire", "000#"]);
    assert_eq!(code, 0);
    assert!(out.contains("00000[1]"), "{out}");
    assert!(out.contains("length  50 bits"), "{out}");
}

#[test]
fn bittiming_json_has_the_documented_keys() {
    let j = json(&[
        "bittiming",
        "--clock",
        "8000000",
        "--bitrate",
        "500000",
        "--sample-point",
        "0.875",
        "--controller",
        "sja1000",
        "--json",
    ]);
    for (key, value) in [
        ("bitrate", 500_000.0),
        ("sample_point", 0.875),
        ("tq_ns", 125.0),
        ("brp", 1.0),
        ("prop_seg", 6.0),
        ("phase_seg1", 7.0),
        ("phase_seg2", 2.0),
        ("sjw", 1.0),
        ("bitrate_error", 0.0),
    ] {
        assert_eq!(j[key].as_f64(), Some(value), "{key}");
    }
    // Percent works as well as a fraction; FD adds the data phase.
    let j = json(&[
        "bittiming",
        "--clock",
        "80000000",
        "--bitrate",
        "500000",
        "--sample-point",
        "80",
        "--dbitrate",
        "2000000",
        "--json",
    ]);
    assert_eq!(j["sample_point"], 0.8);
    assert_eq!(j["data"]["bitrate"], 2_000_000);
}

#[test]
fn bad_input_is_a_clear_error_with_exit_1() {
    let (code, _, err) = bywire(&["wire", "12G#00"]);
    assert_eq!(code, 1);
    assert!(
        err.contains("column 3") && err.contains("'G' is not a hex digit"),
        "{err}"
    );
    let (code, _, err) = bywire(&[
        "bittiming",
        "--clock",
        "8000000",
        "--bitrate",
        "950000",
        "--controller",
        "sja1000",
    ]);
    assert_eq!(code, 1);
    assert!(err.contains("5.2% off"), "{err}");
    let (code, _, err) = bywire(&[
        "bittiming",
        "--clock",
        "8000000",
        "--bitrate",
        "500000",
        "--controller",
        "nope",
    ]);
    assert_eq!(code, 1);
    assert!(err.contains("unknown controller 'nope'"), "{err}");
    let (code, _, err) = bywire(&[
        "bittiming",
        "--clock",
        "8000000",
        "--bitrate",
        "1000000",
        "--controller",
        "sja1000",
        "--bus-length",
        "40",
    ]);
    assert_eq!(code, 1);
    assert!(err.contains("does not fit"), "{err}");
    assert!(
        err.contains("it fits at 500000 bit/s (--bitrate 500000)"),
        "{err}"
    );
    // What the error suggests fits: a later sample point, or a slower rate.
    let ask = ["bittiming", "--clock", "40000000", "--bus-length", "40"];
    let (code, _, err) = bywire(&[&ask[..], &["--bitrate", "1000000"]].concat());
    assert_eq!(code, 1);
    let suggested = |flag: &str| -> String {
        let after = err.split(&format!("({flag} ")).nth(1).unwrap();
        after.split(')').next().unwrap().to_string()
    };
    for flag in ["--sample-point", "--bitrate"] {
        let value = suggested(flag);
        let mut args = ask.to_vec();
        if flag == "--sample-point" {
            args.extend(["--bitrate", "1000000"]);
        }
        args.extend([flag, value.as_str()]);
        let (code, _, err) = bywire(&args);
        assert_eq!(code, 0, "{args:?}: {err}");
    }
    let (code, _, _) = bywire(&["wire"]);
    assert_eq!(code, 2, "usage errors exit 2");
}

/// Numeric options out of range — huge, tiny, negative, not a number — are usage errors
/// naming the option (they used to reach `Duration::from_secs_f64` and panic).
#[test]
fn numeric_options_out_of_range_are_usage_errors_naming_the_option() {
    let cases: &[(&[&str], &str)] = &[
        (&["gen", "virtual:numbers", "-g", "1e300"], "-g"),
        (&["play", "--speed", "1e-300", "stdout=can0"], "--speed"),
        (&["play", "-t", "-g", "1e300", "stdout=can0"], "-g"),
        (
            &[
                "canopen",
                "node",
                "virtual:numbers",
                "--node",
                "1",
                "--duration=-1",
            ],
            "--duration",
        ),
        (
            &[
                "canopen",
                "node",
                "virtual:numbers",
                "--node",
                "1",
                "--duration",
                "NaN",
            ],
            "--duration",
        ),
        (
            &[
                "canopen",
                "node",
                "virtual:numbers",
                "--node",
                "1",
                "--duration",
                "1e300",
            ],
            "--duration",
        ),
        (
            &[
                "bridge",
                "--profile",
                "reference-tug",
                "virtual:numbers",
                "--rate",
                "1e-300",
            ],
            "--rate",
        ),
        (
            &[
                "vehicle",
                "--profile",
                "reference-tug",
                "virtual:numbers",
                "--duration",
                "inf",
            ],
            "--duration",
        ),
        (&["sim", "--fast", "--max-seconds", "0"], "--max-seconds"),
    ];
    for (args, option) in cases {
        let (code, _, err) = common::bywire(args, "");
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(
            err.contains(option) && !err.contains("panicked"),
            "{args:?}: {err}"
        );
    }
}

/// Shell completions for bash, zsh and fish, generated from the command line's definition;
/// bash completes commands and subcommands with them. Manual pages for every command.
/// `--version` names the commit and features; the commands' summaries say what they do.
#[test]
fn completions_man_pages_version_and_summaries() {
    let dir = common::Scratch::new("shell");
    for shell in ["bash", "zsh", "fish"] {
        let (code, out, err) = bywire(&["completions", shell]);
        assert_eq!(code, 0, "{shell}: {err}");
        assert!(out.contains("bywire") && out.len() > 1000, "{shell}");
    }
    let (_, script, _) = bywire(&["completions", "bash"]);
    let path = dir.join("bywire.bash");
    std::fs::write(&path, script).unwrap();
    let complete = |words: &str| -> String {
        let words: Vec<&str> = words.split(' ').collect();
        let line = words.join(" ");
        let test = format!(
            "source {}; COMP_WORDS=({}); COMP_CWORD={}; COMP_LINE='{line}'; COMP_POINT={}; \
             _bywire bywire {} {}; echo \"${{COMPREPLY[@]}}\"",
            path.display(),
            words.join(" "),
            words.len() - 1,
            line.len(),
            words[words.len() - 1],
            words[words.len() - 2],
        );
        let out = std::process::Command::new("bash")
            .args(["-c", &test])
            .output()
            .unwrap();
        String::from_utf8_lossy(&out.stdout).trim().to_string()
    };
    assert_eq!(complete("bywire lo"), "log");
    assert_eq!(complete("bywire log c"), "cat convert");
    // A command's options: candump's -L among dump's.
    let options = complete("bywire dump -");
    assert!(options.split(' ').any(|o| o == "-L"), "{options}");
    let man = dir.join("man");
    let (code, out, err) = bywire(&["man", man.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("pages in"), "{out}");
    let page = std::fs::read_to_string(man.join("bywire-log-convert.1")).unwrap();
    assert!(
        page.contains(".SH NAME") && page.contains("bywire\\-log\\-convert"),
        "{page}"
    );
    assert!(man.join("bywire.1").exists() && man.join("bywire-ros2-vehicle.1").exists());
    let (code, version, _) = bywire(&["--version"]);
    assert_eq!(code, 0);
    assert!(
        version.starts_with("bywire 0.")
            && version.contains("commit ")
            && version.contains("features: ros2"),
        "{version}"
    );
    let (_, help, _) = bywire(&["--help"]);
    for (command, says) in [
        ("dbc", "dump, lint, convert"),
        ("log", "Logs of any format"),
        ("uds", "a tester"),
        ("ros2", "vehicle interface, CANopen drives"),
    ] {
        let line = help
            .lines()
            .find(|l| l.trim_start().starts_with(&format!("{command} ")))
            .unwrap();
        assert!(line.contains(says), "{line}");
    }
}
