//! `bywire latency` as a user runs it.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use common::Scratch;

fn tug_dbc(name: &str) -> String {
    format!("{}/../bywire-tug/dbc/{name}", env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn predict_reports_each_message_of_one_bus_as_json() {
    let dbc = tug_dbc("reference-tug.dbc");
    let (code, out, err) = common::bywire(
        &[
            "latency",
            "--predict",
            &dbc,
            "--bitrate",
            "500000",
            "--senders",
            "IMU,IO",
            "--json",
        ],
        "",
    );
    assert_eq!(code, 0, "{err}");
    let json: serde_json::Value = serde_json::from_str(&out).unwrap();
    let names: Vec<&str> = json["messages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["Imu", "WheelEncoders", "SteeringAngleSensors"]);
    assert_eq!(json["misses"], 0);
    // Three 8-byte frames (268 µs each at their longest) every 10 ms.
    let utilisation = json["utilisation_percent"].as_f64().unwrap();
    assert!((utilisation - 3.0 * 268.0 / 10_000.0 * 100.0).abs() < 1e-6);
    let lowest = &json["messages"][2];
    assert_eq!(lowest["id"], "0x122");
    assert_eq!(lowest["worst_case_us"], 3.0 * 268.0);
    assert_eq!(lowest["meets_deadline"], true);
}

#[test]
fn predict_with_strict_fails_on_a_miss_and_names_it() {
    let dir = Scratch::new("latency");
    let path = dir.join("overloaded.dbc");
    let mut text = String::from("BA_DEF_ BO_ \"GenMsgCycleTime\" INT 0 65535;\n");
    for i in 0..11 {
        let id = 0x100 + i;
        text.push_str(&format!(
            "BO_ {id} M{i}: 8 N\nBA_ \"GenMsgCycleTime\" BO_ {id} 3;\n"
        ));
    }
    std::fs::write(&path, text).unwrap();
    let path = path.to_str().unwrap();
    let args = ["latency", "--predict", path, "--bitrate", "500000"];
    let (code, out, err) = common::bywire(&args, "");
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("0 can miss their deadline"), "{out}");
    let late = [&args[..], &["--jitter", "0.1", "--strict"]].concat();
    let (code, out, err) = common::bywire(&late, "");
    assert_eq!(code, 1, "{out}");
    assert!(
        out.contains("M9") && out.contains("MISS by 48.0 µs"),
        "{out}"
    );
    assert!(
        err.contains("2 message(s) can miss their deadline"),
        "{err}"
    );
}

#[test]
fn predict_refuses_what_it_cannot_do() {
    let dbc = tug_dbc("reference-tug.dbc");
    for (args, expected) in [
        (vec!["--bitrate", "0"], "--bitrate must be above 0"),
        (
            vec!["--bitrate", "500000", "--senders", "NOBODY"],
            "no message of",
        ),
        (
            vec!["--bitrate", "500000", "--messages", "Nothing"],
            "has no message 'Nothing'",
        ),
        (vec!["--bitrate", "500000", "--jitter", "-1"], "-1"),
    ] {
        let all = [&["latency", "--predict", &dbc][..], &args[..]].concat();
        let (code, _, err) = common::bywire(&all, "");
        assert_ne!(code, 0, "{args:?}");
        assert!(err.contains(expected), "{args:?}: {err}");
    }
}

/// Run the simulated tug (`bywire sim --fast`) for `seconds` with `scenario` into a new folder:
/// the scratch folder, and the run's folder in it.
fn sim_run(name: &str, scenario: &str, seconds: &str) -> (Scratch, std::path::PathBuf) {
    let dir = Scratch::new(&format!("latency-{name}"));
    let scenario_path = dir.join("scenario.toml");
    std::fs::write(&scenario_path, scenario).unwrap();
    let out = dir.join("run");
    let (code, _, err) = common::bywire(
        &[
            "sim",
            "--fast",
            "--no-view",
            "--scenario",
            scenario_path.to_str().unwrap(),
            "--max-seconds",
            seconds,
            "--out",
            out.to_str().unwrap(),
        ],
        "",
    );
    assert_eq!(code, 0, "{err}");
    (dir, out)
}

/// The ADS's commands delayed 15 ms on bus 1 only (a scenario's `delay_frames`): the copy on
/// bus 1b is on time, so the transfer from bus 1b to bus 1 is the injected delay, within a
/// frame time (an 8-byte frame at 500 kbit/s: ≤ 0.27 ms).
#[test]
fn logs_show_an_injected_delay_between_the_redundant_buses() {
    let (_dir, run) = sim_run(
        "delay",
        "name = \"delayed\"\nroute = \"apron-loop\"\n[[event]]\nat_s = 1.0\nfault = \"delay_frames\"\nbus = \"bus1\"\nid = 0x100\ndelay_ms = 15\n",
        "6",
    );
    let bus1 = run.join("bus1.log");
    let bus1b = run.join("bus1b.log");
    let plot = run.join("latency.png");
    let (code, out, err) = common::bywire(
        &[
            "latency",
            bus1.to_str().unwrap(),
            bus1b.to_str().unwrap(),
            "--profile",
            "reference-tug",
            "--transfer",
            "bus1b=bus1",
            "--json",
            "--plot",
            plot.to_str().unwrap(),
        ],
        "",
    );
    assert_eq!(code, 0, "{err}");
    let png = std::fs::read(&plot).unwrap();
    assert!(
        png.starts_with(b"\x89PNG") && png.len() > 10_000,
        "{}",
        png.len()
    );
    let json: serde_json::Value = serde_json::from_str(&out).unwrap();
    let latency = &json["transfers"][0]["latency"];
    let (p50, max) = (
        latency["p50_ms"].as_f64().unwrap(),
        latency["max_ms"].as_f64().unwrap(),
    );
    assert!((15.0..=15.27).contains(&p50), "{latency}");
    assert!(max <= 15.27, "{latency}");
    // Before the fault (the first second) the copies were a frame apart.
    assert!(latency["min_ms"].as_f64().unwrap() < 0.3, "{latency}");
    assert_eq!(json["transfers"][0]["unmatched"], 0);
}

/// The steering steps at a standstill, measured from bus 1's log (the command's setpoint
/// against the reported front-left wheel angle, 50 Hz, 0.1° steps, from the angle sensor)
/// agree with the simulator's own step metrics (the plant's true angle every millisecond):
/// rise within 30 ms and 5 % settling within 150 ms (the log samples every 20 ms and ends a
/// step at its next one), overshoot within 4 points (sensor noise on the peak).
#[test]
fn logged_steering_steps_agree_with_the_simulators_metrics() {
    let (_dir, run) = sim_run(
        "steps",
        "name = \"steps\"\nroute = \"apron-loop\"\nsteering_steps = [10, -10, 0]\n",
        "10",
    );
    let bus1 = run.join("bus1.log");
    let (code, out, err) = common::bywire(
        &[
            "latency",
            bus1.to_str().unwrap(),
            "--profile",
            "reference-tug",
            "--response",
            "AdsToVehicle_Control.SteeringAngleCmd=VehicleToAds_WheelAngles.WheelAngleFL",
            "--step-min",
            "5",
            "--step-window",
            "3",
            "--json",
        ],
        "",
    );
    assert_eq!(code, 0, "{err}");
    let ours: serde_json::Value = serde_json::from_str(&out).unwrap();
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("metrics.json")).unwrap()).unwrap();
    let theirs = metrics["steering_steps"].as_array().unwrap();
    let steps = ours["responses"][0]["steps"].as_array().unwrap();
    assert_eq!(theirs.len(), 3);
    assert!(steps.len() >= 3, "{steps:?}");
    for (ours, theirs) in steps.iter().zip(theirs) {
        let f = |v: &serde_json::Value, k: &str| v[k].as_f64().unwrap();
        assert_eq!(f(ours, "from"), f(theirs, "from_deg"));
        assert_eq!(f(ours, "to"), f(theirs, "to_deg"));
        assert!(
            (f(ours, "rise_s") - f(theirs, "rise_s")).abs() < 0.03,
            "{ours} {theirs}"
        );
        assert!(
            (f(ours, "settling_5_s") - f(theirs, "settling_5_s")).abs() < 0.15,
            "{ours} {theirs}"
        );
        assert!(
            (f(ours, "overshoot_percent") - f(theirs, "overshoot_percent")).abs() < 4.0,
            "{ours} {theirs}"
        );
        assert!(f(ours, "dead_time_s") > 0.0 && f(ours, "dead_time_s") < f(ours, "t90_s"));
    }
}

#[test]
fn logs_mode_refuses_bad_options_with_their_names() {
    let log = std::env::temp_dir().join(format!("bywire-latency-bad-{}.log", std::process::id()));
    std::fs::write(&log, "(1.000000) can0 100#00\n").unwrap();
    let log = log.to_str().unwrap();
    for (args, expected) in [
        (vec![log], "give --profile or --dbc"),
        (
            vec![log, "--profile", "reference-tug", "--echo", "Nope"],
            "--echo 'Nope': expected MESSAGE.SIGNAL=MESSAGE.SIGNAL",
        ),
        (
            vec![log, "--profile", "reference-tug", "--response", "A.B=C.D"],
            "A.B: the DBC has no message 'A'",
        ),
        (
            vec![log, "--profile", "reference-tug", "--transfer", "can0"],
            "--transfer 'can0': expected FROM=TO",
        ),
        (
            vec![log, "--profile", "reference-tug", "--plot", "x.gif"],
            "the image must end in .png or .svg",
        ),
        (
            vec![log, "--profile", "reference-tug", "--plot", "x.png"],
            "nothing to plot",
        ),
    ] {
        let all = [&["latency"][..], &args[..]].concat();
        let (code, _, err) = common::bywire(&all, "");
        assert_ne!(code, 0, "{args:?}");
        assert!(err.contains(expected), "{args:?}: {err}");
    }
    std::fs::remove_file(log).unwrap();
}
