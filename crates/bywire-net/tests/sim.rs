//! The bit-timed bus against the textbook: arbitration order, exact frame times from the wire
//! model, and the fault-confinement path to bus-off and back, with exact simulated timestamps.
// Tests fail by panicking; helpers outside #[test] functions may unwrap too.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use bywire_core::confinement::NodeState;
use bywire_core::wire::{self, Field};
use bywire_core::{Frame, Timestamp};
use bywire_net::sim::{BusEvent, Corruption, Fault, SimBus, Tamper};
use std::time::Duration;

/// 500 kbit/s: 2 µs per bit.
const BIT_NS: u64 = 2_000;

fn frame(t: &str) -> Frame {
    t.parse().unwrap()
}

fn ns(t: Timestamp) -> u64 {
    t.as_nanos()
}

#[test]
fn three_nodes_start_together_and_leave_in_id_order() {
    let mut bus = SimBus::new(500_000, None);
    let nodes = [bus.add_node(), bus.add_node(), bus.add_node()];
    let listener = bus.add_node();
    let frames = ["300#0102", "100#0A0B0C", "200#FF"];
    for (n, f) in nodes.iter().zip(frames) {
        bus.submit(*n, frame(f), Timestamp::ZERO);
    }
    bus.advance(Timestamp::from_millis(10));
    let events = bus.take_events();
    let sent: Vec<(u32, u64, u64)> = events
        .iter()
        .filter_map(|e| match e {
            BusEvent::Transmitted { id, start, end, .. } => {
                Some((id.as_raw(), ns(*start), ns(*end)))
            }
            _ => None,
        })
        .collect();
    assert_eq!(
        sent.iter().map(|s| s.0).collect::<Vec<_>>(),
        [0x100, 0x200, 0x300]
    );
    // Each frame lasts its exact stuffed length; the next starts after 3 bits of intermission.
    let mut expected_start = 0;
    for (id, start, end) in &sent {
        let text = frames
            .iter()
            .find(|f| u32::from_str_radix(&f[..3], 16).unwrap() == *id)
            .unwrap();
        let length = u64::try_from(wire::encode(&frame(text)).unwrap().len()).unwrap();
        assert_eq!(*start, expected_start, "{id:X}");
        assert_eq!(end - start, length * BIT_NS, "{id:X}");
        expected_start = end + 3 * BIT_NS;
    }
    // Losers at the first arbitration: 0x300 and 0x200; at the second: 0x300.
    let losses: Vec<(u32, u64)> = events
        .iter()
        .filter_map(|e| match e {
            BusEvent::ArbitrationLost { id, at, .. } => Some((id.as_raw(), ns(*at))),
            _ => None,
        })
        .collect();
    assert_eq!(losses, [(0x300, 0), (0x200, 0), (0x300, sent[1].1)]);
    // The listener got all three, stamped at their end of frame.
    let got: Vec<(String, u64)> = std::iter::from_fn(|| bus.receive(listener))
        .map(|r| (r.frame.to_string(), ns(r.timestamp)))
        .collect();
    assert_eq!(
        got,
        [
            ("100#0A0B0C".to_string(), sent[0].2),
            ("200#FF".to_string(), sent[1].2),
            ("300#0102".to_string(), sent[2].2)
        ]
    );
    // Unreported, the losses are left out and nothing else changes.
    let mut quiet = SimBus::new(500_000, None);
    quiet.report_arbitration(false);
    let quiet_nodes = [quiet.add_node(), quiet.add_node(), quiet.add_node()];
    for (n, f) in quiet_nodes.iter().zip(frames) {
        quiet.submit(*n, frame(f), Timestamp::ZERO);
    }
    quiet.advance(Timestamp::from_millis(10));
    let reported: Vec<BusEvent> = events
        .into_iter()
        .filter(|e| !matches!(e, BusEvent::ArbitrationLost { .. }))
        .collect();
    assert_eq!(quiet.take_events(), reported);
}

#[test]
fn repeated_corruption_leads_to_bus_off_and_recovery_at_exact_times() {
    let mut bus = SimBus::new(500_000, None);
    let sender = bus.add_node();
    let receiver = bus.add_node();
    let f = frame("123#DEADBEEF");
    bus.corrupt(Fault {
        node: Some(sender),
        id: None,
        count: 32,
        kind: Default::default(),
    });
    bus.submit(sender, f, Timestamp::ZERO);
    bus.advance(Timestamp::from_millis(100));
    let events = bus.take_events();

    // Each destroyed attempt: up to the CRC delimiter, 14 bits of error flag and delimiter,
    // 3 of intermission; an error-passive sender waits 8 bits more (suspend transmission).
    let encoded = wire::encode(&f).unwrap();
    let detected = u64::try_from(
        encoded
            .spans()
            .iter()
            .find(|s| s.field == Field::CrcDelimiter)
            .unwrap()
            .start
            + 1,
    )
    .unwrap();
    let attempt = detected + 14;
    let mut t = 0;
    let mut passive_at = None;
    let mut bus_off_at = None;
    let destroyed: Vec<(u64, u64)> = events
        .iter()
        .filter_map(|e| match e {
            BusEvent::Destroyed { start, end, .. } => Some((ns(*start), ns(*end))),
            _ => None,
        })
        .collect();
    assert_eq!(destroyed.len(), 32);
    for (k, (start, end)) in destroyed.iter().enumerate() {
        assert_eq!(*start, t, "attempt {}", k + 1);
        assert_eq!(*end, t + attempt * BIT_NS, "attempt {}", k + 1);
        let passive = k + 1 >= 16;
        if k + 1 == 16 {
            passive_at = Some(*end);
        }
        if k + 1 == 32 {
            bus_off_at = Some(*end);
        }
        t = end + (3 + if passive { 8 } else { 0 }) * BIT_NS;
    }
    let changes: Vec<(NodeState, u64)> = events
        .iter()
        .filter_map(|e| match e {
            BusEvent::StateChanged { node, state, at } if *node == sender => {
                Some((*state, ns(*at)))
            }
            _ => None,
        })
        .collect();
    // TEC reaches 128 with the 16th error (error passive) and 256 with the 32nd (bus-off);
    // recovery after 128 sequences of 11 recessive bits counted from the end of intermission.
    let bus_off = bus_off_at.unwrap();
    let recovered = bus_off + 3 * BIT_NS + 128 * 11 * BIT_NS;
    assert_eq!(
        changes,
        [
            (NodeState::ErrorPassive, passive_at.unwrap()),
            (NodeState::BusOff, bus_off),
            (NodeState::ErrorActive, recovered)
        ]
    );
    // The receiver counted one receive error per destroyed frame, and the recovered sender
    // delivers the frame it still held, as soon as it is back.
    assert_eq!(bus.confinement(receiver).unwrap().rec(), 32 - 1);
    let sent: Vec<u64> = events
        .iter()
        .filter_map(|e| match e {
            BusEvent::Transmitted { start, .. } => Some(ns(*start)),
            _ => None,
        })
        .collect();
    assert_eq!(sent, [recovered]);
    let r = bus.receive(receiver).unwrap();
    assert_eq!(r.frame, f);
    assert_eq!(bus.confinement(sender).unwrap().tec(), 0);
    assert_eq!(bus.now(), Timestamp::from_millis(100));
}

/// A faulty sender of one identifier: its frames leave with a flipped bit (classic and FD), twice,
/// or late — well formed on the wire, the other identifiers untouched; mended, it sends true.
#[test]
fn tampered_identifiers_are_flipped_duplicated_or_delayed() {
    let mut bus = SimBus::new(500_000, Some(2_000_000));
    let (sender, listener) = (bus.add_node(), bus.add_node());
    let id = |raw: u32| frame(&format!("{raw:03X}#00")).id().unwrap();
    let received = |bus: &mut SimBus| -> Vec<(String, u64)> {
        std::iter::from_fn(|| bus.receive(listener))
            .map(|r| (r.frame.to_string(), ns(r.timestamp)))
            .collect()
    };
    bus.tamper(id(0x100), Some(Tamper::FlipBit));
    bus.tamper(id(0x101), Some(Tamper::FlipBit));
    bus.tamper(id(0x200), Some(Tamper::Duplicate));
    bus.submit(sender, frame("100#F0AA"), Timestamp::ZERO);
    bus.submit(sender, frame("101##1F1020304"), Timestamp::ZERO);
    bus.submit(sender, frame("200#55"), Timestamp::ZERO);
    bus.submit(sender, frame("300#F0AA"), Timestamp::ZERO);
    bus.advance(Timestamp::from_millis(10));
    let got: Vec<String> = received(&mut bus).into_iter().map(|r| r.0).collect();
    assert_eq!(
        got,
        ["100#F1AA", "101##5F0020304", "200#55", "200#55", "300#F0AA"],
        "{got:?}"
    );
    // 300 ms late, and the frame behind it from the same node is not held up.
    bus.tamper(id(0x100), Some(Tamper::Delay(Duration::from_millis(300))));
    bus.submit(sender, frame("100#01"), Timestamp::from_millis(20));
    bus.submit(sender, frame("300#02"), Timestamp::from_millis(20));
    bus.advance(Timestamp::from_millis(400));
    let got = received(&mut bus);
    assert_eq!(got.len(), 2, "{got:?}");
    assert_eq!(got[0].0, "300#02");
    assert!(got[0].1 < 21_000_000, "{got:?}");
    assert_eq!(got[1].0, "100#01");
    assert!((320_000_000..321_000_000).contains(&got[1].1), "{got:?}");
    // Mended.
    bus.tamper(id(0x100), None);
    bus.submit(sender, frame("100#F0"), Timestamp::from_millis(500));
    bus.advance(Timestamp::from_millis(510));
    let got = received(&mut bus);
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].0, "100#F0");
    assert!(got[0].1 < 501_000_000, "{got:?}");
}

/// A burst until bus-off: the sender of 0x300 goes bus-off although its 0x100 frames succeed
/// in between (each taking 1 off its error counter), once; after its recovery the burst is
/// over and the frame it was retrying goes through.
#[test]
fn a_burst_until_bus_off_gets_there_and_then_ends() {
    let mut bus = SimBus::new(500_000, None);
    let (sender, listener) = (bus.add_node(), bus.add_node());
    bus.take_off_bus(None, Some(frame("300#00").id().unwrap()));
    bus.submit(sender, frame("300#AA"), Timestamp::ZERO);
    // A higher-priority frame of its own every 0.5 ms wins each arbitration it is in.
    for k in 0..200 {
        bus.submit(sender, frame("100#01"), Timestamp::from_micros(k * 500));
    }
    bus.advance(Timestamp::from_millis(200));
    let events = bus.take_events();
    let states: Vec<NodeState> = events
        .iter()
        .filter_map(|e| match e {
            BusEvent::StateChanged { node, state, .. } if *node == sender => Some(*state),
            _ => None,
        })
        .collect();
    let offs = states.iter().filter(|s| **s == NodeState::BusOff).count();
    assert_eq!(offs, 1, "{states:?}");
    assert_eq!(states.last(), Some(&NodeState::ErrorActive), "{states:?}");
    let destroyed = events
        .iter()
        .filter(|e| matches!(e, BusEvent::Destroyed { .. }))
        .count();
    assert!(
        destroyed > 32,
        "successes in between cost more: {destroyed}"
    );
    let got: Vec<String> = std::iter::from_fn(|| bus.receive(listener))
        .map(|r| r.frame.to_string())
        .collect();
    assert!(got.iter().any(|f| f == "300#AA"), "{got:?}");
}

/// The bus remembers which nodes take an identifier and when the next frame may start; a
/// filter changed, a node added or a frame queued between transmissions must still count at
/// once (regression guard for those caches).
#[test]
fn filters_nodes_and_queued_frames_changed_between_frames_count_at_once() {
    use bywire_core::Filter;
    use bywire_net::Filtering;
    let mut bus = SimBus::new(500_000, None);
    let (sender, listener) = (bus.add_node(), bus.add_node());
    let heard = |bus: &mut SimBus, node| {
        let mut ids = Vec::new();
        while let Some(r) = bus.receive(node) {
            ids.push(r.frame.id().unwrap().as_raw());
        }
        ids
    };
    bus.submit(sender, frame("123#01"), Timestamp::ZERO);
    bus.advance(Timestamp::from_millis(1));
    assert_eq!(heard(&mut bus, listener), [0x123]);
    // Asked when the next change is (nothing queued), then a frame queued: it is seen.
    assert_eq!(bus.next_change(listener), None);
    bus.submit(sender, frame("123#02"), Timestamp::from_millis(1));
    assert_eq!(
        bus.next_change(listener),
        Some(Timestamp::from_millis(1)),
        "a frame queued after the question"
    );
    // The listener now takes 0x200 only: 0x123 no longer reaches it, 0x200 does.
    bus.set_filtering(
        listener,
        Filtering {
            filters: vec![Filter::new(0x200, 0x7FF)],
            ..Filtering::default()
        },
    );
    bus.submit(sender, frame("200#03"), Timestamp::from_millis(1));
    bus.advance(Timestamp::from_millis(3));
    assert_eq!(heard(&mut bus, listener), [0x200]);
    // A node added later hears 0x123 (the default filter) though the bus knew 0x123 before.
    let late = bus.add_node();
    bus.submit(sender, frame("123#04"), Timestamp::from_millis(3));
    bus.advance(Timestamp::from_millis(5));
    assert_eq!(heard(&mut bus, late), [0x123]);
    assert!(heard(&mut bus, listener).is_empty());
}

/// Builds the same bus twice, one with its first `routed` nodes routed, runs the same
/// traffic (a node corrupted to bus-off and back, a filter, own frames echoed) and returns
/// what each node received on each: the routed copies spread out to the nodes they name.
fn same_traffic_routed_or_not() -> [Vec<Vec<(u64, String, bool)>>; 2] {
    use bywire_core::Filter;
    use bywire_net::Filtering;
    [false, true].map(|routed| {
        let mut bus = SimBus::new(500_000, None);
        let nodes: Vec<usize> = (0..4).map(|_| bus.add_node()).collect();
        for &n in &nodes[..3] {
            bus.set_receive_own(n, true);
            if routed {
                assert!(bus.route(n));
            }
        }
        bus.set_filtering(
            nodes[2],
            Filtering {
                filters: vec![Filter::new(0x200, 0x700)],
                ..Filtering::default()
            },
        );
        // Node 1, the victim, takes every error frame: its state reports.
        bus.set_filtering(
            nodes[1],
            Filtering {
                error_mask: bywire_core::filter::ErrorMask::ALL,
                ..Filtering::default()
            },
        );
        bus.corrupt(Fault {
            node: Some(nodes[1]),
            id: None,
            count: 40,
            kind: Default::default(),
        });
        let mut heard = vec![Vec::new(); nodes.len()];
        for step in 0..400u64 {
            let at = Timestamp::from_micros(step * 250);
            bus.advance(at);
            while let Some(r) = bus.next_routed(at) {
                for (n, heard) in heard.iter_mut().enumerate() {
                    if r.to >> n & 1 == 1 {
                        let own = r.sender == Some(n);
                        heard.push((ns(r.received.timestamp), r.received.frame.to_string(), own));
                    }
                }
            }
            for (n, heard) in heard.iter_mut().enumerate() {
                while let Some(r) = bus.receive_by(n, at) {
                    heard.push((ns(r.timestamp), r.frame.to_string(), r.own));
                }
            }
            if step % 4 == 0 {
                let id = 0x100 + 0x100 * (step % 3);
                let sender = nodes[usize::try_from(step % 3).unwrap()];
                bus.submit(sender, frame(&format!("{id:03X}#{step:04X}")), at);
            }
        }
        heard
    })
}

#[test]
fn routed_nodes_get_what_their_own_queues_would_have_held() {
    let [plain, routed] = same_traffic_routed_or_not();
    assert_eq!(plain, routed);
    // The traffic reached every kind of delivery: frames, own echoes, state reports.
    let all: Vec<&(u64, String, bool)> = plain.iter().flatten().collect();
    assert!(all.iter().any(|(_, _, own)| *own));
    assert!(all.iter().any(|(_, text, _)| text.contains("#")));
    let reports: Vec<&String> = plain[1]
        .iter()
        .map(|(_, t, _)| t)
        .filter(|t| t.len() > 12)
        .collect();
    // Error passive, bus-off and restarted, each with the counters.
    for class in ["20000204", "20000240", "20000300"] {
        assert!(
            reports.iter().any(|t| t.starts_with(class)),
            "{class} in {reports:?}"
        );
    }
    // Node 2 takes 0x2xx only (and its own frames).
    assert!(plain[2]
        .iter()
        .all(|(_, text, own)| *own || text.starts_with("2") || text.len() > 12));
}

#[test]
fn routing_stops_at_max_routed_and_a_withdrawn_node_gets_nothing_queued() {
    use bywire_net::sim::MAX_ROUTED;
    let mut bus = SimBus::new(500_000, None);
    let nodes: Vec<usize> = (0..=MAX_ROUTED).map(|_| bus.add_node()).collect();
    assert!(bus.route(nodes[0]) && bus.route(nodes[1]));
    assert!(!bus.route(nodes[MAX_ROUTED]), "one bit a node");
    assert!(!bus.route(MAX_ROUTED + 5), "no such node");
    bus.submit(nodes[2], frame("123#01"), Timestamp::ZERO);
    bus.submit(nodes[2], frame("124#02"), Timestamp::ZERO);
    bus.advance(Timestamp::from_micros(100));
    // The first frame is on its way (decided), the second waits.
    assert!(bus.next_routed_arrival().is_some());
    assert_eq!(bus.next_routed(Timestamp::from_micros(100)), None);
    bus.withdraw(nodes[0]);
    bus.advance(Timestamp::from_millis(2));
    let mut got = Vec::new();
    while let Some(r) = bus.next_routed(Timestamp::from_millis(2)) {
        got.push((r.to, r.received.frame.to_string()));
    }
    // Node 0 left while the first frame was on the wire: neither frame is queued for it.
    assert_eq!(
        got,
        [(0b10, "123#01".to_string()), (0b11, "124#02".to_string())]
    );
}

#[test]
fn a_bus_of_more_than_64_nodes_delivers_to_each_filter_and_echoes_the_sender() {
    use bywire_core::Filter;
    use bywire_net::Filtering;
    let mut bus = SimBus::new(500_000, None);
    let nodes: Vec<usize> = (0..70).map(|_| bus.add_node()).collect();
    // Odd nodes take 0x100 only; node 66 sends and hears its own frames.
    for &n in nodes.iter().filter(|n| *n % 2 == 1) {
        bus.set_filtering(
            n,
            Filtering {
                filters: vec![Filter::new(0x100, 0x7FF)],
                ..Filtering::default()
            },
        );
    }
    bus.set_receive_own(66, true);
    bus.submit(66, frame("100#01"), Timestamp::ZERO);
    bus.submit(66, frame("200#02"), Timestamp::ZERO);
    bus.advance(Timestamp::from_millis(2));
    for &n in &nodes {
        let mut heard = Vec::new();
        while let Some(r) = bus.receive(n) {
            heard.push((r.frame.to_string(), r.own));
        }
        let expected: Vec<(String, bool)> = match n {
            66 => vec![("100#01".into(), true), ("200#02".into(), true)],
            n if n % 2 == 1 => vec![("100#01".into(), false)],
            _ => vec![("100#01".into(), false), ("200#02".into(), false)],
        };
        assert_eq!(heard, expected, "node {n}");
    }
}

/// A frame given to the bus: by whom, when, and its place in the order of submission.
#[derive(Debug, Clone)]
struct Submitted {
    node: usize,
    frame: Frame,
    at: u64,
    order: usize,
}

/// Identifiers that tie in their 11 base bits across formats (0x123 standard and extended
/// 0x123 << 18 | x), repeat on one node and across nodes.
fn tied_identifiers() -> impl proptest::strategy::Strategy<Value = Frame> {
    use proptest::prelude::*;
    (0usize..6, 0u8..3).prop_map(|(kind, byte)| {
        let text = match kind {
            0 => format!("123#{byte:02X}"),
            1 => format!("{:08X}#{byte:02X}", 0x123 << 18),
            2 => format!("{:08X}#{byte:02X}", 0x123 << 18 | 5),
            3 => format!("122#{byte:02X}"),
            4 => format!("{:08X}#{byte:02X}", 0x122 << 18 | 0x3_FFFF),
            _ => format!("7FF#{byte:02X}"),
        };
        frame(&text)
    })
}

proptest::proptest! {
    /// Against the rule itself, from the events alone: each frame starts as soon as the bus
    /// is idle and something is waiting, and it is the waiting frame that wins arbitration —
    /// the lowest identifier in arbitration order (a standard frame before an extended one
    /// with the same base), the earlier submitted of equal ones. Every frame goes out once.
    #[test]
    fn the_waiting_frame_first_in_arbitration_order_goes_next(
        frames in proptest::collection::vec((0usize..4, tied_identifiers(), 0u64..600_000), 1..40),
    ) {
        let mut bus = SimBus::new(500_000, None);
        let nodes: Vec<_> = (0..4).map(|_| bus.add_node()).collect();
        let mut submitted: Vec<Submitted> = frames
            .iter()
            .enumerate()
            .map(|(order, (node, frame, at))| Submitted { node: *node, frame: *frame, at: *at, order })
            .collect();
        // Submitted in time order (as nodes would), ties in the order generated.
        submitted.sort_by_key(|s| (s.at, s.order));
        for (order, s) in submitted.iter_mut().enumerate() {
            s.order = order;
            bus.advance(Timestamp::from_nanos(s.at));
            bus.submit(nodes[s.node], s.frame, Timestamp::from_nanos(s.at));
        }
        bus.advance(Timestamp::from_millis(100));
        let mut waiting = submitted.clone();
        let mut idle_from = 0;
        let mut sent = 0;
        for event in bus.take_events() {
            let BusEvent::Transmitted { node, id, start, end, .. } = event else {
                continue;
            };
            let start = ns(start);
            let ready: Vec<&Submitted> = waiting.iter().filter(|s| s.at <= start).collect();
            let first_ready = waiting.iter().map(|s| s.at).min().unwrap();
            proptest::prop_assert_eq!(start, idle_from.max(first_ready));
            let best = ready
                .iter()
                .min_by_key(|s| (s.frame.id().unwrap(), s.order))
                .unwrap();
            proptest::prop_assert_eq!((node, id), (nodes[best.node], best.frame.id().unwrap()));
            let order = best.order;
            waiting.retain(|s| s.order != order);
            idle_from = ns(end) + 3 * BIT_NS;
            sent += 1;
        }
        proptest::prop_assert_eq!(sent, submitted.len());
        proptest::prop_assert!(waiting.is_empty());
    }
}

#[test]
fn each_kind_of_corruption_starts_its_error_frame_where_that_error_is_found() {
    let f = frame("123#DEADBEEF00FF0000");
    let encoded = wire::encode(&f).unwrap();
    let start_of = |field| {
        encoded
            .spans()
            .iter()
            .find(|s| s.field == field)
            .unwrap()
            .start
    };
    let first_stuff = (0..encoded.len())
        .find(|i| encoded.is_stuff_bit(*i))
        .unwrap();
    let cases = [
        (Corruption::Crc, start_of(Field::CrcDelimiter) + 1),
        (Corruption::Bit, start_of(Field::Data) + 1),
        (Corruption::Stuff, first_stuff + 1),
    ];
    for (kind, detected) in cases {
        let mut bus = SimBus::new(500_000, None);
        let sender = bus.add_node();
        bus.add_node();
        bus.corrupt(Fault {
            node: Some(sender),
            id: None,
            count: 1,
            kind,
        });
        bus.submit(sender, f, Timestamp::ZERO);
        bus.advance(Timestamp::from_millis(10));
        let destroyed: Vec<_> = bus
            .take_events()
            .into_iter()
            .filter_map(|e| match e {
                BusEvent::Destroyed { start, end, .. } => Some(end.saturating_since(start)),
                _ => None,
            })
            .collect();
        // The error flag and delimiter: 14 bits of 2 µs after the bit where it was found.
        let bits = u64::try_from(detected).unwrap() + 14;
        assert_eq!(destroyed, vec![Duration::from_micros(2 * bits)], "{kind:?}");
    }
}

#[test]
fn a_dropped_frame_never_reaches_the_bus_and_the_others_do() {
    let mut bus = SimBus::new(500_000, None);
    let sender = bus.add_node();
    let receiver = bus.add_node();
    let id = |raw: u32| frame(&format!("{raw:03X}#00")).id().unwrap();
    bus.tamper(id(0x100), Some(Tamper::Drop));
    bus.submit(sender, frame("100#01"), Timestamp::ZERO);
    bus.submit(sender, frame("101#02"), Timestamp::ZERO);
    bus.advance(Timestamp::from_millis(10));
    let got = bus.receive(receiver).unwrap();
    assert_eq!(got.frame, frame("101#02"));
    assert!(bus.receive(receiver).is_none());
    bus.tamper(id(0x100), None);
    bus.submit(sender, frame("100#03"), Timestamp::from_millis(10));
    bus.advance(Timestamp::from_millis(20));
    assert_eq!(bus.receive(receiver).unwrap().frame, frame("100#03"));
}
