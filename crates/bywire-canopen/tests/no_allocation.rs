//! After start the control path allocates nothing: a master commanding a CiA 402 drive and a
//! Roboteq controller, the devices answering with heartbeats, TPDOs and EMCY, through a
//! heartbeat loss and a fault, all under `allocation-counter`'s counting allocator.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::time::Duration;

use bywire_canopen::cia402::{drive_dictionary, Drive, DriveController, Mode, Setpoint};
use bywire_canopen::device::Device;
use bywire_canopen::master::{Controlled, Master};
use bywire_canopen::nmt::NmtCommand;
use bywire_canopen::roboteq::{dictionary, Mdc1460, RoboteqCommand, RoboteqMotor};
use bywire_canopen::{Node, Port};
use bywire_core::frame::Frame;
use bywire_core::time::Timestamp;

/// One millisecond of the bus: every node polled, frames passed to the others, with buffers
/// sized before counting starts. The one loop of its kind left outside the two runners, on
/// purpose: the count covers everything the closure does, and the network runner's bit-timed
/// buses grow their queues to their working size during a run (a few amortised allocations in
/// its first second and at the first fault), which would hide the nodes' own count.
fn step(
    now: Timestamp,
    nodes: &mut [&mut dyn Node],
    pending: &mut Vec<(usize, Frame)>,
    round: &mut Vec<(usize, Frame)>,
    silent: Option<usize>,
) {
    for (i, node) in nodes.iter_mut().enumerate() {
        node.poll(now, &mut |_, frame| pending.push((i, frame)));
    }
    for _ in 0..8 {
        if pending.is_empty() {
            break;
        }
        round.clear();
        round.append(pending);
        for (from, frame) in round.iter() {
            if Some(*from) == silent {
                continue;
            }
            for (i, node) in nodes.iter_mut().enumerate() {
                if i != *from {
                    node.on_frame(now, Port::MAIN, frame);
                }
            }
        }
        for (i, node) in nodes.iter_mut().enumerate() {
            node.poll(now, &mut |_, frame| pending.push((i, frame)));
        }
    }
}

#[test]
fn the_master_and_devices_never_allocate_after_start() {
    let mut master = Master::new(127, Duration::from_millis(100), Duration::from_millis(10))
        .with_sync(Duration::from_millis(20));
    let mut controller = DriveController::new(2, Mode::ProfileVelocity, Duration::from_millis(300));
    controller.set_enabled(true);
    controller.set_setpoint(Setpoint::Velocity(1_500));
    master.add(Controlled::Drive(controller));
    let mut motor = RoboteqMotor::new(1, RoboteqCommand::Power(0));
    motor.set(RoboteqCommand::Power(-400));
    master.add(Controlled::Roboteq(motor));
    master.monitor(2, Duration::from_millis(250));
    master.monitor(1, Duration::from_millis(250));
    let mut drive = Device::new(2, drive_dictionary(2), Drive::new());
    let mut roboteq = Device::new(1, dictionary(1, 2), Mdc1460::default()).with_autostart();
    master.nmt(NmtCommand::Start, 2);
    let mut pending = Vec::with_capacity(1024);
    let mut round = Vec::with_capacity(1024);
    // Boot and first polls outside the count (start).
    for ms in 0..5 {
        step(
            Timestamp::from_millis(ms),
            &mut [&mut master, &mut drive, &mut roboteq],
            &mut pending,
            &mut round,
            None,
        );
    }
    let counted = allocation_counter::measure(|| {
        for ms in 5..3_000 {
            if ms == 1_500 {
                drive.app_mut().0.inject_fault(0x2310);
            }
            // The Roboteq goes silent for the last second.
            let silent = (ms >= 2_000).then_some(2);
            step(
                Timestamp::from_millis(ms),
                &mut [&mut master, &mut drive, &mut roboteq],
                &mut pending,
                &mut round,
                silent,
            );
        }
    });
    assert_eq!(
        drive.app().state(),
        bywire_canopen::cia402::State::Fault,
        "the run went through a fault"
    );
    assert!(
        matches!(master.controlled(1), Some(Controlled::Roboteq(m)) if m.stopped().is_some()),
        "and a heartbeat loss"
    );
    assert_eq!(counted.count_total, 0, "allocations on the control path");
}
