//! `bywire serve`: a socketcand server for any bus, so socketcand clients (python-can's
//! `socketcand` interface, SavvyCAN) can join it over TCP.

use std::io::Write;
use std::net::{SocketAddr, TcpListener};
use std::sync::atomic::Ordering;
use std::sync::Arc;

use anyhow::{anyhow, Context, Result};
use bywire_bus::socketcand::{self, ServerStats};

use crate::support::busarg;

#[derive(clap::Args)]
#[command(after_help = "Examples:
  bywire serve virtual:test                    (a virtual bus other programs can join)
  bywire serve can0 --listen 127.0.0.1:29536
  python3 -c \"import can; b = can.Bus(interface='socketcand', host='127.0.0.1', port=29536, channel='test')\"

Each client gets its own endpoint on the bus and a bounded queue: a slow client loses frames
(counted, shown when the server stops) and never stalls the bus or the other clients. Clients
may open any bus name unless --name restricts them. Listening beyond this host needs
--allow-remote: the protocol has no authentication. The discovery beacon is off unless
--beacon is given.")]
pub struct Args {
    /// The bus to serve (a plain interface name means SocketCAN).
    bus: String,
    /// Address and port to listen on.
    #[arg(long, default_value = "127.0.0.1:29536")]
    listen: SocketAddr,
    /// Bus names clients may open (any when none is given).
    #[arg(long = "name", value_name = "NAME")]
    names: Vec<String>,
    /// Allow listening on an address other hosts can reach.
    #[arg(long)]
    allow_remote: bool,
    /// Require clients to send `< auth TOKEN >` first (plain socketcand clients cannot; for
    /// bywire clients and scripts on other hosts).
    #[arg(long, value_name = "TOKEN")]
    token: Option<String>,
    /// Send socketcand's discovery beacon every 3 s (to 255.255.255.255:42000 when listening
    /// beyond this host, else to 127.0.0.1:42000).
    #[arg(long)]
    beacon: bool,
    /// Where to send the beacon instead.
    #[arg(long, value_name = "ADDR:PORT", requires = "beacon")]
    beacon_to: Option<SocketAddr>,
}

pub fn run(args: &Args, out: &mut impl Write) -> Result<()> {
    if !args.listen.ip().is_loopback() && !args.allow_remote {
        return Err(anyhow!(
            "--listen {}: not a loopback address; socketcand has no authentication, so add --allow-remote to serve other hosts",
            args.listen
        ));
    }
    let spec = busarg::full_spec(&args.bus);
    // Open once now, so a bad spec fails before anyone connects; the endpoint keeps an
    // in-process bus alive between clients.
    let keep = busarg::open(&args.bus).with_context(|| format!("bus '{}'", args.bus))?;
    let listener = TcpListener::bind(args.listen)
        .with_context(|| format!("cannot listen on {}", args.listen))?;
    writeln!(
        out,
        "serving {spec} on {} (socketcand)",
        listener.local_addr()?
    )?;
    out.flush()?;
    let stop = crate::interrupt_flag();
    let beacon = if args.beacon {
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
        let xml = socketcand::beacon_xml(listener.local_addr()?, &buses, "bywire serve");
        Some(
            socketcand::spawn_beacon(xml, to, Arc::clone(&stop))
                .context("cannot send the beacon")?,
        )
    } else {
        None
    };
    let stats = Arc::new(ServerStats::default());
    let open_spec = spec.clone();
    let open = Arc::new(move |_name: &str| {
        bywire_bus::open(&open_spec).map_err(|e| bywire_bus::BusError::Unsupported(e.to_string()))
    });
    socketcand::serve(
        listener,
        socketcand::Access {
            names: args.names.clone(),
            token: args.token.clone(),
        },
        open,
        Arc::clone(&stop),
        Arc::clone(&stats),
    )?;
    if let Some(beacon) = beacon {
        let _ = beacon.join();
    }
    drop(keep);
    writeln!(
        out,
        "clients {}, frames dropped for slow clients {}, malformed commands {}",
        stats.clients.load(Ordering::Relaxed),
        stats.dropped.load(Ordering::Relaxed),
        stats.errors.load(Ordering::Relaxed)
    )?;
    Ok(())
}
