//! A CANopen master walking a CiA 402 drive to Operation enabled and running it at a
//! velocity, both on one simulated 1 Mbit/s bus (the simulated runner, in simulated time).
//! The same two nodes run on a real bus with `bywire_bus::runner`.
//!
//!     cargo run -p bywire-examples --example canopen_master

use std::time::Duration;

use bywire_canopen::cia402::{self, Drive, DriveController, Mode, Setpoint};
use bywire_canopen::device::Device;
use bywire_canopen::master::{Controlled, Master};
use bywire_canopen::nmt::NmtCommand;
use bywire_canopen::Port;
use bywire_net::network::Network;

fn main() {
    const DRIVE: u8 = 2;
    let mut master = Master::new(1, Duration::from_millis(100), Duration::from_millis(10));
    let mut controller =
        DriveController::new(DRIVE, Mode::ProfileVelocity, Duration::from_millis(500));
    controller.set_enabled(true);
    controller.set_setpoint(Setpoint::Velocity(1_000));
    master.add(Controlled::Drive(controller));
    master.monitor(DRIVE, Duration::from_millis(250));
    master.nmt(NmtCommand::Start, 0);
    let drive = Device::new(DRIVE, cia402::drive_dictionary(DRIVE), Drive::new());

    let mut net = Network::new();
    let bus = net.add_bus("drives", 1_000_000, None);
    let (master, drive) = (net.add_node(master), net.add_node(drive));
    let _ = net.wire(master, Port::MAIN, bus);
    let _ = net.wire(drive, Port::MAIN, bus);
    for _ in 0..4 {
        net.run_for(Duration::from_millis(500));
        let state = match net
            .node_mut(master)
            .as_mut()
            .and_then(|m| m.controlled(DRIVE))
        {
            Some(Controlled::Drive(d)) => format!("{:?}, actual {:?}", d.drive_state(), d.actual()),
            _ => "not controlled".into(),
        };
        let velocity = net.node(drive).map_or(0.0, |d| d.app().motor().velocity);
        println!(
            "{:.1} s: drive {state}; its motor at {:.0}",
            net.now().as_nanos() as f64 / 1e9,
            velocity
        );
    }
}
