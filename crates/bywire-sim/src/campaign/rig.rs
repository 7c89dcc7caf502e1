//! One campaign cell on the simulated runner: a profile's vehicle ([`SimulatedVehicle`]: its
//! real supervisor and wire), a fault-injecting ADS, the vehicle's safety controller and an
//! intruder, on one or two bit-timed buses; brought to its operating state, given its fault,
//! and watched a millisecond at a time.
//!
//! The ADS here is a test source, not the real ADS side (`bywire_vehicle::ads::Ads`), for the
//! reason a test bench has one: the real ADS refuses to send what these faults send
//! (setpoints beyond the limits, repeated counters, wrong checksums). It encodes through the
//! profile's own wire, so every frame is the vehicle's format.

use core::time::Duration;
use std::path::Path;

use bywire_core::node::{Node, Port};
use bywire_core::{Frame, Id, Timestamp};
use bywire_dbc::codec::MessageCodec;
use bywire_net::network::{Network, NodeHandle};
use bywire_net::sim::{Corruption, Fault as WireFault, NodeId, Tamper};
use bywire_secoc::keys::KeyFile;
use bywire_vehicle::ads::AdsCommand;
use bywire_vehicle::command::{ControlMode, DegradationLevel, Gear};
use bywire_vehicle::degradation::Fault as DegradationFault;
use bywire_vehicle::mechanism::{Mechanism, Mechanisms};
use bywire_vehicle::profile::{LoadedProfile, SecOcRoles};
use bywire_vehicle::secured::{Secured, SecuredTable};
use bywire_vehicle::supervisor::{Actuators, CommandStats, EstopState, Supervisor, Watchdog};
use bywire_vehicle::wire::{AdsWire, ProfileWire};

use super::{
    cell_name, Campaign, CampaignError, Cell, CellResult, Detection, FaultClass, Model,
    ProfileEntry, Reaction, State, Verdict,
};
use crate::rng::Rng;
use crate::vehicle::SimulatedVehicle;

type Wire = Secured<ProfileWire>;
type VehicleNode = SimulatedVehicle<Wire>;

/// A campaign's vehicle, loaded once and shared by its cells.
pub struct Vehicle {
    pub(super) label: String,
    /// What its cells run.
    pub(super) model: Model,
    /// The tug model: the redundant tug.
    pub(super) redundant: bool,
    profile: LoadedProfile,
    /// The profile without `[secoc]`: what the ADS and the intruder encode with.
    plain: LoadedProfile,
    keys: Option<KeyFile>,
    buses: u8,
    pub(super) disabled: Mechanisms,
}

/// A key file holding `key` (32 hex digits) as `id`, in memory (`name` for its errors).
fn key_file(id: u32, key: &str, name: &str) -> Result<KeyFile, String> {
    KeyFile::parse(Path::new(name), format!("{id} {key}\n").as_bytes()).map_err(|e| e.to_string())
}

/// A key the intruder signs with: not the vehicle's.
const INTRUDER_KEY: &str = "000102030405060708090a0b0c0d0e0f";

impl Vehicle {
    /// The vehicle `entry` names (a built-in profile, or a file relative to `dir`), with the
    /// mechanisms `disabled` switched off in its supervisor.
    pub fn load(
        entry: &ProfileEntry,
        dir: &Path,
        disabled: Mechanisms,
    ) -> Result<Vehicle, CampaignError> {
        let fail = |reason: String| CampaignError::Profile {
            name: entry.name.clone(),
            reason,
        };
        let mut profile =
            bywire_tug::named_or_file(&entry.name, dir).map_err(|e| fail(e.to_string()))?;
        let mut plain = profile.clone();
        plain.profile.secoc = None;
        let keys = match &entry.secoc {
            None => None,
            Some(table) => {
                let mut table = table.clone();
                let key = table
                    .remove("test_key")
                    .and_then(|k| k.as_str().map(str::to_string))
                    .ok_or_else(|| fail("[profile.secoc] needs test_key (32 hex digits)".into()))?;
                let roles: SecOcRoles = toml::Value::Table(table)
                    .try_into()
                    .map_err(|e| fail(format!("[profile.secoc]: {e}")))?;
                let keys = key_file(roles.key_id, &key, "test_key").map_err(fail)?;
                profile.profile.secoc = Some(roles);
                Some(keys)
            }
        };
        let redundant = entry.name == "reference-tug-redundant";
        if entry.model == Model::Tug && !(redundant || entry.name == "reference-tug") {
            return Err(fail(
                "model = \"tug\" is the reference tug's: reference-tug or reference-tug-redundant"
                    .into(),
            ));
        }
        let vehicle = Vehicle {
            label: entry.label().to_string(),
            model: entry.model,
            redundant,
            profile,
            plain,
            keys,
            buses: entry.buses,
            disabled,
        };
        // Everything a cell builds, built once here so that a bad profile fails the run.
        vehicle.vehicle_wire()?;
        vehicle.table(None)?;
        Ok(vehicle)
    }

    fn fail(&self, reason: String) -> CampaignError {
        CampaignError::Profile {
            name: self.label.clone(),
            reason,
        }
    }

    fn vehicle_wire(&self) -> Result<Wire, CampaignError> {
        self.profile
            .wire_with_keys(self.keys.as_ref(), 1)
            .map_err(|e| self.fail(e.to_string()))
    }

    /// A sender's table: signing with the vehicle's key, or (`key`) another.
    fn table(&self, key: Option<&str>) -> Result<Option<SecuredTable>, CampaignError> {
        let (Some(keys), Some(roles)) = (&self.keys, &self.profile.profile.secoc) else {
            return Ok(None);
        };
        let other;
        let keys = match key {
            None => keys,
            Some(key) => {
                other = key_file(roles.key_id, key, "intruder").map_err(|e| self.fail(e))?;
                &other
            }
        };
        self.profile
            .secured_table(keys, 1)
            .map_err(|e| self.fail(e.to_string()))
    }

    fn plain_wire(&self) -> Result<ProfileWire, CampaignError> {
        ProfileWire::new(&self.plain).map_err(|e| self.fail(e.to_string()))
    }

    fn secured(&self) -> bool {
        self.keys.is_some()
    }

    /// The vehicle's steering (degrees) and speed (m/s) limits.
    pub(super) fn limits(&self) -> (f64, f64) {
        let c = self.profile.supervisor_config();
        (c.steering_range, c.speed_limit)
    }

    /// Its command cycle.
    pub(super) fn cycle(&self) -> Duration {
        self.profile.supervisor_config().cycle
    }
}

/// `frame` as a sender with `table` puts it on the wire: signed where the profile secures it.
fn signed(table: &mut Option<SecuredTable>, frame: Option<Frame>) -> Option<Frame> {
    match table.as_mut() {
        Some(table) => frame.and_then(|f| table.protect(f)),
        None => frame,
    }
}

/// The fault-injecting ADS: the command every cycle on each command bus.
struct TestAds {
    wire: ProfileWire,
    table: Option<SecuredTable>,
    /// The command's codec and its checksum signal, to corrupt the checksum.
    checksum: Option<(MessageCodec, usize)>,
    command: AdsCommand,
    counter: u64,
    cycle: Duration,
    next: Timestamp,
    buses: u8,
    silent: bool,
    frozen: bool,
    skip_once: bool,
    corrupt_checksum: bool,
    slow_percent: f64,
    jitter_ms: u64,
    rng: Rng,
}

impl TestAds {
    fn frame(&mut self) -> Option<Frame> {
        if self.skip_once {
            self.skip_once = false;
            self.counter = self.counter.wrapping_add(1);
        }
        let frame = self.wire.command_frame(&self.command, self.counter)?;
        let frame = match (&self.checksum, self.corrupt_checksum) {
            (Some((codec, index)), true) => {
                let mut data = [0u8; 8];
                let n = frame.data().len().min(8);
                data.get_mut(..n)?.copy_from_slice(frame.data().get(..n)?);
                let sum = codec.read_raw(*index, &data)?;
                codec.write_raw(*index, sum ^ 1, &mut data);
                Frame::classic(frame.id()?, data.get(..n)?).ok()?
            }
            _ => frame,
        };
        signed(&mut self.table, Some(frame))
    }
}

impl Node for TestAds {
    fn on_frame(&mut self, _: Timestamp, _: Port, _: &Frame) {}

    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        if now < self.next {
            return;
        }
        let slow = self.cycle.as_secs_f64() * (1.0 + self.slow_percent / 100.0);
        let jitter = if self.jitter_ms > 0 {
            (self.rng.uniform() * 2.0 - 1.0) * self.jitter_ms as f64 / 1e3
        } else {
            0.0
        };
        let period = Duration::from_secs_f64((slow + jitter).max(1e-3));
        self.next = now.saturating_add(period);
        if self.silent {
            return;
        }
        for port in 0..self.buses {
            if let Some(frame) = self.frame() {
                out(Port(port), frame);
            }
        }
        if !self.frozen {
            self.counter = self.counter.wrapping_add(1);
        }
        self.command.engage = false;
    }

    fn next_deadline(&self) -> Option<Timestamp> {
        Some(self.next)
    }
}

/// The vehicle's safety controller: its E-stop message every cycle.
struct SafetyController {
    wire: ProfileWire,
    table: Option<SecuredTable>,
    pressed: bool,
    counter: u64,
    cycle: Duration,
    next: Timestamp,
}

impl Node for SafetyController {
    fn on_frame(&mut self, _: Timestamp, _: Port, _: &Frame) {}

    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        if now < self.next {
            return;
        }
        self.next = now.saturating_add(self.cycle);
        let frame = signed(
            &mut self.table,
            self.wire.estop_frame(self.pressed, self.counter),
        );
        if let Some(frame) = frame {
            out(Port::MAIN, frame);
        }
        self.counter = self.counter.wrapping_add(1);
    }

    fn next_deadline(&self) -> Option<Timestamp> {
        Some(self.next)
    }
}

/// What the intruder does.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Intrusion {
    Quiet,
    /// Floods with this identifier.
    Babble(Id),
    /// Re-sends command frames recorded this long before.
    Replay(Duration),
    /// Sends commands of its own.
    Forge,
}

/// A node on the first bus that records the commands it hears and misbehaves on request.
struct Intruder {
    wire: ProfileWire,
    /// Signs with a key that is not the vehicle's.
    table: Option<SecuredTable>,
    command_id: Option<Id>,
    /// Commands heard, oldest first (bounded).
    heard: std::collections::VecDeque<(Timestamp, Frame)>,
    intrusion: Intrusion,
    cycle: Duration,
    next: Timestamp,
    counter: u64,
}

/// Commands the intruder keeps: a few seconds' worth.
const HEARD: usize = 512;
/// A babbling node's gap between frames: faster than the bus can carry them.
const BABBLE_GAP: Duration = Duration::from_micros(100);

impl Node for Intruder {
    fn on_frame(&mut self, now: Timestamp, _: Port, frame: &Frame) {
        if frame.id().is_some() && frame.id() == self.command_id {
            if self.heard.len() >= HEARD {
                self.heard.pop_front();
            }
            self.heard.push_back((now, *frame));
        }
    }

    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        if self.intrusion == Intrusion::Quiet || now < self.next {
            return;
        }
        match self.intrusion {
            Intrusion::Quiet => {}
            Intrusion::Babble(id) => {
                self.next = now.saturating_add(BABBLE_GAP);
                if let Ok(frame) = Frame::classic(id, &[0xFF; 8]) {
                    out(Port::MAIN, frame);
                }
            }
            Intrusion::Replay(age) => {
                self.next = now.saturating_add(self.cycle);
                let then = Timestamp::from_nanos(
                    now.as_nanos()
                        .saturating_sub(u64::try_from(age.as_nanos()).unwrap_or(u64::MAX)),
                );
                let old = self.heard.iter().rev().find(|(t, _)| *t <= then);
                if let Some((_, frame)) = old {
                    out(Port::MAIN, *frame);
                }
            }
            Intrusion::Forge => {
                self.next = now.saturating_add(self.cycle);
                // Its own command: creeping, turned away.
                let command = AdsCommand {
                    velocity: 0.5,
                    steering: -10.0,
                    gear: Gear::Drive,
                    mode: ControlMode::Autonomous,
                    ..AdsCommand::default()
                };
                self.counter = self.counter.wrapping_add(1);
                let frame = signed(
                    &mut self.table,
                    self.wire.command_frame(&command, self.counter),
                );
                if let Some(frame) = frame {
                    out(Port::MAIN, frame);
                }
            }
        }
    }

    fn next_deadline(&self) -> Option<Timestamp> {
        (self.intrusion != Intrusion::Quiet).then_some(self.next)
    }
}

/// The network of one cell.
struct Rig {
    net: Network,
    ads: NodeHandle<TestAds>,
    /// The ADS's controller on the first bus.
    ads_endpoint: Option<NodeId>,
    vehicle: NodeHandle<VehicleNode>,
    safety: Option<NodeHandle<SafetyController>>,
    intruder: NodeHandle<Intruder>,
    command_id: Option<Id>,
    buses: u8,
}

/// What the detectors read, taken at the injection and compared at every millisecond.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Snapshot {
    stats: CommandStats,
    watchdog: Watchdog,
    degraded: bool,
    latched: bool,
    chain_lost: bool,
    autonomous: bool,
    driver: bool,
    tec: u16,
    level: DegradationLevel,
}

impl Snapshot {
    /// A supervisor's state, with the error counter of the ADS's controller.
    pub(super) fn of<W: bywire_vehicle::wire::VehicleWire>(s: &Supervisor<W>, tec: u16) -> Self {
        Snapshot {
            stats: s.stats(),
            watchdog: s.watchdog(),
            degraded: s.degraded().is_some(),
            latched: s.estop() != EstopState::Normal,
            chain_lost: s.estop_chain_lost(),
            autonomous: s.mode() == ControlMode::Autonomous,
            driver: s.driver_input(),
            tec,
            level: s.degradation().level(),
        }
    }
}

impl Rig {
    fn build(vehicle: &Vehicle, seed: u64) -> Result<Rig, CampaignError> {
        let mut net = Network::new();
        let bitrate = vehicle.profile.profile.bitrate;
        let data = vehicle.secured().then_some(2_000_000);
        let a = net.add_bus("a", bitrate, data);
        let b = (vehicle.buses == 2).then(|| net.add_bus("b", bitrate, data));
        let wire = vehicle.vehicle_wire()?;
        let node = SimulatedVehicle::from_profile_without(
            &vehicle.profile,
            wire,
            vehicle.buses == 2,
            vehicle.disabled,
        );
        let config = vehicle.profile.supervisor_config();
        let mut ads_wire = vehicle.plain_wire()?;
        let command_id = ads_wire
            .command_frame(&AdsCommand::default(), 0)
            .and_then(|f| f.id());
        let checksum = vehicle.plain.bindings.command.and_then(|c| {
            let message = vehicle.plain.database.messages.get(c.message)?;
            Some((MessageCodec::new(message), c.checksum))
        });
        let ads = net.add_node(TestAds {
            wire: ads_wire,
            table: vehicle.table(None)?,
            checksum,
            command: AdsCommand {
                gear: Gear::Drive,
                mode: ControlMode::Autonomous,
                ..AdsCommand::default()
            },
            counter: 0,
            cycle: config.cycle,
            next: Timestamp::ZERO,
            buses: vehicle.buses,
            silent: false,
            frozen: false,
            skip_once: false,
            corrupt_checksum: false,
            slow_percent: 0.0,
            jitter_ms: 0,
            rng: Rng::new(seed),
        });
        let vehicle_node = net.add_node(node);
        let safety_wire = vehicle.plain_wire()?;
        let safety = if safety_wire.has_estop() {
            Some(net.add_node(SafetyController {
                wire: safety_wire,
                table: vehicle.table(None)?,
                pressed: false,
                counter: 0,
                cycle: config.cycle,
                next: Timestamp::ZERO,
            }))
        } else {
            None
        };
        let intruder = net.add_node(Intruder {
            wire: vehicle.plain_wire()?,
            table: vehicle.table(Some(INTRUDER_KEY))?,
            command_id,
            heard: std::collections::VecDeque::new(),
            intrusion: Intrusion::Quiet,
            cycle: config.cycle,
            next: Timestamp::ZERO,
            counter: 0,
        });
        let ads_endpoint = net.wire(ads.key(), Port(0), a);
        net.wire(vehicle_node.key(), Supervisor::<Wire>::PORT_A, a);
        if let Some(b) = b {
            net.wire(ads.key(), Port(1), b);
            net.wire(vehicle_node.key(), Supervisor::<Wire>::PORT_B, b);
        }
        if let Some(safety) = safety {
            net.wire(safety.key(), Port::MAIN, a);
        }
        net.wire(intruder.key(), Port::MAIN, a);
        Ok(Rig {
            net,
            ads,
            ads_endpoint,
            vehicle: vehicle_node,
            safety,
            intruder,
            command_id,
            buses: vehicle.buses,
        })
    }

    fn vehicle(&self) -> Option<&VehicleNode> {
        self.net.node(self.vehicle)
    }

    fn ads(&mut self, change: impl FnOnce(&mut TestAds)) {
        if let Some(mut ads) = self.net.node_mut(self.ads) {
            change(&mut ads);
        }
    }

    fn driver(&mut self, torque: f64) {
        if let Some(mut v) = self.net.node_mut(self.vehicle) {
            v.supervisor_mut().set_driver_input(torque, 0.0);
        }
    }

    fn estop(&mut self, pressed: bool) {
        if let Some(mut s) = self.safety.and_then(|h| self.net.node_mut(h)) {
            s.pressed = pressed;
        }
    }

    fn intrude(&mut self, intrusion: Intrusion) {
        if let Some(mut i) = self.net.node_mut(self.intruder) {
            i.intrusion = intrusion;
            i.next = Timestamp::ZERO;
        }
    }

    /// Tamper with the command on every command bus (`None`: mend it).
    fn tamper(&mut self, tamper: Option<Tamper>) {
        let Some(id) = self.command_id else { return };
        for bus in 0..usize::from(self.buses) {
            if let Some(sim) = self.net.bus_mut(bus) {
                sim.tamper(id, tamper);
            }
        }
    }

    fn snapshot(&self) -> Option<Snapshot> {
        let tec = self
            .ads_endpoint
            .and_then(|e| self.net.bus(0)?.confinement(e))
            .map_or(0, |c| c.tec());
        Some(Snapshot::of(self.vehicle()?.supervisor(), tec))
    }
}

/// The reaction the vehicle's outputs and state show.
pub(super) fn reaction_of(s: &Snapshot, a: &Actuators) -> Reaction {
    if s.latched && !a.motors_enabled {
        return Reaction::Estop;
    }
    if !s.autonomous {
        return Reaction::Manual;
    }
    if !a.motors_enabled && a.brake >= 100.0 {
        return Reaction::SafeStop;
    }
    match (s.watchdog, s.level) {
        (Watchdog::Decelerating { .. }, _) => Reaction::Decelerate,
        (Watchdog::Holding { .. }, _) => Reaction::Hold,
        (_, DegradationLevel::MinimalRisk) => Reaction::MinimalRisk,
        (_, DegradationLevel::Nominal) if !s.degraded => Reaction::None,
        _ => Reaction::Degraded,
    }
}

/// The mechanisms that have noticed something since `before`.
pub(super) fn detectors(before: &Snapshot, now: &Snapshot) -> Mechanisms {
    let (b, n) = (before.stats, now.stats);
    let mut found = Mechanisms::NONE;
    let e2e = n.checksum + n.repeated + n.skipped + n.malformed;
    if e2e > b.checksum + b.repeated + b.skipped + b.malformed {
        found = found.with(Mechanism::E2e);
    }
    if n.out_of_range > b.out_of_range {
        found = found.with(Mechanism::Range);
    }
    if n.disagreements > b.disagreements || (now.degraded && !before.degraded) {
        found = found.with(Mechanism::Redundancy);
    }
    if n.authentication + n.unauthenticated > b.authentication + b.unauthenticated {
        found = found.with(Mechanism::Secoc);
    }
    let missed = !matches!(now.watchdog, Watchdog::Normal)
        && matches!(before.watchdog, Watchdog::Normal)
        && n.disagreements == b.disagreements;
    if missed || (now.chain_lost && !before.chain_lost) {
        found = found.with(Mechanism::Timeout);
    }
    // The latch taking an E-stop request (a lost chain is the timeout's).
    if now.latched && !before.latched && !now.chain_lost {
        found = found.with(Mechanism::SafeState);
    }
    if !now.autonomous && before.autonomous && now.driver {
        found = found.with(Mechanism::Takeover);
    }
    if now.tec > before.tec {
        found = found.with(Mechanism::Can);
    }
    found
}

/// Why `fault` cannot be injected into this vehicle in `state` (`None`: it can).
fn not_applicable(vehicle: &Vehicle, class: FaultClass, state: State) -> Option<String> {
    let has_estop = vehicle.plain.bindings.estop.is_some();
    match class {
        FaultClass::AngleSensor
        | FaultClass::EcuSilent
        | FaultClass::EcuWrongOutput
        | FaultClass::EcuBabble
        | FaultClass::SteeringActuator => Some(
            "a fault of the whole tug's layers (sensors, ECUs, steering actuators): its cells run on model = \"tug\""
                .into(),
        ),
        FaultClass::RedundantBusLost if vehicle.buses < 2 => {
            Some("the command runs on one bus: no redundant bus to lose".into())
        }
        FaultClass::Forged if !vehicle.secured() => Some(
            "unsecured: a forged frame with a valid checksum and counter is the ADS's to the vehicle (SecOC profiles only)"
                .into(),
        ),
        FaultClass::Estop if !has_estop => Some("the profile has no E-stop message".into()),
        FaultClass::NonFinite if !float_setpoints(vehicle) => Some(
            "its setpoint signals are integers: no frame can carry a value that is not a number"
                .into(),
        ),
        FaultClass::NonFinite => Some(
            "a float setpoint: injecting a value that is not a number is not supported yet".into(),
        ),
        _ => match state {
            State::EstopLatched if !has_estop => {
                Some("the profile has no E-stop message to latch".into())
            }
            State::Degraded if vehicle.buses < 2 && degraded_class(vehicle).is_none() => Some(
                "one command bus and no degradation rules: the vehicle has no degraded level"
                    .into(),
            ),
            _ => None,
        },
    }
}

/// Whether the command's steering or speed setpoint is an IEEE float signal.
fn float_setpoints(vehicle: &Vehicle) -> bool {
    let Some(b) = vehicle.plain.bindings.command else {
        return false;
    };
    let message = vehicle.plain.database.messages.get(b.message);
    [b.steering, b.velocity].iter().any(|i| {
        message
            .and_then(|m| m.signals.get(*i))
            .is_some_and(|s| !matches!(s.value_type, bywire_dbc::ValueType::Integer { .. }))
    })
}

/// A fault class the vehicle's degradation rules make the degraded level.
fn degraded_class(vehicle: &Vehicle) -> Option<bywire_vehicle::command::FaultClass> {
    let policy = vehicle.profile.supervisor_config().degradation?;
    bywire_vehicle::command::FaultClass::ALL
        .iter()
        .copied()
        .find(|c| policy.rule(*c) == DegradationLevel::Degraded)
}

/// The setpoint an out-of-range fault sends: the furthest beyond the vehicle's limit its
/// signal carries (`None`: the signal cannot carry a value beyond it).
fn beyond_limit(vehicle: &Vehicle, signal: &str) -> Option<(f64, bool)> {
    let b = vehicle.plain.bindings.command?;
    let message = vehicle.plain.database.messages.get(b.message)?;
    let config = vehicle.profile.supervisor_config();
    let (index, limit, steering) = match signal {
        "velocity" => (b.velocity, config.speed_limit, false),
        _ => (b.steering, config.steering_range, true),
    };
    let s = message.signals.get(index)?;
    let max = s.maximum.as_f64();
    (max > limit).then_some((max, steering))
}

/// Run one cell.
pub fn run_cell(campaign: &Campaign, vehicle: &Vehicle, cell: &Cell) -> CellResult {
    let wall = std::time::Instant::now();
    let entry = campaign.faults.get(cell.fault);
    let fault_name = entry.map_or("?", |f| f.name()).to_string();
    let class = entry.map_or(FaultClass::NodeSilent, |f| f.class);
    let mut result = CellResult {
        name: cell_name(
            &vehicle.label,
            cell.state,
            &fault_name,
            cell.expect.mechanism,
        ),
        profile: vehicle.label.clone(),
        state: cell.state,
        fault: fault_name,
        class,
        expected: cell.expect,
        detected_by: Vec::new(),
        reaction: Reaction::None,
        reaction_ms: None,
        verdict: Verdict::NotApplicable,
        why: String::new(),
        requirements: entry.map(|f| f.requirements.clone()).unwrap_or_default(),
        wall_seconds: 0.0,
    };
    let outcome = match (entry, &cell.skip) {
        (_, Some(reason)) => Err(reason.clone()),
        (None, _) => Err("no such fault".to_string()),
        (Some(entry), None) => match vehicle.model {
            Model::Plant => drive(campaign, vehicle, cell, entry, &mut result),
            Model::Tug => super::tug_cell::drive(campaign, vehicle, cell, entry, &mut result),
        },
    };
    match outcome {
        Ok(failures) if failures.is_empty() => result.verdict = Verdict::Pass,
        Ok(failures) => {
            result.verdict = Verdict::Fail;
            result.why = failures.join("; ");
        }
        Err(reason) => {
            result.verdict = Verdict::NotApplicable;
            result.why = reason;
        }
    }
    result.wall_seconds = wall.elapsed().as_secs_f64();
    result
}

/// The cell's run: `Err` when it does not apply, else its failures (none: a pass).
fn drive(
    campaign: &Campaign,
    vehicle: &Vehicle,
    cell: &Cell,
    entry: &super::FaultEntry,
    result: &mut CellResult,
) -> Result<Vec<String>, String> {
    let seed = campaign.seed ^ (cell.fault as u64) << 16 ^ (cell.state as u64) << 8;
    if let Some(reason) = not_applicable(vehicle, entry.class, cell.state) {
        return Err(reason);
    }
    let mut rig = Rig::build(vehicle, seed).map_err(|e| e.to_string())?;
    let config = vehicle.profile.supervisor_config();
    let cycle = config.cycle;
    let out_of_range = match entry.class {
        FaultClass::OutOfRange => {
            let signal = entry.signal.as_deref().unwrap_or("steering");
            Some(beyond_limit(vehicle, signal).ok_or_else(|| {
                format!("its {signal} signal cannot carry a value beyond the vehicle's limit")
            })?)
        }
        _ => None,
    };
    let ms = Duration::from_millis(1);
    let at = |ms: u64| Timestamp::from_millis(ms);
    // The watchdog takes a run of valid commands before an engage counts.
    let engage_ms = (u64::try_from(cycle.as_millis()).unwrap_or(20)
        * (u64::from(config.cascade.recovery_run) + 3))
        .max(600);
    let steering = if cell.state == State::Turning {
        (config.steering_range / 2.0).min(15.0)
    } else {
        0.0
    };
    let inject = campaign.inject_at_ms.max(engage_ms + 800);
    let observe = entry.observe_ms.unwrap_or(campaign.observe_ms);
    let end = inject + observe;
    let until = entry.duration(cycle).map_or(u64::MAX, |d| {
        inject.saturating_add(u64::try_from(d.as_millis()).unwrap_or(u64::MAX))
    });
    let mut before = None;
    let mut observer = Observer::new(vehicle.limits());
    for t in 1..=end {
        // The operating state, scripted.
        if t == engage_ms {
            rig.ads(|a| {
                a.command.engage = true;
                a.command.velocity = 2.0;
                a.command.steering = steering;
            });
        }
        match cell.state {
            State::Manual if t == engage_ms + 300 => rig.driver(config.takeover_torque * 2.0),
            State::Manual if t == engage_ms + 400 => {
                rig.driver(0.0);
                rig.ads(|a| {
                    a.command.mode = ControlMode::Manual;
                    a.command.velocity = 0.0;
                });
            }
            State::EstopLatched if t == engage_ms + 300 => rig.estop(true),
            State::EstopLatched if t == engage_ms + 600 => {
                rig.estop(false);
                rig.ads(|a| a.command.velocity = 0.0);
            }
            State::Degraded if t == engage_ms + 300 => {
                if rig.buses == 2 {
                    rig.net.drop_port_output(rig.ads.key(), Port(1), true);
                } else if let Some(class) = degraded_class(vehicle) {
                    if let Some(mut v) = rig.net.node_mut(rig.vehicle) {
                        v.supervisor_mut().report_fault(DegradationFault {
                            class,
                            source: 0,
                            at: at(t),
                        });
                    }
                }
            }
            _ => {}
        }
        if t == inject {
            before = rig.snapshot();
            let actuators = rig.vehicle().map(|v| v.supervisor().actuators(at(t)));
            if let (Some(s), Some(a)) = (&before, actuators) {
                observer.baseline = reaction_of(s, &a);
            }
            inject_fault(
                &mut rig,
                entry,
                out_of_range,
                seed,
                config.takeover_torque * 2.0,
            );
        }
        if t == until {
            clear_fault(&mut rig, entry);
        }
        rig.net.run_for(ms);
        let Some(v) = rig.vehicle() else {
            return Err("the vehicle left the network".into());
        };
        let now = rig.net.now();
        let a = v.supervisor().actuators(now);
        if t >= engage_ms {
            observer.limits(&a, || format!("at {t} ms"));
        }
        let Some(before) = before else { continue };
        let Some(snap) = rig.snapshot() else { continue };
        let since = (t - inject) as f64;
        observer.observe(
            since,
            detectors(&before, &snap),
            reaction_of(&snap, &a),
            result,
        );
    }
    Ok(observer.judge(cell, cycle, result))
}

/// What a cell's run has seen since the injection: the mechanisms that noticed the fault (the
/// first time each), the most severe reaction beyond the state's own, and the actuators' limits
/// kept.
pub(super) struct Observer {
    /// The reaction the operating state already had at the injection.
    pub(super) baseline: Reaction,
    found: Mechanisms,
    reaction: (Reaction, Option<f64>),
    failures: Vec<String>,
    /// The vehicle's steering (degrees) and speed (m/s) limits.
    limits: (f64, f64),
}

impl Observer {
    pub(super) fn new(limits: (f64, f64)) -> Self {
        Observer {
            baseline: Reaction::None,
            found: Mechanisms::NONE,
            reaction: (Reaction::None, None),
            failures: Vec::new(),
            limits,
        }
    }

    /// The actuators must stay within the vehicle's limits (the first breach, `when` it came,
    /// is the failure).
    pub(super) fn limits(&mut self, a: &Actuators, when: impl FnOnce() -> String) {
        let (steering, speed) = (self.limits.0 + 1e-6, self.limits.1 + 1e-6);
        let within = a.steering.is_finite()
            && a.velocity.is_finite()
            && a.steering.abs() <= steering
            && a.velocity.abs() <= speed
            && (0.0..=100.0).contains(&a.brake);
        if !within && self.failures.is_empty() {
            let when = when();
            self.failures.push(format!(
                "{when} the actuators were sent steering {:.2} deg, velocity {:.2} m/s, brake {:.0} %: beyond the vehicle's limits",
                a.steering, a.velocity, a.brake
            ));
        }
    }

    /// One millisecond, `since` the injection: the mechanisms that noticed something, the
    /// reaction shown.
    pub(super) fn observe(
        &mut self,
        since: f64,
        noticed: Mechanisms,
        shown: Reaction,
        result: &mut CellResult,
    ) {
        for m in noticed.iter() {
            if !self.found.contains(m) {
                self.found = self.found.with(m);
                result.detected_by.push(Detection {
                    mechanism: Some(m),
                    ms: since,
                });
            }
        }
        let worse = shown.severity() > self.baseline.severity()
            && shown.severity() > self.reaction.0.severity();
        if worse {
            self.reaction = (shown, Some(since));
        }
    }

    /// The cell's failures, with the reaction written into `result`.
    pub(super) fn judge(
        mut self,
        cell: &Cell,
        cycle: Duration,
        result: &mut CellResult,
    ) -> Vec<String> {
        result.reaction = self.reaction.0;
        result.reaction_ms = self.reaction.1;
        judge(cell, cycle, result, &mut self.failures);
        self.failures
    }
}

fn inject_fault(
    rig: &mut Rig,
    entry: &super::FaultEntry,
    out_of_range: Option<(f64, bool)>,
    seed: u64,
    takeover_torque: f64,
) {
    let count = entry.count.unwrap_or(1);
    let corrupt = |rig: &mut Rig, kind| {
        let (Some(node), Some(id)) = (rig.ads_endpoint, rig.command_id) else {
            return;
        };
        if let Some(bus) = rig.net.bus_mut(0) {
            bus.corrupt(WireFault {
                node: Some(node),
                id: Some(id),
                count,
                kind,
            });
        }
    };
    match entry.class {
        FaultClass::BitError => corrupt(rig, Corruption::Bit),
        FaultClass::StuffError => corrupt(rig, Corruption::Stuff),
        FaultClass::CrcError => corrupt(rig, Corruption::Crc),
        FaultClass::FrameDropped => rig.tamper(Some(Tamper::Drop)),
        FaultClass::Delayed => rig.tamper(Some(Tamper::Delay(Duration::from_millis(
            entry.delay_ms.unwrap_or(50),
        )))),
        FaultClass::Duplicated => rig.tamper(Some(Tamper::Duplicate)),
        FaultClass::Replayed => rig.intrude(Intrusion::Replay(Duration::from_secs(1))),
        FaultClass::CounterSkipped => rig.ads(|a| a.skip_once = true),
        FaultClass::CounterFrozen => rig.ads(|a| a.frozen = true),
        FaultClass::ChecksumCorrupted => rig.ads(|a| a.corrupt_checksum = true),
        FaultClass::BabblingIdiot => {
            let id = Id::standard(u32::from(entry.id.unwrap_or(0))).ok();
            if let Some(id) = id {
                rig.intrude(Intrusion::Babble(id));
            }
        }
        FaultClass::BusOff => {
            let node = rig.ads_endpoint;
            if let Some(bus) = rig.net.bus_mut(0) {
                bus.take_off_bus(node, None);
            }
        }
        FaultClass::RedundantBusLost => rig.net.drop_port_output(rig.ads.key(), Port(1), true),
        FaultClass::NodeSilent => rig.ads(|a| a.silent = true),
        FaultClass::ClockDrift => {
            let percent = entry.percent.unwrap_or(60.0);
            rig.ads(|a| a.slow_percent = percent);
        }
        FaultClass::Jitter => {
            let jitter = entry.jitter_ms.unwrap_or(5);
            rig.ads(|a| {
                a.jitter_ms = jitter;
                a.rng = Rng::new(seed);
            });
        }
        FaultClass::OutOfRange => {
            if let Some((value, steering)) = out_of_range {
                rig.ads(|a| match steering {
                    true => a.command.steering = value,
                    false => a.command.velocity = value,
                });
            }
        }
        FaultClass::NonFinite
        | FaultClass::AngleSensor
        | FaultClass::EcuSilent
        | FaultClass::EcuWrongOutput
        | FaultClass::EcuBabble
        | FaultClass::SteeringActuator => {}
        FaultClass::Forged => rig.intrude(Intrusion::Forge),
        FaultClass::Estop => rig.estop(true),
        FaultClass::DriverTakeover => rig.driver(takeover_torque),
    }
}

fn clear_fault(rig: &mut Rig, entry: &super::FaultEntry) {
    match entry.class {
        FaultClass::FrameDropped | FaultClass::Delayed | FaultClass::Duplicated => rig.tamper(None),
        FaultClass::Replayed | FaultClass::BabblingIdiot | FaultClass::Forged => {
            rig.intrude(Intrusion::Quiet)
        }
        FaultClass::CounterFrozen => rig.ads(|a| a.frozen = false),
        FaultClass::ChecksumCorrupted => rig.ads(|a| a.corrupt_checksum = false),
        FaultClass::RedundantBusLost => rig.net.drop_port_output(rig.ads.key(), Port(1), false),
        FaultClass::NodeSilent => rig.ads(|a| a.silent = false),
        FaultClass::ClockDrift => rig.ads(|a| a.slow_percent = 0.0),
        FaultClass::Jitter => rig.ads(|a| a.jitter_ms = 0),
        FaultClass::Estop => rig.estop(false),
        FaultClass::DriverTakeover => rig.driver(0.0),
        _ => {}
    }
}

/// The cell's verdict from what was seen.
fn judge(cell: &Cell, cycle: Duration, result: &CellResult, failures: &mut Vec<String>) {
    let e = cell.expect;
    let (detect, react) = (e.detect_bound(cycle), e.react_bound(cycle));
    if let Some(m) = e.mechanism {
        match result.detected_by.iter().find(|d| d.mechanism == Some(m)) {
            None => failures.push(format!(
                "{m} did not detect it{}",
                describe_detections(&result.detected_by)
            )),
            Some(d) if d.ms > detect => failures.push(format!(
                "{m} detected it after {} ms (bound {detect} ms)",
                d.ms
            )),
            Some(_) => {}
        }
    }
    if result.reaction != e.reaction {
        failures.push(format!(
            "the vehicle's reaction was {}{}, expected {}",
            result.reaction.name(),
            result
                .reaction_ms
                .map_or(String::new(), |ms| format!(" after {ms} ms")),
            e.reaction.name()
        ));
    } else if let Some(ms) = result.reaction_ms {
        if ms > react && e.reaction != Reaction::None {
            failures.push(format!(
                "{} reached after {ms} ms (bound {react} ms)",
                e.reaction.name()
            ));
        }
    }
}

fn describe_detections(d: &[Detection]) -> String {
    if d.is_empty() {
        return " (no mechanism noticed anything)".into();
    }
    let list: Vec<String> = d
        .iter()
        .map(|d| {
            format!(
                "{} at {} ms",
                d.mechanism.map_or("none", Mechanism::name),
                d.ms
            )
        })
        .collect();
    format!(" (noticed: {})", list.join(", "))
}
