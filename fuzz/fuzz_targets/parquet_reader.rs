//! Any bytes as a Parquet file of raw frames: reading never panics (errors name the row).
//! The bytes go through a file because Parquet is read by seeking.
#![no_main]

use std::io::Write;

use bywire_log::format::Format;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = std::env::temp_dir().join(format!("bywire-fuzz-{}.parquet", std::process::id()));
    std::fs::File::create(&path).unwrap().write_all(data).unwrap();
    let file = std::fs::File::open(&path).unwrap();
    for _ in Format::Parquet.file_reader(file).take(100_000) {}
});
