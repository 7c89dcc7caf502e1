//! The UDS client against the UDS server in simulated time: answers decoded, negative
//! responses named, P2 and P2* timeouts (and the server's timing adopted), response pending
//! repeated for a long routine, and TesterPresent keeping a session past S3.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use bywire_core::node::Port;
use core::time::Duration;

use bywire_core::node::Node;
use bywire_core::{Frame, Id, Timestamp};
use bywire_diag::client::{self, ClientError, ClientTiming, UdsClient};
use bywire_diag::isotp::IsoTpConfig;
use bywire_diag::uds::{nrc, status, Did, Routine, Session, UdsServer, UdsTiming};

fn id(raw: u32) -> Id {
    Id::standard(raw).unwrap()
}

struct Bench {
    client: UdsClient,
    server: UdsServer,
    /// The server hears nothing (unplugged).
    server_silent: bool,
    now: Timestamp,
    /// Requests the server saw.
    requests: Vec<Frame>,
}

impl Bench {
    fn new(timing: ClientTiming) -> Bench {
        let mut server =
            UdsServer::new(IsoTpConfig::new(id(0x7E8), id(0x7E0)), UdsTiming::default());
        server.set_did(
            0xF190,
            Did {
                value: b"WBYWIRE0TUG000042".to_vec(),
                writable_in: Vec::new(),
                secured: false,
            },
        );
        server.set_did(
            0x0101,
            Did {
                value: vec![1, 2],
                writable_in: vec![Session::Extended],
                secured: false,
            },
        );
        Bench {
            client: UdsClient::new(IsoTpConfig::new(id(0x7E0), id(0x7E8)), timing),
            server,
            server_silent: false,
            now: Timestamp::ZERO,
            requests: Vec::new(),
        }
    }

    /// Run in 1 ms steps until the request has an outcome (or `limit` passes).
    fn ask(&mut self, request: &[u8], limit: Duration) -> (Result<Vec<u8>, ClientError>, Duration) {
        let start = self.now;
        self.client.request(self.now, request).unwrap();
        let end = self.now.saturating_add(limit);
        while self.now < end {
            self.step();
            if let Some(outcome) = self.client.take_outcome() {
                return (outcome, self.now.saturating_since(start));
            }
        }
        panic!("no outcome for {request:02X?} within {limit:?}");
    }

    fn step(&mut self) {
        let mut to_server = Vec::new();
        let mut to_client = Vec::new();
        Node::poll(&mut self.client, self.now, &mut |_, f| to_server.push(f));
        self.server.poll(self.now, &mut |_, f| to_client.push(f));
        for f in &to_server {
            self.requests.push(*f);
            if !self.server_silent {
                self.server.on_frame(self.now, Port::MAIN, f);
            }
        }
        for f in &to_client {
            self.client.on_frame(self.now, Port::MAIN, f);
        }
        self.now = self.now.saturating_add(Duration::from_millis(1));
    }

    fn idle(&mut self, duration: Duration) {
        let end = self.now.saturating_add(duration);
        while self.now < end {
            self.step();
        }
    }
}

#[test]
fn answers_come_back_decoded_and_refusals_named() {
    let mut b = Bench::new(ClientTiming::default());
    let (answer, _) = b.ask(&[0x22, 0xF1, 0x90, 0x01, 0x01], Duration::from_secs(1));
    let lengths = |did: u16| (did == 0xF190).then_some(17);
    let values = client::did_values(&answer.unwrap(), &[0xF190, 0x0101], &lengths).unwrap();
    assert_eq!(values[0], (0xF190, b"WBYWIRE0TUG000042".to_vec()));
    assert_eq!(values[1], (0x0101, vec![1, 2]));
    let (refused, _) = b.ask(&[0x2E, 0x01, 0x01, 9, 9], Duration::from_secs(1));
    assert_eq!(
        refused,
        Err(ClientError::Negative {
            service: 0x2E,
            code: nrc::CONDITIONS_NOT_CORRECT
        })
    );
    assert!(refused
        .unwrap_err()
        .to_string()
        .contains("conditionsNotCorrect"));

    b.server.report(0xC07300, true);
    b.server.report(0x512300, true);
    b.server.report(0x512300, false);
    let (listed, _) = b.ask(&[0x19, 0x02, 0xFF], Duration::from_secs(1));
    let (_, dtcs) = client::dtc_list(&listed.unwrap()).unwrap();
    assert_eq!(dtcs.len(), 2);
    let failing = dtcs.iter().find(|(d, _)| *d == 0xC07300).unwrap().1;
    assert_ne!(failing & status::TEST_FAILED, 0);
    let passed = dtcs.iter().find(|(d, _)| *d == 0x512300).unwrap().1;
    assert_eq!(passed & status::TEST_FAILED, 0);
    assert_ne!(passed & status::CONFIRMED, 0);
}

#[test]
fn the_session_answer_sets_p2_and_a_silent_server_times_out_at_p2() {
    let mut b = Bench::new(ClientTiming {
        tester_present: None,
        ..ClientTiming::default()
    });
    assert_eq!(b.client.p2().0, Duration::from_millis(1000));
    let (answer, _) = b.ask(&[0x10, 0x03], Duration::from_secs(1));
    assert_eq!(answer.unwrap()[..2], [0x50, 0x03]);
    // The server's 50 ms and 5000 ms, plus the 50 ms margin.
    assert_eq!(
        b.client.p2(),
        (Duration::from_millis(100), Duration::from_millis(5050))
    );
    b.server_silent = true;
    let (outcome, took) = b.ask(&[0x22, 0xF1, 0x90], Duration::from_secs(2));
    assert_eq!(outcome, Err(ClientError::Timeout { pending: false }));
    assert!(
        (Duration::from_millis(100)..=Duration::from_millis(102)).contains(&took),
        "{took:?}"
    );
}

#[test]
fn response_pending_stretches_the_wait_to_p2_star_and_repeats_for_a_long_routine() {
    let mut b = Bench::new(ClientTiming::default());
    // Longer than one P2* (5 s): the server repeats its response pending.
    b.server.set_routine(
        0x0203,
        Routine {
            runs_for: Duration::from_secs(9),
            result: vec![0xAA],
            secured: false,
        },
    );
    b.ask(&[0x10, 0x03], Duration::from_secs(1)).0.unwrap();
    let (answer, took) = b.ask(&[0x31, 0x01, 0x02, 0x03], Duration::from_secs(20));
    assert_eq!(answer.unwrap(), vec![0x71, 0x01, 0x02, 0x03, 0x00]);
    assert!(
        (Duration::from_secs(9)..Duration::from_millis(9010)).contains(&took),
        "{took:?}"
    );
    let (results, _) = b.ask(&[0x31, 0x03, 0x02, 0x03], Duration::from_secs(1));
    assert_eq!(results.unwrap(), vec![0x71, 0x03, 0x02, 0x03, 0xAA]);

    // A server that goes quiet after its response pending: the client gives up at P2*.
    b.server.set_routine(
        0x0204,
        Routine {
            runs_for: Duration::from_secs(3),
            result: Vec::new(),
            secured: false,
        },
    );
    b.client.request(b.now, &[0x31, 0x01, 0x02, 0x04]).unwrap();
    let start = b.now;
    // Long enough for the request and its response pending, then the server is unplugged.
    b.idle(Duration::from_millis(5));
    b.server_silent = true;
    let mut outcome = None;
    while outcome.is_none() && b.now < start.saturating_add(Duration::from_secs(20)) {
        let mut to_client = Vec::new();
        Node::poll(&mut b.client, b.now, &mut |_, _| {});
        // The server's own answers are lost too.
        b.server.poll(b.now, &mut |_, f| to_client.push(f));
        b.now = b.now.saturating_add(Duration::from_millis(1));
        outcome = b.client.take_outcome();
    }
    assert_eq!(outcome, Some(Err(ClientError::Timeout { pending: true })));
    let took = b.now.saturating_since(start);
    assert!(
        (Duration::from_millis(5050)..Duration::from_millis(5060)).contains(&took),
        "{took:?}"
    );
}

#[test]
fn tester_present_keeps_a_session_past_s3_and_without_it_the_server_falls_back() {
    for keep in [true, false] {
        let mut b = Bench::new(ClientTiming {
            tester_present: keep.then_some(Duration::from_secs(2)),
            ..ClientTiming::default()
        });
        b.ask(&[0x10, 0x03], Duration::from_secs(1)).0.unwrap();
        b.idle(Duration::from_millis(12_500));
        let expected = if keep {
            Session::Extended
        } else {
            Session::Default
        };
        assert_eq!(b.server.session(), expected, "tester present {keep}");
        // Each TesterPresent is one single frame, 3E 80, with no answer.
        let tester_presents = b
            .requests
            .iter()
            .filter(|f| f.data().get(..3) == Some(&[0x02, 0x3E, 0x80][..]))
            .count();
        assert_eq!(tester_presents, if keep { 6 } else { 0 });
        assert!(!b.client.busy());
    }
}

#[test]
fn one_request_at_a_time() {
    let mut b = Bench::new(ClientTiming::default());
    b.client.request(b.now, &[0x3E, 0x00]).unwrap();
    assert_eq!(
        b.client.request(b.now, &[0x3E, 0x00]),
        Err(ClientError::Busy)
    );
    assert!(matches!(
        b.client.request(b.now, &[]),
        Err(ClientError::Busy)
    ));
}

#[test]
fn malformed_answers_are_named_not_misread() {
    let by = |_: u16| Some(2);
    assert!(client::dtc_list(&[0x59, 0x02, 0xFF, 1, 2, 3]).is_err());
    assert!(client::did_values(&[0x62, 0xF1, 0x90, 1], &[0xF190], &by).is_err());
    assert!(client::did_values(&[0x62, 0xF1, 0x91, 1, 2], &[0xF190], &by).is_err());
    assert!(client::snapshots(&[0x59, 0x04, 1, 2, 3, 0x09, 1, 1, 0xDD], &by).is_err());
    let (dtc, status, records) =
        client::snapshots(&[0x59, 0x04, 1, 2, 3, 0x09, 1, 1, 0xDD, 0x01, 7, 8], &by).unwrap();
    assert_eq!((dtc, status), (0x010203, 0x09));
    assert_eq!(records[0].values, vec![(0xDD01, vec![7, 8])]);
}
