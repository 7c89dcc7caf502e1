//! The tug's vehicle control ECU diagnosed over UDS on the simulated bus 1, by bywire's own
//! client as a tester plugged into the bus: after the fault tour every injected fault is a
//! DTC with its status bits and snapshots, ClearDTC clears them, ECUReset reboots the ECU (the
//! tug stops and recovers), and the steering calibration sweep runs only at standstill.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use bywire_core::node::{Node, Port};
use bywire_core::{Id, Timestamp};
use bywire_diag::client::{self, ClientError, ClientTiming, UdsClient};
use bywire_diag::isotp::IsoTpConfig;
use bywire_diag::uds::{nrc, status};
use bywire_net::sim::NodeId;
use bywire_sim::scenario::Scenario;
use bywire_sim::tug::{Tug, TugBus, TugParams, DRIVE_NODES};
use bywire_tug::diagnostics::{did, dtc, CALIBRATION_ROUTINE, SWEEP_TIME};
use bywire_tug::ecu::BOOT_TIME;
use bywire_vehicle::command::ControlMode;

struct Tester {
    client: UdsClient,
    port: NodeId,
}

impl Tester {
    fn plug_into(tug: &mut Tug) -> Tester {
        let id = |raw| Id::standard(raw).unwrap();
        Tester {
            client: UdsClient::new(
                IsoTpConfig::new(id(0x7E0), id(0x7E8)),
                ClientTiming::default(),
            ),
            port: tug.attach(TugBus::Bus1),
        }
    }

    /// The extended session and security access with the ECU's key.
    fn unlock(&mut self, tug: &mut Tug, step: &dyn Fn(&mut Tug)) {
        self.ask(tug, step, &[0x10, 0x03]).unwrap();
        let seed = self.ask(tug, step, &[0x27, 0x01]).unwrap();
        let key = bywire_diag::uds::demo_key(1, &seed[2..]);
        let mut send_key = vec![0x27, 0x02];
        send_key.extend_from_slice(&key);
        self.ask(tug, step, &send_key).unwrap();
    }

    /// One request, the tug stepping (by `step`) until its answer.
    fn ask(
        &mut self,
        tug: &mut Tug,
        step: &dyn Fn(&mut Tug),
        request: &[u8],
    ) -> Result<Vec<u8>, ClientError> {
        self.client.request(tug.now(), request).unwrap();
        for _ in 0..30_000 {
            step(tug);
            let now = tug.now();
            while let Some((_, frame)) = tug.receive(TugBus::Bus1, self.port) {
                self.client.on_frame(now, Port::MAIN, &frame);
            }
            let mut out = Vec::new();
            self.client.poll(now, &mut |_, f| out.push(f));
            for frame in out {
                tug.send(TugBus::Bus1, self.port, frame);
            }
            if let Some(outcome) = self.client.take_outcome() {
                return outcome;
            }
        }
        panic!("no answer to {request:02X?}");
    }
}

fn fault_tour() -> (Tug, Scenario) {
    let scenario = Scenario::builtin("fault-tour").unwrap();
    let mut tug = Tug::new(scenario.params(1, scenario.tug.payload)).unwrap();
    while tug.now() < Timestamp::from_millis(62_000) {
        scenario.step(&mut tug);
    }
    (tug, scenario)
}

#[test]
fn after_the_fault_tour_every_fault_is_a_dtc_read_over_uds_and_cleared() {
    let (mut tug, scenario) = fault_tour();
    let step = |t: &mut Tug| scenario.step(t);
    let mut tester = Tester::plug_into(&mut tug);
    let answer = tester.ask(&mut tug, &step, &[0x19, 0x02, 0xFF]).unwrap();
    let (_, dtcs) = client::dtc_list(&answer).unwrap();
    let listed: std::collections::BTreeMap<u32, u8> = dtcs.into_iter().collect();
    let expected = [
        // The ADS's silence walks the cascade.
        dtc::WATCHDOG_HOLDING,
        dtc::WATCHDOG_DECELERATING,
        dtc::WATCHDOG_FULL_BRAKING,
        dtc::BUS_1B_LOST,
        dtc::ESTOP,
        dtc::heartbeat_lost(DRIVE_NODES[1]),
        // Corner 2 (RL)'s sensor stuck.
        dtc::steering_sensors(2),
        dtc::COMMAND_CHECKSUM,
        dtc::COMMAND_COUNTER_REPEATED,
        dtc::DRIVER_TAKEOVER,
        dtc::BUS_1_OFF,
        // Bus 2's node sending 0x723 (drive 0x23's heartbeat) goes bus-off and, recovered,
        // says so with EMCY 0x8140.
        dtc::drive_emergency(0x23),
    ];
    for code in expected {
        let status = listed
            .get(&code)
            .copied()
            .unwrap_or_else(|| panic!("{code:06X} missing from {listed:06X?}"));
        let occurred = status::CONFIRMED | status::FAILED_SINCE_CLEAR | status::PENDING;
        assert_eq!(status & occurred, occurred, "{code:06X}: {status:02X}");
    }
    // What UDS lists is what the run's memory holds.
    let memory: Vec<(u32, u8)> = tug
        .vehicle_control_ecu()
        .unwrap()
        .diagnostics()
        .server()
        .dtcs()
        .collect();
    assert_eq!(memory.len(), listed.len());
    // The E-stop's faults are over: not failing now.
    assert_eq!(listed[&dtc::ESTOP] & status::TEST_FAILED, 0);

    // The E-stop's first snapshot: at 16 s, at speed, from the ECU's own clock.
    let answer = tester
        .ask(&mut tug, &step, &[0x19, 0x04, 0x50, 0x00, 0x00, 0x01])
        .unwrap();
    let description = bywire_tug::diagnostics::description();
    let (code, _, records) = client::snapshots(&answer, &|id| description.did_length(id)).unwrap();
    assert_eq!(code, dtc::ESTOP);
    let value = |id: u16| {
        records[0]
            .values
            .iter()
            .find(|(d, _)| *d == id)
            .map(|(_, v)| v.clone())
            .unwrap()
    };
    let time_ms = u32::from_be_bytes(value(did::TIME).try_into().unwrap());
    assert!((16_000..16_100).contains(&time_ms), "{time_ms}");
    let speed = f64::from(i16::from_be_bytes(value(did::SPEED).try_into().unwrap())) / 100.0;
    assert!(speed > 1.0, "{speed}");
    // Extended data: full braking happened three times — the ADS's silence, and the voter's
    // answer to the forged and to the replayed commands on bus 1 (the tour is not secured).
    let answer = tester
        .ask(&mut tug, &step, &[0x19, 0x06, 0xD0, 0x01, 0x03, 0x01])
        .unwrap();
    assert_eq!(answer[answer.len() - 2..], [0x01, 0x03]);

    // DIDs: VIN, odometer (the route's length so far), battery.
    let answer = tester
        .ask(&mut tug, &step, &[0x22, 0xF1, 0x90, 0x03, 0x01])
        .unwrap();
    let values = client::did_values(&answer, &[did::VIN, did::ODOMETER], &|id| {
        description.did_length(id)
    })
    .unwrap();
    assert_eq!(values[0].1, b"BYWIRETUG00000042");
    let odometer = u32::from_be_bytes(values[1].1.clone().try_into().unwrap());
    assert!((50..400).contains(&odometer), "{odometer} m");

    // The drives' emergency history: drive 0x23's bus-off recovery, EMCY 0x8140.
    let answer = tester.ask(&mut tug, &step, &[0x22, 0x03, 0x10]).unwrap();
    let history = &answer[3..];
    let drive_23 = history
        .chunks_exact(4)
        .find(|entry| entry[0] == 0x23)
        .unwrap();
    assert!(drive_23[1] >= 1, "{history:02X?}");
    assert_eq!(drive_23[2..], [0x81, 0x40]);

    tester
        .ask(&mut tug, &step, &[0x14, 0xFF, 0xFF, 0xFF])
        .unwrap();
    let answer = tester.ask(&mut tug, &step, &[0x19, 0x02, 0xFF]).unwrap();
    let (_, after) = client::dtc_list(&answer).unwrap();
    // Only what still fails comes back.
    assert!(
        after.iter().all(|(_, s)| s & status::TEST_FAILED != 0),
        "{after:06X?}"
    );
}

fn cruising() -> Tug {
    let mut tug = Tug::new(TugParams {
        seed: 2,
        payload: 0.0,
        ..TugParams::default()
    })
    .unwrap();
    while tug.now() < Timestamp::from_millis(8_000) {
        tug.step();
    }
    assert_eq!(tug.ecu().unwrap().mode(), ControlMode::Autonomous);
    tug
}

#[test]
fn ecu_reset_reboots_the_ecu_the_tug_stops_and_recovers() {
    let mut tug = cruising();
    let mut tester = Tester::plug_into(&mut tug);
    let step = |t: &mut Tug| t.step();
    let answer = tester.ask(&mut tug, &step, &[0x11, 0x01]).unwrap();
    assert_eq!(answer, vec![0x51, 0x01]);
    let reset_at = tug.now();
    assert!(tug.vehicle_control_ecu().unwrap().booting(reset_at));
    // While it boots it is silent and the spring brakes hold.
    let frames_before = tug.bus1_log.len();
    for _ in 0..BOOT_TIME.as_millis() - 10 {
        tug.step();
    }
    let ecu_frames = tug.bus1_log[frames_before..]
        .iter()
        .filter(|(_, f)| f.id().map(|id| id.as_raw()) == Some(0x101))
        .count();
    assert_eq!(ecu_frames, 0, "the state frame during the boot");
    assert_eq!(
        tug.vehicle_control_ecu().unwrap().brake_demand(tug.now()),
        1.0
    );
    // Back: failed closed at first, then the ADS's commands re-engage it.
    let mut engaged_again = None;
    for _ in 0..20_000 {
        tug.step();
        if tug.ecu().unwrap().mode() == ControlMode::Autonomous {
            engaged_again = Some(tug.now());
            break;
        }
    }
    let engaged_again = engaged_again.expect("the tug re-engages after the reset");
    assert!(engaged_again.saturating_since(reset_at) >= BOOT_TIME);
    assert!(
        tug.pose_speed() < 2.5,
        "it stopped meanwhile: {}",
        tug.pose_speed()
    );
}

#[test]
fn the_steering_calibration_sweep_runs_at_standstill_only_and_reports_offsets() {
    let mut tug = cruising();
    let mut tester = Tester::plug_into(&mut tug);
    let step = |t: &mut Tug| t.step();
    tester.unlock(&mut tug, &step);
    // Moving under the ADS: refused.
    let [hi, lo] = CALIBRATION_ROUTINE.to_be_bytes();
    let start = [0x31, 0x01, hi, lo];
    assert_eq!(
        tester.ask(&mut tug, &step, &start),
        Err(ClientError::Negative {
            service: 0x31,
            code: nrc::CONDITIONS_NOT_CORRECT
        })
    );
    // A silent ADS: the tug brakes to standstill and falls back to manual.
    let widest = std::cell::Cell::new(0.0f64);
    let quiet = |t: &mut Tug| {
        t.step_with_ads(&mut Silent);
        widest.set(widest.get().max(t.wheel_angles()[0].abs()));
    };
    for _ in 0..6_000 {
        quiet(&mut tug);
    }
    assert!(tug.pose_speed() < 0.05);
    assert!(
        !tug.vehicle_control_ecu()
            .unwrap()
            .actuators(tug.now())
            .motors_enabled
    );
    widest.set(0.0);
    // The session ended meanwhile (S3): again, then the sweep.
    tester.unlock(&mut tug, &quiet);
    let started = tug.now();
    let answer = tester.ask(&mut tug, &quiet, &start).unwrap();
    assert_eq!(answer, vec![0x71, 0x01, hi, lo, 0x00]);
    // Answered once the sweep is done (through response pending), the wheels swept.
    assert!(tug.now().saturating_since(started) >= SWEEP_TIME);
    assert!(
        widest.get() > 15.0,
        "the sweep reached {} degrees",
        widest.get()
    );
    let results = tester.ask(&mut tug, &quiet, &[0x31, 0x03, hi, lo]).unwrap();
    assert_eq!(results.len(), 4 + 8, "{results:02X?}");
    // Healthy sensors: each corner's offset is well under a degree.
    for pair in results[4..].chunks_exact(2) {
        let offset = f64::from(i16::from_be_bytes([pair[0], pair[1]])) / 100.0;
        assert!(offset.abs() < 1.0, "{offset}");
    }
}

/// An ADS that sends nothing.
struct Silent;

impl bywire_core::node::Node for Silent {
    fn on_frame(&mut self, _: Timestamp, _: bywire_core::node::Port, _: &bywire_core::Frame) {}

    fn poll(
        &mut self,
        _: Timestamp,
        _: &mut dyn FnMut(bywire_core::node::Port, bywire_core::Frame),
    ) {
    }

    fn next_deadline(&self) -> Option<Timestamp> {
        None
    }
}
