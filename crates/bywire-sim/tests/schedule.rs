//! The worst-case response times the tug's DBCs predict (`bywire_dbc::schedule`) bound what
//! its buses really take: on every bus, each message's longest time from being queued to the
//! end of its frame over a run stays within its predicted worst case less its queuing jitter
//! (the simulator measures from the queuing, the analysis from the nominal release). And a
//! deliberately overloaded DBC misses on the bit-timed bus exactly where the analysis says.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use std::time::Duration;

use bywire_core::busload::Bitrates;
use bywire_core::frame::ClassicFrame;
use bywire_core::{Frame, Id, Timestamp};
use bywire_dbc::schedule::{analyse, Options, Schedule};
use bywire_dbc::{parse, Database, Message, Mode};
use bywire_net::sim::{BusEvent, SimBus};
use bywire_sim::record::ResponseTimes;
use bywire_sim::tug::{Tug, TugParams};

fn database(text: &str) -> Database {
    parse(text.as_bytes(), Mode::Lenient).unwrap().0
}

fn schedule(db: &Database, bitrate: u32, on_bus: impl Fn(&Message) -> bool) -> Schedule {
    analyse(
        db,
        on_bus,
        Options {
            rates: Bitrates {
                nominal: bitrate,
                data: None,
            },
            jitter: Duration::ZERO,
        },
    )
}

fn check(bus: &str, schedule: &Schedule, measured: &[ResponseTimes]) {
    assert!(
        schedule.misses().next().is_none(),
        "{bus}: the tug's own schedule misses a deadline"
    );
    for seen in measured {
        let Some(message) = schedule.messages.iter().find(|m| m.id == seen.id) else {
            // Only what the DBC leaves out may be sent unanalysed.
            let raw = seen.id.as_raw();
            assert!(
                schedule.skipped.iter().any(|s| s.raw_id == raw),
                "{bus}: 0x{raw:X} is on the bus but not in its DBC"
            );
            continue;
        };
        let bound = message.outcome.unwrap().worst_ns - message.jitter_ns;
        assert!(
            seen.max_ns <= bound,
            "{bus}: {} took {} ns, predicted at most {bound} ns",
            message.name,
            seen.max_ns
        );
        assert!(seen.count > 0);
    }
}

/// Thirty seconds of the apron loop on the plain or the redundant tug: each bus's measured
/// response times within the analysis of its DBC, and no deadline missed in the analysis.
fn every_bus_stays_within_its_predicted_worst_case_on(redundant: bool) {
    let mut tug = Tug::new(TugParams {
        redundant,
        ..TugParams::default()
    })
    .unwrap();
    while tug.now().as_nanos() < 30_000_000_000 {
        tug.step();
    }
    let buses = tug.response_times();
    let vehicle = database(bywire_tug::messages::DBC);
    let drives = database(bywire_tug::DRIVES_DBC);
    let sent_by =
        |nodes: &'static [&'static str]| move |m: &Message| nodes.contains(&m.transmitter.as_str());
    let bus1 = schedule(&vehicle, 500_000, sent_by(&["ADS", "VCU", "BMS", "SAFETY"]));
    let bus1b = schedule(&vehicle, 500_000, |m| m.name == "AdsToVehicle_Control");
    let sensors: &'static [&'static str] = if redundant {
        &["IMU", "IO", "ANGLE_B", "ANGLE_C"]
    } else {
        &["IMU", "IO"]
    };
    let bus3 = schedule(&vehicle, 500_000, sent_by(sensors));
    // The redundant tug's backup valve drivers (SteerB1..4) are not on the plain tug's bus.
    let bus2 = schedule(&drives, 1_000_000, |m| {
        redundant || !m.name.contains("SteerB")
    });
    for ((name, measured), schedule) in buses.iter().zip([&bus1, &bus2, &bus3, &bus1b]) {
        assert!(!measured.is_empty(), "{name} carried nothing");
        check(name, schedule, measured);
    }
    // The drives bus's busiest messages were all seen and bounded.
    let (_, bus2_seen) = buses[1];
    let expected = if redundant { 55 } else { 40 };
    assert!(bus2_seen.len() >= expected, "{}", bus2_seen.len());
}

#[test]
fn every_bus_stays_within_its_predicted_worst_case() {
    every_bus_stays_within_its_predicted_worst_case_on(false);
}

/// Twelve nodes on the drives bus: the analysis of the whole drives DBC holds with a margin.
#[test]
fn the_redundant_tugs_buses_stay_within_their_predicted_worst_case() {
    every_bus_stays_within_its_predicted_worst_case_on(true);
    let drives = database(bywire_tug::DRIVES_DBC);
    let bus2 = schedule(&drives, 1_000_000, |_| true);
    assert!(bus2.utilisation < 70.0, "{} %", bus2.utilisation);
}

/// Eleven 8-byte messages every 3 ms at 500 kbit/s (98 % of the bus), each queued up to 0.3 ms
/// late.
fn overloaded_dbc() -> String {
    let mut text = String::from(
        "BA_DEF_ BO_ \"GenMsgCycleTime\" INT 0 65535;\nBA_DEF_ BO_ \"GenMsgJitter\" INT 0 65535;\n",
    );
    for i in 0..11 {
        let id = 0x100 + i;
        text.push_str(&format!(
            "BO_ {id} M{i}: 8 N\n SG_ S : 0|8@1+ (1,0) [0|255] \"\" N\nBA_ \"GenMsgCycleTime\" BO_ {id} 3;\nBA_ \"GenMsgJitter\" BO_ {id} 0.3;\n"
        ));
    }
    text
}

/// The worst case the analysis assumes, built on the bus for message `index`: the next lower
/// message's frame has just started, then `index` (as late as its jitter allows) and every
/// higher message are queued together. Payloads of 0x3C: after the DLC's last zeros they stuff a
/// bit every four data bits, within a few bits of the longest frame.
/// Returns the response time from `index`'s nominal release.
fn critical_instant(schedule: &Schedule, index: usize) -> u64 {
    let mut bus = SimBus::new(500_000, None);
    let frame = |id: Id| Frame::Classic(ClassicFrame::new(id, &[0x3C; 8]).unwrap());
    let mut target = None;
    if let Some(lower) = schedule.messages.get(index + 1) {
        let node = bus.add_node();
        bus.submit(node, frame(lower.id), Timestamp::ZERO);
    }
    for (i, message) in schedule.messages.iter().enumerate().take(index + 1) {
        let node = bus.add_node();
        bus.submit(node, frame(message.id), Timestamp::from_nanos(1));
        if i == index {
            target = Some(node);
        }
    }
    bus.advance(Timestamp::from_millis(20));
    let end = bus
        .take_events()
        .into_iter()
        .find_map(|event| match event {
            BusEvent::Transmitted { node, end, .. } if Some(node) == target => Some(end),
            _ => None,
        })
        .unwrap();
    // Queued at 1 ns, `jitter` after its nominal release.
    end.as_nanos() - 1 + schedule.messages[index].jitter_ns
}

#[test]
fn an_overloaded_dbc_misses_where_the_analysis_says() {
    let db = database(&overloaded_dbc());
    let schedule = schedule(&db, 500_000, |_| true);
    let predicted: Vec<&str> = schedule.misses().map(|m| m.name.as_str()).collect();
    assert_eq!(predicted, ["M9", "M10"]);
    for (index, message) in schedule.messages.iter().enumerate() {
        let response = critical_instant(&schedule, index);
        let bound = message.outcome.unwrap().worst_ns;
        assert!(response <= bound, "{}: {response} > {bound}", message.name);
        assert_eq!(
            response > message.deadline_ns,
            !message.meets_deadline(),
            "{}: {response} ns against a {} ns deadline, predicted {bound} ns",
            message.name,
            message.deadline_ns
        );
    }
}
