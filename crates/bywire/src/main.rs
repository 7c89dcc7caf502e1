//! `bywire`: the command line. Each subcommand parses its arguments, calls the library and
//! prints; the work is in the library crates.

mod bittiming_cmd;
mod bridge_cmd;
mod dbc_cmd;
mod wire_cmd;

use std::io::{self, Write};
use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// A drive-by-wire CAN stack: wire model, bit timing and CAN tools.
#[derive(Parser)]
#[command(name = "bywire", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Show a frame's exact bit sequence on the bus: stuffing, CRC, length and time.
    Wire(wire_cmd::Args),
    /// Compute bit-timing registers for a bitrate and sample point on a controller.
    Bittiming(bittiming_cmd::Args),
    /// Work with DBC files: dump.
    Dbc {
        #[command(subcommand)]
        command: dbc_cmd::DbcCommand,
    },
    /// Decode candump lines from standard input with a DBC file, like `cantools decode`.
    Decode(dbc_cmd::DecodeArgs),
    /// Run the ADS side of a vehicle interface on a bus: JSON commands in, vehicle state out.
    Bridge(bridge_cmd::Args),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let mut out = io::stdout().lock();
    let result = match cli.command {
        Command::Wire(args) => wire_cmd::run(&args, &mut out),
        Command::Bittiming(args) => bittiming_cmd::run(&args, &mut out),
        Command::Dbc { command } => dbc_cmd::run(&command, &mut out),
        Command::Decode(args) => dbc_cmd::decode(&args, &mut io::stdin().lock(), &mut out),
        Command::Bridge(args) => bridge_cmd::run(&args, &mut out),
    };
    let flushed = result.and_then(|()| out.flush().map_err(anyhow::Error::from));
    match flushed {
        Ok(()) => ExitCode::SUCCESS,
        // A closed pipe (`bywire ... | head`) is the reader's choice, not a failure.
        Err(e) if is_broken_pipe(&e) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.downcast_ref::<io::Error>()
        .is_some_and(|io| io.kind() == io::ErrorKind::BrokenPipe)
}
