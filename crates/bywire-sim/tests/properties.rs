//! Scenario files come from users: text of any shape is read or refused without a panic, and
//! any scenario that is accepted — odd routes, speeds, stops, manoeuvres and faults at any
//! time — runs without a panic.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use bywire_sim::scenario::Scenario;
use bywire_sim::tug::Tug;
use proptest::prelude::*;

/// A line of a scenario file, more often right than wrong.
fn line() -> impl Strategy<Value = String> {
    prop_oneof![
        "(name|route|speed|crab_final_m|tank_turn_deg|payload|grade) = (-?[0-9]{1,4}(\\.[0-9]{1,3})?|\"[a-z-]{0,12}\"|nan|inf)",
        "(waypoints|speeds|stops|steering_steps) = \\[(\\[-?[0-9]{1,3}(\\.5)?, ?-?[0-9]{1,3}\\],? ?){0,4}\\]",
        "steering_steps = \\[(-?[0-9]{1,3}, ?){0,4}\\]",
        Just("[[event]]".to_string()),
        "(at_s|duration_s|value|delay_ms|node|corner|id) = -?(0x)?[0-9]{1,5}(\\.[0-9])?",
        "fault = \"(ads_silence|estop|operator_reset|drive_silence|sensor_fault|corrupt_commands|duplicate_commands|delay_commands|driver_takeover|ecu_bus_off|bus_off|redundant_bus_loss|corrupt_frames|duplicate_frames|delay_frames|nonsense)\"",
        "(bus|sensor) = \"(bus1|bus2|bus3|bus1b|bus9|stuck|drift|open|x)\"",
        "[ -~]{0,30}",
    ]
}

/// A scenario file the parser accepts: a route of 2–5 points (repeated points, reversals and
/// very short legs included), the manoeuvres, and faults at any time.
fn accepted_text() -> impl Strategy<Value = String> {
    let point = (-60i32..60, -60i32..60);
    let fault = prop_oneof![
        Just("fault = \"ads_silence\"".to_string()),
        Just("fault = \"estop\"".to_string()),
        Just("fault = \"operator_reset\"".to_string()),
        (0usize..8).prop_map(|i| format!(
            "fault = \"drive_silence\"\nnode = {}",
            [0x11, 0x12, 0x13, 0x14, 0x21, 0x22, 0x23, 0x24][i]
        )),
        (0usize..4, 0usize..3, -90.0f64..90.0).prop_map(|(c, s, v)| format!(
            "fault = \"sensor_fault\"\ncorner = {c}\nsensor = \"{}\"\nvalue = {v}",
            ["stuck", "drift", "open"][s]
        )),
        Just("fault = \"corrupt_commands\"".to_string()),
        Just("fault = \"duplicate_commands\"".to_string()),
        (0u64..500).prop_map(|ms| format!("fault = \"delay_commands\"\ndelay_ms = {ms}")),
        Just("fault = \"driver_takeover\"".to_string()),
        Just("fault = \"ecu_bus_off\"".to_string()),
        Just("fault = \"redundant_bus_loss\"".to_string()),
        (0usize..4, 0u16..0x800, 0usize..4, 0u64..500).prop_map(|(b, id, kind, ms)| format!(
            "fault = \"{}\"\nbus = \"{}\"\nid = {id}\ndelay_ms = {ms}",
            [
                "corrupt_frames",
                "duplicate_frames",
                "delay_frames",
                "bus_off"
            ][kind],
            ["bus1", "bus2", "bus3", "bus1b"][b]
        )),
    ];
    let event = (0.0f64..4.0, proptest::option::of(0.0f64..2.0), fault).prop_map(
        |(at, duration, fault)| {
            let duration = duration.map_or(String::new(), |d| format!("duration_s = {d}\n"));
            format!("[[event]]\nat_s = {at}\n{duration}{fault}\n")
        },
    );
    (
        proptest::collection::vec(point, 2..5),
        0.1f64..5.0,
        proptest::collection::vec((0.0f64..1.0, 0.1f64..5.0), 0..3),
        proptest::collection::vec((0.0f64..1.0, 0.1f64..3.0), 0..3),
        0.0f64..30.0,
        -360.0f64..360.0,
        proptest::collection::vec(-40.0f64..40.0, 0..3),
        0.0f64..4500.0,
        -0.1f64..0.1,
        proptest::collection::vec(event, 0..5),
    )
        .prop_map(
            |(points, speed, speeds, stops, crab, tank, steps, payload, grade, events)| {
                let points: Vec<(f64, f64)> = points
                    .iter()
                    .map(|(x, y)| (f64::from(*x), f64::from(*y)))
                    .collect();
                let length: f64 = points
                    .windows(2)
                    .map(|w| (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1))
                    .sum();
                // Along the route: fractions of its length, in order, each after the last.
                let along = |pairs: &[(f64, f64)]| {
                    let mut pairs: Vec<(f64, f64)> =
                        pairs.iter().map(|(f, v)| (f * length, *v)).collect();
                    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
                    pairs.dedup_by(|a, b| a.0 <= b.0);
                    pairs
                };
                let pairs = |v: &[(f64, f64)]| {
                    v.iter()
                        .map(|(a, b)| format!("[{a}, {b}]"))
                        .collect::<Vec<_>>()
                        .join(", ")
                };
                let steps: Vec<String> = steps.iter().map(f64::to_string).collect();
                format!(
                    "waypoints = [{}]\nspeed = {speed}\nspeeds = [{}]\nstops = [{}]\n\
                     crab_final_m = {crab}\ntank_turn_deg = {tank}\nsteering_steps = [{}]\n\
                     payload = {payload}\ngrade = {grade}\n\n{}",
                    pairs(&points),
                    pairs(&along(&speeds)),
                    pairs(&along(&stops)),
                    steps.join(", "),
                    events.concat()
                )
            },
        )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    #[test]
    fn scenario_text_of_any_shape_is_read_or_refused(lines in proptest::collection::vec(line(), 0..25)) {
        let text = lines.join("\n");
        if let Err(e) = Scenario::parse(&text, "any.toml") {
            prop_assert!(e.to_string().starts_with("any.toml"), "{}", e);
        }
    }
}

proptest! {
    // Each case drives a tug for a few simulated seconds: fewer cases.
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn accepted_scenarios_run_without_panic(text in accepted_text(), seed in 0u64..1000) {
        let scenario = Scenario::parse(&text, "generated.toml");
        prop_assert!(scenario.is_ok(), "{:?}\n{}", scenario.err(), text);
        let scenario = scenario.unwrap();
        let mut tug = Tug::new(scenario.params(seed, scenario.tug.payload)).unwrap();
        for _ in 0..8_000 {
            scenario.step(&mut tug);
        }
        let pose = tug.pose();
        prop_assert!(pose.x.is_finite() && pose.y.is_finite() && pose.yaw.is_finite(), "{:?}", pose);
        prop_assert!(tug.bus_loads().iter().all(|l| (0.0..=1.0).contains(l)));
    }
}
