//! # bywire-web: a CAN analyser in the browser, and a Foxglove WebSocket server
//!
//! A [`Hub`] reads any number of buses, decodes their frames with a database and publishes
//! them on Foxglove WebSocket channels (`/BUS/frames`, `/BUS/stats`, `/BUS/MESSAGE`); a
//! [`WebServer`] serves, on one port, the page (embedded: a trace, a signal tree, plots, bus
//! panels and a transmit panel) and the protocol, which the page, Foxglove's app and
//! Foxglove's clients all speak. Clients send frames only when the server allows it.
//!
//! ```no_run
//! use std::sync::Arc;
//! use bywire_web::{Access, HubBuilder, WebServer};
//! let bus = bywire_bus::open("virtual:doc").unwrap();
//! let (tx, rx) = bus.split();
//! let hub = HubBuilder::new("doc").bus("doc", Some(tx), Some(500_000), None).build().unwrap();
//! let listener = std::net::TcpListener::bind("127.0.0.1:8080").unwrap();
//! let logs = Arc::new(bywire_web::Logs::new(Vec::new(), None, false));
//! let server = WebServer::start(Arc::clone(&hub), logs, listener, Access::default()).unwrap();
//! let stop = std::sync::atomic::AtomicBool::new(false);
//! hub.read_bus(0, rx, &stop);
//! server.stop();
//! ```

pub mod assets;
pub mod foxglove;
pub mod hub;
pub mod logs;
pub mod server;

pub use hub::{Database, Hub, HubBuilder, Outgoing, Session};
pub use logs::Logs;
pub use server::{Access, WebServer};
