//! Differential tests against implementations that share no code with bywire:
//! crccheck and sigrok's CAN decoder for the wire model (classic and ISO CAN FD), the `autosar-e2e` package for the E2E
//! profiles. `.ci/run` installs them (pip: crccheck, autosar-e2e; apt: sigrok-cli).
// Tests fail by panicking; helpers outside #[test] functions may unwrap too.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::process::Command;

use bywire_core::e2e::{profile1, profile2, SequenceConfig};

mod common;

fn run_python(script: &str, input: &str) -> String {
    let path = format!("{}/tests/oracles/{script}", env!("CARGO_MANIFEST_DIR"));
    let (code, out, err) = common::run_with_input(Command::new("python3").arg(&path), input);
    assert_eq!(code, 0, "{script} failed: {err}");
    out
}

/// A small deterministic generator, so a failure names a reproducible frame.
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> u32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 33) as u32
    }
}

fn fd_frames(count: usize) -> Vec<String> {
    let mut rng = Lcg(11);
    let lengths = [0, 1, 5, 8, 12, 16, 20, 24, 32, 48, 64];
    (0..count)
        .map(|i| {
            let id = if rng.next().is_multiple_of(2) {
                format!("{:08X}", rng.next() & 0x1FFF_FFFF)
            } else {
                format!("{:03X}", rng.next() & 0x7FF)
            };
            let len = lengths[i % lengths.len()];
            let fill = [0x00, 0xFF, 0x0F, 0xF0][(rng.next() % 4) as usize];
            let data: String = (0..len)
                .map(|_| {
                    if rng.next().is_multiple_of(2) {
                        fill
                    } else {
                        rng.next() & 0xFF
                    }
                })
                .map(|b| format!("{b:02X}"))
                .collect();
            format!("{id}##{:X}{data}", rng.next() % 4)
        })
        .collect()
}

fn classic_frames(count: usize) -> Vec<String> {
    let mut rng = Lcg(7);
    let mut frames = vec![
        "000#".to_string(),
        "7FF#FFFFFFFFFFFFFFFF".to_string(),
        "1FFFFFFF#R".to_string(),
    ];
    while frames.len() < count {
        let extended = rng.next().is_multiple_of(3);
        let id = if extended {
            format!("{:08X}", rng.next() & 0x1FFF_FFFF)
        } else {
            format!("{:03X}", rng.next() & 0x7FF)
        };
        let text = match rng.next() % 8 {
            0 => format!("{id}#R{}", rng.next() % 9),
            1 => {
                let data: String = (0..8)
                    .map(|_| format!("{:02X}", rng.next() & 0xFF))
                    .collect();
                format!("{id}#{data}_{:X}", 9 + rng.next() % 7)
            }
            _ => {
                let len = rng.next() % 9;
                // Runs of equal bytes provoke stuffing.
                let fill = [0x00, 0xFF, 0x0F, 0xF0][(rng.next() % 4) as usize];
                let data: String = (0..len)
                    .map(|_| {
                        if rng.next().is_multiple_of(2) {
                            fill
                        } else {
                            rng.next() & 0xFF
                        }
                    })
                    .map(|b| format!("{b:02X}"))
                    .collect();
                format!("{id}#{data}")
            }
        };
        frames.push(text);
    }
    frames
}

#[test]
fn bit_sequences_agree_with_crccheck_and_sigrok() {
    let mut frames = classic_frames(300);
    frames.extend(fd_frames(200));
    let mut input = String::new();
    for text in &frames {
        let out = Command::new(env!("CARGO_BIN_EXE_bywire"))
            .args(["wire", text, "--json"])
            .output()
            .unwrap();
        assert!(out.status.success(), "{text}");
        let mut json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        json["frame"] = serde_json::Value::String(text.clone());
        input.push_str(&json.to_string());
        input.push('\n');
    }
    let summary: serde_json::Value =
        serde_json::from_str(&run_python("wire_frames.py", &input)).unwrap();
    assert_eq!(summary["checked"], 500, "{summary:#}");
    assert_eq!(
        summary["sigrok_frames"], summary["sigrok_checked"],
        "{summary:#}"
    );
    assert!(
        summary["sigrok_checked"].as_u64().unwrap() >= 200,
        "{summary:#}"
    );
    assert_eq!(summary["problems"], serde_json::json!([]), "{summary:#}");
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// `count` successive protections of `start`, as hex.
fn protect_run(start: [u8; 8], count: usize, mut protect: impl FnMut(&mut [u8; 8])) -> Vec<String> {
    let mut data = start;
    (0..count)
        .map(|_| {
            protect(&mut data);
            hex(&data)
        })
        .collect()
}

#[test]
fn e2e_profile1_matches_autosar_e2e() {
    let modes = [
        ("both", profile1::DataIdMode::Both),
        ("alt", profile1::DataIdMode::Alt),
        ("low", profile1::DataIdMode::Low),
        ("nibble", profile1::DataIdMode::Nibble),
    ];
    let mut input = String::new();
    let mut ours = Vec::new();
    for (name, mode) in modes {
        for data_id in [0x0000u16, 0x0123, 0x0A5F, 0x00FF] {
            let config = profile1::Config {
                data_id,
                data_id_mode: mode,
                length: 8,
                sequence: SequenceConfig::default(),
            };
            let start = [0u8, 0x00, 0x11, 0x22, 0x33, 0x44, 0x55, 0x66];
            input.push_str(
                &serde_json::json!({"profile": 1, "mode": name, "data_id": data_id,
                    "data_hex": hex(&start), "count": 20})
                .to_string(),
            );
            input.push('\n');
            let mut tx = profile1::Protector::new();
            ours.push(protect_run(start, 20, |d| tx.protect(&config, d).unwrap()));
        }
    }
    let theirs: Vec<Vec<String>> = run_python("e2e_profiles.py", &input)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(ours, theirs);
}

#[test]
fn e2e_profile2_matches_autosar_e2e() {
    let mut input = String::new();
    let mut ours = Vec::new();
    for seed in 0..4u8 {
        let list: [u8; 16] =
            std::array::from_fn(|i| (i as u8).wrapping_mul(37).wrapping_add(seed * 11));
        let config = profile2::Config {
            data_id_list: list,
            length: 8,
            sequence: SequenceConfig::default(),
        };
        let start = [0u8, 0xA0, 1, 2, 3, 4, 5, seed];
        input.push_str(
            &serde_json::json!({"profile": 2, "data_id_list": list.to_vec(),
                "data_hex": hex(&start), "count": 34})
            .to_string(),
        );
        input.push('\n');
        let mut tx = profile2::Protector::new();
        ours.push(protect_run(start, 34, |d| tx.protect(&config, d).unwrap()));
    }
    let theirs: Vec<Vec<String>> = run_python("e2e_profiles.py", &input)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(ours, theirs);
}
