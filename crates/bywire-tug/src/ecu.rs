//! The tug's vehicle control ECU as one node on four ports:
//!
//! - [`BUS1`] (vehicle control, 500 kbit/s): the ADS's commands and the E-stop chain into the
//!   supervisor; out go the supervisor's state frame and the ECU's reports every 20 ms — wheel
//!   speeds and angles (as the drives report them), and the vehicle status;
//! - [`BUS1B`] (the redundant command bus): the commands' second copy, voted on;
//! - [`BUS2`] (drives, CANopen, 1 Mbit/s): the ECU as NMT master of four steering drives
//!   (profile position) and four wheel drives (profile velocity), with SYNC and heartbeats; the
//!   supervisor's actuator outputs become eight setpoints through the 4WS kinematics;
//! - [`BUS3`] (sensors): the steering sensors' second tracks, checked against the first tracks
//!   the steering drives report ([`crate::plausibility`]).
//!
//! On bus 1 it also answers UDS ([`crate::diagnostics`]): its faults as DTCs, its DIDs, the
//! steering calibration sweep, and ECUReset — after which it is silent for [`BOOT_TIME`]
//! (spring brakes applied, the drives losing their master) and starts afresh, its DTC memory
//! kept.
//!
//! Inputs that are not frames come in as values ([`VehicleControlEcu::set_driver_input`],
//! [`VehicleControlEcu::set_status_inputs`], [`VehicleControlEcu::operator_reset`]); what the
//! ECU decides goes out as typed events ([`VehicleControlEcu::next_event`]) and as its brake
//! demand. A drive the master had to stop, or a steering fault, stops the tug: the other wheels
//! alone would drag it off its path.

use core::time::Duration;
use std::collections::VecDeque;

use bywire_canopen::cia402::{Mode, Setpoint};
use bywire_canopen::master::{Controlled, Master, MasterEvent};
use bywire_canopen::nmt::{HeartbeatEvent, NmtCommand};
use bywire_control::kinematics::{four_wheel, Swerve, WheelState};
use bywire_core::node::{Node, Port};
use bywire_core::num::round_to_i32;
use bywire_core::time::earliest;
use bywire_core::{Frame, Id, Timestamp};
use bywire_vehicle::backup::InCharge;
use bywire_vehicle::command::{DegradationLevel, FaultClass, SteeringMode};
use bywire_vehicle::degradation::Fault;
use bywire_vehicle::mechanism::{Mechanism, Mechanisms};
use bywire_vehicle::redundancy::Channel;
use bywire_vehicle::redundancy::{ChannelHealth, TripleConfig, TripleVoter};
use bywire_vehicle::supervisor::{Actuators, Supervisor, SupervisorConfig};
use bywire_vehicle::wire::VehicleWire;

use bywire_core::frame::ErrorClass;

use crate::backup_steering::{BackupSteering, PairChange, SteeringPair};
use crate::diagnostics::{self, DiagnosticRequest, Diagnostics, Observation};
use crate::messages::{
    self, Battery as BatteryMessage, SteeringAngleSensors, SteeringAnglesB, SteeringAnglesC,
    VehicleStatus,
};
use crate::plausibility::{SteeringFault, SteeringPlausibility};
use crate::secured::{self, TugWire};

/// Bus 1, vehicle control (the supervisor's command bus A).
pub const BUS1: Port = Channel::A.port();
/// Bus 1b, the redundant command bus (the supervisor's bus B).
pub const BUS1B: Port = Channel::B.port();
/// Bus 2, the drives (CANopen).
pub const BUS2: Port = Port(2);
/// Bus 3, the sensors.
pub const BUS3: Port = Port(3);

pub use crate::drives::{
    DRIVE_NODES, DRIVE_UNITS_PER_M, MASTER_NODE, STEERING_NODES, STEERING_UNITS_PER_DEG,
};

/// How often the ECU reports wheel speeds, angles and status on bus 1.
const REPORT_PERIOD: Duration = Duration::from_millis(20);
/// Events kept for the caller; more are counted and dropped.
const EVENT_CAPACITY: usize = 64;
/// How long the ECU is silent after an ECUReset.
pub const BOOT_TIME: Duration = Duration::from_millis(500);
/// Below this speed (m/s) the tug is at standstill for the calibration sweep.
const CALIBRATION_STANDSTILL: f64 = 0.05;

/// The chassis the 4WS mapping needs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geometry {
    /// Wheelbase, m.
    pub wheelbase: f64,
    /// Track, m.
    pub track: f64,
}

/// Something the ECU decided or saw.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum EcuEvent {
    /// A drive the master stopped (heartbeat lost, EMCY, fault) stops the tug; `None`: every
    /// drive is enabled again.
    DrivesStopped(Option<u8>),
    /// The steering plausibility check latched a fault.
    SteeringFault(SteeringFault),
    /// The operator's reset of a steering fault: accepted (the tracks agree) or refused.
    SteeringReset {
        /// The fault cleared.
        accepted: bool,
    },
    /// A drive's heartbeat was lost.
    HeartbeatLost(u8),
    /// A drive's heartbeat came back.
    HeartbeatRecovered(u8),
    /// A drive sent an emergency with a non-zero code.
    Emergency {
        /// The drive.
        node: u8,
        /// Its error code.
        code: u16,
    },
}

impl EcuEvent {
    /// The event's kind, as run reports name it.
    pub fn kind(&self) -> &'static str {
        match self {
            EcuEvent::DrivesStopped(_) => "drives",
            EcuEvent::SteeringFault(_) | EcuEvent::SteeringReset { .. } => "plausibility",
            EcuEvent::HeartbeatLost(_) => "heartbeat_lost",
            EcuEvent::HeartbeatRecovered(_) => "heartbeat_recovered",
            EcuEvent::Emergency { .. } => "emcy",
        }
    }
}

/// The event's detail, node IDs and codes in hex.
impl core::fmt::Display for EcuEvent {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            EcuEvent::DrivesStopped(Some(node)) => {
                write!(f, "drive 0x{node:02X} stopped by the master: the tug stops")
            }
            EcuEvent::DrivesStopped(None) => f.write_str("every drive enabled again"),
            EcuEvent::SteeringFault(fault) => write!(f, "{fault}"),
            EcuEvent::SteeringReset { accepted: true } => f.write_str("reset: the tracks agree"),
            EcuEvent::SteeringReset { accepted: false } => {
                f.write_str("reset refused: the tracks still disagree")
            }
            EcuEvent::HeartbeatLost(node) | EcuEvent::HeartbeatRecovered(node) => {
                write!(f, "node 0x{node:02X}")
            }
            EcuEvent::Emergency { node, code } => write!(f, "node 0x{node:02X} code 0x{code:04X}"),
        }
    }
}

/// Values the status report carries that come from the tug's wiring, not from frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StatusInputs {
    /// The E-stop chain (hardwired to the ECU) is open.
    pub estop_chain_open: bool,
    /// The parking brakes are applied.
    pub parking_brake_applied: bool,
}

/// The vehicle control ECU.
pub struct VehicleControlEcu {
    supervisor: Supervisor<TugWire>,
    master: Master,
    plausibility: SteeringPlausibility,
    /// A track arrived (or the check was reset) since the plausibility check last ran, and
    /// the first tracks it last saw (bits): it runs when its tracks arrive and at its own
    /// deadline, never on a poll for something else, so two ECUs given the same frames latch
    /// at the same instant.
    plausibility_due: bool,
    plausibility_seen: Option<[u64; 4]>,
    swerve: Swerve<4>,
    wheel_targets: [WheelState; 4],
    /// What the wheel targets were last worked out from (the command and the targets before
    /// them) and what came out: the same again gives the same, so a poll between commands
    /// reuses it.
    last_wheel_states: Option<(WheelInputs, [WheelState; 4])>,
    /// What the drives were last given: the same commands again are not given again (the
    /// master's controllers keep them), so a poll between commands leaves them be.
    last_commands: Option<DriveCommands>,
    drives_lost: bool,
    status: StatusInputs,
    next_report: Timestamp,
    report_counter: u64,
    events: VecDeque<(Timestamp, EcuEvent)>,
    events_dropped: u64,
    config: SupervisorConfig,
    geometry: Geometry,
    diagnostics: Diagnostics,
    /// Each corner's steering trim from the calibration DID, degrees.
    offsets: [f64; 4],
    /// The BMS's last reading: state of charge (%), voltage (V), current (A).
    battery: Option<(f64, f64, f64)>,
    /// The sensors' second tracks, as the I/O node last sent them.
    second_tracks: [f64; 4],
    /// A calibration sweep: when it began, each corner's summed track difference, samples.
    calibration: Option<(Timestamp, [f64; 4], u32)>,
    /// After an ECUReset: silent until then.
    booting_until: Option<Timestamp>,
    /// The redundant tug: each corner's angle voted 2-out-of-3 (the potentiometer's second
    /// track, modules B and C).
    voted: Option<[TripleVoter; 4]>,
    /// ... and the values of the last vote (`None`: no vote, or none to trust).
    voted_angles: [Option<f64>; 4],
    /// A reading came since the last vote. The vote is taken when readings arrive and at
    /// the voters' own deadlines, never on a poll for something else, so both ECUs of a pair
    /// latch a channel out at the same instant whatever else each is polled for.
    vote_due: bool,
    /// The I/O node's angles came since the last vote: the backup steering samples the vote
    /// then, so both ECUs of a pair sample at the same instants.
    angles_arrived: bool,
    /// The redundant tug: each corner's backup steering valve and its judge.
    backup: Option<BackupSteering>,
    /// Mechanisms of its own switched off (a campaign's proof, see
    /// `bywire_vehicle::mechanism`): without the voter, each corner's angle is its first
    /// channel's, unjudged.
    disabled: Mechanisms,
}

/// The degradation latch's source numbers of the backup steering's faults: this plus the
/// corner (an ECU's own standby loss is source 0).
const BACKUP_SOURCE: u8 = 0x10;

/// The raw value modules B and C send for a corner without a reading.
const NO_READING: u64 = 0x800;

impl VehicleControlEcu {
    /// An ECU with its supervisor configured by `config` (the tug's profile, with redundancy on
    /// bus 1b), mastering the eight drives.
    pub fn new(config: SupervisorConfig, geometry: Geometry) -> Self {
        Self::with_wire(config, geometry, secured::plain())
    }

    /// The same ECU speaking `wire` (the secured variant: [`secured::secured`]).
    pub fn with_wire(config: SupervisorConfig, geometry: Geometry, wire: TugWire) -> Self {
        let mut master = Master::new(
            MASTER_NODE,
            Duration::from_millis(100),
            Duration::from_millis(10),
        )
        .with_sync(Duration::from_millis(10));
        for (nodes, mode) in [
            (STEERING_NODES, Mode::ProfilePosition),
            (DRIVE_NODES, Mode::ProfileVelocity),
        ] {
            for node in nodes {
                crate::drives::add_drive(&mut master, node, mode);
            }
        }
        master.nmt(NmtCommand::Start, 0);
        VehicleControlEcu {
            supervisor: Supervisor::with_wire(config, wire),
            master,
            plausibility: SteeringPlausibility::default(),
            plausibility_due: true,
            plausibility_seen: None,
            swerve: four_wheel(geometry.wheelbase, geometry.track),
            wheel_targets: [WheelState::default(); 4],
            last_wheel_states: None,
            last_commands: None,
            drives_lost: false,
            status: StatusInputs::default(),
            next_report: Timestamp::ZERO,
            report_counter: 0,
            events: VecDeque::with_capacity(EVENT_CAPACITY),
            events_dropped: 0,
            config,
            geometry,
            diagnostics: Diagnostics::new("reference-tug"),
            offsets: [0.0; 4],
            battery: None,
            second_tracks: [0.0; 4],
            calibration: None,
            booting_until: None,
            voted: None,
            voted_angles: [None; 4],
            vote_due: false,
            angles_arrived: false,
            backup: None,
            disabled: Mechanisms::NONE,
        }
    }

    /// Switch off its own mechanisms that `off` names (the 2-out-of-3 voter): a
    /// fault-injection campaign's proof that its cells would notice. The supervisor's are
    /// its configuration's (`SupervisorConfig::disabled`).
    pub fn switch_off(&mut self, off: Mechanisms) {
        self.disabled = off;
    }

    /// The same ECU voting each corner's angle 2-out-of-3 with `configs` (FL, FR, RL, RR):
    /// the potentiometer's second track and modules B and C on bus 3. A channel voted out
    /// and a corner whose vote fails are reported to the supervisor's degradation latch; the
    /// plausibility check compares the drive's track with the voted angle.
    pub fn with_voted_angles(mut self, configs: [TripleConfig; 4]) -> Self {
        self.voted = Some(configs.map(|c| TripleVoter::new(c, Timestamp::ZERO)));
        self
    }

    /// The same ECU with a backup steering valve at each corner (FL, FR, RL, RR), judged by
    /// the voted angles' rate (give [`Self::with_voted_angles`] too: without a vote no pair is
    /// judged, and a lost primary stops the tug as on the plain tug).
    pub fn with_backup_steering(mut self, pairs: [SteeringPair; 4]) -> Self {
        let backup = BackupSteering::new(pairs, Timestamp::ZERO);
        backup.add_drivers(&mut self.master);
        self.backup = Some(backup);
        self
    }

    /// Which actuator steers each corner (the plain tug: always the primary).
    pub fn steering_in_charge(&self) -> [InCharge; 4] {
        match &self.backup {
            Some(backup) => [0, 1, 2, 3].map(|corner| backup.in_charge(corner)),
            None => [InCharge::Primary; 4],
        }
    }

    /// Vote each corner's angle, if a reading came or a voter's deadline has passed: faults
    /// to the latch (each channel out, each corner lost; the latch takes a fault it has
    /// once), the plausibility check given the voted angles (NaN where a vote has no value).
    /// Out of the poll's line: the plain tug votes none.
    #[inline(never)]
    fn vote_angles(&mut self, now: Timestamp) {
        if !self.vote_due && self.vote_deadline().is_none_or(|at| now < at) {
            return;
        }
        self.vote_due = false;
        let Some(voters) = self.voted.as_mut() else {
            return;
        };
        let mut angles = [None; 4];
        let unvoted = self.disabled.contains(Mechanism::Voter);
        for (corner, (voter, angle)) in voters.iter_mut().zip(angles.iter_mut()).enumerate() {
            if unvoted {
                *angle = voter.reading(0);
                continue;
            }
            let vote = voter.vote(now);
            *angle = vote.value();
            let source = u8::try_from(corner).unwrap_or(0);
            let mut report = |class, source| {
                self.supervisor.report_fault(Fault {
                    class,
                    source,
                    at: now,
                })
            };
            for (channel, health) in (0u8..).zip(voter.health()) {
                if matches!(health, ChannelHealth::Out(_)) {
                    report(FaultClass::SensorChannelOut, source * 3 + channel);
                }
            }
            if voter.lost(vote) {
                report(FaultClass::SensorLost, source);
            }
        }
        self.plausibility
            .second_tracks(now, angles.map(|a| a.unwrap_or(f64::NAN)));
        self.plausibility_due = true;
        self.voted_angles = angles;
        if let (Some(backup), true) = (self.backup.as_mut(), self.angles_arrived) {
            backup.sample(now, angles);
        }
        self.angles_arrived = false;
    }

    /// When a voter next judges on time alone (a channel silent, a suspect's persistence
    /// over).
    fn vote_deadline(&self) -> Option<Timestamp> {
        let voters = self.voted.as_ref()?;
        voters.iter().filter_map(TripleVoter::next_deadline).min()
    }

    /// The backup steering's step (the redundant tug): each corner's pair judged and
    /// commanded, a change reported to the degradation latch — the backup taking over, the
    /// backup failing too, an idle backup lost. Out of the poll's line: the plain tug has none.
    #[inline(never)]
    fn steer_backup(&mut self, now: Timestamp, a: &Actuators) {
        let Some(backup) = self.backup.as_mut() else {
            return;
        };
        let targets = self.wheel_targets.map(|w| w.angle.to_degrees());
        let steering_on = a.steering_enabled || a.motors_enabled;
        let changes = backup.step(
            now,
            &mut self.master,
            (targets, self.voted_angles),
            steering_on,
        );
        for (corner, change) in (0u8..).zip(changes) {
            let class = match change {
                Some(PairChange::InCharge(InCharge::Backup)) => FaultClass::ActuatorBackup,
                Some(PairChange::InCharge(InCharge::Neither)) => FaultClass::ActuatorLost,
                Some(PairChange::BackupLost) => FaultClass::StandbyLost,
                Some(PairChange::InCharge(InCharge::Primary)) | None => continue,
            };
            self.supervisor.report_fault(Fault {
                class,
                // The ECU standby's own loss is source 0.
                source: BACKUP_SOURCE + corner,
                at: now,
            });
        }
    }

    /// The diagnostics: the UDS server with the DTC memory.
    pub fn diagnostics(&self) -> &Diagnostics {
        &self.diagnostics
    }

    /// Whether the ECU is rebooting after an ECUReset.
    pub fn booting(&self, now: Timestamp) -> bool {
        self.booting_until.is_some_and(|until| now < until)
    }

    /// Start afresh, as after power-on: a new supervisor (failed closed), a new master, no
    /// latched faults; the diagnostics' DTC memory, the odometer and the wiring's inputs
    /// stay, and so does the wire's freshness. Silent for [`BOOT_TIME`].
    fn restart(&mut self, now: Timestamp) {
        // The wire's freshness values are kept, as in non-volatile memory: a restart is not a
        // rewind.
        let wire = self.supervisor.wire_mut().clone();
        let mut fresh = VehicleControlEcu::with_wire(self.config, self.geometry, wire);
        core::mem::swap(&mut fresh.diagnostics, &mut self.diagnostics);
        fresh.diagnostics.restart();
        fresh.offsets = fresh.diagnostics.steering_offsets();
        fresh.status = self.status;
        fresh.battery = self.battery;
        fresh.events = core::mem::take(&mut self.events);
        fresh.events_dropped = self.events_dropped;
        fresh.booting_until = Some(now.saturating_add(BOOT_TIME));
        fresh.voted = self
            .voted
            .map(|voters| voters.map(|voter| TripleVoter::new(voter.config(), now)));
        if let Some(backup) = &self.backup {
            let mut backup = backup.clone();
            backup.reset(now);
            backup.add_drivers(&mut fresh.master);
            fresh.backup = Some(backup);
        }
        fresh.next_report = now.saturating_add(BOOT_TIME);
        *self = fresh;
    }

    /// The supervisor (watchdog, latch, mode, counts, degraded bus, degradation level).
    pub fn supervisor(&self) -> &Supervisor<TugWire> {
        &self.supervisor
    }

    /// A fault a fail-operational mechanism found: the degradation level from now on.
    pub fn report_fault(&mut self, fault: Fault) -> DegradationLevel {
        self.supervisor.report_fault(fault)
    }

    /// Back to nominal after a repair, only at a standstill (whether it was reset): the
    /// degradation level, and every angle channel voted in again.
    pub fn reset_degradation(&mut self, now: Timestamp) -> bool {
        let reset = self.supervisor.reset_degradation();
        if let (true, Some(voters)) = (reset, self.voted.as_mut()) {
            for voter in voters {
                voter.reset(now);
            }
        }
        if let (true, Some(backup)) = (reset, self.backup.as_mut()) {
            backup.reset(now);
            // The primaries enabled again with the next commands.
            self.last_commands = None;
        }
        reset
    }

    /// A fault of this ECU's own, as a test bench injects it: a corner's steering trim
    /// corrupted in its memory by `deg` (its setpoints for that corner off by as much).
    pub fn corrupt_trim(&mut self, corner: usize, deg: f64) {
        if let Some(offset) = self.offsets.get_mut(corner) {
            *offset += deg;
        }
        self.last_commands = None;
    }

    /// The CANopen master (its drive controllers' states). Whatever is changed through it,
    /// the next poll gives the drives their commands again.
    pub fn master(&mut self) -> &mut Master {
        self.last_commands = None;
        &mut self.master
    }

    /// The driver's steering torque (N·m) and pedal (0–1): above the thresholds, a takeover.
    pub fn set_driver_input(&mut self, torque: f64, pedal: f64) {
        self.supervisor.set_driver_input(torque, pedal);
    }

    /// The status report's inputs from the wiring.
    pub fn set_status_inputs(&mut self, status: StatusInputs) {
        self.status = status;
    }

    /// The operator's reset: acknowledges drives the master stopped, and clears a steering
    /// fault whose tracks agree again (reported as an event). The E-stop latch's reset is the
    /// ADS's command bit, not this.
    pub fn operator_reset(&mut self, now: Timestamp) {
        if self.plausibility.faulted().is_some() {
            let first = self.first_tracks();
            let accepted = self.plausibility.reset(now, first);
            self.plausibility_due = true;
            self.push(now, EcuEvent::SteeringReset { accepted });
        }
        let backups = self
            .backup
            .as_ref()
            .map_or([0; 4], BackupSteering::backup_nodes);
        for node in DRIVE_NODES.iter().chain(&STEERING_NODES).chain(&backups) {
            if let Some(Controlled::Drive(d)) = self.master.controlled(*node) {
                d.acknowledge();
            }
        }
    }

    /// The steering fault latched, if any.
    pub fn steering_fault(&self) -> Option<SteeringFault> {
        self.plausibility.faulted()
    }

    /// Whether the ECU stops the tug on its own: a drive stopped by the master, a steering
    /// fault, or a reboot (its outputs off: the spring brakes apply).
    pub fn stops(&self) -> bool {
        self.drives_lost || self.plausibility.faulted().is_some() || self.booting_until.is_some()
    }

    /// What the supervisor asks of the actuators now.
    pub fn actuators(&self, now: Timestamp) -> Actuators {
        self.supervisor.actuators(now)
    }

    /// The friction brakes' demand now, 0–1: the supervisor's, or full when the ECU stops.
    pub fn brake_demand(&self, now: Timestamp) -> f64 {
        self.brake_demand_of(&self.supervisor.actuators(now))
    }

    /// The friction brakes' demand for actuators `a` the supervisor asked for now (a caller
    /// that has them already asks once).
    pub fn brake_demand_of(&self, a: &Actuators) -> f64 {
        if self.stops() {
            1.0
        } else {
            a.brake / 100.0
        }
    }

    /// Whether events wait to be taken.
    pub fn has_events(&self) -> bool {
        !self.events.is_empty()
    }

    /// The oldest event not yet taken.
    pub fn next_event(&mut self) -> Option<(Timestamp, EcuEvent)> {
        self.events.pop_front()
    }

    /// Events dropped because the caller did not take them.
    pub fn events_dropped(&self) -> u64 {
        self.events_dropped
    }

    fn push(&mut self, now: Timestamp, event: EcuEvent) {
        match event {
            EcuEvent::HeartbeatLost(node) => self.diagnostics.heartbeat(now, node, true),
            EcuEvent::HeartbeatRecovered(node) => self.diagnostics.heartbeat(now, node, false),
            EcuEvent::Emergency { node, code } => self.diagnostics.emergency(now, node, code),
            EcuEvent::SteeringFault(fault) => {
                self.diagnostics.steering_sensors(now, Some(fault.corner()));
            }
            EcuEvent::SteeringReset { accepted: true } => {
                self.diagnostics.steering_sensors(now, None);
            }
            EcuEvent::SteeringReset { accepted: false } | EcuEvent::DrivesStopped(_) => {}
        }
        if self.events.len() < EVENT_CAPACITY {
            self.events.push_back((now, event));
        } else {
            self.events_dropped = self.events_dropped.saturating_add(1);
        }
    }

    /// The steering sensors' first tracks, as the steering drives report them, degrees.
    /// A corner the backup steers reads its voted angle in the first track's place (its
    /// drive, off or lost, reports nothing current), the trim added as the track has it.
    pub fn first_tracks(&mut self) -> [f64; 4] {
        let mut angles = [0.0; 4];
        for (angle, steer) in angles.iter_mut().zip(STEERING_NODES) {
            if let Some(Controlled::Drive(d)) = self.master.controlled(steer) {
                *angle = f64::from(d.actual().0) / STEERING_UNITS_PER_DEG;
            }
        }
        if self.backup.is_some() {
            self.voted_in_place_of_tracks(&mut angles);
        }
        angles
    }

    /// The voted angles where the backup steers (out of the poll's line: the plain tug has
    /// no backup).
    #[inline(never)]
    fn voted_in_place_of_tracks(&self, angles: &mut [f64; 4]) {
        let Some(backup) = &self.backup else {
            return;
        };
        for (corner, ((angle, voted), offset)) in angles
            .iter_mut()
            .zip(self.voted_angles)
            .zip(self.offsets)
            .enumerate()
        {
            if let (InCharge::Backup | InCharge::Neither, Some(voted)) =
                (backup.in_charge(corner), voted)
            {
                *angle = voted + offset;
            }
        }
    }

    /// The wheels' speeds as the wheel drives report them, m/s. A drive the master has
    /// stopped (its heartbeat lost, a fault) reports nothing current: its last value would
    /// tell the ADS's odometry the wheel still turns, so the healthy wheels' mean stands in
    /// (the tug is stopping on all four).
    fn wheel_speeds(&mut self) -> [f64; 4] {
        let mut speeds = [None; 4];
        for (speed, drive) in speeds.iter_mut().zip(DRIVE_NODES) {
            if let Some(Controlled::Drive(d)) = self.master.controlled(drive) {
                if d.stopped().is_none() {
                    *speed = Some(f64::from(d.actual().1) / DRIVE_UNITS_PER_M);
                }
            }
        }
        let (sum, count) = speeds
            .iter()
            .flatten()
            .fold((0.0, 0.0), |(sum, count), s| (sum + s, count + 1.0));
        let mean = if count > 0.0 { sum / count } else { 0.0 };
        speeds.map(|s| s.unwrap_or(mean))
    }

    /// The second tracks from the I/O node on bus 3.
    fn on_sensor_frame(&mut self, now: Timestamp, frame: &Frame) {
        if let Some(voters) = self.voted.as_mut() {
            for (channel, id) in [(1, SteeringAnglesB::ID), (2, SteeringAnglesC::ID)] {
                if frame.id() != Id::standard(id).ok() {
                    continue;
                }
                let sealed = messages::payload(frame).filter(|p| messages::is_sealed(id, p));
                if let Some(payload) = sealed {
                    // Both modules' messages have one layout.
                    let m = SteeringAnglesB(payload);
                    let readings = [
                        (m.angle_fl_raw(), m.angle_fl()),
                        (m.angle_fr_raw(), m.angle_fr()),
                        (m.angle_rl_raw(), m.angle_rl()),
                        (m.angle_rr_raw(), m.angle_rr()),
                    ];
                    for (voter, (raw, angle)) in voters.iter_mut().zip(readings) {
                        if raw != NO_READING {
                            voter.receive(channel, now, angle);
                        }
                    }
                    self.vote_due = true;
                }
                return;
            }
        }
        let is_tracks = frame.id() == Id::standard(SteeringAngleSensors::ID).ok();
        let Some(payload) = messages::payload(frame).filter(|_| is_tracks) else {
            return;
        };
        if messages::is_sealed(SteeringAngleSensors::ID, &payload) {
            let m = SteeringAngleSensors(payload);
            self.second_tracks = [
                m.second_angle_fl(),
                m.second_angle_fr(),
                m.second_angle_rl(),
                m.second_angle_rr(),
            ];
            match self.voted.as_mut() {
                // Voted, the track is one channel of three; the plausibility check is given
                // the voted angle.
                Some(voters) => {
                    for (voter, angle) in voters.iter_mut().zip(self.second_tracks) {
                        voter.receive(0, now, angle);
                    }
                    self.angles_arrived = true;
                    self.vote_due = true;
                }
                None => {
                    self.plausibility.second_tracks(now, self.second_tracks);
                    self.plausibility_due = true;
                }
            }
        }
    }

    /// The drives' stop and the plausibility check, then the eight setpoints from the
    /// actuators through the 4WS kinematics.
    fn command_drives(&mut self, now: Timestamp, a: &Actuators, first_tracks: [f64; 4]) {
        // A drive the backup steering answers for is its to judge.
        let backup = self.backup.as_ref();
        let stopped = DRIVE_NODES.iter().chain(&STEERING_NODES).copied().find(|node| {
            matches!(self.master.controlled(*node), Some(Controlled::Drive(d)) if d.stopped().is_some())
                && !backup.is_some_and(|b| b.answers_for(*node))
        });
        if stopped.is_some() != self.drives_lost {
            self.drives_lost = stopped.is_some();
            self.push(now, EcuEvent::DrivesStopped(stopped));
        }
        let seen = first_tracks.map(f64::to_bits);
        let due = self.plausibility_due
            || self.plausibility_seen != Some(seen)
            || self
                .plausibility
                .next_deadline()
                .is_some_and(|at| at <= now);
        if due {
            self.plausibility_due = false;
            self.plausibility_seen = Some(seen);
            if let Some(fault) = self.plausibility.check(now, first_tracks) {
                self.push(now, EcuEvent::SteeringFault(fault));
            }
        }
        let speed = if a.motors_enabled && !self.stops() {
            a.velocity
        } else {
            0.0
        };
        let sweep = self.sweep_angle(now);
        let targets = match sweep {
            // The calibration sweep: every wheel to the same angle, none turning.
            Some(angle) => {
                [WheelState {
                    angle: angle.to_radians(),
                    speed: 0.0,
                }; 4]
            }
            None => {
                let inputs = WheelInputs {
                    mode: a.steering_mode,
                    speed: speed.to_bits(),
                    steering: a.steering.to_bits(),
                    before: self
                        .wheel_targets
                        .map(|w| (w.angle.to_bits(), w.speed.to_bits())),
                };
                match self.last_wheel_states {
                    Some((last, states)) if last == inputs => states,
                    _ => {
                        let states = a.steering_mode.wheel_states(
                            speed,
                            a.steering.to_radians(),
                            &self.swerve,
                            &self.wheel_targets,
                        );
                        self.last_wheel_states = Some((inputs, states));
                        states
                    }
                }
            }
        };
        self.wheel_targets = targets;
        let steering_on = a.steering_enabled || a.motors_enabled || sweep.is_some();
        let faulted = self.plausibility.faulted().map(|f| f.corner());
        let commands = DriveCommands {
            targets: targets.map(|w| (w.angle.to_bits(), w.speed.to_bits())),
            offsets: self.offsets.map(f64::to_bits),
            steering_on,
            faulted,
        };
        if self.last_commands == Some(commands) {
            return;
        }
        self.last_commands = Some(commands);
        for (i, (target, (steer, drive))) in targets
            .iter()
            .zip(STEERING_NODES.iter().zip(DRIVE_NODES))
            .enumerate()
        {
            let offset = self.offsets.get(i).copied().unwrap_or(0.0);
            if let Some(Controlled::Drive(d)) = self.master.controlled(*steer) {
                // A corner whose sensors disagree is not steered: its valve holds the wheel.
                d.set_enabled(steering_on && faulted != Some(i));
                d.set_setpoint(Setpoint::Position(round_to_i32(
                    (target.angle.to_degrees() + offset) * STEERING_UNITS_PER_DEG,
                )));
            }
            if let Some(Controlled::Drive(d)) = self.master.controlled(drive) {
                d.set_enabled(true);
                d.set_setpoint(Setpoint::Velocity(round_to_i32(
                    target.speed * DRIVE_UNITS_PER_M,
                )));
            }
        }
    }

    /// The calibration sweep's angle now (one sine period over the sweep), if it runs.
    fn sweep_angle(&self, now: Timestamp) -> Option<f64> {
        let (started, ..) = self.calibration?;
        let phase =
            now.saturating_since(started).as_secs_f64() / diagnostics::SWEEP_TIME.as_secs_f64();
        Some(diagnostics::SWEEP_DEG * libm::sin(2.0 * core::f64::consts::PI * phase.min(1.0)))
    }

    /// Every report cycle of the sweep: each corner's track difference summed; at its end,
    /// the means become the routine's results.
    fn calibrate(&mut self, now: Timestamp, first_tracks: [f64; 4]) {
        let Some((started, mut sums, mut samples)) = self.calibration else {
            return;
        };
        if !self.diagnostics.calibrating(now) {
            return;
        }
        for (sum, (second, first)) in sums
            .iter_mut()
            .zip(self.second_tracks.iter().zip(first_tracks))
        {
            *sum += second - first;
        }
        samples = samples.saturating_add(1);
        self.calibration = Some((started, sums, samples));
    }

    /// What the tester asked of the ECU.
    fn serve_diagnostics(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        // The sweep's end: its results before the server answers anything more.
        if let Some((_, sums, samples)) = self.calibration {
            if !self.diagnostics.calibrating(now) {
                self.calibration = None;
                let n = f64::from(samples.max(1));
                self.diagnostics.calibration_result(sums.map(|s| s / n));
            }
        }
        self.diagnostics.poll(now, &mut |frame| out(BUS1, frame));
        // Bounded by the diagnostics' request queue.
        while let Some(request) = self.diagnostics.next_request() {
            match request {
                DiagnosticRequest::Reset => {
                    self.restart(now);
                    return;
                }
                DiagnosticRequest::OffsetsWritten => {
                    self.offsets = self.diagnostics.steering_offsets();
                }
                DiagnosticRequest::CalibrationStarted => {
                    self.calibration = Some((now, [0.0; 4], 0));
                }
                DiagnosticRequest::CalibrationStopped => self.calibration = None,
            }
        }
    }

    /// The wheel targets of the last command (for a plant's "aligned yet?").
    pub fn wheel_targets(&self) -> [WheelState; 4] {
        self.wheel_targets
    }

    /// Every 20 ms: wheel speeds, wheel angles and status on bus 1.
    fn report(
        &mut self,
        now: Timestamp,
        out: &mut dyn FnMut(Port, Frame),
        angles: [f64; 4],
        speeds: [f64; 4],
    ) {
        if now < self.next_report {
            return;
        }
        self.next_report = now.saturating_add(REPORT_PERIOD);
        self.diagnose(now, angles, speeds);
        let counter = self.report_counter & 0x0F;
        self.report_counter = self.report_counter.wrapping_add(1);
        // The frames any vehicle on this wire sends (the simulated vehicle's too).
        let wire = self.supervisor.wire_mut();
        let frames = [
            wire.wheel_speeds_frame(speeds, counter),
            wire.wheel_angles_frame(angles, counter),
        ];
        for frame in frames.into_iter().flatten() {
            out(BUS1, frame);
        }
        let mut status = VehicleStatus::default();
        status.set_drive_fault_raw(u64::from(self.drives_lost));
        status.set_steering_fault_raw(u64::from(self.plausibility.faulted().is_some()));
        status.set_degraded_bus_raw(u64::from(self.supervisor.degraded().is_some()));
        status.set_estop_chain_open_raw(u64::from(self.status.estop_chain_open));
        status.set_parking_brake_applied_raw(u64::from(self.status.parking_brake_applied));
        status.set_counter_raw(counter);
        out(BUS1, messages::sealed_frame(VehicleStatus::ID, status.0));
    }

    /// The monitors, every report cycle.
    fn diagnose(&mut self, now: Timestamp, angles: [f64; 4], speeds: [f64; 4]) {
        let speed = speeds.iter().sum::<f64>() / 4.0;
        let steering = angles.first().copied().unwrap_or(0.0);
        self.calibrate(now, angles);
        self.diagnostics.observe(
            now,
            &Observation {
                watchdog: self.supervisor.watchdog(),
                estop: self.supervisor.estop(),
                degraded: self.supervisor.degraded(),
                stats: self.supervisor.stats(),
                driver_input: self.supervisor.driver_input(),
                speed,
                steering,
            },
        );
        self.diagnostics.refresh_values(now, self.battery);
        // The sweep needs the tug at standstill and the ADS not driving it (manual, or its
        // commands braked away by the watchdog or the E-stop).
        let standstill = speed.abs() < CALIBRATION_STANDSTILL;
        let a = self.supervisor.actuators(now);
        let ads_driving = a.ads_in_control && a.motors_enabled;
        self.diagnostics
            .allow_calibration(standstill && !ads_driving);
    }

    /// A bus-1 frame that is not a command: diagnostics, the BMS's reading, the
    /// controller's state.
    fn on_bus1_frame(&mut self, now: Timestamp, frame: &Frame) {
        if let Frame::Error(error) = frame {
            if error.has(ErrorClass::BusOff) {
                self.diagnostics.bus_off(now, true);
            } else if error.has(ErrorClass::Restarted) {
                self.diagnostics.bus_off(now, false);
            }
            return;
        }
        // Every bus-1 identifier is an 11-bit one.
        let raw = frame.id().filter(|id| !id.is_extended()).map(Id::as_raw);
        if raw == Some(diagnostics::REQUEST_ID) || raw == Some(diagnostics::FUNCTIONAL_ID) {
            self.diagnostics.on_frame(now, frame);
        } else if raw == Some(BatteryMessage::ID) {
            if let Some(payload) =
                messages::payload(frame).filter(|p| messages::is_sealed(BatteryMessage::ID, p))
            {
                let m = BatteryMessage(payload);
                self.battery = Some((
                    m.state_of_charge(),
                    m.battery_voltage(),
                    m.battery_current(),
                ));
            }
        } else {
            Node::on_frame(
                &mut self.supervisor,
                now,
                Supervisor::<TugWire>::PORT_A,
                frame,
            );
        }
    }

    fn take_master_events(&mut self, now: Timestamp) {
        // Bounded by the master's own event queue.
        while let Some(event) = self.master.next_event() {
            let event = match event {
                MasterEvent::Heartbeat(HeartbeatEvent::Lost { node }) => {
                    EcuEvent::HeartbeatLost(node)
                }
                MasterEvent::Heartbeat(HeartbeatEvent::Recovered { node, .. }) => {
                    EcuEvent::HeartbeatRecovered(node)
                }
                MasterEvent::Emergency { node, emergency } if emergency.code != 0 => {
                    EcuEvent::Emergency {
                        node,
                        code: emergency.code,
                    }
                }
                // Error reset: the drive's emergency monitor passes.
                MasterEvent::Emergency { node, .. } => {
                    self.diagnostics.emergency(now, node, 0);
                    continue;
                }
                _ => continue,
            };
            self.push(now, event);
        }
    }

    /// Feedback for the supervisor: the wheels' mean speed and the front-left angle, as the
    /// drives report them.
    fn feed_back(&mut self, first_tracks: [f64; 4], speeds: [f64; 4]) {
        let mean = speeds.iter().map(|s| s / 4.0).sum::<f64>();
        let angle = first_tracks.first().copied().unwrap_or(0.0);
        self.supervisor.set_feedback(mean, angle);
    }
}

impl Node for VehicleControlEcu {
    fn on_frame(&mut self, now: Timestamp, port: Port, frame: &Frame) {
        if self.booting(now) {
            return;
        }
        match port {
            BUS1 => self.on_bus1_frame(now, frame),
            BUS1B => self
                .supervisor
                .on_frame(now, Supervisor::<TugWire>::PORT_B, frame),
            BUS2 => self.master.on_frame(now, Port::MAIN, frame),
            BUS3 => self.on_sensor_frame(now, frame),
            _ => {}
        }
    }

    fn on_sent(&mut self, now: Timestamp, port: Port, frame: &Frame) -> bool {
        // Only the diagnostic responses are timed by their confirmations.
        let raw = frame.id().filter(|id| !id.is_extended()).map(Id::as_raw);
        let response = port == BUS1 && raw == Some(diagnostics::RESPONSE_ID);
        if response {
            self.diagnostics.on_sent(now, frame);
        }
        response
    }

    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        match self.booting_until {
            Some(until) if now < until => return,
            Some(_) => self.booting_until = None,
            None => {}
        }
        // The state frame goes on bus 1 only: the ADS reads it there.
        self.supervisor.poll(now, &mut |port, frame| {
            if port == Supervisor::<TugWire>::PORT_A {
                out(BUS1, frame);
            }
        });
        // The voted angles (the redundant tug): faults to the latch before the actuators are
        // asked, the plausibility check given them.
        if self.voted.is_some() {
            self.vote_angles(now);
        }
        let actuators = self.supervisor.actuators(now);
        // The drives' actual values change only with their frames: read once a poll (the
        // speeds after the master's poll, which may stop a drive).
        let first_tracks = self.first_tracks();
        self.command_drives(now, &actuators, first_tracks);
        if self.backup.is_some() {
            self.steer_backup(now, &actuators);
        }
        self.master.poll(now, &mut |_, frame| out(BUS2, frame));
        self.take_master_events(now);
        let speeds = self.wheel_speeds();
        self.feed_back(first_tracks, speeds);
        self.report(now, out, first_tracks, speeds);
        self.serve_diagnostics(now, out);
    }

    fn next_deadline(&self) -> Option<Timestamp> {
        if let Some(until) = self.booting_until {
            return Some(until);
        }
        earliest([
            self.supervisor.next_deadline(),
            self.master.next_deadline(),
            Some(self.next_report),
            self.diagnostics.next_deadline(),
            self.vote_deadline(),
            self.plausibility.next_deadline(),
        ])
    }
}

/// What the drives are given, bit for bit: each wheel's target angle and speed, the steering
/// trims, whether steering is on and which corner is not steered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct DriveCommands {
    targets: [(u64, u64); 4],
    offsets: [u64; 4],
    steering_on: bool,
    faulted: Option<usize>,
}

/// What the wheel targets are worked out from, bit for bit: the steering mode, speed (m/s),
/// steering angle (degrees) and the targets before (each wheel's angle and speed).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct WheelInputs {
    mode: SteeringMode,
    speed: u64,
    steering: u64,
    before: [(u64, u64); 4],
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn drive_setpoint(ecu: &mut VehicleControlEcu, node: u8) -> Setpoint {
        match ecu.master().controlled(node) {
            Some(Controlled::Drive(d)) => d.setpoint(),
            _ => panic!("no drive at node {node}"),
        }
    }

    /// The commands are not given again while they stay the same, but a change made through
    /// `master()` is undone by the next poll, as it was when every poll gave them all.
    #[test]
    fn the_drives_get_their_commands_again_after_a_change_through_the_master() {
        let geometry = Geometry {
            wheelbase: 2.5,
            track: 1.5,
        };
        let mut ecu = VehicleControlEcu::new(SupervisorConfig::default(), geometry);
        let mut out = |_: Port, _: Frame| {};
        ecu.poll(Timestamp::from_millis(1), &mut out);
        let node = DRIVE_NODES[0];
        let given = drive_setpoint(&mut ecu, node);
        assert_eq!(given, Setpoint::Velocity(0));
        if let Some(Controlled::Drive(d)) = ecu.master().controlled(node) {
            d.set_setpoint(Setpoint::Velocity(1_234));
        }
        ecu.poll(Timestamp::from_millis(2), &mut out);
        assert_eq!(drive_setpoint(&mut ecu, node), given);
    }
}
