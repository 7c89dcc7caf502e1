//! `bywire serve`: a socketcand server for any bus, so socketcand clients (python-can's
//! `socketcand` interface, SavvyCAN) can join it over TCP.

use std::io::Write;
use std::net::{SocketAddr, TcpListener};
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, Result};
use bywire_bus::socketcand::{self, Limits, Server};

use crate::support::interrupt::interrupt_flag;
use crate::support::live::{self, Live, LiveBus, LiveConfig};
use crate::support::{access, busarg, numbers};

#[derive(clap::Args)]
#[command(after_help = "Examples:
  bywire serve virtual:test                    (a virtual bus other programs can join)
  bywire serve can0 --listen 127.0.0.1:29536
  python3 -c \"import can; b = can.Bus(interface='socketcand', host='127.0.0.1', port=29536, channel='test')\"
  BYWIRE_SERVE_TOKEN=... bywire serve can0 --listen 0.0.0.0:29536 --allow-remote

Each client gets its own endpoint on the bus and a bounded queue: a slow client loses frames
(counted, shown when the server stops) and never stalls the bus or the other clients. Every
resource a client can spend is limited (connections, time to open a bus, cyclic jobs and their
interval, subscriptions, time a client may stop reading); what a limit refuses is counted and
shown when the server stops. Clients may open any bus name unless --name restricts them.
Listening beyond this host needs --allow-remote and a token (--token-file or the
BYWIRE_SERVE_TOKEN environment variable): plain socketcand has no authentication. The
discovery beacon is off unless --beacon is given.")]
pub struct Args {
    /// The bus to serve (a plain interface name means SocketCAN).
    bus: String,
    /// Address and port to listen on.
    #[arg(long, default_value = "127.0.0.1:29536")]
    listen: SocketAddr,
    /// Bus names clients may open (any when none is given).
    #[arg(long = "name", value_name = "NAME")]
    names: Vec<String>,
    #[command(flatten)]
    remote: access::Remote,
    /// Send socketcand's discovery beacon every 3 s (to 255.255.255.255:42000 when listening
    /// beyond this host, else to 127.0.0.1:42000).
    #[arg(long)]
    beacon: bool,
    /// Where to send the beacon instead.
    #[arg(long, value_name = "ADDR:PORT", requires = "beacon")]
    beacon_to: Option<SocketAddr>,
    /// Clients served at once; more are told the server is full and closed.
    #[arg(long, default_value_t = 64, value_parser = clap::value_parser!(u16).range(1..=4096))]
    max_clients: u16,
    /// Cyclic (BCM `add`) jobs per client.
    #[arg(long, default_value_t = 64, value_parser = clap::value_parser!(u16).range(0..=4096))]
    max_jobs_per_client: u16,
    /// Cyclic jobs over all clients.
    #[arg(long, default_value_t = 1024, value_parser = clap::value_parser!(u16).range(0..=16384))]
    max_jobs: u16,
    /// The shortest interval of a cyclic job, in milliseconds.
    #[arg(long, value_name = "MS", default_value = "1", value_parser = numbers::milliseconds)]
    min_interval: f64,
    /// Subscriptions and content filters per client.
    #[arg(long, default_value_t = 2048, value_parser = clap::value_parser!(u16).range(0..=16384))]
    max_subscriptions: u16,
    /// Seconds a connection may take to open a bus before it is closed.
    #[arg(long, value_name = "SECONDS", default_value = "10", value_parser = numbers::positive_seconds)]
    handshake_timeout: f64,
    /// Also serve the page and the Foxglove WebSocket protocol here (the bus's frames, decoded
    /// with --db; the same token rules).
    #[arg(long, value_name = "ADDR:PORT", num_args = 0..=1, default_missing_value = "127.0.0.1:8080")]
    foxglove: Option<SocketAddr>,
    /// With --foxglove: decode with this database (DBC, KCD, SYM, ARXML, JSON).
    #[arg(long, alias = "dbc", value_name = "FILE", requires = "foxglove")]
    db: Option<PathBuf>,
    /// With --foxglove: let its clients send frames (socketcand clients always may).
    #[arg(long, requires = "foxglove")]
    allow_send: bool,
    /// With --foxglove: pages of this origin may connect without the token.
    #[arg(long = "allow-origin", value_name = "ORIGIN", requires = "foxglove")]
    origins: Vec<String>,
    /// Seconds a client may accept no data before it is closed.
    #[arg(long, value_name = "SECONDS", default_value = "10", value_parser = numbers::positive_seconds)]
    write_timeout: f64,
}

impl Args {
    fn limits(&self) -> Limits {
        Limits {
            max_clients: self.max_clients.into(),
            jobs_per_client: self.max_jobs_per_client.into(),
            jobs_total: self.max_jobs.into(),
            min_interval: Duration::from_secs_f64(self.min_interval / 1e3),
            subscriptions_per_client: self.max_subscriptions.into(),
            handshake_timeout: Duration::from_secs_f64(self.handshake_timeout),
            write_timeout: Duration::from_secs_f64(self.write_timeout),
        }
    }
}

pub fn run(args: &Args, out: &mut impl Write) -> Result<()> {
    let token = args.remote.token()?;
    args.remote.check(
        "--listen",
        args.listen,
        token.as_deref(),
        "socketcand has no authentication",
    )?;
    if let Some(listen) = args.foxglove {
        args.remote.check(
            "--foxglove",
            listen,
            token.as_deref(),
            "the page shows the bus",
        )?;
    }
    let spec = busarg::full_spec(&args.bus);
    // Open once now, so a bad spec fails before anyone connects; the endpoint keeps an
    // in-process bus alive between clients.
    let keep = busarg::open(&args.bus).with_context(|| format!("bus '{}'", args.bus))?;
    let listener = TcpListener::bind(args.listen)
        .with_context(|| format!("cannot listen on {}", args.listen))?;
    let open_spec = spec.clone();
    let open = Arc::new(move |_name: &str| {
        bywire_bus::open(&open_spec).map_err(|e| bywire_bus::BusError::Unsupported(e.to_string()))
    });
    let config = socketcand::Config {
        access: socketcand::Access {
            names: args.names.clone(),
            token: token.clone(),
        },
        limits: args.limits(),
    };
    let mut server = Server::start(listener, config, open).context("cannot start the server")?;
    writeln!(
        out,
        "serving {spec} on {} (socketcand)",
        server.local_addr()
    )?;
    out.flush()?;
    if args.beacon {
        let to = args.beacon_to.unwrap_or_else(|| {
            let host = if args.listen.ip().is_loopback() {
                "127.0.0.1:42000"
            } else {
                "255.255.255.255:42000"
            };
            host.parse().unwrap_or(args.listen)
        });
        let name = spec.rsplit(':').next().unwrap_or(&spec).to_string();
        let buses = if args.names.is_empty() {
            vec![name]
        } else {
            args.names.clone()
        };
        let xml = socketcand::beacon_xml(server.local_addr(), &buses, "bywire serve");
        server
            .start_beacon(xml, to)
            .context("cannot send the beacon")?;
    }
    let live = match args.foxglove {
        Some(listen) => {
            let database = live::database(args.db.as_deref())?;
            let live = Live::start(
                &[LiveBus {
                    arg: busarg::parse(&args.bus)?,
                    bitrate: None,
                    database,
                    fed: false,
                }],
                LiveConfig::new(
                    "bywire serve",
                    listen,
                    bywire_web::Access {
                        token: token.clone(),
                        origins: args.origins.clone(),
                        allow_send: args.allow_send,
                    },
                ),
                |hub| hub,
            )?;
            live::announce(out, live.address())?;
            Some(live)
        }
        None => None,
    };
    let stop = interrupt_flag();
    while !stop.load(Ordering::Relaxed) && server.is_running() {
        std::thread::sleep(Duration::from_millis(50));
    }
    if let Some(live) = live {
        live.stop();
    }
    let ended = server.stop();
    drop(keep);
    writeln!(out, "{}", server.stats().summary())?;
    ended.context("the server stopped")
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: Args,
    }

    #[test]
    fn the_options_default_to_the_servers_limits() {
        let cli = Cli::try_parse_from(["serve", "virtual:x"]).unwrap();
        assert_eq!(cli.args.limits(), Limits::default());
        assert!(Cli::try_parse_from(["serve", "virtual:x", "--max-clients", "0"]).is_err());
        assert!(Cli::try_parse_from(["serve", "virtual:x", "--min-interval", "-1"]).is_err());
    }
}
