//! `bywire sim --serve`: each simulated bus through a socketcand server, so `bywire dump`,
//! python-can or SavvyCAN watch and inject traffic while the simulation runs. Each bus gets a
//! port on the simulated bus and an endpoint on an in-process virtual bus that the server's
//! clients join; [`Served::exchange`] carries frames between the two after every step.

use std::net::{SocketAddr, TcpListener};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use anyhow::{anyhow, Context, Result};
use bywire_bus::sim::NodeId;
use bywire_bus::socketcand::{self, Access, ServerStats};
use bywire_bus::virtual_bus::VirtualBus;
use bywire_bus::{Bus, BusError, BusRx, BusTx};
use bywire_sim::tug::{Tug, TugBus};

/// One bus's link: its port on the simulated bus and its endpoint on the served bus.
struct Link {
    bus: TugBus,
    port: NodeId,
    tx: Box<dyn BusTx>,
    rx: Box<dyn BusRx>,
}

/// The server and the links; stops the server when dropped.
pub struct Served {
    links: Vec<Link>,
    stop: Arc<AtomicBool>,
    server: Option<JoinHandle<std::io::Result<()>>>,
    beacon: Option<JoinHandle<()>>,
    /// Where it listens.
    pub address: SocketAddr,
}

impl Served {
    /// Serve `tug`'s buses on `listen` (clients open `bus1`, `bus2`, `bus3` or `bus1b`), with
    /// socketcand's discovery beacon sent to `beacon` if given.
    pub fn start(tug: &mut Tug, listen: SocketAddr, beacon: Option<SocketAddr>) -> Result<Served> {
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
        let links = TugBus::ALL
            .into_iter()
            .map(|bus| {
                let endpoint: Box<dyn Bus> =
                    Box::new(VirtualBus::join(&format!("{prefix}-{}", bus.name())));
                let (tx, rx) = endpoint.split();
                Link {
                    bus,
                    port: tug.attach(bus),
                    tx,
                    rx,
                }
            })
            .collect();
        let open = Arc::new(move |name: &str| -> Result<Box<dyn Bus>, BusError> {
            Ok(Box::new(VirtualBus::join(&format!("{prefix}-{name}"))))
        });
        let names: Vec<String> = TugBus::ALL.iter().map(|b| b.name().to_string()).collect();
        let stop = Arc::new(AtomicBool::new(false));
        let beacon = match beacon {
            Some(to) => Some(
                socketcand::spawn_beacon(
                    socketcand::beacon_xml(address, &names, "bywire sim"),
                    to,
                    Arc::clone(&stop),
                )
                .context("--beacon: cannot send the beacon")?,
            ),
            None => None,
        };
        let access = Access { names, token: None };
        let server_stop = Arc::clone(&stop);
        let server = std::thread::spawn(move || {
            socketcand::serve(
                listener,
                access,
                open,
                server_stop,
                Arc::new(ServerStats::default()),
            )
        });
        Ok(Served {
            links,
            stop,
            server: Some(server),
            beacon,
            address,
        })
    }

    /// Carry frames both ways: what the simulated buses carried out to the clients, what the
    /// clients sent onto the simulated buses. Bounded by what arrived since the last call.
    pub fn exchange(&mut self, tug: &mut Tug) {
        for link in &mut self.links {
            while let Some((_, frame)) = tug.receive(link.bus, link.port) {
                // A client that cannot keep up loses frames (its queue is bounded).
                let _ = link.tx.send(&frame);
            }
            while let Ok(Some(received)) = link.rx.recv(Some(Duration::ZERO)) {
                tug.send(link.bus, link.port, received.frame);
            }
        }
    }
}

impl Drop for Served {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(server) = self.server.take() {
            let _ = server.join();
        }
        if let Some(beacon) = self.beacon.take() {
            let _ = beacon.join();
        }
    }
}
