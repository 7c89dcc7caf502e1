//! `bywire replay`: a simulated session's command bus through the profile's supervisor, its
//! trace the same on every run, a stored trace matched, and a changed limit found at the
//! first command it decides otherwise.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::Scratch;

use std::path::Path;
use std::process::{Command, Output};

fn bywire(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_bywire"))
        .args(args)
        .output()
        .unwrap()
}

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Verifies: REQ-REP-1.
#[test]
fn a_replayed_session_gives_one_trace_and_a_changed_limit_shows_where_it_decides_otherwise() {
    let dir = Scratch::new("replay");
    let run = dir.join("run");
    let sim = bywire(&[
        "sim",
        "--fast",
        "--no-view",
        "--seed",
        "1",
        "--out",
        path(&run),
    ]);
    assert!(
        sim.status.success(),
        "{}",
        String::from_utf8_lossy(&sim.stderr)
    );
    let log = run.join("bus1.log");
    let traces = [dir.join("a.trace"), dir.join("b.trace")];
    for trace in &traces {
        let out = bywire(&[
            "replay",
            path(&log),
            "--profile",
            "reference-tug",
            "--out",
            path(trace),
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let text = std::fs::read_to_string(&traces[0]).unwrap();
    assert_eq!(text, std::fs::read_to_string(&traces[1]).unwrap());
    let lines: Vec<&str> = text.lines().collect();
    let count = |what: &str| lines.iter().filter(|l| l.contains(what)).count();
    // The tug engaged and drove the loop on commands the supervisor took, every one of them.
    assert!(count(" mode Autonomous") == 1, "{}", &text[..400]);
    assert!(
        count(" command accepted") > 2_500,
        "{}",
        count(" command accepted")
    );
    assert_eq!(count(" command refused"), 0);
    // Its state frame every 20 ms.
    assert!(count(" sent 0 101 ") > 2_500);

    // Both command buses: each command's copy on bus 1b voted with its original (--bus-b),
    // none refused; given as one bus, every copy is a repeated counter.
    let bus1b = run.join("bus1b.log");
    let both = |bus_b: &[&str]| {
        let mut args = vec![
            "replay",
            path(&log),
            path(&bus1b),
            "--profile",
            "reference-tug",
        ];
        args.extend_from_slice(bus_b);
        let out = bywire(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let text = String::from_utf8(out.stdout).unwrap();
        let count = |what: &str| text.lines().filter(|l| l.contains(what)).count();
        (
            count(" command accepted"),
            count(" command refused: repeated counter"),
        )
    };
    let accepted = count(" command accepted");
    assert_eq!(both(&["--bus-b", "bus1b"]), (accepted, 0));
    assert_eq!(both(&[]), (accepted, accepted));

    // The stored trace matches: nothing printed, exit 0.
    let same = bywire(&[
        "replay",
        path(&log),
        "--profile",
        "reference-tug",
        "--expect",
        path(&traces[0]),
    ]);
    assert!(
        same.status.success(),
        "{}",
        String::from_utf8_lossy(&same.stderr)
    );
    assert!(same.stdout.is_empty());

    // The same profile with a steering limit of 5° (its DBC beside it): the first command
    // beyond it is refused, and that is the line named.
    let profile = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../bywire-tug/profiles/reference-tug.toml"),
    )
    .unwrap();
    assert!(profile.contains("steering_deg = 40.0"));
    let narrow = dir.join("narrow.toml");
    std::fs::write(
        &narrow,
        profile.replace("steering_deg = 40.0", "steering_deg = 5.0"),
    )
    .unwrap();
    std::fs::copy(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../bywire-tug/dbc/reference-tug.dbc"),
        dir.join("reference-tug.dbc"),
    )
    .unwrap();
    let changed = bywire(&[
        "replay",
        path(&log),
        "--profile",
        path(&narrow),
        "--expect",
        path(&traces[0]),
    ]);
    assert_eq!(changed.status.code(), Some(1));
    let err = String::from_utf8_lossy(&changed.stderr);
    let narrow_trace = bywire(&["replay", path(&log), "--profile", path(&narrow)]);
    let narrow_text = String::from_utf8(narrow_trace.stdout).unwrap();
    let first = lines
        .iter()
        .zip(narrow_text.lines())
        .position(|(a, b)| *a != b)
        .expect("the narrow limit changed nothing");
    assert!(
        narrow_text
            .lines()
            .nth(first)
            .unwrap()
            .ends_with(" command refused: out of range"),
        "{}",
        narrow_text.lines().nth(first).unwrap()
    );
    assert!(
        err.contains(&format!("line {}: expected '{}'", first + 1, lines[first])),
        "{err}"
    );
}

#[test]
fn the_fuzzer_finds_the_ads_side_and_the_vehicle_agreed_and_says_so() {
    let out = bywire(&["replay", "--fuzz", "2000", "--profile", "reference-tug"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        text.starts_with("reference-tug: 2000 commands (seed 1), ")
            && text.contains(", 0 disagreements"),
        "{text}"
    );
    // A log and --fuzz are one or the other.
    let both = bywire(&[
        "replay",
        "x.log",
        "--fuzz",
        "10",
        "--profile",
        "reference-tug",
    ]);
    assert_eq!(both.status.code(), Some(2));
}
