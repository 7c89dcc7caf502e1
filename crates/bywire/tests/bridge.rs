//! `bywire bridge` end to end: JSON commands streamed in real time to the ADS side, a simulated
//! vehicle (the real supervisor) on the same bit-timed bus, vehicle state out as JSON lines.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use std::io::Write;
use std::process::{Command, Stdio};
use std::time::Duration;

use serde_json::Value;

#[test]
fn bridge_engages_a_simulated_vehicle_and_brakes_at_end_of_input() {
    let mut child = Command::new(env!("CARGO_BIN_EXE_bywire"))
        .args([
            "bridge",
            "--profile",
            "reference-tug",
            "sim:bridge-test@500000",
            "--with-vehicle",
            "--estop-on-eof",
            "--rate",
            "20",
        ])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    // Commands must keep coming (a command older than 200 ms becomes a controlled stop).
    let drive = r#"{"velocity": 1.5, "gear": "drive", "mode": "autonomous", "steering": 5.0}"#;
    for k in 0..60 {
        let line = match k {
            20 => r#"{"engage": true}"#,
            30 => "not json",
            _ => drive,
        };
        writeln!(stdin, "{line}").unwrap();
        std::thread::sleep(Duration::from_millis(25));
    }
    drop(stdin);
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let lines: Vec<Value> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let states: Vec<&Value> = lines.iter().filter(|l| l.get("mode").is_some()).collect();
    // Manual and braked at first (the vehicle fails closed), then autonomous at the commanded
    // speed with the steering reached.
    assert!(states
        .iter()
        .any(|s| s["mode"] == "manual" && s["watchdog_level"] == 4));
    let driving: Vec<&&Value> = states
        .iter()
        .filter(|s| s["mode"] == "autonomous" && s["velocity"] == 1.5)
        .collect();
    assert!(!driving.is_empty(), "never drove: {states:?}");
    assert!(driving
        .iter()
        .any(|s| (s["steering"].as_f64().unwrap() - 5.0).abs() < 0.05));
    // Real time on a shared machine: a late thread can age a frame past its timeout now and
    // then (the exact timing is tested in simulated time); most states must be fresh.
    let alive = driving
        .iter()
        .filter(|s| s["feedback_alive"] == true)
        .count();
    assert!(
        alive * 10 >= driving.len() * 8,
        "{alive} of {} fresh",
        driving.len()
    );
    let latency = driving.last().unwrap()["echo_latency_ms"].as_f64().unwrap();
    assert!(latency < 100.0, "{latency} ms");
    // The bad line is reported with its number; the end of input brakes.
    assert!(lines
        .iter()
        .any(|l| l["event"] == "bad_command"
            && l["detail"].as_str().unwrap().starts_with("line 31:")));
    let end = lines
        .iter()
        .position(|l| l["event"] == "end_of_input")
        .unwrap();
    let after: Vec<&Value> = lines[end..]
        .iter()
        .filter(|l| l.get("velocity").is_some())
        .collect();
    assert!(after.last().unwrap()["velocity"] == 0.0, "{after:?}");
}

#[test]
fn bridge_refuses_bad_arguments_clearly() {
    let (code, _, err) = common::bywire(&["bridge", "--profile", "hovercraft", "virtual:x"], "");
    assert_eq!(code, 1);
    assert!(err.contains("no built-in profile 'hovercraft'"), "{err}");
    let (code, _, err) = common::bywire(&["bridge", "--profile", "autoware-can", "virtual:x"], "");
    assert_eq!(code, 1);
    assert!(err.contains("no [command] section"), "{err}");
    let (code, _, err) = common::bywire(
        &[
            "bridge",
            "--profile",
            "reference-tug",
            "socketcan:can9",
            "--with-vehicle",
        ],
        "",
    );
    assert_eq!(code, 1);
    assert!(err.contains("can9") || err.contains("in-process"), "{err}");
    let (code, _, err) = common::bywire(&["bridge", "--profile", "reference-tug", "bus"], "");
    assert_eq!(code, 1);
    assert!(err.contains("not a bus spec"), "{err}");
    // Without --estop-on-eof, the end of input just ends the bridge.
    let (code, out, _) = common::bywire(
        &["bridge", "--profile", "reference-tug", "virtual:quiet"],
        "",
    );
    assert_eq!(code, 0);
    assert!(!out.contains("end_of_input"));
}

#[test]
fn bridge_drives_over_two_redundant_buses() {
    let mut child = Command::new(env!("CARGO_BIN_EXE_bywire"))
        .args([
            "bridge",
            "--profile",
            "reference-tug",
            "sim:redundant-a@500000",
            "sim:redundant-b@500000",
            "--with-vehicle",
            "--rate",
            "20",
        ])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let drive = r#"{"velocity": 1.0, "gear": "drive", "mode": "autonomous"}"#;
    for k in 0..50 {
        let line = if k == 20 {
            r#"{"engage": true}"#
        } else {
            drive
        };
        writeln!(stdin, "{line}").unwrap();
        std::thread::sleep(Duration::from_millis(25));
    }
    drop(stdin);
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success());
    let states: Vec<Value> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .filter(|v: &Value| v.get("mode").is_some())
        .collect();
    // Both copies agree: the vehicle drives, not degraded (no warning), and the feedback
    // that arrives twice is taken once (no counter rejections).
    let driving: Vec<&Value> = states
        .iter()
        .filter(|s| s["mode"] == "autonomous" && s["velocity"] == 1.0)
        .collect();
    assert!(!driving.is_empty(), "{states:?}");
    assert!(driving.iter().any(|s| s["warning"] == false));
    assert_eq!(states.last().unwrap()["rejected"]["counter"], 0);
}
