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
use bywire_net::network::{BusIndex, Network, NodeHandle, NodeMut};
use bywire_net::sim::NodeId;

/// The master (sender 0) and one device (sender 1) on a simulated 1 Mbit/s bus, run by the
/// network runner (bit-timed frames, each node polled at its deadline); `log` is every frame
/// on the wire with its sender, as a tap saw it.
struct Bus<D: Node + 'static> {
    net: Network,
    bus: BusIndex,
    tap: NodeId,
    master: NodeHandle<Master>,
    device: NodeHandle<D>,
    /// The device's node ID (its heartbeat tells the two senders apart).
    device_id: u8,
    log: Vec<(Timestamp, usize, Frame)>,
}

impl<D: Node + 'static> Bus<D> {
    fn new(device_id: u8, master: Master, device: D) -> Bus<D> {
        let mut net = Network::new();
        let bus = net.add_bus("can0", 1_000_000, None);
        let master = net.add_node(master);
        let device = net.add_node(device);
        net.wire(master, Port::MAIN, bus).unwrap();
        net.wire(device, Port::MAIN, bus).unwrap();
        let tap = net.tap(bus).unwrap();
        Bus {
            net,
            bus,
            tap,
            master,
            device,
            device_id,
            log: Vec::new(),
        }
    }

    fn master(&mut self) -> NodeMut<'_, Master> {
        self.net.node_mut(self.master).unwrap()
    }

    fn device(&self) -> &D {
        self.net.node(self.device).unwrap()
    }

    fn device_mut(&mut self) -> NodeMut<'_, D> {
        self.net.node_mut(self.device).unwrap()
    }

    fn now(&self) -> Timestamp {
        self.net.now()
    }

    /// Cut a node off the bus (nothing it sends arrives), or put it back.
    fn silence(&mut self, sender: usize, silent: bool) {
        match sender {
            0 => self.net.drop_output(self.master, silent),
            _ => self.net.drop_output(self.device, silent),
        }
    }

    /// Who sent `frame`: CANopen's COB-IDs say it (the master sends NMT, SYNC, RPDOs, SDO
    /// requests and its heartbeat; the device its TPDOs, SDO responses, EMCY, heartbeat).
    fn sender(&self, frame: &Frame) -> usize {
        let id = frame.id().map_or(0, |id| id.as_raw());
        let device = match id {
            0x700..=0x77F => id == 0x700 + u32::from(self.device_id),
            0x081..=0x0FF | 0x180..=0x1FF | 0x280..=0x2FF | 0x380..=0x3FF | 0x480..=0x4FF => true,
            0x580..=0x5FF => true,
            _ => false,
        };
        usize::from(device)
    }

    /// Run for `duration`, logging.
    fn run(&mut self, duration: Duration) {
        let end = self.now().saturating_add(duration);
        // In slices, so the tap's queue never fills.
        while self.now() < end {
            let until = self
                .now()
                .saturating_add(Duration::from_millis(10))
                .min(end);
            self.net.run_until(until);
            while let Some(r) = self.net.bus_mut(self.bus).and_then(|b| b.receive(self.tap)) {
                self.log.push((r.timestamp, self.sender(&r.frame), r.frame));
            }
        }
    }
}

const DRIVE: u8 = 2;
const MASTER: u8 = 1;
const TICK: Duration = Duration::from_millis(1);
const CONSUMER_TIME: Duration = Duration::from_millis(250);

/// A master that walks a velocity drive to Operation enabled and commands `velocity`.
fn running_drive(velocity: i32) -> Bus<Device<Drive>> {
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
    let drive = Device::new(DRIVE, od, Drive::new());
    let mut bus = Bus::new(DRIVE, master, drive);
    bus.run(Duration::from_millis(20));
    bus.master().nmt(NmtCommand::Start, DRIVE);
    bus.run(Duration::from_millis(1_500));
    bus
}

fn controller<'a>(master: &'a mut NodeMut<'_, Master>) -> &'a mut DriveController {
    match master.controlled(DRIVE) {
        Some(Controlled::Drive(drive)) => drive,
        _ => panic!("no drive"),
    }
}

#[test]
fn the_master_walks_a_drive_to_operation_enabled_and_it_follows() {
    let mut bus = running_drive(1_000);
    assert_eq!(bus.device().state(), NmtState::Operational);
    assert_eq!(bus.device().app().state(), State::OperationEnabled);
    assert!((bus.device().app().motor().velocity - 1_000.0).abs() < 1.0);
    assert_eq!(
        controller(&mut bus.master()).drive_state(),
        Some(State::OperationEnabled)
    );
    assert_eq!(
        controller(&mut bus.master()).actual().1,
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
fn the_controller_knows_when_the_drives_process_data_last_came() {
    let mut bus = running_drive(1_000);
    let last_tpdo = |bus: &Bus<Device<Drive>>| {
        bus.log
            .iter()
            .rev()
            .find(|(_, from, frame)| {
                *from == 1 && matches!(frame.id().map(|id| id.as_raw()), Some(0x182 | 0x282))
            })
            .map(|(at, ..)| *at)
    };
    let heard = controller(&mut bus.master()).last_heard();
    assert!(heard.is_some());
    assert_eq!(heard, last_tpdo(&bus));
    // Cut off: the time stays at its last process data while the master runs on.
    bus.silence(1, true);
    bus.run(Duration::from_millis(50));
    assert_eq!(controller(&mut bus.master()).last_heard(), heard);
    assert!(bus.now().saturating_since(heard.unwrap()) >= Duration::from_millis(50));
}

#[test]
fn a_lost_drive_heartbeat_is_detected_within_the_consumer_time_and_stopped_at_once() {
    let mut bus = running_drive(1_000);
    // Cut the drive off: nothing it sends reaches the bus.
    bus.silence(1, true);
    let cut_at = bus.now();
    let last_heartbeat = bus
        .log
        .iter()
        .rev()
        .find(|(_, from, f)| *from == 1 && f.id().map(|id| id.as_raw()) == Some(0x702))
        .unwrap()
        .0;
    bus.run(Duration::from_millis(400));
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
    // At once (the next frame on the wire): target velocity zero on RPDO2.
    let target = bus
        .log
        .iter()
        .find(|(t, from, f)| {
            *t >= lost_at && *from == 0 && f.id().map(|id| id.as_raw()) == Some(0x302)
        })
        .unwrap();
    assert!(target.0.saturating_since(lost_at) <= Duration::from_micros(250));
    assert_eq!(
        i32::from_le_bytes(target.2.data()[4..8].try_into().unwrap()),
        0
    );
    assert_eq!(
        controller(&mut bus.master()).stopped(),
        Some(StopReason::HeartbeatLost)
    );
    let events: Vec<MasterEvent> = std::iter::from_fn(|| bus.master().next_event()).collect();
    assert!(
        events.contains(&MasterEvent::Heartbeat(HeartbeatEvent::Lost {
            node: DRIVE
        }))
    );
    // The drive heard the quick stop and is stopping (it still receives).
    assert!(
        bus.device().app().motor().velocity.abs() < 1.0,
        "stopped: {}",
        bus.device().app().motor().velocity
    );
    // Back on the bus, the drive is held stopped until the application acknowledges.
    bus.silence(1, false);
    bus.run(Duration::from_millis(500));
    assert!(bus.device().app().motor().velocity.abs() < 1.0);
    assert_ne!(bus.device().app().state(), State::OperationEnabled);
    controller(&mut bus.master()).acknowledge();
    bus.run(Duration::from_millis(500));
    assert_eq!(bus.device().app().state(), State::OperationEnabled);
}

/// The runner polls the master at its deadline, not at the next millisecond: the quick stop
/// is on the wire one frame after the consumer time has passed (the master received the last
/// heartbeat at its end of frame, and the quick stop takes its own frame time).
#[test]
fn with_the_runner_waking_at_the_deadline_detection_is_exact() {
    let mut bus = running_drive(500);
    bus.silence(1, true);
    let cut_at = bus.now();
    let last_heartbeat = bus
        .log
        .iter()
        .rev()
        .find(|(_, from, f)| *from == 1 && f.id().map(|id| id.as_raw()) == Some(0x702))
        .unwrap()
        .0;
    bus.run(Duration::from_millis(400));
    let quick_stop = bus
        .log
        .iter()
        .find(|(t, from, f)| {
            *t >= cut_at
                && *from == 0
                && f.id().map(|id| id.as_raw()) == Some(0x202)
                && f.data()[..2] == [0x02, 0x00]
        })
        .map(|(t, _, _)| *t)
        .expect("a quick stop controlword");
    let deadline = last_heartbeat.saturating_add(CONSUMER_TIME);
    let late = quick_stop.saturating_since(deadline);
    assert!(quick_stop >= deadline, "{quick_stop:?} before {deadline:?}");
    // One 1 Mbit/s frame is about 0.1 ms (a frame already on the wire may delay it by one).
    assert!(
        late <= Duration::from_micros(250),
        "{late:?} after the deadline"
    );
}

#[test]
fn a_silent_master_faults_the_drive_and_it_stops() {
    let mut bus = running_drive(2_000);
    bus.silence(0, true);
    bus.run(Duration::from_millis(600));
    assert_eq!(
        bus.device().app().state(),
        State::Fault,
        "abort connection option 1: fault"
    );
    assert!(bus.device().app().motor().velocity.abs() < 1.0);
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

/// A drive whose controller restarted after bus-off says so (EMCY 0x8140, then the error
/// reset), and the master keeps it running: the heartbeat consumer watches the link itself.
#[test]
fn recovery_from_bus_off_is_reported_and_does_not_stop_the_drive() {
    let mut bus = running_drive(1_000);
    let restarted = bywire_core::frame::ErrorFrame::from_array(
        bywire_core::frame::ErrorClass::Restarted.bit(),
        [0; 8],
    );
    bus.device_mut()
        .on_frame(Timestamp::ZERO, Port::MAIN, &Frame::Error(restarted));
    bus.run(Duration::from_millis(300));
    let emcys: Vec<[u8; 2]> = bus
        .log
        .iter()
        .filter(|(_, from, f)| *from == 1 && f.id().map(|id| id.as_raw()) == Some(0x82))
        .map(|(_, _, f)| [f.data()[0], f.data()[1]])
        .collect();
    assert_eq!(emcys, vec![[0x40, 0x81], [0, 0]]);
    assert_eq!(controller(&mut bus.master()).stopped(), None);
    assert_eq!(bus.device().app().state(), State::OperationEnabled);
}

#[test]
fn an_emergency_stops_the_drive_until_acknowledged() {
    let mut bus = running_drive(1_000);
    bus.device_mut().app_mut().0.inject_fault(0x2310);
    bus.run(Duration::from_millis(300));
    assert_eq!(
        controller(&mut bus.master()).stopped(),
        Some(StopReason::Emergency(0x2310))
    );
    assert_eq!(bus.device().app().state(), State::Fault);
    assert!(bus.device().app().motor().velocity.abs() < 1.0);
    // Acknowledged while the cause remains: the fault reset does nothing; the controller
    // gives it the status timeout (500 ms) before it stops the drive again.
    controller(&mut bus.master()).acknowledge();
    bus.run(Duration::from_millis(300));
    assert_eq!(bus.device().app().state(), State::Fault);
    assert_eq!(controller(&mut bus.master()).stopped(), None);
    bus.run(Duration::from_millis(300));
    assert_eq!(
        controller(&mut bus.master()).stopped(),
        Some(StopReason::Fault)
    );
    // The cause gone and acknowledged again: back to Operation enabled, running.
    bus.device_mut().app_mut().0.clear_fault();
    controller(&mut bus.master()).acknowledge();
    bus.run(Duration::from_millis(1_000));
    assert_eq!(bus.device().app().state(), State::OperationEnabled);
    assert!((bus.device().app().motor().velocity - 1_000.0).abs() < 1.0);
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
    let drive = Device::new(DRIVE, cia402::drive_dictionary(DRIVE), Drive::new());
    let mut bus = Bus::new(DRIVE, master, drive);
    bus.run(Duration::from_millis(10));
    bus.master().nmt(NmtCommand::Start, DRIVE);
    bus.run(Duration::from_millis(5_000));
    assert!(
        (bus.device().app().motor().position - 5_000.0).abs() <= 10.0,
        "{:?}",
        bus.device().app().motor()
    );
    let statusword = bus.device().od().get_unsigned(0x6041, 0).unwrap();
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
    let controller =
        Device::new(NODE, roboteq::dictionary(NODE, 2), Mdc1460::default()).with_autostart();
    roboteq::remap_rpdo1_to_velocity(master.sdo(), NODE, 1).unwrap();
    let mut bus = Bus::new(NODE, master, controller);
    bus.run(Duration::from_millis(100));
    let outcomes: Vec<_> = std::iter::from_fn(|| bus.master().take_sdo_outcome()).collect();
    assert_eq!(outcomes.len(), 5);
    assert!(outcomes.iter().all(|o| o.result.is_ok()), "{outcomes:?}");
    match bus.master().controlled(NODE) {
        Some(Controlled::Roboteq(motor)) => motor.set(RoboteqCommand::Velocity(1200)),
        _ => panic!(),
    }
    bus.run(Duration::from_millis(1_500));
    assert!(
        (bus.device().app().speed(1) - 1200.0).abs() < 2.0,
        "{}",
        bus.device().app().speed(1)
    );
    assert!(bus.log.iter().any(|(_, from, f)| *from == 0
        && f.id().map(|id| id.as_raw()) == Some(0x201)
        && f.data() == [0xB0, 0x04, 0x00, 0x00]));
    // The controller stops reporting: the master zeroes the command.
    bus.silence(1, true);
    bus.run(Duration::from_millis(1_500));
    let last = bus
        .log
        .iter()
        .rev()
        .find(|(_, from, f)| *from == 0 && f.id().map(|id| id.as_raw()) == Some(0x201))
        .unwrap();
    assert_eq!(last.2.data(), [0, 0, 0, 0]);
    assert!(bus.device().app().speed(1).abs() < 1.0);
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
        let drive = Device::new(DRIVE, cia402::drive_dictionary(DRIVE), Drive::new());
        let mut bus = Bus::new(DRIVE, master, drive);
        bus.run(Duration::from_millis(10));
        bus.master().nmt(NmtCommand::Start, DRIVE);
        bus.run(Duration::from_millis(300));
        assert_eq!(
            bus.device().app().state(),
            State::OperationEnabled,
            "{mode:?}"
        );
        // A ramp streamed every cycle: 0 → 1000 units in one second.
        for step in 0..=200 {
            let value = step * 5;
            let setpoint = if mode == Mode::CyclicSynchronousVelocity {
                Setpoint::Velocity(value)
            } else {
                Setpoint::Position(value)
            };
            controller(&mut bus.master()).set_setpoint(setpoint);
            bus.run(Duration::from_millis(5));
        }
        bus.run(Duration::from_millis(200));
        let motor = bus.device().app().motor();
        match mode {
            Mode::CyclicSynchronousVelocity => {
                assert!((motor.velocity - 1_000.0).abs() < 1.0, "{motor:?}")
            }
            _ => assert!((motor.position - 1_000.0).abs() <= 10.0, "{motor:?}"),
        }
        assert_eq!(
            bus.device().od().get_signed(0x6061, 0),
            Some(i64::from(mode.code())),
            "modes display"
        );
    }
}
