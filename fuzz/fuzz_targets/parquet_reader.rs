//! Any bytes as a Parquet file of raw frames: reading never panics (errors name the row).
//! The bytes go through a file because Parquet is read by seeking.
#![no_main]

use std::io::Write;
use std::sync::Once;

use bywire_log::format::Format;
use libfuzzer_sys::fuzz_target;

/// libfuzzer-sys aborts at any panic, caught or not. parquet-rs asserts on some malformed
/// pages, and the reader takes those panics as the file's error: a panic while the reader has
/// parquet-rs decode is let unwind to it; every other one still aborts (a finding), and so
/// would one the reader did not catch, in libfuzzer-sys's own wrapper.
fn let_the_readers_panics_unwind() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let aborting = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !bywire_log::parquet::panic_is_caught_by_reader() {
                aborting(info);
            }
        }));
    });
}

fuzz_target!(|data: &[u8]| {
    let_the_readers_panics_unwind();
    let path = std::env::temp_dir().join(format!("bywire-fuzz-{}.parquet", std::process::id()));
    std::fs::File::create(&path).unwrap().write_all(data).unwrap();
    let file = std::fs::File::open(&path).unwrap();
    for _ in Format::Parquet.file_reader(file).take(100_000) {}
});
