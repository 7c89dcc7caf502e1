//! An AUTOSAR system description (`examples/data/powertrain.arxml`) wherever a database is
//! taken: its container frame decoded as cantools decodes it, its E2E profile 1 declaration
//! filling the counter and CRC the `autosar-e2e` package computes, the SecOC-secured PDU inside
//! its container frames verified (MACs made by cantools' SecOC framing with `cryptography`'s
//! CMAC), and one of its two clusters chosen by `--db-bus`.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::panic
)]

mod common;

use std::os::unix::fs::PermissionsExt;
use std::process::Command;

use common::{bywire, oracles, run_with_input, Scratch};

const KEY: &str = "2b7e151628aed2a6abf7158809cf4f3c";

fn arxml() -> String {
    format!(
        "{}/../../examples/data/powertrain.arxml",
        env!("CARGO_MANIFEST_DIR")
    )
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// The secured Steer PDU (angle raw value `angle`, freshness `freshness`) as cantools' SecOC
/// framing with a CMAC from `cryptography` makes it.
fn secured_steer(angle: i16, freshness: u64) -> Vec<u8> {
    let script = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../bywire-secoc/tests/oracles/cantools_secoc.py"
    );
    let case = serde_json::json!({
        "key": KEY, "data_id": 85, "payload_length": 2, "fv_length": 32, "fv_tx_length": 8,
        "mac_tx_length": 24, "freshness": freshness,
        "data": format!("{}00000000", hex(&angle.to_le_bytes())),
    });
    let (code, out, err) =
        run_with_input(Command::new("python3").arg(script), &format!("{case}\n"));
    assert_eq!(code, 0, "{err}");
    let answer: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    let secured = answer["secured"].as_str().unwrap();
    (0..secured.len() / 2)
        .map(|i| u8::from_str_radix(&secured[2 * i..2 * i + 2], 16).unwrap())
        .collect()
}

/// A Bundle frame (20 bytes, short headers): Lights with `beam`, the secured Steer PDU, and
/// Lights again, which fills the frame.
fn bundle(beam: u8, steer: &[u8]) -> String {
    let mut data = vec![0, 0, 0x10, 1, beam, 0, 0, 0x20, 6];
    data.extend_from_slice(steer);
    data.extend_from_slice(&[0, 0, 0x10, 1, beam]);
    assert_eq!(data.len(), 20);
    format!("300##0{}", hex(&data))
}

#[test]
fn frames_and_container_frames_decode_as_cantools_decodes_them() {
    let steer = secured_steer(-123, 7);
    let log = format!(
        "(1.000000) can0 100#5A03E204\n(1.010000) can0 {}\n(1.020000) can0 18FF0010#01\n",
        bundle(2, &steer)
    );
    let (code, ours, err) = bywire(&["decode", &arxml()], &log);
    assert_eq!(code, 0, "{err}");
    let (code, theirs, err) = run_with_input(
        Command::new("python3").args(["-m", "cantools", "decode", &arxml()]),
        &log,
    );
    assert_eq!(code, 0, "{err}");
    assert_eq!(ours, theirs);
    assert!(ours.contains("Angle: -12.3 deg"), "{ours}");
    assert!(ours.contains("Beam: High"), "{ours}");
    assert!(ours.contains("Speed: 12.5 km/h"), "{ours}");
    // One line per frame: the same, but for cantools' doubled spaces between a container's PDUs.
    let (_, ours, _) = bywire(&["decode", "--single-line", &arxml()], &log);
    let (_, theirs, _) = run_with_input(
        Command::new("python3").args(["-m", "cantools", "decode", "--single-line", &arxml()]),
        &log,
    );
    let theirs = theirs.replace("( ", "(").replace(",  ", ", ");
    assert_eq!(ours, theirs);
    // JSON: the container's PDUs under "contained".
    let (_, json, _) = bywire(&["decode", "--json", &arxml()], &log);
    let bundle: serde_json::Value = serde_json::from_str(json.lines().nth(1).unwrap()).unwrap();
    assert_eq!(bundle["name"], "Bundle");
    assert_eq!(bundle["contained"][1]["name"], "Steer");
    assert_eq!(bundle["contained"][1]["header_id"], 32);
    assert_eq!(bundle["contained"][1]["signals"]["Angle"], -12.3);
    assert_eq!(bundle["contained"][0]["signals"]["Beam"], 2);
    // CSV: each PDU's rows under its own name.
    let (_, csv, _) = bywire(&["decode", "--csv", &arxml()], &log);
    assert!(csv.contains(",can0,Steer,Angle,-12.3,,deg\n"), "{csv}");
    assert!(csv.contains(",can0,Lights,Beam,2,High,\n"), "{csv}");
    // Parquet: a table a PDU, read back by pyarrow.
    let dir = Scratch::new("arxml-parquet");
    let log_file = dir.join("bundle.log");
    std::fs::write(&log_file, &log).unwrap();
    let lake = dir.join("lake");
    let (code, _, err) = bywire(
        &[
            "decode",
            &arxml(),
            "-I",
            log_file.to_str().unwrap(),
            "--parquet",
            lake.to_str().unwrap(),
        ],
        "",
    );
    assert_eq!(code, 0, "{err}");
    let script = format!(
        "import pyarrow.parquet as pq\nrows = pq.read_table({:?}).to_pylist()\n\
         print(rows[0]['Angle'], pq.read_table({:?}).num_rows)",
        lake.join("message=Steer").display().to_string(),
        lake.join("message=Lights").display().to_string()
    );
    let read = Command::new("python3")
        .args(["-c", &script])
        .output()
        .unwrap();
    assert_eq!(
        String::from_utf8_lossy(&read.stdout).trim(),
        "-12.3 2",
        "{}",
        String::from_utf8_lossy(&read.stderr)
    );
    // MCAP: a JSON channel a PDU, read back by the mcap package.
    let mcap = dir.join("bundle.mcap");
    let (code, _, err) = bywire(
        &[
            "log",
            "convert",
            log_file.to_str().unwrap(),
            mcap.to_str().unwrap(),
            "--dbc",
            &arxml(),
        ],
        "",
    );
    assert_eq!(code, 0, "{err}");
    let script = format!(
        "from mcap.reader import make_reader\n\
         for _, channel, message in make_reader(open({:?}, 'rb')).iter_messages():\n    \
         print(channel.topic, message.data.decode(errors='replace') if channel.topic != '/from_can_bus' else '')",
        mcap.display().to_string()
    );
    let read = Command::new("python3")
        .args(["-c", &script])
        .output()
        .unwrap();
    let topics = String::from_utf8_lossy(&read.stdout);
    assert!(
        topics.contains("/can0/Steer {\"Angle\":-12.3,"),
        "{topics}{}",
        String::from_utf8_lossy(&read.stderr)
    );
    assert!(
        topics.contains("/can0/Lights {\"Beam\":2,\"Beam_choice\":\"High\"}"),
        "{topics}"
    );
    // A header whose length runs past the frame: the error, not a guess.
    let overrun = format!("(1.0) can0 300##000001090{}\n", "00".repeat(16));
    let (_, out, _) = bywire(&["decode", &arxml()], &overrun);
    assert!(
        out.contains(
            ":: the contained PDU at byte 0 (header ID 0x10) claims 144 bytes, 16 are left"
        ),
        "{out}"
    );
}

#[test]
fn e2e_profile_1_is_filled_as_autosar_e2e_computes_it() {
    // Speed 12.5 km/h is 1250 (0x04E2); counter 3; data ID 0x123, both bytes.
    let (code, out, err) = bywire(
        &[
            "send",
            "virtual:arxml-e2e",
            "-v",
            "--dbc",
            &arxml(),
            "--counter",
            "3",
            "Drive",
            "Speed=12.5",
        ],
        "",
    );
    assert_eq!(code, 0, "{err}");
    let case = serde_json::json!({"profile": 1, "mode": "both", "data_id": 0x123,
        "data_hex": "0003e204", "count": 1});
    let (code, theirs, err) = run_with_input(
        Command::new("python3").arg(format!("{}/e2e_profiles.py", oracles())),
        &format!("{case}\n"),
    );
    assert_eq!(code, 0, "{err}");
    let theirs: Vec<String> = serde_json::from_str(theirs.trim()).unwrap();
    assert_eq!(out.trim(), format!("100#{}", theirs[0].to_uppercase()));
}

#[test]
fn secured_pdus_inside_container_frames_are_verified() {
    let dir = Scratch::new("arxml-secoc");
    let key = dir.join("ads.key");
    std::fs::write(&key, format!("0 {KEY}\n")).unwrap();
    std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o600)).unwrap();
    let key = key.display().to_string();
    let mut lines: Vec<String> = (1..=5)
        .map(|fv| {
            format!(
                "(1.{fv:06}) can0 {}",
                bundle(1, &secured_steer(100 * fv as i16, fv))
            )
        })
        .collect();
    let log = dir.join("clean.log");
    std::fs::write(&log, lines.join("\n") + "\n").unwrap();
    let verify = |log: &std::path::Path| {
        bywire(
            &[
                "secoc",
                "verify",
                "--key",
                &key,
                "--dbc",
                &arxml(),
                log.to_str().unwrap(),
            ],
            "",
        )
    };
    let (code, out, err) = verify(&log);
    assert_eq!(code, 0, "{out}{err}");
    assert_eq!(
        out.trim(),
        "Steer: 5 accepted, 0 bad MAC, 0 replayed or stale, 0 beyond the window, 0 malformed"
    );
    // The angle changed under an old MAC: rejected, named with its record.
    let mut forged = secured_steer(600, 6);
    forged[0] ^= 0x01;
    lines.push(format!("(2.0) can0 {}", bundle(1, &forged)));
    let log = dir.join("forged.log");
    std::fs::write(&log, lines.join("\n") + "\n").unwrap();
    let (code, out, err) = verify(&log);
    assert_eq!(code, 1);
    assert!(err.contains("1 secured frames rejected"), "{err}");
    assert!(
        out.contains("record 6") && out.contains("Steer: the MAC does not match"),
        "{out}"
    );
    assert!(out.contains("Steer: 5 accepted, 1 bad MAC"), "{out}");
}

#[test]
fn one_cluster_of_several_is_chosen_by_name() {
    let (code, out, err) = bywire(&["dbc", "dump", &arxml()], "");
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("ARXML, 3 messages"), "{out}");
    assert!(out.contains("Bus:        Powertrain") && out.contains("Bus:        Body"));
    assert!(out.contains("Protected:  counter DriveCounter, checksum DriveCrc"));
    assert!(out.contains("Secured:    SecOC data ID 0x0055, 2 payload bytes"));
    assert!(
        out.contains("PDU:        Steer\n  Header ID:  0x000020"),
        "{out}"
    );
    let (code, out, err) = bywire(&["--db-bus", "Body", "dbc", "dump", &arxml()], "");
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("ARXML, 1 messages") && out.contains("Name:       Doors"));
    let (code, _, err) = bywire(&["--db-bus", "Chassis", "dbc", "dump", &arxml()], "");
    assert_eq!(code, 1);
    assert!(
        err.contains("no CAN cluster named Chassis (the file has Powertrain, Body)"),
        "{err}"
    );
    // Converted to DBC for tools that need one, what DBC cannot say named.
    let dir = Scratch::new("arxml-convert");
    let dbc = dir.join("powertrain.dbc");
    let (code, _, err) = bywire(&["dbc", "convert", &arxml(), dbc.to_str().unwrap()], "");
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("1 container frames' 2 contained PDUs"),
        "{err}"
    );
    let (code, out, _) = bywire(&["dbc", "dump", dbc.to_str().unwrap()], "");
    assert_eq!(code, 0);
    assert!(
        out.contains("Protected:  counter DriveCounter, checksum DriveCrc"),
        "{out}"
    );
    // ARXML is read, not written.
    let (code, _, err) = bywire(
        &[
            "dbc",
            "convert",
            dbc.to_str().unwrap(),
            dir.join("back.arxml").to_str().unwrap(),
        ],
        "",
    );
    assert_eq!(code, 1);
    assert!(err.contains("ARXML is read, not written"), "{err}");
}
