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

/// `bywire uds` as the tester of a server built on udsoncan's request parser and response
/// encoder: every service's answer decoded, the server's P2/P2* adopted, response pending
/// waited through, the security key computed, negative responses named.
#[test]
fn bywire_uds_diagnoses_a_udsoncan_server() {
    if !inside_lonet("bywire_uds_diagnoses_a_udsoncan_server") {
        return;
    }
    let bus = "udp:239.74.163.4:43562";
    let mut server = KillOnDrop(
        Command::new("python3")
            .arg(format!("{}/udsoncan_server.py", oracles()))
            .args(["239.74.163.4", "43562"])
            .stdout(std::process::Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let mut lines =
        std::io::BufRead::lines(std::io::BufReader::new(server.0.stdout.take().unwrap()));
    assert_eq!(lines.next().unwrap().unwrap(), "ready");
    let uds = |args: &[&str]| {
        let mut all = vec!["uds"];
        all.extend_from_slice(args);
        let (code, out, err) = bywire(&all, "");
        (code, format!("{out}{err}"))
    };
    let ok = |args: &[&str]| {
        let (mut code, mut text) = uds(args);
        // UDP multicast is best effort (and Python on a busy machine can miss a 50 ms P2): a
        // read, or a seed request, whose request or answer was lost is asked once more, as a
        // tester would (P2 and its timeouts are tested exactly in simulated time).
        let read = matches!(
            args.first(),
            Some(&("read-dtc" | "read-did" | "session" | "security"))
        );
        if read && code != 0 && text.contains("no answer within P2") {
            (code, text) = uds(args);
        }
        assert_eq!(code, 0, "{args:?}: {text}");
        text
    };
    let json = |args: &[&str]| -> Value {
        let mut all = args.to_vec();
        all.push("--json");
        serde_json::from_str(ok(&all).trim()).unwrap()
    };
    assert_eq!(
        json(&["session", bus, "3"]),
        json!({"session": 3, "p2_ms": 50, "p2_star_ms": 2000})
    );
    assert_eq!(
        ok(&["read-did", bus, "F190"]).trim(),
        "F190 VIN: UDSONCAN000000042"
    );
    // Two DIDs in one request, split by the VIN's known length.
    let read = json(&["read-did", bus, "F190", "0101"]);
    assert_eq!(read["0101"]["hex"], "1234", "{read}");
    // Writing needs the session and security: refused, then done with --session/--security.
    let (code, text) = uds(&["write-did", bus, "--session", "1", "0101", "hex:BEEF"]);
    assert_ne!(code, 0);
    assert!(text.contains("0x22 (conditionsNotCorrect)"), "{text}");
    let (code, text) = uds(&["write-did", bus, "--session", "3", "0101", "hex:BEEF"]);
    assert_ne!(code, 0);
    assert!(text.contains("0x33 (securityAccessDenied)"), "{text}");
    ok(&[
        "write-did",
        bus,
        "--session",
        "3",
        "--security",
        "1",
        "0101",
        "hex:BEEF",
    ]);
    assert_eq!(json(&["read-did", bus, "0101"])["0101"]["hex"], "beef");
    // DTCs with their names from a description file, snapshots and occurrence counts.
    let file = std::env::temp_dir().join("bywire-uds-describe.toml");
    std::fs::write(
        &file,
        "[did.DD01]\nname = \"speed\"\nlength = 2\nkind = \"signed\"\nscale = 0.01\nunit = \"m/s\"\n\
         [dtc]\nC07300 = \"bus-off\"\n",
    )
    .unwrap();
    let describe = file.to_str().unwrap();
    let dtcs = json(&["read-dtc", bus, "--snapshots", "--describe", describe]);
    assert_eq!(dtcs[0]["dtc"], "512300", "{dtcs}");
    assert_eq!(dtcs[1]["code"], "U0073-00");
    assert_eq!(dtcs[1]["name"], "bus-off");
    assert_eq!(dtcs[1]["status"], 0x2F);
    assert_eq!(dtcs[1]["snapshots"][0]["values"][0]["value"], "3 m/s");
    assert_eq!(dtcs[1]["occurrences"], 3);
    let text = ok(&["read-dtc", bus, "--status", "01", "--describe", describe]);
    assert_eq!(
        text.trim(),
        "U0073-00 C07300 bus-off, status 2F: testFailed testFailedThisOperationCycle pendingDTC confirmedDTC testFailedSinceLastClear"
    );
    assert_eq!(json(&["read-dtc", bus, "--count"]), json!({"count": 2}));
    ok(&["clear-dtc", bus]);
    assert_eq!(ok(&["read-dtc", bus]).trim(), "no DTCs");
    // A routine answered after response pending, then its results.
    assert_eq!(
        ok(&["routine", bus, "start", "0203"]).trim(),
        "routine 0203 start: 00"
    );
    assert_eq!(json(&["routine", bus, "results", "0203"])["record"], "2a");
    assert_eq!(
        json(&["security", bus, "--session", "3", "1"]),
        json!({"unlocked": 1})
    );
    let (code, text) = uds(&["security", bus, "--session", "3", "1", "--key-fn", "xor:FF"]);
    assert_ne!(code, 0);
    assert!(text.contains("0x35 (invalidKey)"), "{text}");
    // A key program of the user's (here the server's algorithm, written again in Python): run
    // with the level and the seed, its key printed in hex; one that fails, or prints no key,
    // is named.
    let key_program = |name: &str, body: &str| {
        use std::os::unix::fs::PermissionsExt;
        let path = std::env::temp_dir().join(name);
        std::fs::write(
            &path,
            format!("#!/usr/bin/env python3\nimport sys\n{body}\n"),
        )
        .unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
        format!("exec:{}", path.display())
    };
    let seed2key = key_program(
        "bywire-seed2key.py",
        "level, seed = int(sys.argv[1]), bytes.fromhex(sys.argv[2])\n\
         print(bytes(((b ^ 0x5A) + level) & 0xFF for b in seed).hex())",
    );
    assert_eq!(
        json(&[
            "security",
            bus,
            "--session",
            "3",
            "1",
            "--key-fn",
            &seed2key
        ]),
        json!({"unlocked": 1})
    );
    let failing = key_program("bywire-seed2key-fails.py", "sys.exit(3)");
    let (code, text) = uds(&["security", bus, "--session", "3", "1", "--key-fn", &failing]);
    assert_ne!(code, 0);
    assert!(text.contains("the program failed"), "{text}");
    let garbage = key_program("bywire-seed2key-garbage.py", "print('no key here')");
    let (code, text) = uds(&["security", bus, "--session", "3", "1", "--key-fn", &garbage]);
    assert_ne!(code, 0);
    assert!(text.contains("its key"), "{text}");
    assert_eq!(json(&["reset", bus, "soft"]), json!({"reset": 3}));
    ok(&["tester-present", bus]);
    ok(&["dtc-setting", bus, "--session", "3", "off"]);
    ok(&["comm-control", bus, "--session", "3", "3", "1"]);
    let (code, text) = uds(&["raw", bus, "BA 01"]);
    assert_ne!(code, 0);
    assert!(text.contains("0x11 (serviceNotSupported)"), "{text}");
    drop(server);
    // What the server saw: every request bywire sent, in udsoncan's parse.
    let seen: Vec<String> = lines.map_while(Result::ok).collect();
    assert!(seen.contains(&"request 1003".to_string()), "{seen:?}");
    assert!(seen.contains(&"request 2e0101beef".to_string()), "{seen:?}");
    assert!(seen.contains(&"request 190201".to_string()), "{seen:?}");
    assert!(
        seen.contains(&"request 1904c07300ff".to_string()),
        "{seen:?}"
    );
}

/// A peer process, killed when the test ends (also when it fails).
struct KillOnDrop(std::process::Child);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A CANdela CDD (cantools' example) describes the DIDs read: the record split into its fields,
/// each value as cantools decodes that DID's record.
#[test]
fn a_cdd_describes_the_dids_read_field_by_field() {
    if !inside_lonet("a_cdd_describes_the_dids_read_field_by_field") {
        return;
    }
    let cdd = format!(
        "{}/../../target/cantools-files/cdd/example.cdd",
        env!("CARGO_MANIFEST_DIR")
    );
    let bus = "udp:239.74.163.9:43571";
    let record = "0102030405060708090A";
    let server = Background::start(&["uds", "serve", bus, "--did", &format!("0090=hex:{record}")]);
    // Ready when it answers: each attempt waits out its own P2 timeout.
    let mut answer = None;
    for _ in 0..50 {
        let (code, out, _) = bywire(
            &["uds", "read-did", bus, "0090", "--describe", &cdd, "--json"],
            "",
        );
        if code == 0 {
            answer = Some(out);
            break;
        }
    }
    let _ = server.stop();
    let answer: Value = serde_json::from_str(answer.expect("the server answers").trim()).unwrap();
    let script = format!(
        "import json, warnings, cantools\nwarnings.simplefilter('ignore')\n\
         db = cantools.database.load_file({cdd:?})\n\
         print(json.dumps(db.get_did_by_identifier(0x90).decode(bytes.fromhex({record:?}))))"
    );
    let theirs = Command::new("python3")
        .args(["-c", &script])
        .output()
        .unwrap();
    assert!(
        theirs.status.success(),
        "{}",
        String::from_utf8_lossy(&theirs.stderr)
    );
    let theirs: Value = serde_json::from_slice(&theirs.stdout).unwrap();
    assert_eq!(answer["0090"]["name"], "ECU_Identification");
    assert_eq!(answer["0090"]["value"], theirs, "{answer}");
}
