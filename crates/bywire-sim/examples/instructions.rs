//! The simulator's instruction count, the figure that must not rise: the tug powered on and
//! run for N simulated seconds (20 by default), its final pose printed. Counted, not timed:
//!
//! ```text
//! cargo build --profile dist -p bywire-sim --example instructions
//! valgrind --tool=callgrind target/dist/examples/instructions 20
//! ```
//!
//! Two builds compared this way differ only by what changed (a timed benchmark varies by a
//! few per cent from run to run on a loaded machine).

use bywire_sim::tug::{Tug, TugParams};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let seconds: u32 = match std::env::args().nth(1) {
        Some(text) => text.parse()?,
        None => 20,
    };
    let mut tug = Tug::new(TugParams::default())?;
    for _ in 0..seconds.saturating_mul(1_000) {
        tug.step();
    }
    println!("{:?}", tug.pose());
    Ok(())
}
