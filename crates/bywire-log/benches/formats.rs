//! Reading and writing each log format: 100,000 frames of mixed identifiers and lengths on two
//! interfaces, from a candump log in memory, through each writer, and back through each reader.
//! The peers' figures (python-can's `can.logconvert`, can-utils' `log2asc`) come from running
//! them on the same data; see the project's notes.
#![allow(missing_docs, clippy::unwrap_used, clippy::indexing_slicing)]

use std::io::Cursor;

use bywire_core::{Frame, Id, Timestamp};
use bywire_log::format::Format;
use bywire_log::stats::LogStats;
use bywire_log::LogRecord;
use criterion::{criterion_group, criterion_main, Criterion, Throughput};

const FRAMES: u64 = 100_000;

fn records() -> Vec<LogRecord> {
    (0..FRAMES)
        .map(|i| {
            let raw = [0x123, 0x1F0, 0x200, 0x18FF_1234][usize::try_from(i % 4).unwrap()];
            let id = if raw > 0x7FF {
                Id::extended(raw)
            } else {
                Id::standard(raw)
            }
            .unwrap();
            let length = usize::try_from(i % 9).unwrap();
            let data: Vec<u8> = (0..length)
                .map(|b| u8::try_from((i + b as u64) % 256).unwrap())
                .collect();
            LogRecord {
                timestamp: Timestamp::from_nanos(1_700_000_000_000_000_000 + i * 500_000),
                interface: format!("can{}", i % 2),
                frame: Frame::classic(id, &data).unwrap(),
                direction: Some('R'),
            }
        })
        .collect()
}

fn write(format: Format, records: &[LogRecord]) -> Vec<u8> {
    let mut writer = format.writer(Cursor::new(Vec::new())).unwrap();
    for record in records {
        writer.write(record).unwrap();
    }
    writer.finish().unwrap().into_inner()
}

fn formats(c: &mut Criterion) {
    let records = records();
    let mut group = c.benchmark_group("100,000 frames");
    group.throughput(Throughput::Elements(FRAMES));
    group.sample_size(10);
    for (format, name) in Format::ALL {
        group.bench_function(format!("write {name}"), |b| {
            b.iter(|| write(format, &records))
        });
        let bytes = write(format, &records);
        if matches!(format, Format::Parquet | Format::Mf4) {
            // Parquet and MF4 are read from a file (their indexes link by offset).
            let path =
                std::env::temp_dir().join(format!("bywire-bench-{}.{name}", std::process::id()));
            std::fs::write(&path, &bytes).unwrap();
            group.bench_function(format!("read {name}"), |b| {
                b.iter(|| {
                    format
                        .file_reader(std::fs::File::open(&path).unwrap())
                        .count()
                })
            });
            std::fs::remove_file(&path).unwrap();
            continue;
        }
        group.bench_function(format!("read {name}"), |b| {
            b.iter(|| format.reader(bytes.as_slice()).count())
        });
    }
    group.finish();
}

/// Reading candump text, in bytes per second: records lent by the reader (no copy of a
/// line), and counted as `bywire log stats` counts them.
fn candump_reading(c: &mut Criterion) {
    let text = write(Format::Candump, &records());
    let mut group = c.benchmark_group("candump text");
    group.throughput(Throughput::Bytes(u64::try_from(text.len()).unwrap()));
    group.sample_size(20);
    group.bench_function("read, records lent", |b| {
        b.iter(|| {
            let mut frames = 0u64;
            let end: Option<()> = bywire_log::Reader::new(text.as_slice()).for_each_ref(|r| {
                frames += u64::from(!r.unwrap().frame.data().is_empty());
                std::ops::ControlFlow::Continue(())
            });
            assert!(end.is_none());
            frames
        })
    });
    group.bench_function("read and counted (log stats)", |b| {
        b.iter(|| {
            let mut stats = LogStats::new();
            let _: Option<()> = bywire_log::Reader::new(text.as_slice()).for_each_ref(|r| {
                stats.add(r.unwrap());
                std::ops::ControlFlow::Continue(())
            });
            stats.frames
        })
    });
    group.finish();
}

criterion_group!(benches, formats, candump_reading);
criterion_main!(benches);
