//! The ADS side of the reference tug on a SocketCAN interface (or any bus spec), on the
//! real-time runner: it asks to engage until the vehicle follows, drives at 1 m/s, and prints
//! the vehicle's state — or why it is not following — every second, for ten seconds.
//!
//!     bywire vehicle --profile reference-tug vcan0 &     # a vehicle to talk to
//!     cargo run -p bywire-examples --example ads_socketcan -- vcan0

use std::sync::atomic::AtomicBool;
use std::time::Duration;

use bywire_bus::runner::{Flow, Runner};
use bywire_core::node::Port;
use bywire_core::Timestamp;
use bywire_tug::wire::ReferenceWire;
use bywire_vehicle::ads::{Ads, AdsCommand, AdsConfig};
use bywire_vehicle::command::{ControlMode, Gear};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let spec = std::env::args().nth(1).unwrap_or_else(|| "vcan0".into());
    let spec = if spec.contains(':') {
        spec
    } else {
        format!("socketcan:{spec}")
    };
    let bus = bywire_bus::open(&spec)?;
    let mut runner = Runner::new(vec![(Port::MAIN, bus)]);
    let mut ads = Ads::with_wire(AdsConfig::default(), ReferenceWire);
    let mut next_print = Timestamp::ZERO;
    let mut after_poll = |ads: &mut Ads<ReferenceWire>, now: Timestamp| {
        // Engage is an edge: asked for now and then until the vehicle follows.
        let engage = ads.blocker(now).is_some() && now.as_nanos() % 500_000_000 < 20_000_000;
        ads.set_command(
            now,
            AdsCommand {
                velocity: 1.0,
                gear: Gear::Drive,
                mode: ControlMode::Autonomous,
                engage,
                ..AdsCommand::default()
            },
        );
        if now >= next_print {
            next_print = next_print.saturating_add(Duration::from_secs(1));
            match ads.blocker(now) {
                Some(why) => println!("{:.1} s: not following: {why}", now.as_nanos() as f64 / 1e9),
                None => println!(
                    "{:.1} s: following at {:.2} m/s",
                    now.as_nanos() as f64 / 1e9,
                    ads.state().velocity.value.unwrap_or(0.0)
                ),
            }
        }
        Flow::Continue
    };
    let stop = AtomicBool::new(false);
    runner.run(
        &mut ads,
        &stop,
        Some(Duration::from_secs(10)),
        &mut after_poll,
    )?;
    Ok(())
}
