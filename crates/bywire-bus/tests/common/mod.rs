//! The conformance suite every backend must pass: ordering, filters, own-message semantics, FD,
//! monotonic timestamps, no loss below the queue limit (and counted drops above it), split
//! halves across threads. Each check takes a function that opens endpoints on one fresh bus, so
//! the same checks run on every backend (the virtual and bit-timed buses in
//! `tests/conformance.rs`, SocketCAN in `tests/socketcan.rs`).
#![allow(dead_code)]

use std::time::Duration;

use bywire_bus::{Bus, Filtering, Received, Stats};
use bywire_core::filter::{ErrorMask, Filter, FilterItem};
use bywire_core::Frame;

pub const WAIT: Duration = Duration::from_secs(2);
pub const QUIET: Duration = Duration::from_millis(100);

pub fn frame(text: &str) -> Frame {
    text.parse().unwrap()
}

pub fn filter(text: &str) -> Filter {
    match text.parse::<FilterItem>().unwrap() {
        FilterItem::Filter(f) => f,
        other => panic!("{other:?}"),
    }
}

/// Everything that arrives until the bus is quiet.
pub fn drain(bus: &mut dyn Bus) -> Vec<String> {
    let mut out = Vec::new();
    while let Some(r) = bus.recv(Some(QUIET)).unwrap() {
        out.push(r.frame.to_string());
    }
    out
}

/// What arrives, in no particular order: a controller with several transmit mailboxes (the
/// bit-timed bus) sends a burst in priority order, not in the order it was queued.
pub fn drain_set(bus: &mut dyn Bus) -> Vec<String> {
    let mut out = drain(bus);
    out.sort();
    out
}

fn sorted<const N: usize>(texts: [&str; N]) -> Vec<String> {
    let mut out: Vec<String> = texts.iter().map(|t| t.to_string()).collect();
    out.sort();
    out
}

/// Opens endpoints on one bus that no other check uses.
pub type Opener = dyn Fn() -> Box<dyn Bus>;

/// A reader on its own thread, as a program would have one: what it received until quiet.
fn reader(mut bus: Box<dyn Bus>) -> std::thread::JoinHandle<(Vec<Received>, Stats)> {
    std::thread::spawn(move || {
        let mut got = Vec::new();
        while let Some(r) = bus.recv(Some(QUIET * 5)).unwrap() {
            got.push(r);
        }
        (got, bus.stats())
    })
}

pub fn ordering_and_timestamps(open: &Opener) {
    let (mut a, b) = (open(), open());
    let b = reader(b);
    let sent: Vec<String> = (0..500)
        .map(|i| format!("{:03X}#{:04X}", i % 0x800, i))
        .collect();
    for s in &sent {
        a.send(&frame(s)).unwrap();
    }
    let (got, stats) = b.join().unwrap();
    let texts: Vec<String> = got.iter().map(|r| r.frame.to_string()).collect();
    assert_eq!(texts, sent, "every frame arrives, in order");
    assert!(got.iter().all(|r| !r.own));
    assert!(
        got.windows(2).all(|w| w[1].timestamp >= w[0].timestamp),
        "timestamps never go back"
    );
    assert_eq!(a.stats().tx_frames, 500);
    assert_eq!(a.stats().tx_bytes, 1000);
    assert_eq!(
        (stats.rx_frames, stats.rx_bytes, stats.rx_dropped),
        (500, 1000, 0)
    );
}

/// Two senders on two threads: every reader gets all frames with each sender's order kept, and
/// with `global` the same interleaving at every reader (one wire; SocketCAN delivers frames
/// from several local senders through per-CPU queues, so its readers may interleave them
/// differently).
pub fn senders_keep_their_order(open: &Opener, global: bool) {
    let (a, c) = (open(), open());
    let (b, d) = (reader(open()), reader(open()));
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
    let texts = |received: Vec<Received>| -> Vec<String> {
        received.iter().map(|r| r.frame.to_string()).collect()
    };
    let (seen_b, seen_d) = (texts(b.join().unwrap().0), texts(d.join().unwrap().0));
    if global {
        assert_eq!(seen_b, seen_d, "every reader sees the same order");
    }
    for seen in [&seen_b, &seen_d] {
        for base in ["100#", "200#"] {
            let mine: Vec<&String> = seen.iter().filter(|s| s.starts_with(base)).collect();
            let sent: Vec<String> = (0..300).map(|i| format!("{base}{i:04X}")).collect();
            assert_eq!(
                mine,
                sent.iter().collect::<Vec<_>>(),
                "each sender's order kept"
            );
        }
    }
}

pub fn filters_follow_socketcan(open: &Opener) {
    let (mut a, mut b) = (open(), open());
    b.set_filtering(Filtering {
        filters: vec![filter("100:7F0"), filter("00000200:1FFFFFFF")],
        error_mask: ErrorMask::NONE,
        join: false,
    })
    .unwrap();
    for t in ["100#", "10F#01", "110#", "00000200#", "200#", "00000201#"] {
        a.send(&frame(t)).unwrap();
    }
    // 0x200 standard matches the extended filter too: its mask lacks the EFF flag.
    assert_eq!(
        drain_set(b.as_mut()),
        sorted(["100#", "10F#01", "00000200#", "200#"])
    );
    // Inverted and joined: everything in 0x100..0x1FF except 0x123.
    b.set_filtering(Filtering {
        filters: vec![filter("100:700"), filter("123~7FF")],
        error_mask: ErrorMask::NONE,
        join: true,
    })
    .unwrap();
    for t in ["123#", "124#", "223#", "1FF#"] {
        a.send(&frame(t)).unwrap();
    }
    assert_eq!(drain_set(b.as_mut()), sorted(["124#", "1FF#"]));
    // No filters: no data frames at all.
    b.set_filtering(Filtering {
        filters: vec![],
        error_mask: ErrorMask::NONE,
        join: false,
    })
    .unwrap();
    a.send(&frame("100#")).unwrap();
    assert_eq!(drain(b.as_mut()), Vec::<String>::new());
}

/// Error frames injected by a sender reach only the endpoints whose error mask asks for their
/// class (for backends that can carry injected error frames: the real-time virtual bus).
pub fn injected_error_frames_follow_the_mask(open: &Opener) {
    let (mut a, mut b) = (open(), open());
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

pub fn own_messages_only_when_asked(open: &Opener) {
    let (mut a, mut b) = (open(), open());
    a.send(&frame("123#01")).unwrap();
    assert_eq!(drain(a.as_mut()), Vec::<String>::new());
    a.set_receive_own(true).unwrap();
    a.send(&frame("123#02")).unwrap();
    let r = a.recv(Some(WAIT)).unwrap().unwrap();
    assert!(r.own && r.frame.to_string() == "123#02", "{r:?}");
    // A frame from another endpoint is not "own", even with the same content.
    b.send(&frame("123#02")).unwrap();
    let r = a.recv(Some(WAIT)).unwrap().unwrap();
    assert!(!r.own && r.frame.to_string() == "123#02", "{r:?}");
    assert_eq!(drain(b.as_mut()), ["123#01", "123#02"]);
}

pub fn loopback_off_keeps_frames_from_local_endpoints(open: &Opener) {
    let (mut a, mut b) = (open(), open());
    a.set_loopback(false).unwrap();
    a.set_receive_own(true).unwrap();
    a.send(&frame("321#01")).unwrap();
    // Own frames need loopback in SocketCAN too; with it off, nobody local hears the frame.
    assert_eq!(drain(b.as_mut()), Vec::<String>::new());
    assert_eq!(drain(a.as_mut()), Vec::<String>::new());
    a.set_loopback(true).unwrap();
    a.send(&frame("321#02")).unwrap();
    assert_eq!(drain(b.as_mut()), ["321#02"]);
}

pub fn fd_and_remote_frames(open: &Opener) {
    let (mut a, mut b) = (open(), open());
    let texts = [
        "123##5000102030405060708090A0B0C0D0E0F101112131415161718191A1B1C1D1E1F",
        "1ABCDEF0##4",
        "1ABCDEF0#R3",
        "7FF#1122334455667788",
    ];
    for t in texts {
        a.send(&frame(t)).unwrap();
    }
    assert_eq!(drain_set(b.as_mut()), sorted(texts));
}

/// A burst larger than the reader's queue: what arrives is the start of the burst in order,
/// and every missing frame is counted (some backends report their count with the next frame
/// received, so one more frame is sent after the burst).
pub fn bounded_queue_counts_drops(open_small: &Opener, burst: usize) {
    let (mut a, mut slow) = (open_small(), open_small());
    let sent: Vec<String> = (0..burst).map(|i| format!("123#{:04X}", i)).collect();
    for s in &sent {
        a.send(&frame(s)).unwrap();
    }
    // The reader is slow: it looks only after the whole burst has been on the bus.
    std::thread::sleep(Duration::from_millis(200));
    let got = drain(slow.as_mut());
    assert!(
        !got.is_empty() && got.len() < burst,
        "{} arrived",
        got.len()
    );
    assert_eq!(
        got[..],
        sent[..got.len()],
        "the start of the burst, in order"
    );
    a.send(&frame("456#")).unwrap();
    assert_eq!(drain(slow.as_mut()), ["456#"]);
    let dropped = usize::try_from(slow.stats().rx_dropped).unwrap();
    assert_eq!(got.len() + dropped, burst, "every lost frame counted");
}

pub fn halves_on_two_threads(open: &Opener) {
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

pub fn timeout_returns_none(open: &Opener) {
    let mut a = open();
    let start = std::time::Instant::now();
    assert!(a.recv(Some(Duration::from_millis(30))).unwrap().is_none());
    assert!(start.elapsed() >= Duration::from_millis(30));
}

/// Every check that needs nothing beyond the Bus trait, each on a bus of its own; `global`:
/// whether the backend promises one order of all frames at every reader.
pub fn run_all(open_for: &dyn Fn(&str) -> Box<Opener>, global: bool) {
    ordering_and_timestamps(&*open_for("order"));
    senders_keep_their_order(&*open_for("global"), global);
    filters_follow_socketcan(&*open_for("filters"));
    own_messages_only_when_asked(&*open_for("own"));
    fd_and_remote_frames(&*open_for("fd"));
    halves_on_two_threads(&*open_for("split"));
    timeout_returns_none(&*open_for("timeout"));
}

/// For tests that need an environment this machine lacks (a kernel with CAN, a private network
/// namespace): true when running in it (`marker` is set); otherwise runs this test binary's
/// `test` there through `launcher` (a command line ending before the binary), checks it passed,
/// and returns false.
pub fn inside(marker: &str, test: &str, launcher: &[&std::ffi::OsStr]) -> bool {
    if std::env::var_os(marker).is_some() {
        return true;
    }
    let exe = std::env::current_exe().unwrap();
    let (program, args) = launcher.split_first().expect("a launcher");
    let out = std::process::Command::new(program)
        .args(args)
        .arg(&exe)
        .args(["--exact", test, "--nocapture", "--test-threads", "1"])
        .env(marker, "1")
        .env("CANVM_ENV", marker)
        .output()
        .expect("the launcher runs (see ../shared/tools/README.md)");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && text.contains("test result: ok. 1 passed"),
        "{test} in {program:?}: {text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    false
}
