//! The UDS server over ISO-TP in simulated time, asked by a tester channel: each service's
//! answers and refusals with their codes, the session's S3 timeout, the suppress bit, DTC
//! status bits, and multi-frame answers.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use bywire_core::node::{Node, Port};
use core::time::Duration;

use bywire_core::{Id, Timestamp};
use bywire_diag::isotp::{IsoTp, IsoTpConfig, IsoTpEvent};
use bywire_diag::uds::{demo_key, status, Did, Routine, Session, UdsEvent, UdsServer, UdsTiming};

const VIN: &[u8] = b"WBYWIRE0TUG000042";

struct Bench {
    tester: IsoTp,
    server: UdsServer,
    now: Timestamp,
}

impl Bench {
    fn new() -> Bench {
        let id = |raw| Id::standard(raw).unwrap();
        let mut server =
            UdsServer::new(IsoTpConfig::new(id(0x7E8), id(0x7E0)), UdsTiming::default());
        server.set_did(
            0xF190,
            Did {
                value: VIN.to_vec(),
                writable_in: Vec::new(),
                secured: false,
            },
        );
        server.set_did(
            0xF195,
            Did {
                value: b"1.4.0".to_vec(),
                writable_in: Vec::new(),
                secured: false,
            },
        );
        server.set_did(
            0x0101,
            Did {
                value: vec![0, 0],
                writable_in: vec![Session::Extended],
                secured: false,
            },
        );
        Bench {
            tester: IsoTp::new(IsoTpConfig::new(id(0x7E0), id(0x7E8))),
            server,
            now: Timestamp::ZERO,
        }
    }

    /// Let `duration` pass with frames crossing at once.
    fn run(&mut self, duration: Duration) -> Vec<Vec<u8>> {
        let end = self.now.saturating_add(duration);
        let mut answers = Vec::new();
        for _ in 0..100_000 {
            let mut to_server = Vec::new();
            let mut to_tester = Vec::new();
            self.tester.poll(self.now, &mut |_, f| to_server.push(f));
            self.server.poll(self.now, &mut |_, f| to_tester.push(f));
            let moved = !to_server.is_empty() || !to_tester.is_empty();
            for f in &to_server {
                self.server.on_frame(self.now, Port::MAIN, f);
            }
            for f in &to_tester {
                self.tester.on_frame(self.now, Port::MAIN, f);
            }
            while let Some(event) = self.tester.next_event() {
                if let IsoTpEvent::Received(m) = event {
                    answers.push(m);
                }
            }
            if moved {
                continue;
            }
            let next = [self.tester.next_deadline(), self.server.next_deadline()]
                .into_iter()
                .flatten()
                .min()
                .filter(|t| *t < end);
            match next {
                Some(t) => self.now = t.max(self.now),
                None => {
                    self.now = end;
                    break;
                }
            }
        }
        answers
    }

    /// The answer to `request` (none if suppressed).
    fn ask(&mut self, request: &[u8]) -> Option<Vec<u8>> {
        self.tester.send(request).unwrap();
        let answers = self.run(Duration::from_millis(100));
        assert!(answers.len() <= 1, "{answers:x?}");
        answers.into_iter().next()
    }
}

#[test]
fn sessions_answer_with_their_timing_and_fall_back_after_s3() {
    let mut b = Bench::new();
    assert_eq!(
        b.ask(&[0x10, 0x03]),
        Some(vec![0x50, 0x03, 0x00, 0x32, 0x01, 0xF4])
    );
    assert_eq!(b.server.session(), Session::Extended);
    // TesterPresent keeps it alive past S3; the suppressed form answers nothing.
    for _ in 0..3 {
        b.run(Duration::from_secs(3));
        assert_eq!(b.ask(&[0x3E, 0x80]), None);
    }
    assert_eq!(b.server.session(), Session::Extended);
    assert_eq!(b.ask(&[0x3E, 0x00]), Some(vec![0x7E, 0x00]));
    b.run(Duration::from_millis(5100));
    assert_eq!(b.server.session(), Session::Default);
    assert!(b
        .server
        .take_events()
        .contains(&UdsEvent::Session(Session::Default)));
    assert_eq!(b.ask(&[0x10, 0x04]), Some(vec![0x7F, 0x10, 0x12]));
    assert_eq!(b.ask(&[0x10]), Some(vec![0x7F, 0x10, 0x13]));
}

#[test]
fn several_dids_are_read_in_one_request_over_multi_frame_answers() {
    let mut b = Bench::new();
    let mut want = vec![0x62, 0xF1, 0x90];
    want.extend_from_slice(VIN);
    want.extend_from_slice(&[0xF1, 0x95]);
    want.extend_from_slice(b"1.4.0");
    assert_eq!(b.ask(&[0x22, 0xF1, 0x90, 0xF1, 0x95]), Some(want));
    assert_eq!(
        b.ask(&[0x22, 0xF1, 0x90, 0x12, 0x34]),
        Some(vec![0x7F, 0x22, 0x31])
    );
    assert_eq!(b.ask(&[0x22, 0xF1]), Some(vec![0x7F, 0x22, 0x13]));
}

#[test]
fn writing_needs_the_right_session_and_length() {
    let mut b = Bench::new();
    assert_eq!(
        b.ask(&[0x2E, 0x01, 0x01, 0x12, 0x34]),
        Some(vec![0x7F, 0x2E, 0x22])
    );
    b.ask(&[0x10, 0x03]);
    assert_eq!(
        b.ask(&[0x2E, 0x01, 0x01, 0x12, 0x34]),
        Some(vec![0x6E, 0x01, 0x01])
    );
    assert_eq!(b.server.did(0x0101), Some(&[0x12, 0x34][..]));
    assert_eq!(
        b.ask(&[0x22, 0x01, 0x01]),
        Some(vec![0x62, 0x01, 0x01, 0x12, 0x34])
    );
    assert_eq!(
        b.ask(&[0x2E, 0x01, 0x01, 0x12]),
        Some(vec![0x7F, 0x2E, 0x13])
    );
    assert_eq!(
        b.ask(&[0x2E, 0xF1, 0x90, 0x00]),
        Some(vec![0x7F, 0x2E, 0x31])
    );
    assert!(b.server.take_events().contains(&UdsEvent::Written(0x0101)));
}

#[test]
fn dtcs_are_listed_with_their_status_bits_and_cleared() {
    let mut b = Bench::new();
    b.server.report(0xC10100, true);
    b.server.report(0x512300, true);
    b.server.report(0x512300, false);
    let confirmed = status::TEST_FAILED_THIS_CYCLE
        | status::PENDING
        | status::CONFIRMED
        | status::FAILED_SINCE_CLEAR;
    assert_eq!(
        b.ask(&[0x19, 0x02, 0xFF]),
        Some(vec![
            0x59,
            0x02,
            0x2F,
            0x51,
            0x23,
            0x00,
            confirmed,
            0xC1,
            0x01,
            0x00,
            confirmed | status::TEST_FAILED
        ])
    );
    // Only those failing now.
    assert_eq!(
        b.ask(&[0x19, 0x02, 0x01]),
        Some(vec![
            0x59,
            0x02,
            0x2F,
            0xC1,
            0x01,
            0x00,
            confirmed | status::TEST_FAILED
        ])
    );
    assert_eq!(
        b.ask(&[0x19, 0x01, 0x08]),
        Some(vec![0x59, 0x01, 0x2F, 0x01, 0x00, 0x02])
    );
    assert_eq!(b.ask(&[0x19, 0x0A]).unwrap().len(), 3 + 2 * 4);
    assert_eq!(b.ask(&[0x19, 0x42]), Some(vec![0x7F, 0x19, 0x12]));
    assert_eq!(b.ask(&[0x14, 0xFF, 0xFF, 0xFF]), Some(vec![0x54]));
    assert_eq!(b.ask(&[0x19, 0x02, 0xFF]), Some(vec![0x59, 0x02, 0x2F]));
    assert!(b
        .server
        .take_events()
        .contains(&UdsEvent::Cleared(0xFFFFFF)));
}

#[test]
fn dtc_setting_off_stops_reporting_outside_the_default_session_only() {
    let mut b = Bench::new();
    assert_eq!(b.ask(&[0x85, 0x02]), Some(vec![0x7F, 0x85, 0x7F]));
    b.ask(&[0x10, 0x03]);
    assert_eq!(b.ask(&[0x85, 0x02]), Some(vec![0xC5, 0x02]));
    b.server.report(0xC10100, true);
    assert_eq!(b.server.dtc_status(0xC10100), None);
    assert_eq!(b.ask(&[0x85, 0x81]), None);
    b.server.report(0xC10100, true);
    assert!(b.server.dtc_status(0xC10100).is_some());
}

#[test]
fn reset_answers_then_tells_the_application() {
    let mut b = Bench::new();
    b.ask(&[0x10, 0x03]);
    assert_eq!(b.ask(&[0x11, 0x01]), Some(vec![0x51, 0x01]));
    assert!(b.server.take_events().contains(&UdsEvent::Reset(1)));
    assert_eq!(b.server.session(), Session::Default);
    assert_eq!(b.ask(&[0x11, 0x09]), Some(vec![0x7F, 0x11, 0x12]));
    assert_eq!(b.ask(&[0x99, 0x00]), Some(vec![0x7F, 0x99, 0x11]));
    assert_eq!(b.ask(&[0x28, 0x00, 0x01]), Some(vec![0x7F, 0x28, 0x7F]));
}

#[test]
fn security_access_gives_a_seed_takes_the_key_and_delays_after_three_wrong_ones() {
    let mut b = Bench::new();
    b.server.set_did(
        0x0202,
        Did {
            value: vec![7],
            writable_in: vec![Session::Extended],
            secured: true,
        },
    );
    assert_eq!(
        b.ask(&[0x27, 0x01]),
        Some(vec![0x7F, 0x27, 0x7F]),
        "not in the default session"
    );
    b.ask(&[0x10, 0x03]);
    assert_eq!(
        b.ask(&[0x2E, 0x02, 0x02, 0x09]),
        Some(vec![0x7F, 0x2E, 0x33])
    );
    assert_eq!(
        b.ask(&[0x27, 0x02, 0, 0, 0, 0]),
        Some(vec![0x7F, 0x27, 0x24]),
        "a key before a seed"
    );
    let answer = b.ask(&[0x27, 0x01]).unwrap();
    assert_eq!((answer[0], answer[1], answer.len()), (0x67, 0x01, 6));
    let mut request = vec![0x27, 0x02];
    request.extend(demo_key(1, &answer[2..]));
    assert_eq!(b.ask(&request), Some(vec![0x67, 0x02]));
    assert!(b.server.take_events().contains(&UdsEvent::Unlocked(1)));
    assert_eq!(
        b.ask(&[0x2E, 0x02, 0x02, 0x09]),
        Some(vec![0x6E, 0x02, 0x02])
    );
    // Unlocked: the seed is zeros.
    assert_eq!(b.ask(&[0x27, 0x01]), Some(vec![0x67, 0x01, 0, 0, 0, 0]));
    // A new session locks again; three wrong keys start the delay.
    b.ask(&[0x10, 0x03]);
    for expected in [0x35, 0x35, 0x36] {
        b.ask(&[0x27, 0x01]).unwrap();
        assert_eq!(
            b.ask(&[0x27, 0x02, 1, 2, 3, 4]),
            Some(vec![0x7F, 0x27, expected])
        );
    }
    assert_eq!(b.ask(&[0x27, 0x01]), Some(vec![0x7F, 0x27, 0x37]));
    b.ask(&[0x3E, 0x80]);
    b.run(Duration::from_secs(4));
    b.ask(&[0x3E, 0x80]);
    b.run(Duration::from_secs(4));
    b.ask(&[0x3E, 0x80]);
    b.run(Duration::from_secs(3));
    assert_eq!(
        b.ask(&[0x27, 0x01]).unwrap()[0],
        0x67,
        "after the 10 s delay"
    );
}

#[test]
fn a_routine_that_takes_time_answers_pending_then_its_result() {
    let mut b = Bench::new();
    b.server.set_routine(
        0x0203,
        Routine {
            runs_for: Duration::from_millis(300),
            result: vec![0x00, 0x2A],
            secured: false,
        },
    );
    assert_eq!(
        b.ask(&[0x31, 0x01, 0x02, 0x03]),
        Some(vec![0x7F, 0x31, 0x7F])
    );
    b.ask(&[0x10, 0x03]);
    b.tester.send(&[0x31, 0x01, 0x02, 0x03]).unwrap();
    let answers = b.run(Duration::from_millis(500));
    assert_eq!(
        answers,
        [vec![0x7F, 0x31, 0x78], vec![0x71, 0x01, 0x02, 0x03, 0x00]]
    );
    assert_eq!(
        b.ask(&[0x31, 0x03, 0x02, 0x03]),
        Some(vec![0x71, 0x03, 0x02, 0x03, 0x00, 0x2A])
    );
    assert_eq!(
        b.ask(&[0x31, 0x02, 0x02, 0x03]),
        Some(vec![0x71, 0x02, 0x02, 0x03, 0x00])
    );
    assert_eq!(
        b.ask(&[0x31, 0x03, 0x02, 0x03]),
        Some(vec![0x7F, 0x31, 0x24])
    );
    assert_eq!(
        b.ask(&[0x31, 0x01, 0x99, 0x99]),
        Some(vec![0x7F, 0x31, 0x31])
    );
}

#[test]
fn functional_requests_are_answered_physically_and_quietly_refused() {
    let id = |raw| Id::standard(raw).unwrap();
    let mut b = Bench::new();
    b.server = b.server.clone().with_functional(id(0x7DF));
    let mut functional = IsoTp::new(IsoTpConfig::new(id(0x7DF), id(0x7E8)));
    let mut ask = |b: &mut Bench, request: &[u8]| {
        functional.send(request).unwrap();
        let mut frames = Vec::new();
        functional.poll(b.now, &mut |_, f| frames.push(f));
        for f in &frames {
            b.server.on_frame(b.now, Port::MAIN, f);
        }
        b.run(Duration::from_millis(100))
    };
    assert_eq!(ask(&mut b, &[0x3E, 0x00]), [vec![0x7E, 0x00]]);
    assert_eq!(ask(&mut b, &[0x10, 0x03]).len(), 1);
    assert_eq!(b.server.session(), Session::Extended);
    // Out of range and not supported: nothing comes back to a functional request.
    assert!(ask(&mut b, &[0x22, 0x12, 0x34]).is_empty());
    assert!(ask(&mut b, &[0x99]).is_empty());
}

#[test]
fn snapshots_keep_the_first_and_latest_occurrence_and_count_them() {
    let mut b = Bench::new();
    // Speed (0x0D01, 2 bytes) and steering (0x0D02, 2 bytes) when the fault was seen.
    b.server.report_with_snapshot(
        0xC10100,
        vec![(0x0D01, vec![0x01, 0x2C]), (0x0D02, vec![0xFF, 0x38])],
    );
    b.server.report(0xC10100, false);
    b.server.report_with_snapshot(
        0xC10100,
        vec![(0x0D01, vec![0x00, 0x00]), (0x0D02, vec![0x00, 0x05])],
    );
    let status = b.server.dtc_status(0xC10100).unwrap() & 0x2F;
    assert_eq!(
        b.ask(&[0x19, 0x04, 0xC1, 0x01, 0x00, 0xFF]),
        Some(vec![
            0x59, 0x04, 0xC1, 0x01, 0x00, status, 0x01, 2, 0x0D, 0x01, 0x01, 0x2C, 0x0D, 0x02,
            0xFF, 0x38, 0x02, 2, 0x0D, 0x01, 0x00, 0x00, 0x0D, 0x02, 0x00, 0x05,
        ])
    );
    assert_eq!(
        b.ask(&[0x19, 0x04, 0xC1, 0x01, 0x00, 0x02]).unwrap()[6..],
        [0x02, 2, 0x0D, 0x01, 0x00, 0x00, 0x0D, 0x02, 0x00, 0x05]
    );
    // Two occurrences (it passed in between).
    assert_eq!(
        b.ask(&[0x19, 0x06, 0xC1, 0x01, 0x00, 0xFF]),
        Some(vec![0x59, 0x06, 0xC1, 0x01, 0x00, status, 0x01, 2])
    );
    assert_eq!(
        b.ask(&[0x19, 0x04, 0x12, 0x34, 0x56, 0x01]),
        Some(vec![0x7F, 0x19, 0x31])
    );
    assert_eq!(
        b.ask(&[0x19, 0x04, 0xC1, 0x01, 0x00, 0x07]),
        Some(vec![0x7F, 0x19, 0x31])
    );
    assert_eq!(
        b.ask(&[0x19, 0x06, 0xC1, 0x01]),
        Some(vec![0x7F, 0x19, 0x13])
    );
}
