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
                b.on_frame(now, &frame);
            } else {
                a.on_frame(now, &frame);
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
    b.on_frame(Timestamp::ZERO, &"7E0#1014000102030405".parse().unwrap());
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
    b.on_frame(Timestamp::ZERO, &"7E0#1014000102030405".parse().unwrap());
    b.on_frame(Timestamp::ZERO, &"7E0#2106070809101112".parse().unwrap());
    b.on_frame(Timestamp::ZERO, &"7E0#2313141516171819".parse().unwrap());
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
        a.on_frame(t, &wait);
        // Each WAIT restarts N_Bs.
        assert_eq!(
            a.next_deadline(),
            Some(t.saturating_add(Duration::from_secs(1)))
        );
    }
    a.on_frame(Timestamp::from_nanos(1_500_000_000), &wait);
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
    a.on_frame(Timestamp::ZERO, &"7E8#370000".parse().unwrap());
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
    b.on_frame(Timestamp::ZERO, &"7E0#11020102".parse().unwrap());
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
                b.on_frame(now, &frame);
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
/// interframe space), classic and padded, and CAN FD at 1/4 Mbit/s.
#[test]
fn throughput_is_within_5_percent_of_the_wire() {
    use bywire_bus::network::Network;
    use bywire_core::busload::{frame_time_ns, Bitrates};
    use bywire_core::node::{Node, Port};
    for (fd, data) in [(false, None), (true, Some(4_000_000))] {
        let mut net = Network::new();
        let bus = net.add_bus("can0", 1_000_000, data);
        net.wire(0, Port::MAIN, bus);
        net.wire(1, Port::MAIN, bus);
        let tap = net.tap(bus).unwrap();
        let (mut a, mut b) = pair(|c| {
            c.padding = Some(0xCC);
            c.fd = fd;
            c.brs = fd;
            c.tx_dl = 64;
        });
        a.send(&message(4095)).unwrap();
        let mut frames = Vec::new();
        let mut received_at = None;
        for _ in 0..20_000 {
            net.changed(0);
            let until = net.now().saturating_add(Duration::from_micros(200));
            net.run_until(until, &mut [&mut a as &mut dyn Node, &mut b]);
            while let Some(r) = net.bus_mut(bus).and_then(|s| s.receive(tap)) {
                frames.push(r);
            }
            if let Some(IsoTpEvent::Received(m)) = b.next_event() {
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
            "ISO-TP 4095 bytes, {}: {} frames, {:.3} ms on the wire, {:.3} ms taken ({:.1} %)",
            if fd {
                "CAN FD 1/4 Mbit/s"
            } else {
                "classic 1 Mbit/s"
            },
            frames.len(),
            wire_ns / 1e6,
            took_ns / 1e6,
            ratio * 100.0
        );
        assert!(ratio >= 0.95, "{ratio}");
    }
}
