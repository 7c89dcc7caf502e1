//! `bywire uds serve` as the ECU of udsoncan 1.26 (with can-isotp 2.0 on python-can's
//! `udp_multicast`, inside `../shared/tools/lonet.sh`): every service's answer as udsoncan
//! reads it, a negative response, DTC status bits, ClearDTC.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]
#![cfg(target_os = "linux")]

mod common;

use std::process::Command;

use common::*;
use serde_json::{json, Value};

#[test]
fn udsoncan_diagnoses_bywire_uds_serve() {
    if !inside_lonet("udsoncan_diagnoses_bywire_uds_serve") {
        return;
    }
    let bus = "udp:239.74.163.2:43560";
    let server = Background::start(&[
        "uds",
        "serve",
        bus,
        "--did",
        "F190=WBYWIRE0TUG000042",
        "--did",
        "F195=1.4.0",
        "--did",
        "0101=hex:0000:rw",
        "--dtc",
        "C10100",
        "--dtc",
        "512300:passed",
        "--did",
        "0202=hex:07:rws",
        "--routine",
        "0203=300:hex:002A",
        "--functional",
        "7DF",
    ]);
    std::thread::sleep(std::time::Duration::from_millis(300));
    let run = Command::new("python3")
        .arg(format!("{}/udsoncan_client.py", oracles()))
        .args(["239.74.163.2", "43560"])
        .output()
        .unwrap();
    let (_, out, err) = server.stop();
    let text = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{text}{}\n{out}{err}",
        String::from_utf8_lossy(&run.stderr)
    );
    let seen: Value = serde_json::from_str(text.lines().last().unwrap()).unwrap();
    // The extended session with P2 50 ms and P2* 5000 ms, as udsoncan decodes them.
    assert_eq!(seen["session"], json!([3, 0.05, 5.0]), "{seen}");
    assert_eq!(
        seen["dids"],
        json!({"F190": "WBYWIRE0TUG000042", "F195": "1.4.0"})
    );
    assert_eq!(seen["written"], json!([0x1234]), "the struct codec's tuple");
    assert_eq!(seen["refused"], 0x31, "requestOutOfRange");
    // Both DTCs with their status bits; only one failing now; none after ClearDTC.
    assert_eq!(seen["dtcs"], json!([["512300", 0x2E], ["C10100", 0x2F]]));
    assert_eq!(seen["failing"], json!(["C10100"]));
    assert_eq!(seen["after_clear"], 0);
    assert_eq!(seen["reset"], 1);
    // Writing a secured DID is refused until SecurityAccess, then done.
    assert_eq!(seen["locked_write"], 0x33, "securityAccessDenied");
    assert_eq!(seen["secured"], json!([9]));
    // The routine's result, after udsoncan waited through response pending.
    assert_eq!(seen["routine"], json!([0x00, 0x2A]));
    // A functional request (0x7DF) answered on the physical identifier.
    assert_eq!(seen["functional"], "027e00");
    // What the tester did, as the server printed it.
    for line in [
        "session Extended",
        "written 0101",
        "cleared FFFFFF",
        "reset 1",
    ] {
        assert!(out.contains(line), "{line}: {out}");
    }
}
