//! The data engineer's path end to end: a candump log of a real vehicle DBC's traffic (Ford's
//! powertrain bus, 331 messages, random payloads) read, every signal decoded, and written as
//! the decoded Parquet dataset (a table per message; zstd, and snappy). The peer figures
//! (`python -m cantools decode`) come from running it on the same log; see the project's notes.
#![allow(missing_docs, clippy::unwrap_used, clippy::indexing_slicing)]

use std::ops::ControlFlow;

use bywire_data::decoded::{decode_frames_batch, DecodedDataset, Partitioning};
use bywire_dbc::decoder::Decoder;
use bywire_log::parquet::{raw_schema, FrameColumns, ParquetCompression};
use criterion::{criterion_group, criterion_main, BatchSize, Criterion, Throughput};

const FRAMES: u64 = 1_000_000;
const DBC: &str = "../../../shared/corpus/dbc/opendbc/opendbc__dbc__ford_lincoln_base_pt.dbc";

/// The traffic as candump log text: each message in turn, payloads from a fixed generator.
fn traffic(decoder: &Decoder) -> String {
    let messages = &decoder.database().messages;
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut text = String::new();
    for i in 0..FRAMES {
        let message = &messages[usize::try_from(i).unwrap() % messages.len()];
        let nanos = 1_700_000_000_000_000_000 + i * 137_000;
        let ident = if message.extended {
            format!("{:08X}", message.id)
        } else {
            format!("{:03X}", message.id)
        };
        let separator = if message.size > 8 { "##1" } else { "#" };
        let mut data = String::new();
        for _ in 0..message.size {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            data.push_str(&format!("{:02X}", state & 0xFF));
        }
        text.push_str(&format!(
            "({}.{:06}) can{} {ident}{separator}{data}\n",
            nanos / 1_000_000_000,
            nanos % 1_000_000_000 / 1000,
            i % 2
        ));
    }
    text
}

fn end_to_end(c: &mut Criterion) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(DBC);
    let (db, _) =
        bywire_dbc::parse(&std::fs::read(path).unwrap(), bywire_dbc::Mode::Lenient).unwrap();
    let decoder = Decoder::new(db);
    let log = traffic(&decoder);
    let out = std::env::temp_dir().join(format!("bywire-bench-dataset-{}", std::process::id()));
    let mut group = c.benchmark_group("decode 1,000,000 frames of a vehicle DBC");
    group.throughput(Throughput::Elements(FRAMES));
    group.sample_size(10);
    for (name, compression) in [
        ("candump to decoded Parquet", ParquetCompression::Zstd),
        (
            "candump to decoded Parquet, snappy",
            ParquetCompression::Snappy,
        ),
    ] {
        group.bench_function(name, |b| {
            b.iter(|| {
                let _ = std::fs::remove_dir_all(&out);
                let mut dataset =
                    DecodedDataset::create(&out, &decoder, Partitioning::default()).unwrap();
                dataset.set_compression(compression);
                // Records lent by the reader, as `bywire decode --parquet` reads one log.
                bywire_log::Reader::new(log.as_bytes()).for_each_ref(|record| {
                    dataset.write_lent(record.unwrap()).unwrap();
                    ControlFlow::<()>::Continue(())
                });
                dataset.finish().unwrap()
            })
        });
    }
    group.bench_function("candump read and decoded (no output)", |b| {
        b.iter(|| {
            let mut signals = 0usize;
            for record in bywire_log::Reader::new(log.as_bytes()) {
                if let Some(decoded) = decoder.decode(&record.unwrap().frame) {
                    signals += decoded.signals.len();
                }
            }
            signals
        })
    });
    // What the Python package's `decode_arrow` does: raw frames already in Arrow batches.
    let mut batches = Vec::new();
    let mut columns = FrameColumns::new();
    for record in bywire_log::Reader::new(log.as_bytes()) {
        columns.push(&record.unwrap());
        if columns.rows() == 65_536 {
            batches.push(columns.finish(&raw_schema()).unwrap());
        }
    }
    batches.push(columns.finish(&raw_schema()).unwrap());
    group.bench_function("raw frames batches decoded to tables", |b| {
        b.iter(|| {
            let mut tables = 0;
            for batch in &batches {
                tables += decode_frames_batch(&decoder, batch).unwrap().0.len();
            }
            tables
        })
    });
    group.finish();
    let _ = std::fs::remove_dir_all(&out);
    lake(c, &decoder, &batches);
}

/// A data lake's long files (`ts, channel, signal, value`, a file a message folder, snappy)
/// written from the decoded tables: bywire's encoding (`parquet::lake`) against parquet-rs's
/// `ArrowWriter` given the same rows as Arrow (`signals_long`), dictionaries for the texts,
/// into the same folders. The previous run's lake is removed untimed.
fn lake(c: &mut Criterion, decoder: &Decoder, batches: &[arrow_array::RecordBatch]) {
    use bywire_data::lake::{LakeCompression, LakeFiles, LAKE_GROUP_ROWS};
    use bywire_data::long::signals_long;
    use parquet::arrow::ArrowWriter;
    use parquet::file::properties::{EnabledStatistics, WriterProperties};
    use parquet::schema::types::ColumnPath;

    let tables: Vec<(String, arrow_array::RecordBatch)> = batches
        .iter()
        .flat_map(|batch| decode_frames_batch(decoder, batch).unwrap().0)
        .collect();
    let rows: usize = tables
        .iter()
        .map(|(_, t)| signals_long(t, None).unwrap().num_rows())
        .sum();
    let out = std::env::temp_dir().join(format!("bywire-bench-lake-{}", std::process::id()));
    let mut group = c.benchmark_group("a lake's long files from decoded tables");
    group.throughput(Throughput::Elements(rows as u64));
    group.sample_size(10);
    let fresh = || {
        let _ = std::fs::remove_dir_all(&out);
        out.clone()
    };
    group.bench_function("bywire (parquet::lake)", |b| {
        b.iter_batched(
            fresh,
            |out| {
                let mut files = LakeFiles::new(
                    &out,
                    "part-0",
                    LakeCompression::Snappy,
                    256,
                    LAKE_GROUP_ROWS,
                )
                .unwrap();
                for (message, table) in &tables {
                    files
                        .add(Some("v"), Some("2026-12-04"), message, table)
                        .unwrap();
                }
                files.finish().unwrap().len()
            },
            BatchSize::PerIteration,
        )
    });
    group.bench_function("parquet-rs ArrowWriter (signals_long)", |b| {
        b.iter_batched(
            fresh,
            |out| {
                let properties = WriterProperties::builder()
                    .set_compression(parquet::basic::Compression::SNAPPY)
                    .set_dictionary_enabled(false)
                    .set_column_dictionary_enabled(ColumnPath::from("channel"), true)
                    .set_column_dictionary_enabled(ColumnPath::from("signal"), true)
                    .set_statistics_enabled(EnabledStatistics::None)
                    .set_column_statistics_enabled(ColumnPath::from("ts"), EnabledStatistics::Chunk)
                    .build();
                let mut writers = std::collections::HashMap::new();
                for (message, table) in &tables {
                    let long = signals_long(table, None).unwrap();
                    let writer = writers.entry(message.clone()).or_insert_with(|| {
                        let folder =
                            out.join(format!("vehicle=v/date=2026-12-04/message={message}"));
                        std::fs::create_dir_all(&folder).unwrap();
                        let file = std::fs::File::create(folder.join("part-0.parquet")).unwrap();
                        ArrowWriter::try_new(file, long.schema(), Some(properties.clone())).unwrap()
                    });
                    writer.write(&long).unwrap();
                }
                let files = writers.len();
                for (_, writer) in writers {
                    writer.close().unwrap();
                }
                files
            },
            BatchSize::PerIteration,
        )
    });
    group.finish();
    let _ = std::fs::remove_dir_all(&out);
}

criterion_group!(benches, end_to_end);
criterion_main!(benches);
