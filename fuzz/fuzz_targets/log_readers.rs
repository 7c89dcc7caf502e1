//! Any bytes as each log format's file (ASC, TRC, BLF, pcapng, MCAP): reading never panics,
//! and every record read writes back through the same format's writer without a panic or an
//! error. The first byte picks the format, so one corpus grows for all of them.
#![no_main]

use bywire_log::format::Format;
use libfuzzer_sys::fuzz_target;

const FORMATS: [Format; 5] = [
    Format::Asc,
    Format::Trc,
    Format::Blf,
    Format::Pcapng,
    Format::Mcap,
];

fuzz_target!(|data: &[u8]| {
    let Some((pick, bytes)) = data.split_first() else {
        return;
    };
    let format = FORMATS[usize::from(*pick) % FORMATS.len()];
    let records: Vec<_> = format.reader(bytes).take(10_000).flatten().collect();
    let mut writer = format.writer(std::io::Cursor::new(Vec::new())).unwrap();
    for record in &records {
        writer.write(record).unwrap();
    }
    writer.finish().unwrap();
});
