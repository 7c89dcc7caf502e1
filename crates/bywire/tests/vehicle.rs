//! `bywire vehicle` as an ADS developer uses it: an ADS written with python-can and cantools
//! (`oracles/ads_sweep.py`, no bywire code) engages the simulated reference tug and sweeps its
//! steering from −40° to +40° in 1° steps, reading the actual angle back from the state frame —
//! on the kernel's SocketCAN (vcan in `../shared/tools/canvm.sh`, python-can's socketcan
//! interface) and over `bywire serve` (python-can's socketcand interface).
//!
//! And the bridge's redundancy end to end: bridge and vehicle on two served buses, one server
//! killed mid-run: the bridge reports the lost bus and goes on commanding on the other, and the
//! vehicle keeps following (degraded).
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use std::io::{BufRead, BufReader, Write};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use serde_json::Value;

fn dbc() -> String {
    format!(
        "{}/../bywire-tug/dbc/reference-tug.dbc",
        env!("CARGO_MANIFEST_DIR")
    )
}

fn sweep_script() -> String {
    format!("{}/tests/oracles/ads_sweep.py", env!("CARGO_MANIFEST_DIR"))
}

/// What the sweep saw: engaged, and each of the 81 steps reached, in order.
fn check_sweep(report: &Value) {
    assert_eq!(report["engaged"], true, "{report}");
    let steps = report["steps"].as_array().unwrap();
    assert_eq!(steps.len(), 81, "{report}");
    for (step, target) in steps.iter().zip(-40i64..=40) {
        assert_eq!(step["target"].as_i64(), Some(target));
        assert_eq!(
            step["reached"], true,
            "step {step}; the last state: {}",
            report["last"]
        );
        assert_eq!(
            step["mode"].as_i64(),
            Some(1),
            "autonomous throughout: {step}"
        );
        let actual = step["actual"].as_f64().unwrap();
        assert!((actual - target as f64).abs() < 0.2, "{step}");
    }
    assert_eq!(report["rejected_state"], 0, "every state frame's CRC held");
}

/// A `bywire serve` on a free loopback port; its port.
fn serve(bus: &str) -> (Child, u16) {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let mut server = Command::new(env!("CARGO_BIN_EXE_bywire"))
        .args(["serve", bus, "--listen", &format!("127.0.0.1:{port}")])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = String::new();
    BufReader::new(server.stdout.as_mut().unwrap())
        .read_line(&mut first)
        .unwrap();
    (server, port)
}

fn stop(mut child: Child) {
    let _ = child.kill();
    let _ = child.wait();
}

#[test]
fn a_python_can_ads_sweeps_the_vehicles_steering_over_bywire_serve() {
    let (server, port) = serve("virtual:vehicle-sweep");
    let vehicle = Command::new(env!("CARGO_BIN_EXE_bywire"))
        .args([
            "vehicle",
            "--profile",
            "reference-tug",
            &format!("socketcand:127.0.0.1:{port}/vehicle-sweep"),
            "--rate",
            "0",
        ])
        .spawn()
        .unwrap();
    let out = Command::new("python3")
        .args([
            &sweep_script(),
            &dbc(),
            "socketcand",
            "vehicle-sweep",
            "127.0.0.1",
            &port.to_string(),
        ])
        .output()
        .unwrap();
    stop(vehicle);
    stop(server);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    check_sweep(&serde_json::from_slice(&out.stdout).unwrap());
}

#[test]
fn a_python_can_ads_sweeps_the_vehicles_steering_on_socketcan() {
    let bin = env!("CARGO_BIN_EXE_bywire");
    let python = format!("{}/../../target/vm-python", env!("CARGO_MANIFEST_DIR"));
    assert!(
        std::path::Path::new(&python).join("can").exists(),
        "{python}: python-can for the VM (scripts/install-test-deps.sh installs it)"
    );
    let (dbc, script) = (dbc(), sweep_script());
    let shell = format!(
        "cd /tmp\n{bin} vehicle --profile reference-tug vcan0 --rate 0 --duration 200 &\n\
         PYTHONPATH={python} /usr/bin/python3.11 {script} {dbc} socketcan vcan0\n"
    );
    let options = [
        "--include",
        bin,
        "--include",
        "/usr/bin/python3.11",
        "--include",
        "/usr/lib/python3.11",
        "--include",
        &python,
        "--include",
        &dbc,
        "--include",
        &script,
    ];
    let text = common::in_canvm(&options, &shell);
    let line = text
        .lines()
        .find(|l| l.starts_with("{\"engaged\""))
        .unwrap_or_else(|| panic!("no report in:\n{text}"));
    check_sweep(&serde_json::from_str(line).unwrap());
}

/// `bywire vehicle` or `bywire bridge` for the reference tug on `buses` (the vehicle reports
/// at 10 Hz, the bridge at 20 Hz and reads its commands from stdin).
fn reference_tug(command: &str, buses: &[&str]) -> Child {
    let rate = if command == "vehicle" { "10" } else { "20" };
    Command::new(env!("CARGO_BIN_EXE_bywire"))
        .args([command, "--profile", "reference-tug"])
        .args(buses)
        .args(["--rate", rate])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// The bridge's `k`-th input line, one every 25 ms: drive at 1 m/s, engaging at lines 20, 40
/// and 60 (again, as an ADS would, should the vehicle still have been recovering from its
/// start-up braking: a loaded machine starts the processes more slowly).
fn bridge_input(k: usize) -> &'static str {
    if matches!(k, 20 | 40 | 60) {
        r#"{"engage": true}"#
    } else {
        r#"{"velocity": 1.0, "gear": "drive", "mode": "autonomous"}"#
    }
}

#[test]
fn the_bridge_goes_on_commanding_on_bus_a_when_bus_b_is_lost() {
    let (server_a, port_a) = serve("virtual:lost-a");
    let (server_b, port_b) = serve("virtual:lost-b");
    let a = format!("socketcand:127.0.0.1:{port_a}/lost-a");
    let b = format!("socketcand:127.0.0.1:{port_b}/lost-b");
    let vehicle = reference_tug("vehicle", &[&a, &b]);
    let mut bridge = reference_tug("bridge", &[&a, &b]);
    let mut stdin = bridge.stdin.take().unwrap();
    let mut server_b = Some(server_b);
    for k in 0..200 {
        writeln!(stdin, "{}", bridge_input(k)).unwrap();
        if k == 80 {
            // Bus B's server goes away: its connections break.
            stop(server_b.take().unwrap());
        }
        std::thread::sleep(Duration::from_millis(25));
    }
    drop(stdin);
    let out = bridge.wait_with_output().unwrap();
    stop(vehicle);
    stop(server_a);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    let lines = common::json_lines(out);
    let lost = lines
        .iter()
        .position(|l| l["event"] == "bus_lost")
        .unwrap_or_else(|| panic!("no bus_lost event: {lines:?}"));
    assert!(
        lines[lost]["detail"]
            .as_str()
            .unwrap()
            .contains(&format!("commanding on {a} only")),
        "{}",
        lines[lost]
    );
    assert!(err.contains("lost-b"), "{err}");
    // Before the loss the vehicle drove; a second after it, it still does (degraded: the
    // warning flag set), on commands from bus A alone, its watchdog never tripped.
    let states: Vec<&Value> = lines.iter().filter(|l| l.get("mode").is_some()).collect();
    assert!(
        states[..states.len() / 3]
            .iter()
            .any(|s| s["mode"] == "autonomous"),
        "{states:?}"
    );
    let late: Vec<&&Value> = states[states.len() * 3 / 4..].iter().collect();
    assert!(!late.is_empty());
    for s in &late {
        assert_eq!(s["mode"], "autonomous", "{s}");
        assert_eq!(s["watchdog_level"], 0, "{s}");
        assert_eq!(s["warning"], true, "degraded: {s}");
        assert!((s["velocity"].as_f64().unwrap() - 1.0).abs() < 0.02, "{s}");
    }
    // The vehicle's state frames now come on bus A alone: a vehicle process starved of the
    // processor for a moment (a loaded machine) can leave the last one over three cycles old
    // at a sample, which the bridge rightly reports; most samples see it alive.
    let alive = late.iter().filter(|s| s["feedback_alive"] == true).count();
    assert!(
        alive * 4 >= late.len() * 3,
        "{alive} of {}: {late:?}",
        late.len()
    );
}

/// A vehicle process stopped for 200 ms (ten command cycles; a stall of the machine) and
/// continued: the commands that came meanwhile are taken before it looks at its watchdog,
/// so it goes on driving rather than braking in full for commands that were there all along.
#[test]
fn a_stalled_vehicle_process_takes_the_commands_that_came_meanwhile() {
    let (server, port) = serve("virtual:stalled");
    let bus = format!("socketcand:127.0.0.1:{port}/stalled");
    let vehicle = reference_tug("vehicle", &[&bus]);
    let mut bridge = reference_tug("bridge", &[&bus]);
    let mut stdin = bridge.stdin.take().unwrap();
    let signal = |name: &str| {
        let status = Command::new("kill")
            .args([name, &vehicle.id().to_string()])
            .status()
            .unwrap();
        assert!(status.success());
    };
    for k in 0..160 {
        writeln!(stdin, "{}", bridge_input(k)).unwrap();
        if k == 100 {
            signal("-STOP");
            std::thread::sleep(Duration::from_millis(200));
            signal("-CONT");
        }
        std::thread::sleep(Duration::from_millis(25));
    }
    drop(stdin);
    let out = bridge.wait_with_output().unwrap();
    stop(vehicle);
    stop(server);
    let lines = common::json_lines(out);
    let states: Vec<&Value> = lines.iter().filter(|l| l.get("mode").is_some()).collect();
    // Driving before the stall, and after it to the end: never braked in full (level 3).
    let before = states.len() * 5 / 8;
    assert!(
        states[..before]
            .iter()
            .any(|s| s["mode"] == "autonomous" && s["watchdog_level"] == 0),
        "{states:?}"
    );
    let after = &states[before..];
    assert!(!after.is_empty());
    for s in after {
        assert_eq!(s["mode"], "autonomous", "{s}");
        assert_eq!(s["watchdog_level"], 0, "{s}");
    }
}
