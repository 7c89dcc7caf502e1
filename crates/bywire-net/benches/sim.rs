//! Simulated seconds per wall second: one simulated second of a 500 kbit/s bus at about 60 %
//! load from 10 nodes, each sending 8-byte frames at its own period.
// Benchmark set-up may panic on impossible inputs; the measured code is the library.
#![allow(clippy::unwrap_used, clippy::indexing_slicing, missing_docs)]

use std::time::Duration;

use bywire_core::{Frame, Timestamp};
use bywire_net::sim::SimBus;
use criterion::{criterion_group, criterion_main, Criterion, Throughput};

fn one_second() -> SimBus {
    let mut bus = SimBus::new(500_000, None);
    let nodes: Vec<usize> = (0..10).map(|_| bus.add_node()).collect();
    // These 8-byte standard frames take about 111 bits with stuffing and intermission: 2,700
    // frames/s fill 60 % of 500 kbit/s, 270 per node: one every 3.7 ms, offset per node.
    for (i, &n) in nodes.iter().enumerate() {
        let frame: Frame = format!(
            "{:03X}#{:016X}",
            0x100 + i * 0x10,
            0x0123_4567_89AB_CDEFu64.rotate_left(u32::try_from(i).unwrap() * 7)
        )
        .parse()
        .unwrap();
        for k in 0..270u64 {
            let at = Timestamp::from_micros(k * 3_703 + u64::try_from(i).unwrap() * 400);
            bus.submit(n, frame, at);
        }
    }
    bus
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("sim");
    group.throughput(Throughput::Elements(1));
    group.bench_function("500k_60pct_10nodes/simulated_second", |b| {
        b.iter_batched(
            one_second,
            |mut bus| {
                bus.advance(Timestamp::ZERO.saturating_add(Duration::from_secs(1)));
                bus.busy_ns()
            },
            criterion::BatchSize::LargeInput,
        )
    });
    group.finish();
    let mut bus = one_second();
    bus.advance(Timestamp::from_millis(1000));
    eprintln!(
        "load of the benchmark bus: {:.1} %",
        bus.busy_ns() as f64 / 1e7
    );
}

criterion_group!(benches, bench);
criterion_main!(benches);
