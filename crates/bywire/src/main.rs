//! `bywire`: the command line. Each subcommand parses its arguments, calls the library and
//! prints; the work is in the library crates.
// Doc comments here are clap's help text (`[,DATA_BITRATE]`, `INDEX[:SUB]`), not rustdoc links.
#![allow(rustdoc::broken_intra_doc_links)]

mod bittiming_cmd;
mod bridge_cmd;
mod busarg;
mod busload_cmd;
mod canopen_cmd;
mod check_cmd;
mod dbc_cmd;
mod dump_cmd;
mod gen_cmd;
mod live;
mod log_cmd;
mod monitor_cmd;
mod numbers;
mod play_cmd;
mod plot_cmd;
mod send_cmd;
mod serve_cmd;
mod signals;
mod sim_cmd;
mod sim_plot;
mod sim_serve;
mod sim_view;
mod slcan_adapter_cmd;
mod sniff_cmd;
mod vehicle_cmd;
mod wire_cmd;

use std::io::{self, Write};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};

use clap::{Parser, Subcommand};

/// A drive-by-wire CAN stack: wire model, bit timing and CAN tools.
#[derive(Parser)]
#[command(
    name = "bywire",
    version,
    about,
    long_about = None,
    after_help = "Examples:
  bywire dump -ta can0                       (candump; any bus spec: virtual:x, sim:x@500000)
  bywire send can0 123#DEADBEEF              (cansend)
  bywire monitor vehicle.dbc can0            (decoded live table)
  candump -L can0 | bywire decode vehicle.dbc
  bywire wire 123#DEADBEEF --bitrate 500000  (the frame's bits on the wire)

Exit status: 0 on success (and when the reader of the output goes away), 1 on an error,
2 on a usage error. `bywire COMMAND --help` shows each command's options and examples."
)]
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
    #[command(
        after_help = "Examples:\n  bywire dbc dump vehicle.dbc\n  bywire dbc lint vehicle.dbc\n  bywire dbc convert vehicle.dbc vehicle.json\n  bywire dbc gen-rust vehicle.dbc > src/vehicle.rs"
    )]
    Dbc {
        #[command(subcommand)]
        command: dbc_cmd::DbcCommand,
    },
    /// Decode candump lines from standard input with a DBC file, like `cantools decode`.
    Decode(dbc_cmd::DecodeArgs),
    /// Print frames from one or more buses, like candump (same options, filters and output).
    Dump(dump_cmd::Args),
    /// Send one frame, like cansend, or a DBC message by name with its signals.
    Send(send_cmd::Args),
    /// Generate traffic like cangen, or every message of a DBC at its cycle time.
    Gen(gen_cmd::Args),
    /// Replay candump log files onto buses, like canplayer.
    Play(play_cmd::Args),
    /// Show the load of buses each second, like canbusload, per ID and against a DBC.
    Busload(busload_cmd::Args),
    /// Watch identifiers like cansniffer: changing bytes highlighted, rates, DBC values.
    Sniff(sniff_cmd::Args),
    /// A live table of decoded messages and signals, like cantools monitor.
    Monitor(monitor_cmd::Args),
    /// Plot signals from a candump log (or a live capture) to PNG or SVG, like cantools plot.
    Plot(plot_cmd::Args),
    /// Read candump logs: print them (log or screen form, filtered) or summarise them.
    #[command(
        after_help = "Examples:\n  bywire log cat --screen drive.log\n  bywire log stats drive.log"
    )]
    Log {
        #[command(subcommand)]
        command: log_cmd::LogCommand,
    },
    /// Vehicle acceptance checks: steering sweep, speed steps, watchdog and E-stop timing.
    Check(check_cmd::Args),
    /// The simulated tug on its buses, driven along a route (real time or --fast).
    Sim(sim_cmd::Args),
    /// CANopen: scan a bus, SDO read/write, NMT, run a device (EDS, CiA 402 drive, Roboteq).
    Canopen {
        #[command(subcommand)]
        command: canopen_cmd::CanopenCommand,
    },
    /// Serve a bus over the socketcand protocol (python-can, SavvyCAN and other clients).
    Serve(serve_cmd::Args),
    /// Emulate an SLCAN adapter for a bus on a pseudo terminal (for SLCAN tools).
    SlcanAdapter(slcan_adapter_cmd::Args),
    /// Run the ADS side of a vehicle interface on a bus: JSON commands in, vehicle state out.
    Bridge(bridge_cmd::Args),
    /// A simulated vehicle for any profile on any bus: the real supervisor and a plant.
    Vehicle(vehicle_cmd::Args),
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
        Command::Vehicle(args) => vehicle_cmd::run(&args, &mut out),
        Command::Dump(args) => dump_cmd::run(&args, &mut out),
        Command::Send(args) => send_cmd::run(&args, &mut out),
        Command::Gen(args) => gen_cmd::run(&args, &mut out),
        Command::Play(args) => play_cmd::run(&args, &mut out),
        Command::Sniff(args) => sniff_cmd::run(&args),
        Command::Monitor(args) => monitor_cmd::run(&args),
        Command::Plot(args) => plot_cmd::run(&args),
        Command::Serve(args) => serve_cmd::run(&args, &mut out),
        Command::Canopen { command } => canopen_cmd::run(&command, &mut out),
        Command::Sim(args) => sim_cmd::run(&args, &mut out),
        Command::Check(args) => check_cmd::run(&args, &mut out),
        Command::SlcanAdapter(args) => slcan_adapter_cmd::run(&args, &mut out),
        Command::Log { command } => log_cmd::run(&command, &mut out),
        Command::Busload(args) => busload_cmd::run(&args, &mut out),
    };
    let flushed = result.and_then(|()| out.flush().map_err(anyhow::Error::from));
    match flushed {
        Ok(()) => ExitCode::SUCCESS,
        // A closed pipe (`bywire ... | head`) is the reader's choice, not a failure.
        Err(e) if is_broken_pipe(&e) => ExitCode::SUCCESS,
        Err(e) => {
            // (Not eprintln!: it panics when standard error is gone, e.g. a closed terminal.)
            let _ = writeln!(io::stderr(), "error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// Set when the user presses Ctrl-C (SIGINT) or the process gets SIGTERM: long-running
/// commands stop at the next frame, flush their output and exit 0, as can-utils do.
pub fn interrupt_flag() -> Arc<AtomicBool> {
    static FLAG: OnceLock<Arc<AtomicBool>> = OnceLock::new();
    Arc::clone(FLAG.get_or_init(|| {
        let flag = Arc::new(AtomicBool::new(false));
        let set = Arc::clone(&flag);
        // Without a handler (e.g. one is already installed) Ctrl-C simply ends the process.
        let _ = ctrlc::set_handler(move || set.store(true, Ordering::Relaxed));
        flag
    }))
}

fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.downcast_ref::<io::Error>()
        .is_some_and(|io| io.kind() == io::ErrorKind::BrokenPipe)
}
