//! `bywire latency` as a user runs it.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

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
    let dir = std::env::temp_dir().join(format!("bywire-latency-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
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
    std::fs::remove_dir_all(&dir).unwrap();
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
