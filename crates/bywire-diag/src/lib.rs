//! Diagnostics as sans-IO nodes (`no_std` + `alloc`): frames and time in, frames out.
//!
//! - [`isotp`]: ISO-TP (ISO 15765-2), one channel between two addresses, classic and CAN FD.
//! - [`uds`]: a UDS (ISO 14229-1) server's request handling over an ISO-TP channel.
//! - [`client`]: a UDS client (the tester) over an ISO-TP channel, P2/P2* and S3 timed.
//! - [`describe`]: an ECU's DIDs and DTCs as a tester names them; J2012 DTC codes (read from
//!   a TOML file with the `toml` feature);
//! - [`tester`]: a tester's script: a session, an unlock, then one service, each request
//!   chosen once the answer to the one before is in.
//!
//! Two ISO-TP channels, a tester's and an ECU's, carry a 20-byte message across a first frame,
//! a flow control and consecutive frames, driven as a runner drives any node (each frame
//! handed to the other side, and confirmed to its sender):
//!
//! ```
//! use bywire_core::node::Node;
//! use bywire_core::{Id, Timestamp};
//! use bywire_diag::isotp::{IsoTp, IsoTpConfig, IsoTpEvent};
//!
//! let (tester_id, ecu_id) = (Id::standard(0x7E0).unwrap(), Id::standard(0x7E8).unwrap());
//! let mut tester = IsoTp::new(IsoTpConfig::new(tester_id, ecu_id));
//! let mut ecu = IsoTp::new(IsoTpConfig::new(ecu_id, tester_id));
//! let message: Vec<u8> = (1..=20).collect();
//! tester.send(&message).unwrap();
//! let mut received = None;
//! for ms in 0..100 {
//!     let now = Timestamp::from_millis(ms);
//!     let mut frames = Vec::new();
//!     Node::poll(&mut tester, now, &mut |port, f| frames.push((true, port, f)));
//!     Node::poll(&mut ecu, now, &mut |port, f| frames.push((false, port, f)));
//!     for (from_tester, port, frame) in frames {
//!         let (sender, receiver) =
//!             if from_tester { (&mut tester, &mut ecu) } else { (&mut ecu, &mut tester) };
//!         Node::on_sent(sender, now, port, &frame);
//!         Node::on_frame(receiver, now, port, &frame);
//!     }
//!     if let Some(IsoTpEvent::Received(data)) = ecu.next_event() {
//!         received = Some(data);
//!         break;
//!     }
//! }
//! assert_eq!(received, Some(message));
//! ```
#![no_std]

extern crate alloc;

pub mod client;
pub mod describe;
#[cfg(feature = "toml")]
pub mod describe_file;
pub mod isotp;
pub mod tester;
pub mod uds;
