//! Everything a DBC file carries. Every type is serde-serializable (`bywire dbc convert` writes
//! and reads JSON with it); positions are not serialized.

use core::time::Duration;
use std::fmt;

use serde::{Deserialize, Serialize};

/// A number as written in the file: integers stay integers (as cantools and Python keep them),
/// so that `(1,0)` scaling yields exact integer values and `(0.5,0)` floating ones.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Num {
    /// Written without a fraction or exponent.
    Int(i128),
    /// Anything else.
    Float(f64),
}

impl Num {
    /// The value as a float.
    pub fn as_f64(self) -> f64 {
        match self {
            // Integers in DBC files are far below 2^53 in practice; above, rounding is Python's.
            #[allow(clippy::cast_precision_loss)]
            Num::Int(i) => i as f64,
            Num::Float(f) => f,
        }
    }

    /// Whether the value is a whole number (Python's `float.is_integer()` for floats).
    pub fn is_integer(self) -> bool {
        match self {
            Num::Int(_) => true,
            Num::Float(f) => f.is_finite() && f.fract() == 0.0,
        }
    }
}

/// Integers as JSON integers (as a string beyond 64 bits), floats as JSON floats, so a number
/// keeps its kind through JSON.
impl Serialize for Num {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Num::Int(i) => match (i64::try_from(*i), u64::try_from(*i)) {
                (Ok(v), _) => s.serialize_i64(v),
                (_, Ok(v)) => s.serialize_u64(v),
                _ => s.serialize_str(&i.to_string()),
            },
            Num::Float(f) => s.serialize_f64(*f),
        }
    }
}

impl<'de> Deserialize<'de> for Num {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Num, D::Error> {
        struct Visitor;
        impl serde::de::Visitor<'_> for Visitor {
            type Value = Num;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a number")
            }
            fn visit_i64<E>(self, v: i64) -> Result<Num, E> {
                Ok(Num::Int(i128::from(v)))
            }
            fn visit_u64<E>(self, v: u64) -> Result<Num, E> {
                Ok(Num::Int(i128::from(v)))
            }
            fn visit_f64<E>(self, v: f64) -> Result<Num, E> {
                Ok(Num::Float(v))
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Num, E> {
                v.parse().map(Num::Int).map_err(E::custom)
            }
        }
        d.deserialize_any(Visitor)
    }
}

impl fmt::Display for Num {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Num::Int(i) => write!(f, "{i}"),
            // Debug keeps a fraction or exponent (1.0, 1e300), so the text reads back as a float.
            Num::Float(x) => write!(f, "{x:?}"),
        }
    }
}

/// Where something was defined in its file (line and column, 1-based; 0 when it was not read
/// from a file). Not part of a database's identity: two databases that differ only in where
/// their objects stood compare equal, so a written-back file loads to an equal database.
#[derive(Debug, Clone, Copy, Default, Eq)]
pub struct Position {
    /// 1-based line.
    pub line: u32,
    /// 1-based column.
    pub column: u32,
}

impl PartialEq for Position {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

/// Byte order of a signal.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum ByteOrder {
    /// `@1`: Intel, the start bit is the least significant bit.
    LittleEndian,
    /// `@0`: Motorola, the start bit is the most significant bit (sawtooth numbering).
    BigEndian,
}

/// How the raw bits are read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum ValueType {
    /// Two's complement (`-`) or unsigned (`+`) integer.
    Integer {
        /// Signed.
        signed: bool,
    },
    /// IEEE 754 single (`SIG_VALTYPE_ ... : 1`).
    Float32,
    /// IEEE 754 double (`SIG_VALTYPE_ ... : 2`).
    Float64,
}

/// A signal's role in multiplexing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Multiplexing {
    /// Always present.
    None,
    /// `M`: selects which multiplexed signals are present.
    Multiplexor,
    /// `mN`: present when the multiplexor has value N.
    Multiplexed(u64),
    /// `mNM`: present for value N of its multiplexor, and itself a multiplexor.
    MultiplexedMultiplexor(u64),
}

/// Extended multiplexing (`SG_MUL_VAL_`): the switch this signal depends on and the value ranges.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct MuxCondition {
    /// The multiplexor signal's name.
    pub switch: String,
    /// Inclusive ranges of the switch's raw value.
    pub ranges: Vec<(u64, u64)>,
}

/// An attribute value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum AttrValue {
    /// A number (INT, HEX, FLOAT, or an ENUM index).
    Number(Num),
    /// A string (STRING, or an ENUM given by name).
    Str(String),
}

/// A signal.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Signal {
    /// Name.
    pub name: String,
    /// Start bit (LSB for little endian, MSB in sawtooth numbering for big endian).
    pub start_bit: u32,
    /// Length in bits (1–64).
    pub length: u32,
    /// Byte order.
    pub byte_order: ByteOrder,
    /// Raw value type.
    pub value_type: ValueType,
    /// Scale.
    pub factor: Num,
    /// Offset.
    pub offset: Num,
    /// Minimum physical value.
    pub minimum: Num,
    /// Maximum physical value.
    pub maximum: Num,
    /// Unit.
    pub unit: String,
    /// Receiving nodes.
    pub receivers: Vec<String>,
    /// Simple multiplexing.
    pub multiplexing: Multiplexing,
    /// Extended multiplexing, when `SG_MUL_VAL_` gives it.
    pub mux_condition: Option<MuxCondition>,
    /// Comment.
    pub comment: Option<String>,
    /// Attribute values (`BA_ "name" SG_ ...`), in file order.
    pub attributes: Vec<(String, AttrValue)>,
    /// Value descriptions (`VAL_`).
    pub value_descriptions: Vec<(i128, String)>,
    /// Where the `SG_` statement stood.
    #[serde(skip)]
    pub position: Position,
}

/// A message.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Message {
    /// Identifier without the extended flag.
    pub id: u32,
    /// 29-bit identifier (bit 31 set in the file).
    pub extended: bool,
    /// Name.
    pub name: String,
    /// Size in bytes.
    pub size: u32,
    /// Transmitting node (`Vector__XXX` when none).
    pub transmitter: String,
    /// Further senders (`BO_TX_BU_`).
    pub senders: Vec<String>,
    /// Signals in file order.
    pub signals: Vec<Signal>,
    /// Comment.
    pub comment: Option<String>,
    /// Attribute values, in file order.
    pub attributes: Vec<(String, AttrValue)>,
    /// Where the `BO_` statement stood.
    #[serde(skip)]
    pub position: Position,
}

impl Message {
    /// The identifier as written in the file (bit 31 marks extended).
    pub fn raw_id(&self) -> u32 {
        if self.extended {
            self.id | 0x8000_0000
        } else {
            self.id
        }
    }

    /// An attribute's value on this message.
    pub fn attribute(&self, name: &str) -> Option<&AttrValue> {
        self.attributes
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v)
    }

    /// A signal by name.
    pub fn signal(&self, name: &str) -> Option<&Signal> {
        self.signals.iter().find(|s| s.name == name)
    }

    /// The full name: `SystemMessageLongSymbol` when the file gives one (DBC names are limited
    /// to 32 characters, longer ones live in that attribute), else the name.
    pub fn display_name(&self) -> &str {
        long_symbol(&self.attributes, "SystemMessageLongSymbol").unwrap_or(&self.name)
    }
}

fn long_symbol<'a>(attributes: &'a [(String, AttrValue)], key: &str) -> Option<&'a str> {
    attributes.iter().find_map(|(n, v)| match v {
        AttrValue::Str(s) if n == key && !s.is_empty() => Some(s.as_str()),
        _ => None,
    })
}

impl ValueType {
    /// The raw values an integer signal of `length` bits holds, as floats; `None` for float
    /// signals.
    pub fn raw_range(self, length: u32) -> Option<(f64, f64)> {
        let ValueType::Integer { signed } = self else {
            return None;
        };
        let bits = i32::try_from(length.clamp(1, 64)).unwrap_or(64);
        Some(if signed {
            (-(2f64.powi(bits - 1)), 2f64.powi(bits - 1) - 1.0)
        } else {
            (0.0, 2f64.powi(bits) - 1.0)
        })
    }
}

impl Signal {
    /// The signal's bits as absolute positions (byte × 8 + bit, bit 0 the LSB), in the order
    /// the DBC numbering walks them from the start bit: LSB first for little endian, MSB first
    /// for big endian (down through a byte, then on to the next byte's bit 7).
    pub fn bit_positions(&self) -> impl Iterator<Item = u32> + '_ {
        let mut pos = Some(self.start_bit);
        (0..self.length.min(512)).map_while(move |_| {
            let here = pos?;
            pos = match self.byte_order {
                ByteOrder::LittleEndian => here.checked_add(1),
                ByteOrder::BigEndian if here % 8 == 0 => here.checked_add(15),
                ByteOrder::BigEndian => here.checked_sub(1),
            };
            Some(here)
        })
    }

    /// The physical values the raw bits can express with this scaling (low, high); `None` for
    /// float signals.
    pub fn reachable_range(&self) -> Option<(f64, f64)> {
        let (lo, hi) = self.value_type.raw_range(self.length)?;
        let (factor, offset) = (self.factor.as_f64(), self.offset.as_f64());
        let (a, b) = (lo * factor + offset, hi * factor + offset);
        Some((a.min(b), a.max(b)))
    }

    /// The full name: `SystemSignalLongSymbol` when the file gives one, else the name.
    pub fn display_name(&self) -> &str {
        long_symbol(&self.attributes, "SystemSignalLongSymbol").unwrap_or(&self.name)
    }

    /// The start bit counted in network order (a big-endian signal's most significant bit
    /// renumbered byte by byte from the top): the key cantools orders a message's signals by,
    /// and where its bits begin in the payload read as one bit string.
    pub fn network_start_bit(&self) -> u32 {
        match self.byte_order {
            ByteOrder::LittleEndian => self.start_bit,
            ByteOrder::BigEndian => 8 * (self.start_bit / 8) + (7 - self.start_bit % 8),
        }
    }
}

/// A node (ECU).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Node {
    /// Name.
    pub name: String,
    /// Comment.
    pub comment: Option<String>,
    /// Attribute values.
    pub attributes: Vec<(String, AttrValue)>,
}

/// An environment variable (`EV_`), kept as declared.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EnvVar {
    /// Name.
    pub name: String,
    /// The declaration after the name, as written.
    pub definition: String,
    /// Comment.
    pub comment: Option<String>,
    /// Attribute values.
    pub attributes: Vec<(String, AttrValue)>,
    /// Value descriptions.
    pub value_descriptions: Vec<(i128, String)>,
}

/// What an attribute definition applies to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum AttrScope {
    /// The network (database).
    Network,
    /// `BU_`.
    Node,
    /// `BO_`.
    Message,
    /// `SG_`.
    Signal,
    /// `EV_`.
    EnvVar,
}

/// The type of an attribute.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum AttrType {
    /// `INT min max`.
    Int(Num, Num),
    /// `HEX min max`.
    Hex(Num, Num),
    /// `FLOAT min max`.
    Float(Num, Num),
    /// `STRING`.
    Str,
    /// `ENUM "a","b"`.
    Enum(Vec<String>),
}

/// An attribute definition (`BA_DEF_`) with its default (`BA_DEF_DEF_`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AttrDef {
    /// Scope.
    pub scope: AttrScope,
    /// Name.
    pub name: String,
    /// Type.
    pub kind: AttrType,
    /// Default value.
    pub default: Option<AttrValue>,
}

/// A signal group (`SIG_GROUP_`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SignalGroup {
    /// The message's identifier as written.
    pub message_raw_id: u32,
    /// Name.
    pub name: String,
    /// Repetitions.
    pub repetitions: u32,
    /// Member signals.
    pub signals: Vec<String>,
}

/// A whole database.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Database {
    /// `VERSION`.
    pub version: String,
    /// `NS_` symbols.
    pub new_symbols: Vec<String>,
    /// `BS_` contents as written (usually empty).
    pub bit_timing: String,
    /// `BU_`.
    pub nodes: Vec<Node>,
    /// `VAL_TABLE_`.
    pub value_tables: Vec<(String, Vec<(i128, String)>)>,
    /// `BO_` with their signals.
    pub messages: Vec<Message>,
    /// `EV_`.
    pub env_vars: Vec<EnvVar>,
    /// Network comment.
    pub comment: Option<String>,
    /// `BA_DEF_` / `BA_DEF_DEF_`.
    pub attribute_defs: Vec<AttrDef>,
    /// Network attribute values.
    pub attributes: Vec<(String, AttrValue)>,
    /// `SIG_GROUP_`.
    pub signal_groups: Vec<SignalGroup>,
    /// Statements this parser does not interpret, kept verbatim in file order.
    pub unknown: Vec<String>,
    /// Frames that carry other PDUs behind headers (AUTOSAR container PDUs; DBC has none).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub containers: Vec<Container>,
}

/// The header in front of each PDU in a container frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum ContainerHeader {
    /// A 3-byte identifier and a 1-byte length.
    Short,
    /// A 4-byte identifier and a 4-byte length.
    Long,
}

impl ContainerHeader {
    /// The header's bytes: (identifier, length).
    pub fn sizes(self) -> (usize, usize) {
        match self {
            ContainerHeader::Short => (3, 1),
            ContainerHeader::Long => (4, 4),
        }
    }
}

/// A frame that carries PDUs, each behind a header naming it and its length (an AUTOSAR
/// container I-PDU with dynamic layout): the frame is a message of the database without
/// signals; the PDUs it may carry are listed here.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Container {
    /// The name of the frame's message.
    pub message: String,
    /// The header's kind.
    pub header: ContainerHeader,
    /// The byte order of the header's fields.
    pub header_byte_order: ByteOrder,
    /// The PDUs the frame may carry: each a message whose `id` is its header identifier.
    pub pdus: Vec<Message>,
}

impl Database {
    /// A message by identifier and format.
    pub fn message(&self, id: u32, extended: bool) -> Option<&Message> {
        self.messages
            .iter()
            .find(|m| m.id == id && m.extended == extended)
    }

    /// A message by name.
    pub fn message_by_name(&self, name: &str) -> Option<&Message> {
        self.messages.iter().find(|m| m.name == name)
    }

    /// The network attribute value or, failing that, the definition's default.
    pub fn attribute_default(&self, name: &str) -> Option<&AttrValue> {
        self.attribute_defs
            .iter()
            .find(|d| d.name == name)
            .and_then(|d| d.default.as_ref())
    }

    /// A message's attribute as text, falling back to the file's default: an enum attribute
    /// by its value name, a number as written, a string as is.
    pub fn message_attribute_text(&self, message: &Message, name: &str) -> Option<String> {
        let value = message
            .attribute(name)
            .or_else(|| self.attribute_default(name))?;
        let def = self.attribute_defs.iter().find(|d| d.name == name);
        Some(match (value, def.map(|d| &d.kind)) {
            (AttrValue::Number(Num::Int(i)), Some(AttrType::Enum(names))) => usize::try_from(*i)
                .ok()
                .and_then(|i| names.get(i).cloned())
                .unwrap_or_else(|| i.to_string()),
            (AttrValue::Number(n), _) => n.to_string(),
            (AttrValue::Str(s), _) => s.clone(),
        })
    }

    /// A message attribute in milliseconds (`GenMsgCycleTime`, `GenMsgDelayTime`, …), when it
    /// is a positive number.
    pub fn message_attribute_ms(&self, message: &Message, name: &str) -> Option<Duration> {
        let ms: f64 = self.message_attribute_text(message, name)?.parse().ok()?;
        Duration::try_from_secs_f64(ms / 1000.0)
            .ok()
            .filter(|d| !d.is_zero())
    }

    /// The message's cycle time (`GenMsgCycleTime`), when it has a positive one.
    pub fn cycle_time(&self, message: &Message) -> Option<Duration> {
        self.message_attribute_ms(message, "GenMsgCycleTime")
    }

    /// Whether the message is sent as CAN FD (`VFrameFormat` says so, or it is over 8 bytes),
    /// and with bit rate switching.
    pub fn fd_format(&self, message: &Message) -> (bool, bool) {
        let format = self
            .message_attribute_text(message, "VFrameFormat")
            .unwrap_or_default();
        let fd = format.contains("FD") || message.size > 8;
        (fd, fd && !format.contains("NoBRS"))
    }
}

#[cfg(test)]
mod json_precision {
    #[test]
    fn floats_survive_json() {
        let text = serde_json::to_string(&super::Num::Float(0.39215686274509803)).unwrap();
        let back: super::Num = serde_json::from_str(&text).unwrap();
        assert_eq!(text, "0.39215686274509803");
        assert_eq!(back, super::Num::Float(0.39215686274509803));
    }
}
