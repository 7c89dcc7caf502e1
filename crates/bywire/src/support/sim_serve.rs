//! The simulated buses shared with other programs while `bywire sim` runs: `--serve` puts each
//! through a socketcand server (for `bywire dump`, python-can and other socketcand clients),
//! `--attach` carries one to another bus (a SocketCAN interface such as vcan0, for candump
//! and the like), `--web` onto the live page and the Foxglove server. Each
//! share is a port on the simulated bus linked to an endpoint; [`Shared::exchange`] carries
//! frames between the two after every step.

use std::net::{SocketAddr, TcpListener};
use std::sync::Arc;
use std::time::Duration;

use anyhow::{anyhow, Context, Result};
use bywire_bus::socketcand::{self, Access, Config, Server};
use bywire_bus::virtual_bus::VirtualBus;
use bywire_bus::{Bus, BusError, BusRx, BusTx};
use bywire_net::sim::NodeId;
use bywire_sim::fault::Fault;
use bywire_sim::tug::{Tug, TugBus};

use crate::support::sim_web::SimWeb;

/// One link: a port on a simulated bus and the endpoint its frames go to and come from.
struct Link {
    bus: TugBus,
    port: NodeId,
    tx: Box<dyn BusTx>,
    rx: Box<dyn BusRx>,
}

/// The links of a run and the servers, if it serves.
#[derive(Default)]
pub struct Shared {
    links: Vec<Link>,
    server: Option<Server>,
    web: Option<SimWeb>,
}

impl Shared {
    /// `bus` of the tug linked to `endpoint`, both ways.
    fn link(&mut self, tug: &mut Tug, bus: TugBus, endpoint: Box<dyn Bus>) {
        let (tx, rx) = endpoint.split();
        self.links.push(Link {
            bus,
            port: tug.attach(bus),
            tx,
            rx,
        });
    }

    /// Carry `bus` to and from `endpoint` while the run goes on.
    pub fn attach(&mut self, tug: &mut Tug, bus: TugBus, endpoint: Box<dyn Bus>) {
        self.link(tug, bus, endpoint);
    }

    /// Serve `tug`'s buses on `listen` (clients open `bus1`, `bus2`, `bus3` or `bus1b`), with
    /// socketcand's discovery beacon sent to `beacon` if given; returns where it listens.
    pub fn serve(
        &mut self,
        tug: &mut Tug,
        listen: SocketAddr,
        beacon: Option<SocketAddr>,
    ) -> Result<SocketAddr> {
        if !listen.ip().is_loopback() {
            return Err(anyhow!(
                "--serve {listen}: not a loopback address (socketcand has no authentication; use `bywire serve` with --allow-remote and a token to reach other hosts)"
            ));
        }
        let listener = TcpListener::bind(listen)
            .with_context(|| format!("--serve: cannot listen on {listen}"))?;
        let address = listener.local_addr()?;
        // In-process bus names of this run only.
        let prefix = format!("bywire-sim-{}", std::process::id());
        for bus in TugBus::ALL {
            let endpoint = VirtualBus::join(&format!("{prefix}-{}", bus.name()));
            self.link(tug, bus, Box::new(endpoint));
        }
        let open = Arc::new(move |name: &str| -> Result<Box<dyn Bus>, BusError> {
            Ok(Box::new(VirtualBus::join(&format!("{prefix}-{name}"))))
        });
        let names: Vec<String> = TugBus::ALL.iter().map(|b| b.name().to_string()).collect();
        let config = Config {
            access: Access {
                names: names.clone(),
                token: None,
            },
            ..Config::default()
        };
        let mut server =
            Server::start(listener, config, open).context("--serve: cannot start the server")?;
        if let Some(to) = beacon {
            server
                .start_beacon(socketcand::beacon_xml(address, &names, "bywire sim"), to)
                .context("--beacon: cannot send the beacon")?;
        }
        self.server = Some(server);
        Ok(address)
    }

    /// Serve the page and the Foxglove WebSocket protocol on `listen` (loopback only: the page
    /// sends frames and injects faults); `faults`: the scenario's, for the page's buttons.
    pub fn web(
        &mut self,
        tug: &mut Tug,
        listen: SocketAddr,
        start: bywire_core::Timestamp,
        faults: Vec<(Fault, Option<Duration>)>,
    ) -> Result<SocketAddr> {
        if !listen.ip().is_loopback() {
            return Err(anyhow!(
                "--web {listen}: not a loopback address (the page sends frames and injects faults; use `bywire web` with --allow-remote and a token to reach other hosts)"
            ));
        }
        let web = SimWeb::start(tug, listen, start, faults).context("--web")?;
        let address = web.address();
        self.web = Some(web);
        Ok(address)
    }

    /// Carry frames both ways: what the simulated buses carried out to the endpoints, what the
    /// endpoints received onto the simulated buses. Bounded by what arrived since the last call.
    /// An error when the server stopped serving (the run must not go on as if it served).
    pub fn exchange(&mut self, tug: &mut Tug) -> Result<()> {
        if let Some(server) = &mut self.server {
            if !server.is_running() {
                let why = server
                    .stop()
                    .err()
                    .map_or("ended".into(), |e| e.to_string());
                return Err(anyhow!("--serve: the socketcand server stopped: {why}"));
            }
        }
        for link in &mut self.links {
            while let Some((_, frame)) = tug.receive(link.bus, link.port) {
                // An endpoint that cannot keep up loses frames (its queue is bounded).
                let _ = link.tx.send(&frame);
            }
            while let Ok(Some(received)) = link.rx.recv(Some(Duration::ZERO)) {
                tug.send(link.bus, link.port, received.frame);
            }
        }
        if let Some(web) = &mut self.web {
            web.step(tug);
        }
        Ok(())
    }

    /// The socketcand server's counts, for the end of the run.
    pub fn summary(&self) -> Option<String> {
        self.server.as_ref().map(|s| s.stats().summary())
    }

    /// Stop the page's server: what its clients lost by reading too slowly.
    pub fn stop_web(&mut self) -> Option<u64> {
        self.web.take().map(SimWeb::stop)
    }
}
