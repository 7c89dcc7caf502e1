extern crate std;

use super::*;
use crate::frame::{Dlc, Frame};
use std::string::ToString;

fn frame(text: &str) -> Frame {
    text.parse().unwrap()
}

fn levels(text: &str) -> BitSeq {
    BitSeq::parse_levels(text).unwrap()
}

/// Standard ID 0, DLC 0: 19 dominant header bits and a CRC of 0 give 34 dominant bits in a row,
/// so a recessive stuff bit follows every fifth: six stuff bits, 50 bits in all.
#[test]
fn hand_worked_all_dominant_frame() {
    let w = encode(&frame("000#")).unwrap();
    let expected = "000001 000001 000001 000001 000001 000001 0000 1 0 1 1111111";
    assert_eq!(w.bits(), &levels(expected));
    assert_eq!(w.crc(), 0);
    assert_eq!((w.len(), w.stuff_bits(), w.crc_width()), (50, 6, 15));
    for i in [5, 11, 17, 23, 29, 35] {
        assert!(w.is_stuff_bit(i), "bit {i}");
    }
    assert_eq!(w.field_at(0), Some(Field::Sof));
    assert_eq!(w.field_at(12), Some(Field::BaseId));
    assert_eq!(w.field_at(41), Some(Field::AckSlot));
}

/// Hand-worked: ID 0x7FF, one byte 0xFF. The identifier is 11 recessive bits after SOF, stuffed
/// after the 5th and the 9th recessive bit counting the stuff bit's run, etc.
#[test]
fn hand_worked_recessive_identifier() {
    let w = encode(&frame("7FF#FF")).unwrap();
    let s = w.bits().to_string();
    // SOF 0 | ID 11111 s0 11111 s0 1 | RTR 0 IDE 0 r0 0 DLC 00 s1 01 | data 1111 s0 1111 ...
    // (a stuff bit starts a new run of its own level).
    assert!(
        s.starts_with(
            "0 11111 0 11111 0 1 00000 1 01 1111 0 1111"
                .replace(' ', "")
                .as_str()
        ),
        "{s}"
    );
    let d = decode(w.bits()).unwrap();
    assert_eq!(d, frame("7FF#FF"));
}

#[test]
fn stuff_count_is_gray_coded_with_even_parity() {
    let codes: std::vec::Vec<u8> = (0..8).map(stuff_count_code).collect();
    assert_eq!(
        codes,
        [0b0000, 0b0011, 0b0110, 0b0101, 0b1100, 0b1111, 0b1010, 0b1001]
    );
    assert_eq!(stuff_count_code(8), 0);
}

#[test]
fn fd_frames_carry_the_right_crc_and_fixed_stuff_bits() {
    let short = encode(&frame("123##1112233445566778899AABBCCDDEEFF00")).unwrap();
    assert_eq!((short.crc_width(), short.fixed_stuff_bits()), (17, 6));
    let long = encode(&frame(
        "123##10102030405060708090A0B0C0D0E0F101112131415161718191A1B1C1D1E1F20",
    ))
    .unwrap();
    assert_eq!((long.crc_width(), long.fixed_stuff_bits()), (21, 7));
    // Fixed stuff bits always oppose the bit before them.
    for w in [short, long] {
        let crc = w.spans().iter().find(|s| s.field == Field::Crc).unwrap();
        let sbc = w
            .spans()
            .iter()
            .find(|s| s.field == Field::StuffCount)
            .unwrap();
        assert_eq!(sbc.len, 5);
        assert_eq!(
            crc.len,
            usize::from(w.crc_width()) + (usize::from(w.crc_width()) - 1) / 4 + 1
        );
        for i in sbc.start..crc.start + crc.len {
            if w.is_stuff_bit(i) {
                assert_ne!(w.bits().get(i), w.bits().get(i - 1));
            }
        }
    }
}

#[test]
fn fd_time_counts_the_data_phase_at_the_data_bitrate() {
    let w = encode(&frame("123##1DEADBEEF")).unwrap();
    let data_bits = w.data_phase_bits();
    // ESI, 4 DLC, 32 data, 5 SBC, 17 CRC + 5 fixed stuff, delimiter, plus dynamic stuff bits.
    assert!(data_bits > 1 + 4 + 32 + 5 + 22, "{data_bits}");
    let at_one_rate = w.time_ns(500_000, None);
    assert!((at_one_rate - 2000.0 * w.len() as f64).abs() < 1e-6);
    let switched = w.time_ns(500_000, Some(2_000_000));
    let expected = 2000.0 * (w.len() - data_bits) as f64 + 500.0 * data_bits as f64;
    assert!((switched - expected).abs() < 1e-6);
    // Without BRS the whole frame runs at the nominal rate.
    let slow = encode(&frame("123##0DEADBEEF")).unwrap();
    assert_eq!(slow.data_phase_bits(), 0);
}

#[test]
fn decodes_what_it_encodes() {
    for text in [
        "000#",
        "123#DEADBEEF",
        "7FF#0011223344556677",
        "123#R",
        "123#R5",
        "1ABCDEF0#",
        "00000000#FFFFFFFFFFFFFFFF",
        "1FFFFFFF#R8_E",
        "123#1122334455667788_F",
        "123##0",
        "123##3AA",
        "1ABCDEF0##1000102030405060708090A0B0C0D0E0F101112131415161718191A1B1C1D1E1F202122232425262728292A2B2C2D2E2F303132333435363738393A3B3C3D3E3F",
    ] {
        let f = frame(text);
        let w = encode(&f).unwrap();
        assert_eq!(decode(w.bits()), Ok(f), "{text}");
        let shape = FrameShape {
            extended: f.id().unwrap().is_extended(),
            remote: f.is_remote(),
            fd: f.is_fd(),
        };
        let (lo, hi) = length_bounds(shape, f.dlc());
        assert!(lo <= w.len() && w.len() <= hi, "{text}: {lo} <= {} <= {hi}", w.len());
    }
}

#[test]
fn error_frames_have_no_bit_sequence() {
    assert_eq!(
        encode(&frame("20000004#0004000000000000")),
        Err(EncodeError::NotOnWire)
    );
}

fn first_error(bits: &BitSeq) -> (ErrorKind, Field) {
    let e = decode(bits).unwrap_err();
    (e.kind, e.field)
}

#[test]
fn each_error_kind_is_told_apart() {
    let w = encode(&frame("123#DEADBEEF")).unwrap();
    let index_of = |field: Field| w.spans().iter().find(|s| s.field == field).unwrap().start;

    let mut b = *w.bits();
    b.flip(index_of(Field::CrcDelimiter));
    assert_eq!(first_error(&b), (ErrorKind::Form, Field::CrcDelimiter));

    let mut b = *w.bits();
    b.flip(index_of(Field::AckSlot));
    assert_eq!(first_error(&b), (ErrorKind::Ack, Field::AckSlot));

    let mut b = *w.bits();
    b.flip(index_of(Field::Eof) + 6);
    assert_eq!(first_error(&b), (ErrorKind::Form, Field::Eof));

    let mut b = *w.bits();
    b.flip(index_of(Field::Crc));
    assert_eq!(first_error(&b).0, ErrorKind::Crc);

    // Flipping a stuff bit makes six equal levels.
    let z = encode(&frame("000#")).unwrap();
    let mut b = *z.bits();
    b.flip(5);
    assert_eq!(decode(&b).unwrap_err().kind, ErrorKind::Stuff);
    assert_eq!(decode(&b).unwrap_err().position, 5);

    // A sequence that does not start dominant is no frame.
    assert_eq!(first_error(&levels("1111")), (ErrorKind::Form, Field::Sof));
    // Cut short, the idle bus reads recessive: six of them break stuffing or form.
    let mut cut = *w.bits();
    cut.truncate(30);
    assert!(decode(&cut).is_err());
}

#[test]
fn fd_fixed_stuff_bit_and_stuff_count_errors() {
    let w = encode(&frame("123##1DEADBEEF")).unwrap();
    let sbc = w
        .spans()
        .iter()
        .find(|s| s.field == Field::StuffCount)
        .unwrap();
    let mut b = *w.bits();
    b.flip(sbc.start);
    assert_eq!(first_error(&b), (ErrorKind::Form, Field::StuffCount));
    let mut b = *w.bits();
    b.flip(sbc.start + 4);
    assert_eq!(first_error(&b), (ErrorKind::Crc, Field::StuffCount));
}

#[test]
fn transmitter_tells_lost_arbitration_from_bit_and_ack_errors() {
    let mine = encode_with_ack(&frame("123#11"), false).unwrap();
    // A frame with a lower identifier wins where the identifiers first differ.
    let theirs = encode(&frame("122#11")).unwrap();
    match check_transmission(&mine, theirs.bits()) {
        TransmitOutcome::LostArbitration { at } => assert_eq!(at, 11),
        other => panic!("{other:?}"),
    }
    // Acknowledged by a receiver: success.
    let acked = encode(&frame("123#11")).unwrap();
    assert_eq!(
        check_transmission(&mine, acked.bits()),
        TransmitOutcome::Success
    );
    // Alone on the bus: ACK error.
    match check_transmission(&mine, mine.bits()) {
        TransmitOutcome::Error(e) => assert_eq!(e.kind, ErrorKind::Ack),
        other => panic!("{other:?}"),
    }
    // A dominant level overwriting a recessive data bit: bit error.
    let data = mine
        .spans()
        .iter()
        .find(|s| s.field == Field::Data)
        .unwrap();
    let recessive = (data.start..data.start + data.len)
        .find(|&i| mine.bits().get(i) == Some(true))
        .unwrap();
    let mut seen = *acked.bits();
    seen.flip(recessive);
    match check_transmission(&mine, &seen) {
        TransmitOutcome::Error(e) => assert_eq!((e.kind, e.position), (ErrorKind::Bit, recessive)),
        other => panic!("{other:?}"),
    }
    // A recessive stuff bit in arbitration read back dominant: stuff error, not lost arbitration.
    let zero = encode_with_ack(&frame("000#"), false).unwrap();
    let mut seen = *zero.bits();
    seen.flip(5);
    match check_transmission(&zero, &seen) {
        TransmitOutcome::Error(e) => assert_eq!(e.kind, ErrorKind::Stuff),
        other => panic!("{other:?}"),
    }
}

#[test]
fn classic_bounds_match_the_known_worst_case_formula() {
    // Without stuffing: 47 bits (standard) / 67 (extended) + 8 per byte, interframe space
    // excluded here: 44 / 64. The worst case cannot exceed the classic bound of one stuff bit per
    // four bits after the first five: floor((34 + 8n - 1) / 4) and floor((54 + 8n - 1) / 4).
    for n in 0..=8usize {
        let dlc = Dlc::from_classic_len(n).unwrap();
        let (lo, hi) = length_bounds(FrameShape::default(), dlc);
        assert!(lo >= 44 + 8 * n);
        assert!(hi <= 44 + 8 * n + (34 + 8 * n - 1) / 4, "n={n} hi={hi}");
        let ext = FrameShape {
            extended: true,
            ..FrameShape::default()
        };
        let (lo, hi) = length_bounds(ext, dlc);
        assert!(lo >= 64 + 8 * n);
        assert!(hi <= 64 + 8 * n + (54 + 8 * n - 1) / 4, "n={n} hi={hi}");
    }
    // Over every standard identifier with a spread of one-byte payloads, real lengths lie within
    // the bounds and come close to both ends (the CRC, fixed by the rest, leaves some slack).
    let dlc = Dlc::from_classic_len(1).unwrap();
    let (lo, hi) = length_bounds(FrameShape::default(), dlc);
    let payloads = [
        0x00, 0xFF, 0x0F, 0xF0, 0x55, 0xAA, 0x78, 0x87, 0x3C, 0xC3, 0x1E, 0xE1, 0x07,
    ];
    let lengths: std::vec::Vec<usize> = (0..=0x7FFu32)
        .flat_map(|id| payloads.iter().map(move |&b| (id, b)))
        .map(|(id, b)| {
            let f = Frame::classic(crate::Id::standard(id).unwrap(), &[b]).unwrap();
            encode(&f).unwrap().len()
        })
        .collect();
    let (min, max) = (
        *lengths.iter().min().unwrap(),
        *lengths.iter().max().unwrap(),
    );
    assert!(lo <= min && max <= hi, "{lo} <= {min} .. {max} <= {hi}");
    // Exhaustively over all 2048 x 256 such frames the longest is 59 bits against a bound of 62.
    assert!(min == lo && hi - max <= 3, "{lo} <= {min} .. {max} <= {hi}");
}
