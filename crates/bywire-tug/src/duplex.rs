//! The redundant tug's two vehicle control ECUs as halves of one
//! ([`bywire_vehicle::arbitration::Duplex`]): their status messages on bus 1, and the
//! comparison the standby makes of the setpoints the ECU in control gives the drives on bus 2.
//! Both run [`crate::ecu::VehicleControlEcu`] in step on the same inputs, so the setpoints
//! agree to the count; they disagree when one ECU computes wrongly (a corrupted trim, a fault
//! in its memory), which the standby finds within the profile's disagreement time.

use core::time::Duration;

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

/// RPDO2 (target position, target velocity) of CANopen node `node`.
fn rpdo2(node: u8) -> u32 {
    0x300 + u32::from(node)
}

/// A little-endian i32 at `at` in `data`.
fn i32_at(data: &[u8], at: usize) -> Option<i32> {
    let bytes: [u8; 4] = data.get(at..at + 4)?.try_into().ok()?;
    Some(i32::from_le_bytes(bytes))
}

impl DuplexWire for TugDuplexWire {
    fn status_port(&self) -> Port {
        BUS1
    }

    fn status_period(&self) -> Duration {
        STATUS_PERIOD
    }

    fn status_frame(&mut self, side: Side, role: Role, counter: u8) -> Option<Frame> {
        let (id, mut payload) = match side {
            Side::A => (VcuAStatus::ID, VcuAStatus::default().0),
            Side::B => (VcuBStatus::ID, VcuBStatus::default().0),
        };
        // Both have the role in bits 0–2 and the counter in bits 48–51.
        let mut m = VcuAStatus(payload);
        m.set_role_raw(u64::from(role.raw()));
        m.set_counter_raw(u64::from(counter & 0x0F));
        payload = m.0;
        Some(messages::sealed_frame(id, payload))
    }

    fn partner_status(&mut self, side: Side, frame: &Frame) -> Option<Role> {
        let id = match side {
            Side::A => VcuBStatus::ID,
            Side::B => VcuAStatus::ID,
        };
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
        let id = theirs.id().filter(|id| !id.is_extended())?.as_raw();
        let (ours, other) = (mine.data(), theirs.data());
        if STEERING_NODES.iter().any(|&n| rpdo2(n) == id) {
            let apart = i32_at(ours, 0)?.abs_diff(i32_at(other, 0)?);
            Some(f64::from(apart) <= self.steering_tolerance_deg * STEERING_UNITS_PER_DEG)
        } else if DRIVE_NODES.iter().any(|&n| rpdo2(n) == id) {
            let apart = i32_at(ours, 4)?.abs_diff(i32_at(other, 4)?);
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
