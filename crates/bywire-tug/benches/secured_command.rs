//! The cost of an authenticated command on the vehicle side, on one core: the supervisor's
//! wire reading one command frame as it is, and secured (freshness rebuilt, MAC checked, then
//! read, the command before it taken); and a forged secured frame refused (every candidate
//! freshness value tried: the most a frame costs).
#![allow(missing_docs, clippy::unwrap_used)]

use bywire_secoc::Key;
use bywire_tug::secured;
use bywire_tug::wire::ReferenceWire;
use bywire_vehicle::command::ControlCommand;
use bywire_vehicle::redundancy::Channel;
use bywire_vehicle::wire::{AdsWire, VehicleWire};
use criterion::{black_box, criterion_group, criterion_main, Criterion};

fn bench(c: &mut Criterion) {
    let key = Key::new([0x2b; 16]);
    let command = ControlCommand {
        steering: 12.5,
        velocity: 3.0,
        ..ControlCommand::default()
    };
    let plain = ReferenceWire.command_frame(&command, 5).unwrap();
    c.bench_function("tug command read, plain", |b| {
        b.iter(|| ReferenceWire.incoming(black_box(&plain)))
    });
    // The vehicle has taken the command before (freshness 999): the next one is one MAC.
    let mut ads = secured::secured(&key, 999).unwrap();
    let before = ads.command_frame(&command, 4).unwrap();
    let signed = ads.command_frame(&command, 5).unwrap();
    let mut vehicle = secured::secured(&key, 1).unwrap();
    vehicle.incoming_from(Channel::A, &before);
    c.bench_function("tug command verified and read, secured", |b| {
        b.iter_batched(
            || vehicle.clone(),
            |mut wire| wire.incoming_from(Channel::A, black_box(&signed)),
            criterion::BatchSize::SmallInput,
        )
    });
    let mut data = signed.data().to_vec();
    if let Some(last) = data.get_mut(11) {
        *last ^= 1;
    }
    let forged = bywire_core::Frame::fd(signed.id().unwrap(), &data, true, false).unwrap();
    c.bench_function("tug command refused, forged", |b| {
        b.iter_batched(
            || vehicle.clone(),
            |mut wire| wire.incoming_from(Channel::A, black_box(&forged)),
            criterion::BatchSize::SmallInput,
        )
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
