//! ISO-TP channels in simulated time: two ends exchanging directly (each frame delivered the
//! moment it is sent), timings read from the frames' times, and the failures the standard
//! names. The kernel's ISO-TP is the peer in `bywire`'s tests.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing,
    clippy::cast_possible_truncation
)]

use bywire_core::node::{Node, Port};
use core::time::Duration;

use bywire_core::{Frame, Id, Timestamp};
use bywire_diag::isotp::{Addressing, IsoTp, IsoTpConfig, IsoTpError, IsoTpEvent, StMin};
use proptest::prelude::*;

fn id(raw: u32) -> Id {
    Id::standard(raw).unwrap()
}

/// A tester on 0x7E0/0x7E8 and an ECU on 0x7E8/0x7E0 with `edit` applied to both.
fn pair(edit: impl Fn(&mut IsoTpConfig)) -> (IsoTp, IsoTp) {
    let mut a = IsoTpConfig::new(id(0x7E0), id(0x7E8));
    let mut b = IsoTpConfig::new(id(0x7E8), id(0x7E0));
    edit(&mut a);
    edit(&mut b);
    (IsoTp::new(a), IsoTp::new(b))
}

/// Every frame with its time and which end sent it (0: a, 1: b).
type Trace = Vec<(Timestamp, usize, Frame)>;

/// Run both ends until neither has anything due or `limit` passes; frames cross at once.
fn pump(a: &mut IsoTp, b: &mut IsoTp, mut now: Timestamp, limit: Duration) -> (Trace, Timestamp) {
    let end = now.saturating_add(limit);
    let mut trace = Trace::new();
    for _ in 0..1_000_000 {
        let mut sent = Vec::new();
        a.poll(now, &mut |_, f| sent.push((0, f)));
        b.poll(now, &mut |_, f| sent.push((1, f)));
        let moved = !sent.is_empty();
        for (from, frame) in sent {
            if from == 0 {
                b.on_frame(now, Port::MAIN, &frame);
            } else {
                a.on_frame(now, Port::MAIN, &frame);
            }
            trace.push((now, from, frame));
        }
        if moved {
            continue;
        }
        let Some(next) = [a.next_deadline(), b.next_deadline()]
            .into_iter()
            .flatten()
            .min()
        else {
            break;
        };
        if next > end {
            now = end;
            a.poll(now, &mut |_, _| {});
            b.poll(now, &mut |_, _| {});
            break;
        }
        now = next.max(now);
    }
    (trace, now)
}

fn events(channel: &mut IsoTp) -> Vec<IsoTpEvent> {
    core::iter::from_fn(|| channel.next_event()).collect()
}

fn message(len: usize) -> Vec<u8> {
    (0..len).map(|i| (i * 7 + 3) as u8).collect()
}

#[test]
fn single_frames_classic_and_fd() {
    let (mut a, mut b) = pair(|_| {});
    a.send(&[0x22, 0xF1, 0x90]).unwrap();
    let (trace, _) = pump(&mut a, &mut b, Timestamp::ZERO, Duration::from_secs(1));
    assert_eq!(trace.len(), 1);
    assert_eq!(trace[0].2.to_string(), "7E0#0322F190");
    assert_eq!(
        events(&mut b),
        [IsoTpEvent::Received(vec![0x22, 0xF1, 0x90])]
    );
    assert_eq!(events(&mut a), [IsoTpEvent::Sent]);
    // CAN FD: up to 62 bytes in one frame, with the escape length.
    let (mut a, mut b) = pair(|c| {
        c.fd = true;
        c.tx_dl = 64;
    });
    a.send(&message(62)).unwrap();
    let (trace, _) = pump(&mut a, &mut b, Timestamp::ZERO, Duration::from_secs(1));
    assert_eq!(trace.len(), 1);
    let data = trace[0].2.data();
    assert_eq!((data[0], data[1], data.len()), (0x00, 62, 64));
    assert_eq!(events(&mut b), [IsoTpEvent::Received(message(62))]);
}

#[test]
fn a_4095_byte_message_goes_in_585_consecutive_frames() {
    let (mut a, mut b) = pair(|_| {});
    a.send(&message(4095)).unwrap();
    let (trace, _) = pump(&mut a, &mut b, Timestamp::ZERO, Duration::from_secs(5));
    assert_eq!(events(&mut b), [IsoTpEvent::Received(message(4095))]);
    assert_eq!(events(&mut a), [IsoTpEvent::Sent]);
    // FF (6 bytes), one FC, then ceil(4089 / 7) = 585 CFs, sequence numbers 1..15, 0, 1...
    let from_a: Vec<&Frame> = trace.iter().filter(|t| t.1 == 0).map(|t| &t.2).collect();
    assert_eq!(from_a.len(), 1 + 585);
    assert_eq!(&from_a[0].data()[..2], &[0x1F, 0xFF]);
    for (i, cf) in from_a[1..].iter().enumerate() {
        assert_eq!(cf.data()[0], 0x20 | ((i + 1) % 16) as u8, "CF {i}");
    }
    // The last one carries what is left (4089 - 584 * 7 = 1 byte), unpadded.
    assert_eq!(from_a.last().unwrap().data().len(), 2);
    let flows = trace.iter().filter(|t| t.1 == 1).count();
    assert_eq!(flows, 1);
}

#[test]
fn block_size_and_stmin_are_honoured_to_the_microsecond() {
    for (st_min, gap) in [
        (StMin::Millis(5), Duration::from_millis(5)),
        (StMin::Micros(300), Duration::from_micros(300)),
    ] {
        let (mut a, mut b) = pair(|c| {
            c.block_size = 3;
            c.st_min = st_min;
        });
        a.send(&message(100)).unwrap();
        let (trace, _) = pump(&mut a, &mut b, Timestamp::ZERO, Duration::from_secs(5));
        assert_eq!(events(&mut b), [IsoTpEvent::Received(message(100))]);
        // After the FF: FC, then blocks of three CFs with `gap` between, a FC after each.
        let kinds: Vec<(u8, usize)> = trace.iter().map(|t| (t.2.data()[0] >> 4, t.1)).collect();
        let cfs = (100 - 6_usize).div_ceil(7);
        assert_eq!(cfs, 14);
        let expected_flows = 1 + (cfs - 1) / 3;
        assert_eq!(kinds.iter().filter(|k| k.0 == 3).count(), expected_flows);
        let mut last_cf: Option<Timestamp> = None;
        let mut in_block = 0;
        for (t, from, frame) in &trace {
            match frame.data()[0] >> 4 {
                3 => {
                    assert_eq!(*from, 1);
                    assert_eq!(frame.data()[1], 3, "BS");
                    assert_eq!(frame.data()[2], st_min.to_byte(), "STmin");
                    in_block = 0;
                    last_cf = None;
                }
                2 => {
                    if let Some(previous) = last_cf {
                        assert_eq!(t.saturating_since(previous), gap, "{st_min:?}");
                    }
                    in_block += 1;
                    assert!(in_block <= 3);
                    last_cf = Some(*t);
                }
                _ => {}
            }
        }
    }
}

#[test]
fn longer_than_4095_bytes_uses_the_escape_first_frame() {
    for fd in [false, true] {
        let (mut a, mut b) = pair(|c| {
            c.fd = fd;
            c.tx_dl = 64;
            c.max_message = 10_000;
        });
        a.send(&message(5000)).unwrap();
        let (trace, _) = pump(&mut a, &mut b, Timestamp::ZERO, Duration::from_secs(5));
        assert_eq!(
            events(&mut b),
            [IsoTpEvent::Received(message(5000))],
            "fd {fd}"
        );
        let ff = trace[0].2.data();
        assert_eq!(&ff[..6], &[0x10, 0x00, 0x00, 0x00, 0x13, 0x88]);
    }
}

#[test]
fn no_flow_control_is_n_timeout_bs() {
    let mut a = IsoTp::new(IsoTpConfig::new(id(0x7E0), id(0x7E8)));
    a.send(&message(20)).unwrap();
    let mut sent = Vec::new();
    a.poll(Timestamp::ZERO, &mut |_, f| sent.push(f));
    assert_eq!(sent.len(), 1);
    let deadline = a.next_deadline().unwrap();
    assert_eq!(
        deadline,
        Timestamp::ZERO.saturating_add(Duration::from_millis(1000))
    );
    a.poll(
        deadline.saturating_add(Duration::from_nanos(0)),
        &mut |_, _| {},
    );
    assert_eq!(
        events(&mut a),
        [IsoTpEvent::Failed {
            sending: true,
            error: IsoTpError::TimeoutBs
        }]
    );
    assert!(!a.sending());
}

#[test]
fn a_missing_consecutive_frame_is_n_timeout_cr() {
    let mut b = IsoTp::new(IsoTpConfig::new(id(0x7E8), id(0x7E0)));
    b.on_frame(
        Timestamp::ZERO,
        Port::MAIN,
        &"7E0#1014000102030405".parse().unwrap(),
    );
    let mut fc = Vec::new();
    b.poll(Timestamp::ZERO, &mut |_, f| fc.push(f));
    assert_eq!(fc[0].to_string(), "7E8#300000");
    let at = Timestamp::ZERO.saturating_add(Duration::from_millis(999));
    b.poll(at, &mut |_, _| {});
    assert!(events(&mut b).is_empty());
    b.poll(
        Timestamp::ZERO.saturating_add(Duration::from_millis(1000)),
        &mut |_, _| {},
    );
    assert_eq!(
        events(&mut b),
        [IsoTpEvent::Failed {
            sending: false,
            error: IsoTpError::TimeoutCr
        }]
    );
}

#[test]
fn a_consecutive_frame_out_of_sequence_is_n_wrong_sn() {
    let mut b = IsoTp::new(IsoTpConfig::new(id(0x7E8), id(0x7E0)));
    b.on_frame(
        Timestamp::ZERO,
        Port::MAIN,
        &"7E0#1014000102030405".parse().unwrap(),
    );
    b.on_frame(
        Timestamp::ZERO,
        Port::MAIN,
        &"7E0#2106070809101112".parse().unwrap(),
    );
    b.on_frame(
        Timestamp::ZERO,
        Port::MAIN,
        &"7E0#2313141516171819".parse().unwrap(),
    );
    assert_eq!(
        events(&mut b),
        [IsoTpEvent::Failed {
            sending: false,
            error: IsoTpError::WrongSequenceNumber {
                expected: 2,
                received: 3
            }
        }]
    );
}

#[test]
fn wait_frames_hold_the_sender_until_their_limit() {
    let mut cfg = IsoTpConfig::new(id(0x7E0), id(0x7E8));
    cfg.max_wait_frames = 2;
    let mut a = IsoTp::new(cfg);
    a.send(&message(20)).unwrap();
    a.poll(Timestamp::ZERO, &mut |_, _| {});
    let wait: Frame = "7E8#310000".parse().unwrap();
    for i in 1..=2u64 {
        let t = Timestamp::from_nanos(i * 500_000_000);
        a.on_frame(t, Port::MAIN, &wait);
        // Each WAIT restarts N_Bs.
        assert_eq!(
            a.next_deadline(),
            Some(t.saturating_add(Duration::from_secs(1)))
        );
    }
    a.on_frame(Timestamp::from_nanos(1_500_000_000), Port::MAIN, &wait);
    assert_eq!(
        events(&mut a),
        [IsoTpEvent::Failed {
            sending: true,
            error: IsoTpError::WaitFrameOverrun
        }]
    );
    // A flow status that is not CTS, WAIT or OVFLW.
    let mut a = IsoTp::new(IsoTpConfig::new(id(0x7E0), id(0x7E8)));
    a.send(&message(20)).unwrap();
    a.poll(Timestamp::ZERO, &mut |_, _| {});
    a.on_frame(Timestamp::ZERO, Port::MAIN, &"7E8#370000".parse().unwrap());
    assert_eq!(
        events(&mut a),
        [IsoTpEvent::Failed {
            sending: true,
            error: IsoTpError::InvalidFlowStatus(7)
        }]
    );
}

#[test]
fn a_message_beyond_the_buffer_is_refused_with_overflow() {
    let (mut a, mut b) = pair(|c| c.max_message = 100);
    a.send(&message(101)).unwrap();
    let (trace, _) = pump(&mut a, &mut b, Timestamp::ZERO, Duration::from_secs(2));
    assert_eq!(trace[1].2.to_string(), "7E8#320000");
    assert_eq!(
        events(&mut a),
        [IsoTpEvent::Failed {
            sending: true,
            error: IsoTpError::BufferOverflow
        }]
    );
    assert_eq!(
        events(&mut b),
        [IsoTpEvent::Failed {
            sending: false,
            error: IsoTpError::BufferOverflow
        }]
    );
}

#[test]
fn extended_and_mixed_addressing_put_their_byte_first() {
    let (mut a, mut b) = pair(|_| {});
    let mut ca = *a.config();
    ca.addressing = Addressing::Extended {
        target: 0x10,
        source: 0xF1,
    };
    let mut cb = *b.config();
    cb.addressing = Addressing::Extended {
        target: 0xF1,
        source: 0x10,
    };
    a = IsoTp::new(ca);
    b = IsoTp::new(cb);
    a.send(&message(20)).unwrap();
    let (trace, _) = pump(&mut a, &mut b, Timestamp::ZERO, Duration::from_secs(1));
    assert_eq!(events(&mut b), [IsoTpEvent::Received(message(20))]);
    for (_, from, frame) in &trace {
        assert_eq!(frame.data()[0], if *from == 0 { 0x10 } else { 0xF1 });
    }
    // A frame for another target is not ours.
    b.on_frame(
        Timestamp::ZERO,
        Port::MAIN,
        &"7E0#11020102".parse().unwrap(),
    );
    assert!(events(&mut b).is_empty());
    let (mut a, mut b) = pair(|c| c.addressing = Addressing::Mixed { extension: 0x42 });
    a.send(&[1, 2, 3]).unwrap();
    let (trace, _) = pump(&mut a, &mut b, Timestamp::ZERO, Duration::from_secs(1));
    assert_eq!(trace[0].2.to_string(), "7E0#4203010203");
    assert_eq!(events(&mut b), [IsoTpEvent::Received(vec![1, 2, 3])]);
}

#[test]
fn padding_fills_every_frame() {
    let (mut a, mut b) = pair(|c| c.padding = Some(0xAA));
    a.send(&[0x3E, 0x00]).unwrap();
    let (trace, _) = pump(&mut a, &mut b, Timestamp::ZERO, Duration::from_secs(1));
    assert_eq!(trace[0].2.to_string(), "7E0#023E00AAAAAAAAAA");
    assert_eq!(events(&mut b), [IsoTpEvent::Received(vec![0x3E, 0x00])]);
}

/// Received frames' padding checked as Linux's ISO-TP checks it (isotprecv's -P): a frame
/// that fails is dropped and its transfer fails with the padding error.
#[test]
fn received_padding_is_checked_for_length_and_content() {
    use bywire_diag::isotp::PaddingCheck;
    let all = PaddingCheck {
        length: true,
        content: true,
    };
    let length = PaddingCheck {
        length: true,
        content: false,
    };
    // (sender's padding, receiver's expected byte, check, accepted)
    for (tx, rx, check, accepted) in [
        (Some(0xAA), Some(0xAA), all, true),
        (Some(0xCC), Some(0xAA), all, false),
        (Some(0xCC), Some(0xAA), length, true),
        (None, Some(0xAA), length, false),
        (None, None, length, true),
        (Some(0xAA), None, length, false),
        (None, Some(0xAA), PaddingCheck::default(), true),
    ] {
        // A single frame, and a transfer whose last consecutive frame is padded.
        for len in [3, 19] {
            let mut a = IsoTpConfig::new(id(0x7E0), id(0x7E8));
            let mut b = IsoTpConfig::new(id(0x7E8), id(0x7E0));
            a.padding = tx;
            b.padding = Some(0xAA);
            b.rx_padding = rx;
            b.rx_padding_check = check;
            a.rx_padding = Some(0xAA);
            a.rx_padding_check = all;
            let (mut a, mut b) = (IsoTp::new(a), IsoTp::new(b));
            a.send(&message(len)).unwrap();
            pump(&mut a, &mut b, Timestamp::ZERO, Duration::from_secs(2));
            let got = events(&mut b);
            let case = format!("{tx:?} {rx:?} {check:?}, {len} bytes");
            if accepted {
                assert_eq!(got, [IsoTpEvent::Received(message(len))], "{case}");
            } else {
                assert!(
                    got.contains(&IsoTpEvent::Failed {
                        sending: false,
                        error: IsoTpError::Padding
                    }),
                    "{case}: {got:?}"
                );
                assert!(
                    !got.iter().any(|e| matches!(e, IsoTpEvent::Received(_))),
                    "{case}"
                );
            }
        }
    }
    // A sender checking the flow control's padding gives up on a bad one.
    let (a, mut b) = pair(|c| c.padding = Some(0xCC));
    let mut strict = *a.config();
    strict.rx_padding = Some(0xAA);
    strict.rx_padding_check = all;
    let mut a = IsoTp::new(strict);
    a.send(&message(20)).unwrap();
    pump(&mut a, &mut b, Timestamp::ZERO, Duration::from_secs(2));
    assert!(events(&mut a).contains(&IsoTpEvent::Failed {
        sending: true,
        error: IsoTpError::Padding
    }));
}

/// isotpsend's -t: the frame time is added to the separation the receiver asks for.
#[test]
fn the_frame_gap_adds_to_st_min() {
    let (a, mut b) = pair(|c| c.st_min = StMin::Millis(1));
    let mut config = *a.config();
    config.frame_gap = Duration::from_micros(250);
    let mut a = IsoTp::new(config);
    a.send(&message(40)).unwrap();
    let (trace, _) = pump(&mut a, &mut b, Timestamp::ZERO, Duration::from_secs(1));
    assert_eq!(events(&mut b), [IsoTpEvent::Received(message(40))]);
    let cfs: Vec<Timestamp> = trace
        .iter()
        .filter(|t| t.2.data()[0] >> 4 == 2)
        .map(|t| t.0)
        .collect();
    assert_eq!(cfs.len(), 5);
    for pair in cfs.windows(2) {
        assert_eq!(
            pair[1].saturating_since(pair[0]),
            Duration::from_micros(1250)
        );
    }
}

#[test]
fn normal_fixed_addressing_names_29_bit_identifiers() {
    let (tx, rx) = Addressing::normal_fixed(0x10, 0xF1, false);
    assert_eq!((tx.as_raw(), rx.as_raw()), (0x18DA_10F1, 0x18DA_F110));
    let (tx, _) = Addressing::normal_fixed(0x33, 0xF1, true);
    assert_eq!(tx.as_raw(), 0x18DB_33F1);
}

#[test]
fn st_min_codes_follow_the_standard() {
    assert_eq!(StMin::from_byte(0x7F), StMin::Millis(127));
    assert_eq!(StMin::from_byte(0xF1), StMin::Micros(100));
    assert_eq!(StMin::from_byte(0xF9), StMin::Micros(900));
    // Reserved codes are taken as 127 ms.
    for reserved in [0x80, 0xF0, 0xFA, 0xFF] {
        assert_eq!(
            StMin::from_byte(reserved).duration(),
            Duration::from_millis(127)
        );
    }
    assert_eq!(StMin::Micros(300).to_byte(), 0xF3);
}

proptest! {
    /// Whatever arrives, nothing panics and nothing is received beyond the buffer.
    #[test]
    fn any_frames_are_taken_without_a_panic(frames in prop::collection::vec(
        (any::<bool>(), prop::collection::vec(any::<u8>(), 0..=64)), 0..40)) {
        let mut cfg = IsoTpConfig::new(id(0x7E8), id(0x7E0));
        cfg.max_message = 300;
        let mut b = IsoTp::new(cfg);
        let mut now = Timestamp::ZERO;
        for (fd, data) in frames {
            let frame = if fd {
                Frame::fd(id(0x7E0), &data, true, false)
            } else {
                Frame::classic(id(0x7E0), &data[..data.len().min(8)])
            };
            if let Ok(frame) = frame {
                b.on_frame(now, Port::MAIN, &frame);
            }
            b.poll(now, &mut |_, _| {});
            now = now.saturating_add(Duration::from_millis(3));
            while let Some(event) = b.next_event() {
                if let IsoTpEvent::Received(m) = event {
                    prop_assert!(!m.is_empty() && m.len() <= 300);
                }
            }
        }
    }

    /// Any message of any length arrives whole, in any frame format and flow control.
    #[test]
    fn any_message_arrives_whole(len in 1usize..3000, fd in any::<bool>(), bs in 0u8..5,
                                 st in 0u8..3, pad in any::<bool>()) {
        let (mut a, mut b) = pair(|c| {
            c.fd = fd;
            c.tx_dl = 32;
            c.block_size = bs;
            c.st_min = StMin::Millis(st);
            c.padding = pad.then_some(0x55);
        });
        a.send(&message(len)).unwrap();
        let _ = pump(&mut a, &mut b, Timestamp::ZERO, Duration::from_secs(60));
        prop_assert_eq!(events(&mut b), vec![IsoTpEvent::Received(message(len))]);
        prop_assert_eq!(events(&mut a), vec![IsoTpEvent::Sent]);
    }
}

/// Throughput on a bit-timed 1 Mbit/s bus with BS 0 and STmin 0: the transfer takes no more
/// than 5 % over the time its frames occupy the wire (each frame's exact stuffed length and
/// interframe space), classic and padded, and CAN FD at 1/4 Mbit/s; with each frame waiting
/// for its confirmation too (the next is handed over at the end of the one before, in time
/// for the bus to start it after the interframe space).
#[test]
fn throughput_is_within_5_percent_of_the_wire() {
    use bywire_core::busload::{frame_time_ns, Bitrates};
    use bywire_net::network::Network;
    for (fd, data, confirmed) in [
        (false, None, false),
        (true, Some(4_000_000), false),
        (false, None, true),
        (true, Some(4_000_000), true),
    ] {
        let mut net = Network::new();
        let bus = net.add_bus("can0", 1_000_000, data);
        let (mut a, b) = pair(|c| {
            c.padding = Some(0xCC);
            c.fd = fd;
            c.brs = fd;
            c.tx_dl = 64;
            if confirmed {
                *c = c.confirmed(Duration::from_millis(100));
            }
        });
        a.send(&message(4095)).unwrap();
        let (a, b) = (net.add_node(a), net.add_node(b));
        net.wire(a, Port::MAIN, bus).unwrap();
        net.wire(b, Port::MAIN, bus).unwrap();
        let tap = net.tap(bus).unwrap();
        let mut frames = Vec::new();
        let mut received_at = None;
        for _ in 0..20_000 {
            let until = net.now().saturating_add(Duration::from_micros(200));
            net.run_until(until);
            while let Some(r) = net.bus_mut(bus).and_then(|s| s.receive(tap)) {
                frames.push(r);
            }
            let event = net.node_mut(b).unwrap().next_event();
            if let Some(IsoTpEvent::Received(m)) = event {
                assert_eq!(m, message(4095));
                received_at = frames.last().map(|r| r.timestamp);
                break;
            }
        }
        let end = received_at.expect("the message arrived");
        let rates = Bitrates {
            nominal: 1_000_000,
            data,
        };
        let wire_ns: f64 = frames.iter().map(|r| frame_time_ns(&r.frame, rates)).sum();
        // From the start of the first frame (its end less its own time) to the end of the last.
        let first = &frames[0];
        let start_ns = first.timestamp.as_nanos() as f64 - frame_time_ns(&first.frame, rates);
        let took_ns = end.as_nanos() as f64 - start_ns;
        let ratio = wire_ns / took_ns;
        println!(
            "ISO-TP 4095 bytes, {}{}: {} frames, {:.3} ms on the wire, {:.3} ms taken ({:.1} %)",
            if fd {
                "CAN FD 1/4 Mbit/s"
            } else {
                "classic 1 Mbit/s"
            },
            if confirmed { ", confirmed" } else { "" },
            frames.len(),
            wire_ns / 1e6,
            took_ns / 1e6,
            ratio * 100.0
        );
        assert!(ratio >= 0.95, "{ratio}");
    }
}

/// Two channels on a bit-timed 500 kbit/s bus, confirmed by the simulated runner.
mod confirmed {
    use super::*;
    use bywire_core::busload::{frame_time_ns, Bitrates};
    use bywire_net::network::{Network, NodeHandle, NodeMut};

    const N_A: Duration = Duration::from_millis(50);

    struct Bench {
        net: Network,
        tap: bywire_net::sim::NodeId,
        bus: usize,
        ends: [NodeHandle<IsoTp>; 2],
        /// Every frame on the wire, with its end of frame.
        wire: Vec<(Timestamp, Frame)>,
        /// Each end's events with the time they were seen (within 100 µs).
        events: [Vec<(Timestamp, IsoTpEvent)>; 2],
    }

    impl Bench {
        fn new(edit: impl Fn(&mut IsoTpConfig)) -> Bench {
            let mut net = Network::new();
            let bus = net.add_bus("can0", 500_000, None);
            let (a, b) = pair(|c| {
                *c = c.confirmed(N_A);
                edit(c);
            });
            let ends = [net.add_node(a), net.add_node(b)];
            for end in ends {
                net.wire(end, Port::MAIN, bus).unwrap();
            }
            let tap = net.tap(bus).unwrap();
            Bench {
                net,
                tap,
                bus,
                ends,
                wire: Vec::new(),
                events: [Vec::new(), Vec::new()],
            }
        }

        fn run_for(&mut self, duration: Duration) {
            let end = self.net.now().saturating_add(duration);
            while self.net.now() < end {
                let until = self.net.now().saturating_add(Duration::from_micros(100));
                self.net.run_until(until);
                let now = self.net.now();
                while let Some(r) = self.net.bus_mut(self.bus).and_then(|s| s.receive(self.tap)) {
                    self.wire.push((r.timestamp, r.frame));
                }
                for (end, events) in self.ends.into_iter().zip(&mut self.events) {
                    let mut channel = self.net.node_mut(end).unwrap();
                    while let Some(event) = channel.next_event() {
                        events.push((now, event));
                    }
                }
            }
        }

        /// The sending end.
        fn a(&mut self) -> NodeMut<'_, IsoTp> {
            self.net.node_mut(self.ends[0]).unwrap()
        }

        fn failure(&self, end: usize) -> Option<(Timestamp, bool, IsoTpError)> {
            self.events[end].iter().find_map(|(at, e)| match e {
                IsoTpEvent::Failed { sending, error } => Some((*at, *sending, *error)),
                _ => None,
            })
        }
    }

    /// A sender whose frames never reach the bus (its controller silenced) gives up after N_As
    /// with N_TIMEOUT_A, not after N_Bs: nothing it sent was ever on the wire.
    #[test]
    fn a_frame_never_confirmed_is_n_timeout_a_after_n_as() {
        let mut bench = Bench::new(|c| c.n_bs = Duration::from_millis(500));
        bench.net.drop_output(bench.ends[0], true);
        bench.a().send(&message(100)).unwrap();
        bench.run_for(Duration::from_millis(45));
        assert_eq!(bench.failure(0), None, "not before N_As");
        assert!(bench.a().sending());
        bench.run_for(Duration::from_millis(15));
        let (at, sending, error) = bench.failure(0).expect("N_As ran out");
        assert_eq!((sending, error), (true, IsoTpError::TimeoutA));
        assert!(at >= Timestamp::ZERO.saturating_add(N_A), "{at:?}");
        assert!(!bench.a().sending());
        assert!(bench.wire.is_empty());
        assert!(bench.events[1].is_empty(), "{:?}", bench.events[1]);
    }

    /// A receiver whose flow control is never confirmed gives up after N_Ar (N_TIMEOUT_A, on
    /// its receiving side); the sender, which never got the flow control, after N_Bs.
    #[test]
    fn a_flow_control_never_confirmed_is_n_timeout_a_after_n_ar() {
        let mut bench = Bench::new(|c| c.n_bs = Duration::from_millis(200));
        bench.net.drop_port_output(bench.ends[1], Port::MAIN, true);
        bench.a().send(&message(100)).unwrap();
        bench.run_for(Duration::from_millis(250));
        let first_frame_end = bench.wire.first().map(|(at, _)| *at).unwrap();
        assert_eq!(bench.wire.len(), 1, "only the first frame is on the wire");
        let (at, sending, error) = bench.failure(1).expect("N_Ar ran out");
        assert_eq!((sending, error), (false, IsoTpError::TimeoutA));
        let waited = at.saturating_since(first_frame_end);
        assert!(
            waited >= N_A && waited < N_A + Duration::from_millis(1),
            "{waited:?}"
        );
        let (at, sending, error) = bench.failure(0).expect("N_Bs ran out");
        assert_eq!((sending, error), (true, IsoTpError::TimeoutBs));
        // N_Bs counts from the first frame's confirmation, its end of frame.
        let waited = at.saturating_since(first_frame_end);
        assert!(
            waited >= Duration::from_millis(200) && waited < Duration::from_millis(201),
            "{waited:?}"
        );
    }

    /// With confirmations a message is sent when its last frame is on the wire, each
    /// consecutive frame waits STmin after the end of the one before (ISO 15765-2's timing
    /// diagram), and the message arrives whole.
    #[test]
    fn sent_comes_with_the_last_frame_and_st_min_runs_from_the_end_of_frame() {
        let mut bench = Bench::new(|c| c.st_min = StMin::Micros(300));
        bench.a().send(&message(300)).unwrap();
        bench.run_for(Duration::from_millis(50));
        let received = bench.events[1].iter().find_map(|(_, e)| match e {
            IsoTpEvent::Received(m) => Some(m.clone()),
            _ => None,
        });
        assert_eq!(received, Some(message(300)));
        let data: Vec<_> = bench
            .wire
            .iter()
            .filter(|(_, f)| f.id() == Some(id(0x7E0)))
            .collect();
        assert_eq!(data.len(), 1 + 300_usize.saturating_sub(6).div_ceil(7));
        let rates = Bitrates {
            nominal: 500_000,
            data: None,
        };
        // Consecutive frames only (the first after the flow control).
        for pair in data[1..].windows(2) {
            let (end_before, _) = pair[0];
            let (end, frame) = pair[1];
            // The frame's time counts its interframe space (3 bits, 6 µs) after it.
            let start = end.as_nanos() as f64 - frame_time_ns(frame, rates) + 6_000.0;
            let gap = start - end_before.as_nanos() as f64;
            assert!(
                (300_000.0..310_000.0).contains(&gap),
                "{gap} ns between consecutive frames"
            );
        }
        let last_end = data.last().unwrap().0;
        let sent_at = bench.events[0]
            .iter()
            .find_map(|(at, e)| (*e == IsoTpEvent::Sent).then_some(*at))
            .expect("sent");
        assert!(sent_at >= last_end, "{sent_at:?} before {last_end:?}");
        assert!(bench.failure(0).is_none() && bench.failure(1).is_none());
    }
}
