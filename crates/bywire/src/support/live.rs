//! The live web page and Foxglove WebSocket server over buses (`bywire web`, `serve
//! --foxglove`): the buses opened, a reader thread per bus feeding the hub, a ticker for the
//! statistics, the server on its port.

use std::net::{SocketAddr, TcpListener};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context, Result};
use bywire_web::{Access, Database, Hub, HubBuilder, Logs, WebServer};

use crate::support::busarg::BusArg;

/// What the server is given.
pub struct LiveConfig<'a> {
    /// The name clients see.
    pub name: &'a str,
    /// Where to listen.
    pub listen: SocketAddr,
    /// Who may connect, and whether they may send.
    pub access: Access,
    /// Logs the page may open, decoded with the database given.
    pub logs: Vec<std::path::PathBuf>,
    /// The logs' database.
    pub logs_database: Option<Arc<Database>>,
    /// Whether the page may upload logs.
    pub uploads: bool,
    /// A second address serving the same (`web --foxglove`: Foxglove on a port of its own).
    pub also: Option<SocketAddr>,
}

impl<'a> LiveConfig<'a> {
    /// A server of buses alone: no logs, no uploads, one port.
    pub fn new(name: &'a str, listen: SocketAddr, access: Access) -> Self {
        LiveConfig {
            name,
            listen,
            access,
            logs: Vec::new(),
            logs_database: None,
            uploads: false,
            also: None,
        }
    }
}

/// A bus to serve: its argument, its bitrate (for the load) and its database.
pub struct LiveBus {
    /// The bus argument (its name labels the channels).
    pub arg: BusArg,
    /// The bitrate, when known.
    pub bitrate: Option<u32>,
    /// The database its frames are decoded with.
    pub database: Option<Arc<Database>>,
    /// The caller hands the hub this bus's frames itself ([`Hub::on_frame`], with times of its
    /// own: the simulator's); the bus only carries what clients send.
    pub fed: bool,
}

/// A running hub and server; [`Live::stop`] ends both.
pub struct Live {
    address: SocketAddr,
    server: Option<WebServer>,
    second: Option<WebServer>,
    hub: Arc<Hub>,
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
}

impl Live {
    /// Open `buses`, decode with `decoder`, and serve.
    pub fn start(
        buses: &[LiveBus],
        config: LiveConfig<'_>,
        extend: impl FnOnce(HubBuilder) -> HubBuilder,
    ) -> Result<Self> {
        // A fed bus is opened only to take what clients send.
        let opening: Vec<BusArg> = buses
            .iter()
            .filter(|b| !b.fed || config.access.allow_send)
            .map(|b| b.arg.clone())
            .collect();
        let mut opened = crate::support::busarg::open_all(&opening)?.into_iter();
        let listener = TcpListener::bind(config.listen)
            .with_context(|| format!("cannot listen on {}", config.listen))?;
        let also = config
            .also
            .map(|address| {
                TcpListener::bind(address).with_context(|| format!("cannot listen on {address}"))
            })
            .transpose()?;
        let mut builder = HubBuilder::new(config.name).metadata("program", "bywire");
        let mut receivers = Vec::with_capacity(buses.len());
        for bus in buses {
            let endpoint = if !bus.fed || config.access.allow_send {
                opened.next()
            } else {
                None
            };
            let (tx, rx) = match endpoint {
                Some(mut endpoint) => {
                    // What clients send shows in the trace as the bus's other traffic does.
                    let _ = endpoint.set_receive_own(config.access.allow_send && !bus.fed);
                    let (tx, rx) = endpoint.split();
                    (
                        config.access.allow_send.then_some(tx),
                        (!bus.fed).then_some(rx),
                    )
                }
                None => (None, None),
            };
            builder = builder.bus(&bus.arg.name, tx, bus.bitrate, bus.database.clone());
            receivers.push(rx);
        }
        let hub = extend(builder).build().map_err(|e| anyhow!(e))?;
        let stop = Arc::new(AtomicBool::new(false));
        let mut threads = Vec::new();
        for (index, rx) in receivers.into_iter().enumerate() {
            let Some(rx) = rx else { continue };
            let (hub, stop) = (Arc::clone(&hub), Arc::clone(&stop));
            threads.push(
                std::thread::Builder::new()
                    .name(format!("web-bus-{index}"))
                    .spawn(move || hub.read_bus(index, rx, &stop))?,
            );
        }
        let (ticking, ticker_stop) = (Arc::clone(&hub), Arc::clone(&stop));
        threads.push(
            std::thread::Builder::new()
                .name("web-stats".into())
                .spawn(move || tick(&ticking, &ticker_stop))?,
        );
        let logs = Arc::new(Logs::new(config.logs, config.logs_database, config.uploads));
        let second = also
            .map(|listener| {
                WebServer::start(
                    Arc::clone(&hub),
                    Arc::clone(&logs),
                    listener,
                    config.access.clone(),
                )
            })
            .transpose()
            .context("cannot start the second server")?;
        let server = WebServer::start(Arc::clone(&hub), logs, listener, config.access)
            .context("cannot start the web server")?;
        Ok(Live {
            address: server.address(),
            second,
            server: Some(server),
            hub,
            stop,
            threads,
        })
    }

    /// The hub (for the caller's channels and commands).
    pub fn hub(&self) -> &Hub {
        &self.hub
    }

    /// Where the server listens.
    pub fn address(&self) -> SocketAddr {
        self.address
    }

    /// Where the second server listens, if there is one.
    pub fn also(&self) -> Option<SocketAddr> {
        self.second.as_ref().map(WebServer::address)
    }

    /// Stop serving and reading; what clients lost, in all.
    pub fn stop(mut self) -> u64 {
        self.stop.store(true, Ordering::Relaxed);
        for server in [self.server.take(), self.second.take()]
            .into_iter()
            .flatten()
        {
            server.stop();
        }
        for thread in std::mem::take(&mut self.threads) {
            let _ = thread.join();
        }
        self.hub.dropped()
    }
}

impl Drop for Live {
    /// Readers and the ticker end with the hub's owner even when it did not call
    /// [`Live::stop`] (an error ended the run).
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// The database at `path` (any format), ready for the hub.
pub fn database(path: Option<&std::path::Path>) -> Result<Option<Arc<Database>>> {
    path.map(|path| {
        let db = crate::support::dbc::load(path, false)?;
        Ok(Arc::new(Database::new(bywire_dbc::decoder::Decoder::new(
            db,
        ))))
    })
    .transpose()
}

/// Say where the page and the Foxglove server are.
pub fn announce(out: &mut impl std::io::Write, address: SocketAddr) -> Result<()> {
    writeln!(
        out,
        "the page on http://{address}/ (Foxglove: ws://{address})"
    )?;
    out.flush()?;
    Ok(())
}

/// The batches every 50 ms and the statistics once a second, until `stop`.
fn tick(hub: &Hub, stop: &AtomicBool) {
    let mut last = Vec::new();
    let mut previous = Instant::now();
    // Bounded by `stop`.
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(50));
        hub.flush(bywire_bus::monotonic_unix_now());
        let elapsed = previous.elapsed();
        if elapsed >= Duration::from_secs(1) {
            previous = Instant::now();
            hub.tick(
                bywire_bus::monotonic_unix_now(),
                elapsed.as_secs_f64(),
                &mut last,
            );
        }
    }
}
