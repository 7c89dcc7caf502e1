//! Simulation speed: one simulated second of the tug network (bus 1 and bus 2 bit-timed, ten
//! nodes, the plants) per iteration, cruising on the apron loop. Simulated seconds per wall
//! second is 1 / the time per iteration.
#![allow(missing_docs)]

use criterion::{criterion_group, criterion_main, Criterion};

use bywire_sim::tug::{apron_loop, Tug, TugParams};

fn one_simulated_second(c: &mut Criterion) {
    let mut tug = Tug::new(TugParams {
        seed: 1,
        payload: 2_000.0,
        grade: 0.0,
        route: apron_loop(),
        speed: 3.0,
        crab_final_m: 0.0,
        tank_turn_deg: 0.0,
        steering_steps: Vec::new(),
    });
    // Engaged and cruising before measuring.
    for _ in 0..5_000 {
        tug.step();
    }
    c.bench_function("tug network, 1 simulated second", |b| {
        b.iter(|| {
            for _ in 0..1_000 {
                tug.step();
            }
        })
    });
}

criterion_group!(benches, one_simulated_second);
criterion_main!(benches);
