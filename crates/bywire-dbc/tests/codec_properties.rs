//! Property tests for the codec: random signal layouts, written as DBC text and parsed, decode
//! what a bit-by-bit reference placement put into the payload, and encode it back exactly.
// Tests fail by panicking; helpers outside #[test] functions may unwrap too.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use bywire_dbc::codec::{MessageCodec, Value};
use bywire_dbc::{parse_str, Mode};
use proptest::prelude::*;

#[derive(Debug, Clone)]
struct Sig {
    start: u32,
    length: u32,
    big_endian: bool,
    signed: bool,
    /// None: scale 1 offset 0; Some: a fractional scale and an offset.
    scaling: Option<(f64, f64)>,
    raw: u64,
}

/// The absolute bit positions (byte * 8 + bit, bit 0 the LSB), least significant bit first,
/// straight from the DBC definition of the two numberings.
fn positions(start: u32, length: u32, big_endian: bool) -> Vec<u32> {
    let mut msb_first = Vec::new();
    let mut p = start;
    if big_endian {
        for _ in 0..length {
            msb_first.push(p);
            p = if p.is_multiple_of(8) { p + 15 } else { p - 1 };
        }
        msb_first.reverse();
        msb_first
    } else {
        (start..start + length).collect()
    }
}

fn layout(size: u32) -> impl Strategy<Value = Vec<Sig>> {
    let bits = size * 8;
    prop::collection::vec(
        (
            0..bits,
            1u32..=64,
            any::<bool>(),
            any::<bool>(),
            prop::option::of((
                prop_oneof![Just(0.5), Just(0.01), Just(0.1), Just(2.5), Just(-0.25)],
                -100.0f64..100.0,
            )),
            any::<u64>(),
        ),
        1..12,
    )
    .prop_map(move |candidates| {
        let mut used = vec![false; usize::try_from(bits).unwrap()];
        let mut sigs = Vec::new();
        for (start, length, big_endian, signed, scaling, raw) in candidates {
            // Fractional scales keep raw values exact in f64 only up to 2^53: stay at 32 bits.
            let length = if scaling.is_some() {
                length.min(32)
            } else {
                length
            };
            let pos = positions(start, length, big_endian);
            if pos
                .iter()
                .any(|&p| p >= bits || used[usize::try_from(p).unwrap()])
            {
                continue;
            }
            for &p in &pos {
                used[usize::try_from(p).unwrap()] = true;
            }
            let mask = if length == 64 {
                u64::MAX
            } else {
                (1u64 << length) - 1
            };
            sigs.push(Sig {
                start,
                length,
                big_endian,
                signed,
                scaling,
                raw: raw & mask,
            });
        }
        sigs
    })
    .prop_filter("at least one signal fits", |s| !s.is_empty())
}

fn dbc(size: u32, sigs: &[Sig]) -> String {
    let mut text = format!("BO_ 291 Msg: {size} Node\n");
    for (i, s) in sigs.iter().enumerate() {
        let (scale, offset) = match s.scaling {
            Some((scale, offset)) => (format!("{scale:?}"), format!("{offset:?}")),
            None => ("1".into(), "0".into()),
        };
        text += &format!(
            " SG_ S{i} : {}|{}@{}{} ({scale},{offset}) [0|0] \"\" Node\n",
            s.start,
            s.length,
            if s.big_endian { 0 } else { 1 },
            if s.signed { '-' } else { '+' }
        );
    }
    text
}

fn place(size: u32, sigs: &[Sig]) -> Vec<u8> {
    let mut payload = vec![0u8; usize::try_from(size).unwrap()];
    for s in sigs {
        for (k, p) in positions(s.start, s.length, s.big_endian)
            .into_iter()
            .enumerate()
        {
            if (s.raw >> k) & 1 == 1 {
                payload[usize::try_from(p / 8).unwrap()] |= 1 << (p % 8);
            }
        }
    }
    payload
}

fn expected(s: &Sig) -> Value {
    let value: i128 = if s.signed && s.length < 64 && (s.raw >> (s.length - 1)) & 1 == 1 {
        i128::from(s.raw) - (1i128 << s.length)
    } else if s.signed && s.length == 64 {
        i128::from(i64::from_ne_bytes(s.raw.to_ne_bytes()))
    } else {
        i128::from(s.raw)
    };
    match s.scaling {
        None => Value::integer(value),
        // |value| < 2^32 for scaled signals (see `layout`): exact in f64.
        #[allow(clippy::cast_precision_loss)]
        Some((scale, offset)) => Value::Float(value as f64 * scale + offset),
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1000))]

    #[test]
    fn random_layouts_decode_and_encode_exactly(fd in any::<bool>(), sigs in layout(8), fd_sigs in layout(64)) {
        let (size, sigs) = if fd { (64, fd_sigs) } else { (8, sigs) };
        let text = dbc(size, &sigs);
        let (db, diagnostics) = parse_str(&text, Mode::Strict).unwrap();
        prop_assert!(diagnostics.is_empty());
        let codec = MessageCodec::new(&db.messages[0]);
        let payload = place(size, &sigs);
        let mut out = vec![None; codec.signal_count()];
        codec.decode(&payload, &mut out).unwrap();
        for (s, d) in sigs.iter().zip(&out) {
            let d = d.unwrap();
            prop_assert_eq!(d.raw, s.raw, "{:?}", s);
            prop_assert_eq!(d.physical, expected(s), "{:?}", s);
        }
        let values: Vec<Option<Value>> = out.iter().map(|d| d.map(|d| d.physical)).collect();
        let mut encoded = vec![0u8; codec.size()];
        codec.encode(&values, &mut encoded).unwrap();
        prop_assert_eq!(encoded, payload);
    }

    #[test]
    fn decoding_any_bytes_never_panics(text_sigs in layout(8), data in prop::collection::vec(any::<u8>(), 0..80)) {
        let (db, _) = parse_str(&dbc(8, &text_sigs), Mode::Lenient).unwrap();
        let codec = MessageCodec::new(&db.messages[0]);
        let mut out = vec![None; codec.signal_count()];
        let result = codec.decode(&data, &mut out);
        prop_assert_eq!(result.is_err(), data.len() < 8);
    }

    #[test]
    fn parsing_any_text_never_panics(text in "\\\\PC{0,400}") {
        let _ = parse_str(&text, Mode::Lenient);
    }

    #[test]
    fn parsing_dbc_like_text_never_panics(text in "(BO_|SG_|CM_|BA_|VAL_|SG_MUL_VAL_|[ :;,|@()+\\-\"\\n0-9A-Za-z_.]){0,300}") {
        if let Ok((db, _)) = parse_str(&text, Mode::Lenient) {
            // Whatever loaded writes back to text that loads to the same database.
            let again = parse_str(&bywire_dbc::write(&db), Mode::Lenient).unwrap().0;
            prop_assert_eq!(again, db);
        }
    }
}
