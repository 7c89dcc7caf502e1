//! Fault injection, each action on a real virtual bus: the wrapped endpoint sends, a plain
//! endpoint listens.
// Tests fail by panicking; helpers outside #[test] functions may unwrap too.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::time::Duration;

use bywire_bus::faults::{Action, FaultyBus, Match, Rule, When};
use bywire_bus::virtual_bus::VirtualBus;
use bywire_bus::{Bus, BusRx, BusTx};
use bywire_core::{Frame, Id};

fn frame(t: &str) -> Frame {
    t.parse().unwrap()
}

fn pair(name: &str, rules: Vec<Rule>, seed: u64) -> (FaultyBus<VirtualBus>, VirtualBus) {
    let listener = VirtualBus::join(name);
    (
        FaultyBus::new(VirtualBus::join(name), rules, seed),
        listener,
    )
}

fn heard(bus: &mut VirtualBus) -> Vec<String> {
    std::iter::from_fn(|| bus.recv(Some(Duration::from_millis(30))).unwrap())
        .map(|r| r.frame.to_string())
        .collect()
}

fn rule(ids: &[u32], when: When, action: Action) -> Rule {
    let matching = if ids.is_empty() {
        Match::All
    } else {
        Match::Ids(ids.iter().map(|&i| Id::standard(i).unwrap()).collect())
    };
    Rule {
        matching,
        when,
        action,
    }
}

#[test]
fn drop_duplicate_and_silence() {
    let (mut a, mut b) = pair(
        "faults-drop",
        vec![
            rule(&[0x100], When::Always, Action::Drop),
            rule(&[0x200], When::Always, Action::Duplicate),
        ],
        1,
    );
    for t in ["100#01", "200#02", "300#03"] {
        a.send(&frame(t)).unwrap();
    }
    assert_eq!(heard(&mut b), ["200#02", "200#02", "300#03"]);
    let (mut s, mut b) = pair(
        "faults-silence",
        vec![rule(&[], When::Always, Action::Silence)],
        1,
    );
    for t in ["100#01", "7FF#"] {
        s.send(&frame(t)).unwrap();
    }
    assert_eq!(heard(&mut b), Vec::<String>::new());
}

#[test]
fn reorder_swaps_with_the_next_frame() {
    let (mut a, mut b) = pair(
        "faults-reorder",
        vec![rule(&[0x200], When::Always, Action::Reorder)],
        1,
    );
    for t in ["100#01", "200#02", "300#03", "400#04"] {
        a.send(&frame(t)).unwrap();
    }
    assert_eq!(heard(&mut b), ["100#01", "300#03", "200#02", "400#04"]);
}

#[test]
fn corrupt_flips_one_bit_per_byte_reproducibly() {
    let run = |seed| {
        let (mut a, mut b) = pair(
            &format!("faults-corrupt-{seed}"),
            vec![rule(&[], When::Always, Action::Corrupt { bytes: 1 })],
            seed,
        );
        a.send(&frame("123#0000000000000000")).unwrap();
        b.recv(Some(Duration::from_secs(1))).unwrap().unwrap().frame
    };
    let f = run(7);
    assert_eq!(
        f.data().iter().map(|b| b.count_ones()).sum::<u32>(),
        1,
        "{f}"
    );
    assert_eq!(run(7), f, "the same seed corrupts the same bit");
}

#[test]
fn freeze_repeats_the_first_payload() {
    let (mut a, mut b) = pair(
        "faults-freeze",
        vec![rule(&[0x100], When::Always, Action::Freeze)],
        1,
    );
    for counter in 0..4 {
        a.send(&frame(&format!("100#{counter:02X}AA"))).unwrap();
        a.send(&frame(&format!("101#{counter:02X}"))).unwrap();
    }
    assert_eq!(
        heard(&mut b),
        ["100#00AA", "101#00", "100#00AA", "101#01", "100#00AA", "101#02", "100#00AA", "101#03"]
    );
}

#[test]
fn probability_is_seeded_and_roughly_right() {
    let pattern = |seed| {
        let (mut a, mut b) = pair(
            &format!("faults-p-{seed}"),
            vec![rule(&[], When::Probability(0.3), Action::Drop)],
            seed,
        );
        for i in 0..1000u32 {
            a.send(&frame(&format!("123#{:04X}", i))).unwrap();
        }
        heard(&mut b)
    };
    let first = pattern(42);
    assert!(
        (600..800).contains(&first.len()),
        "{} of 1000 passed at p = 0.3",
        first.len()
    );
    assert_eq!(pattern(42), first);
    assert_ne!(pattern(43), first);
}

#[test]
fn delay_and_time_windows() {
    let (mut a, mut b) = pair(
        "faults-delay",
        vec![rule(
            &[0x100],
            When::Always,
            Action::Delay(Duration::from_millis(80)),
        )],
        1,
    );
    a.send(&frame("100#01")).unwrap();
    a.send(&frame("200#02")).unwrap();
    assert_eq!(heard(&mut b), ["200#02"]);
    std::thread::sleep(Duration::from_millis(100));
    // Due frames go out on the wrapper's next send or receive.
    assert!(a.recv(Some(Duration::from_millis(1))).unwrap().is_none());
    assert_eq!(heard(&mut b), ["100#01"]);

    let window = When::Window {
        from: Duration::ZERO,
        to: Duration::from_millis(60),
    };
    let (mut w, mut b) = pair("faults-window", vec![rule(&[], window, Action::Drop)], 1);
    w.send(&frame("123#01")).unwrap();
    std::thread::sleep(Duration::from_millis(80));
    w.send(&frame("123#02")).unwrap();
    assert_eq!(heard(&mut b), ["123#02"]);
}

#[test]
fn a_split_faulty_bus_keeps_its_faults_on_the_sending_half() {
    let (a, mut b) = pair(
        "faults-split",
        vec![rule(&[0x100], When::Always, Action::Drop)],
        1,
    );
    let (mut tx, _rx) = Box::new(a).split();
    tx.send(&frame("100#")).unwrap();
    tx.send(&frame("200#")).unwrap();
    assert_eq!(heard(&mut b), ["200#"]);
}
