//! Any bytes as a candump log and as screen lines: reading never panics, and every record read
//! writes back to a line that reads to the same record.
#![no_main]

use bywire_log::{Precision, Reader, Writer};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    for record in Reader::new(data).flatten() {
        let mut writer = Writer::new(Vec::new()).raw_dlc(true).precision(Precision::Nanos);
        writer.write_record(&record).unwrap();
        let bytes = writer.into_inner();
        let back: Vec<_> = Reader::new(&bytes[..]).collect();
        assert_eq!(back, vec![Ok(record)]);
    }
    if let Ok(text) = std::str::from_utf8(data) {
        for line in text.lines() {
            let _ = bywire_log::screen::parse_line(line);
        }
    }
});
