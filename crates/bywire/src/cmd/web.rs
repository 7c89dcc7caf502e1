//! `bywire web`: a CAN analyser in the browser over live buses, with a database; the same
//! port speaks the Foxglove WebSocket protocol.

use std::io::Write;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::time::Duration;

use anyhow::{Context, Result};

use crate::support::access;
use crate::support::busarg::{self, BusArg};
use crate::support::interrupt::interrupt_flag;
use crate::support::live::{self, Live, LiveBus, LiveConfig};

#[derive(clap::Args)]
#[command(after_help = "Examples:
  bywire web can0 --db vehicle.dbc                (then open http://127.0.0.1:8080/)
  bywire web front=can0 rear=can1 --db vehicle.dbc --allow-send --bitrate 500000
  bywire web socketcand:127.0.0.1:29536/bus1 --db examples/data/reference-tug.dbc --listen 127.0.0.1:0
  bywire web -I drive.blf -I run1/bus1.log --db vehicle.dbc     (logs: play, step, plot, export)
  BYWIRE_SERVE_TOKEN=... bywire web can0 --listen 0.0.0.0:8080 --allow-remote   (open /?token=...)

The page (served from the binary: no internet needed) shows a trace (one row per identifier
with changed bytes highlighted, or every frame), filters (an identifier, a name, or
SIGNAL>VALUE), the database's messages and signals, plots of any signals (several panels,
drag to zoom, a cursor with values), each bus's rate, load and errors, and with --allow-send a
transmit panel (a raw frame, or a message by its signals with counters and checksums filled
in from the database), once or periodically.

The same port speaks the Foxglove WebSocket protocol: in Foxglove, open a connection to
ws://ADDRESS. Channels: /BUS/frames (every frame), /BUS/stats (once a second) and /BUS/MESSAGE
(each message of the database, decoded). A client that reads too slowly loses messages
(counted and told), never the bus or the other clients. A page of another site cannot
connect (browsers say where a page comes from) unless --allow-origin names it.")]
pub struct Args {
    /// Buses to watch, each with optional candump filters and a label:
    /// [LABEL=]BUS[,ID:MASK|ID~MASK|#ERRMASK|j]*
    #[arg(required_unless_present = "logs", num_args = 0..=16)]
    buses: Vec<String>,
    /// Logs the page may open (any format bywire reads): played, stepped through, plotted
    /// whole (decimated on the server) and exported, a span of them, to any format.
    #[arg(short = 'I', long = "input", value_name = "LOG")]
    logs: Vec<PathBuf>,
    /// The page may not upload logs (uploads go to a temporary folder removed at the end, at
    /// most 2 GiB each and 8 GiB in all).
    #[arg(long)]
    no_upload: bool,
    /// Decode with this database (DBC, KCD, SYM, ARXML, JSON).
    #[arg(long, alias = "dbc", value_name = "FILE")]
    db: Option<PathBuf>,
    /// Address and port to serve on (port 0: any free port, printed).
    #[arg(long, default_value = "127.0.0.1:8080")]
    listen: SocketAddr,
    /// Serve the Foxglove WebSocket protocol on this address too (the page's port speaks it
    /// already): for a Foxglove layout that expects its own port, such as 8765.
    #[arg(long, value_name = "ADDR:PORT", num_args = 0..=1, default_missing_value = "127.0.0.1:8765")]
    foxglove: Option<SocketAddr>,
    /// Let clients (the page's transmit panel, Foxglove's publish) send frames on the buses.
    #[arg(long)]
    allow_send: bool,
    /// The buses' bitrate, for their load.
    #[arg(long, value_name = "BIT/S", value_parser = clap::value_parser!(u32).range(1_000..=16_000_000))]
    bitrate: Option<u32>,
    /// Pages of this origin may connect without the token (https://app.foxglove.dev).
    #[arg(long = "allow-origin", value_name = "ORIGIN")]
    origins: Vec<String>,
    #[command(flatten)]
    remote: access::Remote,
}

pub fn run(args: &Args, out: &mut impl Write) -> Result<()> {
    let token = args.remote.token()?;
    args.remote.check(
        "--listen",
        args.listen,
        token.as_deref(),
        "the page can send frames",
    )?;
    let buses: Vec<BusArg> = args
        .buses
        .iter()
        .map(|b| busarg::parse(b))
        .collect::<Result<_>>()?;
    for log in &args.logs {
        std::fs::File::open(log).with_context(|| format!("-I {}", log.display()))?;
    }
    let database = live::database(args.db.as_deref())?;
    let buses: Vec<LiveBus> = buses
        .into_iter()
        .map(|arg| LiveBus {
            arg,
            bitrate: args.bitrate,
            database: database.clone(),
            fed: false,
        })
        .collect();
    let live = Live::start(
        &buses,
        LiveConfig {
            name: "bywire web",
            listen: args.listen,
            access: bywire_web::Access {
                token,
                origins: args.origins.clone(),
                allow_send: args.allow_send,
            },
            logs: args.logs.clone(),
            logs_database: database,
            uploads: !args.no_upload,
            also: args.foxglove,
        },
        |hub| hub,
    )?;
    live::announce(out, live.address())?;
    if let Some(also) = live.also() {
        writeln!(out, "Foxglove also on ws://{also}")?;
        out.flush()?;
    }
    let stop = interrupt_flag();
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(50));
    }
    let dropped = live.stop();
    if dropped > 0 {
        writeln!(out, "clients lost {dropped} messages by reading too slowly")?;
    }
    Ok(())
}
