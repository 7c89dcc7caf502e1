//! `bywire send`: cansend, plus encoding a DBC message by name.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{anyhow, Context, Result};
use bywire_core::Frame;

use crate::support::busarg;
use crate::support::signals::Dbc;
use bywire_dbc::codec::EncodeMode;

#[derive(clap::Args)]
#[command(after_help = "Examples:
  bywire send can0 123#DEADBEEF          (standard ID, 4 bytes)
  bywire send can0 1ABCDEF0#1122         (extended ID: 8 digits)
  bywire send can0 123#R4                (remote frame, DLC 4)
  bywire send can0 123##1112233          (CAN FD, flags 1 = BRS)
  bywire send virtual:test 7FF#DE.AD.BE.EF
  bywire send can0 --dbc vehicle.dbc AdsToVehicle_Control SteeringAngle=12.5 Gear=Drive

With --dbc the message is encoded by name (or hex ID): signals not given take their start
value or 0, value names from the DBC are accepted, values out of range are refused, and the
rolling counter and checksum are filled in (--counter sets the counter).")]
pub struct Args {
    /// The bus (a plain interface name means SocketCAN).
    bus: String,
    /// A frame in cansend syntax, or with --dbc: MESSAGE [SIGNAL=VALUE]...
    #[arg(required = true, num_args = 1..)]
    frame: Vec<String>,
    /// Encode MESSAGE with this DBC file.
    #[arg(long, value_name = "FILE")]
    dbc: Option<PathBuf>,
    /// The rolling counter value for --dbc.
    #[arg(long, default_value_t = 0)]
    counter: u64,
    /// Print the frame sent, in cansend syntax.
    #[arg(short = 'v', long)]
    verbose: bool,
}

/// The frame the arguments describe.
fn frame_of(args: &Args) -> Result<Frame> {
    match &args.dbc {
        Some(path) => {
            let dbc = Dbc::new(crate::support::dbc::load(path, false)?);
            let (name, assignments) = args
                .frame
                .split_first()
                .ok_or_else(|| anyhow!("--dbc needs a message name"))?;
            let message = dbc.find(name)?;
            dbc.encode(message, assignments, args.counter, EncodeMode::Strict)
        }
        None => {
            let [text] = args.frame.as_slice() else {
                return Err(anyhow!(
                    "expected one frame such as 123#DEADBEEF, got {} arguments (use --dbc to encode signals)",
                    args.frame.len()
                ));
            };
            text.parse::<Frame>()
                .map_err(|e| anyhow!("frame '{text}': {e}"))
        }
    }
}

pub fn run(args: &Args, out: &mut impl Write) -> Result<()> {
    let frame = frame_of(args)?;
    let mut bus =
        busarg::open_to_send(&args.bus, "send").with_context(|| format!("bus '{}'", args.bus))?;
    bus.send(&frame)
        .with_context(|| format!("bus '{}': cannot send {frame}", args.bus))?;
    if args.verbose {
        writeln!(out, "{frame}")?;
    }
    Ok(())
}
