//! Simulation speed: one simulated second of the whole tug network (buses 1, 1b, 2 and 3
//! bit-timed; the ADS, the ECU, the safety controller, the BMS, eight CiA 402 drives, the IMU
//! and I/O nodes; the plants) per iteration, while the tug cruises the apron loop — a fresh tug
//! is started, untimed, whenever one nears the end of its route. Simulated seconds per wall
//! second is 1 / the time per iteration.
#![allow(missing_docs, clippy::unwrap_used)]

use std::time::{Duration, Instant};

use criterion::{criterion_group, criterion_main, Criterion};

use bywire_sim::tug::{Tug, TugParams};

/// A tug engaged and cruising (5 simulated seconds after power-on).
fn cruising() -> Tug {
    let mut tug = Tug::new(TugParams::default()).unwrap();
    for _ in 0..5_000 {
        tug.step();
    }
    tug
}

fn one_simulated_second(c: &mut Criterion) {
    let mut tug = cruising();
    c.bench_function("tug network, 1 simulated second", |b| {
        b.iter_custom(|iterations| {
            let mut spent = Duration::ZERO;
            for _ in 0..iterations {
                // Cruising only: the last 15 m are the slow-down and the stop.
                if tug.remaining().unwrap() < 15.0 {
                    tug = cruising();
                }
                let start = Instant::now();
                for _ in 0..1_000 {
                    tug.step();
                }
                spent += start.elapsed();
            }
            spent
        })
    });
}

criterion_group!(benches, one_simulated_second);
criterion_main!(benches);
