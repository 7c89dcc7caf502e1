//! Frames per second through the real-time virtual bus: one sender, 1 and 4 reader threads, each
//! reader receiving every frame.
// Benchmark set-up may panic on impossible inputs; the measured code is the library.
#![allow(clippy::unwrap_used, clippy::indexing_slicing, missing_docs)]

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Duration;

use bywire_bus::virtual_bus::VirtualBus;
use bywire_bus::{BusRx, BusTx};
use bywire_core::Frame;
use criterion::{criterion_group, criterion_main, Criterion, Throughput};

const FRAMES: usize = 20_000;

fn run(readers: usize, name: &str) {
    let mut sender = VirtualBus::join(name);
    let done = Arc::new(AtomicUsize::new(0));
    let handles: Vec<_> = (0..readers)
        .map(|_| {
            // Queues big enough that nothing is dropped: the figure is delivery, not loss.
            let mut rx = VirtualBus::join_with_queue(name, FRAMES);
            let done = Arc::clone(&done);
            std::thread::spawn(move || {
                let mut n = 0;
                while n < FRAMES {
                    if rx.recv(Some(Duration::from_secs(5))).unwrap().is_some() {
                        n += 1;
                    }
                }
                done.fetch_add(1, Ordering::SeqCst);
                rx.stats().rx_frames
            })
        })
        .collect();
    let frame: Frame = "123#0011223344556677".parse().unwrap();
    for _ in 0..FRAMES {
        sender.send(&frame).unwrap();
    }
    for h in handles {
        assert_eq!(h.join().unwrap(), FRAMES as u64);
    }
    assert_eq!(done.load(Ordering::SeqCst), readers);
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("virtual_bus");
    group.throughput(Throughput::Elements(FRAMES as u64));
    group.sample_size(10);
    group.bench_function("1_reader", |b| b.iter(|| run(1, "bench-1")));
    group.bench_function("4_readers", |b| b.iter(|| run(4, "bench-4")));
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
