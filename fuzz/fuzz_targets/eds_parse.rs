//! Any text as an EDS/DCF file: reading never panics, every diagnostic names a line within the
//! file, and what was read writes out to a file that reads back into the same dictionary.
#![no_main]

use bywire_canopen::eds;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let Ok(read) = eds::parse(text, Some(5)) else { return };
    let lines = text.lines().count();
    assert!(read.diagnostics.iter().all(|d| d.line <= lines));
    if read.dictionary.objects().is_empty() {
        return;
    }
    let written = eds::write(&read.dictionary, &read.info, None);
    let again = eds::parse(&written, Some(5)).unwrap();
    assert_eq!(again.dictionary, read.dictionary);
});
