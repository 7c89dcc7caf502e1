//! Frames the vehicle tests send: sealed with the reference tug's CRC.
#![allow(dead_code, clippy::unwrap_used)]

use bywire_core::{Frame, Id, Timestamp};
use bywire_tug::messages::{self, AdsToVehicleControl, ControlMode};

pub fn ms(t: u64) -> Timestamp {
    Timestamp::from_millis(t)
}

/// A classic frame with `payload` and its CRC in byte 7.
pub fn sealed(id: u32, mut payload: [u8; 8]) -> Frame {
    messages::seal(id, &mut payload);
    Frame::classic(Id::standard(id).unwrap(), &payload).unwrap()
}

/// An autonomous drive command with counter `counter`, changed by `edit`.
pub fn command(counter: u8, edit: impl FnOnce(&mut AdsToVehicleControl)) -> Frame {
    let mut m = AdsToVehicleControl::default();
    m.set_velocity_cmd(2.0).unwrap();
    m.set_gear_cmd_raw(3);
    m.set_control_mode_cmd_raw(ControlMode::Autonomous as u64);
    m.set_heartbeat_counter_raw(u64::from(counter & 0x0F));
    edit(&mut m);
    sealed(AdsToVehicleControl::ID, m.0)
}
