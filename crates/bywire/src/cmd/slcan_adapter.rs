//! `bywire slcan-adapter`: an emulated SLCAN adapter for a bus on a pseudo terminal, so SLCAN
//! tools (python-can's `slcan`, SavvyCAN, slcand) can be tried without hardware.

use std::io::Write;
use std::sync::atomic::Ordering;

use anyhow::{Context, Result};

use crate::support::busarg;
use crate::support::interrupt::interrupt_flag;

#[derive(clap::Args)]
#[command(after_help = "Examples:
  bywire slcan-adapter virtual:test
      (prints the terminal, e.g. /dev/pts/5; then in another program:)
  python3 -c \"import can; b = can.Bus(interface='slcan', channel='/dev/pts/5', bitrate=500000)\"

The adapter answers C, O, L, Sn, V, N, F, Z0/Z1, acknowledges transmissions with z/Z, refuses
anything else with BEL, and sends the bus's frames while open. Runs until Ctrl-C.")]
pub struct Args {
    /// The bus behind the adapter (a plain interface name means SocketCAN).
    bus: String,
}

pub fn run(args: &Args, out: &mut impl Write) -> Result<()> {
    let bus = busarg::open(&args.bus).with_context(|| format!("bus '{}'", args.bus))?;
    let stop = interrupt_flag();
    let (path, handle) = bywire_bus::slcan::emulate(bus, std::sync::Arc::clone(&stop))?;
    writeln!(out, "{path}")?;
    out.flush()?;
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    let _ = handle.join();
    Ok(())
}
