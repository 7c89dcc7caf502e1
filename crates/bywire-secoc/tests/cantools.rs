//! bywire's secured frames against cantools' SecOC framing (`cantools.autosar.secoc`, 45.1.0)
//! with a CMAC-AES-128 authenticator from the `cryptography` package: for the same data ID,
//! lengths, key and freshness, the frames are equal, and each side verifies the other's and
//! refuses a frame with one bit changed.
//!
//! The layouts are AUTOSAR's profile 1, the lengths of a reference-tug command, and seeded
//! random ones (odd bit lengths, MACs that end mid-byte). cantools cannot express a zero-bit
//! field (its bit packing refuses one), so profile 2 ("24Bit-CMAC-No-FV"), layouts sending no
//! freshness bits and empty payloads are checked by the unit tests against RFC 4493's CMAC
//! alone.
// Truncating casts pick bytes and lengths from the seeded generator.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::cast_possible_truncation
)]

use std::io::{BufRead, BufReader, Write};
use std::process::{Command, Stdio};

use bywire_secoc::{profile, Authenticator, Key, Layout};

/// A small seeded generator (xorshift64*), so every run checks the same cases.
struct Seeded(u64);

impl Seeded {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn unhex(text: &str) -> Vec<u8> {
    (0..text.len() / 2)
        .map(|i| u8::from_str_radix(&text[i * 2..i * 2 + 2], 16).unwrap())
        .collect()
}

struct Case {
    key: [u8; 16],
    layout: Layout,
    freshness: u64,
    data: Vec<u8>,
}

fn cases() -> Vec<Case> {
    let mut rng = Seeded(0x5EC0C);
    let mut layouts = vec![
        Layout::of_profile(profile("24Bit-CMAC-8Bit-FV").unwrap(), 0x0100, 4).unwrap(),
        Layout::of_profile(profile("24Bit-CMAC-8Bit-FV").unwrap(), 0xBEEF, 60).unwrap(),
        // A tug command on CAN FD: 8 bytes, a 32-bit freshness with 8 bits sent, 32-bit MAC.
        Layout::new(0x0100, 8, 32, 8, 32).unwrap(),
        Layout::new(0x0001, 1, 64, 64, 128).unwrap(),
    ];
    while layouts.len() < 60 {
        let fv_length = 1 + rng.below(64) as u32;
        let fv_tx = 1 + rng.below(u64::from(fv_length)) as u32;
        let mac = 1 + rng.below(128) as u32;
        let payload = 1 + rng.below(47) as usize;
        if let Ok(layout) = Layout::new(rng.next() as u16, payload, fv_length, fv_tx, mac) {
            layouts.push(layout);
        }
    }
    layouts
        .into_iter()
        .map(|layout| {
            let mut key = [0u8; 16];
            key.iter_mut().for_each(|b| *b = rng.next() as u8);
            let freshness = rng.next() & layout.freshness_max();
            // The frame: the payload, room for the authenticator, and sometimes a byte more.
            let length = layout.secured_length() + rng.below(2) as usize;
            let data = (0..length.min(64)).map(|_| rng.next() as u8).collect();
            Case {
                key,
                layout,
                freshness,
                data,
            }
        })
        .collect()
}

/// cantools' secured frame of each case's data, and whether it verifies `data` as it is.
fn cantools(cases: &[(&Case, Vec<u8>)]) -> Vec<(Vec<u8>, bool)> {
    let script = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/oracles/cantools_secoc.py"
    );
    let mut peer = Command::new("python3")
        .arg(script)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("python3 with cantools and cryptography (scripts/install-test-deps.sh)");
    let mut input = peer.stdin.take().unwrap();
    for (case, data) in cases {
        let l = case.layout;
        writeln!(
            input,
            r#"{{"key":"{}","data_id":{},"payload_length":{},"fv_length":{},"fv_tx_length":{},"mac_tx_length":{},"freshness":{},"data":"{}"}}"#,
            hex(&case.key),
            l.data_id,
            l.payload_length,
            l.fv_length,
            l.fv_tx_length,
            l.mac_tx_length,
            case.freshness,
            hex(data)
        )
        .unwrap();
    }
    drop(input);
    let answers: Vec<(Vec<u8>, bool)> = BufReader::new(peer.stdout.take().unwrap())
        .lines()
        .map(|line| {
            let line = line.unwrap();
            let secured = line.split("\"secured\": \"").nth(1).unwrap();
            let secured = unhex(secured.split('"').next().unwrap());
            (secured, line.contains("\"verified\": true"))
        })
        .collect();
    assert!(peer.wait().unwrap().success(), "the cantools peer failed");
    assert_eq!(answers.len(), cases.len());
    answers
}

#[test]
fn secured_frames_equal_cantools_both_ways() {
    let cases = cases();
    let mut ours = Vec::new();
    for case in &cases {
        let auth = Authenticator::new(&Key::new(case.key));
        let mut secured = case.data.clone();
        auth.sign(&case.layout, case.freshness, &mut secured)
            .unwrap();
        ours.push(secured);
    }
    // cantools signs the unsigned data, and checks our signed frames and a bit-flipped copy.
    let mut asked: Vec<(&Case, Vec<u8>)> = Vec::new();
    for (case, secured) in cases.iter().zip(&ours) {
        asked.push((case, case.data.clone()));
        asked.push((case, secured.clone()));
        let mut flipped = secured.clone();
        let last_mac_bit = case.layout.payload_length * 8
            + (case.layout.fv_tx_length + case.layout.mac_tx_length) as usize
            - 1;
        flipped[last_mac_bit / 8] ^= 0x80 >> (last_mac_bit % 8);
        asked.push((case, flipped));
    }
    let answers = cantools(&asked);
    for (i, case) in cases.iter().enumerate() {
        let auth = Authenticator::new(&Key::new(case.key));
        let (theirs, _) = &answers[i * 3];
        assert_eq!(hex(theirs), hex(&ours[i]), "case {i}: {:?}", case.layout);
        assert!(answers[i * 3 + 1].1, "case {i}: cantools verifies ours");
        assert!(
            auth.verify(&case.layout, case.freshness, theirs),
            "case {i}: we verify cantools'"
        );
        let (_, flipped_ok) = &answers[i * 3 + 2];
        assert!(!flipped_ok, "case {i}: cantools refuses a changed MAC bit");
        assert!(!auth.verify(&case.layout, case.freshness, &asked[i * 3 + 2].1));
    }
}
