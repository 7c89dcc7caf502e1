//! `bywire`: the command line. Each subcommand parses its arguments, calls the library and
//! prints; the work is in the library crates. [`run`] is the whole command, for the `bywire`
//! binary and for the Python package's `bywire` console script.
// Doc comments here are clap's help text (`[,DATA_BITRATE]`, `INDEX[:SUB]`), not rustdoc links.
#![allow(rustdoc::broken_intra_doc_links)]

mod cmd;
mod plot;
mod support;
mod tui;

use std::ffi::OsString;
use std::io::{self, Write};

use clap::{CommandFactory, Parser, Subcommand};

/// A drive-by-wire CAN stack: wire model, bit timing and CAN tools.
#[derive(Parser)]
#[command(
    name = "bywire",
    version = concat!(env!("CARGO_PKG_VERSION"), " (", env!("BYWIRE_VERSION_DETAIL"), ")"),
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
    /// Read every database as this format (dbc, kcd, sym, arxml) instead of by its extension
    /// or content.
    #[arg(long, global = true, value_name = "FORMAT", value_parser = support::dbc::parse_format)]
    db_format: Option<bywire_dbc::Format>,
    /// Of a database describing several buses (an ARXML system's CAN clusters), read only this
    /// one; without it every bus is read, each message's in its BusName attribute.
    #[arg(long, global = true, value_name = "NAME")]
    db_bus: Option<String>,
}

#[derive(Subcommand)]
enum Command {
    /// Show a frame's exact bit sequence on the bus: stuffing, CRC, length and time.
    Wire(cmd::wire::Args),
    /// Compute bit-timing registers for a bitrate and sample point on a controller.
    Bittiming(cmd::bittiming::Args),
    /// Work with databases (DBC, KCD, SYM, ARXML): dump, lint, convert among them and JSON,
    /// generate Rust.
    #[command(
        after_help = "Examples:\n  bywire dbc dump vehicle.dbc\n  bywire dbc lint vehicle.dbc\n  bywire dbc convert vehicle.dbc vehicle.json\n  bywire dbc gen-rust vehicle.dbc > src/vehicle.rs"
    )]
    Dbc {
        #[command(subcommand)]
        command: cmd::dbc::DbcCommand,
    },
    /// Decode candump lines from standard input (or a log of any format) with a DBC file, like
    /// `cantools decode`; or into CSV or a Parquet dataset.
    Decode(cmd::dbc::DecodeArgs),
    /// Print frames from one or more buses, like candump (same options, filters and output).
    Dump(cmd::dump::Args),
    /// Record buses in the field: listen-only, into any log format, a file per bus or merged,
    /// rotated, checkpointed against kills, around triggers, with metadata and a status line.
    Record(cmd::record::Args),
    /// Send one frame, like cansend, or a DBC message by name with its signals.
    Send(cmd::send::Args),
    /// Generate traffic like cangen, or every message of a DBC at its cycle time.
    Gen(cmd::gen::Args),
    /// Replay candump log files onto buses, like canplayer.
    Play(cmd::play::Args),
    /// Show the load of buses each second, like canbusload, per ID and against a DBC.
    Busload(cmd::busload::Args),
    /// Latency of a drive-by-wire chain from logs (echo, steps, cycle times, transfers), or
    /// worst-case response times predicted from a DBC.
    Latency(cmd::latency::Args),
    /// A training dataset from logs: actions and observations on a time grid, ages, episodes,
    /// a split, the simulator's ground truth, and a dataset card.
    Dataset(cmd::dataset::Args),
    /// Replay a recorded session through a profile's supervisor: its decisions as a trace,
    /// compared with a stored one (regression).
    Replay(cmd::replay::Args),
    /// Run a fault-injection campaign: every fault × operating state × profile in the
    /// simulator, judged against the mechanism and reaction expected, as a coverage matrix.
    Campaign(cmd::campaign::Args),
    /// Watch identifiers like cansniffer: changing bytes highlighted, rates, DBC values.
    Sniff(cmd::sniff::Args),
    /// A live table of decoded messages and signals, like cantools monitor.
    Monitor(cmd::monitor::Args),
    /// Plot signals from a candump log (or a live capture) to PNG or SVG, like cantools plot.
    Plot(cmd::plot::Args),
    /// Logs of any format (candump, ASC, BLF, TRC, pcapng, MF4, MCAP, Parquet): print, convert
    /// or decode, summarise.
    #[command(
        after_help = "Examples:\n  bywire log cat --screen drive.log\n  bywire log stats drive.log"
    )]
    Log {
        #[command(subcommand)]
        command: cmd::log::LogCommand,
    },
    /// Vehicle acceptance checks: steering sweep, speed steps, watchdog and E-stop timing.
    Check(cmd::check::Args),
    /// The simulated tug on its buses, driven along a route (real time or --fast).
    Sim(cmd::sim::Args),
    /// CANopen: scan a bus, SDO read/write, NMT, run a device (EDS, CiA 402 drive, Roboteq).
    Canopen {
        #[command(subcommand)]
        command: cmd::canopen::CanopenCommand,
    },
    /// Serve a bus over the socketcand protocol (python-can, SavvyCAN and other clients).
    Serve(cmd::serve::Args),
    /// A CAN analyser in the browser over live buses (trace, signals, plots, bus load,
    /// transmit), and a Foxglove WebSocket server on the same port.
    Web(cmd::web::Args),
    /// Emulate an SLCAN adapter for a bus on a pseudo terminal (for SLCAN tools).
    SlcanAdapter(cmd::slcan_adapter::Args),
    /// ISO-TP on any bus, like can-utils' isotpsend and isotprecv (same options).
    Isotp {
        #[command(subcommand)]
        command: cmd::isotp::IsotpCommand,
    },
    /// UDS diagnostics on any bus: a tester (sessions, DIDs, DTCs, routines, security access)
    /// and a server (an ECU for testers).
    Uds {
        #[command(subcommand)]
        command: cmd::uds::UdsCommand,
    },
    /// SecOC (AUTOSAR authenticated messages): sign a frame, verify one or a whole capture.
    Secoc {
        #[command(subcommand)]
        command: cmd::secoc::SecocCommand,
    },
    /// Run the ADS side of a vehicle interface on a bus: JSON commands in, vehicle state out.
    Bridge(cmd::bridge::Args),
    /// A simulated vehicle for any profile on any bus: the real supervisor and a plant.
    Vehicle(cmd::vehicle::Args),
    /// ROS 2 over DDS, without a ROS installation: ros2_socketcan's CAN topics, Autoware's
    /// controller output and vehicle interface, CANopen drives as ros2_canopen offers them.
    #[cfg(feature = "ros2")]
    Ros2 {
        #[command(subcommand)]
        command: cmd::ros2::Ros2Command,
    },
    /// Print the completion script for a shell (bash, zsh, fish, elvish, powershell).
    Completions(cmd::shell::CompletionsArgs),
    /// Write the manual pages (bywire.1 and one per command) into a folder.
    Man(cmd::shell::ManArgs),
}

/// Run the command line on `args` (the program's name first, as `std::env::args_os` gives
/// them): the exit status, 0 or 1. `--help`, `--version` and usage errors print and end the
/// process, as clap does.
pub fn run<I, T>(args: I) -> u8
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    // A panic inside parquet-rs while it reads a file is taken as the file's error, which is
    // printed; every other panic is reported as usual.
    bywire_log::parquet::quiet_panics_taken_as_errors();
    let cli = Cli::parse_from(args);
    support::dbc::force_format(cli.db_format);
    support::dbc::select_bus(cli.db_bus);
    let mut out = io::stdout().lock();
    let result = match cli.command {
        Command::Wire(args) => cmd::wire::run(&args, &mut out),
        Command::Bittiming(args) => cmd::bittiming::run(&args, &mut out),
        Command::Dbc { command } => cmd::dbc::run(&command, &mut out),
        Command::Decode(args) => cmd::dbc::decode(&args, io::stdin(), &mut out),
        Command::Bridge(args) => cmd::bridge::run(&args, &mut out),
        Command::Vehicle(args) => cmd::vehicle::run(&args, &mut out),
        Command::Dump(args) => cmd::dump::run(&args, &mut out),
        Command::Record(args) => cmd::record::run(&args, &mut out),
        Command::Send(args) => cmd::send::run(&args, &mut out),
        Command::Gen(args) => cmd::gen::run(&args, &mut out),
        Command::Play(args) => cmd::play::run(&args, &mut out),
        Command::Sniff(args) => cmd::sniff::run(&args),
        Command::Monitor(args) => cmd::monitor::run(&args),
        Command::Plot(args) => cmd::plot::run(&args),
        Command::Serve(args) => cmd::serve::run(&args, &mut out),
        Command::Web(args) => cmd::web::run(&args, &mut out),
        Command::Canopen { command } => cmd::canopen::run(&command, &mut out),
        Command::Sim(args) => cmd::sim::run(&args, &mut out),
        Command::Check(args) => cmd::check::run(&args, &mut out),
        Command::SlcanAdapter(args) => cmd::slcan_adapter::run(&args, &mut out),
        Command::Log { command } => cmd::log::run(&command, &mut out),
        Command::Busload(args) => cmd::busload::run(&args, &mut out),
        Command::Latency(args) => cmd::latency::run(&args, &mut out),
        Command::Dataset(args) => cmd::dataset::run(&args, &mut out),
        Command::Replay(args) => cmd::replay::run(&args, &mut out),
        Command::Campaign(args) => cmd::campaign::run(&args, &mut out),
        Command::Uds { command } => cmd::uds::run(&command, &mut out),
        Command::Secoc { command } => cmd::secoc::run(&command, &mut out),
        Command::Isotp { command } => cmd::isotp::run(&command, &mut io::stdin().lock(), &mut out),
        #[cfg(feature = "ros2")]
        Command::Ros2 { command } => cmd::ros2::run(&command, &mut out),
        Command::Completions(args) => cmd::shell::completions(&args, Cli::command(), &mut out),
        Command::Man(args) => cmd::shell::man(&args, Cli::command(), &mut out),
    };
    let flushed = result.and_then(|()| out.flush().map_err(anyhow::Error::from));
    match flushed {
        Ok(()) => 0,
        // A closed pipe (`bywire ... | head`) is the reader's choice, not a failure.
        Err(e) if is_broken_pipe(&e) => 0,
        Err(e) => {
            // (Not eprintln!: it panics when standard error is gone, e.g. a closed terminal.)
            let _ = writeln!(io::stderr(), "error: {e:#}");
            1
        }
    }
}

fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.downcast_ref::<io::Error>()
        .is_some_and(|io| io.kind() == io::ErrorKind::BrokenPipe)
}
