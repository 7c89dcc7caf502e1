//! Any bytes as a DBC file: lenient and strict parsing never panic, and whatever loads writes
//! back to text that loads to the same database.
#![no_main]

use bywire_dbc::{parse, parse_str, write, Mode};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = parse(data, Mode::Strict);
    if let Ok((db, _)) = parse(data, Mode::Lenient) {
        let again = parse_str(&write(&db), Mode::Lenient).map(|(db, _)| db);
        assert_eq!(again.ok(), Some(db));
    }
});
