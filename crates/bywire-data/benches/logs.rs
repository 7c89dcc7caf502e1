//! Dataset and latency throughput: ten minutes of the reference tug's bus 1 (its eight cyclic
//! messages at their cycle times, values changing every frame, the steering mode switching
//! every 30 s) through `dataset::Builder` at 50 Hz and through `latency::Analyzer`, on one
//! core. Frames per second of input is the frame count / the time per iteration.
#![allow(missing_docs, clippy::unwrap_used, clippy::indexing_slicing)]

use criterion::{criterion_group, criterion_main, Criterion, Throughput};

use bywire_core::frame::{ClassicFrame, StandardId};
use bywire_core::{Frame, Id, Timestamp};
use bywire_data::dataset::{Builder, Config};
use bywire_data::latency::{Analyzer, Config as LatencyConfig};
use bywire_dbc::codec::{MessageCodec, Value};
use bywire_dbc::decoder::Decoder;

/// Ten minutes of bus 1: every message of the tug's DBC with a cycle time, at that cycle.
fn traffic() -> (
    Decoder,
    Vec<(Timestamp, Frame)>,
    bywire_vehicle::profile::LoadedProfile,
) {
    let loaded = bywire_tug::profile().unwrap();
    let db = loaded.database.clone();
    let mut frames = Vec::new();
    for message in &db.messages {
        let Some(cycle) = db.cycle_time(message) else {
            continue;
        };
        let codec = MessageCodec::new(message);
        let period = u64::try_from(cycle.as_nanos()).unwrap();
        let mut t = 0u64;
        let mut k = 0u64;
        while t < 600_000_000_000 {
            // Each signal walks through its raw range; the steering mode changes every 30 s.
            let values: Vec<Option<Value>> = message
                .signals
                .iter()
                .map(|s| {
                    let v = if s.name.contains("SteeringMode") {
                        ((t / 30_000_000_000) % 2) as f64
                    } else {
                        (k % 16) as f64
                    };
                    Some(Value::Float(v))
                })
                .collect();
            let mut data = [0u8; 8];
            if codec.encode(&values, &mut data).is_ok() {
                let id = Id::Standard(StandardId::new(u16::try_from(message.id).unwrap()).unwrap());
                frames.push((
                    Timestamp::from_nanos(t),
                    Frame::Classic(ClassicFrame::new(id, &data[..message.size as usize]).unwrap()),
                ));
            }
            t += period;
            k += 1;
        }
    }
    frames.sort_by_key(|(t, _)| *t);
    (Decoder::new(db), frames, loaded)
}

fn throughput(c: &mut Criterion) {
    let (decoder, frames, profile) = traffic();
    let mut group = c.benchmark_group("logs");
    group.sample_size(10);
    group.throughput(Throughput::Elements(frames.len() as u64));
    group.bench_function("dataset rows at 50 Hz", |b| {
        b.iter(|| {
            let mut builder = Builder::new(&decoder, Config::from_profile(&profile, 50.0)).unwrap();
            let mut rows = 0u64;
            for (t, f) in &frames {
                builder.push(*t, f, &mut |_| rows += 1);
            }
            builder.finish(&mut |_| rows += 1);
            assert!(rows >= 30_000);
        })
    });
    group.bench_function("latency analysis", |b| {
        b.iter(|| {
            let mut analyzer =
                Analyzer::new(&decoder, LatencyConfig::from_profile(&profile)).unwrap();
            for (t, f) in &frames {
                analyzer.push(*t, "bus1", f);
            }
            assert!(analyzer.finish().records > 0);
        })
    });
    group.finish();
}

criterion_group!(benches, throughput);
criterion_main!(benches);
