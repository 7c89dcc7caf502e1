//! Latency from an Autoware `Control` sample published on DDS to its last CAN frame (0x102) on
//! a virtual bus, through `control_output` (RustDDS on both ends, over loopback). Criterion
//! gives the mean and spread; the p50 and p99 of every sample measured are printed at the end.
//!
//! DDS discovery is multicast: the bench re-runs itself inside `../shared/tools/lonet.sh`.
#![allow(
    missing_docs,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing
)]

use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use bywire_core::Frame;
use bywire_ros::control_output::{self, ControlOutputConfig};
use bywire_ros::dds::{reliable, RosNode, RosOptions};
use bywire_ros::msg::Control;
use criterion::Criterion;

const MARKER: &str = "BYWIRE_IN_LONET";

fn node(name: &str) -> RosNode {
    let mut options = RosOptions::new(name);
    options.interfaces = vec!["lo".into()];
    RosNode::open(&options).unwrap()
}

fn is_last_frame(frame: &Frame) -> bool {
    frame.id().is_some_and(|id| id.as_raw() == 0x102)
}

fn bench(c: &mut Criterion) {
    let bus_name = "virtual:control-latency";
    let stop = Arc::new(AtomicBool::new(false));
    let output_stop = Arc::clone(&stop);
    let output = std::thread::spawn(move || {
        let mut node = node("control_output");
        let bus = bywire_bus::open(bus_name).unwrap();
        control_output::run(
            &mut node,
            bus,
            &ControlOutputConfig::default(),
            &output_stop,
            &mut |_, _| {},
        )
        .unwrap();
    });
    let mut bus = bywire_bus::open(bus_name).unwrap();
    let mut publisher_node = node("controller");
    let publisher = publisher_node
        .publisher::<Control>(control_output::INPUT_TOPIC, &reliable(1))
        .unwrap();
    // Until discovery has matched the two, samples go nowhere.
    let mut matched = false;
    for _ in 0..400 {
        publisher
            .publish(control_output::control(0.1, 0.0, 1.0, 0.0, 1))
            .unwrap();
        if let Ok(Some(r)) = bus.recv(Some(Duration::from_millis(25))) {
            if is_last_frame(&r.frame) {
                matched = true;
                break;
            }
        }
    }
    assert!(matched, "the control output never answered");
    while bus
        .recv(Some(Duration::from_millis(100)))
        .unwrap()
        .is_some()
    {}

    let samples = Arc::new(Mutex::new(Vec::<Duration>::new()));
    let mut velocity = 0.0f32;
    c.bench_function("control_cmd sample to its CAN frames (virtual bus)", |b| {
        b.iter_custom(|iterations| {
            let mut total = Duration::ZERO;
            for _ in 0..iterations {
                velocity = (velocity + 0.001) % 10.0;
                let sent = Instant::now();
                publisher
                    .publish(control_output::control(0.1, 0.0, velocity, 0.0, 1))
                    .unwrap();
                loop {
                    let r = bus
                        .recv(Some(Duration::from_secs(2)))
                        .unwrap()
                        .expect("a frame");
                    if is_last_frame(&r.frame) {
                        break;
                    }
                }
                let latency = sent.elapsed();
                samples.lock().unwrap().push(latency);
                total += latency;
            }
            total
        })
    });
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    output.join().unwrap();
    let mut all = samples.lock().unwrap().clone();
    all.sort();
    // The sample at `percent` % of the sorted list.
    let at = |percent: usize| all[(all.len() - 1) * percent / 100];
    println!(
        "control_cmd → 0x102 on a virtual bus: p50 {:.1} µs, p99 {:.1} µs, max {:.1} µs over {} samples",
        at(50).as_secs_f64() * 1e6,
        at(99).as_secs_f64() * 1e6,
        all.last().unwrap().as_secs_f64() * 1e6,
        all.len()
    );
}

fn main() {
    if std::env::var_os(MARKER).is_none() {
        let lonet = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../../shared/tools/lonet.sh"
        );
        let status = std::process::Command::new(lonet)
            .arg(std::env::current_exe().unwrap())
            .args(std::env::args_os().skip(1))
            .env(MARKER, "1")
            .status()
            .expect("lonet.sh runs (see ../shared/tools/README.md)");
        std::process::exit(status.code().unwrap_or(1));
    }
    let mut criterion = Criterion::default().configure_from_args();
    bench(&mut criterion);
    criterion.final_summary();
}
