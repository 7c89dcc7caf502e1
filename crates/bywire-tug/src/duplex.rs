//! The redundant tug's two vehicle control ECUs as halves of one
//! ([`bywire_vehicle::arbitration::Duplex`]): their status messages on bus 1, and the
//! comparison the standby makes of the setpoints the ECU in control gives the drives on bus 2.
//! Both run [`crate::ecu::VehicleControlEcu`] in step on the same inputs, so the setpoints
//! agree to the count; they disagree when one ECU computes wrongly (a corrupted trim, a fault
//! in its memory), which the standby finds within the profile's disagreement time.

use core::time::Duration;

use bywire_canopen::cia402::rpdo2_targets;
use bywire_core::node::Port;
use bywire_core::{Frame, Id};
use bywire_vehicle::arbitration::{Degrades, DuplexWire, Role, Side};
use bywire_vehicle::degradation::Fault;

use crate::drives::{DRIVE_NODES, DRIVE_UNITS_PER_M, STEERING_NODES, STEERING_UNITS_PER_DEG};
use crate::ecu::{VehicleControlEcu, BUS1, BUS2};
use crate::messages::{self, VcuAStatus, VcuBStatus};

/// How often each ECU sends its status.
pub const STATUS_PERIOD: Duration = Duration::from_millis(10);

/// The two ECUs' wire for their arbitration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TugDuplexWire {
    /// Steering setpoints further apart than this disagree, degrees.
    pub steering_tolerance_deg: f64,
    /// Wheel-speed setpoints further apart than this disagree, m/s.
    pub speed_tolerance: f64,
}

impl Default for TugDuplexWire {
    /// The profile's output tolerance (1°), and 0.1 m/s.
    fn default() -> Self {
        TugDuplexWire {
            steering_tolerance_deg: 1.0,
            speed_tolerance: 0.1,
        }
    }
}

/// `side`'s status message.
fn status_id(side: Side) -> u32 {
    match side {
        Side::A => VcuAStatus::ID,
        Side::B => VcuBStatus::ID,
    }
}

impl DuplexWire for TugDuplexWire {
    fn status_port(&self) -> Port {
        BUS1
    }

    fn status_period(&self) -> Duration {
        STATUS_PERIOD
    }

    fn status_frame(&mut self, side: Side, role: Role, counter: u8) -> Option<Frame> {
        // Both ECUs' status messages have one layout: the role in bits 0–2, the counter in
        // bits 48–51.
        let mut m = VcuAStatus::default();
        m.set_role_raw(u64::from(role.raw()));
        m.set_counter_raw(u64::from(counter & 0x0F));
        Some(messages::sealed_frame(status_id(side), m.0))
    }

    fn partner_status(&mut self, side: Side, frame: &Frame) -> Option<Role> {
        let id = status_id(side.other());
        if frame.id() != Id::standard(id).ok() {
            return None;
        }
        let payload = messages::payload(frame).filter(|p| messages::is_sealed(id, p))?;
        Some(Role::from_raw(VcuAStatus(payload).role_raw()))
    }

    fn agree(&self, port: Port, mine: &Frame, theirs: &Frame) -> Option<bool> {
        if port != BUS2 {
            return None;
        }
        let (node, position, velocity) = rpdo2_targets(theirs)?;
        let (_, my_position, my_velocity) = rpdo2_targets(mine)?;
        if STEERING_NODES.contains(&node) {
            let apart = position.abs_diff(my_position);
            Some(f64::from(apart) <= self.steering_tolerance_deg * STEERING_UNITS_PER_DEG)
        } else if DRIVE_NODES.contains(&node) {
            let apart = velocity.abs_diff(my_velocity);
            Some(f64::from(apart) <= self.speed_tolerance * DRIVE_UNITS_PER_M)
        } else {
            None
        }
    }
}

/// The ECU's supervisor keeps the degradation latch.
impl Degrades for VehicleControlEcu {
    fn report_fault(&mut self, fault: Fault) {
        self.report_fault(fault);
    }
}
