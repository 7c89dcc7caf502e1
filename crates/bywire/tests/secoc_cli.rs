//! `bywire secoc`: a frame signed as cantools' SecOC framing with a CMAC from `cryptography`
//! signs it, verified (exit 1 on a changed bit), key files others can read refused, and a
//! capture checked with a DBC's declarations: a replay, a forgery and a jump past the window
//! each named with its record, the counts per message, exit 1.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::panic
)]

mod common;

use std::io::Write;
use std::os::unix::fs::PermissionsExt;
use std::path::PathBuf;
use std::process::{Command, Stdio};

use common::{bywire, Scratch};

const KEY: &str = "2b7e151628aed2a6abf7158809cf4f3c";

fn dir(name: &str) -> Scratch {
    Scratch::new(&format!("secoc-{name}"))
}

fn key_file(dir: &std::path::Path, text: &str, mode: u32) -> String {
    let path = dir.join("ads.key");
    std::fs::write(&path, text).unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(mode)).unwrap();
    path.display().to_string()
}

/// cantools' secured data for one case (the peer script of bywire-secoc's tests).
fn cantools_secured(case: &str) -> String {
    let script = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../bywire-secoc/tests/oracles/cantools_secoc.py"
    );
    let mut peer = Command::new("python3")
        .arg(script)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    writeln!(peer.stdin.take().unwrap(), "{case}").unwrap();
    let out = peer.wait_with_output().unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    let secured = text.split("\"secured\": \"").nth(1).unwrap();
    secured.split('"').next().unwrap().to_uppercase()
}

#[test]
fn sign_equals_cantools_and_verify_refuses_a_changed_bit() {
    let dir = dir("sign");
    let key = key_file(&dir, &format!("# the ADS key\n{KEY}\n"), 0o600);
    let (code, out, err) = bywire(
        &[
            "secoc",
            "sign",
            "--key",
            &key,
            "--data-id",
            "0x100",
            "--freshness",
            "7",
            "--profile",
            "24Bit-CMAC-8Bit-FV",
            "100#11223344",
        ],
        "",
    );
    assert_eq!(code, 0, "{err}");
    let theirs = cantools_secured(&format!(
        r#"{{"key":"{KEY}","data_id":256,"payload_length":4,"fv_length":8,"fv_tx_length":8,"mac_tx_length":24,"freshness":7,"data":"1122334400000000"}}"#
    ));
    assert_eq!(out.trim(), format!("100#{theirs}"));
    let secured = out.trim().to_string();
    let verify = |frame: &str, freshness: &str| {
        bywire(
            &[
                "secoc",
                "verify",
                "--key",
                &key,
                "--data-id",
                "256",
                "--freshness",
                freshness,
                "--profile",
                "24Bit-CMAC-8Bit-FV",
                frame,
            ],
            "",
        )
    };
    let (code, out, err) = verify(&secured, "7");
    assert_eq!((code, out.trim()), (0, "ok"), "{err}");
    // Every whole number is spelt as --data-id is: 0x7 is 7 (it was refused).
    let (code, out, err) = verify(&secured, "0x7");
    assert_eq!((code, out.trim()), (0, "ok"), "{err}");
    let (code, _, err) = verify(&secured, "0x1Z");
    assert_eq!(code, 2);
    assert!(err.contains("0x1Z: not a whole number"), "{err}");
    let (code, _, err) = verify(&secured, "8");
    assert_eq!(code, 1);
    assert!(err.contains("does not verify with freshness 8"), "{err}");
    // The last MAC bit changed.
    let mut changed = secured.clone();
    let last = changed.pop().unwrap();
    changed.push(if last == '0' { '1' } else { '0' });
    let (code, _, _) = verify(&changed, "7");
    assert_eq!(code, 1);
    // A CAN FD command with custom lengths; a classic frame too short for them is refused.
    let (code, out, err) = bywire(
        &[
            "secoc",
            "sign",
            "--key",
            &key,
            "--data-id",
            "256",
            "--freshness",
            "1000",
            "--fv-length",
            "32",
            "--fv-tx-length",
            "8",
            "--mac-tx-length",
            "32",
            "100##00102030405060708",
        ],
        "",
    );
    assert_eq!(code, 0, "{err}");
    // (FD flags as can-utils prints them: 4 is FDF.)
    assert!(out.starts_with("100##40102030405060708E8"), "{out}");
    assert_eq!(
        out.trim().len(),
        "100##0".len() + 2 * 16,
        "padded to 16 bytes: {out}"
    );
    let (code, _, err) = bywire(
        &[
            "secoc",
            "sign",
            "--key",
            &key,
            "--data-id",
            "256",
            "--freshness",
            "1",
            "--fv-length",
            "32",
            "--fv-tx-length",
            "8",
            "--mac-tx-length",
            "32",
            "100#0102030405060708",
        ],
        "",
    );
    assert_eq!(code, 1);
    assert!(err.contains("more than a classic frame carries"), "{err}");
}

#[test]
fn keys_others_can_read_are_refused_and_never_shown() {
    let dir = dir("keys");
    let key = key_file(&dir, KEY, 0o644);
    let args = [
        "secoc",
        "sign",
        "--key",
        &key,
        "--data-id",
        "1",
        "--freshness",
        "1",
        "--profile",
        "24Bit-CMAC-8Bit-FV",
        "100#11223344",
    ];
    let (code, out, err) = bywire(&args, "");
    assert_eq!(code, 1);
    assert!(err.contains("chmod 600"), "{err}");
    let key = key_file(&dir, &format!("3 {}\n", &KEY[..31]), 0o600);
    let (code, _, err) = bywire(
        &[
            "secoc",
            "sign",
            "--key",
            &key,
            "--data-id",
            "1",
            "--freshness",
            "1",
            "--profile",
            "24Bit-CMAC-8Bit-FV",
            "100#11223344",
        ],
        "",
    );
    assert_eq!(code, 1);
    assert!(err.contains("ads.key:1: a key is 32 hex digits"), "{err}");
    assert!(
        !err.contains(&KEY[..12]) && !out.contains(&KEY[..12]),
        "{err}"
    );
}

const DBC: &str = "VERSION \"\"\n\nBU_: ADS ECU\n\n\
BO_ 256 Command: 8 ADS\n SG_ Steering : 0|16@1- (0.001,0) [-1|1] \"rad\" ECU\n SG_ Speed : 16|16@1+ (0.01,0) [0|10] \"m/s\" ECU\n\n\
BO_ 512 Status: 8 ECU\n SG_ State : 0|8@1+ (1,0) [0|255] \"\" ADS\n\n\
BA_DEF_ BO_ \"SecOCDataId\" INT 0 65535;\nBA_DEF_ BO_ \"SecOCKeyId\" INT 0 65535;\n\
BA_DEF_ BO_ \"SecOCFreshnessValueLength\" INT 0 64;\nBA_DEF_ BO_ \"SecOCFreshnessValueTxLength\" INT 0 64;\n\
BA_DEF_ BO_ \"SecOCAuthInfoTxLength\" INT 0 128;\n\
BA_ \"SecOCDataId\" BO_ 256 256;\nBA_ \"SecOCKeyId\" BO_ 256 1;\nBA_ \"SecOCFreshnessValueLength\" BO_ 256 32;\n\
BA_ \"SecOCFreshnessValueTxLength\" BO_ 256 8;\nBA_ \"SecOCAuthInfoTxLength\" BO_ 256 24;\n";

#[test]
fn a_capture_is_checked_with_the_dbcs_declarations() {
    let dir = dir("capture");
    let key = key_file(&dir, &format!("1 {KEY}\n"), 0o600);
    let dbc = dir.join("secured.dbc");
    std::fs::write(&dbc, DBC).unwrap();
    let sign = |freshness: u64| {
        let (code, out, err) = bywire(
            &[
                "secoc",
                "sign",
                "--key",
                &key,
                "--key-id",
                "1",
                "--data-id",
                "256",
                "--freshness",
                &freshness.to_string(),
                "--fv-length",
                "32",
                "--fv-tx-length",
                "8",
                "--mac-tx-length",
                "24",
                "100#E8030A00",
            ],
            "",
        );
        assert_eq!(code, 0, "{err}");
        out.trim().to_string()
    };
    // A 32-bit freshness, 8 bits sent: 1..=300 (the bits sent wrap at 256), a status frame
    // between.
    let mut lines: Vec<String> = (1..=300)
        .map(|fv| format!("(1.{fv:06}) can0 {}", sign(fv)))
        .collect();
    lines.insert(5, "(1.000005) can0 200#01".to_string());
    let log = dir.join("clean.log");
    std::fs::write(&log, lines.join("\n") + "\n").unwrap();
    let dbc_arg = dbc.display().to_string();
    let check = |log: &PathBuf| {
        bywire(
            &[
                "secoc",
                "verify",
                "--key",
                &key,
                "--dbc",
                &dbc_arg,
                log.to_str().unwrap(),
            ],
            "",
        )
    };
    let (code, out, err) = check(&log);
    assert_eq!(code, 0, "{out}{err}");
    assert_eq!(
        out.trim(),
        "Command: 300 accepted, 0 bad MAC, 0 replayed or stale, 0 beyond the window, 0 malformed"
    );
    // A replay of freshness 299, a forgery (changed payload, old MAC), a jump of 40.
    let mut attacked = lines.clone();
    attacked.push(lines[299].clone());
    let forged = sign(301).replacen("100#E8", "100#FF", 1);
    attacked.push(format!("(2.0) can0 {forged}"));
    attacked.push(format!("(2.1) can0 {}", sign(341)));
    attacked.push(format!("(2.2) can0 {}", sign(301)));
    let log = dir.join("attacked.log");
    std::fs::write(&log, attacked.join("\n") + "\n").unwrap();
    let (code, out, err) = check(&log);
    assert_eq!(code, 1);
    assert!(err.contains("3 secured frames rejected"), "{err}");
    let name = log.display().to_string();
    let rejected: Vec<&str> = out.lines().filter(|l| l.starts_with(&name)).collect();
    assert_eq!(rejected.len(), 3, "{out}");
    assert!(
        rejected[0].contains("record 302") && rejected[0].contains("not fresh"),
        "{out}"
    );
    assert!(
        rejected[1].contains("record 303") && rejected[1].contains("MAC does not match"),
        "{out}"
    );
    assert!(
        rejected[2].contains("record 304") && rejected[2].contains("beyond the freshness window"),
        "{out}"
    );
    assert!(out.contains("Command: 301 accepted, 1 bad MAC, 1 replayed or stale, 1 beyond the window, 0 malformed"), "{out}");
    // The message's key id missing from the key file: refused, not checked without it.
    let other = key_file(&dir, &format!("2 {KEY}\n"), 0o600);
    let (code, _, err) = bywire(
        &[
            "secoc",
            "verify",
            "--key",
            &other,
            "--dbc",
            &dbc_arg,
            log.to_str().unwrap(),
        ],
        "",
    );
    assert_eq!(code, 1);
    assert!(err.contains("message Command needs key id 1"), "{err}");
}
