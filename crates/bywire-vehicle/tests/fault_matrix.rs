//! The supervisor's fault matrix, on the simulated runner: the supervisor as a node on one
//! bit-timed 500 kbit/s bus, with the ADS and the safety controller as endpoints the tests send
//! the reference tug's frames from (byte by byte, so the rows can break them). Every frame
//! reaches the supervisor at its end-of-frame instant, so the timings asserted are those of the
//! wire. Each row of the matrix is one named test; the rows every vehicle must pass run over
//! several wires in `fault_suite.rs`.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use std::time::Duration;

use bywire_core::node::Port;
use bywire_core::{Frame, Id, Timestamp};
use bywire_net::network::{Network, NodeHandle, NodeMut};
use bywire_net::sim::{Fault, NodeId, SimBus};
use bywire_tug::messages::{self, AdsToVehicleControl, ControlMode, EmergencyBrake, EmergencyStop};
use bywire_tug::wire::ReferenceWire;
use bywire_vehicle::supervisor::{EstopState, Supervisor, SupervisorConfig, Watchdog};

const CYCLE_MS: u64 = 20;

fn ms(t: u64) -> Timestamp {
    Timestamp::from_millis(t)
}

/// A command as the ADS would send it.
#[derive(Clone, Copy)]
struct Cmd {
    steering: f64,
    velocity: f64,
    mode: u64,
    engage: bool,
    reset: bool,
    steering_mode: u64,
}

impl Default for Cmd {
    fn default() -> Self {
        Cmd {
            steering: 0.0,
            velocity: 2.0,
            mode: ControlMode::Autonomous as u64,
            engage: false,
            reset: false,
            steering_mode: 0,
        }
    }
}

fn command_frame(c: Cmd, counter: u8) -> Frame {
    let mut m = AdsToVehicleControl::default();
    m.set_steering_angle_cmd(c.steering).unwrap();
    m.set_velocity_cmd(c.velocity).unwrap();
    m.set_gear_cmd_raw(3);
    m.set_control_mode_cmd_raw(c.mode);
    m.set_steering_mode_cmd_raw(c.steering_mode);
    m.set_engage_request_raw(u64::from(c.engage));
    m.set_operator_reset_raw(u64::from(c.reset));
    m.set_heartbeat_counter_raw(u64::from(counter & 0x0F));
    let mut payload = m.0;
    messages::seal(AdsToVehicleControl::ID, &mut payload);
    Frame::classic(Id::standard(AdsToVehicleControl::ID).unwrap(), &payload).unwrap()
}

fn estop_frame(active: bool) -> Frame {
    let mut m = EmergencyStop::default();
    m.set_estop_request_raw(u64::from(active));
    m.set_estop_source_raw(1);
    let mut payload = m.0;
    messages::seal(EmergencyStop::ID, &mut payload);
    Frame::classic(Id::standard(EmergencyStop::ID).unwrap(), &payload).unwrap()
}

fn brake_frame() -> Frame {
    let mut m = EmergencyBrake::default();
    m.set_brake_request_raw(1);
    m.set_deceleration_raw(40);
    let mut payload = m.0;
    messages::seal(EmergencyBrake::ID, &mut payload);
    Frame::classic(Id::standard(EmergencyBrake::ID).unwrap(), &payload).unwrap()
}

/// The supervisor on one bit-timed bus, run a millisecond at a time; the ADS, the safety
/// controller and a logger are endpoints of the bus.
struct Rig {
    net: Network,
    ads: NodeId,
    safety: NodeId,
    logger: NodeId,
    supervisor: NodeHandle<Supervisor<ReferenceWire>>,
    now: u64,
    counter: u8,
    /// Watchdog level changes: (ms, level).
    watchdog_log: Vec<(u64, Watchdog)>,
    /// The supervisor's state frames: (ms at their end of frame, payload).
    state_frames: Vec<(u64, [u8; 8])>,
    /// The E-stop chain's frame, once the safety controller has sent one: it repeats it every
    /// command cycle, as the tug's does (a chain that falls silent counts as open).
    chain: Option<Frame>,
}

impl Rig {
    fn new() -> Rig {
        let mut net = Network::new();
        let bus = net.add_bus("bus1", 500_000, None);
        let supervisor = net.add_node(Supervisor::with_wire(
            SupervisorConfig::default(),
            ReferenceWire,
        ));
        net.wire(supervisor, Port::MAIN, bus).unwrap();
        let (ads, safety, logger) = (
            net.tap(bus).unwrap(),
            net.tap(bus).unwrap(),
            net.tap(bus).unwrap(),
        );
        Rig {
            net,
            ads,
            safety,
            logger,
            supervisor,
            now: 0,
            counter: 0,
            watchdog_log: Vec::new(),
            state_frames: Vec::new(),
            chain: None,
        }
    }

    /// The ADS sends `frame` now.
    fn ads_sends(&mut self, frame: Frame) {
        let (ads, now) = (self.ads, ms(self.now));
        self.bus().submit(ads, frame, now);
    }

    /// The safety controller sends `frame` now.
    fn safety_sends(&mut self, frame: Frame) {
        self.chain = Some(frame);
        let (safety, now) = (self.safety, ms(self.now));
        self.bus().submit(safety, frame, now);
    }

    fn supervisor(&self) -> &Supervisor<ReferenceWire> {
        self.net.node(self.supervisor).unwrap()
    }

    fn supervisor_mut(&mut self) -> NodeMut<'_, Supervisor<ReferenceWire>> {
        self.net.node_mut(self.supervisor).unwrap()
    }

    /// The bus, to send on and break.
    fn bus(&mut self) -> &mut SimBus {
        self.net.bus_mut(0).unwrap()
    }

    /// Run until `until_ms`, a millisecond at a time, the vehicle's speed following the
    /// actuators (braking stops it).
    fn run_to(&mut self, until_ms: u64) {
        while self.now < until_ms {
            let before = self.supervisor().watchdog();
            self.net.run_for(Duration::from_millis(1));
            self.now += 1;
            let now = ms(self.now);
            let logger = self.logger;
            while let Some(r) = self.net.bus_mut(0).unwrap().receive(logger) {
                if r.frame.id() == Id::standard(0x101).ok() {
                    let at = r.timestamp.as_nanos() / 1_000_000;
                    self.state_frames
                        .push((at, r.frame.data().try_into().unwrap()));
                }
            }
            let after = self.supervisor().watchdog();
            if after != before {
                self.watchdog_log.push((self.now, after));
            }
            let a = self.supervisor().actuators(now);
            let speed = common::plant_speed(&a);
            let mut supervisor = self.net.node_mut(self.supervisor).unwrap();
            supervisor.set_feedback(speed, a.steering);
        }
    }

    /// The ADS sends one command now.
    fn send(&mut self, c: Cmd) {
        let f = command_frame(c, self.counter);
        self.counter = self.counter.wrapping_add(1);
        let (ads, now) = (self.ads, ms(self.now));
        self.bus().submit(ads, f, now);
        if let Some(chain) = self.chain {
            let safety = self.safety;
            self.bus().submit(safety, chain, now);
        }
    }

    /// The ADS sends `n` commands, one per cycle, starting now.
    fn commands(&mut self, n: u32, c: Cmd) {
        for _ in 0..n {
            self.send(c);
            let next = self.now + CYCLE_MS;
            self.run_to(next);
        }
    }

    /// From failed-closed start to autonomous driving: a run of valid commands, then an
    /// engage edge.
    fn engaged() -> Rig {
        let mut rig = Rig::new();
        rig.commands(12, Cmd::default());
        rig.commands(
            1,
            Cmd {
                engage: true,
                ..Cmd::default()
            },
        );
        rig.commands(2, Cmd::default());
        assert_eq!(rig.supervisor().watchdog(), Watchdog::Normal);
        assert_eq!(rig.supervisor().mode(), ControlMode::Autonomous);
        rig
    }
}

/// Verifies: REQ-TO-2.
#[test]
fn starts_failed_closed_and_engages_only_after_a_run_and_a_request() {
    let mut rig = Rig::new();
    rig.run_to(100);
    let a = rig.supervisor().actuators(ms(rig.now));
    assert_eq!(rig.supervisor().watchdog(), Watchdog::FullBraking);
    assert!(!a.steering_enabled && a.brake == 100.0 || !a.ads_in_control);
    // Engage too early (3rd valid command): refused.
    rig.commands(2, Cmd::default());
    rig.commands(
        1,
        Cmd {
            engage: true,
            ..Cmd::default()
        },
    );
    assert!(matches!(
        rig.supervisor().watchdog(),
        Watchdog::Recovering { .. }
    ));
    assert_eq!(rig.supervisor().mode(), ControlMode::Manual);
    // Holding the bit is not a new request.
    rig.commands(
        10,
        Cmd {
            engage: true,
            ..Cmd::default()
        },
    );
    assert!(matches!(
        rig.supervisor().watchdog(),
        Watchdog::Recovering { .. }
    ));
    // A fresh edge after the run engages.
    rig.commands(1, Cmd::default());
    rig.commands(
        1,
        Cmd {
            engage: true,
            ..Cmd::default()
        },
    );
    assert_eq!(rig.supervisor().watchdog(), Watchdog::Normal);
    assert_eq!(rig.supervisor().mode(), ControlMode::Autonomous);
    let a = rig.supervisor().actuators(ms(rig.now));
    assert!(a.ads_in_control && a.steering_enabled && a.velocity == 2.0);
    assert!((a.motor_rpm - 2.0 * 20.0 * 60.0 / (std::f64::consts::PI * 0.5)).abs() < 1e-9);
}

/// Miss `k` command cycles after normal driving; the watchdog's levels and when they came.
fn miss(k: u64) -> (Rig, u64) {
    let mut rig = Rig::engaged();
    // The last command before the silence: its end of frame is when it counted as valid.
    rig.send(Cmd::default());
    let sent_at = rig.now;
    rig.run_to(sent_at + CYCLE_MS * k + CYCLE_MS / 2 + 5);
    (rig, sent_at)
}

/// Level expected after `k` missed cycles.
fn level_after(k: u64) -> Watchdog {
    match k {
        0 => Watchdog::Normal,
        1..=2 => Watchdog::Holding {
            missed: u32::try_from(k).unwrap(),
        },
        3..=4 => Watchdog::Decelerating {
            missed: u32::try_from(k).unwrap(),
        },
        _ => Watchdog::FullBraking,
    }
}

macro_rules! missed_cycles {
    ($($name:ident: $k:expr,)*) => {$(
        #[test]
        fn $name() {
            let (rig, sent_at) = miss($k);
            assert_eq!(rig.supervisor().watchdog(), level_after($k), "{:?}", rig.watchdog_log);
            // Each level came exactly when its cycle was half a cycle overdue (to the
            // millisecond the rig steps in; the command's own frame time is under 1 ms).
            for (at, level) in &rig.watchdog_log {
                if *at <= sent_at {
                    continue;
                }
                let missed = match level {
                    Watchdog::Holding { missed } | Watchdog::Decelerating { missed } => {
                        u64::from(*missed)
                    }
                    Watchdog::FullBraking => 5,
                    other => panic!("unexpected {other:?}"),
                };
                let due = sent_at + missed * CYCLE_MS + CYCLE_MS / 2;
                assert!(*at == due || *at == due + 1, "{level:?} at {at} ms, due {due} ms");
            }
            let a = rig.supervisor().actuators(ms(rig.now));
            match level_after($k) {
                Watchdog::Holding { .. } => {
                    assert!(a.warning && a.velocity == 2.0 && a.steering_enabled);
                }
                Watchdog::Decelerating { .. } => {
                    assert!(a.warning && a.velocity < 2.0 && a.brake == 0.0);
                }
                Watchdog::FullBraking => {
                    assert!(!a.steering_enabled && a.brake == 100.0 && !a.motors_enabled);
                }
                _ => unreachable!(),
            }
        }
    )*};
}

missed_cycles! {
    missed_1_cycle_holds_and_warns: 1,
    missed_2_cycles_hold_and_warn: 2,
    missed_3_cycles_decelerate: 3,
    missed_4_cycles_decelerate: 4,
    missed_5_cycles_brake_fully: 5,
    missed_6_cycles_brake_fully: 6,
    missed_7_cycles_brake_fully: 7,
    missed_8_cycles_brake_fully: 8,
    missed_9_cycles_brake_fully: 9,
    missed_10_cycles_brake_fully: 10,
}

/// Verifies: REQ-TO-1.
#[test]
fn controlled_deceleration_follows_its_rate() {
    let (mut rig, sent_at) = miss(3);
    // Decelerating since cycle 3 was overdue: 2.0 m/s falls at 1.5 m/s².
    let start = sent_at + 3 * CYCLE_MS + CYCLE_MS / 2;
    let t = start + 20;
    rig.run_to(t);
    let a = rig.supervisor().actuators(ms(t));
    let expected = 2.0 - 1.5 * (t - start) as f64 / 1000.0;
    assert!(
        (a.velocity - expected).abs() < 1.5 * 0.002,
        "{} vs {expected}",
        a.velocity
    );
}

/// Verifies: REQ-TO-2.
#[test]
fn full_braking_recovers_only_after_a_run_and_a_re_engage() {
    let (mut rig, _) = miss(6);
    rig.commands(20, Cmd::default());
    assert!(matches!(
        rig.supervisor().watchdog(),
        Watchdog::Recovering { .. }
    ));
    assert_eq!(rig.supervisor().actuators(ms(rig.now)).brake, 100.0);
    rig.commands(
        1,
        Cmd {
            engage: true,
            ..Cmd::default()
        },
    );
    assert_eq!(rig.supervisor().watchdog(), Watchdog::Normal);
    // The mode fell to manual? No: autonomous stays requested, the watchdog braked it.
    let a = rig.supervisor().actuators(ms(rig.now));
    assert_eq!(a.brake, 0.0);
}

/// Verifies: REQ-E2E-1.
#[test]
fn corrupted_checksum_is_rejected_and_counted() {
    let mut rig = Rig::engaged();
    let mut frame = command_frame(Cmd::default(), rig.counter);
    rig.counter += 1;
    if let Frame::Classic(f) = &mut frame {
        let mut data: [u8; 8] = f.data().try_into().unwrap();
        data[0] ^= 0x01;
        frame = Frame::classic(f.id(), &data).unwrap();
    }
    let before = rig.supervisor().stats();
    rig.ads_sends(frame);
    let t = rig.now + CYCLE_MS + CYCLE_MS / 2 + 2;
    rig.run_to(t);
    assert_eq!(rig.supervisor().stats().checksum, before.checksum + 1);
    assert_eq!(rig.supervisor().stats().accepted, before.accepted);
    assert!(matches!(
        rig.supervisor().watchdog(),
        Watchdog::Holding { .. }
    ));
}

/// Verifies: REQ-E2E-2.
#[test]
fn repeated_counter_is_rejected_and_counted() {
    let mut rig = Rig::engaged();
    rig.counter = rig.counter.wrapping_sub(1);
    rig.commands(3, Cmd::default());
    assert_eq!(rig.supervisor().stats().repeated, 1);
    assert_eq!(rig.supervisor().watchdog(), Watchdog::Normal);
}

/// Verifies: REQ-E2E-2.
#[test]
fn skipped_counter_is_rejected_and_counted() {
    let mut rig = Rig::engaged();
    rig.counter = rig.counter.wrapping_add(3);
    rig.commands(1, Cmd::default());
    assert_eq!(rig.supervisor().stats().skipped, 1);
    // The next one in sequence is accepted again.
    rig.commands(1, Cmd::default());
    assert_eq!(rig.supervisor().stats().skipped, 1);
    assert_eq!(rig.supervisor().watchdog(), Watchdog::Normal);
}

/// Verifies: REQ-TO-1.
#[test]
fn stale_counter_escalates_like_silence() {
    // A frozen ADS repeats its last frame: nothing new, so the watchdog escalates.
    let mut rig = Rig::engaged();
    let frozen = rig.counter;
    for _ in 0..7 {
        rig.counter = frozen;
        rig.commands(1, Cmd::default());
    }
    assert_eq!(rig.supervisor().stats().repeated, 6);
    assert_eq!(rig.supervisor().watchdog(), Watchdog::FullBraking);
}

/// Verifies: REQ-RNG-1.
#[test]
fn out_of_range_setpoints_are_rejected() {
    let mut rig = Rig::engaged();
    for bad in [
        Cmd {
            steering: 44.0,
            ..Cmd::default()
        },
        Cmd {
            velocity: 6.0,
            ..Cmd::default()
        },
        Cmd {
            steering_mode: 3,
            ..Cmd::default()
        },
    ] {
        rig.commands(1, bad);
    }
    assert_eq!(rig.supervisor().stats().out_of_range, 3);
    // Three cycles without a valid command: decelerating, not driving a bad setpoint.
    let a = rig.supervisor().actuators(ms(rig.now));
    assert!(a.steering.abs() < 1.0 && a.velocity <= 2.0);
}

fn press_estop(rig: &mut Rig) -> u64 {
    rig.safety_sends(estop_frame(true));
    let t = rig.now;
    rig.run_to(t + 2);
    t
}

macro_rules! estop_in_mode {
    ($($name:ident: $mode:expr,)*) => {$(
        #[test]
        fn $name() {
            let mut rig = Rig::engaged();
            match $mode {
                ControlMode::Manual => rig.commands(2, Cmd { mode: 0, ..Cmd::default() }),
                ControlMode::Calibration => {
                    rig.commands(2, Cmd { mode: 0, velocity: 0.0, ..Cmd::default() });
                    rig.commands(2, Cmd { mode: 3, velocity: 0.0, ..Cmd::default() });
                }
                _ => {}
            }
            assert_eq!(rig.supervisor().mode(), $mode);
            let pressed = press_estop(&mut rig);
            // Within the frame's time on the wire (< 1 ms at 500 kbit/s) the latch has
            // disabled the motors and applied the brakes; at standstill it is stopped.
            assert_eq!(rig.supervisor().estop(), EstopState::Stopped);
            assert_eq!(rig.supervisor().mode(), ControlMode::Estop);
            let a = rig.supervisor().actuators(ms(rig.now));
            assert!(!a.motors_enabled && a.brake == 100.0 && !a.steering_enabled);
            assert!(rig.now - pressed <= 2);
        }
    )*};
}

estop_in_mode! {
    estop_in_autonomous_mode_latches: ControlMode::Autonomous,
    estop_in_manual_mode_latches: ControlMode::Manual,
    estop_in_calibration_mode_latches: ControlMode::Calibration,
}

/// Verifies: REQ-ES-1.
#[test]
fn estop_refuses_every_automatic_reset_path() {
    let mut rig = Rig::engaged();
    press_estop(&mut rig);
    // Chain closed again: stays stopped.
    rig.safety_sends(estop_frame(false));
    rig.commands(3, Cmd::default());
    assert_eq!(rig.supervisor().estop(), EstopState::Stopped);
    // Engage alone: stays stopped.
    rig.commands(
        1,
        Cmd {
            engage: true,
            ..Cmd::default()
        },
    );
    rig.commands(1, Cmd::default());
    assert_eq!(rig.supervisor().estop(), EstopState::Stopped);
    // Operator reset while the chain is open: refused.
    rig.safety_sends(estop_frame(true));
    rig.commands(
        1,
        Cmd {
            reset: true,
            ..Cmd::default()
        },
    );
    rig.commands(1, Cmd::default());
    assert_eq!(rig.supervisor().estop(), EstopState::Stopped);
    // The full sequence: chain closed, reset (→ E_STOP_RESET once verified), reset again to
    // confirm, then engage.
    rig.safety_sends(estop_frame(false));
    rig.commands(1, Cmd::default());
    rig.commands(
        1,
        Cmd {
            reset: true,
            ..Cmd::default()
        },
    );
    assert_eq!(rig.supervisor().estop(), EstopState::EstopReset);
    rig.commands(1, Cmd::default());
    assert_eq!(
        rig.supervisor().estop(),
        EstopState::EstopReset,
        "no automatic confirm"
    );
    rig.commands(
        1,
        Cmd {
            reset: true,
            ..Cmd::default()
        },
    );
    assert_eq!(rig.supervisor().estop(), EstopState::ResetConfirmed);
    rig.commands(1, Cmd::default());
    rig.commands(
        1,
        Cmd {
            engage: true,
            ..Cmd::default()
        },
    );
    assert_eq!(rig.supervisor().estop(), EstopState::Normal);
    // Out of E-stop into manual, never straight to autonomous.
    assert_eq!(rig.supervisor().mode(), ControlMode::Manual);
    rig.commands(1, Cmd::default());
    rig.commands(
        1,
        Cmd {
            engage: true,
            ..Cmd::default()
        },
    );
    assert_eq!(rig.supervisor().mode(), ControlMode::Autonomous);
    // The state frames reported each latch stage the ADS could see.
    let reported: Vec<u8> = rig
        .state_frames
        .iter()
        .map(|(_, p)| (p[5] >> 1) & 7)
        .collect();
    for stage in [4u8, 6, 7, 0] {
        assert!(reported.contains(&stage), "stage {stage} never reported");
    }
}

/// Verifies: REQ-ES-1.
#[test]
fn a_new_press_during_the_reset_sequence_starts_over() {
    let mut rig = Rig::engaged();
    press_estop(&mut rig);
    rig.safety_sends(estop_frame(false));
    rig.commands(1, Cmd::default());
    rig.commands(
        1,
        Cmd {
            reset: true,
            ..Cmd::default()
        },
    );
    assert_eq!(rig.supervisor().estop(), EstopState::EstopReset);
    press_estop(&mut rig);
    assert_eq!(rig.supervisor().estop(), EstopState::Stopped);
}

/// Verifies: REQ-TK-1.
#[test]
fn driver_takeover_at_speed_drops_to_manual_at_once() {
    let mut rig = Rig::engaged();
    rig.commands(
        5,
        Cmd {
            velocity: 3.0,
            ..Cmd::default()
        },
    );
    let now = ms(rig.now);
    rig.supervisor_mut().set_driver_input(5.0, 0.0);
    assert_eq!(rig.supervisor().mode(), ControlMode::Manual);
    assert!(!rig.supervisor().actuators(now).ads_in_control);
    // Re-engage with the driver's hands still on: refused; hands off: accepted.
    rig.commands(
        1,
        Cmd {
            engage: true,
            velocity: 3.0,
            ..Cmd::default()
        },
    );
    assert_eq!(rig.supervisor().mode(), ControlMode::Manual);
    rig.supervisor_mut().set_driver_input(0.5, 0.0);
    rig.commands(1, Cmd::default());
    rig.commands(
        1,
        Cmd {
            engage: true,
            ..Cmd::default()
        },
    );
    assert_eq!(rig.supervisor().mode(), ControlMode::Autonomous);
    // Pedal and non-finite readings take over too.
    rig.supervisor_mut().set_driver_input(0.0, 0.5);
    assert_eq!(rig.supervisor().mode(), ControlMode::Manual);
    rig.supervisor_mut().set_driver_input(f64::NAN, 0.0);
    assert_eq!(rig.supervisor().mode(), ControlMode::Manual);
}

/// Verifies: REQ-SS-2.
#[test]
fn emergency_brake_burst_brakes_fully_while_it_lasts() {
    let mut rig = Rig::engaged();
    for _ in 0..3 {
        rig.ads_sends(brake_frame());
    }
    let t = rig.now;
    rig.run_to(t + 3);
    assert_eq!(rig.supervisor().actuators(ms(rig.now)).brake, 100.0);
    // Commands continue but no more brake frames: braking ends 3 cycles after the last one.
    rig.commands(4, Cmd::default());
    assert_eq!(rig.supervisor().actuators(ms(rig.now)).brake, 0.0);
}

/// Verifies: REQ-TO-1, REQ-FI-1.
#[test]
fn ads_node_going_bus_off_trips_the_watchdog() {
    let mut rig = Rig::engaged();
    // Every transmission of the ADS destroyed: TEC climbs by 8 per attempt, bus-off after 32;
    // it recovers after 128 × 11 recessive bits and fails again, so nothing gets through.
    rig.bus().take_events();
    rig.net.bus_mut(0).unwrap().corrupt(Fault {
        node: Some(rig.ads),
        id: None,
        count: u32::MAX,
        kind: Default::default(),
    });
    let last_ok = rig.now;
    rig.commands(8, Cmd::default());
    let ads = rig.ads;
    let bus_off = rig.bus().take_events().into_iter().any(|e| {
        matches!(e, bywire_net::sim::BusEvent::StateChanged { node, state: bywire_core::confinement::NodeState::BusOff, .. } if node == ads)
    });
    assert!(bus_off, "the ADS node went bus-off");
    assert_eq!(rig.supervisor().watchdog(), Watchdog::FullBraking);
    let braking_at = rig
        .watchdog_log
        .iter()
        .find(|(_, w)| *w == Watchdog::FullBraking)
        .unwrap()
        .0;
    // Bus-off took a few ms; full braking followed 5½ cycles after the last command through.
    assert!(braking_at > last_ok && braking_at <= last_ok + 5 * CYCLE_MS + CYCLE_MS / 2 + 2);
}

#[test]
fn the_state_frame_echoes_the_heartbeat_and_is_sealed() {
    let mut rig = Rig::engaged();
    rig.commands(3, Cmd::default());
    let (_, last) = *rig.state_frames.last().unwrap();
    assert!(messages::is_sealed(0x101, &last));
    // The state frame and the command fall due at the same instant: the frame goes out first
    // and echoes the command of the cycle before (the last one received).
    let echo = last[6] & 0x0F;
    assert_eq!(echo, rig.counter.wrapping_sub(2) & 0x0F);
    // WatchdogLevel 0 and ControlMode autonomous.
    assert_eq!(last[4] & 3, 1);
    assert_eq!((last[4] >> 6) | ((last[5] & 1) << 2), 0);
    // One state frame per cycle.
    let times: Vec<u64> = rig.state_frames.iter().map(|(t, _)| *t).collect();
    assert!(times.windows(2).all(|w| w[1] - w[0] == CYCLE_MS));
}
