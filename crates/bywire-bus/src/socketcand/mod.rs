//! The socketcand protocol: a server that lets any socketcand client (python-can's
//! `socketcand` interface, SavvyCAN) join a bywire bus over TCP, and a client of such servers.
//!
//! Text messages between `<` and `>`: the server greets with `< hi >`; the client opens a bus
//! (`< open NAME >` → `< ok >`) and is then in BCM mode; `< rawmode >` switches to raw mode, in
//! which every frame goes to the client as `< frame ID SECS.USECS DATA >` and
//! `< send ID LEN B0 B1 ... >` puts one on the bus. BCM mode: `< add SECS USECS ID LEN B... >`
//! sends a frame cyclically, `< update ... >` changes its data, `< delete ID >` stops it,
//! `< subscribe SECS USECS ID >` forwards that identifier (at most once per interval when one
//! is given), `< unsubscribe ID >` stops it, `< filter SECS USECS ID LEN B... >` forwards it when
//! the bits under the mask B... change. `< echo >` is answered with `< echo >`. Anything
//! malformed gets `< error TEXT >` and the session goes on.
//!
//! Each client gets its own endpoint on the served bus and its own bounded output queue: a
//! slow client loses frames (counted) and never stalls the bus or the other clients. Raw mode
//! has no transmit confirmation, no FD and no error frames.
//!
//! - [`protocol`]: the messages' text;
//! - [`session`]: one client's session as a state machine;
//! - [`server`]: the accept loop and the threads that carry a session's bytes, with limits;
//! - [`client`]: the `socketcand:` bus backend;
//! - [`beacon`]: the discovery beacon.

pub mod beacon;
pub mod client;
pub mod config;
pub mod protocol;
pub mod server;
pub mod session;

pub use beacon::beacon_xml;
pub use client::Client;
pub use config::{Access, Config, Limits, ServerStats};
pub use protocol::{format_frame, parse_command, parse_frame, Command};
pub use server::{OpenBus, Server, CLIENT_QUEUE};
