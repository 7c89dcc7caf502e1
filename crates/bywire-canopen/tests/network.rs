//! A master and its devices on one simulated bus, in simulated time: bring-up, control, and
//! the safe stops (heartbeat loss, master silence, emergencies) with their timing.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::time::Duration;

use bywire_canopen::cia402::{self, Drive, DriveController, Mode, Setpoint, State, StopReason};
use bywire_canopen::device::Device;
use bywire_canopen::master::{Controlled, Master, MasterEvent};
use bywire_canopen::nmt::{HeartbeatEvent, NmtCommand, NmtState};
use bywire_canopen::roboteq::{self, Mdc1460, RoboteqCommand, RoboteqMotor};
use bywire_canopen::{Node, Port};
use bywire_core::frame::Frame;
use bywire_core::time::Timestamp;

/// Every node polled at each step; every frame reaches every other node at once (settling
/// within the step); a node marked silent sends nothing (powered off or cut off).
struct Bus {
    now: Timestamp,
    silent: Vec<bool>,
    log: Vec<(Timestamp, usize, Frame)>,
}

impl Bus {
    fn new(nodes: usize) -> Bus {
        Bus {
            now: Timestamp::ZERO,
            silent: vec![false; nodes],
            log: Vec::new(),
        }
    }

    fn step(&mut self, nodes: &mut [&mut dyn Node]) {
        let mut pending: Vec<(usize, Frame)> = Vec::new();
        for (i, node) in nodes.iter_mut().enumerate() {
            node.poll(self.now, &mut |_, frame| pending.push((i, frame)));
        }
        // Bounded: each round's frames are answered by at most a block of responses.
        for _ in 0..64 {
            if pending.is_empty() {
                break;
            }
            let round = std::mem::take(&mut pending);
            for (from, frame) in round {
                if self.silent[from] {
                    continue;
                }
                self.log.push((self.now, from, frame));
                for (i, node) in nodes.iter_mut().enumerate() {
                    if i != from {
                        node.on_frame(self.now, Port::MAIN, &frame);
                    }
                }
            }
            for (i, node) in nodes.iter_mut().enumerate() {
                node.poll(self.now, &mut |_, frame| pending.push((i, frame)));
            }
        }
    }

    fn run(&mut self, duration: Duration, tick: Duration, nodes: &mut [&mut dyn Node]) {
        let end = self.now.saturating_add(duration);
        while self.now < end {
            self.step(nodes);
            self.now = self.now.saturating_add(tick);
        }
    }
}

const DRIVE: u8 = 2;
const MASTER: u8 = 1;
const TICK: Duration = Duration::from_millis(1);
const CONSUMER_TIME: Duration = Duration::from_millis(250);

/// A master that walks a velocity drive to Operation enabled and commands `velocity`.
fn running_drive(velocity: i32) -> (Bus, Master, Device<Drive>) {
    let mut master = Master::new(
        MASTER,
        Duration::from_millis(100),
        Duration::from_millis(10),
    );
    let mut controller =
        DriveController::new(DRIVE, Mode::ProfileVelocity, Duration::from_millis(500));
    controller.set_enabled(true);
    controller.set_setpoint(Setpoint::Velocity(velocity));
    master.add(Controlled::Drive(controller));
    assert!(master.monitor(DRIVE, CONSUMER_TIME));
    let mut od = cia402::drive_dictionary(DRIVE);
    // The drive watches the master's heartbeat.
    od.set(0x1016, 1, &((u32::from(MASTER) << 16) | 300).to_le_bytes())
        .unwrap();
    let mut drive = Device::new(DRIVE, od, Drive::new());
    let mut bus = Bus::new(2);
    bus.run(
        Duration::from_millis(20),
        TICK,
        &mut [&mut master, &mut drive],
    );
    master.nmt(NmtCommand::Start, DRIVE);
    bus.run(
        Duration::from_millis(1_500),
        TICK,
        &mut [&mut master, &mut drive],
    );
    (bus, master, drive)
}

fn controller(master: &mut Master) -> &mut DriveController {
    match master.controlled(DRIVE) {
        Some(Controlled::Drive(drive)) => drive,
        _ => panic!("no drive"),
    }
}

#[test]
fn the_master_walks_a_drive_to_operation_enabled_and_it_follows() {
    let (bus, mut master, drive) = running_drive(1_000);
    assert_eq!(drive.state(), NmtState::Operational);
    assert_eq!(drive.app().state(), State::OperationEnabled);
    assert!((drive.app().motor().velocity - 1_000.0).abs() < 1.0);
    assert_eq!(
        controller(&mut master).drive_state(),
        Some(State::OperationEnabled)
    );
    assert_eq!(
        controller(&mut master).actual().1,
        1_000,
        "TPDO2 reports the velocity"
    );
    // The walk went through every state of the enable path, in order.
    let states: Vec<State> = bus
        .log
        .iter()
        .filter(|(_, from, frame)| *from == 1 && frame.id().map(|id| id.as_raw()) == Some(0x182))
        .filter_map(|(_, _, frame)| {
            State::from_statusword(u16::from_le_bytes([frame.data()[0], frame.data()[1]]))
        })
        .fold(Vec::new(), |mut seen, state| {
            if seen.last() != Some(&state) {
                seen.push(state);
            }
            seen
        });
    assert_eq!(
        states,
        [
            State::SwitchOnDisabled,
            State::ReadyToSwitchOn,
            State::SwitchedOn,
            State::OperationEnabled
        ]
    );
}

#[test]
fn a_lost_drive_heartbeat_is_detected_within_the_consumer_time_and_stopped_at_once() {
    let (mut bus, mut master, mut drive) = running_drive(1_000);
    // Cut the drive off: nothing it sends reaches the bus.
    bus.silent[1] = true;
    let cut_at = bus.now;
    let last_heartbeat = bus
        .log
        .iter()
        .rev()
        .find(|(_, from, f)| *from == 1 && f.id().map(|id| id.as_raw()) == Some(0x702))
        .unwrap()
        .0;
    bus.run(
        Duration::from_millis(400),
        TICK,
        &mut [&mut master, &mut drive],
    );
    let lost_at = bus
        .log
        .iter()
        .find(|(t, from, frame)| {
            *t >= cut_at
                && *from == 0
                && frame.id().map(|id| id.as_raw()) == Some(0x202)
                && frame.data()[..2] == [0x02, 0x00]
        })
        .map(|(t, _, _)| *t)
        .expect("a quick stop controlword");
    let deadline = last_heartbeat.saturating_add(CONSUMER_TIME);
    assert!(
        lost_at >= deadline,
        "not before the consumer time ({lost_at:?} < {deadline:?})"
    );
    assert!(
        lost_at <= deadline.saturating_add(TICK),
        "within the consumer time and one poll ({lost_at:?})"
    );
    // The same instant: target velocity zero on RPDO2.
    let target = bus
        .log
        .iter()
        .find(|(t, from, f)| {
            *t == lost_at && *from == 0 && f.id().map(|id| id.as_raw()) == Some(0x302)
        })
        .unwrap();
    assert_eq!(
        i32::from_le_bytes(target.2.data()[4..8].try_into().unwrap()),
        0
    );
    assert_eq!(
        controller(&mut master).stopped(),
        Some(StopReason::HeartbeatLost)
    );
    let events: Vec<MasterEvent> = std::iter::from_fn(|| master.next_event()).collect();
    assert!(
        events.contains(&MasterEvent::Heartbeat(HeartbeatEvent::Lost {
            node: DRIVE
        }))
    );
    // The drive heard the quick stop and is stopping (it still receives).
    assert!(
        drive.app().motor().velocity.abs() < 1.0,
        "stopped: {}",
        drive.app().motor().velocity
    );
    // Back on the bus, the drive is held stopped until the application acknowledges.
    bus.silent[1] = false;
    bus.run(
        Duration::from_millis(500),
        TICK,
        &mut [&mut master, &mut drive],
    );
    assert!(drive.app().motor().velocity.abs() < 1.0);
    assert_ne!(drive.app().state(), State::OperationEnabled);
    controller(&mut master).acknowledge();
    bus.run(
        Duration::from_millis(500),
        TICK,
        &mut [&mut master, &mut drive],
    );
    assert_eq!(drive.app().state(), State::OperationEnabled);
}

#[test]
fn with_the_runner_sleeping_until_the_next_deadline_detection_is_exact() {
    let (mut bus, mut master, mut drive) = running_drive(500);
    bus.silent[1] = true;
    let last_heartbeat = bus
        .log
        .iter()
        .rev()
        .find(|(_, from, f)| *from == 1 && f.id().map(|id| id.as_raw()) == Some(0x702))
        .unwrap()
        .0;
    // An event-driven runner: poll the master exactly at its next deadline.
    let mut lost = None;
    for _ in 0..1_000 {
        let next = master.next_deadline().unwrap();
        bus.now = next.max(bus.now);
        bus.step(&mut [&mut master, &mut drive]);
        if controller(&mut master).stopped().is_some() {
            lost = Some(bus.now);
            break;
        }
        bus.now = bus.now.saturating_add(Duration::from_micros(1));
    }
    assert_eq!(lost, Some(last_heartbeat.saturating_add(CONSUMER_TIME)));
}

#[test]
fn a_silent_master_faults_the_drive_and_it_stops() {
    let (mut bus, mut master, mut drive) = running_drive(2_000);
    bus.silent[0] = true;
    bus.run(
        Duration::from_millis(600),
        TICK,
        &mut [&mut master, &mut drive],
    );
    assert_eq!(
        drive.app().state(),
        State::Fault,
        "abort connection option 1: fault"
    );
    assert!(drive.app().motor().velocity.abs() < 1.0);
    let emcy = bus
        .log
        .iter()
        .find(|(_, from, f)| *from == 1 && f.id().map(|id| id.as_raw()) == Some(0x82))
        .unwrap();
    assert_eq!(&emcy.2.data()[..2], &[0x30, 0x81], "EMCY 0x8130: heartbeat");
    assert_ne!(
        emcy.2.data()[2] & 0x11,
        0,
        "error register: generic + communication"
    );
}

#[test]
fn an_emergency_stops_the_drive_until_acknowledged() {
    let (mut bus, mut master, mut drive) = running_drive(1_000);
    drive.app_mut().0.inject_fault(0x2310);
    bus.run(
        Duration::from_millis(300),
        TICK,
        &mut [&mut master, &mut drive],
    );
    assert_eq!(
        controller(&mut master).stopped(),
        Some(StopReason::Emergency(0x2310))
    );
    assert_eq!(drive.app().state(), State::Fault);
    assert!(drive.app().motor().velocity.abs() < 1.0);
    // Acknowledged while the cause remains: the fault reset does nothing.
    controller(&mut master).acknowledge();
    bus.run(
        Duration::from_millis(300),
        TICK,
        &mut [&mut master, &mut drive],
    );
    assert_eq!(drive.app().state(), State::Fault);
    // The cause gone and acknowledged again: back to Operation enabled, running.
    drive.app_mut().0.clear_fault();
    controller(&mut master).acknowledge();
    bus.run(
        Duration::from_millis(1_000),
        TICK,
        &mut [&mut master, &mut drive],
    );
    assert_eq!(drive.app().state(), State::OperationEnabled);
    assert!((drive.app().motor().velocity - 1_000.0).abs() < 1.0);
    let resets = bus
        .log
        .iter()
        .filter(|(_, from, f)| {
            *from == 1 && f.id().map(|id| id.as_raw()) == Some(0x82) && f.data()[..2] == [0, 0]
        })
        .count();
    assert!(resets >= 1, "an error-reset EMCY after the fault cleared");
}

#[test]
fn profile_position_reaches_its_target() {
    let mut master = Master::new(
        MASTER,
        Duration::from_millis(100),
        Duration::from_millis(10),
    );
    let mut controller =
        DriveController::new(DRIVE, Mode::ProfilePosition, Duration::from_millis(500));
    controller.set_enabled(true);
    controller.set_setpoint(Setpoint::Position(5_000));
    master.add(Controlled::Drive(controller));
    let mut drive = Device::new(DRIVE, cia402::drive_dictionary(DRIVE), Drive::new());
    let mut bus = Bus::new(2);
    bus.run(
        Duration::from_millis(10),
        TICK,
        &mut [&mut master, &mut drive],
    );
    master.nmt(NmtCommand::Start, DRIVE);
    bus.run(
        Duration::from_millis(5_000),
        TICK,
        &mut [&mut master, &mut drive],
    );
    assert!(
        (drive.app().motor().position - 5_000.0).abs() <= 10.0,
        "{:?}",
        drive.app().motor()
    );
    let statusword = drive.od().get_unsigned(0x6041, 0).unwrap();
    assert_ne!(statusword & 0x0400, 0, "target reached");
}

#[test]
fn a_roboteq_remapped_to_velocity_over_sdo_runs_at_1200_rpm() {
    const NODE: u8 = 1;
    let mut master = Master::new(0x7F, Duration::from_millis(100), Duration::from_millis(20));
    master.add(Controlled::Roboteq(RoboteqMotor::new(
        NODE,
        RoboteqCommand::Velocity(0),
    )));
    master.monitor(NODE, CONSUMER_TIME);
    let mut controller =
        Device::new(NODE, roboteq::dictionary(NODE, 2), Mdc1460::default()).with_autostart();
    let mut bus = Bus::new(2);
    roboteq::remap_rpdo1_to_velocity(master.sdo(), NODE, 1).unwrap();
    bus.run(
        Duration::from_millis(100),
        TICK,
        &mut [&mut master, &mut controller],
    );
    let outcomes: Vec<_> = std::iter::from_fn(|| master.take_sdo_outcome()).collect();
    assert_eq!(outcomes.len(), 5);
    assert!(outcomes.iter().all(|o| o.result.is_ok()), "{outcomes:?}");
    match master.controlled(NODE) {
        Some(Controlled::Roboteq(motor)) => motor.set(RoboteqCommand::Velocity(1200)),
        _ => panic!(),
    }
    bus.run(
        Duration::from_millis(1_500),
        TICK,
        &mut [&mut master, &mut controller],
    );
    assert!(
        (controller.app().speed(1) - 1200.0).abs() < 2.0,
        "{}",
        controller.app().speed(1)
    );
    assert!(bus.log.iter().any(|(_, from, f)| *from == 0
        && f.id().map(|id| id.as_raw()) == Some(0x201)
        && f.data() == [0xB0, 0x04, 0x00, 0x00]));
    // The controller stops reporting: the master zeroes the command.
    bus.silent[1] = true;
    bus.run(
        Duration::from_millis(1_500),
        TICK,
        &mut [&mut master, &mut controller],
    );
    let last = bus
        .log
        .iter()
        .rev()
        .find(|(_, from, f)| *from == 0 && f.id().map(|id| id.as_raw()) == Some(0x201))
        .unwrap();
    assert_eq!(last.2.data(), [0, 0, 0, 0]);
    assert!(controller.app().speed(1).abs() < 1.0);
}

#[test]
fn cyclic_synchronous_modes_follow_the_streamed_targets() {
    for mode in [
        Mode::CyclicSynchronousVelocity,
        Mode::CyclicSynchronousPosition,
    ] {
        let mut master = Master::new(MASTER, Duration::from_millis(100), Duration::from_millis(5))
            .with_sync(Duration::from_millis(5));
        let mut cyclic = DriveController::new(DRIVE, mode, Duration::from_millis(500));
        cyclic.set_enabled(true);
        master.add(Controlled::Drive(cyclic));
        let mut drive = Device::new(DRIVE, cia402::drive_dictionary(DRIVE), Drive::new());
        let mut bus = Bus::new(2);
        bus.run(
            Duration::from_millis(10),
            TICK,
            &mut [&mut master, &mut drive],
        );
        master.nmt(NmtCommand::Start, DRIVE);
        bus.run(
            Duration::from_millis(300),
            TICK,
            &mut [&mut master, &mut drive],
        );
        assert_eq!(drive.app().state(), State::OperationEnabled, "{mode:?}");
        // A ramp streamed every cycle: 0 → 1000 units in one second.
        for step in 0..=200 {
            let value = step * 5;
            let setpoint = if mode == Mode::CyclicSynchronousVelocity {
                Setpoint::Velocity(value)
            } else {
                Setpoint::Position(value)
            };
            controller(&mut master).set_setpoint(setpoint);
            bus.run(
                Duration::from_millis(5),
                TICK,
                &mut [&mut master, &mut drive],
            );
        }
        bus.run(
            Duration::from_millis(200),
            TICK,
            &mut [&mut master, &mut drive],
        );
        let motor = drive.app().motor();
        match mode {
            Mode::CyclicSynchronousVelocity => {
                assert!((motor.velocity - 1_000.0).abs() < 1.0, "{motor:?}")
            }
            _ => assert!((motor.position - 1_000.0).abs() <= 10.0, "{motor:?}"),
        }
        assert_eq!(
            drive.od().get_signed(0x6061, 0),
            Some(i64::from(mode.code())),
            "modes display"
        );
    }
}
