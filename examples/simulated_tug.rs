//! The simulated tug driving its apron loop: an ADS commanding over two redundant buses, the
//! vehicle control ECU with its safety logic, eight CANopen drives, sensors, hydraulics and
//! chassis — in simulated time, as fast as the host computes it.
//!
//!     cargo run --release -p bywire-examples --example simulated_tug

use bywire_sim::tug::{Tug, TugParams};

fn main() -> Result<(), bywire_sim::tug::TugError> {
    let mut tug = Tug::new(TugParams::default())?;
    // One step is a simulated millisecond; at most three minutes.
    for _ in 0..180_000 {
        tug.step();
        if tug.arrived() {
            break;
        }
    }
    let pose = tug.pose();
    println!(
        "after {:.1} s: at ({:.1}, {:.1}) m, {:.1} m to go, battery {:.1} %",
        tug.now().as_nanos() as f64 / 1e9,
        pose.x,
        pose.y,
        tug.remaining().unwrap_or(f64::NAN),
        tug.soc() * 100.0
    );
    for event in tug.events.iter().take(10) {
        println!(
            "  {:>7.3} s  {:<12} {}",
            event.t.as_nanos() as f64 / 1e9,
            event.kind(),
            event.what
        );
    }
    Ok(())
}
