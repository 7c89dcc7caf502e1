//! Any bytes as a KCD, SYM, ARXML or CDD file (the first byte picks): lenient and strict
//! reading never panic; whatever KCD or SYM loads, written in its own format, reads back as
//! what the format says; whatever ARXML or CDD loads decodes any frame of its messages and
//! container frames.
#![no_main]

use bywire_core::{Frame, Id};
use bywire_dbc::decoder::Decoder;
use bywire_dbc::{format, Format, Mode};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&pick, file)) = data.split_first() else { return };
    let kind = match pick % 4 {
        0 => Format::Kcd,
        1 => Format::Sym,
        2 => Format::Arxml,
        _ => Format::Cdd,
    };
    let _ = format::load(file, kind, Mode::Strict);
    let Ok((db, _)) = format::load(file, kind, Mode::Lenient) else {
        return;
    };
    if !kind.is_written() {
        let decoder = Decoder::new(db);
        let payload = file.get(..file.len().min(64)).unwrap_or_default();
        for (index, m) in decoder.database().messages.iter().enumerate() {
            let id = if m.extended { Id::extended(m.id) } else { Id::standard(m.id) };
            if let Some(frame) = id.ok().and_then(|id| Frame::fd(id, payload, false, false).ok()) {
                let _ = decoder.decode(&frame);
            }
            if let Some(pdus) = decoder.contained(index, payload) {
                for pdu in pdus.flatten() {
                    if let Some((_, codec, _)) = pdu.message {
                        let mut values = vec![None; codec.signal_count()];
                        let _ = codec.decode(pdu.pdu.data, &mut values);
                    }
                }
            }
        }
        return;
    }
    let (text, _) = format::write(&db, kind);
    let again = format::load(text.as_bytes(), kind, Mode::Lenient).map(|(db, _)| db);
    assert_eq!(again.ok(), Some(format::expressible(&db, kind).0));
});
