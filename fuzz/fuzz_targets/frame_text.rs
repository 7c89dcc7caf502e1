//! Any text as a can-utils frame: parsing never panics, and a parsed frame prints to text that
//! parses to the same frame.
#![no_main]

use bywire_core::Frame;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(frame) = text.parse::<Frame>() {
        assert_eq!(frame.to_string().parse::<Frame>(), Ok(frame));
    }
    let _ = text.parse::<bywire_core::filter::FilterItem>();
});
