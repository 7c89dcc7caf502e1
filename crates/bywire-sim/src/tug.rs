//! The simulated tug network, stepped by the millisecond in simulated time:
//! - bus 1 (vehicle control, 500 kbit/s, bit-timed): the ADS side following a route with pure
//!   pursuit, and the vehicle control ECU's supervisor (the `reference-tug` profile);
//! - bus 2 (drives, CANopen, 1 Mbit/s, bit-timed): the ECU as NMT master commanding four
//!   steering drives (CiA 402 profile position, each turning its corner's orbital valve) and
//!   four wheel drives (CiA 402 profile velocity), heartbeats monitored;
//! - bus 3 (sensors, 500 kbit/s, bit-timed): the IMU, read by the ECU; the ECU reports wheel
//!   speeds and angles, vehicle status and (from the BMS) the battery to the ADS on bus 1;
//! - the plants: steering chains, wheel drives and brakes, battery, chassis.
//!
//! Every node is the same sans-IO node that runs on hardware; the buses are the bit-timed
//! simulation, so frame timing and bus load are real figures. Nothing reads a clock: a run
//! is a function of its parameters and seed.

use core::time::Duration;

use bywire_bus::sim::{NodeId, SimBus, Tamper};
use bywire_bus::Filtering;
use bywire_canopen::cia402::{self, Drive, Mode};
use bywire_canopen::device::Device;
use bywire_control::kinematics::{Point, Pose};
use bywire_control::metrics::{step_metrics, MetricsError, StepMetrics};
use bywire_control::path::{Geometry, Lookahead, Path, PurePursuit};
use bywire_core::filter::Filter;
use bywire_core::{Frame, Timestamp};
use bywire_tug::messages::{
    self, Battery as BatteryMessage, ControlMode, EmergencyStop, Gear, Imu, SteeringAngleSensors,
    SteeringMode, WheelEncoders,
};
use bywire_vehicle::ads::{Ads, AdsCommand};
use bywire_vehicle::command::{EstopCode, WatchdogLevel};
use bywire_vehicle::redundancy::Channel;
use bywire_vehicle::supervisor::{EstopState, Watchdog};
use bywire_vehicle::supervisor::{Redundancy, Supervisor};

use crate::battery::{Battery, BatteryParams};
use crate::chassis::{Chassis, ChassisParams, WheelInput};
use crate::drive::{DriveParams, WheelDrive};
use crate::rng::Rng;
use crate::steering::{SensorFault, SteeringChain, SteeringParams};
use bywire_core::node::Node;
use bywire_tug::ecu::{self, Geometry as EcuGeometry, StatusInputs, VehicleControlEcu};
use bywire_tug::wire::ReferenceWire;

/// One simulated millisecond.
pub const TICK: Duration = Duration::from_millis(1);

pub use bywire_tug::ecu::{DRIVE_NODES, MASTER_NODE, STEERING_NODES};
use bywire_tug::ecu::{DRIVE_UNITS_PER_M, STEERING_UNITS_PER_DEG};
/// The ADS's command frame (AdsToVehicle_Control in the reference DBC).
const ADS_COMMAND_ID: u16 = 0x100;

/// What a run is given.
#[derive(Debug, Clone, PartialEq)]
pub struct TugParams {
    /// Seed of every noise source.
    pub seed: u64,
    /// Payload, kg.
    pub payload: f64,
    /// Road grade (rise over run).
    pub grade: f64,
    /// The route, m (at least two points).
    pub route: Vec<Point>,
    /// Cruising speed, m/s.
    pub speed: f64,
    /// The last this many metres of the route in crab (a stand approach; 0: none).
    pub crab_final_m: f64,
    /// At the end of the route, a tank turn in place by this many degrees (+ left; 0: none).
    pub tank_turn_deg: f64,
    /// Once engaged, before it drives, the ADS steps the steering to each of these angles
    /// (degrees) in turn at a standstill, holding each for `STEP_HOLD` (the step test).
    pub steering_steps: Vec<f64>,
    /// Speeds along the route: (from this many metres on, m/s), by distance; before the
    /// first, `speed`.
    pub speeds: Vec<(f64, f64)>,
    /// Stops along the route: (at this many metres, for this long), by distance.
    pub stops: Vec<(f64, Duration)>,
}

/// The plain run: the apron loop at 3 m/s with 2 t of bags, level, nothing else asked for.
impl Default for TugParams {
    fn default() -> TugParams {
        TugParams {
            seed: 1,
            payload: 2_000.0,
            grade: 0.0,
            route: apron_loop(),
            speed: 3.0,
            crab_final_m: 0.0,
            tank_turn_deg: 0.0,
            steering_steps: Vec::new(),
            speeds: Vec::new(),
            stops: Vec::new(),
        }
    }
}

/// How long each steering step of the step test is held.
pub const STEP_HOLD: Duration = Duration::from_secs(3);

/// One steering step at a standstill: the ADS's command from `from` to `to` degrees and the
/// front-left wheel's angle every millisecond after it.
#[derive(Debug, Clone, PartialEq)]
pub struct StepResponse {
    /// The angle before, degrees.
    pub from: f64,
    /// The commanded angle, degrees.
    pub to: f64,
    /// Seconds since the command, one a millisecond.
    pub times: Vec<f64>,
    /// The wheel's angle at those times, degrees.
    pub angles: Vec<f64>,
}

impl StepResponse {
    /// Rise, settling, overshoot and steady-state error of this step.
    pub fn metrics(&self) -> Result<StepMetrics, MetricsError> {
        step_metrics(&self.times, &self.angles, self.from, self.to)
    }
}

/// One corner: its two drives (CiA 402 devices with the plant as their motor) and plants.
struct Corner {
    steer: Device<Drive>,
    drive: Device<Drive>,
    steer_port: NodeId,
    drive_port: NodeId,
    chain: SteeringChain,
    wheel: WheelDrive,
    distance: f64,
}

/// The tug's buses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TugBus {
    /// Vehicle control, 500 kbit/s.
    Bus1,
    /// CANopen drives, 1 Mbit/s.
    Bus2,
    /// Sensors, 500 kbit/s.
    Bus3,
    /// The redundant command bus, 500 kbit/s.
    Bus1b,
}

impl TugBus {
    /// Every bus.
    pub const ALL: [TugBus; 4] = [TugBus::Bus1, TugBus::Bus2, TugBus::Bus3, TugBus::Bus1b];

    /// Its name, as its log file and servers call it.
    pub fn name(self) -> &'static str {
        match self {
            TugBus::Bus1 => "bus1",
            TugBus::Bus2 => "bus2",
            TugBus::Bus3 => "bus3",
            TugBus::Bus1b => "bus1b",
        }
    }

    /// The bus of this name (`bus1`, `bus2`, `bus3`, `bus1b`).
    pub fn named(name: &str) -> Option<TugBus> {
        TugBus::ALL.into_iter().find(|b| b.name() == name)
    }
}

/// A frame seen on a bus, with its end-of-frame time.
pub type Logged = (Timestamp, Frame);

/// A fault (or operator action) a scenario injects.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fault {
    /// The ADS stops sending.
    AdsSilence,
    /// The E-stop chain opens (the safety controller requests an E-stop).
    Estop,
    /// The operator's reset: reset pressed until the latch clears, then engage.
    OperatorReset,
    /// A drive node (by node ID) stops sending (cut off, powered down).
    DriveSilence(u8),
    /// The angle sensor of a corner (0 FL … 3 RR) fails.
    SensorFault(usize, SensorFault),
    /// The ADS's commands arrive with a flipped bit (their checksum fails), on bus 1 and 1b.
    CorruptCommands,
    /// Every ADS command arrives twice, on bus 1 and 1b.
    DuplicateCommands,
    /// The ADS's commands arrive this many milliseconds late, on bus 1 and 1b.
    DelayCommands(u64),
    /// A driver turns the steering wheel (torque above the takeover threshold).
    DriverTakeover,
    /// The ECU's controller on bus 1 meets a burst of bus errors until it is bus-off; it
    /// recovers after 128 × 11 recessive bits.
    EcuBusOff,
    /// The node that sends this identifier on this bus meets the same burst, from its next
    /// frame of that identifier on, and recovers the same way.
    BusOff {
        /// The bus.
        bus: TugBus,
        /// An 11-bit identifier the node sends.
        id: u16,
    },
    /// Bus 1b, the redundant command bus, is cut: the ECU votes with bus 1 alone.
    RedundantBusLoss,
    /// Whichever node sends frames with this identifier on this bus sends them corrupted
    /// (a bit flipped), twice, or late (one such fault an identifier: the latest holds).
    TamperFrames {
        /// The bus.
        bus: TugBus,
        /// The 11-bit identifier.
        id: u16,
        /// What happens to them.
        tamper: Tamper,
    },
}

/// As in events and the live view: the variant's name, identifiers and node IDs in hex.
impl core::fmt::Display for Fault {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Fault::DriveSilence(node) => write!(f, "DriveSilence(0x{node:02X})"),
            Fault::TamperFrames { bus, id, tamper } => {
                write!(f, "TamperFrames {{ {} 0x{id:03X} {tamper:?} }}", bus.name())
            }
            Fault::BusOff { bus, id } => write!(f, "BusOff {{ {} 0x{id:03X} }}", bus.name()),
            other => write!(f, "{other:?}"),
        }
    }
}

/// The run's state every 50 ms, for plots.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// When.
    pub t: Timestamp,
    /// Pose.
    pub pose: Pose,
    /// Speed, m/s.
    pub speed: f64,
    /// The ADS's steering command, degrees.
    pub steering_command: f64,
    /// The front-left wheel's angle, degrees.
    pub steering_actual: f64,
    /// How long each bus (bus 1, 2, 3, 1b) has been busy since the start, ns.
    pub busy_ns: [u64; 4],
}

/// Each bus's load (bus 1, 2, 3, 1b; 0–1) over windows of `window` consecutive samples of
/// `trace`, stamped at each window's end: what the buses carried over the run.
pub fn windowed_loads(trace: &[Sample], window: usize) -> [Vec<(Timestamp, f64)>; 4] {
    let mut loads: [Vec<(Timestamp, f64)>; 4] = Default::default();
    let ends = trace.iter().step_by(window.max(1));
    for (from, to) in ends.clone().zip(ends.skip(1)) {
        let span = to.t.saturating_since(from.t).as_nanos() as f64;
        if span <= 0.0 {
            continue;
        }
        for (bus, series) in loads.iter_mut().enumerate() {
            let busy = |s: &Sample| s.busy_ns.get(bus).copied().unwrap_or(0);
            let load = busy(to).saturating_sub(busy(from)) as f64 / span;
            series.push((to.t, load));
        }
    }
    loads
}

/// Something that happened in a run.
#[derive(Debug, Clone, PartialEq)]
pub struct SimEvent {
    /// When.
    pub t: Timestamp,
    /// What kind (`watchdog`, `estop`, `mode`, `fault`, `heartbeat_lost`, ...).
    pub kind: String,
    /// Detail (the new state, the fault).
    pub detail: String,
}

/// The simulated tug.
pub struct Tug {
    now: Timestamp,
    bus1: SimBus,
    bus2: SimBus,
    bus3: SimBus,
    /// The redundant command bus: the ADS's frames again, voted on by the ECU.
    bus1b: SimBus,
    ads_port_b: NodeId,
    ecu_port_b: NodeId,
    log_port_b: NodeId,
    /// Frames on bus 1b.
    pub bus1b_log: Vec<Logged>,
    imu_port: NodeId,
    io_port: NodeId,
    ecu_port3: NodeId,
    log_port3: NodeId,
    bms_port: NodeId,
    next_report: Timestamp,
    report_counter: u64,
    /// Frames on bus 3.
    pub bus3_log: Vec<Logged>,
    ads_port: NodeId,
    ecu_port1: NodeId,
    ecu_port2: NodeId,
    log_port1: NodeId,
    log_port2: NodeId,
    ads: Ads<ReferenceWire>,
    ecu: VehicleControlEcu,
    corners: Vec<Corner>,
    chassis: Chassis,
    battery: Battery,
    rng: Rng,
    route: Vec<Point>,
    follower: PurePursuit,
    params: TugParams,
    next_ads: Timestamp,
    ads_cycles: u32,
    engaged_at: Option<Timestamp>,
    /// Frames on bus 1.
    pub bus1_log: Vec<Logged>,
    /// Frames on bus 2.
    pub bus2_log: Vec<Logged>,
    /// Cross-track error to the route at every ADS cycle, m.
    pub tracking_errors: Vec<f64>,
    /// What happened, in time order.
    pub events: Vec<SimEvent>,
    /// The state every 50 ms.
    pub trace: Vec<Sample>,
    steering_command: f64,
    /// Faults active until their end time (`None`: for good).
    active: Vec<(Fault, Option<Timestamp>)>,
    safety_port: NodeId,
    next_estop_frame: Timestamp,
    estop_counter: u64,
    /// The operator is resetting the E-stop latch (presses reset until it is released).
    resetting: bool,
    last_seen: (Watchdog, EstopState, ControlMode),
    last_degraded: Option<Channel>,
    ads_external: bool,
    /// The next stop to make, and the end of the dwell there once stopped.
    stop_index: usize,
    dwell_until: Option<Timestamp>,
    /// The steering mode the ADS last asked for.
    ads_steering_mode: SteeringMode,
    /// The step test: when the current step was commanded.
    step_started: Timestamp,
    /// The tank turn at the end, once started: the last heading seen and the angle turned.
    tank: Option<(f64, f64)>,
    tank_done: bool,
    /// The step test's responses, one a step.
    pub step_responses: Vec<StepResponse>,
    /// Command to heartbeat echo, as the ADS measured it on every state frame.
    pub echo_latencies: Vec<Duration>,
    remaining: f64,
}

fn drive_device(node: u8, mode: Mode) -> Device<Drive> {
    let mut od = cia402::drive_dictionary(node);
    let (velocity, acceleration) = match mode {
        // Steering: 20°/s, 60°/s².
        Mode::ProfilePosition | Mode::CyclicSynchronousPosition => (2_000, 6_000),
        // Wheels: 8 m/s, 1.5 m/s².
        Mode::ProfileVelocity | Mode::CyclicSynchronousVelocity => (8_000, 1_500),
    };
    let _ = od.set_int(cia402::object::MODES, 0, i64::from(mode.code()));
    let _ = od.set_int(cia402::object::PROFILE_VELOCITY, 0, velocity);
    let _ = od.set_int(cia402::object::PROFILE_ACCELERATION, 0, acceleration);
    let _ = od.set_int(cia402::object::PROFILE_DECELERATION, 0, acceleration);
    let _ = od.set_int(cia402::object::QUICK_STOP_DECELERATION, 0, acceleration * 2);
    // The actual values (TPDO2) sampled at every SYNC, so the master sees all eight drives
    // at one instant each cycle.
    let _ = od.set(0x1801, 2, &[1]);
    // Each drive watches the ECU's heartbeat: silence faults it.
    let _ = od.set(
        0x1016,
        1,
        &((u32::from(MASTER_NODE) << 16) | 300).to_le_bytes(),
    );
    Device::new(node, od, Drive::new().with_external_motor())
}

/// A drive's port on bus 2, with the acceptance filters its controller would have: NMT,
/// SYNC, the master's heartbeat, and what is addressed to its node ID (PDOs, SDO).
fn drive_port(bus: &mut SimBus, node: u8) -> NodeId {
    let port = bus.add_node();
    let exact = |id: u32| Filter::new(id, 0x7FF);
    bus.set_filtering(
        port,
        Filtering {
            filters: vec![
                exact(0x000),
                exact(0x080),
                exact(0x700 + u32::from(MASTER_NODE)),
                Filter::new(u32::from(node), 0x07F),
            ],
            ..Filtering::default()
        },
    );
    port
}

impl Tug {
    /// A tug at the start of its route, parked, everything powered on.
    pub fn new(params: TugParams) -> Tug {
        let loaded = bywire_tug::profile();
        let (ads_config, mut ecu_config) = match &loaded {
            Ok(l) => (l.ads_config(), l.supervisor_config()),
            Err(_) => (Default::default(), Default::default()),
        };
        // Commands come on bus 1 and bus 1b: a copy lost for three cycles leaves the other bus
        // alone (degraded, reported); copies that disagree are a fault.
        ecu_config.redundancy = Some(Redundancy {
            timeout: ecu_config.cycle.saturating_mul(3),
            skew: Duration::from_millis(5),
        });
        let mut bus1b = SimBus::new(500_000, None);
        let (ads_port_b, ecu_port_b, log_port_b) =
            (bus1b.add_node(), bus1b.add_node(), bus1b.add_node());
        let mut bus1 = SimBus::new(500_000, None);
        let mut bus2 = SimBus::new(1_000_000, None);
        let mut bus3 = SimBus::new(500_000, None);
        let (imu_port, ecu_port3, log_port3) = (bus3.add_node(), bus3.add_node(), bus3.add_node());
        let io_port = bus3.add_node();
        // Nodes that only send keep nothing they hear.
        for port in [imu_port, io_port] {
            bus3.set_rx_capacity(port, 0);
        }

        let (ads_port, ecu_port1, log_port1) = (bus1.add_node(), bus1.add_node(), bus1.add_node());
        let safety_port = bus1.add_node();
        let bms_port = bus1.add_node();
        for port in [safety_port, bms_port] {
            bus1.set_rx_capacity(port, 0);
        }
        let (ecu_port2, log_port2) = (bus2.add_node(), bus2.add_node());
        let corners = STEERING_NODES
            .iter()
            .zip(DRIVE_NODES)
            .map(|(steer, drive)| Corner {
                steer: drive_device(*steer, Mode::ProfilePosition),
                drive: drive_device(drive, Mode::ProfileVelocity),
                steer_port: drive_port(&mut bus2, *steer),
                drive_port: drive_port(&mut bus2, drive),
                chain: SteeringChain::new(SteeringParams::default()),
                wheel: WheelDrive::new(DriveParams::default()),
                distance: 0.0,
            })
            .collect();
        let chassis_params = ChassisParams {
            payload: params.payload,
            ..ChassisParams::default()
        };
        let start = match params.route.as_slice() {
            [a, b, ..] => Pose {
                x: a.x,
                y: a.y,
                yaw: libm::atan2(b.y - a.y, b.x - a.x),
            },
            _ => Pose::default(),
        };
        Tug {
            now: Timestamp::ZERO,
            bus1,
            bus2,
            bus3,
            bus1b,
            ads_port_b,
            ecu_port_b,
            log_port_b,
            bus1b_log: Vec::new(),
            last_degraded: None,
            imu_port,
            io_port,
            ecu_port3,
            log_port3,
            bms_port,
            next_report: Timestamp::ZERO,
            report_counter: 0,
            bus3_log: Vec::new(),
            ads_port,
            ecu_port1,
            ecu_port2,
            log_port1,
            log_port2,
            ads: Ads::with_wire(ads_config, ReferenceWire),
            ecu: VehicleControlEcu::new(
                ecu_config,
                EcuGeometry {
                    wheelbase: chassis_params.wheelbase,
                    track: chassis_params.track,
                },
            ),
            corners,
            chassis: Chassis::new(chassis_params, start),
            battery: Battery::new(BatteryParams::default(), 0.8),
            rng: Rng::new(params.seed),
            route: params.route.clone(),
            follower: PurePursuit {
                lookahead: Lookahead {
                    min: 3.0,
                    max: 8.0,
                    time: 1.5,
                },
                geometry: Geometry::CounterPhase {
                    wheelbase: chassis_params.wheelbase,
                    rear_ratio: 1.0,
                },
                max_steer: 35f64.to_radians(),
            },
            params,
            next_ads: Timestamp::ZERO,
            ads_cycles: 0,
            engaged_at: None,
            bus1_log: Vec::new(),
            bus2_log: Vec::new(),
            tracking_errors: Vec::new(),
            events: Vec::new(),
            trace: Vec::new(),
            steering_command: 0.0,
            active: Vec::new(),
            safety_port,
            next_estop_frame: Timestamp::ZERO,
            estop_counter: 0,
            resetting: false,
            last_seen: (
                Watchdog::FullBraking,
                EstopState::Normal,
                ControlMode::Manual,
            ),
            ads_external: false,
            stop_index: 0,
            dwell_until: None,
            ads_steering_mode: SteeringMode::Normal,
            step_started: Timestamp::ZERO,
            tank: None,
            tank_done: false,
            step_responses: Vec::new(),
            echo_latencies: Vec::new(),
            remaining: f64::INFINITY,
        }
    }

    fn sim_bus(&mut self, bus: TugBus) -> &mut SimBus {
        match bus {
            TugBus::Bus1 => &mut self.bus1,
            TugBus::Bus2 => &mut self.bus2,
            TugBus::Bus3 => &mut self.bus3,
            TugBus::Bus1b => &mut self.bus1b,
        }
    }

    /// Set (`on`) or mend the faults that are frames tampered with on their way; others are
    /// left alone.
    fn set_tampering(&mut self, fault: Fault, on: bool) {
        // The ADS's commands on both buses that carry them, as a faulty ADS would send them.
        const COMMAND_BUSES: [TugBus; 2] = [TugBus::Bus1, TugBus::Bus1b];
        let (buses, id, tamper): (&[TugBus], u16, Tamper) = match &fault {
            Fault::CorruptCommands => (&COMMAND_BUSES, ADS_COMMAND_ID, Tamper::FlipBit),
            Fault::DuplicateCommands => (&COMMAND_BUSES, ADS_COMMAND_ID, Tamper::Duplicate),
            Fault::DelayCommands(ms) => (
                &COMMAND_BUSES,
                ADS_COMMAND_ID,
                Tamper::Delay(Duration::from_millis(*ms)),
            ),
            Fault::TamperFrames { bus, id, tamper } => (core::slice::from_ref(bus), *id, *tamper),
            _ => return,
        };
        let Ok(id) = bywire_core::Id::standard(u32::from(id)) else {
            return;
        };
        for bus in buses {
            self.sim_bus(*bus).tamper(id, on.then_some(tamper));
        }
    }

    /// A port on `bus` for a node outside the tug (a tool that watches and injects): it hears
    /// every frame the others send, and what it sends goes on the bus.
    pub fn attach(&mut self, bus: TugBus) -> NodeId {
        self.sim_bus(bus).add_node()
    }

    /// Send `frame` on `bus` from `port` (from [`Tug::attach`]).
    pub fn send(&mut self, bus: TugBus, port: NodeId, frame: Frame) {
        let now = self.now;
        self.sim_bus(bus).submit(port, frame, now);
    }

    /// The next frame `bus` delivered to `port`.
    pub fn receive(&mut self, bus: TugBus, port: NodeId) -> Option<(Timestamp, Frame)> {
        self.sim_bus(bus)
            .receive(port)
            .map(|r| (r.timestamp, r.frame))
    }

    /// Replace the built-in ADS by a node outside the tug on bus 1 (acceptance checks, another
    /// ADS): the built-in one stops, and the returned port sends and receives for the outsider.
    pub fn attach_ads(&mut self) -> NodeId {
        self.ads_external = true;
        self.attach(TugBus::Bus1)
    }

    /// Send `frame` on bus 1 from `port` (from [`Tug::attach_ads`]), and its copy on bus 1b
    /// (unless cut), as the built-in ADS does.
    pub fn send_bus1(&mut self, port: NodeId, frame: Frame) {
        self.bus1.submit(port, frame, self.now);
        if !self.is_active(Fault::RedundantBusLoss) {
            self.bus1b.submit(self.ads_port_b, frame, self.now);
        }
    }

    /// The next frame bus 1 delivered to `port`.
    pub fn receive_bus1(&mut self, port: NodeId) -> Option<(Timestamp, Frame)> {
        self.receive(TugBus::Bus1, port)
    }

    /// Inject `fault` now, for `duration` (`None`: for good).
    pub fn inject(&mut self, fault: Fault, duration: Option<Duration>) {
        let now = self.now;
        self.record("fault", fault.to_string());
        match fault {
            Fault::SensorFault(corner, sensor) => {
                if let Some(c) = self.corners.get_mut(corner) {
                    c.chain.set_fault(sensor);
                }
            }
            Fault::OperatorReset => {
                self.resetting = true;
                // ... at the ECU too: drives the master stopped acknowledged, a steering fault
                // whose sensor tracks agree again cleared.
                self.ecu.operator_reset(now);
                self.take_ecu_events();
            }
            Fault::EcuBusOff => self.bus1.take_off_bus(Some(self.ecu_port1), None),
            Fault::BusOff { bus, id } => {
                if let Ok(id) = bywire_core::Id::standard(u32::from(id)) {
                    self.sim_bus(bus).take_off_bus(None, Some(id));
                }
            }
            Fault::CorruptCommands
            | Fault::DuplicateCommands
            | Fault::DelayCommands(_)
            | Fault::TamperFrames { .. } => self.set_tampering(fault, true),
            Fault::AdsSilence
            | Fault::Estop
            | Fault::DriveSilence(_)
            | Fault::RedundantBusLoss
            | Fault::DriverTakeover => {}
        }
        self.active
            .push((fault, duration.map(|d| now.saturating_add(d))));
    }

    fn is_active(&self, fault: Fault) -> bool {
        self.active.iter().any(|(f, _)| *f == fault)
    }

    /// The steering fault the ECU's plausibility check latched, if any.
    pub fn steering_fault(&self) -> Option<bywire_tug::plausibility::SteeringFault> {
        self.ecu.steering_fault()
    }

    /// The route is done: engaged, at its end, stopped, and the tank turn (if any) made.
    pub fn arrived(&self) -> bool {
        self.engaged_at.is_some()
            && self.remaining < 0.5
            && self.pose_speed() < 0.01
            && (self.params.tank_turn_deg == 0.0 || self.tank_done)
    }

    /// The ADS's speed at `station` (`remaining` to go): the speed of the route there,
    /// slowing in time for lower speeds ahead, for the next stop and for the end
    /// (v² = v_next² + 2·a·d with a gentle 0.5 m/s²); nothing while it dwells at a stop.
    fn speed_target(&mut self, now: Timestamp, station: f64, remaining: f64, speed: f64) -> f64 {
        let approach = |v_next: f64, distance: f64| {
            libm::sqrt(v_next * v_next + 2.0 * 0.5 * distance.max(0.0))
        };
        let speeds = &self.params.speeds;
        let here = speeds
            .iter()
            .rev()
            .find(|(from, _)| *from <= station)
            .map_or(self.params.speed, |(_, v)| *v);
        let target = speeds
            .iter()
            .filter(|(from, _)| *from > station)
            .fold(here.min(approach(0.0, remaining)), |v, (from, next)| {
                v.min(approach(*next, from - station))
            });
        let Some(&(at, dwell)) = self.params.stops.get(self.stop_index) else {
            return target;
        };
        match self.dwell_until {
            Some(until) if now < until => 0.0,
            Some(_) => {
                self.dwell_until = None;
                self.stop_index += 1;
                self.record("depart", format!("from the stop at {at:.1} m"));
                target
            }
            None if at - station < 0.3 && speed.abs() < 0.05 => {
                self.dwell_until = Some(now.saturating_add(dwell));
                self.record(
                    "stop",
                    format!("at {at:.1} m for {:.1} s", dwell.as_secs_f64()),
                );
                0.0
            }
            None => target.min(approach(0.0, at - station)),
        }
    }

    /// The step test's angle while it runs; a step is recorded as it is first commanded.
    fn step_target(&mut self, now: Timestamp) -> Option<f64> {
        let engaged = self.engaged_at?;
        let index =
            usize::try_from(now.saturating_since(engaged).as_nanos() / STEP_HOLD.as_nanos())
                .ok()?;
        let to = *self.params.steering_steps.get(index)?;
        if self.step_responses.len() == index {
            let from = index
                .checked_sub(1)
                .and_then(|before| self.params.steering_steps.get(before))
                .copied()
                .unwrap_or(0.0);
            self.step_responses.push(StepResponse {
                from,
                to,
                times: Vec::new(),
                angles: Vec::new(),
            });
            self.step_started = now;
        }
        Some(to)
    }

    /// The step test's record: the front-left wheel every millisecond of the current step.
    fn record_step(&mut self, now: Timestamp) {
        if now >= self.step_started.saturating_add(STEP_HOLD) {
            return;
        }
        let angle = self.corners.first().map(|c| c.chain.wheel_angle_deg());
        if let (Some(response), Some(angle)) = (self.step_responses.last_mut(), angle) {
            let since = now.saturating_since(self.step_started);
            response.times.push(since.as_secs_f64());
            response.angles.push(angle);
        }
    }

    /// The tank turn at the end of the route: the wheel speed to command while it runs.
    fn tank_turn(&mut self, remaining: f64, yaw: f64) -> Option<f64> {
        let wanted = self.params.tank_turn_deg.to_radians();
        if wanted == 0.0 || self.tank_done || self.engaged_at.is_none() || remaining >= 0.3 {
            return None;
        }
        let (last_yaw, turned) = match self.tank {
            Some(tank) => tank,
            None if self.pose_speed() < 0.01 => (yaw, 0.0),
            None => return None,
        };
        let turned = turned + libm::remainder(yaw - last_yaw, 2.0 * core::f64::consts::PI);
        self.tank = Some((yaw, turned));
        let left = wanted - turned;
        if libm::fabs(left) < 0.5f64.to_radians() {
            self.tank_done = true;
            return None;
        }
        // The wheels turn to their tank angles first, then the tug rotates.
        let aligned = self
            .corners
            .iter()
            .zip(&self.ecu.wheel_targets())
            .all(|(c, t)| libm::fabs(c.chain.wheel_angle_deg() - t.angle.to_degrees()) < 3.0);
        if !aligned {
            return Some(0.0);
        }
        let c = self.chassis.params;
        let radius = libm::hypot(c.wheelbase / 2.0, c.track / 2.0);
        // Slow to a stop on the heading: ω² = 2·α·θ with a gentle 0.3 rad/s².
        let rate = libm::sqrt(2.0 * 0.3 * libm::fabs(left)).min(0.5);
        Some(libm::copysign(rate * radius, left))
    }

    fn record(&mut self, kind: &str, detail: String) {
        self.events.push(SimEvent {
            t: self.now,
            kind: kind.to_string(),
            detail,
        });
    }

    /// Simulated time.
    pub fn now(&self) -> Timestamp {
        self.now
    }

    /// Where the tug is.
    pub fn pose(&self) -> Pose {
        self.chassis.pose()
    }

    /// The four wheels' angles (FL, FR, RL, RR), degrees.
    pub fn wheel_angles(&self) -> [f64; 4] {
        let mut angles = [0.0; 4];
        for (angle, corner) in angles.iter_mut().zip(&self.corners) {
            *angle = corner.chain.wheel_angle_deg();
        }
        angles
    }

    /// The route, m.
    pub fn route(&self) -> &[Point] {
        &self.route
    }

    /// Faults active now.
    pub fn active_faults(&self) -> impl Iterator<Item = Fault> + '_ {
        self.active.iter().map(|(fault, _)| *fault)
    }

    /// The tug's speed, m/s.
    pub fn pose_speed(&self) -> f64 {
        libm::hypot(self.chassis.twist().vx, self.chassis.twist().vy)
    }

    /// The vehicle control ECU's supervisor.
    pub fn ecu(&self) -> &Supervisor<ReferenceWire> {
        self.ecu.supervisor()
    }

    /// The route's remaining distance from the tug's projection at the last ADS cycle, m.
    pub fn remaining(&self) -> f64 {
        self.remaining
    }

    /// When the vehicle first reported autonomous mode to the ADS.
    pub fn engaged_at(&self) -> Option<Timestamp> {
        self.engaged_at
    }

    /// The battery's state of charge.
    pub fn soc(&self) -> f64 {
        self.battery.soc()
    }

    /// Bus loads over the run so far: busy time over elapsed time, buses 1, 2, 3 and 1b.
    #[allow(clippy::cast_precision_loss)]
    pub fn bus_loads(&self) -> [f64; 4] {
        let elapsed = self.now.as_nanos().max(1) as f64;
        self.busy_ns().map(|busy| busy as f64 / elapsed)
    }

    /// How long each bus (1, 2, 3, 1b) has been busy since the start, ns.
    fn busy_ns(&self) -> [u64; 4] {
        [
            self.bus1.busy_ns(),
            self.bus2.busy_ns(),
            self.bus3.busy_ns(),
            self.bus1b.busy_ns(),
        ]
    }

    /// One millisecond.
    pub fn step(&mut self) {
        let now = self.now.saturating_add(TICK);
        self.now = now;
        self.bus1.advance(now);
        self.bus2.advance(now);
        self.bus3.advance(now);
        self.bus1b.advance(now);
        let expired: Vec<Fault> = self
            .active
            .iter()
            .filter(|(_, end)| end.is_some_and(|end| now >= end))
            .map(|(f, _)| *f)
            .collect();
        for fault in expired {
            match fault {
                Fault::SensorFault(corner, _) => {
                    if let Some(c) = self.corners.get_mut(corner) {
                        c.chain.set_fault(SensorFault::None);
                    }
                }
                _ => self.set_tampering(fault, false),
            }
            self.record("fault_cleared", fault.to_string());
        }
        self.active
            .retain(|(_, end)| end.is_none_or(|end| now < end));
        self.deliver();
        self.run_safety(now);
        self.run_ads(now);
        self.run_ecu(now);
        self.run_plants(now);
        self.run_reports(now);
        self.record_step(now);
        self.note_changes();
        if now.as_nanos().is_multiple_of(50_000_000) {
            let steering_actual = self
                .corners
                .first()
                .map_or(0.0, |c| c.chain.wheel_angle_deg());
            self.trace.push(Sample {
                t: now,
                pose: self.chassis.pose(),
                speed: self.pose_speed(),
                steering_command: self.steering_command,
                steering_actual,
                busy_ns: self.busy_ns(),
            });
        }
    }

    /// The periodic reports of the sensor nodes: the IMU and the I/O node on bus 3 every
    /// 10 ms, the BMS on bus 1 every 100 ms (the ECU reports on its own).
    fn run_reports(&mut self, now: Timestamp) {
        if now < self.next_report {
            return;
        }
        self.next_report = now.saturating_add(Duration::from_millis(10));
        let counter = self.report_counter;
        self.report_counter = self.report_counter.wrapping_add(1);
        let (yaw_rate, accel) = self.chassis.imu(TICK.as_secs_f64(), &mut self.rng);
        let mut imu = Imu::default();
        let _ = imu.set_yaw_rate(yaw_rate.to_degrees().clamp(-327.0, 327.0));
        let _ = imu.set_accel_x(accel.clamp(-32.0, 32.0));
        imu.set_counter_raw(counter & 0x0F);
        self.bus3
            .submit(self.imu_port, messages::sealed_frame(Imu::ID, imu.0), now);
        // The I/O node: the hub encoders and the steering sensors' second tracks.
        let mut encoders = WheelEncoders::default();
        let [fl, fr, rl, rr] = self.chassis.encoders(0.01).map(|v| v.clamp(-20.0, 20.0));
        let _ = (
            encoders.set_encoder_speed_fl(fl),
            encoders.set_encoder_speed_fr(fr),
            encoders.set_encoder_speed_rl(rl),
            encoders.set_encoder_speed_rr(rr),
        );
        encoders.set_counter_raw(counter & 0x0F);
        let mut second = SteeringAngleSensors::default();
        let mut tracks = [0.0; 4];
        for (track, corner) in tracks.iter_mut().zip(&self.corners) {
            *track = corner
                .chain
                .second_track_deg(&mut self.rng)
                .clamp(-200.0, 200.0);
        }
        let [fl, fr, rl, rr] = tracks;
        let _ = (
            second.set_second_angle_fl(fl),
            second.set_second_angle_fr(fr),
            second.set_second_angle_rl(rl),
            second.set_second_angle_rr(rr),
        );
        second.set_counter_raw(counter & 0x0F);
        for (id, payload) in [
            (WheelEncoders::ID, encoders.0),
            (SteeringAngleSensors::ID, second.0),
        ] {
            self.bus3
                .submit(self.io_port, messages::sealed_frame(id, payload), now);
        }
        if counter.is_multiple_of(10) {
            let mut m = BatteryMessage::default();
            let _ = m.set_battery_voltage(self.battery.terminal_v().clamp(0.0, 120.0));
            let _ = m.set_battery_current(self.battery.current().clamp(-1000.0, 1000.0));
            let _ = m.set_state_of_charge((self.battery.soc() * 100.0).clamp(0.0, 100.0));
            m.set_counter_raw((counter / 10) & 0x0F);
            self.bus1.submit(
                self.bms_port,
                messages::sealed_frame(BatteryMessage::ID, m.0),
                now,
            );
        }
    }

    /// The safety controller: the E-stop chain's state every 20 ms.
    fn run_safety(&mut self, now: Timestamp) {
        if now < self.next_estop_frame {
            return;
        }
        self.next_estop_frame = now.saturating_add(Duration::from_millis(20));
        let mut m = EmergencyStop::default();
        m.set_estop_request_raw(u64::from(self.is_active(Fault::Estop)));
        m.set_counter_raw(self.estop_counter & 0x0F);
        self.estop_counter = self.estop_counter.wrapping_add(1);
        self.bus1.submit(
            self.safety_port,
            messages::sealed_frame(EmergencyStop::ID, m.0),
            now,
        );
    }

    /// Who is at `port` on `bus`: an ECU, a drive by node ID, ... or a port from
    /// [`Tug::attach`].
    pub fn port_name(&self, bus: TugBus, port: NodeId) -> String {
        let named: &[(NodeId, &str)] = match bus {
            TugBus::Bus1 => &[
                (self.ads_port, "ADS"),
                (self.ecu_port1, "ECU"),
                (self.safety_port, "safety controller"),
                (self.bms_port, "BMS"),
                (self.log_port1, "logger"),
            ],
            TugBus::Bus1b => &[
                (self.ads_port_b, "ADS"),
                (self.ecu_port_b, "ECU"),
                (self.log_port_b, "logger"),
            ],
            TugBus::Bus2 => &[
                (self.ecu_port2, "ECU (CANopen master)"),
                (self.log_port2, "logger"),
            ],
            TugBus::Bus3 => &[
                (self.imu_port, "IMU"),
                (self.io_port, "I/O node"),
                (self.ecu_port3, "ECU"),
                (self.log_port3, "logger"),
            ],
        };
        let named = named.iter().find(|(p, _)| *p == port);
        if let Some((_, name)) = named {
            return name.to_string();
        }
        let drive = self
            .corners
            .iter()
            .zip(STEERING_NODES.iter().zip(DRIVE_NODES))
            .find_map(|(corner, (steer, drive))| {
                if corner.steer_port == port {
                    Some(*steer)
                } else if corner.drive_port == port {
                    Some(drive)
                } else {
                    None
                }
            });
        match drive {
            Some(node) if bus == TugBus::Bus2 => format!("drive 0x{node:02X}"),
            _ => format!("port {port}"),
        }
    }

    /// Record the supervisor's state changes, bus state changes and the master's heartbeat
    /// events.
    fn note_changes(&mut self) {
        let mut changes = Vec::new();
        for bus in TugBus::ALL {
            for event in self.sim_bus(bus).drain_events() {
                if let bywire_bus::sim::BusEvent::StateChanged { node, state, .. } = event {
                    changes.push((bus, node, state));
                }
            }
        }
        for (bus, node, state) in changes {
            let detail = format!("{} {}: {state:?}", bus.name(), self.port_name(bus, node));
            self.record("bus_state", detail);
        }
        let supervisor = self.ecu.supervisor();
        let seen = (supervisor.watchdog(), supervisor.estop(), supervisor.mode());
        let (watchdog, estop, mode) = self.last_seen;
        if core::mem::discriminant(&seen.0) != core::mem::discriminant(&watchdog) {
            self.record("watchdog", watchdog_name(seen.0).to_string());
        }
        if seen.1 != estop {
            self.record("estop", format!("{:?}", seen.1));
        }
        if seen.2 != mode {
            self.record("mode", format!("{:?}", seen.2));
        }
        self.last_seen = seen;
        let degraded = self.ecu.supervisor().degraded();
        if degraded != self.last_degraded {
            self.last_degraded = degraded;
            let detail = match degraded {
                Some(Channel::A) => "bus 1 alone (bus 1b lost)",
                Some(Channel::B) => "bus 1b alone (bus 1 lost)",
                None => "both buses agree",
            };
            self.record("redundancy", detail.to_string());
        }
        self.take_ecu_events();
    }

    /// The ECU's events into the run's.
    fn take_ecu_events(&mut self) {
        // Bounded by the ECU's event queue.
        while let Some((_, event)) = self.ecu.next_event() {
            self.record(event.kind(), event.to_string());
        }
    }

    fn deliver(&mut self) {
        while let Some(r) = self.bus1.receive(self.ads_port) {
            let before = self.ads.state().echo_latency.at;
            self.ads.on_frame(r.timestamp, &r.frame);
            let echo = self.ads.state().echo_latency;
            if echo.at != before {
                self.echo_latencies.extend(echo.value);
            }
        }
        while let Some(r) = self.bus1.receive(self.ecu_port1) {
            self.ecu.on_frame(r.timestamp, ecu::BUS1, &r.frame);
        }
        while let Some(r) = self.bus1.receive(self.log_port1) {
            self.bus1_log.push((r.timestamp, r.frame));
        }
        while let Some(r) = self.bus1b.receive(self.ecu_port_b) {
            self.ecu.on_frame(r.timestamp, ecu::BUS1B, &r.frame);
        }
        while let Some(r) = self.bus1b.receive(self.log_port_b) {
            self.bus1b_log.push((r.timestamp, r.frame));
        }
        while self.bus1b.receive(self.ads_port_b).is_some() {}
        while let Some(r) = self.bus2.receive(self.ecu_port2) {
            self.ecu.on_frame(r.timestamp, ecu::BUS2, &r.frame);
        }
        while let Some(r) = self.bus2.receive(self.log_port2) {
            self.bus2_log.push((r.timestamp, r.frame));
        }
        while let Some(r) = self.bus3.receive(self.log_port3) {
            self.bus3_log.push((r.timestamp, r.frame));
        }
        // The ECU takes the steering sensors' second tracks from bus 3 (the IMU and encoders are
        // logged; the ADS localises itself).
        while let Some(r) = self.bus3.receive(self.ecu_port3) {
            self.ecu.on_frame(r.timestamp, ecu::BUS3, &r.frame);
        }
        for corner in &mut self.corners {
            while let Some(r) = self.bus2.receive(corner.steer_port) {
                corner.steer.on_frame(r.timestamp, &r.frame);
            }
            while let Some(r) = self.bus2.receive(corner.drive_port) {
                corner.drive.on_frame(r.timestamp, &r.frame);
            }
        }
    }

    /// The ADS: every 20 ms, pure pursuit on the route from the tug's pose, at cruising speed
    /// slowing to a stop at the end; engaged once the vehicle answers.
    fn run_ads(&mut self, now: Timestamp) {
        if self.ads_external {
            return;
        }
        if now >= self.next_ads {
            self.next_ads = now.saturating_add(Duration::from_millis(20));
            let pose = self.chassis.pose();
            let speed = self.chassis.twist().vx;
            let crab = self.remaining < self.params.crab_final_m;
            let (steering, error, remaining, station) = match Path::new(&self.route) {
                Some(path) => {
                    let projection = path.project(Point {
                        x: pose.x,
                        y: pose.y,
                    });
                    let steering = if crab {
                        // The stand approach in crab: every wheel toward the point a lookahead
                        // ahead on the route, the heading held.
                        let ahead =
                            path.at_station(projection.station + self.follower.lookahead.at(speed));
                        let bearing = libm::atan2(ahead.y - pose.y, ahead.x - pose.x) - pose.yaw;
                        libm::atan2(libm::sin(bearing), libm::cos(bearing))
                            .clamp(-self.follower.max_steer, self.follower.max_steer)
                            .to_degrees()
                    } else {
                        self.follower.steer(pose, speed, &path).front.to_degrees()
                    };
                    (
                        steering,
                        projection.offset.abs(),
                        path.length() - projection.station,
                        projection.station,
                    )
                }
                None => (0.0, 0.0, 0.0, 0.0),
            };
            self.remaining = remaining;
            if self.engaged_at.is_some() {
                self.tracking_errors.push(error);
            }
            let target = self.speed_target(now, station, remaining, speed);
            let velocity = if remaining < 0.3 || self.engaged_at.is_none() {
                0.0
            } else {
                target
            };
            // The step test comes first, the tank turn last; after it the tug stands in normal
            // mode.
            let step = self.step_target(now);
            let tank = self.tank_turn(remaining, pose.yaw);
            let (steering, velocity, mode) = match (step, tank) {
                (Some(angle), _) => (angle, 0.0, SteeringMode::Normal),
                (None, Some(wheel_speed)) => (0.0, wheel_speed, SteeringMode::Tank),
                (None, None) if crab && !self.tank_done => (steering, velocity, SteeringMode::Crab),
                (None, None) => (steering, velocity, SteeringMode::Normal),
            };
            if mode != self.ads_steering_mode {
                self.ads_steering_mode = mode;
                self.record("steering_mode", format!("{mode:?}"));
            }
            // Engage is an edge, taken once the vehicle's recovery run is complete: request it
            // every tenth cycle until the vehicle reports autonomous mode.
            self.ads_cycles = self.ads_cycles.wrapping_add(1);
            // (Watchdog level 4: the vehicle waits for a re-engage after full braking.)
            let state = self.ads.state();
            let autonomous = state.mode.value == Some(ControlMode::Autonomous);
            let awaiting = state.watchdog_level.value == Some(WatchdogLevel::AwaitingEngage);
            let engage = self.ads.feedback_alive(now)
                && (!autonomous || awaiting)
                && self.ads_cycles.is_multiple_of(10);
            if autonomous && self.engaged_at.is_none() {
                self.engaged_at = Some(now);
            }
            self.steering_command = steering;
            // The operator presses reset (an edge, every half second) while the latch is
            // stopped or waiting for the confirming press, until the vehicle reports it clear.
            let estop = self.ads.state().estop_state.value;
            if estop == Some(EstopCode::Normal) && self.resetting && autonomous {
                self.resetting = false;
            }
            let operator_reset = self.resetting
                && estop.is_some_and(EstopCode::awaits_operator_reset)
                && self.ads_cycles.is_multiple_of(25);
            let command = AdsCommand {
                steering,
                velocity,
                brake: if velocity == 0.0 { 30.0 } else { 0.0 },
                gear: Gear::Drive,
                mode: ControlMode::Autonomous,
                steering_mode: mode,
                engage,
                operator_reset,
            };
            let _ = self.ads.set_command(now, command);
        }
        // A silent ADS sends nothing; corrupted, duplicated and delayed commands are the
        // buses' doing (set_tampering).
        let silent = self.is_active(Fault::AdsSilence);
        let mut sent = Vec::new();
        self.ads.poll(now, &mut |f| sent.push(f));
        if !silent {
            for frame in sent {
                self.send_ads(frame);
            }
        }
    }

    /// The built-in ADS sends on bus 1 and on bus 1b.
    fn send_ads(&mut self, frame: Frame) {
        let port = self.ads_port;
        self.send_bus1(port, frame);
    }

    /// The vehicle control ECU node, its inputs from the wiring set first (a driver's hand on
    /// the wheel, the hardwired E-stop chain, the parking brakes), its frames onto its buses.
    fn run_ecu(&mut self, now: Timestamp) {
        let takeover = if self.is_active(Fault::DriverTakeover) {
            8.0
        } else {
            0.0
        };
        self.ecu.set_driver_input(takeover, 0.0);
        self.ecu.set_status_inputs(StatusInputs {
            estop_chain_open: self.is_active(Fault::Estop),
            parking_brake_applied: self.corners.iter().any(|c| c.wheel.is_parked()),
        });
        let (bus1, bus2) = (&mut self.bus1, &mut self.bus2);
        let (port1, port2) = (self.ecu_port1, self.ecu_port2);
        self.ecu.poll(now, &mut |port, frame| match port {
            ecu::BUS1 => bus1.submit(port1, frame, now),
            ecu::BUS2 => bus2.submit(port2, frame, now),
            _ => {}
        });
    }

    /// The drives' devices and the plants they move.
    fn run_plants(&mut self, now: Timestamp) {
        let dt = TICK.as_secs_f64();
        let a = self.ecu.actuators(now);
        let rolling = self.chassis.twist().vx.abs() > 0.05;
        let speeds = self.chassis.wheel_speeds();
        let soc = self.battery.soc();
        let mut inputs = [WheelInput::default(); 4];
        let mut power = 0.0;
        let active = &self.active;
        let brake = self.ecu.brake_demand(now);
        for ((corner, input), speed) in self.corners.iter_mut().zip(inputs.iter_mut()).zip(speeds) {
            let steer_silent = active
                .iter()
                .any(|(f, _)| *f == Fault::DriveSilence(corner.steer.node()));
            let drive_silent = active
                .iter()
                .any(|(f, _)| *f == Fault::DriveSilence(corner.drive.node()));
            let (bus, steer_port, drive_port) =
                (&mut self.bus2, corner.steer_port, corner.drive_port);
            corner.steer.poll(now, &mut |f| {
                if !steer_silent {
                    bus.submit(steer_port, f, now);
                }
            });
            corner.drive.poll(now, &mut |f| {
                if !drive_silent {
                    bus.submit(drive_port, f, now);
                }
            });
            // Steering: the drive's velocity demand is the valve shaft's speed command.
            let max_rate = 19.0 * STEERING_UNITS_PER_DEG;
            let command = corner.steer.app().demand() / max_rate;
            let before = corner.chain.wheel_angle_deg();
            corner.chain.step(dt, command, rolling);
            let reading = corner.chain.sensor_deg(&mut self.rng);
            let rate = (corner.chain.wheel_angle_deg() - before) / dt;
            corner.steer.app_mut().0.set_actual(
                reading * STEERING_UNITS_PER_DEG,
                rate * STEERING_UNITS_PER_DEG,
            );
            // Drive: the drive's velocity demand is the motor controller's setpoint.
            let setpoint = corner.drive.app().demand() / DRIVE_UNITS_PER_M;
            let output = corner.wheel.motor(setpoint, speed, soc);
            corner
                .wheel
                .set_parked(!a.motors_enabled && speed.abs() < 0.05);
            corner.wheel.step_brake(dt, brake);
            power += output.power;
            corner.distance += speed * dt;
            corner.drive.app_mut().0.set_actual(
                corner.distance * DRIVE_UNITS_PER_M,
                speed * DRIVE_UNITS_PER_M,
            );
            *input = WheelInput {
                angle_deg: corner.chain.wheel_angle_deg(),
                drive_torque: output.torque,
                brake_torque: corner.wheel.holding_torque(),
            };
        }
        self.chassis.step(dt, &inputs, self.params.grade);
        self.battery.step(dt, power);
    }
}

/// The built-in `apron-loop` route: out along the stand row, a 15 m turn, up the service
/// road, a second turn and back toward the start (about 140 m).
pub fn apron_loop() -> Vec<Point> {
    let mut points: Vec<Point> = (0..=40)
        .map(|x| Point {
            x: f64::from(x),
            y: 0.0,
        })
        .collect();
    let arc = |cx: f64, cy: f64, from: f64, points: &mut Vec<Point>| {
        for k in 1..=24 {
            let a = from + f64::from(k) / 24.0 * core::f64::consts::PI;
            points.push(Point {
                x: cx + 15.0 * libm::cos(a),
                y: cy + 15.0 * libm::sin(a),
            });
        }
    };
    // A half circle to the left brings the route back parallel, 30 m over.
    arc(40.0, 15.0, -core::f64::consts::FRAC_PI_2, &mut points);
    for x in (10..40).rev() {
        points.push(Point {
            x: f64::from(x),
            y: 30.0,
        });
    }
    points
}

fn watchdog_name(watchdog: Watchdog) -> &'static str {
    match watchdog {
        Watchdog::Normal => "normal",
        Watchdog::Holding { .. } => "holding",
        Watchdog::Decelerating { .. } => "decelerating",
        Watchdog::FullBraking => "full_braking",
        Watchdog::Recovering { .. } => "recovering",
    }
}
