//! The simulated tug: its nodes wired to its four bit-timed buses on the simulated runner
//! ([`bywire_net::network::Network`]), its plants stepped every millisecond between them.
//!
//! - bus 1 (vehicle control, 500 kbit/s): the built-in ADS ([`crate::mission::AdsDriver`]),
//!   the vehicle control ECU ([`bywire_tug::ecu::VehicleControlEcu`]), the safety controller and
//!   the BMS ([`crate::nodes`]);
//! - bus 1b (the redundant command bus): the ADS's second copy of every command, voted on by
//!   the ECU;
//! - bus 2 (drives, CANopen, 1 Mbit/s): the ECU as NMT master of four steering drives and four
//!   wheel drives (CiA 402 devices whose motors are the plants), with their controllers'
//!   acceptance filters; on the redundant tug, four backup steering valve drivers too;
//! - bus 3 (sensors, 500 kbit/s): the IMU and the I/O node (hub encoders, the steering
//!   sensors' second tracks);
//! - the plants: steering chains (on the redundant tug with a backup valve in parallel),
//!   wheel drives and brakes, battery, chassis.
//!
//! This file is wiring: nodes, plants and faults applied at the edges (a node's output
//! dropped, a bus's frames tampered with, a plant or input value changed). Every node is the
//! same sans-IO node that runs on hardware; the buses are the bit-timed simulation, so frame
//! timing and bus load are real figures. Nothing reads a clock: a run is a function of its
//! parameters and seed.

use core::time::Duration;

use bywire_canopen::cia402::{self, Drive, Mode, State};
use bywire_canopen::device::Device;
use bywire_control::kinematics::{Point, Pose};
use bywire_control::path::Path;
use bywire_core::filter::{ErrorMask, Filter};
use bywire_core::frame::ErrorClass;
use bywire_core::node::{Node, Port};
use bywire_core::{Frame, Id, Timestamp};
use bywire_net::network::{BusIndex, Network, NodeHandle, NodeKey};
use bywire_net::sim::{BusEvent, NodeId};
use bywire_net::Filtering;
use bywire_tug::backup_steering::{self, SteeringPair};
use bywire_tug::diagnostics;
use bywire_tug::drives::BACKUP_STEERING_NODES;
use bywire_tug::duplex::TugDuplexWire;
use bywire_tug::ecu::{
    self, Geometry as EcuGeometry, StatusInputs, VehicleControlEcu, DRIVE_UNITS_PER_M,
    STEERING_UNITS_PER_DEG,
};
pub use bywire_tug::ecu::{DRIVE_NODES, MASTER_NODE, STEERING_NODES};
use bywire_tug::messages::{
    AdsToVehicleControl, Battery as BatteryMessage, ControlMode, EmergencyBrake, EmergencyStop,
    SteeringAngleSensors, SteeringAnglesB, SteeringAnglesC, VcuAStatus, VcuBStatus,
    VehicleToAdsDegradation, VehicleToAdsSensors, VehicleToAdsState, VehicleToAdsWheelAngles,
};
use bywire_tug::secured::{self, TugWire};
use bywire_vehicle::ads::{Ads, AdsConfig};
use bywire_vehicle::arbitration::{ArbiterConfig, Duplex, FencedPair, Side};
use bywire_vehicle::backup::InCharge;
use bywire_vehicle::command::SteeringMode;
use bywire_vehicle::command::{DegradationLevel, FaultClass};
use bywire_vehicle::fail_operational::VotedRoles;
use bywire_vehicle::redundancy::Channel;
use bywire_vehicle::redundancy::TripleConfig;
use bywire_vehicle::secured::Signing;
use bywire_vehicle::supervisor::{EstopState, Redundancy, Supervisor, SupervisorConfig, Watchdog};

use crate::attacker::{Attack, Attacker};
use crate::battery::{Battery, BatteryParams};
pub use crate::bus::TugBus;
use crate::chassis::{Chassis, ChassisParams, WheelInput};
use crate::drive::{DriveParams, WheelDrive};
use crate::event::{Happening, SimEvent};
use crate::fault::{ActuatorFailure, Fault};
use crate::mission::{apron_loop, AdsDriver, Mission, MissionParams, Phase};
use crate::nodes::{
    self, AngleModule, BatteryReading, Bms, ImuNode, IoNode, IoReading, SafetyController,
};
use crate::record::{
    Logged, ResponseLog, ResponseTimes, Sample, SecurityWatch, SteeringRecord, SupervisorWatch,
    TruthSample,
};
use crate::rng::Rng;
use crate::steering::{SensorFault, SteeringChain, SteeringParams};

/// One simulated millisecond.
pub const TICK: Duration = Duration::from_millis(1);

/// The redundant tug's further angle sensors' faults, corner by corner (modules B and C), and
/// since when each holds.
type AngleFaults = [[(SensorFault, Timestamp); 2]; 4];

/// How far off an ECU that computes wrongly puts its front-left setpoint, degrees.
const WRONG_TRIM_DEG: f64 = 5.0;

/// What the redundant tug last showed: who is in control, the degradation level and its
/// reason, and which ECU fences the other.
#[derive(Debug, Clone, Copy, PartialEq)]
struct FailOperationalSeen {
    control: Option<Side>,
    level: (DegradationLevel, Option<FaultClass>),
    fenced: [bool; 2],
    /// Which actuator steers each corner.
    steering: [InCharge; 4],
}

impl Default for FailOperationalSeen {
    fn default() -> Self {
        FailOperationalSeen {
            control: Some(Side::A),
            level: (DegradationLevel::Nominal, None),
            fenced: [false; 2],
            steering: [InCharge::Primary; 4],
        }
    }
}

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
    /// The secured variant: the command path authenticated, CAN FD on bus 1 and 1b
    /// ([`bywire_tug::secured`]).
    pub secoc: bool,
    /// The redundant tug: two vehicle control ECUs (A in control, B in hot standby) and the
    /// degradation levels of the `reference-tug-redundant` profile.
    pub redundant: bool,
    /// Safe stop points along the route, m by distance: where a minimal-risk manoeuvre ends.
    pub safe_stops: Vec<f64>,
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
            secoc: false,
            redundant: false,
            safe_stops: Vec::new(),
        }
    }
}

pub use crate::mission::STEP_HOLD;

/// One corner's plants: the steering chain its steering drive turns, the wheel its drive turns.
struct Corner {
    chain: SteeringChain,
    wheel: WheelDrive,
    distance: f64,
    /// Its steering actuators' failures: the primary's, the backup valve's.
    actuator: [Option<ActuatorFailure>; 2],
}

/// The redundant tug's two vehicle control ECUs and the fence line between them.
pub type EcuPair = FencedPair<VehicleControlEcu, TugDuplexWire>;

/// The vehicle control ECU: one, or the redundant tug's pair.
#[derive(Clone, Copy)]
enum Ecus {
    One(NodeHandle<VehicleControlEcu>),
    Two(NodeHandle<EcuPair>),
}

impl Ecus {
    /// The ECU (of two, the one in control; A when neither is).
    fn in_control(self, net: &Network) -> Option<&VehicleControlEcu> {
        match self {
            Ecus::One(ecu) => net.node(ecu),
            Ecus::Two(pair) => {
                let pair = net.node(pair)?;
                let side = pair.in_control().unwrap_or(Side::A);
                Some(pair.half(side).node())
            }
        }
    }

    fn key(self) -> NodeKey {
        match self {
            Ecus::One(ecu) => ecu.key(),
            Ecus::Two(pair) => pair.key(),
        }
    }

    /// The node's ports for each ECU: (its name, the port on bus 1, 1b, 2 and 3).
    fn halves(self) -> Vec<(&'static str, [Port; 4])> {
        let ports = [ecu::BUS1, ecu::BUS1B, ecu::BUS2, ecu::BUS3];
        match self {
            Ecus::One(_) => vec![("ECU", ports)],
            Ecus::Two(_) => vec![("ECU A", ports), ("ECU B", ports.map(EcuPair::b_port))],
        }
    }
}

/// What the redundant tug's profile declares: its ECUs' arbitration, its voted angles, its
/// backup steering.
#[derive(Clone, Copy)]
struct Redundant {
    arbitration: ArbiterConfig,
    voted: Option<[TripleConfig; 4]>,
    steering: Option<[SteeringPair; 4]>,
}

/// The tug's nodes, as its network holds them.
struct TugNodes {
    ads: NodeHandle<AdsDriver>,
    ecu: Ecus,
    safety: NodeHandle<Signing<SafetyController>>,
    bms: NodeHandle<Bms>,
    imu: NodeHandle<ImuNode>,
    io: NodeHandle<IoNode>,
    /// The redundant tug's angle-sensor modules B and C.
    angle_modules: Option<[NodeHandle<AngleModule>; 2]>,
    /// Steering drives FL..RR.
    steer: [NodeHandle<Device<Drive>>; 4],
    /// Wheel drives FL..RR.
    drive: [NodeHandle<Device<Drive>>; 4],
    /// The redundant tug's backup steering valve drivers FL..RR.
    steer_backup: Option<[NodeHandle<Device<Drive>>; 4]>,
    attacker: NodeHandle<Attacker>,
}

/// The inputs last given to the ECU and the safety controller from the wiring: given again
/// only when they change (a node changed between runs is asked its deadline again).
#[derive(Clone, Copy, PartialEq)]
struct WiringInputs {
    takeover_torque: f64,
    status: StatusInputs,
}
/// The simulated vehicle's SecOC key (a simulation's, not a secret): every node of the
/// secured variant has it, the attacker does not.
const SIM_KEY: [u8; 16] = *b"bywire-sim-key!!";

/// Receive exactly these identifiers.
fn only(ids: &[u32]) -> Filtering {
    Filtering {
        filters: ids.iter().map(|id| Filter::new(*id, 0x7FF)).collect(),
        ..Filtering::default()
    }
}

/// Receive nothing (nodes that only send).
fn deaf() -> Filtering {
    Filtering {
        filters: Vec::new(),
        ..Filtering::default()
    }
}

/// A drive's acceptance filters, as its controller would have them: NMT, SYNC, the master's
/// heartbeat, and what is addressed to its node ID (PDOs, SDO).
fn drive_filtering(node: u8) -> Filtering {
    let exact = |id: u32| Filter::new(id, 0x7FF);
    Filtering {
        filters: vec![
            exact(0x000),
            exact(0x080),
            exact(0x700 + u32::from(MASTER_NODE)),
            Filter::new(u32::from(node), 0x07F),
        ],
        // Its controller's restart after bus-off, which it reports as an EMCY.
        error_mask: ErrorMask(ErrorClass::Restarted.bit()),
        ..Filtering::default()
    }
}

/// An ADS node that sends on one port, in the built-in ADS's place: what it sends goes on
/// bus 1 and, copied, on bus 1b, as the built-in ADS sends.
pub struct OnBothCommandBuses<N>(pub N);

impl<N: Node> Node for OnBothCommandBuses<N> {
    fn on_frame(&mut self, now: Timestamp, port: Port, frame: &Frame) {
        if port == Port::MAIN {
            self.0.on_frame(now, port, frame);
        }
    }
    fn on_sent(&mut self, now: Timestamp, port: Port, frame: &Frame) -> bool {
        port == Port::MAIN && self.0.on_sent(now, port, frame)
    }
    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        self.0.poll(now, &mut |port, frame| {
            if port == Port::MAIN {
                out(Port::MAIN, frame);
                out(Ads::<TugWire>::PORT_B, frame);
            }
        });
    }
    fn next_deadline(&self) -> Option<Timestamp> {
        self.0.next_deadline()
    }
}

/// The tug's four buses (1, 2, 3, 1b, in [`TugBus::ALL`]'s order), arbitration unreported.
fn add_buses(net: &mut Network, secoc: bool) -> [BusIndex; 4] {
    // The secured variant's frames are CAN FD with a faster data phase on the command buses.
    let command_data = secoc.then_some(secured::DATA_BITRATE);
    let buses = [
        net.add_bus("bus1", 500_000, command_data),
        net.add_bus("bus2", 1_000_000, None),
        net.add_bus("bus3", 500_000, None),
        net.add_bus("bus1b", 500_000, command_data),
    ];
    // The run reports what was sent and the controllers' states, not who lost arbitration.
    for bus in buses {
        if let Some(sim) = net.bus_mut(bus) {
            sim.report_arbitration(false);
        }
    }
    buses
}

impl TugNodes {
    /// Every node of the tug, added in the order they are polled at one instant (the runs are
    /// reproducible in it).
    fn add(
        net: &mut Network,
        params: &TugParams,
        mission: Mission,
        (ads_config, ecu_config): (AdsConfig, SupervisorConfig),
        geometry: EcuGeometry,
        redundancy: Option<Redundant>,
    ) -> Result<TugNodes, TugError> {
        // Every node of the secured variant starts its freshness at 1: a new key.
        let key = bywire_secoc::Key::new(SIM_KEY);
        let wire = || -> Result<_, TugError> {
            Ok(if params.secoc {
                secured::secured(&key, 1)?
            } else {
                secured::plain()
            })
        };
        let safety_table = match params.secoc {
            true => Some(secured::table(&key, 1)?),
            false => None,
        };
        let ads = net.add_node(AdsDriver::new(ads_config, mission, wire()?));
        let ecu = match redundancy {
            None => {
                Ecus::One(net.add_node(VehicleControlEcu::with_wire(ecu_config, geometry, wire()?)))
            }
            Some(Redundant {
                arbitration: config,
                voted,
                steering,
            }) => {
                let half = |side| -> Result<_, TugError> {
                    let mut node = VehicleControlEcu::with_wire(ecu_config, geometry, wire()?);
                    if let Some(voted) = voted {
                        node = node.with_voted_angles(voted);
                    }
                    if let Some(pairs) = steering {
                        node = node.with_backup_steering(pairs);
                    }
                    let duplex = TugDuplexWire::default();
                    Ok(Duplex::new(side, config, node, duplex, Timestamp::ZERO))
                };
                let pair = FencedPair::new(half(Side::A)?, half(Side::B)?);
                Ecus::Two(net.add_node(pair))
            }
        };
        Ok(TugNodes {
            ads,
            ecu,
            safety: net.add_node(Signing::new(nodes::safety_controller(), safety_table)),
            bms: net.add_node(nodes::bms()),
            imu: net.add_node(nodes::imu()),
            io: net.add_node(nodes::io_node()),
            angle_modules: redundancy.map(|_| [0, 1].map(|m| net.add_node(nodes::angle_module(m)))),
            steer: STEERING_NODES.map(|n| net.add_node(drive_device(n, Mode::ProfilePosition))),
            drive: DRIVE_NODES.map(|n| net.add_node(drive_device(n, Mode::ProfileVelocity))),
            steer_backup: redundancy
                .and_then(|r| r.steering)
                .map(|pairs| pairs.map(|p| net.add_node(valve_driver(p.backup)))),
            attacker: net.add_node(Attacker::new()),
        })
    }

    /// Each node's ports on `buses` (1, 2, 3, 1b); who is at each endpoint of each bus, and
    /// the ECU's endpoint on bus 1.
    fn wire(
        &self,
        net: &mut Network,
        buses: [BusIndex; 4],
    ) -> ([Vec<(NodeId, String)>; 4], NodeId) {
        let mut names: [Vec<(NodeId, String)>; 4] = Default::default();
        let mut wire = |net: &mut Network, node: NodeKey, port: Port, bus: usize, name: &str| {
            let index = buses.get(bus).copied().unwrap_or_default();
            let endpoint = net.wire(node, port, index).unwrap_or_default();
            if let Some(list) = names.get_mut(bus) {
                list.push((endpoint, name.to_string()));
            }
            endpoint
        };
        let (ads, ecu) = (self.ads.key(), self.ecu.key());
        wire(net, ads, Ads::<TugWire>::PORT_A, 0, "ADS");
        wire(net, ads, Ads::<TugWire>::PORT_B, 3, "ADS");
        let mut ecu_bus1 = None;
        for (name, [bus1, bus1b, bus2, bus3]) in self.ecu.halves() {
            let endpoint = wire(net, ecu, bus1, 0, name);
            ecu_bus1.get_or_insert(endpoint);
            wire(net, ecu, bus1b, 3, name);
            wire(net, ecu, bus2, 1, &format!("{name} (CANopen master)"));
            wire(net, ecu, bus3, 2, name);
        }
        let ecu_bus1 = ecu_bus1.unwrap_or_default();
        wire(net, self.safety.key(), Port::MAIN, 0, "safety controller");
        wire(net, self.bms.key(), Port::MAIN, 0, "BMS");
        wire(net, self.attacker.key(), Port::MAIN, 0, "attacker");
        wire(net, self.imu.key(), Port::MAIN, 2, "IMU");
        wire(net, self.io.key(), Port::MAIN, 2, "I/O node");
        for (module, name) in self
            .angle_modules
            .iter()
            .flatten()
            .zip(["angle module B", "angle module C"])
        {
            wire(net, module.key(), Port::MAIN, 2, name);
        }
        // Corner by corner: its steering drive, then its wheel drive.
        let corners = STEERING_NODES.iter().zip(self.steer);
        for ((steer, steer_node), (drive, drive_node)) in
            corners.zip(DRIVE_NODES.iter().zip(self.drive))
        {
            for (id, node) in [(steer, steer_node), (drive, drive_node)] {
                wire(net, node.key(), Port::MAIN, 1, &format!("drive 0x{id:02X}"));
            }
        }
        for (id, node) in BACKUP_STEERING_NODES
            .iter()
            .zip(self.steer_backup.iter().flatten())
        {
            wire(
                net,
                node.key(),
                Port::MAIN,
                1,
                &format!("valve driver 0x{id:02X}"),
            );
        }
        (names, ecu_bus1)
    }

    /// Each node hears only what it reads: delivering is where a simulator's time goes.
    fn filter(&self, net: &mut Network) {
        for (id, node) in STEERING_NODES.iter().zip(self.steer) {
            net.set_filtering(node, Port::MAIN, drive_filtering(*id));
        }
        for (id, node) in DRIVE_NODES.iter().zip(self.drive) {
            net.set_filtering(node, Port::MAIN, drive_filtering(*id));
        }
        for (id, node) in BACKUP_STEERING_NODES
            .iter()
            .zip(self.steer_backup.iter().flatten())
        {
            net.set_filtering(*node, Port::MAIN, drive_filtering(*id));
        }
        let commands = [
            EmergencyBrake::ID,
            EmergencyStop::ID,
            AdsToVehicleControl::ID,
        ];
        // And on bus 1: its diagnostic requests, the BMS's reading, its controller's state
        // (and the redundant tug's ECUs each other's status).
        let mut ecu_hears = commands.to_vec();
        ecu_hears.extend([
            secured::SYNC_ID,
            diagnostics::REQUEST_ID,
            diagnostics::FUNCTIONAL_ID,
            BatteryMessage::ID,
        ]);
        let mut sensors = vec![SteeringAngleSensors::ID];
        if matches!(self.ecu, Ecus::Two(_)) {
            ecu_hears.extend([VcuAStatus::ID, VcuBStatus::ID]);
            sensors.extend([SteeringAnglesB::ID, SteeringAnglesC::ID]);
        }
        let ecu = self.ecu.key();
        for (_, [bus1, bus1b, _, bus3]) in self.ecu.halves() {
            net.set_filtering(
                ecu,
                bus1,
                Filtering {
                    error_mask: ErrorMask(ErrorClass::BusOff.bit() | ErrorClass::Restarted.bit()),
                    ..only(&ecu_hears)
                },
            );
            net.set_filtering(ecu, bus1b, only(&[AdsToVehicleControl::ID]));
            net.set_filtering(ecu, bus3, only(&sensors));
        }
        let mut feedback = vec![
            VehicleToAdsState::ID,
            VehicleToAdsSensors::ID,
            VehicleToAdsWheelAngles::ID,
            secured::SYNC_ID,
        ];
        if matches!(self.ecu, Ecus::Two(_)) {
            feedback.push(VehicleToAdsDegradation::ID);
        }
        net.set_filtering(self.ads, Ads::<TugWire>::PORT_A, only(&feedback));
        net.set_filtering(self.ads, Ads::<TugWire>::PORT_B, deaf());
        let senders = [
            self.safety.key(),
            self.bms.key(),
            self.imu.key(),
            self.io.key(),
        ];
        for node in senders {
            net.set_filtering(node, Port::MAIN, deaf());
        }
        for module in self.angle_modules.iter().flatten() {
            net.set_filtering(*module, Port::MAIN, deaf());
        }
        net.set_filtering(
            self.attacker,
            Port::MAIN,
            only(&[AdsToVehicleControl::ID, VehicleToAdsState::ID]),
        );
    }
}

/// The simulated tug.
pub struct Tug {
    now: Timestamp,
    net: Network,
    /// Bus 1, 2, 3 and 1b, in [`TugBus::ALL`]'s order.
    buses: [BusIndex; 4],
    /// The loggers, one a bus.
    taps: [NodeId; 4],
    /// Who is at each endpoint of each bus, for events.
    names: [Vec<(NodeId, String)>; 4],
    /// The ECU's endpoint on bus 1.
    ecu_bus1: NodeId,
    nodes: TugNodes,
    /// What the wiring last told the nodes (`None`: nothing yet).
    wiring: Option<WiringInputs>,
    corners: Vec<Corner>,
    chassis: Chassis,
    battery: Battery,
    rng: Rng,
    params: TugParams,
    /// Frames on bus 1.
    pub bus1_log: Vec<Logged>,
    /// Frames on bus 2.
    pub bus2_log: Vec<Logged>,
    /// Frames on bus 3.
    pub bus3_log: Vec<Logged>,
    /// Frames on bus 1b.
    pub bus1b_log: Vec<Logged>,
    /// Cross-track error of the true pose to the route every 20 ms once engaged, m.
    pub tracking_errors: Vec<f64>,
    /// The route's segment the tug was last found on (where the next sample looks first).
    tracked_segment: Option<usize>,
    /// What happened, in time order.
    pub events: Vec<SimEvent>,
    /// The state every 50 ms.
    pub trace: Vec<Sample>,
    /// The plant's true state every 10 ms.
    pub truth: Vec<TruthSample>,
    /// Faults active until their end time (`None`: for good).
    active: Vec<(Fault, Option<Timestamp>)>,
    /// The faults changed since the cut connections and the attack were last set from them.
    faults_changed: bool,
    supervisor_watch: SupervisorWatch,
    ads_external: bool,
    /// The steering's responses: the step test's steps and the tank turn.
    pub steering: SteeringRecord,
    /// Command to heartbeat echo, as the ADS measured it on every state frame.
    pub echo_latencies: Vec<Duration>,
    last_echo: Option<Timestamp>,
    /// What the attacks achieved.
    pub security: SecurityWatch,
    /// Each bus's response times by identifier, in [`TugBus::ALL`]'s order.
    response_times: [ResponseLog; 4],
    /// The redundant tug's control and level as last recorded.
    fail_operational: FailOperationalSeen,
    /// The redundant tug's further angle sensors' faults (corner by corner, modules B and C)
    /// and since when.
    angle_faults: AngleFaults,
}

/// Why a tug could not be built.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TugError {
    /// The tug's shipped profile did not load.
    #[error("the reference tug's profile: {0}")]
    Profile(String),
    /// The secured variant's table did not build.
    #[error(transparent)]
    SecOc(#[from] secured::SecuredError),
}

impl Tug {
    /// A tug at the start of its route, parked, everything powered on. Refused only if the
    /// tug's own profile or secured table does not build: a run never falls back to other
    /// settings than the ones asked for.
    pub fn new(params: TugParams) -> Result<Tug, TugError> {
        let loaded = if params.redundant {
            bywire_tug::redundant_profile()
        } else {
            bywire_tug::profile()
        }
        .map_err(|e| TugError::Profile(e.to_string()))?;
        // The redundant tug: its ECUs' arbitration, and each corner's angle voted when the
        // profile declares the four.
        let steering = backup_steering::pairs_of(&loaded).map_err(TugError::Profile)?;
        let redundancy = loaded.profile.fail_operational.as_ref().and_then(|f| {
            let voted: Option<[TripleConfig; 4]> = f
                .voted
                .iter()
                .map(VotedRoles::config)
                .collect::<Vec<_>>()
                .try_into()
                .ok();
            f.control.as_ref().map(|c| Redundant {
                arbitration: c.config(),
                voted,
                steering,
            })
        });
        let (ads_config, mut ecu_config) = (loaded.ads_config(), loaded.supervisor_config());
        // Commands come on bus 1 and bus 1b: a copy half a cycle overdue leaves the other bus
        // alone (degraded, reported); copies that disagree are a fault.
        ecu_config.redundancy = Some(Redundancy::for_cycle(ecu_config.cycle));
        let chassis_params = ChassisParams {
            payload: params.payload,
            ..ChassisParams::default()
        };
        let mission = Mission::new(MissionParams {
            route: params.route.clone(),
            speed: params.speed,
            speeds: params.speeds.clone(),
            stops: params.stops.clone(),
            crab_final_m: params.crab_final_m,
            tank_turn_deg: params.tank_turn_deg,
            steering_steps: params.steering_steps.clone(),
            wheelbase: chassis_params.wheelbase,
            track: chassis_params.track,
            safe_stops: params.safe_stops.clone(),
            degraded_speeds: {
                let policy = ecu_config.degradation.unwrap_or_default();
                (policy.degraded.speed_limit, policy.minimal_risk.speed_limit)
            },
        });
        let start = mission.start_pose();
        let mut net = Network::new();
        let geometry = EcuGeometry {
            wheelbase: chassis_params.wheelbase,
            track: chassis_params.track,
        };
        let nodes = TugNodes::add(
            &mut net,
            &params,
            mission,
            (ads_config, ecu_config),
            geometry,
            redundancy,
        )?;
        let buses = add_buses(&mut net, params.secoc);
        let (mut names, ecu_bus1) = nodes.wire(&mut net, buses);
        nodes.filter(&mut net);
        let mut taps = [0; 4];
        for (tap, (bus, list)) in taps.iter_mut().zip(buses.iter().zip(names.iter_mut())) {
            *tap = net.tap(*bus).unwrap_or_default();
            list.push((*tap, "logger".to_string()));
        }
        let corners = (0..4)
            .map(|_| Corner {
                chain: SteeringChain::new(SteeringParams::default()),
                wheel: WheelDrive::new(DriveParams::default()),
                distance: 0.0,
                actuator: [None; 2],
            })
            .collect();
        Ok(Tug {
            now: Timestamp::ZERO,
            net,
            buses,
            taps,
            names,
            ecu_bus1,
            nodes,
            wiring: None,
            corners,
            chassis: Chassis::new(chassis_params, start),
            battery: Battery::new(BatteryParams::default(), 0.8),
            rng: Rng::new(params.seed),
            params,
            bus1_log: Vec::new(),
            bus2_log: Vec::new(),
            bus3_log: Vec::new(),
            bus1b_log: Vec::new(),
            tracking_errors: Vec::new(),
            tracked_segment: None,
            events: Vec::new(),
            trace: Vec::new(),
            truth: Vec::new(),
            active: Vec::new(),
            faults_changed: true,
            supervisor_watch: SupervisorWatch::default(),
            ads_external: false,
            steering: SteeringRecord::default(),
            echo_latencies: Vec::new(),
            last_echo: None,
            security: SecurityWatch::default(),
            response_times: Default::default(),
            fail_operational: FailOperationalSeen::default(),
            angle_faults: [[(SensorFault::None, Timestamp::ZERO); 2]; 4],
        })
    }

    fn bus_index(&self, bus: TugBus) -> BusIndex {
        let i = TugBus::ALL.iter().position(|b| *b == bus).unwrap_or(0);
        self.buses.get(i).copied().unwrap_or(0)
    }

    /// Set (`on`) or mend the faults that are frames tampered with on their way; others are
    /// left alone.
    fn set_tampering(&mut self, fault: Fault, on: bool) {
        let Some(tampering) = fault.tampering() else {
            return;
        };
        let Ok(id) = Id::standard(u32::from(tampering.id)) else {
            return;
        };
        for bus in tampering.buses {
            let index = self.bus_index(*bus);
            if let Some(sim) = self.net.bus_mut(index) {
                sim.tamper(id, on.then_some(tampering.tamper));
            }
        }
    }

    /// A port on `bus` for a node outside the tug (a tool that watches and injects): it hears
    /// every frame the others send, and what it sends goes on the bus.
    pub fn attach(&mut self, bus: TugBus) -> NodeId {
        let index = self.bus_index(bus);
        self.net.tap(index).unwrap_or_default()
    }

    /// Send `frame` on `bus` from `port` (from [`Tug::attach`]).
    pub fn send(&mut self, bus: TugBus, port: NodeId, frame: Frame) {
        let (now, index) = (self.now, self.bus_index(bus));
        if let Some(sim) = self.net.bus_mut(index) {
            sim.submit(port, frame, now);
        }
    }

    /// The next frame `bus` delivered to `port`.
    pub fn receive(&mut self, bus: TugBus, port: NodeId) -> Option<(Timestamp, Frame)> {
        let index = self.bus_index(bus);
        self.net
            .bus_mut(index)?
            .receive(port)
            .map(|r| (r.timestamp, r.frame))
    }

    /// Inject `fault` now, for `duration` (`None`: for good).
    pub fn inject(&mut self, fault: Fault, duration: Option<Duration>) {
        let now = self.now;
        self.record(Happening::Fault(fault));
        match fault {
            Fault::SensorFault(corner, sensor) => {
                if let Some(c) = self.corners.get_mut(corner) {
                    c.chain.set_fault(sensor);
                }
            }
            Fault::AngleSensor {
                corner,
                module,
                fault,
            } => {
                if let Some(slot) = self
                    .angle_faults
                    .get_mut(corner)
                    .and_then(|c| c.get_mut(module))
                {
                    *slot = (fault, now);
                }
            }
            Fault::OperatorReset => {
                // The operator presses reset: at the ADS's console (the E-stop latch's reset
                // sequence) and at the ECU (drives the master stopped acknowledged, a steering
                // fault whose sensor tracks agree again cleared).
                if let Some(mut ads) = self.net.node_mut(self.nodes.ads) {
                    ads.operator_reset();
                }
                self.each_ecu(|ecu| ecu.operator_reset(now));
                self.take_node_events();
            }
            Fault::EcuBusOff => {
                let (index, ecu) = (self.bus_index(TugBus::Bus1), self.ecu_bus1);
                if let Some(sim) = self.net.bus_mut(index) {
                    sim.take_off_bus(Some(ecu), None);
                }
            }
            Fault::BusOff { bus, id } => {
                let index = self.bus_index(bus);
                if let (Ok(id), Some(sim)) = (Id::standard(u32::from(id)), self.net.bus_mut(index))
                {
                    sim.take_off_bus(None, Some(id));
                }
            }
            Fault::CorruptCommands
            | Fault::DuplicateCommands
            | Fault::DelayCommands(_)
            | Fault::TamperFrames { .. } => self.set_tampering(fault, true),
            Fault::EcuWrongOutput(side) => {
                self.with_ecu(side, |ecu| ecu.corrupt_trim(0, WRONG_TRIM_DEG));
            }
            Fault::SteeringActuator {
                corner,
                backup,
                failure,
            } => {
                if let Some(slot) = self
                    .corners
                    .get_mut(corner)
                    .and_then(|c| c.actuator.get_mut(usize::from(backup)))
                {
                    *slot = Some(failure);
                }
            }
            Fault::Repair => self.repair(now),
            Fault::AdsSilence
            | Fault::Estop
            | Fault::DriveSilence(_)
            | Fault::RedundantBusLoss
            | Fault::DriverTakeover
            | Fault::Attack(_)
            | Fault::EcuSilent(_)
            | Fault::EcuBabble(_) => {}
        }
        self.active
            .push((fault, duration.map(|d| now.saturating_add(d))));
        self.faults_changed = true;
    }

    fn is_active(&self, fault: Fault) -> bool {
        self.active.iter().any(|(f, _)| *f == fault)
    }

    /// Do `f` to one of the redundant tug's ECUs (nothing on the tug with one).
    fn with_ecu(&mut self, side: Side, f: impl FnOnce(&mut VehicleControlEcu)) {
        if let Ecus::Two(pair) = self.nodes.ecu {
            if let Some(mut pair) = self.net.node_mut(pair) {
                f(pair.half_mut(side).node_mut());
            }
        }
    }

    /// The redundant tug's repair at a standstill: both ECUs back to their power-on roles,
    /// the degradation level back to nominal (refused while it moves).
    fn repair(&mut self, now: Timestamp) {
        let Ecus::Two(handle) = self.nodes.ecu else {
            return;
        };
        if self.pose_speed() >= 0.05 {
            return;
        }
        if let Some(mut pair) = self.net.node_mut(handle) {
            for side in [Side::A, Side::B] {
                let half = pair.half_mut(side);
                half.reset(now);
                let ecu = half.node_mut();
                ecu.reset_degradation(now);
                // Drives that stopped when neither ECU was in control are acknowledged.
                ecu.operator_reset(now);
            }
        }
    }

    /// The redundant tug's changes of control and of degradation level into the run's
    /// events; a babbling ECU's flood kept up until its partner's fence cuts it.
    fn note_fail_operational(&mut self) {
        let control = self.ecu_in_control();
        let Some(pair) = self.ecu_pair() else {
            return;
        };
        let latch = pair
            .half(control.unwrap_or(Side::A))
            .node()
            .supervisor()
            .degradation();
        let level = (latch.level(), latch.reason().map(|f| f.class));
        let fenced = [Side::A, Side::B].map(|side| pair.half(side).arbiter().fences_partner());
        let steering = pair
            .half(control.unwrap_or(Side::A))
            .node()
            .steering_in_charge();
        if control != self.fail_operational.control {
            self.fail_operational.control = control;
            self.record(Happening::Control(control));
        }
        // With neither in control, neither ECU's actuators are commanded: nothing to show.
        if control.is_some() && steering != self.fail_operational.steering {
            let before = core::mem::replace(&mut self.fail_operational.steering, steering);
            for (corner, (now, was)) in steering.into_iter().zip(before).enumerate() {
                if now != was {
                    self.record(Happening::Steering {
                        corner,
                        in_charge: now,
                    });
                }
            }
        }
        // With neither in control, no ECU reports a level: the last one stands.
        if control.is_some() && level != self.fail_operational.level {
            self.fail_operational.level = level;
            self.record(Happening::Degradation(level.0, level.1));
        }
        if fenced != self.fail_operational.fenced {
            self.fail_operational.fenced = fenced;
            self.faults_changed = true;
        }
    }

    /// Whether `side`'s babble reaches bus 1: it babbles and its partner has not fenced it.
    fn babbling(&self, side: Side) -> bool {
        let [a_fences, b_fences] = self.fail_operational.fenced;
        let fenced = match side {
            Side::A => b_fences,
            Side::B => a_fences,
        };
        self.is_active(Fault::EcuBabble(side)) && !fenced
    }

    /// The steering fault the ECU's plausibility check latched, if any.
    pub fn steering_fault(&self) -> Option<bywire_tug::plausibility::SteeringFault> {
        self.vehicle_control_ecu()
            .and_then(VehicleControlEcu::steering_fault)
    }

    /// Do `f` to each vehicle control ECU (both of the redundant tug's).
    fn each_ecu(&mut self, mut f: impl FnMut(&mut VehicleControlEcu)) {
        match self.nodes.ecu {
            Ecus::One(ecu) => {
                if let Some(mut ecu) = self.net.node_mut(ecu) {
                    f(&mut ecu);
                }
            }
            Ecus::Two(pair) => {
                if let Some(mut pair) = self.net.node_mut(pair) {
                    for side in [Side::A, Side::B] {
                        f(pair.half_mut(side).node_mut());
                    }
                }
            }
        }
    }

    /// The redundant tug's two ECUs (`None`: the tug has one).
    pub fn ecu_pair(&self) -> Option<&EcuPair> {
        match self.nodes.ecu {
            Ecus::One(_) => None,
            Ecus::Two(pair) => self.net.node(pair),
        }
    }

    /// Switch off the ECUs' own mechanisms that `off` names (the 2-out-of-3 voter): a
    /// fault-injection campaign's proof that its cells would notice.
    pub fn switch_off(&mut self, off: bywire_vehicle::mechanism::Mechanisms) {
        match self.nodes.ecu {
            Ecus::One(ecu) => {
                if let Some(mut ecu) = self.net.node_mut(ecu) {
                    ecu.switch_off(off);
                }
            }
            Ecus::Two(pair) => {
                if let Some(mut pair) = self.net.node_mut(pair) {
                    for side in [Side::A, Side::B] {
                        pair.half_mut(side).node_mut().switch_off(off);
                    }
                }
            }
        }
    }

    /// Which of the redundant tug's ECUs is in control: its outputs on the buses, neither
    /// fenced nor silenced by a fault (`None`: neither, or the tug has one).
    pub fn ecu_in_control(&self) -> Option<Side> {
        self.ecu_pair()
            .and_then(EcuPair::in_control)
            .filter(|&side| {
                !self.is_active(Fault::EcuSilent(side)) && !self.is_active(Fault::EcuBabble(side))
            })
    }

    /// Each bus's response times by identifier (lowest identifier first), under the bus's name.
    pub fn response_times(&self) -> [(&'static str, &[ResponseTimes]); 4] {
        let [a, b, c, d] = &self.response_times;
        [
            ("bus1", &a.times),
            ("bus2", &b.times),
            ("bus3", &c.times),
            ("bus1b", &d.times),
        ]
    }

    /// Each bus's frames under the name its log file takes (`bus1`, `bus2`, `bus3`, `bus1b`).
    pub fn bus_logs(&self) -> [(&'static str, &[Logged]); 4] {
        [
            ("bus1", &self.bus1_log),
            ("bus2", &self.bus2_log),
            ("bus3", &self.bus3_log),
            ("bus1b", &self.bus1b_log),
        ]
    }

    /// The route is done: engaged, at its end (as the ADS reckons it), stopped, and the tank
    /// turn (if any) made.
    pub fn arrived(&self) -> bool {
        self.ads().is_some_and(|ads| {
            ads.engaged_at().is_some()
                && ads.mission().remaining() < 0.5
                && ads.mission().tank_done()
        }) && self.pose_speed() < 0.01
    }

    fn record(&mut self, what: Happening) {
        self.events.push(SimEvent { t: self.now, what });
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
        &self.params.route
    }

    /// Faults active now.
    pub fn active_faults(&self) -> impl Iterator<Item = Fault> + '_ {
        self.active.iter().map(|(fault, _)| *fault)
    }

    /// The tug's speed, m/s.
    pub fn pose_speed(&self) -> f64 {
        speed_of(&self.chassis)
    }

    /// The vehicle control ECU's supervisor (`None` only for a tug that lost its nodes,
    /// which a tug never does: its network is its own).
    pub fn ecu(&self) -> Option<&Supervisor<TugWire>> {
        self.vehicle_control_ecu()
            .map(VehicleControlEcu::supervisor)
    }

    /// The vehicle control ECU: of the redundant tug's, the one in control (A when neither
    /// is).
    pub fn vehicle_control_ecu(&self) -> Option<&VehicleControlEcu> {
        self.nodes.ecu.in_control(&self.net)
    }

    /// The route's remaining distance, as the ADS reckons it from its odometry, m.
    pub fn remaining(&self) -> Option<f64> {
        self.ads().map(|ads| ads.mission().remaining())
    }

    /// The mission's phase (`None`: no built-in ADS drives).
    pub fn phase(&self) -> Option<Phase> {
        self.ads().map(|ads| ads.mission().phase())
    }

    /// When the vehicle first reported autonomous mode to the ADS.
    pub fn engaged_at(&self) -> Option<Timestamp> {
        self.ads().and_then(AdsDriver::engaged_at)
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
        self.buses
            .map(|b| self.net.bus(b).map_or(0, |sim| sim.busy_ns()))
    }

    /// Who is at `port` on `bus`: an ECU, a drive by node ID, ... or a port from
    /// [`Tug::attach`].
    pub fn port_name(&self, bus: TugBus, port: NodeId) -> String {
        let i = TugBus::ALL.iter().position(|b| *b == bus).unwrap_or(0);
        self.names
            .get(i)
            .and_then(|list| list.iter().find(|(p, _)| *p == port))
            .map_or_else(|| format!("port {port}"), |(_, name)| name.clone())
    }

    /// The inputs the nodes read from the wiring and the plants, set before they are due:
    /// faults at the edges (outputs dropped, a hand on the wheel, the E-stop chain), and the
    /// sensor nodes' readings when they send within this millisecond.
    fn set_inputs(&mut self, until: Timestamp) {
        // The cut connections and the attack change only with the faults (every step costs a
        // pass over the nodes otherwise).
        if self.faults_changed {
            self.faults_changed = false;
            // A babbling ECU's flood comes from the attacker's port, standing in for its
            // transceiver: cut when its partner fences it.
            let babble = self.babbling(Side::A) || self.babbling(Side::B);
            let attack = self
                .active
                .iter()
                .find_map(|(f, _)| match f {
                    Fault::Attack(a) => Some(*a),
                    _ => None,
                })
                .or(babble.then_some(Attack::Flood));
            let attacker = self.net.node(self.nodes.attacker).map(Attacker::attack);
            if attacker.is_some_and(|now| now != attack) {
                if let Some(mut attacker) = self.net.node_mut(self.nodes.attacker) {
                    attacker.set_attack(attack);
                }
            }
            let silent = self.is_active(Fault::AdsSilence);
            self.net.drop_output(self.nodes.ads, silent);
            if let Ecus::Two(pair) = self.nodes.ecu {
                for (side, (_, ports)) in
                    [Side::A, Side::B].into_iter().zip(self.nodes.ecu.halves())
                {
                    let silent = self.is_active(Fault::EcuSilent(side))
                        || self.is_active(Fault::EcuBabble(side));
                    for port in ports {
                        self.net.drop_port_output(pair, port, silent);
                    }
                }
            }
            let b_lost = self.is_active(Fault::RedundantBusLoss);
            self.net
                .drop_port_output(self.nodes.ads, Ads::<TugWire>::PORT_B, b_lost);
            let steering = STEERING_NODES.iter().zip(self.nodes.steer);
            let drives = steering.chain(DRIVE_NODES.iter().zip(self.nodes.drive));
            for (id, node) in drives {
                let silent = self.is_active(Fault::DriveSilence(*id));
                self.net.drop_output(node, silent);
            }
            // A steering actuator's drive that lost its supply is silent too.
            let backups = self.nodes.steer_backup.iter().flatten();
            let actuators = self
                .nodes
                .steer
                .iter()
                .zip(backups.map(Some).chain([None; 4]));
            for (corner, (primary, backup)) in self.corners.iter().zip(actuators) {
                let [p, b] = corner
                    .actuator
                    .map(|f| f == Some(ActuatorFailure::DriveLost));
                if p {
                    self.net.drop_output(*primary, true);
                }
                if let Some(backup) = backup {
                    self.net.drop_output(*backup, b);
                }
            }
        }
        let takeover_torque = if self.is_active(Fault::DriverTakeover) {
            8.0
        } else {
            0.0
        };
        let estop = self.is_active(Fault::Estop);
        let wiring = WiringInputs {
            takeover_torque,
            status: StatusInputs {
                estop_chain_open: estop,
                parking_brake_applied: self.corners.iter().any(|c| c.wheel.is_parked()),
            },
        };
        if self.wiring != Some(wiring) {
            self.wiring = Some(wiring);
            self.each_ecu(|ecu| {
                ecu.set_driver_input(takeover_torque, 0.0);
                ecu.set_status_inputs(wiring.status);
            });
            if let Some(mut safety) = self.net.node_mut(self.nodes.safety) {
                safety.node.reading = estop;
            }
        }
        // A reading is taken only for a send within this millisecond (the IMU's and the
        // angle sensors' noise draws come in the order the nodes send); it leaves the send's
        // time where it is, so the runner is not asked to look at the node again.
        let (chassis, corners, rng) = (&self.chassis, &self.corners, &mut self.rng);
        self.net.feed(self.nodes.imu, |imu| {
            if imu.schedule.due_within(until) {
                let (yaw_rate, accel) = chassis.imu(TICK.as_secs_f64(), rng);
                imu.reading = (yaw_rate.to_degrees(), accel);
            }
            false
        });
        self.net.feed(self.nodes.io, |io| {
            if io.schedule.due_within(until) {
                let mut second_tracks = [0.0; 4];
                for (track, corner) in second_tracks.iter_mut().zip(corners) {
                    *track = corner.chain.second_track_deg(rng);
                }
                io.reading = IoReading {
                    encoders: chassis.encoders(0.01),
                    second_tracks,
                };
            }
            false
        });
        if let Some(modules) = self.nodes.angle_modules {
            let faults = &self.angle_faults;
            feed_angle_modules(&mut self.net, modules, (corners, faults), rng, until);
        }
        let battery = &self.battery;
        self.net.feed(self.nodes.bms, |bms| {
            if bms.schedule.due_within(until) {
                bms.reading = BatteryReading {
                    voltage: battery.terminal_v(),
                    current: battery.current(),
                    soc: battery.soc(),
                };
            }
            false
        });
    }

    /// One millisecond: the inputs set, the network run over it, the plants stepped over it.
    pub fn step(&mut self) {
        self.step_inner(None);
    }

    /// One millisecond with `ads` — any node: acceptance checks, another ADS — in the built-in
    /// ADS's place: its main port on bus 1, its port 1 on bus 1b (see [`OnBothCommandBuses`]).
    pub fn step_with_ads(&mut self, ads: &mut dyn Node) {
        if !self.ads_external {
            self.ads_external = true;
            if let Some(mut built_in) = self.net.node_mut(self.nodes.ads) {
                built_in.stop_planning();
            }
        }
        self.step_inner(Some(ads));
    }

    fn step_inner(&mut self, outside_ads: Option<&mut dyn Node>) {
        let now = self.now;
        let until = now.saturating_add(TICK);
        self.expire_faults(now);
        self.set_inputs(until);
        match outside_ads {
            Some(ads) => self.net.run_until_standing_in(until, self.nodes.ads, ads),
            None => self.net.run_until(until),
        }
        self.run_plants(now);
        self.now = until;
        self.take_logs();
        let seen = self.watch_nodes(until);
        self.note_bus_changes();
        if matches!(self.nodes.ecu, Ecus::Two(_)) {
            self.note_fail_operational();
        }
        if let Some(seen) = seen {
            let (now, events) = (self.now, &mut self.events);
            self.supervisor_watch
                .note(seen.supervisor, seen.degraded, |what| {
                    events.push(SimEvent { t: now, what });
                });
            if seen.events_waiting {
                self.take_node_events();
            }
        }
        self.sample(until);
    }

    fn expire_faults(&mut self, now: Timestamp) {
        let expired: Vec<Fault> = self
            .active
            .iter()
            .filter(|(_, end)| end.is_some_and(|end| now >= end))
            .map(|(f, _)| *f)
            .collect();
        let expired_any = !expired.is_empty();
        for fault in expired {
            match fault {
                Fault::SensorFault(corner, _) => {
                    if let Some(c) = self.corners.get_mut(corner) {
                        c.chain.set_fault(SensorFault::None);
                    }
                }
                Fault::AngleSensor { corner, module, .. } => {
                    if let Some(slot) = self
                        .angle_faults
                        .get_mut(corner)
                        .and_then(|c| c.get_mut(module))
                    {
                        *slot = (SensorFault::None, now);
                    }
                }
                Fault::EcuWrongOutput(side) => {
                    self.with_ecu(side, |ecu| ecu.corrupt_trim(0, -WRONG_TRIM_DEG));
                }
                Fault::SteeringActuator { corner, backup, .. } => {
                    if let Some(slot) = self
                        .corners
                        .get_mut(corner)
                        .and_then(|c| c.actuator.get_mut(usize::from(backup)))
                    {
                        *slot = None;
                    }
                }
                _ => self.set_tampering(fault, false),
            }
            self.record(Happening::FaultCleared(fault));
        }
        self.active
            .retain(|(_, end)| end.is_none_or(|end| now < end));
        self.faults_changed |= expired_any;
    }

    /// The loggers' frames into the logs.
    fn take_logs(&mut self) {
        let logs = [
            &mut self.bus1_log,
            &mut self.bus2_log,
            &mut self.bus3_log,
            &mut self.bus1b_log,
        ];
        for ((bus, tap), log) in self.buses.iter().zip(self.taps).zip(logs) {
            if let Some(sim) = self.net.bus_mut(*bus) {
                while let Some(r) = sim.receive(tap) {
                    log.push((r.timestamp, r.frame));
                }
            }
        }
    }

    /// What the ECU and the ADS show after a millisecond, both looked up once (the step's
    /// cost): the ADS's echo latencies; what the attacks achieve (each command the ECU took
    /// compared with the ADS's own, each speed the ADS took with the tug's); the step test's
    /// and the tank turn's records. Returns what is recorded after the buses' changes.
    fn watch_nodes(&mut self, now: Timestamp) -> Option<NodesSeen> {
        let (Some(ecu), Some(ads)) = (
            self.nodes.ecu.in_control(&self.net),
            self.net.node(self.nodes.ads),
        ) else {
            return None;
        };
        let echo = ads.ads().state().echo_latency;
        if echo.at != self.last_echo {
            self.last_echo = echo.at;
            self.echo_latencies.extend(echo.value);
        }
        let supervisor = ecu.supervisor();
        if !self.ads_external {
            let accepted = supervisor.stats().accepted;
            self.security.note_accepted(accepted, || {
                let own = ads.ads().effective_command(now)?;
                let taken = supervisor.command()?;
                Some([
                    (own.steering, own.velocity),
                    (taken.steering, taken.velocity),
                ])
            });
        }
        let speed = ads.ads().state().velocity;
        let chassis = &self.chassis;
        self.security
            .note_speed(speed.at, speed.value, || speed_of(chassis));
        // The front-left wheel every millisecond.
        if let Some(angle) = self.corners.first().map(|c| c.chain.wheel_angle_deg()) {
            let tank = supervisor
                .command()
                .is_some_and(|c| c.steering_mode == SteeringMode::Tank);
            let tank_target = || {
                ecu.wheel_targets()
                    .first()
                    .map_or(0.0, |w| w.angle.to_degrees())
            };
            let step = ads.mission().active_step();
            self.steering.note(now, angle, tank, tank_target, step);
        }
        Some(NodesSeen {
            supervisor: (supervisor.watchdog(), supervisor.estop(), supervisor.mode()),
            degraded: supervisor.degraded(),
            events_waiting: ecu.has_events() || ads.has_events(),
        })
    }

    /// The attacker (its frames sent).
    pub fn attacker(&self) -> Option<&Attacker> {
        self.net.node(self.nodes.attacker)
    }

    /// The built-in ADS (its view of the vehicle, its counts).
    pub fn ads(&self) -> Option<&AdsDriver> {
        self.net.node(self.nodes.ads)
    }

    /// The trace every 50 ms, the tracking error every 20 ms once engaged.
    fn sample(&mut self, now: Timestamp) {
        let pose = self.chassis.pose();
        if self.engaged_at().is_some() && now.as_nanos().is_multiple_of(20_000_000) {
            if let Some(path) = Path::new(&self.params.route) {
                let here = Point {
                    x: pose.x,
                    y: pose.y,
                };
                let projection = path.project_near(here, self.tracked_segment);
                self.tracked_segment = Some(projection.segment);
                self.tracking_errors.push(projection.offset.abs());
            }
        }
        if now.as_nanos().is_multiple_of(10_000_000) {
            self.truth.push(TruthSample {
                t: now,
                pose,
                twist: self.chassis.twist(),
                wheel_angles_deg: core::array::from_fn(|i| {
                    self.corners
                        .get(i)
                        .map_or(0.0, |c| c.chain.wheel_angle_deg())
                }),
                wheel_speeds: self.chassis.wheel_speeds(),
                steering_mode: self
                    .ecu()
                    .and_then(|e| e.command())
                    .map(|c| c.steering_mode),
            });
        }
        if now.as_nanos().is_multiple_of(50_000_000) {
            let steering_actual = self
                .corners
                .first()
                .map_or(0.0, |c| c.chain.wheel_angle_deg());
            self.trace.push(Sample {
                t: now,
                pose,
                speed: self.pose_speed(),
                steering_command: self.ads().map_or(0.0, AdsDriver::steering_command),
                steering_target: self
                    .vehicle_control_ecu()
                    .and_then(|e| e.wheel_targets().first().map(|w| w.angle.to_degrees()))
                    .unwrap_or(0.0),
                steering_actual,
                busy_ns: self.busy_ns(),
            });
        }
    }

    /// Record the buses' state changes and the response times of what they carried.
    fn note_bus_changes(&mut self) {
        let mut changes = Vec::new();
        for (i, bus) in TugBus::ALL.into_iter().enumerate() {
            let index = self.buses.get(i).copied().unwrap_or(0);
            let (Some(sim), Some(times)) =
                (self.net.bus_mut(index), self.response_times.get_mut(i))
            else {
                continue;
            };
            for event in sim.drain_events() {
                match event {
                    BusEvent::StateChanged { node, state, .. } => {
                        changes.push((bus, node, state));
                    }
                    BusEvent::Transmitted { id, latency_ns, .. } => {
                        times.note(id, latency_ns);
                    }
                    _ => {}
                }
            }
        }
        for (bus, node, state) in changes {
            let who = self.port_name(bus, node);
            self.record(Happening::BusState { bus, who, state });
        }
    }

    /// The ECU's and the ADS's events into the run's.
    fn take_node_events(&mut self) {
        // Bounded by the nodes' event queues; a node with none is not borrowed to change.
        match self.nodes.ecu {
            Ecus::One(handle) => {
                while self
                    .vehicle_control_ecu()
                    .is_some_and(VehicleControlEcu::has_events)
                {
                    let event = self.net.node_mut(handle).and_then(|mut e| e.next_event());
                    let Some((_, event)) = event else { break };
                    self.record(Happening::Ecu(event));
                }
            }
            Ecus::Two(handle) => {
                // The ECU in control speaks for the tug; the standby's copies are dropped.
                let in_control = self.ecu_in_control().unwrap_or(Side::A);
                let mut taken = Vec::new();
                if let Some(mut pair) = self.net.node_mut(handle) {
                    for side in [Side::A, Side::B] {
                        let ecu = pair.half_mut(side).node_mut();
                        while let Some((_, event)) = ecu.next_event() {
                            if side == in_control {
                                taken.push(event);
                            }
                        }
                    }
                }
                for event in taken {
                    self.record(Happening::Ecu(event));
                }
            }
        }
        while self.ads().is_some_and(AdsDriver::has_events) {
            let event = self
                .net
                .node_mut(self.nodes.ads)
                .and_then(|mut a| a.next_event());
            let Some((_, event)) = event else { break };
            self.record(Happening::Mission(event));
        }
    }

    /// The plants over the millisecond from `now`: each drive's demand moves its plant, whose
    /// actual values go back to the drive.
    fn run_plants(&mut self, now: Timestamp) {
        let dt = TICK.as_secs_f64();
        let Some(ecu) = self.vehicle_control_ecu() else {
            return;
        };
        let mut a = ecu.actuators(now);
        let mut brake = ecu.brake_demand_of(&a);
        // Neither of the redundant tug's ECUs in control: nothing drives the motors, and the
        // spring brakes apply.
        if matches!(self.nodes.ecu, Ecus::Two(_)) && self.ecu_in_control().is_none() {
            a.motors_enabled = false;
            brake = 1.0;
        }
        let rolling = self.chassis.twist().vx.abs() > 0.05;
        let speeds = self.chassis.wheel_speeds();
        let soc = self.battery.soc();
        let mut inputs = [WheelInput::default(); 4];
        let mut power = 0.0;
        let devices = self.nodes.steer.iter().zip(&self.nodes.drive);
        // The redundant tug's backup valves first: their oil, from their drivers' demands,
        // moves the wheels with the primaries'.
        if let Some(valves) = self.nodes.steer_backup {
            backup_valves(&mut self.net, valves, &mut self.corners, (dt, rolling));
        }
        for (((corner, (&steer, &drive)), input), speed) in self
            .corners
            .iter_mut()
            .zip(devices)
            .zip(inputs.iter_mut())
            .zip(speeds)
        {
            // Steering: the drive's velocity demand (a wheel rate) becomes the valve shaft's
            // speed command. The linkage turns the wheel faster per millimetre of stroke as the
            // angle grows (angle = asin(stroke / arm)), so the drive's output stage scales by
            // cos(angle) at the angle it measures: the loop keeps one gain from 0° to the tank
            // turn's 60° (without it the gain doubles there, and the wheel hunts). Each drive is
            // reached once a millisecond: its demand read, its plant stepped, its actual values
            // given back, saying when they move its deadline (its motor starts or stops).
            let (rng, mut drive_torque) = (&mut self.rng, 0.0);
            self.net.feed(steer, |device: &mut Device<Drive>| {
                let drive = &mut device.app_mut().0;
                let max_rate = 19.0 * STEERING_UNITS_PER_DEG;
                let measured = drive.motor().position / STEERING_UNITS_PER_DEG;
                let linkage = libm::cos(measured.clamp(-75.0, 75.0).to_radians());
                let mut command = drive.demand() / max_rate * linkage;
                if let Some(failure) = corner.actuator[0] {
                    command = match failure {
                        ActuatorFailure::Stuck => {
                            corner.chain.seize();
                            0.0
                        }
                        // Full one way while its power stage is on.
                        ActuatorFailure::Runaway if drive.state() == State::OperationEnabled => 1.0,
                        ActuatorFailure::Runaway | ActuatorFailure::DriveLost => 0.0,
                    };
                }
                let before = corner.chain.wheel_angle_deg();
                corner.chain.step(dt, command, rolling);
                let reading = corner.chain.sensor_deg(rng);
                let rate = (corner.chain.wheel_angle_deg() - before) / dt;
                drive.set_actual(
                    reading * STEERING_UNITS_PER_DEG,
                    rate * STEERING_UNITS_PER_DEG,
                )
            });
            // Drive: the drive's velocity demand is the motor controller's setpoint.
            self.net.feed(drive, |device: &mut Device<Drive>| {
                let drive = &mut device.app_mut().0;
                let setpoint = drive.demand() / DRIVE_UNITS_PER_M;
                let output = corner.wheel.motor(setpoint, speed, soc);
                corner
                    .wheel
                    .set_parked(!a.motors_enabled && speed.abs() < 0.05);
                corner.wheel.step_brake(dt, brake);
                power += output.power;
                corner.distance += speed * dt;
                drive_torque = output.torque;
                drive.set_actual(
                    corner.distance * DRIVE_UNITS_PER_M,
                    speed * DRIVE_UNITS_PER_M,
                )
            });
            *input = WheelInput {
                angle_deg: corner.chain.wheel_angle_deg(),
                drive_torque,
                brake_torque: corner.wheel.holding_torque(),
            };
        }
        self.chassis.step(dt, &inputs, self.params.grade);
        self.battery.step(dt, power);
    }
}

/// What the supervisor shows after a millisecond, and whether the ECU or the ADS has events
/// waiting.
struct NodesSeen {
    supervisor: (Watchdog, EstopState, ControlMode),
    degraded: Option<Channel>,
    events_waiting: bool,
}

/// The redundant tug's angle modules' readings, when they send within this millisecond (out
/// of the step's line: the plain tug has none).
#[inline(never)]
fn feed_angle_modules(
    net: &mut Network,
    modules: [NodeHandle<AngleModule>; 2],
    (corners, faults): (&[Corner], &AngleFaults),
    rng: &mut Rng,
    until: Timestamp,
) {
    for (module, handle) in modules.into_iter().enumerate() {
        net.feed(handle, |node| {
            if node.schedule.due_within(until) {
                for ((reading, corner), faults) in node.reading.iter_mut().zip(corners).zip(faults)
                {
                    let (fault, since) = faults
                        .get(module)
                        .copied()
                        .unwrap_or((SensorFault::None, until));
                    let drift = match fault {
                        SensorFault::Drift(rate) => {
                            rate * until.saturating_since(since).as_secs_f64()
                        }
                        _ => 0.0,
                    };
                    *reading = corner.chain.further_sensor_deg(fault, drift, rng);
                }
            }
            false
        });
    }
}

/// The backup valves over the millisecond `dt`: each meters oil for its driver's demand, or
/// what a failure makes of it (the spool stuck closed or open, its driver unpowered), into
/// its corner's cylinder; each driver told the rate it meters. Out of the step's line: the
/// plain tug has no backup valves.
#[inline(never)]
fn backup_valves(
    net: &mut Network,
    valves: [NodeHandle<Device<Drive>>; 4],
    corners: &mut [Corner],
    (dt, rolling): (f64, bool),
) {
    for (valve, corner) in valves.into_iter().zip(corners) {
        let failure = corner.actuator[1];
        let mut rate = 0.0;
        net.feed(valve, |device: &mut Device<Drive>| {
            let driver = &mut device.app_mut().0;
            let demand = driver.demand();
            rate = match failure {
                None => demand / STEERING_UNITS_PER_DEG,
                Some(ActuatorFailure::Runaway) => VALVE_MAX_RATE,
                Some(ActuatorFailure::Stuck | ActuatorFailure::DriveLost) => 0.0,
            };
            driver.set_actual(0.0, rate * STEERING_UNITS_PER_DEG)
        });
        if rate != 0.0 {
            corner.chain.backup_flow(dt, rate, rolling);
        }
    }
}

/// The body's speed over the ground, m/s.
fn speed_of(chassis: &Chassis) -> f64 {
    libm::hypot(chassis.twist().vx, chassis.twist().vy)
}

/// The backup valve's largest rate, °/s (its spool wide open).
const VALVE_MAX_RATE: f64 = 20.0;

/// A backup steering valve driver: a drive in profile velocity whose velocity is the wheel
/// rate its valve meters (up to 20°/s, reached in 0.1 s). Its statusword at most every
/// 10 ms and its emergencies every 100 ms (its state changes seldom): the drives bus carries
/// twelve nodes on the redundant tug (the drives DBC declares these inhibit times).
fn valve_driver(node: u8) -> Device<Drive> {
    let od = drive_dictionary(node, Mode::ProfileVelocity, (2_000, 20_000), (100, 1_000));
    Device::new(node, od, Drive::new().with_external_motor())
}

fn drive_device(node: u8, mode: Mode) -> Device<Drive> {
    let profile = match mode {
        // Steering: 20°/s, 60°/s².
        Mode::ProfilePosition | Mode::CyclicSynchronousPosition => (2_000, 6_000),
        // Wheels: 8 m/s, 1.5 m/s².
        Mode::ProfileVelocity | Mode::CyclicSynchronousVelocity => (8_000, 1_500),
    };
    // The statusword (TPDO1) and emergencies at most every 10 ms, once a control cycle
    // (inhibit times, in 100 µs): what bounds the drives bus's worst-case response times
    // with the redundant tug's twelve nodes on it (`dbc/reference-tug-drives.dbc` in
    // bywire-tug declares them).
    let od = drive_dictionary(node, mode, profile, (100, 100));
    Device::new(node, od, Drive::new().with_external_motor())
}

/// A drive's dictionary: `mode` with its profile `(velocity, acceleration)`, its statusword's
/// and emergencies' inhibit times (100 µs).
fn drive_dictionary(
    node: u8,
    mode: Mode,
    (velocity, acceleration): (i64, i64),
    (status_inhibit, emergency_inhibit): (u16, u16),
) -> bywire_canopen::od::ObjectDictionary {
    let mut od = cia402::drive_dictionary(node);
    let _ = od.set_int(cia402::object::MODES, 0, i64::from(mode.code()));
    let _ = od.set_int(cia402::object::PROFILE_VELOCITY, 0, velocity);
    let _ = od.set_int(cia402::object::PROFILE_ACCELERATION, 0, acceleration);
    let _ = od.set_int(cia402::object::PROFILE_DECELERATION, 0, acceleration);
    let _ = od.set_int(cia402::object::QUICK_STOP_DECELERATION, 0, acceleration * 2);
    // The actual values (TPDO2) sampled at every SYNC, so the master sees all the drives at
    // one instant each cycle.
    let _ = od.set(0x1801, 2, &[1]);
    let _ = od.set(0x1800, 3, &status_inhibit.to_le_bytes());
    let _ = od.set(0x1015, 0, &emergency_inhibit.to_le_bytes());
    // Each drive watches the ECU's heartbeat: silence faults it.
    let _ = od.set(
        0x1016,
        1,
        &((u32::from(MASTER_NODE) << 16) | 300).to_le_bytes(),
    );
    od
}
