//! # bywire-dbc: DBC databases
//!
//! A DBC file describes a CAN network: its nodes, its messages (identifier, size, sender) and
//! the signals packed into them (start bit, length, byte order, sign, scale and offset, unit,
//! multiplexing), with comments, attributes (cycle times, start values, FD markers) and value
//! descriptions.
//!
//! - [`parse`] reads a file leniently or strictly ([`Mode`]): lenient mode loads what a
//!   reasonable engineer would accept and reports one [`Diagnostic`] per problem with
//!   line and column; strict mode fails on the first.
//! - [`write()`] writes a [`Database`] back as DBC text (load → write → load is equal).
//! - [`decoder`] compiles a whole database: frames found by identifier and decoded, value
//!   descriptions looked up by raw value.
//! - [`codec`] compiles each message once into a plan and decodes and encodes frames without
//!   allocating, with Python-compatible number semantics so results match cantools bit for bit.
//!
//! ```
//! let text = "BO_ 256 Cmd: 8 ADS\n SG_ Speed : 0|16@1+ (0.01,0) [0|100] \"m/s\" ECU\n";
//! let (db, diagnostics) = bywire_dbc::parse(text.as_bytes(), bywire_dbc::Mode::Lenient).unwrap();
//! assert!(diagnostics.is_empty());
//! let codec = bywire_dbc::codec::MessageCodec::new(&db.messages[0]);
//! let mut out = [None];
//! codec.decode(&[0x10, 0x27, 0, 0, 0, 0, 0, 0], &mut out).unwrap();
//! assert_eq!(out[0].unwrap().physical.as_f64(), 100.0);
//! ```

mod arxml;
mod cdd;
pub mod codec;
pub mod codegen;
pub mod condition;
pub mod container;
pub mod decoder;
pub mod e2e;
pub mod format;
pub mod json;
mod kcd;
mod lexer;
pub mod lint;
pub mod model;
pub mod named;
mod parser;
pub mod schedule;
#[cfg(feature = "secoc")]
pub mod secoc;
pub mod select;
mod sym;
mod writer;
mod xml;

pub use arxml::BUS_NAME;
pub use format::Format;
pub use model::*;
pub use parser::{parse, parse_str, Diagnostic, Mode, ParseError, Severity, INDEPENDENT_SIGNALS};
pub use writer::write;
