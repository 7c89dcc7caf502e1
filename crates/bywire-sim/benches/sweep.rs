//! Sweep throughput: four whole apron-loop runs (seeds 1–4, the route to its end) on two
//! threads, each writing its logs, truth and metrics into a temporary folder — runs per
//! minute on 2 cores is 4 × 60 / the time per iteration.
#![allow(missing_docs, clippy::unwrap_used)]

use criterion::{criterion_group, criterion_main, Criterion};

use bywire_core::Timestamp;
use bywire_sim::scenario::Scenario;
use bywire_sim::sweep;

fn four_runs_on_two_threads(c: &mut Criterion) {
    let scenario = Scenario::builtin("apron-loop").unwrap();
    let jobs = sweep::jobs(&[scenario], 1..=4, &[], &[]);
    let out = std::env::temp_dir().join(format!("bywire-bench-sweep-{}", std::process::id()));
    let mut group = c.benchmark_group("sweep");
    group.sample_size(10);
    group.bench_function("4 apron-loop runs, 2 threads", |b| {
        b.iter(|| {
            let outcomes = sweep::run(
                &jobs,
                2,
                Timestamp::from_millis(300_000),
                Timestamp::ZERO,
                &out,
                &|_, _| {},
            );
            assert!(outcomes
                .iter()
                .all(|o| o.as_ref().is_ok_and(|(_, r)| r.completed)));
        })
    });
    group.finish();
    let _ = std::fs::remove_dir_all(&out);
}

criterion_group!(benches, four_runs_on_two_threads);
criterion_main!(benches);
