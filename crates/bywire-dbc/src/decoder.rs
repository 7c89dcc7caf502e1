//! A whole database compiled for decoding frames: each message's codec, found by identifier,
//! and what a decoded signal's value description is (looked up by its raw value, the sign
//! applied, as cantools does).
//!
//! ```
//! use bywire_core::{Frame, Id};
//! use bywire_dbc::decoder::Decoder;
//!
//! let text = "BO_ 256 Cmd: 2 ADS\n SG_ Mode : 0|2@1+ (1,1) [1|4] \"\" ECU\nVAL_ 256 Mode 1 \"Auto\" 2 \"Manual\";\n";
//! let decoder = Decoder::new(bywire_dbc::parse_str(text, bywire_dbc::Mode::Strict).unwrap().0);
//! let frame = Frame::classic(Id::standard(256).unwrap(), &[1, 0]).unwrap();
//! let decoded = decoder.decode(&frame).unwrap();
//! // Raw 1 is "Auto" (its physical value is 2, because of the offset).
//! assert_eq!(decoded.signals[0].description(), Some("Auto"));
//! assert_eq!(decoded.signals[0].value.physical.as_f64(), 2.0);
//! ```

use core::time::Duration;

use bywire_core::Frame;

use crate::codec::{DecodeError, Decoded, MessageCodec};
use crate::container::{split, ContainedPdu, ContainerError};
use crate::{Database, Message, Signal, ValueType};

/// One signal of a decoded frame.
#[derive(Debug, Clone, Copy)]
pub struct SignalValue<'a> {
    /// The signal.
    pub signal: &'a Signal,
    /// Its raw and physical value.
    pub value: Decoded,
}

impl SignalValue<'_> {
    /// The raw value as value descriptions number it: sign applied for signed integers; for a
    /// float, the raw float when it is integral (cantools looks a float's raw value up, before
    /// scaling).
    pub fn description_key(&self) -> Option<i128> {
        match self.signal.value_type {
            ValueType::Integer { signed: true } => {
                let unused = 64u32.saturating_sub(self.signal.length.clamp(1, 64));
                // Reinterpret the bits, then shift back arithmetically: sign extension.
                let bits = i64::from_ne_bytes((self.value.raw << unused).to_ne_bytes());
                Some(i128::from(bits >> unused))
            }
            ValueType::Integer { signed: false } => Some(i128::from(self.value.raw)),
            ValueType::Float32 => {
                let bits = u32::try_from(self.value.raw & u64::from(u32::MAX)).unwrap_or(0);
                integral(f64::from(f32::from_bits(bits)))
            }
            ValueType::Float64 => integral(f64::from_bits(self.value.raw)),
        }
    }

    /// The value's description (`VAL_`), if it has one.
    pub fn description(&self) -> Option<&str> {
        let key = self.description_key()?;
        self.signal
            .value_descriptions
            .iter()
            .find(|(k, _)| *k == key)
            .map(|(_, name)| name.as_str())
    }
}

/// A float that is a whole number within i64, as that integer.
pub(crate) fn integral(value: f64) -> Option<i128> {
    // i64's range as floats: -2^63 is exact, 2^63 is the first float past the top.
    const LIMIT: f64 = 9_223_372_036_854_775_808.0;
    #[allow(clippy::cast_possible_truncation)]
    (value.fract() == 0.0 && (-LIMIT..LIMIT).contains(&value)).then(|| i128::from(value as i64))
}

/// A frame decoded with its message.
#[derive(Debug, Clone)]
pub struct DecodedFrame<'a> {
    /// The message.
    pub message: &'a Message,
    /// The signals present in this frame (multiplexed ones only when selected).
    pub signals: Vec<SignalValue<'a>>,
    /// Why decoding failed (e.g. the frame is shorter than the message).
    pub error: Option<String>,
}

/// The signals of `message` that `values` (one slot a signal, as a codec decodes) holds a
/// value for.
pub fn signal_values<'a, 'v>(
    message: &'a Message,
    values: &'v [Option<Decoded>],
) -> impl Iterator<Item = SignalValue<'a>> + use<'a, 'v> {
    message
        .signals
        .iter()
        .zip(values)
        .filter_map(|(signal, value)| {
            Some(SignalValue {
                signal,
                value: (*value)?,
            })
        })
}

/// The names a message's signals go by in tables and JSON, in signal order: each signal's
/// display name, and a name used twice (a warning when the DBC loads) as `NAME#2`, `NAME#3`.
pub fn field_names(message: &Message) -> Vec<String> {
    let mut names: Vec<String> = Vec::with_capacity(message.signals.len());
    for signal in &message.signals {
        let name = signal.display_name();
        let unique = (1..=message.signals.len())
            .map(|n| match n {
                1 => name.to_string(),
                n => format!("{name}#{n}"),
            })
            .find(|candidate| !names.contains(candidate))
            .unwrap_or_else(|| name.to_string());
        names.push(unique);
    }
    names
}

/// A database compiled for decoding.
#[derive(Debug, Clone)]
pub struct Decoder {
    db: Database,
    codecs: Vec<MessageCodec>,
    /// Message index by standard identifier (0x000–0x7FF): one load, no hashing (profiled:
    /// SipHash on every frame was a fifth of decoding's time).
    standard: Vec<Option<usize>>,
    /// Extended identifiers with their message index, sorted for binary search.
    extended: Vec<(u32, usize)>,
    /// Container frames: their message's index, the container's index in the database and
    /// its first PDU's index in [`Decoder::message_at`]'s numbering.
    containers: Vec<(usize, usize, usize)>,
    /// Each container's PDUs' codecs, in the database's order.
    contained_codecs: Vec<Vec<MessageCodec>>,
}

/// One PDU of a container frame, with its message and codec when the database knows its
/// header identifier.
#[derive(Debug, Clone, Copy)]
pub struct Contained<'a, 'd> {
    /// The PDU's header identifier and bytes.
    pub pdu: ContainedPdu<'d>,
    /// Its message (a PDU of the container) and codec, and the message's index in
    /// [`Decoder::message_at`]'s numbering.
    pub message: Option<(&'a Message, &'a MessageCodec, usize)>,
}

/// Standard identifiers: 11 bits.
const STANDARD_IDS: usize = 0x800;

impl Decoder {
    /// Compile every message of `db`.
    pub fn new(db: Database) -> Self {
        let codecs = db.messages.iter().map(MessageCodec::new).collect();
        // Two messages with one identifier: the first is the one, as the parser's diagnostic
        // says.
        let mut standard = vec![None; STANDARD_IDS];
        let mut extended: Vec<(u32, usize)> = Vec::new();
        for (i, m) in db.messages.iter().enumerate() {
            if m.extended {
                extended.push((m.id, i));
            } else if let Some(slot) = usize::try_from(m.id)
                .ok()
                .and_then(|id| standard.get_mut(id))
            {
                slot.get_or_insert(i);
            }
        }
        // Stable: among equal identifiers the first message stays first.
        extended.sort_by_key(|(id, _)| *id);
        extended.dedup_by_key(|(id, _)| *id);
        let mut first = db.messages.len();
        let mut containers = Vec::new();
        for (c, container) in db.containers.iter().enumerate() {
            if let Some(index) = db.messages.iter().position(|m| m.name == container.message) {
                containers.push((index, c, first));
            }
            first += container.pdus.len();
        }
        let contained_codecs = db
            .containers
            .iter()
            .map(|c| c.pdus.iter().map(MessageCodec::new).collect())
            .collect();
        Decoder {
            db,
            codecs,
            standard,
            extended,
            containers,
            contained_codecs,
        }
    }

    /// Whether the message at `index` is a container frame.
    pub fn is_container(&self, index: usize) -> bool {
        self.containers.iter().any(|(i, ..)| *i == index)
    }

    /// The PDUs a frame of the container message at `index` carries, each with its message
    /// when known; `None` when that message is no container.
    pub fn contained<'s, 'd>(
        &'s self,
        index: usize,
        data: &'d [u8],
    ) -> Option<impl Iterator<Item = Result<Contained<'s, 'd>, ContainerError>> + use<'s, 'd>> {
        let &(_, c, first) = self.containers.iter().find(|(i, ..)| *i == index)?;
        let container = self.db.containers.get(c)?;
        let codecs = self.contained_codecs.get(c)?;
        Some(
            split(container.header, container.header_byte_order, data).map(move |pdu| {
                let pdu = pdu?;
                let message = container
                    .pdus
                    .iter()
                    .zip(codecs)
                    .enumerate()
                    .find(|(_, (m, _))| m.id == pdu.header_id)
                    .map(|(k, (m, codec))| (m, codec, first + k));
                Ok(Contained { pdu, message })
            }),
        )
    }

    /// The index of the message with identifier `raw` (extended or standard).
    fn index_of(&self, raw: u32, extended: bool) -> Option<usize> {
        if extended {
            let at = self
                .extended
                .binary_search_by_key(&raw, |(id, _)| *id)
                .ok()?;
            self.extended.get(at).map(|(_, index)| *index)
        } else {
            *self.standard.get(usize::try_from(raw).ok()?)?
        }
    }

    /// The database.
    pub fn database(&self) -> &Database {
        &self.db
    }

    /// The message at `index` and its codec: the database's messages, then every container's
    /// PDUs in order (numbered after the messages).
    pub fn message_at(&self, index: usize) -> Option<(&Message, &MessageCodec)> {
        if let Some(message) = self.db.messages.get(index) {
            return Some((message, self.codecs.get(index)?));
        }
        let mut k = index.checked_sub(self.db.messages.len())?;
        for (container, codecs) in self.db.containers.iter().zip(&self.contained_codecs) {
            if let (Some(pdu), Some(codec)) = (container.pdus.get(k), codecs.get(k)) {
                return Some((pdu, codec));
            }
            k = k.checked_sub(container.pdus.len())?;
        }
        None
    }

    /// How many messages [`Decoder::message_at`] numbers (messages and contained PDUs).
    pub fn message_count(&self) -> usize {
        self.db.messages.len()
            + self
                .db
                .containers
                .iter()
                .map(|c| c.pdus.len())
                .sum::<usize>()
    }

    /// The codec of `message` (a message of this database).
    pub fn codec(&self, message: &Message) -> Option<&MessageCodec> {
        let index = self.index_of(message.id, message.extended)?;
        self.codecs.get(index)
    }

    /// The message `frame` is (its index in the database, the message and its codec); `None`
    /// when no message has its identifier (or it is an error frame).
    fn lookup(&self, frame: &Frame) -> Option<(usize, &Message, &MessageCodec)> {
        let id = frame.id()?;
        self.message_with_id(id.as_raw(), id.is_extended())
    }

    /// The message `frame` is (its index in the database, the message and its codec) and the
    /// bytes it decodes from (none for a remote frame); `None` when no message has its
    /// identifier (or it is an error frame).
    pub fn message_of<'f>(
        &self,
        frame: &'f Frame,
    ) -> Option<(usize, &Message, &MessageCodec, &'f [u8])> {
        let (index, message, codec) = self.lookup(frame)?;
        let data = if frame.is_remote() {
            &[][..]
        } else {
            frame.data()
        };
        Some((index, message, codec, data))
    }

    /// The message with identifier `raw` (extended or standard): its index in the database, the
    /// message and its codec (for callers that hold identifiers, not frames: columns).
    pub fn message_with_id(
        &self,
        raw: u32,
        extended: bool,
    ) -> Option<(usize, &Message, &MessageCodec)> {
        let index = self.index_of(raw, extended)?;
        Some((index, self.db.messages.get(index)?, self.codecs.get(index)?))
    }

    /// Decode `frame` into `values`, one slot per signal of its message (resized here, so a
    /// caller that keeps the vector decodes without allocating; a remote frame decodes as no
    /// data): the message's index in the database, the message, and whether it decoded.
    /// `None` when no message has its identifier (or it is an error frame).
    pub fn decode_into(
        &self,
        frame: &Frame,
        values: &mut Vec<Option<Decoded>>,
    ) -> Option<(usize, &Message, Result<(), DecodeError>)> {
        let (index, message, codec, data) = self.message_of(frame)?;
        values.clear();
        values.resize(codec.signal_count(), None);
        Some((index, message, codec.decode(data, values)))
    }

    /// Decode `frame`; `None` when no message has its identifier (or it is an error frame). A
    /// container frame gives the signals of the PDUs it carries that the database knows, one
    /// after another.
    pub fn decode(&self, frame: &Frame) -> Option<DecodedFrame<'_>> {
        let mut values = Vec::new();
        let (index, message, decoded) = self.decode_into(frame, &mut values)?;
        if let Some(pdus) = self.contained(index, frame.data()) {
            let mut signals = Vec::new();
            let mut error = None;
            for pdu in pdus {
                let pdu = match pdu {
                    Ok(pdu) => pdu,
                    Err(e) => {
                        error = Some(e.to_string());
                        break;
                    }
                };
                let Some((pdu_message, codec, _)) = pdu.message else {
                    continue;
                };
                values.clear();
                values.resize(codec.signal_count(), None);
                // A PDU that does not decode adds nothing (its bytes are the frame's).
                if codec.decode(pdu.pdu.data, &mut values).is_err() {
                    continue;
                }
                signals.extend(signal_values(pdu_message, &values));
            }
            return Some(DecodedFrame {
                message,
                signals,
                error,
            });
        }
        let error = decoded.err().map(|e| e.to_string());
        let signals = signal_values(message, &values).collect();
        Some(DecodedFrame {
            message,
            signals,
            error,
        })
    }

    /// The message named `name` (or with identifier `name` in hex, `0x` optional).
    pub fn message_named(&self, name: &str) -> Option<&Message> {
        let by_id = u32::from_str_radix(name.trim_start_matches("0x"), 16).ok();
        self.db
            .messages
            .iter()
            .find(|m| m.name == name || m.display_name() == name)
            .or_else(|| by_id.and_then(|id| self.db.messages.iter().find(|m| m.id == id)))
    }

    /// The message's cycle time (`GenMsgCycleTime`), when it has a positive one.
    pub fn cycle_time(&self, message: &Message) -> Option<Duration> {
        self.db.cycle_time(message)
    }

    /// Whether the message is sent as CAN FD, and with bit rate switching
    /// ([`Database::fd_format`]).
    pub fn fd_format(&self, message: &Message) -> (bool, bool) {
        self.db.fd_format(message)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]

    use super::*;
    use bywire_core::Id;

    #[test]
    fn identifiers_find_the_first_message_with_them_standard_and_extended_apart() {
        let text = "BO_ 256 A: 1 X\n SG_ S : 0|8@1+ (1,0) [0|0] \"\" X\n\
                    BO_ 256 B: 1 X\n SG_ S : 0|8@1+ (1,0) [0|0] \"\" X\n\
                    BO_ 2147483904 C: 1 X\n SG_ S : 0|8@1+ (1,0) [0|0] \"\" X\n\
                    BO_ 2147483904 D: 1 X\n SG_ S : 0|8@1+ (1,0) [0|0] \"\" X\n\
                    BO_ 2047 E: 1 X\n SG_ S : 0|8@1+ (1,0) [0|0] \"\" X\n";
        let decoder = Decoder::new(crate::parse_str(text, crate::Mode::Lenient).unwrap().0);
        let name = |raw: u32, extended: bool| {
            decoder
                .message_with_id(raw, extended)
                .map(|(_, m, _)| m.name.clone())
        };
        assert_eq!(name(256, false).as_deref(), Some("A"));
        assert_eq!(name(256, true).as_deref(), Some("C"));
        assert_eq!(name(2047, false).as_deref(), Some("E"));
        assert_eq!(name(2047, true), None);
        assert_eq!(name(0x800, false), None);
        assert_eq!(name(u32::MAX, false), None);
        assert_eq!(name(u32::MAX, true), None);
    }

    #[test]
    fn a_container_frame_decodes_to_its_pdus_signals() {
        let text = include_str!("../../../examples/data/powertrain.arxml");
        let (db, _) =
            crate::format::load(text.as_bytes(), crate::Format::Arxml, crate::Mode::Strict)
                .unwrap();
        let decoder = Decoder::new(db);
        let data = [
            0, 0, 0x10, 1, 2, 0, 0, 0x20, 6, 0x85, 0xFF, 1, 2, 3, 4, 0, 0, 0x10, 1, 1,
        ];
        let frame = Frame::fd(Id::standard(0x300).unwrap(), &data, false, false).unwrap();
        let decoded = decoder.decode(&frame).unwrap();
        assert_eq!(decoded.message.name, "Bundle");
        let names: Vec<&str> = decoded
            .signals
            .iter()
            .map(|s| s.signal.name.as_str())
            .collect();
        assert_eq!(
            names,
            [
                "Beam",
                "Angle",
                "Steer_Freshness",
                "Steer_Authenticator",
                "Beam"
            ]
        );
        assert_eq!(decoded.signals[1].value.physical.as_f64(), -12.3);
        assert!(decoded.error.is_none());
        // A header that claims more than the frame holds: the PDUs before it, and the error.
        let mut cut = data;
        cut[8] = 60;
        let frame = Frame::fd(Id::standard(0x300).unwrap(), &cut, false, false).unwrap();
        let decoded = decoder.decode(&frame).unwrap();
        assert_eq!(decoded.signals.len(), 1);
        assert!(decoded.error.unwrap().contains("claims 60 bytes"));
    }

    #[test]
    fn of_two_messages_with_one_identifier_the_first_decodes() {
        let text = "BO_ 256 First: 1 X\n SG_ A : 0|8@1+ (1,0) [0|0] \"\" X\nBO_ 256 Second: 1 X\n SG_ B : 0|8@1+ (1,0) [0|0] \"\" X\n";
        let (db, diagnostics) = crate::parse_str(text, crate::Mode::Lenient).unwrap();
        assert!(diagnostics[0].resolution.contains("lookups find the first"));
        let decoder = Decoder::new(db);
        let frame = Frame::classic(Id::standard(256).unwrap(), &[7]).unwrap();
        assert_eq!(decoder.decode(&frame).unwrap().message.name, "First");
    }
}
