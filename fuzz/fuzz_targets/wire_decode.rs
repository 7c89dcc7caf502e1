//! Any bus levels: the wire decoder never panics, and a frame it accepts encodes back to the
//! same levels it read (up to the end of EOF).
#![no_main]

use bywire_core::wire::{self, BitSeq};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut bits = BitSeq::new();
    for byte in data {
        for i in 0..8 {
            if bits.push((byte >> i) & 1 == 1).is_err() {
                break;
            }
        }
    }
    if let Ok(frame) = wire::decode(&bits) {
        let encoded = wire::encode(&frame).expect("decoded frames encode");
        // Reserved bits are accepted at either level, so compare the frame, not every level.
        assert_eq!(wire::decode(encoded.bits()), Ok(frame));
    }
});
