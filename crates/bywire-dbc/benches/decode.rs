//! Decoding throughput on `gm_global_a_object.dbc` traffic: random frames of its messages,
//! the workload whose cantools figure the corpus README gives (about 250,000 frames/s).
// Benchmark set-up may panic on a missing corpus; the measured code is the library.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::cast_possible_truncation,
    missing_docs
)]

use bywire_dbc::codec::MessageCodec;
use bywire_dbc::{parse, Mode};
use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};

fn bench_decode(c: &mut Criterion) {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/corpus/dbc/opendbc/opendbc__dbc__gm_global_a_object.dbc"
    );
    let (db, _) = parse(&std::fs::read(path).unwrap(), Mode::Lenient).unwrap();
    let codecs: Vec<MessageCodec> = db.messages.iter().map(MessageCodec::new).collect();
    // A fixed pseudo-random stream of (message, payload), as a log would present them.
    let mut state = 0x1234_5678_9ABC_DEF0u64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let frames: Vec<(usize, [u8; 8])> = (0..4096)
        .map(|_| {
            (
                (next() % codecs.len() as u64) as usize,
                next().to_le_bytes(),
            )
        })
        .collect();
    let signals: usize = frames.iter().map(|(m, _)| codecs[*m].signal_count()).sum();
    let max = codecs.iter().map(MessageCodec::signal_count).max().unwrap();
    let mut out = vec![None; max];

    let mut group = c.benchmark_group("dbc_decode");
    group.throughput(Throughput::Elements(frames.len() as u64));
    group.bench_function("gm_global_a_object/frames", |b| {
        b.iter(|| {
            for (m, data) in &frames {
                let _ = codecs[*m].decode(black_box(data), &mut out);
            }
            out[0]
        })
    });
    group.throughput(Throughput::Elements(signals as u64));
    group.bench_function("gm_global_a_object/signals", |b| {
        b.iter(|| {
            for (m, data) in &frames {
                let _ = codecs[*m].decode(black_box(data), &mut out);
            }
            out[0]
        })
    });
    group.finish();
}

criterion_group!(benches, bench_decode);
criterion_main!(benches);
