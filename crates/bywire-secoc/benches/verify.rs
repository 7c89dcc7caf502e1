//! The cost of authenticated commands on one core: signing one, and verifying one as the
//! supervisor does (freshness rebuilt, MAC checked), for AUTOSAR's profile 1 on an 8-byte
//! command and a 64-bit freshness (8 bits sent) on a CAN FD command; and a forged one, which
//! costs the most (every candidate tried).
#![allow(missing_docs, clippy::unwrap_used, clippy::indexing_slicing)]

use bywire_secoc::{profile, Authenticator, Key, Layout, Receiver, Sender};
use criterion::{black_box, criterion_group, criterion_main, Criterion};

fn bench(c: &mut Criterion) {
    let auth = Authenticator::new(&Key::new([0x2b; 16]));
    for (name, layout, length) in [
        (
            "profile 1, 4-byte payload",
            Layout::of_profile(profile("24Bit-CMAC-8Bit-FV").unwrap(), 0x100, 4).unwrap(),
            8,
        ),
        (
            "64-bit freshness, 8 sent, 24-byte payload",
            Layout::new(0x100, 24, 64, 8, 32).unwrap(),
            32,
        ),
    ] {
        let mut sender = Sender::new(1);
        let mut frame = [0u8; 64];
        c.bench_function(&format!("secoc sign ({name})"), |b| {
            b.iter(|| {
                let mut f = [0x11u8; 64];
                sender = Sender::new(black_box(7));
                sender.sign(&auth, &layout, &mut f[..length]).unwrap()
            })
        });
        Sender::new(8)
            .sign(&auth, &layout, &mut frame[..length])
            .unwrap();
        c.bench_function(&format!("secoc verify ({name})"), |b| {
            b.iter(|| {
                let mut receiver = Receiver::new(black_box(7), 16);
                receiver.accept(&auth, &layout, black_box(&frame[..length]))
            })
        });
        let mut forged = frame;
        forged[layout.secured_length() - 1] ^= 1;
        c.bench_function(&format!("secoc reject forged ({name})"), |b| {
            b.iter(|| {
                let mut receiver = Receiver::new(black_box(7), 16);
                receiver.accept(&auth, &layout, black_box(&forged[..length]))
            })
        });
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
