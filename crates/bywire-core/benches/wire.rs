//! Wire encoding, decoding and CRC throughput.
// Benchmark set-up may panic on impossible inputs; the measured code is the library.
#![allow(clippy::unwrap_used, clippy::indexing_slicing, missing_docs)]

use bywire_core::crc::{crc15_can, crc8_h2f, crc8_sae_j1850, CrcRegister};
use bywire_core::wire;
use bywire_core::Frame;
use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};

fn frames() -> Vec<Frame> {
    [
        "123#DEADBEEF",
        "7FF#0011223344556677",
        "1ABCDEF0#CAFEBABE00FF00FF",
        "123##1000102030405060708090A0B0C0D0E0F101112131415161718191A1B1C1D1E1F202122232425262728292A2B2C2D2E2F303132333435363738393A3B3C3D3E3F",
    ]
    .iter()
    .map(|t| t.parse().unwrap())
    .collect()
}

fn bench_wire(c: &mut Criterion) {
    let mut group = c.benchmark_group("wire");
    for (name, frame) in ["classic4", "classic8", "extended8", "fd64"]
        .iter()
        .zip(frames())
    {
        group.throughput(Throughput::Elements(1));
        group.bench_function(format!("encode/{name}"), |b| {
            b.iter(|| wire::encode(black_box(&frame)).unwrap().len())
        });
        let bits = *wire::encode(&frame).unwrap().bits();
        group.bench_function(format!("decode/{name}"), |b| {
            b.iter(|| wire::decode(black_box(&bits)).unwrap())
        });
    }
    group.finish();
}

fn bench_crc(c: &mut Criterion) {
    let data: Vec<u8> = (0..64u8).collect();
    let mut group = c.benchmark_group("crc");
    group.throughput(Throughput::Bytes(8));
    group.bench_function("crc8_sae_j1850/8B", |b| {
        b.iter(|| crc8_sae_j1850(black_box(&data[..8])))
    });
    group.bench_function("crc8_h2f/8B", |b| {
        b.iter(|| crc8_h2f(black_box(&data[..8])))
    });
    group.bench_function("crc15_can/8B", |b| {
        b.iter(|| crc15_can(black_box(&data[..8])))
    });
    group.throughput(Throughput::Bytes(64));
    group.bench_function("crc21_bitwise/64B", |b| {
        b.iter(|| {
            let mut r = CrcRegister::crc21_iso();
            r.push_bytes(black_box(&data));
            r.value()
        })
    });
    group.finish();
}

criterion_group!(benches, bench_wire, bench_crc);
criterion_main!(benches);
