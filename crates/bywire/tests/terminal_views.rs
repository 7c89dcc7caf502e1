//! `bywire monitor` and `bywire sniff` end to end in a real terminal: tmux runs them on a log,
//! the test reads the screen (capture-pane) and presses keys (send-keys).
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::process::Command;
use std::time::{Duration, Instant};

mod common;

use common::{Scratch, Session};

/// A DBC and a log of 20 s: Speed every 10 ms counting up, Gear once; in their folder.
fn fixture(name: &str) -> (Scratch, String, String) {
    let dir = Scratch::new(name);
    let dbc = dir.join("views.dbc");
    std::fs::write(
        &dbc,
        "VERSION \"\"\nBU_: ECU\nBO_ 291 Speed: 2 ECU\n SG_ Kph : 0|16@1+ (0.1,0) [0|6553.5] \"km/h\" X\n\
         BO_ 292 Gear: 1 ECU\n SG_ Position : 0|8@1+ (1,0) [0|3] \"\" X\n\
         VAL_ 292 Position 0 \"Park\" 1 \"Drive\" ;\n",
    )
    .unwrap();
    let mut fixed = String::from("(1000.000000) can0 124#01\n");
    for i in 0..2000u64 {
        let t = 1_000_000_000 + i * 10_000;
        fixed += &format!(
            "({}.{:06}) can0 123#{:02X}{:02X}\n",
            t / 1_000_000,
            t % 1_000_000,
            i % 256,
            i / 256
        );
    }
    let path = dir.join("views.log");
    std::fs::write(&path, fixed).unwrap();
    let (dbc, path) = (
        dbc.to_str().unwrap().to_string(),
        path.to_str().unwrap().to_string(),
    );
    (dir, dbc, path)
}

#[test]
fn monitor_in_a_terminal() {
    let (_dir, dbc, log) = fixture("monitor");
    let bin = env!("CARGO_BIN_EXE_bywire");
    let s = Session::start("bywire-monitor", &format!("{bin} monitor {dbc} -I {log}"));
    let screen = s.wait_for("Position: Drive");
    assert!(screen.contains("bywire monitor"), "{screen}");
    s.wait_for("Kph:");
    s.keys("Space");
    let paused = s.wait_for("PAUSED");
    std::thread::sleep(Duration::from_millis(500));
    // Paused: the counts stand still.
    let count = |screen: &str| {
        screen
            .lines()
            .find(|l| l.starts_with("Speed"))
            .unwrap()
            .to_string()
    };
    assert_eq!(count(&paused), count(&s.screen()));
    s.keys("/");
    s.keys("gear");
    s.keys("Enter");
    let filtered = s.wait_for("filter: gear");
    assert!(!filtered.contains("Kph"), "{filtered}");
    s.keys("q");
    s.wait_closed();
}

#[test]
fn sniff_in_a_terminal() {
    let (_dir, dbc, log) = fixture("sniff");
    let bin = env!("CARGO_BIN_EXE_bywire");
    let s = Session::start("bywire-sniff", &format!("{bin} sniff --dbc {dbc} -I {log}"));
    s.wait_for("Speed(Kph:");
    // Once a second frame of 0x123 is in, its cycle (from the log's timestamps) shows.
    let screen = s.wait_for("     10.0  ");
    assert!(screen.contains("2 identifiers"), "{screen}");
    let row = screen.lines().find(|l| l.contains(" 123 ")).unwrap();
    assert!(row.contains("     10.0  "), "a 10 ms cycle: {row}");
    s.keys("Space");
    s.wait_for("PAUSED");
    s.keys("c");
    s.wait_for("0 identifiers");
    s.keys("q");
    s.wait_closed();
}

/// `bywire sim` in a terminal: the live view starts, E-stop (e) latches, the operator's reset
/// (r) releases it and the tug drives again, q quits and the run's files are written.
#[test]
fn sim_live_view_in_a_terminal() {
    let bin = env!("CARGO_BIN_EXE_bywire");
    let dir = Scratch::new("sim-view");
    let session = Session::start(
        "sim",
        &format!("{bin} sim --out {} --max-seconds 120", dir.display()),
    );
    session.wait_for("keys: e E-stop");
    session.wait_for("mode       Autonomous");
    // The view names what the tug does: first the steering step test, then the cruise.
    session.wait_for("phase      step test");
    session.wait_for("phase      cruise");
    // Driving: 2.5 m/s and more.
    let moving = Instant::now() + Duration::from_secs(15);
    while !["2.5", "2.6", "2.7", "2.8", "2.9", "3.0"]
        .iter()
        .any(|v| session.screen().contains(&format!("speed       {v}")))
    {
        assert!(Instant::now() < moving, "{}", session.screen());
        std::thread::sleep(Duration::from_millis(100));
    }
    session.keys("e");
    session.wait_for("E-stop     BrakesApplied");
    session.wait_for("E-stop     Stopped");
    // The button released (a second), the operator resets.
    session.wait_for("faults     none");
    session.keys("r");
    session.wait_for("E-stop     Normal");
    session.wait_for("mode       Autonomous");
    let screen = session.wait_for("estop            Normal");
    assert!(
        screen.contains("route") && screen.contains("tug"),
        "{screen}"
    );
    session.keys("q");
    session.wait_closed();
    let metrics = std::fs::read_to_string(dir.join("metrics.json")).unwrap();
    assert!(
        metrics.contains("\"BrakesApplied\"") && metrics.contains("\"OperatorReset\""),
        "{metrics}"
    );
}

/// The scenario's faults by hand (key 1: the fault tour's ADS silence), and a paused view
/// whose terminal goes away still ends and writes its files.
#[test]
fn sim_fault_keys_and_a_closed_terminal() {
    let bin = env!("CARGO_BIN_EXE_bywire");
    let dir = Scratch::new("sim-hangup");
    let session = Session::start(
        "hangup",
        &format!(
            "{bin} sim --scenario fault-tour --out {} --max-seconds 300",
            dir.display()
        ),
    );
    session.wait_for("key 1      AdsSilence");
    session.wait_for("mode       Autonomous");
    session.keys("1");
    session.wait_for("fault            AdsSilence");
    session.wait_for("watchdog   FullBraking");
    session.keys("p");
    session.wait_for("(paused)");
    drop(session);
    let deadline = Instant::now() + Duration::from_secs(20);
    while !dir.join("metrics.json").exists() {
        assert!(
            Instant::now() < deadline,
            "the run did not end with its terminal"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    // Written whole (it parses at once) with the fault pressed by hand.
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
    assert!(
        metrics["events"]
            .as_array()
            .unwrap()
            .iter()
            .any(|e| e["kind"] == "fault" && e["detail"] == "AdsSilence"),
        "{metrics}"
    );
}

/// A hang-up signal with the terminal still there (as `kill -HUP` sends it): the run ends, puts
/// the terminal back (its summary prints on the main screen) and writes its files.
#[test]
fn sim_ends_cleanly_on_a_hangup_signal() {
    let bin = env!("CARGO_BIN_EXE_bywire");
    let dir = Scratch::new("sim-sighup");
    let session = Session::start(
        "sighup",
        &format!(
            "{bin} sim --out {} --max-seconds 300; echo exit=$?; sleep 60",
            dir.display()
        ),
    );
    session.wait_for("mode       Autonomous");
    let killed = Command::new("pkill")
        // Anchored: the shell around it has the same words later in its command line.
        .args(["-HUP", "-f", &format!("^{bin} sim --out {}", dir.display())])
        .status()
        .unwrap();
    assert!(killed.success());
    let screen = session.wait_for("exit=0");
    assert!(screen.contains("stopped after"), "{screen}");
    assert!(!screen.contains("mode       Autonomous"), "{screen}");
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(metrics["completed"], false);
}
