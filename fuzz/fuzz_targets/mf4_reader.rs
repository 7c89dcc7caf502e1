//! Any bytes as an MF4 file: reading never panics (errors name the block's offset), and what is
//! read is written again and read back, frame for frame.
#![no_main]

use std::io::Cursor;

use bywire_log::mf4::{Mf4Reader, Mf4Writer};
use bywire_log::LogRecord;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(reader) = Mf4Reader::open(Cursor::new(data)) else {
        return;
    };
    let records: Vec<LogRecord> = reader.take(10_000).filter_map(Result::ok).collect();
    let mut writer = Mf4Writer::new(Cursor::new(Vec::new())).unwrap();
    for record in &records {
        writer.write(record).unwrap();
    }
    let written = writer.finish().unwrap().into_inner();
    let back: Vec<LogRecord> = Mf4Reader::open(Cursor::new(written.as_slice()))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(back.len(), records.len());
    // The same frames (the writer's groups are merged back by time: ties may change order).
    let sorted = |records: &[LogRecord]| {
        let mut frames: Vec<String> = records.iter().map(|r| format!("{:?}", r.frame)).collect();
        frames.sort();
        frames
    };
    assert_eq!(sorted(&records), sorted(&back));
});
