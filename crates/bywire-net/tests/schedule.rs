//! The response-time analysis (`bywire_core::schedule`) against the bit-timed bus: random
//! message sets, each message queued with random jitter and random payloads from its own
//! controller, never take longer on the simulated bus than the analysis allows. (A DBC the
//! analysis says misses its deadlines is tested against the bus in bywire-sim.)
#![allow(clippy::unwrap_used, clippy::indexing_slicing)]

use bywire_core::busload::Bitrates;
use bywire_core::frame::{ClassicFrame, Dlc, StandardId};
use bywire_core::schedule::{bit_ns, response_time, worst_frame_ns, Stream};
use bywire_core::wire::FrameShape;
use bywire_core::{Frame, Id, Timestamp};
use bywire_net::sim::{BusEvent, SimBus};
use proptest::prelude::*;

const BITRATE: u32 = 500_000;

/// One message: identifier, data length, period and jitter (µs).
#[derive(Debug, Clone)]
struct Message {
    id: u16,
    len: u8,
    period_us: u64,
    jitter_us: u64,
}

/// A small deterministic generator for jitter and payloads.
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        self.0 >> 33
    }
}

fn streams(messages: &[Message]) -> Vec<Stream> {
    let rates = Bitrates {
        nominal: BITRATE,
        data: None,
    };
    messages
        .iter()
        .map(|m| Stream {
            id: Id::Standard(StandardId::new(m.id).unwrap()),
            frame_ns: worst_frame_ns(
                FrameShape::default(),
                Dlc::new(m.len).unwrap(),
                false,
                rates,
            ),
            period_ns: m.period_us * 1_000,
            jitter_ns: m.jitter_us * 1_000,
        })
        .collect()
}

/// Each message from its own controller for `run_us`: the k-th frame queued at k·T plus a
/// random share of its jitter. The largest (end of frame − nominal release) per message, in ns.
fn simulate(messages: &[Message], run_us: u64, seed: u64) -> Vec<u64> {
    let mut bus = SimBus::new(BITRATE, None);
    let mut rng = Lcg(seed);
    let nodes: Vec<_> = messages.iter().map(|_| bus.add_node()).collect();
    let mut releases: Vec<Vec<u64>> = vec![Vec::new(); messages.len()];
    for (i, m) in messages.iter().enumerate() {
        let mut nominal = 0;
        while nominal < run_us * 1_000 {
            let jitter = if m.jitter_us == 0 {
                0
            } else {
                rng.next() % (m.jitter_us * 1_000 + 1)
            };
            let data: Vec<u8> = (0..m.len).map(|_| rng.next().to_le_bytes()[0]).collect();
            let frame = ClassicFrame::new(Id::Standard(StandardId::new(m.id).unwrap()), &data);
            bus.submit(
                nodes[i],
                Frame::Classic(frame.unwrap()),
                Timestamp::from_nanos(nominal + jitter),
            );
            releases[i].push(nominal);
            nominal += m.period_us * 1_000;
        }
    }
    // Long enough for every queued frame to go out on a bus that is not overloaded.
    bus.advance(Timestamp::from_nanos(run_us * 4_000));
    let mut sent = vec![0usize; messages.len()];
    let mut worst = vec![0u64; messages.len()];
    for event in bus.take_events() {
        if let BusEvent::Transmitted { node, end, .. } = event {
            let Some(i) = nodes.iter().position(|&n| n == node) else {
                continue;
            };
            let release = releases[i][sent[i]];
            sent[i] += 1;
            worst[i] = worst[i].max(end.as_nanos() - release);
        }
    }
    worst
}

fn message_set() -> impl Strategy<Value = Vec<Message>> {
    prop::collection::btree_map(0u16..0x800, (0u8..=8, 1u64..=20, 0u64..=1_000), 2..8).prop_map(
        |map| {
            map.into_iter()
                .map(|(id, (len, period_ms, jitter_us))| Message {
                    id,
                    len,
                    period_us: period_ms * 1_000,
                    jitter_us,
                })
                .collect()
        },
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn no_frame_takes_longer_than_its_worst_case(messages in message_set(), seed in any::<u64>()) {
        let streams = streams(&messages);
        let measured = simulate(&messages, 200_000, seed);
        for (i, worst) in measured.iter().enumerate() {
            if let Ok(bound) = response_time(&streams, i, bit_ns(BITRATE)) {
                prop_assert!(
                    *worst <= bound.worst_ns,
                    "{:?}: measured {} ns > predicted {} ns",
                    messages[i], worst, bound.worst_ns
                );
            }
        }
    }
}
