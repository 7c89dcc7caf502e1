//! Any layout and any payload: the first bytes describe up to 8 signals (start, length, byte
//! order, sign, multiplexing), the rest is the payload. Compiling and decoding never panic, and
//! for layouts without diagnostics decoding, encoding and decoding again gives the same values.
#![no_main]

use bywire_dbc::codec::{MessageCodec, Value};
use bywire_dbc::{parse_str, Mode};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&count, rest)) = data.split_first() else { return };
    let count = usize::from(count % 8) + 1;
    if rest.len() < count * 3 + 1 {
        return;
    }
    let (spec, rest) = rest.split_at(count * 3);
    let (size, payload) = rest.split_first().map(|(s, p)| (u32::from(*s % 65), p)).unwrap_or((8, &[]));
    let mut text = format!("BO_ 1 M: {size} N\n");
    for (i, s) in spec.chunks(3).enumerate() {
        let start = u32::from(s[0]) | (u32::from(s[2] & 0x01) << 8);
        let length = u32::from(s[1] % 64) + 1;
        let order = (s[2] >> 1) & 1;
        let sign = if s[2] & 4 != 0 { '-' } else { '+' };
        let mux = match (s[2] >> 3) & 3 {
            0 => String::new(),
            1 if i == 0 => " M".into(),
            v => format!(" m{v}"),
        };
        text += &format!(" SG_ S{i}{mux} : {start}|{length}@{order}{sign} (1,0) [0|0] \"\" N\n");
    }
    let Ok((db, diagnostics)) = parse_str(&text, Mode::Lenient) else { return };
    // Overlapping signals overwrite each other's bits when encoding: check only clean layouts.
    let clean = diagnostics.is_empty();
    let Some(message) = db.messages.first() else { return };
    let codec = MessageCodec::new(message);
    let mut out = vec![None; codec.signal_count()];
    if codec.decode(payload, &mut out).is_err() {
        return;
    }
    let values: Vec<Option<Value>> = out.iter().map(|d| d.map(|d| d.physical)).collect();
    let mut encoded = vec![0u8; codec.size()];
    codec.encode(&values, &mut encoded).expect("a payload of the message's size");
    let mut again = vec![None; codec.signal_count()];
    let decoded_again = codec.decode(&encoded, &mut again);
    if clean {
        assert_eq!(decoded_again, Ok(()));
        assert_eq!(again, out);
    }
});
