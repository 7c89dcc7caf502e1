//! The conformance suite (`tests/common`) on the in-process backends: the real-time virtual bus
//! and the bit-timed bus run against the wall clock (`sim:`), plus what only the simulated
//! wire can show: frames spaced by their wire time, and error frames and controller state from
//! error confinement.
// Tests fail by panicking; helpers outside #[test] functions may unwrap too.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use std::time::Duration;

use bywire_bus::sim_endpoint::{Bitrates, SimEndpoint};
use bywire_bus::virtual_bus::VirtualBus;
use bywire_bus::{open, Bus, BusError, ControllerState, Filtering, OpenError};
use bywire_core::filter::ErrorMask;
use bywire_core::frame::ErrorClass;
use bywire_core::{wire, Frame};
use common::*;

fn opener(spec: String) -> Box<Opener> {
    Box::new(move || open(&spec).unwrap())
}

#[test]
fn virtual_bus_passes_the_conformance_suite() {
    run_all(
        &|check| opener(format!("virtual:conformance-{check}")),
        true,
    );
    loopback_off_keeps_frames_from_local_endpoints(&*opener("virtual:conformance-lo".into()));
    injected_error_frames_follow_the_mask(&*opener("virtual:conformance-err".into()));
    bounded_queue_counts_drops(
        &|| Box::new(VirtualBus::join_with_queue("conformance-small", 16)),
        40,
    );
}

#[test]
fn bit_timed_bus_passes_the_conformance_suite() {
    run_all(
        &|check| opener(format!("sim:conformance-{check}@1000000/5000000")),
        true,
    );
    let bitrates = Bitrates {
        nominal: 1_000_000,
        data: None,
    };
    bounded_queue_counts_drops(
        &move || Box::new(SimEndpoint::join("conformance-small", bitrates, 16).unwrap()),
        40,
    );
}

#[test]
fn bit_timed_bus_delivers_at_wire_time() {
    let (mut a, mut b) = (
        open("sim:wire-time@500000").unwrap(),
        open("sim:wire-time@500000").unwrap(),
    );
    let texts = ["300#0102", "100#0A0B0C0D0E0F1011", "200#"];
    for t in texts {
        a.send(&frame(t)).unwrap();
    }
    let got: Vec<_> = (0..3)
        .map(|_| b.recv(Some(WAIT)).unwrap().unwrap())
        .collect();
    // The first frame had the bus to itself; the two others queued behind it and then went in
    // identifier order, each directly after the previous one's intermission.
    let ids: Vec<String> = got.iter().map(|r| r.frame.to_string()).collect();
    assert_eq!(ids, ["300#0102", "100#0A0B0C0D0E0F1011", "200#"]);
    for pair in got.windows(2) {
        let length = u64::try_from(wire::encode(&pair[1].frame).unwrap().len()).unwrap();
        let gap = pair[1].timestamp.saturating_since(pair[0].timestamp);
        // 2 µs a bit: the frame itself plus 3 bits of intermission, unless the sender's
        // thread was late to queue it (then later, never earlier).
        assert!(
            gap >= Duration::from_nanos((length + 3) * 2_000),
            "{gap:?} for {length} bits"
        );
    }
}

#[test]
fn bit_timed_bus_reports_errors_as_frames_and_status() {
    let bitrates = Bitrates {
        nominal: 500_000,
        data: None,
    };
    let faulty = SimEndpoint::join("errors", bitrates, 64).unwrap();
    let mut peer = open("sim:errors@500000").unwrap();
    let mut bystander = open("sim:errors@500000").unwrap();
    // Destroy 16 transmissions: TEC 8 × 16 = 128, error passive; the 17th attempt succeeds.
    faulty.corrupt_own(16);
    let mut faulty: Box<dyn Bus> = Box::new(faulty);
    assert_eq!(
        faulty.status().unwrap().unwrap().state,
        ControllerState::ErrorActive
    );
    faulty
        .set_filtering(Filtering {
            filters: vec![],
            error_mask: ErrorMask(ErrorClass::Controller.bit()),
            join: false,
        })
        .unwrap();
    faulty.send(&frame("123#01")).unwrap();
    let report = faulty.recv(Some(WAIT)).unwrap().expect("an error frame");
    let Frame::Error(e) = report.frame else {
        panic!("{report:?}")
    };
    assert!(
        e.has(ErrorClass::Controller) && e.data()[1] == 0x20,
        "tx passive: {e:?}"
    );
    assert_eq!(e.counters(), Some((128, 0)));
    assert_eq!(faulty.stats().rx_errors, 1);
    // The peer gets the frame once, after 16 error frames; then TEC is down by one, still
    // above the warning limit, and each receiver's REC went up 16 and down 1.
    assert_eq!(drain(peer.as_mut()), ["123#01"]);
    let status = faulty.status().unwrap().unwrap();
    assert_eq!(
        (status.state, status.tec, status.rec),
        (ControllerState::ErrorWarning, 127, 0)
    );
    let status = bystander.status().unwrap().unwrap();
    assert_eq!(
        (status.state, status.rec),
        (ControllerState::ErrorActive, 15)
    );
    // Data frames only, by default: the bystander got the frame and no error frames.
    assert_eq!(drain(bystander.as_mut()), ["123#01"]);
}

#[test]
fn bit_timed_bus_refuses_what_a_wire_cannot_do() {
    let mut a = open("sim:refuse@500000").unwrap();
    assert!(matches!(
        a.send(&frame("20000004#0004000000000000")),
        Err(BusError::Unsupported(_))
    ));
    let e = match open("sim:refuse@250000") {
        Err(e) => e,
        Ok(_) => panic!("joined at another bitrate"),
    };
    assert!(matches!(e, OpenError::Refused { .. }));
    assert!(e.to_string().contains("already runs at"), "{e}");
}

#[test]
fn buses_with_different_names_are_separate_and_end_with_their_endpoints() {
    for scheme in ["virtual:separate", "sim:separate"] {
        let rate = if scheme.starts_with("sim") {
            "@500000"
        } else {
            ""
        };
        let mut a = open(&format!("{scheme}-a{rate}")).unwrap();
        let mut b = open(&format!("{scheme}-b{rate}")).unwrap();
        a.send(&frame("123#")).unwrap();
        assert!(b.recv(Some(QUIET)).unwrap().is_none());
        drop(a);
        // A new endpoint on a bus nobody holds any more starts empty.
        let mut again = open(&format!("{scheme}-a{rate}")).unwrap();
        assert!(again.recv(Some(QUIET)).unwrap().is_none());
    }
}
