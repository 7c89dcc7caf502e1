//! `bywire sim --fast`: the simulated tug completes the apron loop, writes candump logs that
//! our reader (and candump's format) accepts, a metrics JSON, and the same seed gives the same
//! logs byte for byte.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use std::process::Command;

use serde_json::Value;

fn sim(out: &std::path::Path, seed: &str) -> Value {
    let status = Command::new(env!("CARGO_BIN_EXE_bywire"))
        .args([
            "sim",
            "--fast",
            "--seed",
            seed,
            "--out",
            out.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap()
}

#[test]
fn the_simulated_tug_completes_the_apron_loop_deterministically() {
    let dir = std::env::temp_dir().join(format!("bywire-sim-{}", std::process::id()));
    let (a, b, c) = (dir.join("a"), dir.join("b"), dir.join("c"));
    let metrics = sim(&a, "5");
    assert_eq!(metrics["completed"], true, "{metrics}");
    assert!(
        metrics["tracking_error_m"]["max"].as_f64().unwrap() < 0.5,
        "{metrics}"
    );
    let kinds: Vec<&str> = metrics["events"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["kind"].as_str().unwrap())
        .collect();
    assert_eq!(kinds, ["engaged", "arrived"]);
    let sim_seconds = metrics["sim_seconds"].as_f64().unwrap();
    assert!((20.0..120.0).contains(&sim_seconds), "{sim_seconds}");
    sim(&b, "5");
    for log in ["bus1.log", "bus2.log"] {
        let (x, y) = (
            std::fs::read(a.join(log)).unwrap(),
            std::fs::read(b.join(log)).unwrap(),
        );
        assert!(x == y, "{log} differs between two runs of one seed");
        // Every line reads back as a candump log record.
        let text = String::from_utf8(x).unwrap();
        let records: Vec<_> = bywire_log::candump::Reader::new(text.as_bytes())
            .map(Result::unwrap)
            .collect();
        assert_eq!(records.len(), text.lines().count());
        assert!(records
            .iter()
            .all(|r| r.interface == log.trim_end_matches(".log")));
        assert!(
            records.windows(2).all(|w| w[0].timestamp <= w[1].timestamp),
            "in time order"
        );
    }
    // Another seed changes the sensor noise, so the drives' traffic.
    sim(&c, "6");
    assert_ne!(
        std::fs::read(a.join("bus2.log")).unwrap(),
        std::fs::read(c.join("bus2.log")).unwrap()
    );
    let (code, _, err) = common::bywire(&["sim", "--scenario", "moon-base"], "");
    assert_eq!(code, 1);
    assert!(
        err.contains("--scenario moon-base: not a built-in scenario"),
        "{err}"
    );
}
