//! Property tests: text and wire round trips, error detection, length bounds, and no panics on
//! arbitrary input.
// Tests fail by panicking; helpers outside #[test] functions may unwrap too.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use bywire_core::frame::{ClassicFrame, Dlc, FdFrame, Frame, Id};
use bywire_core::wire::{self, length_bounds, BitSeq, Field, FrameShape};
use proptest::prelude::*;

fn id() -> impl Strategy<Value = Id> {
    prop_oneof![
        (0u32..=0x7FF).prop_map(|v| Id::standard(v).unwrap()),
        (0u32..=0x1FFF_FFFF).prop_map(|v| Id::extended(v).unwrap()),
    ]
}

/// Identifiers from anywhere, or from a few neighbouring bases (standard and extended with the
/// same base bits, where arbitration is decided by the SRR bit and the extension).
fn near_id() -> impl Strategy<Value = Id> {
    prop_oneof![
        id(),
        (0u32..4).prop_map(|v| Id::standard(v).unwrap()),
        (0u32..4, 0u32..4).prop_map(|(base, ext)| Id::extended(base << 18 | ext).unwrap()),
    ]
}

/// Payloads biased towards long runs of equal bits, where stuffing happens.
fn payload(max: usize) -> impl Strategy<Value = Vec<u8>> {
    prop::collection::vec(prop_oneof![Just(0x00u8), Just(0xFF), any::<u8>()], 0..=max)
}

fn frame() -> impl Strategy<Value = Frame> {
    prop_oneof![
        (id(), payload(8)).prop_map(|(id, d)| Frame::classic(id, &d).unwrap()),
        (id(), 0u8..=15).prop_map(|(id, dlc)| Frame::remote(id, Dlc::new(dlc).unwrap())),
        (id(), prop::array::uniform8(any::<u8>()), 9u8..=15).prop_map(|(id, d, dlc)| {
            Frame::Classic(ClassicFrame::with_dlc(id, Dlc::new(dlc).unwrap(), &d).unwrap())
        }),
        (id(), payload(64), any::<bool>(), any::<bool>())
            .prop_map(|(id, d, brs, esi)| Frame::Fd(FdFrame::padded(id, &d, brs, esi).unwrap())),
    ]
}

/// The compact text as can-utils' `lib.c` builds it, field by field through `format!`: the
/// reference the byte-built text is held to.
fn can_utils_text(f: &Frame) -> String {
    let id = |id: Id| match id {
        Id::Standard(_) => format!("{:03X}#", id.as_raw()),
        Id::Extended(_) => format!("{:08X}#", id.as_raw()),
    };
    let hex = |data: &[u8]| data.iter().map(|b| format!("{b:02X}")).collect::<String>();
    match f {
        Frame::Classic(c) => {
            let dlc = c.dlc().as_raw();
            let body = match (c.is_remote(), dlc) {
                (true, 0) => "R".to_string(),
                (true, _) => format!("R{}", c.len()),
                (false, _) => hex(c.data()),
            };
            let raw_dlc = if dlc > 8 {
                format!("_{dlc:X}")
            } else {
                String::new()
            };
            format!("{}{body}{raw_dlc}", id(c.id()))
        }
        Frame::Fd(d) => {
            let flags = 4 | u8::from(d.brs()) | u8::from(d.esi()) << 1;
            format!("{}#{flags:X}{}", id(d.id()), hex(d.data()))
        }
        Frame::Error(e) => format!("{:08X}#{}", 0x2000_0000 | e.class_bits(), hex(e.data())),
    }
}

fn shape(f: &Frame) -> FrameShape {
    FrameShape {
        extended: f.id().unwrap().is_extended(),
        remote: f.is_remote(),
        fd: f.is_fd(),
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn text_round_trip(f in frame()) {
        let text = f.to_string();
        prop_assert_eq!(text.parse::<Frame>(), Ok(f));
    }

    #[test]
    fn text_is_built_as_can_utils_builds_it(
        f in prop_oneof![
            frame(),
            (0u32..=0x1FFF_FFFF, prop::collection::vec(any::<u8>(), 8))
                .prop_map(|(class, data)| Frame::Error(bywire_core::ErrorFrame::new(class, &data).unwrap())),
        ]
    ) {
        let expected = can_utils_text(&f);
        let text = f.text();
        prop_assert_eq!(text.as_str(), expected.as_str());
        prop_assert_eq!(f.to_string(), expected);
    }

    #[test]
    fn error_frame_text_round_trip(class in 0u32..=0x3FF, data in prop::collection::vec(any::<u8>(), 8)) {
        let f = Frame::Error(bywire_core::ErrorFrame::new(class, &data).unwrap());
        prop_assert_eq!(f.to_string().parse::<Frame>(), Ok(f));
    }

    #[test]
    fn identifiers_sort_in_arbitration_order(a in near_id(), b in near_id()) {
        // The base identifier's bits go first; at an equal base a standard frame's dominant RTR
        // beats an extended frame's recessive SRR; then the extension's bits.
        let wire_order = |id: Id| match id {
            Id::Standard(s) => (u32::from(s.as_raw()), 0, 0),
            Id::Extended(e) => (e.as_raw() >> 18, 1, e.as_raw() & 0x3_FFFF),
        };
        prop_assert_eq!(a.cmp(&b), wire_order(a).cmp(&wire_order(b)));
        prop_assert_eq!(a.cmp(&b) == std::cmp::Ordering::Equal, a == b);
    }

    #[test]
    fn the_fast_classic_length_agrees_with_the_encoder(f in frame()) {
        let w = wire::encode(&f).unwrap();
        let crc_delimiter = w.spans().iter().find(|s| s.field == Field::CrcDelimiter).unwrap().start;
        match f {
            Frame::Classic(_) => prop_assert_eq!(wire::classic_length(&f), Some((w.len(), crc_delimiter))),
            _ => prop_assert_eq!(wire::classic_length(&f), None),
        }
    }

    /// A header counted once times every payload of its identifier and length, as the
    /// encoder does.
    #[test]
    fn a_classic_header_times_any_payload_of_its_length(
        id in id(),
        payloads in (0usize..=8).prop_flat_map(|n| prop::collection::vec(
            prop::collection::vec(prop_oneof![Just(0x00u8), Just(0xFF), any::<u8>()], n), 2..4)),
    ) {
        let first = Frame::classic(id, &payloads[0]).unwrap();
        let header = wire::ClassicHeader::of(&first).unwrap();
        for data in &payloads {
            let f = Frame::classic(id, data).unwrap();
            let w = wire::encode(&f).unwrap();
            let crc_delimiter = w.spans().iter().find(|s| s.field == Field::CrcDelimiter).unwrap().start;
            prop_assert_eq!(header.length(f.data()), (w.len(), crc_delimiter));
        }
    }

    #[test]
    fn wire_round_trip_within_bounds(f in frame()) {
        let w = wire::encode(&f).unwrap();
        prop_assert_eq!(wire::decode(w.bits()), Ok(f));
        let (lo, hi) = length_bounds(shape(&f), f.dlc());
        prop_assert!(lo <= w.len() && w.len() <= hi, "{} not in {}..={}", w.len(), lo, hi);
        // Never six equal levels in the stuffed part (SOF through the CRC).
        let crc = w.spans().iter().find(|s| s.field == Field::Crc).unwrap();
        let mut run = 0;
        let mut last = None;
        for bit in w.bits().iter().take(crc.start + crc.len) {
            run = if Some(bit) == last { run + 1 } else { 1 };
            last = Some(bit);
            prop_assert!(run <= 5);
        }
    }

    #[test]
    fn any_single_bit_flip_in_the_stuffed_region_is_detected(f in frame(), pick in any::<prop::sample::Index>()) {
        let w = wire::encode(&f).unwrap();
        let crc = w.spans().iter().find(|s| s.field == Field::Crc).unwrap();
        let end = crc.start + crc.len;
        let i = pick.index(end);
        let mut bits = *w.bits();
        bits.flip(i);
        prop_assert!(wire::decode(&bits).is_err(), "flip at {} of {} went unnoticed", i, f);
    }

    #[test]
    fn decoding_arbitrary_levels_never_panics(levels in prop::collection::vec(any::<bool>(), 0..800)) {
        let mut bits = BitSeq::new();
        for b in levels.iter().take(wire::MAX_FRAME_BITS) {
            bits.push(*b).unwrap();
        }
        let _ = wire::decode(&bits);
    }

    #[test]
    fn parsing_arbitrary_text_never_panics(text in ".{0,160}") {
        let _ = text.parse::<Frame>();
        let _ = text.parse::<bywire_core::filter::FilterItem>();
    }

    #[test]
    fn parsing_frame_like_text_never_panics(text in "[0-9A-Fa-f]{0,9}#{1,2}[0-9A-FRr._#]{0,140}") {
        if let Ok(f) = text.parse::<Frame>() {
            prop_assert_eq!(f.to_string().parse::<Frame>(), Ok(f));
        }
    }
}

proptest! {
    /// A deadline is the time plus the duration in nanoseconds, whatever their sizes, or
    /// nothing past the end of representable time: as 128-bit arithmetic has it.
    #[test]
    fn a_timestamp_plus_a_duration_is_exact_or_none(
        at in prop_oneof![any::<u64>(), 0u64..1 << 40, u64::MAX - (1 << 40)..=u64::MAX],
        secs in prop_oneof![any::<u64>(), 0u64..1 << 20, 18_446_744_073u64..18_446_744_074],
        nanos in 0u32..1_000_000_000,
    ) {
        use bywire_core::Timestamp;
        use std::time::Duration;
        let d = Duration::new(secs, nanos);
        let exact = u128::from(at) + d.as_nanos();
        let expected = u64::try_from(exact).ok().map(Timestamp::from_nanos);
        let t = Timestamp::from_nanos(at);
        prop_assert_eq!(t.checked_add(d), expected);
        prop_assert_eq!(t.saturating_add(d), expected.unwrap_or(Timestamp::from_nanos(u64::MAX)));
    }
}
