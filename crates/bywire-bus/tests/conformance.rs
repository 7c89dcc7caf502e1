//! The conformance suite every backend must pass: ordering, filters, own-message semantics, FD,
//! error frames, monotonic timestamps, no loss below the queue limit (and counted drops above it),
//! split halves across threads. Each check takes a function that opens endpoints on one fresh
//! bus, so the same checks run on every backend; today: the real-time virtual bus.
// Tests fail by panicking; helpers outside #[test] functions may unwrap too.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::time::Duration;

use bywire_bus::{open, Bus, Filtering};
use bywire_core::filter::{ErrorMask, Filter, FilterItem};
use bywire_core::Frame;

const WAIT: Duration = Duration::from_secs(2);
const QUIET: Duration = Duration::from_millis(50);

fn frame(text: &str) -> Frame {
    text.parse().unwrap()
}

fn filter(text: &str) -> Filter {
    match text.parse::<FilterItem>().unwrap() {
        FilterItem::Filter(f) => f,
        other => panic!("{other:?}"),
    }
}

fn drain(bus: &mut dyn Bus) -> Vec<String> {
    let mut out = Vec::new();
    while let Some(r) = bus.recv(Some(QUIET)).unwrap() {
        out.push(r.frame.to_string());
    }
    out
}

/// Opens endpoints on one bus that no other check uses.
type Opener = dyn Fn() -> Box<dyn Bus>;

fn ordering_and_timestamps(open: &Opener) {
    let (mut a, mut b) = (open(), open());
    let sent: Vec<String> = (0..500)
        .map(|i| format!("{:03X}#{:04X}", i % 0x800, i))
        .collect();
    for s in &sent {
        a.send(&frame(s)).unwrap();
    }
    let mut last = None;
    for s in &sent {
        let r = b.recv(Some(WAIT)).unwrap().expect("every frame arrives");
        assert_eq!(&r.frame.to_string(), s);
        assert!(!r.own);
        assert!(
            last.is_none_or(|l| r.timestamp >= l),
            "timestamps never go back"
        );
        last = Some(r.timestamp);
    }
    assert_eq!(a.stats().tx_frames, 500);
    assert_eq!(b.stats().rx_frames, 500);
    assert_eq!(b.stats().rx_bytes, 1000);
}

fn one_global_order(open: &Opener) {
    let (a, c) = (open(), open());
    let (mut b, mut d) = (open(), open());
    let send_all = |mut bus: Box<dyn Bus>, base: u32| {
        std::thread::spawn(move || {
            for i in 0..300 {
                bus.send(&frame(&format!("{:03X}#{i:04X}", base))).unwrap();
            }
            bus
        })
    };
    let (ta, tc) = (send_all(a, 0x100), send_all(c, 0x200));
    let (_a, _c) = (ta.join().unwrap(), tc.join().unwrap());
    let (seen_b, seen_d) = (drain(b.as_mut()), drain(d.as_mut()));
    assert_eq!(seen_b.len(), 600);
    assert_eq!(seen_b, seen_d, "every reader sees the same order");
}

fn filters_follow_socketcan(open: &Opener) {
    let (mut a, mut b) = (open(), open());
    b.set_filtering(Filtering {
        filters: vec![filter("100:7F0"), filter("00000200:1FFFFFFF")],
        error_mask: ErrorMask::NONE,
        join: false,
    })
    .unwrap();
    for t in [
        "100#",
        "10F#01",
        "110#",
        "00000200#",
        "200#",
        "20000004#0000000000000000",
    ] {
        a.send(&frame(t)).unwrap();
    }
    // 0x200 standard matches the extended filter too: its mask lacks the EFF flag.
    assert_eq!(drain(b.as_mut()), ["100#", "10F#01", "00000200#", "200#"]);
    b.set_filtering(Filtering {
        filters: vec![],
        error_mask: ErrorMask(0x04),
        join: false,
    })
    .unwrap();
    a.send(&frame("100#")).unwrap();
    a.send(&frame("20000004#0004000000000000")).unwrap();
    a.send(&frame("20000040#0000000000000000")).unwrap();
    assert_eq!(drain(b.as_mut()), ["20000004#0004000000000000"]);
    assert_eq!(b.stats().rx_errors, 1);
}

fn own_messages_only_when_asked(open: &Opener) {
    let (mut a, mut b) = (open(), open());
    a.send(&frame("123#01")).unwrap();
    assert_eq!(drain(a.as_mut()), Vec::<String>::new());
    a.set_receive_own(true).unwrap();
    a.send(&frame("123#02")).unwrap();
    let r = a.recv(Some(WAIT)).unwrap().unwrap();
    assert!(r.own && r.frame.to_string() == "123#02");
    assert_eq!(drain(b.as_mut()), ["123#01", "123#02"]);
}

fn fd_and_remote_frames(open: &Opener) {
    let (mut a, mut b) = (open(), open());
    let texts = [
        "123##1000102030405060708090A0B0C0D0E0F101112131415161718191A1B1C1D1E1F",
        "1ABCDEF0#R3",
        "7FF#1122334455667788_E",
    ];
    for t in texts {
        a.send(&frame(t)).unwrap();
    }
    assert_eq!(drain(b.as_mut()), texts);
}

fn bounded_queue_counts_drops(open_small: &Opener) {
    let (mut a, mut slow) = (open_small(), open_small());
    for i in 0..40 {
        a.send(&frame(&format!("123#{i:02X}"))).unwrap();
    }
    let got = drain(slow.as_mut());
    // The queue holds 16: the first 16 arrive intact and in order, the rest are counted.
    assert_eq!(
        got,
        (0..16).map(|i| format!("123#{i:02X}")).collect::<Vec<_>>()
    );
    assert_eq!(slow.stats().rx_dropped, 24);
}

fn halves_on_two_threads(open: &Opener) {
    let (a, mut b) = (open(), open());
    let (mut tx, mut rx) = a.split();
    let receiver = std::thread::spawn(move || {
        let mut n = 0;
        while let Some(r) = rx.recv(Some(WAIT)).unwrap() {
            assert_eq!(r.frame.to_string(), "321#");
            n += 1;
            if n == 100 {
                break;
            }
        }
        n
    });
    for _ in 0..100 {
        b.send(&frame("321#")).unwrap();
    }
    assert_eq!(receiver.join().unwrap(), 100);
    tx.send(&frame("111#")).unwrap();
    assert_eq!(drain(b.as_mut()), ["111#"]);
}

fn timeout_returns_none(open: &Opener) {
    let mut a = open();
    let start = std::time::Instant::now();
    assert!(a.recv(Some(Duration::from_millis(30))).unwrap().is_none());
    assert!(start.elapsed() >= Duration::from_millis(30));
}

/// A fresh virtual bus per check.
fn virtual_opener(check: &str) -> impl Fn() -> Box<dyn Bus> {
    let name = format!("virtual:conformance-{check}");
    move || open(&name).unwrap()
}

#[test]
fn virtual_bus_passes_the_conformance_suite() {
    ordering_and_timestamps(&virtual_opener("order"));
    one_global_order(&virtual_opener("global"));
    filters_follow_socketcan(&virtual_opener("filters"));
    own_messages_only_when_asked(&virtual_opener("own"));
    fd_and_remote_frames(&virtual_opener("fd"));
    halves_on_two_threads(&virtual_opener("split"));
    timeout_returns_none(&virtual_opener("timeout"));
    bounded_queue_counts_drops(&|| {
        Box::new(bywire_bus::virtual_bus::VirtualBus::join_with_queue(
            "conformance-small",
            16,
        ))
    });
}

#[test]
fn buses_with_different_names_are_separate_and_end_with_their_endpoints() {
    let mut a = open("virtual:separate-a").unwrap();
    let mut b = open("virtual:separate-b").unwrap();
    a.send(&frame("123#")).unwrap();
    assert!(b.recv(Some(QUIET)).unwrap().is_none());
    drop(a);
    // A new endpoint on a bus nobody holds any more starts empty.
    let mut again = open("virtual:separate-a").unwrap();
    assert!(again.recv(Some(QUIET)).unwrap().is_none());
}
