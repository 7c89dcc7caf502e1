//! The tug's drives bus as both its ECU and its diagnostics see it: the CANopen node IDs and
//! the drives' units.

/// The ECU's node ID on the drives bus.
pub const MASTER_NODE: u8 = 1;
/// Steering drives FL, FR, RL, RR.
pub const STEERING_NODES: [u8; 4] = [0x11, 0x12, 0x13, 0x14];
/// Wheel drives FL, FR, RL, RR.
pub const DRIVE_NODES: [u8; 4] = [0x21, 0x22, 0x23, 0x24];
/// Steering drives count in 0.01°.
pub const STEERING_UNITS_PER_DEG: f64 = 100.0;
/// Wheel drives count in mm/s and mm.
pub const DRIVE_UNITS_PER_M: f64 = 1000.0;
/// The redundant tug's backup steering valve drivers FL, FR, RL, RR (counting wheel rates in
/// the steering drives' units).
pub const BACKUP_STEERING_NODES: [u8; 4] = [0x31, 0x32, 0x33, 0x34];

/// A drive under `master`'s control in `mode`, enabled, its statusword and heartbeat watched
/// (stopped after 500 ms and 250 ms without them).
pub fn add_drive(
    master: &mut bywire_canopen::master::Master,
    node: u8,
    mode: bywire_canopen::cia402::Mode,
) {
    let mut controller = bywire_canopen::cia402::DriveController::new(
        node,
        mode,
        core::time::Duration::from_millis(500),
    );
    controller.set_enabled(true);
    master.add(bywire_canopen::master::Controlled::Drive(controller));
    master.monitor(node, core::time::Duration::from_millis(250));
}
