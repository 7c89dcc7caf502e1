//! The fault matrix's rows that every vehicle must pass, as one suite run over several wires —
//! the reference tug through its generated structs, the reference tug through its profile,
//! and another vehicle's layout (the shuttle: big-endian setpoints, 8-bit counters, XOR
//! checksums, its own enum numbers and limits) — on the simulated runner: the ADS side, the
//! supervisor and (where the vehicle has one) a safety controller sending the E-stop message
//! on one bit-timed bus. `fault_matrix.rs` holds the rows that need the reference tug's bytes.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use std::time::Duration;

use common::vehicles::{self, by_profile, reference_wire, Vehicle};

use bywire_core::node::{Node, Port};
use bywire_core::{Frame, Id, Timestamp};
use bywire_net::network::{Network, NodeHandle, NodeMut};
use bywire_net::sim::Tamper;
use bywire_tug::messages::{self, AdsToVehicleControl, EmergencyStop};
use bywire_tug::wire::ReferenceWire;
use bywire_vehicle::ads::{Ads, AdsCommand};
use bywire_vehicle::command::{ControlMode, DegradationLevel, FaultClass, Gear};
use bywire_vehicle::degradation::Fault;
use bywire_vehicle::supervisor::{EstopState, Supervisor, Watchdog};
use bywire_vehicle::wire::{AdsWire, ProfileWire, VehicleWire};

/// What the suite needs of a wire beyond the nodes' traits: the vehicle's E-stop message (as
/// its safety controller sends it) and the command's identifier.
trait SuiteWire: AdsWire + VehicleWire + Clone + 'static {
    fn estop_frame(&mut self, pressed: bool, counter: u64) -> Option<Frame>;
    fn command_id(&mut self) -> Id {
        self.command_frame(&AdsCommand::default(), 0)
            .and_then(|f| f.id())
            .unwrap()
    }
}

impl SuiteWire for ReferenceWire {
    fn estop_frame(&mut self, pressed: bool, counter: u64) -> Option<Frame> {
        let mut m = EmergencyStop::default();
        m.set_estop_request_raw(u64::from(pressed));
        m.set_counter_raw(counter & 0x0F);
        Some(messages::sealed_frame(EmergencyStop::ID, m.0))
    }
    fn command_id(&mut self) -> Id {
        Id::standard(AdsToVehicleControl::ID).unwrap()
    }
}

impl SuiteWire for ProfileWire {
    fn estop_frame(&mut self, pressed: bool, counter: u64) -> Option<Frame> {
        ProfileWire::estop_frame(self, pressed, counter)
    }
}

/// The vehicle's safety controller: its E-stop message every 20 ms once told to send.
struct Safety<W> {
    wire: W,
    pressed: Option<bool>,
    next: Timestamp,
    counter: u64,
}

impl<W: SuiteWire> Node for Safety<W> {
    fn on_frame(&mut self, _: Timestamp, _: Port, _: &Frame) {}
    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        let Some(pressed) = self.pressed else { return };
        if now >= self.next {
            self.next = now.saturating_add(Duration::from_millis(20));
            if let Some(frame) = self.wire.estop_frame(pressed, self.counter) {
                out(Port::MAIN, frame);
            }
            self.counter = self.counter.wrapping_add(1);
        }
    }
    fn next_deadline(&self) -> Option<Timestamp> {
        self.pressed.map(|_| self.next)
    }
}

fn shuttle() -> Vehicle<ProfileWire> {
    by_profile(&vehicles::shuttle_with(|dbc| dbc))
}

/// The ADS side, the supervisor and the safety controller on one 500 kbit/s bus.
struct Rig<W: SuiteWire> {
    net: Network,
    ads: NodeHandle<Ads<W>>,
    supervisor: NodeHandle<Supervisor<W>>,
    safety: NodeHandle<Safety<W>>,
    cycle: Duration,
    command: AdsCommand,
    /// Watchdog level changes: (ms, level).
    watchdog_log: Vec<(u64, Watchdog)>,
    command_id: Id,
}

impl<W: SuiteWire> Rig<W> {
    fn new(mut vehicle: Vehicle<W>) -> Rig<W> {
        let mut net = Network::new();
        let bus = net.add_bus("bus", 500_000, None);
        let command_id = vehicle.wire.command_id();
        let ads = net.add_node(Ads::with_wire(vehicle.ads, vehicle.wire.clone()));
        let supervisor = net.add_node(Supervisor::with_wire(
            vehicle.supervisor,
            vehicle.wire.clone(),
        ));
        let safety = net.add_node(Safety {
            wire: vehicle.wire,
            pressed: None,
            next: Timestamp::ZERO,
            counter: 0,
        });
        for node in [ads.key(), supervisor.key(), safety.key()] {
            net.wire(node, Port::MAIN, bus).unwrap();
        }
        Rig {
            net,
            ads,
            supervisor,
            safety,
            cycle: vehicle.supervisor.cycle,
            command: AdsCommand {
                velocity: 2.0,
                gear: Gear::Drive,
                mode: ControlMode::Autonomous,
                ..AdsCommand::default()
            },
            watchdog_log: Vec::new(),
            command_id,
        }
    }

    fn supervisor(&self) -> &Supervisor<W> {
        self.net.node(self.supervisor).unwrap()
    }

    fn supervisor_mut(&mut self) -> NodeMut<'_, Supervisor<W>> {
        self.net.node_mut(self.supervisor).unwrap()
    }

    fn ads_mut(&mut self) -> NodeMut<'_, Ads<W>> {
        self.net.node_mut(self.ads).unwrap()
    }

    fn safety_mut(&mut self) -> NodeMut<'_, Safety<W>> {
        self.net.node_mut(self.safety).unwrap()
    }

    fn ms(&self) -> u64 {
        self.net.now().as_nanos() / 1_000_000
    }

    /// Run `ms` milliseconds, a millisecond at a time, the vehicle's speed following its
    /// actuators.
    fn run(&mut self, ms: u64) {
        for _ in 0..ms {
            let before = self.supervisor().watchdog();
            self.net.run_for(Duration::from_millis(1));
            let after = self.supervisor().watchdog();
            if after != before {
                let at = self.ms();
                self.watchdog_log.push((at, after));
            }
            let a = self.supervisor().actuators(self.net.now());
            let speed = common::plant_speed(&a);
            self.supervisor_mut().set_feedback(speed, a.steering);
        }
    }

    /// `n` command cycles with `command` (`engage` for the first only).
    fn commands(&mut self, n: u32, engage: bool) {
        for k in 0..n {
            let command = AdsCommand {
                engage: engage && k == 0,
                ..self.command
            };
            let now = self.net.now();
            self.ads_mut().set_command(now, command);
            let cycle = u64::try_from(self.cycle.as_millis()).unwrap();
            self.run(cycle);
        }
    }

    fn engaged(vehicle: Vehicle<W>) -> Rig<W> {
        let mut rig = Rig::new(vehicle);
        rig.commands(12, false);
        rig.commands(1, true);
        rig.commands(2, false);
        assert_eq!(rig.supervisor().watchdog(), Watchdog::Normal);
        assert_eq!(rig.supervisor().mode(), ControlMode::Autonomous);
        rig
    }

    fn cycle_ms(&self) -> u64 {
        u64::try_from(self.cycle.as_millis()).unwrap()
    }
}

fn starts_failed_closed_and_engages_only_after_a_run_and_a_request<W: SuiteWire>(v: Vehicle<W>) {
    let mut rig = Rig::new(v);
    rig.run(100);
    assert_eq!(rig.supervisor().watchdog(), Watchdog::FullBraking);
    assert!(!rig.supervisor().actuators(rig.net.now()).ads_in_control);
    // An engage request too early (the third valid command) is refused.
    rig.commands(2, false);
    rig.commands(1, true);
    assert!(matches!(
        rig.supervisor().watchdog(),
        Watchdog::Recovering { .. }
    ));
    assert_eq!(rig.supervisor().mode(), ControlMode::Manual);
    // After the run, a fresh request engages.
    rig.commands(10, false);
    rig.commands(1, true);
    rig.commands(1, false);
    assert_eq!(rig.supervisor().watchdog(), Watchdog::Normal);
    assert_eq!(rig.supervisor().mode(), ControlMode::Autonomous);
    let a = rig.supervisor().actuators(rig.net.now());
    assert!(
        a.ads_in_control && a.steering_enabled && a.velocity == 2.0,
        "{a:?}"
    );
}

fn silence_runs_the_watchdog_cascade<W: SuiteWire>(v: Vehicle<W>) {
    let mut rig = Rig::engaged(v);
    rig.watchdog_log.clear();
    rig.net.drop_output(rig.ads, true);
    let cycle = rig.cycle_ms();
    rig.run(cycle * 7);
    let levels: Vec<Watchdog> = rig.watchdog_log.iter().map(|(_, w)| *w).collect();
    assert_eq!(
        levels,
        [
            Watchdog::Holding { missed: 1 },
            Watchdog::Holding { missed: 2 },
            Watchdog::Decelerating { missed: 3 },
            Watchdog::Decelerating { missed: 4 },
            Watchdog::FullBraking,
        ],
        "{:?}",
        rig.watchdog_log
    );
    // One level a cycle.
    for pair in rig.watchdog_log.windows(2) {
        assert!(pair[1].0 - pair[0].0 <= cycle + 1, "{:?}", rig.watchdog_log);
    }
    let a = rig.supervisor().actuators(rig.net.now());
    assert!(a.brake == 100.0 && !a.steering_enabled, "{a:?}");
    // Back: commands alone do not release full braking; a run and an engage do.
    rig.net.drop_output(rig.ads, false);
    rig.commands(5, false);
    assert!(matches!(
        rig.supervisor().watchdog(),
        Watchdog::Recovering { .. }
    ));
    rig.commands(8, false);
    rig.commands(1, true);
    rig.commands(1, false);
    assert_eq!(rig.supervisor().watchdog(), Watchdog::Normal);
}

fn corrupted_commands_are_rejected_and_counted<W: SuiteWire>(v: Vehicle<W>) {
    let mut rig = Rig::engaged(v);
    let id = rig.command_id;
    // A faulty sender: a data bit flipped, the CAN CRC computed over the flipped bits.
    rig.net
        .bus_mut(0)
        .unwrap()
        .tamper(id, Some(Tamper::FlipBit));
    rig.commands(3, false);
    assert_eq!(
        rig.supervisor().stats().checksum,
        3,
        "{:?}",
        rig.supervisor().stats()
    );
    assert!(matches!(
        rig.supervisor().watchdog(),
        Watchdog::Holding { .. } | Watchdog::Decelerating { .. }
    ));
    rig.net.bus_mut(0).unwrap().tamper(id, None);
}

fn out_of_range_commands_are_rejected<W: SuiteWire>(v: Vehicle<W>) {
    let mut rig = Rig::engaged(v);
    let limit = rig.supervisor().actuators(rig.net.now());
    assert!(limit.ads_in_control);
    // Beyond the vehicle's speed limit (within what its signal can carry).
    let accepted = rig.supervisor().stats().accepted;
    rig.command.velocity = 5.5;
    rig.commands(2, false);
    let stats = rig.supervisor().stats();
    let beyond_limit = stats.out_of_range >= 2;
    let within = stats.accepted == accepted + 2;
    // The reference tug's limit is 5 m/s, the shuttle's 6: one refuses, the other obeys.
    assert!(beyond_limit ^ within, "{stats:?}");
    if beyond_limit {
        assert!(rig.supervisor().actuators(rig.net.now()).velocity <= 2.0);
    }
}

fn emergency_brake_brakes_fully_at_once<W: SuiteWire>(v: Vehicle<W>) {
    let mut rig = Rig::engaged(v);
    let now = rig.net.now();
    rig.ads_mut().emergency_brake(now, 3.0);
    rig.run(3);
    assert_eq!(rig.supervisor().actuators(rig.net.now()).brake, 100.0);
}

fn estop_latches_until_the_operator_reset<W: SuiteWire>(mut v: Vehicle<W>) {
    if v.wire.estop_frame(false, 0).is_none() {
        // A vehicle without an E-stop message: nothing to press (the shuttle's profile).
        assert!(v.wire.estop_frame(true, 0).is_none());
        return;
    }
    let mut rig = Rig::engaged(v);
    rig.safety_mut().pressed = Some(true);
    rig.run(3);
    // Within the frame's time on the wire: motors off, brakes on; at standstill (by the next
    // poll, within a cycle) stopped.
    assert!(rig.supervisor().estop().is_latched());
    let a = rig.supervisor().actuators(rig.net.now());
    assert!(!a.motors_enabled && a.brake == 100.0, "{a:?}");
    let cycle = rig.cycle_ms();
    rig.run(cycle);
    assert_eq!(rig.supervisor().estop(), EstopState::Stopped);
    assert_eq!(rig.supervisor().mode(), ControlMode::Estop);
    // Released: still latched, whatever the ADS sends.
    rig.safety_mut().pressed = Some(false);
    rig.commands(3, true);
    assert_eq!(rig.supervisor().estop(), EstopState::Stopped);
    // The operator's reset: a press, the check, a second press, then an engage.
    rig.command.operator_reset = true;
    rig.commands(1, false);
    rig.command.operator_reset = false;
    rig.commands(1, false);
    rig.command.operator_reset = true;
    rig.commands(1, false);
    rig.command.operator_reset = false;
    rig.commands(1, false);
    assert_eq!(rig.supervisor().estop(), EstopState::ResetConfirmed);
    rig.commands(1, true);
    assert_eq!(rig.supervisor().estop(), EstopState::Normal);
}

/// A fault a fail-operational mechanism reports: the level the profile's rule gives (a
/// profile without the section is fail-safe: a safe stop), its speed limit applied and shown
/// to the ADS where the state message carries it; a second fault is a safe stop, and only a
/// standstill resets.
fn a_reported_fault_degrades_by_the_profiles_rule<W: SuiteWire>(v: Vehicle<W>) {
    let mut rig = Rig::engaged(v);
    rig.command.velocity = 4.0;
    rig.commands(3, false);
    let policy = *rig.supervisor().degradation().policy();
    let now = rig.net.now();
    let first = Fault {
        class: FaultClass::SensorChannelOut,
        source: 0,
        at: now,
    };
    let level = rig.supervisor_mut().report_fault(first);
    assert_eq!(level, policy.rule(FaultClass::SensorChannelOut));
    rig.commands(3, false);
    let a = rig.supervisor().actuators(rig.net.now());
    match policy.limits(level) {
        Some(limits) => {
            assert_eq!(a.velocity, 4.0_f64.min(limits.speed_limit), "{a:?}");
            assert!(a.warning && a.brake == 0.0, "{a:?}");
        }
        None => assert!(a.brake == 100.0 && !a.motors_enabled, "{a:?}"),
    }
    // The vehicle that declares its levels reports them (the shuttle); the fail-safe tug's
    // state message has no place for one.
    let ads = rig.net.node(rig.ads).unwrap().state();
    let declared = policy.limits(level).is_some();
    assert_eq!(ads.degradation.value, declared.then_some(level));
    assert!(ads.warning.value.is_none_or(|w| w));
    // A second fault on top stops the vehicle where it is.
    let second = Fault {
        class: FaultClass::ActuatorBackup,
        ..first
    };
    assert_eq!(
        rig.supervisor_mut().report_fault(second),
        DegradationLevel::SafeStop
    );
    rig.commands(1, false);
    let a = rig.supervisor().actuators(rig.net.now());
    assert!(a.brake == 100.0 && !a.motors_enabled, "{a:?}");
    rig.commands(40, false);
    assert!(rig.supervisor_mut().reset_degradation());
    assert_eq!(
        rig.supervisor().degradation().level(),
        DegradationLevel::Nominal
    );
}

/// Each row for each wire.
macro_rules! for_every_wire {
    ($($row:ident),* $(,)?) => {
        mod reference_wire {
            use super::*;
            $(#[test] fn $row() { super::$row(reference_wire()) })*
        }
        mod reference_tug_profile {
            use super::*;
            $(#[test] fn $row() { super::$row(by_profile(&bywire_tug::profile().unwrap())) })*
        }
        mod shuttle_profile {
            use super::*;
            $(#[test] fn $row() { super::$row(shuttle()) })*
        }
    };
}

for_every_wire!(
    starts_failed_closed_and_engages_only_after_a_run_and_a_request,
    silence_runs_the_watchdog_cascade,
    corrupted_commands_are_rejected_and_counted,
    out_of_range_commands_are_rejected,
    emergency_brake_brakes_fully_at_once,
    estop_latches_until_the_operator_reset,
    a_reported_fault_degrades_by_the_profiles_rule,
);
