//! The reference tug's messages: the generated structs against hand-computed bytes, against
//! bywire-dbc's runtime codec and E2E protection, and against cantools decoding the shipped DBC.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::process::Command;

use bywire_dbc::codec::MessageCodec;
use bywire_dbc::e2e::Protection;
use bywire_tug::messages::{self, AdsToVehicleControl, VehicleToAdsState, DBC};

#[test]
fn hand_computed_command_bytes() {
    let mut m = AdsToVehicleControl::default();
    m.set_steering_angle_cmd(25.3).unwrap();
    m.set_velocity_cmd(2.5).unwrap();
    assert_eq!(&m.0[..4], &[0xFD, 0x00, 0xFA, 0x00]);
    m.set_steering_angle_cmd(-25.3).unwrap();
    assert_eq!(&m.0[..2], &[0x03, 0xFF]);
    assert!((m.steering_angle_cmd() + 25.3).abs() < 1e-9);
    // Outside the DBC's range: refused, bytes untouched.
    assert!(m.set_steering_angle_cmd(45.1).is_err());
    assert_eq!(&m.0[..2], &[0x03, 0xFF]);
}

fn database() -> bywire_dbc::Database {
    bywire_dbc::parse_str(DBC, bywire_dbc::Mode::Strict)
        .unwrap()
        .0
}

/// Deterministic pseudo-random payloads.
fn payloads(n: usize, seed: u64) -> Vec<[u8; 8]> {
    let mut rng = lcg(seed);
    (0..n)
        .map(|_| std::array::from_fn(|_| rng().to_le_bytes()[3]))
        .collect()
}

fn lcg(mut state: u64) -> impl FnMut() -> u64 {
    move || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        state
    }
}

#[test]
fn the_crc_agrees_with_the_dbc_declared_protection() {
    let db = database();
    for message in &db.messages {
        let codec = MessageCodec::new(message);
        let protection = Protection::of(message).expect("every message is protected");
        for (k, mut payload) in payloads(50, u64::from(message.id)).into_iter().enumerate() {
            let id = message.id;
            messages::seal(id, &mut payload);
            assert_eq!(
                protection.verify(&codec, &payload),
                Ok(Some(
                    codec
                        .read_raw(protection.counter.unwrap().0, &payload)
                        .unwrap()
                )),
                "{} #{k}",
                message.name
            );
            // And the other way: the runtime fills, the generated check accepts.
            let mut filled = payload;
            protection.fill(&codec, 5, &mut filled).unwrap();
            assert!(messages::is_sealed(id, &filled), "{}", message.name);
            filled[0] ^= 0x10;
            assert!(!messages::is_sealed(id, &filled));
        }
    }
}

#[test]
fn generated_structs_decode_like_the_runtime_codec() {
    let db = database();
    let find = |name: &str| db.messages.iter().find(|m| m.name == name).unwrap();
    let control = MessageCodec::new(find("AdsToVehicle_Control"));
    let state = MessageCodec::new(find("VehicleToAds_State"));
    for payload in payloads(500, 7) {
        let mut out = vec![None; control.signal_count()];
        control.decode(&payload, &mut out).unwrap();
        let m = AdsToVehicleControl(payload);
        let generated = [
            m.steering_angle_cmd(),
            m.velocity_cmd(),
            m.brake_cmd(),
            m.gear_cmd(),
            m.control_mode_cmd(),
            m.steering_mode_cmd(),
            m.engage_request(),
            m.operator_reset(),
            m.heartbeat_counter(),
            m.checksum(),
        ];
        for (g, d) in generated.iter().zip(&out) {
            assert!(
                (g - d.unwrap().physical.as_f64()).abs() < 1e-9,
                "{payload:02X?}"
            );
        }
        let mut out = vec![None; state.signal_count()];
        state.decode(&payload, &mut out).unwrap();
        let s = VehicleToAdsState(payload);
        assert!((s.steering_angle_actual() - out[0].unwrap().physical.as_f64()).abs() < 1e-9);
        assert_eq!(s.estop_state_raw(), out[6].unwrap().raw);
        assert_eq!(s.heartbeat_echo_raw(), out[10].unwrap().raw);
    }
}

#[test]
fn cantools_decodes_the_shipped_dbc_as_we_do() {
    let db = database();
    let dir = std::env::temp_dir().join(format!("bywire-tug-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let dbc_path = dir.join("reference-tug.dbc");
    std::fs::write(&dbc_path, DBC).unwrap();
    // Frames of every message, as "ID HEX" lines.
    let mut lines = String::new();
    let mut expected = Vec::new();
    for message in &db.messages {
        let codec = MessageCodec::new(message);
        for mut payload in payloads(20, u64::from(message.id) + 99) {
            messages::seal(message.id, &mut payload);
            let mut out = vec![None; codec.signal_count()];
            codec.decode(&payload, &mut out).unwrap();
            lines.push_str(&format!("{} {}\n", message.id, hex(&payload)));
            expected.push(
                message
                    .signals
                    .iter()
                    .zip(&out)
                    .map(|(s, d)| (s.name.clone(), d.unwrap().physical.as_f64()))
                    .collect::<Vec<_>>(),
            );
        }
    }
    let script = r#"
import sys, json, cantools
db = cantools.database.load_file(sys.argv[1])
for line in sys.stdin:
    frame_id, data = line.split()
    decoded = db.decode_message(int(frame_id), bytes.fromhex(data), decode_choices=False)
    print(json.dumps({k: float(v) for k, v in decoded.items()}))
"#;
    let mut child = Command::new("python3")
        .args(["-c", script])
        .arg(&dbc_path)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    use std::io::Write;
    child
        .stdin
        .take()
        .unwrap()
        .write_all(lines.as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "cantools failed (installed by scripts/install-test-deps.sh)"
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let decoded: Vec<&str> = text.lines().collect();
    assert_eq!(decoded.len(), expected.len());
    for (line, ours) in decoded.iter().zip(&expected) {
        for (name, value) in ours {
            let key = format!("\"{name}\": ");
            let at = line
                .find(&key)
                .unwrap_or_else(|| panic!("{name} missing in {line}"));
            let rest = &line[at + key.len()..];
            let theirs: f64 = rest
                .split([',', '}'])
                .next()
                .unwrap()
                .trim()
                .parse()
                .unwrap();
            assert!(
                (theirs - value).abs() < 1e-9,
                "{name}: cantools {theirs}, bywire {value}"
            );
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02X}")).collect()
}
