//! The vehicle control ECU's diagnostics: a UDS server on bus 1 (requests to 0x7E0, answers
//! from 0x7E8, functional requests to 0x7DF; 11-bit, normal addressing), its DIDs, and a DTC
//! for every fault the ECU can see, each with its status bits and snapshots of the time, the
//! speed and the steering angle.
//!
//! Monitors run every report cycle (20 ms) and on the ECU's events; a DTC is reported failed
//! on the condition's rising edge and passed when it ends, so its status bits tell a test
//! engineer what happened (confirmed, failed since the last clear) and what still is
//! (testFailed). After a ClearDiagnosticInformation every monitor reports afresh.

use bywire_core::node::{Node, Port};
use core::time::Duration;

use bywire_core::{Frame, Id, Timestamp};
use bywire_diag::describe::{Description, DidInfo, ValueKind};
use bywire_diag::isotp::IsoTpConfig;
use bywire_diag::uds::{Did, Routine, Session, UdsEvent, UdsServer, UdsTiming};
use bywire_vehicle::redundancy::Channel;
use bywire_vehicle::supervisor::{CommandStats, EstopState, Watchdog};

use crate::drives::{DRIVE_NODES, STEERING_NODES};

/// Physical requests come on this identifier.
pub const REQUEST_ID: u32 = 0x7E0;
/// Answers go out on this one.
pub const RESPONSE_ID: u32 = 0x7E8;
/// Functional (broadcast) requests.
pub const FUNCTIONAL_ID: u32 = 0x7DF;

/// The ECU's data identifiers.
pub mod did {
    /// VIN, 17 characters.
    pub const VIN: u16 = 0xF190;
    /// ECU hardware version.
    pub const HARDWARE_VERSION: u16 = 0xF191;
    /// ECU software version.
    pub const SOFTWARE_VERSION: u16 = 0xF195;
    /// The active vehicle profile's name (16 characters, space padded).
    pub const PROFILE: u16 = 0xF1A0;
    /// Steering calibration offsets FL, FR, RL, RR: i16 each, 0.01°; written in the extended
    /// session after security access, added to every steering setpoint.
    pub const STEERING_OFFSETS: u16 = 0x0200;
    /// Battery: state of charge (u8, %), voltage (u16, 0.1 V), current (i16, 0.1 A).
    pub const BATTERY: u16 = 0x0300;
    /// Odometer: u32, metres.
    pub const ODOMETER: u16 = 0x0301;
    /// The drives' emergencies: per drive (0x11–0x14, 0x21–0x24) its node ID, how many it
    /// sent (u8) and the last error code (u16).
    pub const DRIVE_EMERGENCIES: u16 = 0x0310;
    /// Snapshot: the ECU's time, u32 milliseconds since it started.
    pub const TIME: u16 = 0xDD00;
    /// Snapshot: the speed, i16, 0.01 m/s.
    pub const SPEED: u16 = 0xDD01;
    /// Snapshot: the front-left steering angle, i16, 0.01°.
    pub const STEERING_ANGLE: u16 = 0xDD02;
}

/// The steering calibration sweep (RoutineControl): extended session, security access, the
/// tug at standstill and not driven by the ADS. The steering drives sweep each wheel to
/// ±[`SWEEP_DEG`] and back; the results are each corner's mean difference of its two sensor
/// tracks (i16, 0.01°), the offsets to write into [`did::STEERING_OFFSETS`].
pub const CALIBRATION_ROUTINE: u16 = 0x0203;
/// How long the sweep takes.
pub const SWEEP_TIME: Duration = Duration::from_secs(4);
/// The sweep's amplitude, degrees.
pub const SWEEP_DEG: f64 = 20.0;

/// The ECU's DTCs (24 bits: the J2012 code and a failure type byte).
pub mod dtc {
    /// U1001-01: ADS commands missed, the last one held.
    pub const WATCHDOG_HOLDING: u32 = 0xD0_0101;
    /// U1001-02: ADS commands missed, decelerating under control.
    pub const WATCHDOG_DECELERATING: u32 = 0xD0_0102;
    /// U1001-03: ADS commands lost, full braking.
    pub const WATCHDOG_FULL_BRAKING: u32 = 0xD0_0103;
    /// C1000-00: E-stop.
    pub const ESTOP: u32 = 0x50_0000;
    /// U1002-00: redundant command bus 1b lost (voting on bus 1 alone).
    pub const BUS_1B_LOST: u32 = 0xD0_0200;
    /// U1002-01: command bus 1 lost (voting on bus 1b alone).
    pub const BUS_1_LOST: u32 = 0xD0_0201;
    /// U1003-01: command checksum wrong.
    pub const COMMAND_CHECKSUM: u32 = 0xD0_0301;
    /// U1003-02: command counter repeated.
    pub const COMMAND_COUNTER_REPEATED: u32 = 0xD0_0302;
    /// U1003-03: command counter skipped.
    pub const COMMAND_COUNTER_SKIPPED: u32 = 0xD0_0303;
    /// U1003-04: command malformed.
    pub const COMMAND_MALFORMED: u32 = 0xD0_0304;
    /// U1003-05: command out of range.
    pub const COMMAND_OUT_OF_RANGE: u32 = 0xD0_0305;
    /// U1003-06: the two buses' copies disagree.
    pub const COMMAND_DISAGREEMENT: u32 = 0xD0_0306;
    /// C1400-00: driver takeover.
    pub const DRIVER_TAKEOVER: u32 = 0x54_0000;
    /// U0073-00: the ECU's controller on bus 1 is bus-off.
    pub const BUS_1_OFF: u32 = 0xC0_7300;

    /// U1100-NN: drive NN's heartbeat lost.
    pub fn heartbeat_lost(node: u8) -> u32 {
        0xD1_0000 | u32::from(node)
    }

    /// C1200-NN: drive NN sent an emergency.
    pub fn drive_emergency(node: u8) -> u32 {
        0x52_0000 | u32::from(node)
    }

    /// C1300-0K: the steering sensors of corner K (1 FL … 4 RR) disagree.
    pub fn steering_sensors(corner: usize) -> u32 {
        0x53_0000 | u32::try_from(corner + 1).unwrap_or(0)
    }
}

/// The ECU's DTCs with their names.
pub fn dtc_names() -> Vec<(u32, String)> {
    let mut names: Vec<(u32, String)> = [
        (dtc::WATCHDOG_HOLDING, "ADS commands missed: holding"),
        (
            dtc::WATCHDOG_DECELERATING,
            "ADS commands missed: decelerating",
        ),
        (
            dtc::WATCHDOG_FULL_BRAKING,
            "ADS commands lost: full braking",
        ),
        (dtc::ESTOP, "E-stop"),
        (dtc::BUS_1B_LOST, "redundant command bus 1b lost"),
        (dtc::BUS_1_LOST, "command bus 1 lost"),
        (dtc::COMMAND_CHECKSUM, "command checksum wrong"),
        (dtc::COMMAND_COUNTER_REPEATED, "command counter repeated"),
        (dtc::COMMAND_COUNTER_SKIPPED, "command counter skipped"),
        (dtc::COMMAND_MALFORMED, "command malformed"),
        (dtc::COMMAND_OUT_OF_RANGE, "command out of range"),
        (dtc::COMMAND_DISAGREEMENT, "command copies disagree"),
        (dtc::DRIVER_TAKEOVER, "driver takeover"),
        (dtc::BUS_1_OFF, "bus 1 controller bus-off"),
    ]
    .into_iter()
    .map(|(code, name)| (code, name.to_string()))
    .collect();
    for node in STEERING_NODES.iter().chain(&DRIVE_NODES) {
        names.push((
            dtc::heartbeat_lost(*node),
            format!("drive 0x{node:02X} heartbeat lost"),
        ));
        names.push((
            dtc::drive_emergency(*node),
            format!("drive 0x{node:02X} emergency"),
        ));
    }
    for (corner, name) in ["FL", "FR", "RL", "RR"].iter().enumerate() {
        names.push((
            dtc::steering_sensors(corner),
            format!("steering sensors {name} disagree"),
        ));
    }
    names
}

/// The ECU's DIDs and DTCs as a tester names them (`bywire uds --describe tug`).
pub fn description() -> Description {
    let number = |name: &str, length, signed, scale, unit: &str| DidInfo {
        name: name.into(),
        length: Some(length),
        kind: ValueKind::Number {
            signed,
            scale,
            offset: 0.0,
            unit: unit.into(),
        },
    };
    let text = |name: &str, length| DidInfo {
        name: name.into(),
        length: Some(length),
        kind: ValueKind::Ascii,
    };
    let mut d = Description::default();
    d.dids.insert(did::VIN, text("VIN", VIN.len()));
    d.dids.insert(
        did::HARDWARE_VERSION,
        text("ECU hardware version", HARDWARE.len()),
    );
    d.dids.insert(
        did::SOFTWARE_VERSION,
        text("ECU software version", SOFTWARE.len()),
    );
    d.dids
        .insert(did::PROFILE, text("active profile", PROFILE_LEN));
    d.dids.insert(
        did::STEERING_OFFSETS,
        DidInfo {
            name: "steering calibration offsets FL FR RL RR".into(),
            length: Some(8),
            kind: ValueKind::Array {
                width: 2,
                signed: true,
                scale: 0.01,
                unit: "deg".into(),
            },
        },
    );
    d.dids.insert(
        did::BATTERY,
        DidInfo {
            name: "battery: SoC %, voltage 0.1 V, current 0.1 A".into(),
            length: Some(5),
            kind: ValueKind::Bytes,
        },
    );
    d.dids
        .insert(did::ODOMETER, number("odometer", 4, false, 1.0, "m"));
    d.dids.insert(
        did::DRIVE_EMERGENCIES,
        DidInfo {
            name: "drive emergencies: node, count, last code".into(),
            length: Some(32),
            kind: ValueKind::Bytes,
        },
    );
    d.dids
        .insert(did::TIME, number("time", 4, false, 1.0, "ms"));
    d.dids
        .insert(did::SPEED, number("speed", 2, true, 0.01, "m/s"));
    d.dids.insert(
        did::STEERING_ANGLE,
        number("steering angle", 2, true, 0.01, "deg"),
    );
    d.dtcs = dtc_names().into_iter().collect();
    d
}

const VIN: &[u8; 17] = b"BYWIRETUG00000042";
const HARDWARE: &[u8] = b"TUG-VCU-A2";
const SOFTWARE: &[u8] = env!("CARGO_PKG_VERSION").as_bytes();
const PROFILE_LEN: usize = 16;

/// The vehicle's state the monitors read each cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    /// The watchdog.
    pub watchdog: Watchdog,
    /// The E-stop latch.
    pub estop: EstopState,
    /// The bus voting alone.
    pub degraded: Option<Channel>,
    /// The command counts so far.
    pub stats: CommandStats,
    /// A driver's input is above the takeover thresholds.
    pub driver_input: bool,
    /// The speed, m/s.
    pub speed: f64,
    /// The front-left steering angle, degrees.
    pub steering: f64,
}

/// What the ECU must do for its diagnostics.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DiagnosticRequest {
    /// Reset the ECU (the tester's ECUReset was answered).
    Reset,
    /// The steering offsets were written.
    OffsetsWritten,
    /// The calibration sweep starts.
    CalibrationStarted,
    /// The calibration sweep was stopped.
    CalibrationStopped,
}

/// The monitors' memory and the UDS server.
pub struct Diagnostics {
    server: UdsServer,
    /// DTCs whose condition held at the last evaluation.
    failing: std::collections::BTreeSet<u32>,
    /// Counts at the last evaluation (rejections since then fail their monitor).
    last_stats: CommandStats,
    /// The latest speed and angle, for snapshots.
    speed: f64,
    steering: f64,
    odometer_m: f64,
    last_odometer: Option<Timestamp>,
    /// Per drive (steering drives, then wheel drives): emergencies and the last code.
    emergencies: [(u8, u16); 8],
    requests: std::collections::VecDeque<DiagnosticRequest>,
}

/// The ECU's N_As and N_Ar.
const N_A: core::time::Duration = core::time::Duration::from_millis(25);

/// Requests kept for the ECU (it takes them every poll).
const REQUEST_CAPACITY: usize = 8;

impl Diagnostics {
    /// The ECU's diagnostics for `profile` (the active profile's name).
    pub fn new(profile: &str) -> Self {
        let id = |raw| Id::standard(raw).unwrap_or(Id::Standard(bywire_core::StandardId::ZERO));
        // Frames are confirmed by the runner; OBD's ISO 15765-4 bounds N_As/N_Ar to 25 ms.
        let mut channel = IsoTpConfig::new(id(RESPONSE_ID), id(REQUEST_ID)).confirmed(N_A);
        // OBD-style ECUs pad every frame.
        channel.padding = Some(0xAA);
        let mut server =
            UdsServer::new(channel, UdsTiming::default()).with_functional(id(FUNCTIONAL_ID));
        let read_only = |value: &[u8]| Did {
            value: value.to_vec(),
            writable_in: Vec::new(),
            secured: false,
        };
        let mut profile_name = [b' '; PROFILE_LEN];
        for (slot, b) in profile_name.iter_mut().zip(profile.bytes()) {
            *slot = b;
        }
        server.set_did(did::VIN, read_only(VIN));
        server.set_did(did::HARDWARE_VERSION, read_only(HARDWARE));
        server.set_did(did::SOFTWARE_VERSION, read_only(SOFTWARE));
        server.set_did(did::PROFILE, read_only(&profile_name));
        server.set_did(
            did::STEERING_OFFSETS,
            Did {
                value: vec![0; 8],
                writable_in: vec![Session::Extended],
                secured: true,
            },
        );
        server.set_routine(
            CALIBRATION_ROUTINE,
            Routine {
                runs_for: SWEEP_TIME,
                result: Vec::new(),
                secured: true,
            },
        );
        let mut d = Diagnostics {
            server,
            failing: std::collections::BTreeSet::new(),
            last_stats: CommandStats::default(),
            speed: 0.0,
            steering: 0.0,
            odometer_m: 0.0,
            last_odometer: None,
            emergencies: [(0, 0); 8],
            requests: std::collections::VecDeque::with_capacity(REQUEST_CAPACITY),
        };
        d.refresh_values(Timestamp::ZERO, None);
        d
    }

    /// The UDS server (its DTC memory, session).
    pub fn server(&self) -> &UdsServer {
        &self.server
    }

    /// The steering offsets written by a tester, degrees (FL, FR, RL, RR).
    pub fn steering_offsets(&self) -> [f64; 4] {
        let mut offsets = [0.0; 4];
        if let Some(value) = self.server.did(did::STEERING_OFFSETS) {
            for (offset, pair) in offsets.iter_mut().zip(value.chunks_exact(2)) {
                if let &[hi, lo] = pair {
                    *offset = f64::from(i16::from_be_bytes([hi, lo])) / 100.0;
                }
            }
        }
        offsets
    }

    /// The next thing the ECU must do.
    pub fn next_request(&mut self) -> Option<DiagnosticRequest> {
        self.requests.pop_front()
    }

    fn request(&mut self, request: DiagnosticRequest) {
        if self.requests.len() < REQUEST_CAPACITY {
            self.requests.push_back(request);
        }
    }

    /// A frame on bus 1: requests to the ECU go to its server.
    pub fn on_frame(&mut self, now: Timestamp, frame: &Frame) {
        self.server.on_frame(now, Port::MAIN, frame);
        self.take_events();
    }

    /// One of the server's answers is on the bus.
    pub fn on_sent(&mut self, now: Timestamp, frame: &Frame) {
        self.server.on_sent(now, Port::MAIN, frame);
    }

    /// The server's answers, and what the tester asked of the ECU.
    pub fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Frame)) {
        self.server.poll(now, &mut |_, frame| out(frame));
        self.take_events();
    }

    fn take_events(&mut self) {
        for event in self.server.take_events() {
            match event {
                UdsEvent::Reset(_) => self.request(DiagnosticRequest::Reset),
                UdsEvent::Written(did::STEERING_OFFSETS) => {
                    self.request(DiagnosticRequest::OffsetsWritten);
                }
                UdsEvent::RoutineStarted(CALIBRATION_ROUTINE) => {
                    self.request(DiagnosticRequest::CalibrationStarted);
                }
                UdsEvent::RoutineStopped(CALIBRATION_ROUTINE) => {
                    self.request(DiagnosticRequest::CalibrationStopped);
                }
                // After a clear, every monitor reports afresh.
                UdsEvent::Cleared(_) => self.failing.clear(),
                UdsEvent::Session(_)
                | UdsEvent::Written(_)
                | UdsEvent::Unlocked(_)
                | UdsEvent::RoutineStarted(_)
                | UdsEvent::RoutineStopped(_)
                | UdsEvent::Transport(_) => {}
            }
        }
    }

    /// When the server next has something to do.
    pub fn next_deadline(&self) -> Option<Timestamp> {
        self.server.next_deadline()
    }

    /// Whether the calibration sweep runs now.
    pub fn calibrating(&self, now: Timestamp) -> bool {
        self.server.routine_running(CALIBRATION_ROUTINE, now)
    }

    /// Whether the sweep may start now (the ECU's conditions).
    pub fn allow_calibration(&mut self, allowed: bool) {
        self.server
            .set_routine_allowed(CALIBRATION_ROUTINE, allowed);
    }

    /// The sweep's measured offsets (degrees, per corner) become its results.
    pub fn calibration_result(&mut self, offsets: [f64; 4]) {
        let mut result = Vec::with_capacity(8);
        for offset in offsets {
            result.extend_from_slice(&centi(offset).to_be_bytes());
        }
        self.server.set_routine_result(CALIBRATION_ROUTINE, result);
    }

    /// The server after the ECU restarted: session and security gone, DTCs kept.
    pub fn restart(&mut self) {
        self.server.restart();
        self.requests.clear();
    }

    /// The snapshot's DIDs and their values now (the time's 4 bytes, the others' first 2).
    fn snapshot_values(&self, now: Timestamp) -> [(u16, [u8; 4], usize); 3] {
        let two = |v: i16| {
            let [a, b] = v.to_be_bytes();
            [a, b, 0, 0]
        };
        [
            (did::TIME, millis(now).to_be_bytes(), 4),
            (did::SPEED, two(centi(self.speed)), 2),
            (did::STEERING_ANGLE, two(centi(self.steering)), 2),
        ]
    }

    fn snapshot(&self, now: Timestamp) -> Vec<(u16, Vec<u8>)> {
        self.snapshot_values(now)
            .iter()
            .map(|(id, bytes, len)| (*id, bytes.get(..*len).unwrap_or(&[]).to_vec()))
            .collect()
    }

    /// One monitor's result: failed on the condition's rising edge (with a snapshot),
    /// passed when it ends.
    fn monitor(&mut self, now: Timestamp, dtc: u32, failing: bool) {
        match (failing, self.failing.contains(&dtc)) {
            (true, false) => {
                let snapshot = self.snapshot(now);
                self.server.report_with_snapshot(dtc, snapshot);
                self.failing.insert(dtc);
            }
            (false, true) => {
                self.server.report(dtc, false);
                self.failing.remove(&dtc);
            }
            (true, true) | (false, false) => {}
        }
    }

    /// The monitors that read the vehicle's state, every report cycle.
    pub fn observe(&mut self, now: Timestamp, o: &Observation) {
        self.speed = o.speed;
        self.steering = o.steering;
        // The watchdog is monitored once the ADS has commanded (it starts at full braking).
        let commanded = o.stats.accepted > 0;
        let watchdog = [
            (
                dtc::WATCHDOG_HOLDING,
                matches!(o.watchdog, Watchdog::Holding { .. }),
            ),
            (
                dtc::WATCHDOG_DECELERATING,
                matches!(o.watchdog, Watchdog::Decelerating { .. }),
            ),
            (
                dtc::WATCHDOG_FULL_BRAKING,
                o.watchdog == Watchdog::FullBraking,
            ),
        ];
        for (code, failing) in watchdog {
            self.monitor(now, code, commanded && failing);
        }
        self.monitor(now, dtc::ESTOP, o.estop != EstopState::Normal);
        self.monitor(now, dtc::BUS_1B_LOST, o.degraded == Some(Channel::B));
        self.monitor(now, dtc::BUS_1_LOST, o.degraded == Some(Channel::A));
        self.monitor(now, dtc::DRIVER_TAKEOVER, o.driver_input);
        // A rejection since the last cycle fails its monitor; a cycle of valid commands
        // without one passes it.
        let (s, last) = (o.stats, self.last_stats);
        let accepted = s.accepted > last.accepted;
        let rejections = [
            (dtc::COMMAND_CHECKSUM, s.checksum > last.checksum),
            (dtc::COMMAND_COUNTER_REPEATED, s.repeated > last.repeated),
            (dtc::COMMAND_COUNTER_SKIPPED, s.skipped > last.skipped),
            (dtc::COMMAND_MALFORMED, s.malformed > last.malformed),
            (
                dtc::COMMAND_OUT_OF_RANGE,
                s.out_of_range > last.out_of_range,
            ),
            (
                dtc::COMMAND_DISAGREEMENT,
                s.disagreements > last.disagreements,
            ),
        ];
        for (code, rejected) in rejections {
            if rejected {
                self.monitor(now, code, true);
            } else if accepted {
                self.monitor(now, code, false);
            }
        }
        self.last_stats = s;
        self.count_distance(now, o.speed);
    }

    fn count_distance(&mut self, now: Timestamp, speed: f64) {
        if let Some(last) = self.last_odometer {
            self.odometer_m += speed.abs() * now.saturating_since(last).as_secs_f64();
        }
        self.last_odometer = Some(now);
    }

    /// A drive's heartbeat lost or back.
    pub fn heartbeat(&mut self, now: Timestamp, node: u8, lost: bool) {
        self.monitor(now, dtc::heartbeat_lost(node), lost);
    }

    /// A drive's emergency: a non-zero code fails its monitor and joins its history; zero
    /// (error reset) passes it.
    pub fn emergency(&mut self, now: Timestamp, node: u8, code: u16) {
        if code != 0 {
            let slot = STEERING_NODES
                .iter()
                .chain(&DRIVE_NODES)
                .position(|n| *n == node)
                .and_then(|i| self.emergencies.get_mut(i));
            if let Some((count, last)) = slot {
                *count = count.saturating_add(1);
                *last = code;
            }
        }
        self.monitor(now, dtc::drive_emergency(node), code != 0);
    }

    /// A corner's steering sensors disagree (`Some`), or every corner agrees again.
    pub fn steering_sensors(&mut self, now: Timestamp, corner: Option<usize>) {
        for c in 0..4 {
            self.monitor(now, dtc::steering_sensors(c), corner == Some(c));
        }
    }

    /// The ECU's controller on bus 1 went bus-off (`true`) or came back.
    pub fn bus_off(&mut self, now: Timestamp, off: bool) {
        self.monitor(now, dtc::BUS_1_OFF, off);
    }

    /// The values DIDs show now: battery (from the BMS's frame, if one came) and odometer,
    /// and the drives' emergency history.
    pub fn refresh_values(&mut self, now: Timestamp, battery: Option<(f64, f64, f64)>) {
        // Every report cycle: the values change in place, nothing is allocated.
        let mut value = [0u8; 5];
        if let Some((soc, voltage, current)) = battery {
            let [v0, v1] = round_u16(voltage * 10.0).to_be_bytes();
            let [c0, c1] = centi(current / 10.0).to_be_bytes();
            value = [round_u8(soc), v0, v1, c0, c1];
        }
        if battery.is_some() || self.server.did(did::BATTERY).is_none() {
            self.server.set_did_value(did::BATTERY, &value);
        }
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let metres = self.odometer_m.clamp(0.0, f64::from(u32::MAX)) as u32;
        self.server
            .set_did_value(did::ODOMETER, &metres.to_be_bytes());
        let mut history = [0u8; 32];
        for ((entry, node), (count, code)) in history
            .chunks_exact_mut(4)
            .zip(STEERING_NODES.iter().chain(&DRIVE_NODES))
            .zip(self.emergencies)
        {
            let [hi, lo] = code.to_be_bytes();
            entry.copy_from_slice(&[*node, count, hi, lo]);
        }
        self.server.set_did_value(did::DRIVE_EMERGENCIES, &history);
        for (id, bytes, len) in self.snapshot_values(now) {
            self.server
                .set_did_value(id, bytes.get(..len).unwrap_or(&[]));
        }
    }
}

/// Hundredths, rounded, saturating to i16.
#[allow(clippy::cast_possible_truncation)]
fn centi(value: f64) -> i16 {
    libm::round(value * 100.0).clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
}

#[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
fn round_u8(value: f64) -> u8 {
    libm::round(value).clamp(0.0, 255.0) as u8
}

#[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
fn round_u16(value: f64) -> u16 {
    libm::round(value).clamp(0.0, f64::from(u16::MAX)) as u16
}

/// Milliseconds of `now`, wrapping (a u32 of ms is 49 days).
#[allow(clippy::cast_possible_truncation)]
fn millis(now: Timestamp) -> u32 {
    (now.as_nanos() / 1_000_000) as u32
}
