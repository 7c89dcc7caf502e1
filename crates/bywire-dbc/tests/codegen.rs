//! Generated Rust code against the compiled codec: for several corpus files the generated
//! module is compiled with rustc into a harness that prints every signal's raw and physical
//! value for a set of payloads and sets each value back; the results must agree with
//! `MessageCodec` exactly.
// Tests fail by panicking; helpers outside #[test] functions may unwrap too.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::fmt::Write;
use std::path::Path;
use std::process::Command;

use bywire_dbc::codec::MessageCodec;
use bywire_dbc::{codegen, parse, Database, Mode, Multiplexing, INDEPENDENT_SIGNALS};

const FILES: &[&str] = &[
    "cantools/tests__files__dbc__motohawk.dbc",
    "cantools/tests__files__dbc__floating_point.dbc",
    "cantools/tests__files__dbc__long_names.dbc",
    "opendbc/opendbc__dbc__gm_global_a_object.dbc",
    "opendbc/opendbc__dbc__ESR.dbc",
    "opendbc/opendbc__dbc__generator__hyundai__hyundai_canfd.dbc",
];

fn payloads(size: usize, seed: u64) -> Vec<Vec<u8>> {
    let mut state = seed | 1;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let mut out = vec![vec![0u8; size], vec![0xFF; size]];
    for _ in 0..3 {
        out.push((0..size).map(|_| next().to_le_bytes()[0]).collect());
    }
    out
}

fn harness(db: &Database, generated: &Path) -> String {
    let names = codegen::names(db);
    let mut main = format!(
        "include!({:?});\nuse messages::*;\nfn main() {{\n",
        generated.display()
    );
    let messages = db.messages.iter().filter(|m| m.name != INDEPENDENT_SIGNALS);
    for (mi, (m, n)) in messages.zip(&names).enumerate() {
        let size = usize::try_from(m.size.min(64)).unwrap();
        for (pi, p) in payloads(size, mi as u64 + 1).iter().enumerate() {
            writeln!(
                main,
                "  let m = {}::from_bytes(&{p:?}).unwrap();",
                n.type_name
            )
            .unwrap();
            for (si, g) in n.getters.iter().enumerate() {
                writeln!(
                    main,
                    "  {{ let mut t = {ty}::default(); let ok = t.set_{g}(m.{g}()).is_ok(); let mut r = {ty}::default(); r.set_{g}_raw(m.{g}_raw()); println!(\"{mi} {pi} {si} {{}} {{}} {{}} {{}} {{}}\", m.{g}_raw(), m.{g}().to_bits(), ok, t.{g}_raw(), r.{g}_raw()); }}",
                    ty = n.type_name
                )
                .unwrap();
            }
        }
    }
    main + "}\n"
}

#[test]
fn generated_accessors_agree_with_the_codec() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/corpus/dbc");
    let dir = std::env::temp_dir().join(format!("bywire-codegen-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut checked = 0;
    for (fi, file) in FILES.iter().enumerate() {
        let (db, _) = parse(&std::fs::read(root.join(file)).unwrap(), Mode::Lenient).unwrap();
        let generated = dir.join(format!("gen{fi}.rs"));
        std::fs::write(&generated, codegen::generate(&db)).unwrap();
        let main = dir.join(format!("main{fi}.rs"));
        std::fs::write(&main, harness(&db, &generated)).unwrap();
        let binary = dir.join(format!("bin{fi}"));
        let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into());
        // The generated module builds without std, as ECU code needs.
        let no_std = dir.join(format!("nostd{fi}.rs"));
        std::fs::write(&no_std, format!("#![no_std]\n{}", codegen::generate(&db))).unwrap();
        let compiled = Command::new(&rustc)
            .args(["--edition", "2021", "--crate-type", "lib", "--crate-name"])
            .arg(format!("nostd{fi}"))
            .arg("-o")
            .arg(dir.join(format!("libnostd{fi}.rlib")))
            .arg(&no_std)
            .output()
            .unwrap();
        assert!(
            compiled.status.success(),
            "{file} without std: {}",
            String::from_utf8_lossy(&compiled.stderr)
        );
        let compiled = Command::new(rustc)
            .args(["--edition", "2021", "-C", "opt-level=0", "-o"])
            .arg(&binary)
            .arg(&main)
            .output()
            .unwrap();
        assert!(
            compiled.status.success(),
            "{file}: {}",
            String::from_utf8_lossy(&compiled.stderr)
        );
        let out = String::from_utf8(Command::new(&binary).output().unwrap().stdout).unwrap();
        let messages: Vec<_> = db
            .messages
            .iter()
            .filter(|m| m.name != INDEPENDENT_SIGNALS)
            .collect();
        for line in out.lines() {
            let f: Vec<&str> = line.split(' ').collect();
            let (mi, pi, si): (usize, usize, usize) = (
                f[0].parse().unwrap(),
                f[1].parse().unwrap(),
                f[2].parse().unwrap(),
            );
            let (raw, phys_bits, set_ok, set_raw, raw_again): (u64, u64, bool, u64, u64) = (
                f[3].parse().unwrap(),
                f[4].parse().unwrap(),
                f[5].parse().unwrap(),
                f[6].parse().unwrap(),
                f[7].parse().unwrap(),
            );
            assert_eq!(raw_again, raw, "raw setter");
            let m = messages[mi];
            let s = &m.signals[si];
            let codec = MessageCodec::new(m);
            let payload = &payloads(usize::try_from(m.size.min(64)).unwrap(), mi as u64 + 1)[pi];
            let context = format!("{file} {}.{} payload {pi}", m.name, s.name);
            let Some(expected_raw) = codec.read_raw(si, payload) else {
                continue;
            };
            assert_eq!(raw, expected_raw, "{context}: raw");
            let mut out = vec![None; codec.signal_count()];
            let plain = m
                .signals
                .iter()
                .all(|s| s.multiplexing == Multiplexing::None);
            if plain && codec.decode(payload, &mut out).is_ok() && raw < (1 << 53) {
                let expected = out[si].unwrap().physical.as_f64();
                assert_eq!(
                    f64::from_bits(phys_bits).to_bits(),
                    expected.to_bits(),
                    "{context}: physical"
                );
            }
            // Setting the value read gives the same raw bits, unless it is outside the declared
            // range (then the setter must refuse it).
            let physical = f64::from_bits(phys_bits);
            let (min, max) = (s.minimum.as_f64(), s.maximum.as_f64());
            let in_range = (min == 0.0 && max == 0.0) || (physical >= min && physical <= max);
            // f64 holds integer raw values exactly below 2^53 (float signals always); beyond
            // that only the raw setter is exact.
            let exact =
                raw < (1 << 53) || !matches!(s.value_type, bywire_dbc::ValueType::Integer { .. });
            if physical.is_finite() && !in_range {
                assert!(
                    !set_ok,
                    "{context}: set accepted {physical} outside [{min}, {max}]"
                );
            } else if physical.is_finite() && exact {
                assert!(set_ok, "{context}: set refused {physical}");
                assert_eq!(set_raw, raw, "{context}: set wrote other bits");
            }
            checked += 1;
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(checked > 3000, "only {checked} accessor checks");
}
