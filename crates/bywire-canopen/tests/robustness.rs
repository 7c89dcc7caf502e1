//! Malformed input from the bus: random frames never panic a device or the master, every
//! malformed SDO request is answered with its abort code, and EDS/TOML text of any shape is
//! read without panicking. (The same properties run longer under `fuzz/`.)
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::time::Duration;

use bywire_canopen::cia402::{drive_dictionary, Drive, DriveController, Mode};
use bywire_canopen::device::{Device, Plain};
use bywire_canopen::master::{Controlled, Master};
use bywire_canopen::roboteq::{dictionary, Mdc1460, RoboteqCommand, RoboteqMotor};
use bywire_canopen::{eds, Abort, Node, Port};
use bywire_core::frame::{Dlc, Frame, Id};
use bywire_core::time::Timestamp;
use proptest::prelude::*;

fn frame_strategy() -> impl Strategy<Value = Frame> {
    // Mostly the identifiers CANopen uses, so the services see the input.
    let id = prop_oneof![
        Just(0x000u32),
        Just(0x080),
        0x181u32..0x190,
        0x201u32..0x210,
        0x301u32..0x310,
        0x581u32..0x590,
        0x601u32..0x610,
        0x701u32..0x710,
        0u32..0x800,
    ];
    (
        id,
        proptest::collection::vec(any::<u8>(), 0..=8),
        any::<bool>(),
        0u8..16,
    )
        .prop_map(|(id, data, remote, dlc)| {
            let id = Id::standard(id).unwrap();
            if remote {
                Frame::remote(id, Dlc::from_nibble(dlc))
            } else {
                Frame::classic(id, &data).unwrap()
            }
        })
}

fn drive_responses(frames: &[(u64, Frame)]) -> Vec<Frame> {
    let mut drive = Device::new(2, drive_dictionary(2), Drive::new());
    let mut roboteq = Device::new(1, dictionary(1, 2), Mdc1460::default()).with_autostart();
    let mut plain = Device::new(3, drive_dictionary(3), Plain);
    let mut master = Master::new(127, Duration::from_millis(100), Duration::from_millis(10));
    master.add(Controlled::Drive(DriveController::new(
        2,
        Mode::ProfileVelocity,
        Duration::from_millis(100),
    )));
    master.add(Controlled::Roboteq(RoboteqMotor::new(
        1,
        RoboteqCommand::Power(0),
    )));
    master.monitor(2, Duration::from_millis(100));
    let mut now = 0;
    let mut from_drive = Vec::new();
    for (step, frame) in frames {
        now += step;
        let time = Timestamp::from_millis(now);
        drive.on_frame(time, Port::MAIN, frame);
        drive.poll(time, &mut |_, f| from_drive.push(f));
        for node in [&mut roboteq as &mut dyn Node, &mut plain, &mut master] {
            node.on_frame(time, Port::MAIN, frame);
            node.poll(time, &mut |_, _| {});
        }
    }
    from_drive
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

    #[test]
    fn random_traffic_never_panics_and_sdo_answers_stay_in_protocol(frames in proptest::collection::vec((0u64..50, frame_strategy()), 0..200)) {
        for frame in drive_responses(&frames) {
            if frame.id() == Id::standard(0x582).ok() {
                prop_assert_eq!(frame.data().len(), 8);
                let command = frame.data()[0];
                prop_assert!(command >> 5 <= 6, "server command specifier {:02X}", command);
                if command == 0x80 {
                    let code = u32::from_le_bytes(frame.data()[4..8].try_into().unwrap());
                    prop_assert!(!matches!(Abort::from_code(code), Abort::Other(_)), "unknown abort {:08X}", code);
                }
            }
        }
    }

    /// Any single request to an idle server is answered: a response, or an abort with a known
    /// code; only a client's own abort goes unanswered.
    #[test]
    fn every_request_to_an_idle_server_gets_an_answer(data in proptest::collection::vec(any::<u8>(), 0..=8)) {
        let mut drive = Device::new(2, drive_dictionary(2), Drive::new());
        drive.poll(Timestamp::ZERO, &mut |_, _| {});
        let request = Frame::classic(Id::standard(0x602).unwrap(), &data).unwrap();
        drive.on_frame(Timestamp::ZERO, Port::MAIN, &request);
        let mut answers = Vec::new();
        drive.poll(Timestamp::ZERO, &mut |_, f| if f.id() == Id::standard(0x582).ok() { answers.push(f) });
        let client_abort = data.len() == 8 && data[0] >> 5 == 4;
        prop_assert_eq!(answers.is_empty(), client_abort, "request {:02X?} answered by {:?}", data, answers);
        if let Some(answer) = answers.first() {
            if answer.data()[0] == 0x80 {
                let code = u32::from_le_bytes(answer.data()[4..8].try_into().unwrap());
                prop_assert!(!matches!(Abort::from_code(code), Abort::Other(_)));
            }
        }
    }

    #[test]
    fn eds_text_of_any_shape_reads_without_panic(lines in proptest::collection::vec(prop_oneof![
        "\\[[0-9A-Fa-f]{4}(sub[0-9A-F]{1,2})?\\]",
        "\\[(DeviceInfo|MandatoryObjects|DeviceComissioning|[0-9A-F]{4}Name)\\]",
        "(ParameterName|ObjectType|DataType|AccessType|DefaultValue|PDOMapping|SubNumber|CompactSubObj|LowLimit|HighLimit|ParameterValue|NodeID|[0-9])=[ -~]{0,12}",
        "(DataType|ObjectType|DefaultValue)=(0x[0-9A-F]{1,4}|\\$NODEID\\+0x180|0[0-7]{1,3}|-?[0-9]{1,20})",
        "[ -~]{0,20}",
    ], 0..60)) {
        let text = lines.join("\n");
        if let Some(read) = eds::parse(&text, Some(4)).ok().filter(|read| !read.dictionary.objects().is_empty()) {
            let again = eds::parse(&eds::write(&read.dictionary, &read.info, None), Some(4)).unwrap();
            prop_assert_eq!(again.dictionary, read.dictionary);
        }
    }

    #[test]
    fn bus_descriptions_of_any_shape_never_panic(text in "[ -~\n]{0,300}") {
        let _ = bywire_canopen::config::BusConfig::parse(&text, "bus.toml", std::path::Path::new("."));
    }
}

/// One request per malformed shape, each with the abort CiA 301 gives it.
#[test]
fn malformed_requests_get_their_abort_codes() {
    let cases: [(&str, Vec<[u8; 8]>, Abort); 11] = [
        (
            "unknown command specifier",
            vec![[0xE0, 0, 0x10, 0, 0, 0, 0, 0]],
            Abort::InvalidCommand,
        ),
        (
            "download segment without a transfer",
            vec![[0x00, 1, 2, 3, 4, 5, 6, 7]],
            Abort::InvalidCommand,
        ),
        (
            "upload segment without a transfer",
            vec![[0x60, 0, 0, 0, 0, 0, 0, 0]],
            Abort::InvalidCommand,
        ),
        (
            "toggle bit not alternated",
            vec![
                [0x21, 0x81, 0x60, 0, 4, 0, 0, 0],
                [0x10, 1, 2, 3, 4, 5, 6, 7],
            ],
            Abort::ToggleNotAlternated,
        ),
        (
            "segmented size differs from the data",
            vec![
                [0x21, 0x81, 0x60, 0, 4, 0, 0, 0],
                [0x0F, 1, 2, 3, 4, 5, 6, 7],
            ],
            Abort::LengthMismatch,
        ),
        (
            "block size zero",
            vec![[0xA4, 0x08, 0x10, 0, 0, 0, 0, 0]],
            Abort::InvalidBlockSize,
        ),
        (
            "block size above 127",
            vec![[0xA4, 0x08, 0x10, 0, 128, 0, 0, 0]],
            Abort::InvalidBlockSize,
        ),
        (
            "block sequence number zero",
            vec![
                [0xC6, 0x81, 0x60, 0, 4, 0, 0, 0],
                [0x00, 1, 2, 3, 4, 5, 6, 7],
            ],
            Abort::InvalidSequence,
        ),
        (
            "block CRC wrong",
            vec![
                [0xC6, 0x81, 0x60, 0, 4, 0, 0, 0],
                [0x81, 1, 2, 3, 4, 0, 0, 0],
                [0xCD, 0x12, 0x34, 0, 0, 0, 0, 0],
            ],
            Abort::CrcError,
        ),
        (
            "block start without initiate",
            vec![[0xA3, 0, 0, 0, 0, 0, 0, 0]],
            Abort::InvalidCommand,
        ),
        (
            "expedited write of the wrong length",
            vec![[0x2B, 0x81, 0x60, 0, 1, 2, 0, 0]],
            Abort::LengthTooLow,
        ),
    ];
    for (what, requests, expected) in cases {
        let mut drive = Device::new(2, drive_dictionary(2), Drive::new());
        drive.poll(Timestamp::ZERO, &mut |_, _| {});
        let mut last = None;
        for request in &requests {
            drive.on_frame(
                Timestamp::ZERO,
                Port::MAIN,
                &Frame::classic(Id::standard(0x602).unwrap(), request).unwrap(),
            );
            drive.poll(Timestamp::ZERO, &mut |_, f| {
                if f.id() == Id::standard(0x582).ok() {
                    last = Some(f)
                }
            });
        }
        let answer = last.unwrap_or_else(|| panic!("{what}: no answer"));
        assert_eq!(answer.data()[0], 0x80, "{what}: {answer:?}");
        let code = u32::from_le_bytes(answer.data()[4..8].try_into().unwrap());
        assert_eq!(Abort::from_code(code), expected, "{what}");
    }
    // A short request (SDO frames are eight bytes).
    let mut drive = Device::new(2, drive_dictionary(2), Drive::new());
    drive.poll(Timestamp::ZERO, &mut |_, _| {});
    drive.on_frame(
        Timestamp::ZERO,
        Port::MAIN,
        &Frame::classic(Id::standard(0x602).unwrap(), &[0x40, 0x00, 0x10]).unwrap(),
    );
    let mut answers = Vec::new();
    drive.poll(Timestamp::ZERO, &mut |_, f| answers.push(f));
    assert_eq!(
        answers.last().unwrap().data(),
        [0x80, 0x00, 0x10, 0x00, 0x01, 0x00, 0x04, 0x05]
    );
}
