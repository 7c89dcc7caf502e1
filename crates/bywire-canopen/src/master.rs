//! The NMT master as a sans-IO node: NMT commands, its own heartbeat, heartbeat monitoring of
//! every node with per-node consumer times, the SDO client, SYNC production, EMCY
//! consumption, and the drives it controls — each stopped safely when its heartbeat is lost,
//! it sends an emergency, or it reports a fault.

use alloc::vec::Vec;
use core::time::Duration;

use bywire_core::frame::Frame;
use bywire_core::node::{Node, Port};
use bywire_core::time::{earliest, Timestamp};

use crate::cia402::{DriveController, StopReason};
use crate::device::Emergency;
use crate::nmt::{
    classic, heartbeat_frame, HeartbeatConsumer, HeartbeatEvent, NmtCommand, NmtState,
};
use crate::queue::EventQueue;
use crate::roboteq::RoboteqMotor;
use crate::sdo::{SdoClient, SdoOutcome};

/// What the master saw.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MasterEvent {
    /// A heartbeat event.
    Heartbeat(HeartbeatEvent),
    /// An emergency from `node`.
    Emergency {
        /// The node.
        node: u8,
        /// The message.
        emergency: Emergency,
    },
}

/// Something the master commands cyclically.
#[derive(Debug, Clone)]
pub enum Controlled {
    /// A CiA 402 drive.
    Drive(DriveController),
    /// A Roboteq controller.
    Roboteq(RoboteqMotor),
}

impl Controlled {
    fn node(&self) -> u8 {
        match self {
            Controlled::Drive(drive) => drive.node(),
            Controlled::Roboteq(motor) => motor.node(),
        }
    }

    fn on_frame(&mut self, now: Timestamp, frame: &Frame) {
        match self {
            Controlled::Drive(drive) => drive.on_frame(now, frame),
            Controlled::Roboteq(motor) => motor.on_frame(now, frame),
        }
    }

    fn stop(&mut self, reason: StopReason) {
        match self {
            Controlled::Drive(drive) => drive.stop(reason),
            Controlled::Roboteq(motor) => motor.stop(reason),
        }
    }

    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Frame)) {
        match self {
            Controlled::Drive(drive) => drive.poll(now, out),
            Controlled::Roboteq(motor) => motor.poll(now, out),
        }
    }
}

/// No controlled device at a node (see `Master::position_of`).
const NOT_CONTROLLED: u16 = u16::MAX;

/// The NMT master.
#[derive(Debug, Clone)]
pub struct Master {
    node: u8,
    heartbeat_period: Duration,
    next_heartbeat: Option<Timestamp>,
    sync_period: Duration,
    next_sync: Option<Timestamp>,
    cycle: Duration,
    next_cycle: Option<Timestamp>,
    consumer: HeartbeatConsumer,
    sdo: SdoClient,
    controlled: Vec<Controlled>,
    /// Where each node's first controlled device is in `controlled` ([`NOT_CONTROLLED`]:
    /// none): the ECU looks its drives up several times a poll.
    position_of: [u16; 256],
    outbox: EventQueue<Frame, 64>,
    events: EventQueue<MasterEvent, 64>,
}

impl Master {
    /// A master at `node` sending its heartbeat every `heartbeat_period` (zero: none) and
    /// commanding its drives every `cycle`.
    pub fn new(node: u8, heartbeat_period: Duration, cycle: Duration) -> Master {
        Master {
            node,
            heartbeat_period,
            next_heartbeat: None,
            sync_period: Duration::ZERO,
            next_sync: None,
            cycle,
            next_cycle: None,
            consumer: HeartbeatConsumer::default(),
            sdo: SdoClient::new(16, Duration::from_millis(500)),
            controlled: Vec::new(),
            position_of: [NOT_CONTROLLED; 256],
            outbox: EventQueue::new(),
            events: EventQueue::new(),
        }
    }

    /// Produce SYNC every `period` (zero: none).
    pub fn with_sync(mut self, period: Duration) -> Master {
        self.sync_period = period;
        self
    }

    /// Give servers `timeout` to answer SDO requests (500 ms by default).
    pub fn with_sdo_timeout(mut self, timeout: Duration) -> Master {
        self.sdo = SdoClient::new(16, timeout);
        self
    }

    /// Its node ID.
    pub fn node(&self) -> u8 {
        self.node
    }

    /// Watch `node`'s heartbeat with `timeout`.
    pub fn monitor(&mut self, node: u8, timeout: Duration) -> bool {
        self.consumer.watch(node, timeout)
    }

    /// What is known of `node`.
    pub fn liveness(&self, node: u8) -> Option<crate::nmt::Liveness> {
        self.consumer.liveness(node)
    }

    /// Control a drive or motor (at start: the table is fixed after).
    pub fn add(&mut self, controlled: Controlled) {
        let position = u16::try_from(self.controlled.len()).unwrap_or(NOT_CONTROLLED);
        if let Some(slot) = self.position_of.get_mut(usize::from(controlled.node())) {
            if *slot == NOT_CONTROLLED {
                *slot = position;
            }
        }
        self.controlled.push(controlled);
    }

    /// The controlled device at `node` (the first added, if several).
    pub fn controlled(&mut self, node: u8) -> Option<&mut Controlled> {
        match self.position_of.get(usize::from(node)) {
            Some(&position) if position != NOT_CONTROLLED => {
                self.controlled.get_mut(usize::from(position))
            }
            // Not indexed: none at that node, or past the index's reach (65,535 devices).
            _ => self.controlled.iter_mut().find(|c| c.node() == node),
        }
    }

    /// Send an NMT command to `node` (0: all).
    pub fn nmt(&mut self, command: NmtCommand, node: u8) {
        let _ = self.outbox.push(command.frame(node));
    }

    /// The SDO client.
    pub fn sdo(&mut self) -> &mut SdoClient {
        &mut self.sdo
    }

    /// The next finished SDO transfer.
    pub fn take_sdo_outcome(&mut self) -> Option<SdoOutcome> {
        self.sdo.take_outcome()
    }

    /// The next event.
    pub fn next_event(&mut self) -> Option<MasterEvent> {
        self.events.pop()
    }

    /// Take in a frame.
    fn receive(&mut self, now: Timestamp, frame: &Frame) {
        self.consumer.on_frame(now, frame);
        self.sdo.on_frame(now, frame);
        if let Some((node, emergency)) = Emergency::parse(frame) {
            let _ = self.events.push(MasterEvent::Emergency { node, emergency });
        }
        for controlled in &mut self.controlled {
            controlled.on_frame(now, frame);
        }
    }

    /// Heartbeat monitoring first (so a loss stops its drive in this very poll), then the
    /// heartbeat, SYNC, drive commands and SDO.
    fn step(&mut self, now: Timestamp, out: &mut dyn FnMut(Frame)) {
        self.consumer.poll(now);
        let mut stop_now = false;
        while let Some(event) = self.consumer.next_event() {
            if let HeartbeatEvent::Lost { node } = event {
                if let Some(controlled) = self.controlled(node) {
                    controlled.stop(StopReason::HeartbeatLost);
                    stop_now = true;
                }
            }
            let _ = self.events.push(MasterEvent::Heartbeat(event));
        }
        while let Some(frame) = self.outbox.pop() {
            out(frame);
        }
        if !self.heartbeat_period.is_zero() && self.next_heartbeat.is_none_or(|due| now >= due) {
            out(heartbeat_frame(self.node, NmtState::Operational));
            self.next_heartbeat = Some(now.saturating_add(self.heartbeat_period));
        }
        if !self.sync_period.is_zero() && self.next_sync.is_none_or(|due| now >= due) {
            out(classic(0x80, &[]));
            self.next_sync = Some(now.saturating_add(self.sync_period));
        }
        // A stop is sent at once, not at the next cycle.
        if stop_now || self.next_cycle.is_none_or(|due| now >= due) {
            for controlled in &mut self.controlled {
                controlled.poll(now, out);
            }
            self.next_cycle = Some(now.saturating_add(self.cycle));
        }
        self.sdo.poll(now, out);
    }

    /// When [`Master::step`] next has work.
    fn deadline(&self) -> Option<Timestamp> {
        if !self.outbox.is_empty() {
            return Some(Timestamp::ZERO);
        }
        let heartbeat = (!self.heartbeat_period.is_zero())
            .then(|| self.next_heartbeat.unwrap_or(Timestamp::ZERO));
        let sync = (!self.sync_period.is_zero()).then(|| self.next_sync.unwrap_or(Timestamp::ZERO));
        let cycle =
            (!self.controlled.is_empty()).then(|| self.next_cycle.unwrap_or(Timestamp::ZERO));
        earliest([
            heartbeat,
            sync,
            cycle,
            self.consumer.next_deadline(),
            self.sdo.next_deadline(),
        ])
    }
}

/// The master has one bus connection: frames from any port go in, its frames go out on the
/// main port.
impl Node for Master {
    fn on_frame(&mut self, now: Timestamp, _port: Port, frame: &Frame) {
        self.receive(now, frame);
    }
    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        self.step(now, &mut |frame| out(Port::MAIN, frame));
    }
    fn next_deadline(&self) -> Option<Timestamp> {
        self.deadline()
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use crate::cia402::Mode;
    use crate::roboteq::RoboteqCommand;

    #[test]
    fn a_device_is_found_by_its_node_the_first_of_a_node_and_none_for_others() {
        let mut master = Master::new(0x7F, Duration::ZERO, Duration::from_millis(10));
        let timeout = Duration::from_millis(100);
        master.add(Controlled::Drive(DriveController::new(
            3,
            Mode::ProfileVelocity,
            timeout,
        )));
        master.add(Controlled::Roboteq(RoboteqMotor::new(
            9,
            RoboteqCommand::Velocity(0),
        )));
        master.add(Controlled::Drive(DriveController::new(
            9,
            Mode::ProfileVelocity,
            timeout,
        )));
        assert!(matches!(master.controlled(3), Some(Controlled::Drive(d)) if d.node() == 3));
        // Two at node 9: the first added.
        assert!(matches!(master.controlled(9), Some(Controlled::Roboteq(m)) if m.node() == 9));
        for absent in [0, 4, 127, 255] {
            assert!(master.controlled(absent).is_none(), "{absent}");
        }
    }
}
