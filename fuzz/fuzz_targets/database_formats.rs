//! Any bytes as a KCD or SYM file (the first byte picks): lenient and strict reading never
//! panic, and whatever loads, written in its own format, reads back as what the format says.
#![no_main]

use bywire_dbc::{format, Format, Mode};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&pick, file)) = data.split_first() else { return };
    let kind = if pick & 1 == 0 { Format::Kcd } else { Format::Sym };
    let _ = format::load(file, kind, Mode::Strict);
    if let Ok((db, _)) = format::load(file, kind, Mode::Lenient) {
        let (text, _) = format::write(&db, kind);
        let again = format::load(text.as_bytes(), kind, Mode::Lenient).map(|(db, _)| db);
        assert_eq!(again.ok(), Some(format::expressible(&db, kind).0));
    }
});
