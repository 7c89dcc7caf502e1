//! The object dictionary: typed entries with access rights, limits and PDO mappability.
//!
//! Values are kept as the little-endian bytes they have on the wire, each in a buffer sized
//! when the entry is created, so reads and writes after start never allocate.

use alloc::format;
use alloc::string::{String, ToString};
use alloc::vec::Vec;
use core::fmt;

use crate::abort::Abort;

/// A CiA 301 data type.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DataType {
    /// BOOLEAN (0x0001), one byte on the wire.
    Boolean,
    /// INTEGER8..INTEGER64 (0x0002-0x0004, 0x0010, 0x0012-0x0015): `bytes` wide, signed.
    Integer(u8),
    /// UNSIGNED8..UNSIGNED64 (0x0005-0x0007, 0x0016, 0x0018-0x001B): `bytes` wide.
    Unsigned(u8),
    /// REAL32 (0x0008).
    Real32,
    /// REAL64 (0x0011).
    Real64,
    /// VISIBLE_STRING (0x0009).
    VisibleString,
    /// OCTET_STRING (0x000A).
    OctetString,
    /// UNICODE_STRING (0x000B).
    UnicodeString,
    /// DOMAIN (0x000F): any number of bytes.
    Domain,
}

/// The shorthands code uses most.
impl DataType {
    /// UNSIGNED8.
    pub const U8: DataType = DataType::Unsigned(1);
    /// UNSIGNED16.
    pub const U16: DataType = DataType::Unsigned(2);
    /// UNSIGNED32.
    pub const U32: DataType = DataType::Unsigned(4);
    /// INTEGER8.
    pub const I8: DataType = DataType::Integer(1);
    /// INTEGER16.
    pub const I16: DataType = DataType::Integer(2);
    /// INTEGER32.
    pub const I32: DataType = DataType::Integer(4);

    /// The type a CiA 301 data type index names (the `DataType=` of an EDS).
    pub fn from_code(code: u16) -> Option<DataType> {
        Some(match code {
            0x01 => DataType::Boolean,
            0x02 => DataType::Integer(1),
            0x03 => DataType::Integer(2),
            0x04 => DataType::Integer(4),
            0x10 => DataType::Integer(3),
            0x12 => DataType::Integer(5),
            0x13 => DataType::Integer(6),
            0x14 => DataType::Integer(7),
            0x15 => DataType::Integer(8),
            0x05 => DataType::Unsigned(1),
            0x06 => DataType::Unsigned(2),
            0x07 => DataType::Unsigned(4),
            0x16 => DataType::Unsigned(3),
            0x18 => DataType::Unsigned(5),
            0x19 => DataType::Unsigned(6),
            0x1A => DataType::Unsigned(7),
            0x1B => DataType::Unsigned(8),
            0x08 => DataType::Real32,
            0x11 => DataType::Real64,
            0x09 => DataType::VisibleString,
            0x0A => DataType::OctetString,
            0x0B => DataType::UnicodeString,
            0x0F => DataType::Domain,
            _ => return None,
        })
    }

    /// The data type index (inverse of [`DataType::from_code`]).
    pub fn code(self) -> u16 {
        match self {
            DataType::Boolean => 0x01,
            DataType::Integer(1) => 0x02,
            DataType::Integer(2) => 0x03,
            DataType::Integer(3) => 0x10,
            DataType::Integer(4) => 0x04,
            DataType::Integer(5) => 0x12,
            DataType::Integer(6) => 0x13,
            DataType::Integer(7) => 0x14,
            DataType::Integer(_) => 0x15,
            DataType::Unsigned(1) => 0x05,
            DataType::Unsigned(2) => 0x06,
            DataType::Unsigned(3) => 0x16,
            DataType::Unsigned(4) => 0x07,
            DataType::Unsigned(5) => 0x18,
            DataType::Unsigned(6) => 0x19,
            DataType::Unsigned(7) => 0x1A,
            DataType::Unsigned(_) => 0x1B,
            DataType::Real32 => 0x08,
            DataType::Real64 => 0x11,
            DataType::VisibleString => 0x09,
            DataType::OctetString => 0x0A,
            DataType::UnicodeString => 0x0B,
            DataType::Domain => 0x0F,
        }
    }

    /// Bytes on the wire for fixed-size types; `None` for strings and domains.
    pub fn size(self) -> Option<usize> {
        match self {
            DataType::Boolean => Some(1),
            DataType::Integer(bytes) | DataType::Unsigned(bytes) => Some(usize::from(bytes)),
            DataType::Real32 => Some(4),
            DataType::Real64 => Some(8),
            DataType::VisibleString
            | DataType::OctetString
            | DataType::UnicodeString
            | DataType::Domain => None,
        }
    }

    /// Parse a value written as text: integers in decimal or `0x` hex (negative for signed
    /// types), reals, `true`/`false`, strings as they are, octet strings and domains as hex
    /// bytes (`DE AD` or `DEAD`).
    pub fn parse(self, text: &str) -> Result<Vec<u8>, String> {
        let text = text.trim();
        match self {
            DataType::Boolean => match text {
                "1" | "true" | "TRUE" | "True" => Ok(alloc::vec![1]),
                "0" | "false" | "FALSE" | "False" => Ok(alloc::vec![0]),
                _ => Err(format!("'{text}' is not a boolean (0, 1, true, false)")),
            },
            DataType::Integer(bytes) => {
                let value = parse_int(text).ok_or_else(|| format!("'{text}' is not an integer"))?;
                let bits = u32::from(bytes) * 8;
                let min = -(1i128 << (bits - 1));
                let max = (1i128 << (bits - 1)) - 1;
                if value < min || value > max {
                    return Err(format!(
                        "{value} does not fit INTEGER{bits} ({min}..={max})"
                    ));
                }
                Ok(value
                    .to_le_bytes()
                    .iter()
                    .take(usize::from(bytes))
                    .copied()
                    .collect())
            }
            DataType::Unsigned(bytes) => {
                let value = parse_int(text).ok_or_else(|| format!("'{text}' is not an integer"))?;
                let bits = u32::from(bytes) * 8;
                let max = (1i128 << bits) - 1;
                if value < 0 || value > max {
                    return Err(format!("{value} does not fit UNSIGNED{bits} (0..={max})"));
                }
                Ok(value
                    .to_le_bytes()
                    .iter()
                    .take(usize::from(bytes))
                    .copied()
                    .collect())
            }
            DataType::Real32 => text
                .parse::<f32>()
                .map(|v| v.to_le_bytes().to_vec())
                .map_err(|_| format!("'{text}' is not a number")),
            DataType::Real64 => text
                .parse::<f64>()
                .map(|v| v.to_le_bytes().to_vec())
                .map_err(|_| format!("'{text}' is not a number")),
            DataType::VisibleString => Ok(text.as_bytes().to_vec()),
            DataType::UnicodeString => Ok(text.encode_utf16().flat_map(u16::to_le_bytes).collect()),
            DataType::OctetString | DataType::Domain => parse_hex_bytes(text),
        }
    }

    /// A value's bytes as text, the way [`DataType::parse`] reads it back.
    pub fn format(self, bytes: &[u8]) -> String {
        match (self, Number::decode(self, bytes)) {
            (DataType::VisibleString, _) => String::from_utf8_lossy(bytes).into_owned(),
            (DataType::UnicodeString, _) => {
                let units: Vec<u16> = bytes
                    .chunks_exact(2)
                    .map(|pair| {
                        u16::from_le_bytes([
                            pair.first().copied().unwrap_or(0),
                            pair.get(1).copied().unwrap_or(0),
                        ])
                    })
                    .collect();
                String::from_utf16_lossy(&units)
            }
            (_, Some(number)) => number.to_string(),
            _ => bytes
                .iter()
                .map(|b| format!("{b:02X}"))
                .collect::<Vec<_>>()
                .join(" "),
        }
    }
}

/// An integer in decimal, `0x` hex, or `0` octal-free decimal; with an optional sign.
pub(crate) fn parse_int(text: &str) -> Option<i128> {
    let (negative, digits) = match text.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, text.strip_prefix('+').unwrap_or(text)),
    };
    let magnitude = match digits
        .strip_prefix("0x")
        .or_else(|| digits.strip_prefix("0X"))
    {
        Some(hex) => i128::from_str_radix(hex, 16).ok()?,
        None => digits.parse::<i128>().ok()?,
    };
    Some(if negative { -magnitude } else { magnitude })
}

fn parse_hex_bytes(text: &str) -> Result<Vec<u8>, String> {
    let digits: String = text.chars().filter(|c| !c.is_whitespace()).collect();
    let digits = digits.strip_prefix("0x").unwrap_or(&digits);
    if !digits.len().is_multiple_of(2) {
        return Err(format!("'{text}' is not a whole number of hex bytes"));
    }
    (0..digits.len() / 2)
        .map(|i| {
            digits
                .get(2 * i..2 * i + 2)
                .and_then(|pair| u8::from_str_radix(pair, 16).ok())
                .ok_or_else(|| format!("'{text}' is not hex bytes"))
        })
        .collect()
}

impl fmt::Display for DataType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DataType::Boolean => write!(f, "BOOLEAN"),
            DataType::Integer(bytes) => write!(f, "INTEGER{}", u32::from(*bytes) * 8),
            DataType::Unsigned(bytes) => write!(f, "UNSIGNED{}", u32::from(*bytes) * 8),
            DataType::Real32 => write!(f, "REAL32"),
            DataType::Real64 => write!(f, "REAL64"),
            DataType::VisibleString => write!(f, "VISIBLE_STRING"),
            DataType::OctetString => write!(f, "OCTET_STRING"),
            DataType::UnicodeString => write!(f, "UNICODE_STRING"),
            DataType::Domain => write!(f, "DOMAIN"),
        }
    }
}

/// A numeric value decoded from its bytes, for limits and display.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Number {
    /// A signed integer (and BOOLEAN).
    Int(i64),
    /// An unsigned integer.
    Uint(u64),
    /// A real.
    Real(f64),
}

impl Number {
    /// Decode `bytes` as `data_type`; `None` for non-numeric types or a wrong length.
    pub fn decode(data_type: DataType, bytes: &[u8]) -> Option<Number> {
        if Some(bytes.len()) != data_type.size() {
            return None;
        }
        let mut wide = [0u8; 8];
        wide.get_mut(..bytes.len())?.copy_from_slice(bytes);
        match data_type {
            DataType::Boolean => Some(Number::Int(i64::from(bytes.first().copied()? != 0))),
            DataType::Unsigned(_) => Some(Number::Uint(u64::from_le_bytes(wide))),
            DataType::Integer(width) => {
                let shift = 64 - u32::from(width) * 8;
                let raw = i64::from_le_bytes(wide);
                Some(Number::Int(raw.wrapping_shl(shift).wrapping_shr(shift)))
            }
            DataType::Real32 => {
                let raw: [u8; 4] = bytes.try_into().ok()?;
                Some(Number::Real(f64::from(f32::from_le_bytes(raw))))
            }
            DataType::Real64 => Some(Number::Real(f64::from_le_bytes(wide))),
            DataType::VisibleString
            | DataType::OctetString
            | DataType::UnicodeString
            | DataType::Domain => None,
        }
    }

    /// As a wide signed value for comparisons (reals compare as reals).
    fn compare(self, other: Number) -> Option<core::cmp::Ordering> {
        match (self, other) {
            (Number::Real(a), b) => a.partial_cmp(&b.as_f64()),
            (a, Number::Real(b)) => a.as_f64().partial_cmp(&b),
            (a, b) => Some(a.as_i128().cmp(&b.as_i128())),
        }
    }

    fn as_i128(self) -> i128 {
        match self {
            Number::Int(v) => i128::from(v),
            Number::Uint(v) => i128::from(v),
            // Reals never reach here (see `compare`).
            Number::Real(_) => 0,
        }
    }

    /// As an `f64` (large integers round).
    #[allow(clippy::cast_precision_loss)]
    pub fn as_f64(self) -> f64 {
        match self {
            Number::Int(v) => v as f64,
            Number::Uint(v) => v as f64,
            Number::Real(v) => v,
        }
    }
}

impl fmt::Display for Number {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Number::Int(v) => write!(f, "{v}"),
            Number::Uint(v) => write!(f, "{v}"),
            Number::Real(v) => write!(f, "{v}"),
        }
    }
}

/// Who may read and write an entry over SDO (the device itself always may).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Access {
    /// Read only.
    ReadOnly,
    /// Write only.
    WriteOnly,
    /// Read and write.
    ReadWrite,
    /// Read and write; mapped into TPDOs (EDS `rwr`).
    ReadWriteRead,
    /// Read and write; mapped into RPDOs (EDS `rww`).
    ReadWriteWrite,
    /// Constant: read only, never changes.
    Const,
}

impl Access {
    /// Readable over SDO.
    pub fn readable(self) -> bool {
        !matches!(self, Access::WriteOnly)
    }

    /// Writable over SDO.
    pub fn writable(self) -> bool {
        matches!(
            self,
            Access::WriteOnly | Access::ReadWrite | Access::ReadWriteRead | Access::ReadWriteWrite
        )
    }

    /// The EDS spelling.
    pub fn eds_name(self) -> &'static str {
        match self {
            Access::ReadOnly => "ro",
            Access::WriteOnly => "wo",
            Access::ReadWrite => "rw",
            Access::ReadWriteRead => "rwr",
            Access::ReadWriteWrite => "rww",
            Access::Const => "const",
        }
    }

    /// Read an EDS `AccessType` (case-insensitive).
    pub fn from_eds(text: &str) -> Option<Access> {
        Some(match text.trim().to_ascii_lowercase().as_str() {
            "ro" => Access::ReadOnly,
            "wo" => Access::WriteOnly,
            "rw" => Access::ReadWrite,
            "rwr" => Access::ReadWriteRead,
            "rww" => Access::ReadWriteWrite,
            "const" => Access::Const,
            _ => return None,
        })
    }
}

/// One sub-index of an object.
#[derive(Debug, Clone, PartialEq)]
pub struct Entry {
    /// The sub-index.
    pub sub: u8,
    /// Its name (`ParameterName` in an EDS).
    pub name: String,
    /// Its type.
    pub data_type: DataType,
    /// SDO access.
    pub access: Access,
    /// May be mapped into a PDO.
    pub pdo_mappable: bool,
    /// Smallest value SDO may write.
    pub low: Option<Number>,
    /// Largest value SDO may write.
    pub high: Option<Number>,
    default: Vec<u8>,
    value: Vec<u8>,
    /// The dictionary's change count when the value last changed.
    changed: ChangeStamp,
}

/// When an entry's value last changed, as the dictionary's change count: history, not
/// content, so two entries are equal whatever their stamps.
#[derive(Debug, Clone, Copy, Default)]
struct ChangeStamp(u64);

impl PartialEq for ChangeStamp {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

/// Bytes reserved for a string or domain entry whose default is shorter.
const VARIABLE_CAPACITY: usize = 256;

impl Entry {
    /// An entry with every byte zero (or empty, for variable-length types).
    pub fn new(sub: u8, name: &str, data_type: DataType, access: Access) -> Entry {
        let default = alloc::vec![0; data_type.size().unwrap_or(0)];
        let mut value = Vec::with_capacity(data_type.size().unwrap_or(VARIABLE_CAPACITY));
        value.extend_from_slice(&default);
        Entry {
            sub,
            name: name.to_string(),
            data_type,
            access,
            pdo_mappable: false,
            low: None,
            high: None,
            default,
            value,
            changed: ChangeStamp::default(),
        }
    }

    /// Mark it PDO-mappable.
    pub fn mappable(mut self) -> Entry {
        self.pdo_mappable = true;
        self
    }

    /// Set its default (and present) value from bytes; for variable-length types the buffer
    /// grows to hold at least `VARIABLE_CAPACITY` bytes.
    pub fn with_default(mut self, bytes: &[u8]) -> Entry {
        self.default = bytes.to_vec();
        self.value = Vec::with_capacity(match self.data_type.size() {
            Some(size) => size,
            None => bytes.len().max(VARIABLE_CAPACITY),
        });
        self.value.extend_from_slice(bytes);
        self
    }

    /// Set its default from an integer (truncated to the type's width).
    pub fn with_int(self, value: i64) -> Entry {
        let width = self.data_type.size().unwrap_or(8).min(8);
        let bytes = value.to_le_bytes();
        self.with_default(bytes.get(..width).unwrap_or(&bytes))
    }

    /// Limit what SDO may write.
    pub fn with_limits(mut self, low: Option<Number>, high: Option<Number>) -> Entry {
        self.low = low;
        self.high = high;
        self
    }

    /// The present value's bytes.
    pub fn value(&self) -> &[u8] {
        &self.value
    }

    /// The default value's bytes.
    pub fn default_value(&self) -> &[u8] {
        &self.default
    }

    /// The present value as a number.
    pub fn number(&self) -> Option<Number> {
        Number::decode(self.data_type, &self.value)
    }

    /// Bytes this entry can hold.
    pub fn capacity(&self) -> usize {
        self.data_type.size().unwrap_or(self.value.capacity())
    }

    /// Check `bytes` as a new value: length and limits (not access).
    pub fn check(&self, bytes: &[u8]) -> Result<(), Abort> {
        match self.data_type.size() {
            Some(size) if bytes.len() > size => return Err(Abort::LengthTooHigh),
            Some(size) if bytes.len() < size => return Err(Abort::LengthTooLow),
            None if bytes.len() > self.capacity() => return Err(Abort::LengthTooHigh),
            _ => {}
        }
        // Only limits make the value itself matter.
        if self.low.is_none() && self.high.is_none() {
            return Ok(());
        }
        if let Some(value) = Number::decode(self.data_type, bytes) {
            if matches!(value, Number::Real(v) if v.is_nan()) {
                return Err(Abort::InvalidValue);
            }
            if let Some(low) = self.low {
                if value.compare(low) == Some(core::cmp::Ordering::Less) {
                    return Err(Abort::ValueTooLow);
                }
            }
            if let Some(high) = self.high {
                if value.compare(high) == Some(core::cmp::Ordering::Greater) {
                    return Err(Abort::ValueTooHigh);
                }
            }
        }
        Ok(())
    }

    /// Store `bytes` after [`Entry::check`]; never reallocates.
    fn store(&mut self, bytes: &[u8]) -> Result<(), Abort> {
        self.check(bytes)?;
        // A number is written over the one of its width in place (see `overwrite`); a value
        // of another length replaces it.
        let value = self.value.as_mut_slice();
        let overwritten = overwrite::<1>(value, bytes)
            || overwrite::<2>(value, bytes)
            || overwrite::<4>(value, bytes)
            || overwrite::<8>(value, bytes);
        if !overwritten {
            self.value.clear();
            self.value.extend_from_slice(bytes);
        }
        Ok(())
    }

    /// The dictionary's change count ([`ObjectDictionary::generation`]) when the value last
    /// changed (or the entry was added): a reader that looked at a generation since then has
    /// seen the value as it is.
    pub fn changed(&self) -> u64 {
        self.changed.0
    }

    fn restore(&mut self) {
        self.value.clear();
        let keep = self.default.len().min(self.value.capacity());
        self.value
            .extend_from_slice(self.default.get(..keep).unwrap_or(&[]));
    }
}

/// What kind of object an index holds (CiA 306 object codes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ObjectKind {
    /// A single value at sub-index 0 (object code 7).
    Var,
    /// Sub-indices of one type; sub 0 holds the count (object code 8).
    Array,
    /// Sub-indices of various types; sub 0 holds the highest sub-index (object code 9).
    Record,
}

impl ObjectKind {
    /// The CiA 306 object code.
    pub fn code(self) -> u8 {
        match self {
            ObjectKind::Var => 7,
            ObjectKind::Array => 8,
            ObjectKind::Record => 9,
        }
    }
}

/// One index of the dictionary with its sub-indices, sorted.
#[derive(Debug, Clone, PartialEq)]
pub struct Object {
    /// The index.
    pub index: u16,
    /// Its name.
    pub name: String,
    /// Var, array or record.
    pub kind: ObjectKind,
    entries: Vec<Entry>,
}

impl Object {
    /// Its sub-indices in order.
    pub fn entries(&self) -> &[Entry] {
        &self.entries
    }
}

/// Where an entry lives, for repeated access without searching (PDO mappings).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Slot {
    object: usize,
    entry: usize,
}

/// The object dictionary.
#[derive(Debug, Clone, Default)]
pub struct ObjectDictionary {
    objects: Vec<Object>,
    /// Counts changes (values or objects), so readers can tell nothing changed since they
    /// last looked without comparing values.
    generation: u64,
}

/// Dictionaries are equal when their objects are: the change count is not content.
impl PartialEq for ObjectDictionary {
    fn eq(&self, other: &Self) -> bool {
        self.objects == other.objects
    }
}

impl ObjectDictionary {
    /// An empty dictionary.
    pub fn new() -> ObjectDictionary {
        ObjectDictionary::default()
    }

    /// Add (or replace) a single-value object at sub-index 0.
    pub fn add_var(&mut self, index: u16, entry: Entry) {
        let name = entry.name.clone();
        self.add_object(
            index,
            &name,
            ObjectKind::Var,
            alloc::vec![Entry { sub: 0, ..entry }],
        );
    }

    /// Add (or replace) an array or record. Sub-index 0 ("highest sub-index supported") is
    /// added when `entries` has none.
    pub fn add_object(
        &mut self,
        index: u16,
        name: &str,
        kind: ObjectKind,
        mut entries: Vec<Entry>,
    ) {
        entries.sort_by_key(|entry| entry.sub);
        entries.dedup_by_key(|entry| entry.sub);
        if kind != ObjectKind::Var && entries.first().is_none_or(|entry| entry.sub != 0) {
            let highest = entries.last().map_or(0, |entry| entry.sub);
            entries.insert(
                0,
                Entry::new(
                    0,
                    "Highest sub-index supported",
                    DataType::U8,
                    Access::ReadOnly,
                )
                .with_int(i64::from(highest)),
            );
        }
        self.generation = self.generation.wrapping_add(1);
        for entry in &mut entries {
            entry.changed = ChangeStamp(self.generation);
        }
        let object = Object {
            index,
            name: name.to_string(),
            kind,
            entries,
        };
        match self.objects.binary_search_by_key(&index, |o| o.index) {
            Ok(at) => {
                if let Some(slot) = self.objects.get_mut(at) {
                    *slot = object;
                }
            }
            Err(at) => self.objects.insert(at, object),
        }
    }

    /// Every object in index order.
    pub fn objects(&self) -> &[Object] {
        &self.objects
    }

    /// The object at `index`.
    pub fn object(&self, index: u16) -> Option<&Object> {
        self.objects
            .binary_search_by_key(&index, |o| o.index)
            .ok()
            .and_then(|at| self.objects.get(at))
    }

    /// Where `index:sub` lives, or why it does not.
    pub fn locate(&self, index: u16, sub: u8) -> Result<Slot, Abort> {
        let object = self
            .objects
            .binary_search_by_key(&index, |o| o.index)
            .map_err(|_| Abort::NoObject)?;
        let entry = self
            .objects
            .get(object)
            .ok_or(Abort::NoObject)?
            .entries
            .binary_search_by_key(&sub, |e| e.sub)
            .map_err(|_| Abort::NoSubindex)?;
        Ok(Slot { object, entry })
    }

    /// Where `index:sub` lives, trying `hint` (a slot it was found at before) first: no search
    /// while the dictionary keeps its objects where they were.
    pub fn relocate(&self, hint: Slot, index: u16, sub: u8) -> Result<Slot, Abort> {
        let object = self.objects.get(hint.object);
        let still = object.is_some_and(|o| {
            o.index == index && o.entries.get(hint.entry).is_some_and(|e| e.sub == sub)
        });
        if still {
            Ok(hint)
        } else {
            self.locate(index, sub)
        }
    }

    /// The entry in a slot from [`ObjectDictionary::locate`].
    pub fn at(&self, slot: Slot) -> Option<&Entry> {
        self.objects.get(slot.object)?.entries.get(slot.entry)
    }

    fn at_mut(&mut self, slot: Slot) -> Option<&mut Entry> {
        self.objects
            .get_mut(slot.object)?
            .entries
            .get_mut(slot.entry)
    }

    /// The entry at `index:sub`.
    pub fn entry(&self, index: u16, sub: u8) -> Result<&Entry, Abort> {
        self.at(self.locate(index, sub)?).ok_or(Abort::NoObject)
    }

    /// Read as an SDO client would: refused for write-only entries.
    pub fn read(&self, index: u16, sub: u8) -> Result<&[u8], Abort> {
        let entry = self.entry(index, sub)?;
        if !entry.access.readable() {
            return Err(Abort::ReadWriteOnly);
        }
        Ok(entry.value())
    }

    /// Check a write as an SDO client would make it, without making it.
    pub fn check_write(&self, index: u16, sub: u8, bytes: &[u8]) -> Result<(), Abort> {
        let entry = self.entry(index, sub)?;
        if !entry.access.writable() {
            return Err(Abort::WriteReadOnly);
        }
        entry.check(bytes)
    }

    /// The device's own write: any access, length and limits still checked.
    pub fn set(&mut self, index: u16, sub: u8, bytes: &[u8]) -> Result<(), Abort> {
        let slot = self.locate(index, sub)?;
        self.set_at(slot, bytes)
    }

    /// [`ObjectDictionary::set`] through a slot.
    pub fn set_at(&mut self, slot: Slot, bytes: &[u8]) -> Result<(), Abort> {
        let generation = self.generation.wrapping_add(1);
        let entry = self.at_mut(slot).ok_or(Abort::NoObject)?;
        // The same value again changes nothing (and was checked when it was stored).
        if same_value(entry.value(), bytes) {
            return Ok(());
        }
        entry.store(bytes)?;
        entry.changed = ChangeStamp(generation);
        self.generation = generation;
        Ok(())
    }

    /// The change count: different after any change to a value or an object.
    pub fn generation(&self) -> u64 {
        self.generation
    }

    /// An unsigned value of up to 8 bytes, or `None` if absent or not unsigned/boolean.
    pub fn get_unsigned(&self, index: u16, sub: u8) -> Option<u64> {
        match self.entry(index, sub).ok()?.number()? {
            Number::Uint(v) => Some(v),
            Number::Int(v) => u64::try_from(v).ok(),
            Number::Real(_) => None,
        }
    }

    /// A signed value, or `None` if absent or not an integer.
    pub fn get_signed(&self, index: u16, sub: u8) -> Option<i64> {
        self.get_signed_at(self.locate(index, sub).ok()?)
    }

    /// [`ObjectDictionary::get_signed`] through a slot.
    pub fn get_signed_at(&self, slot: Slot) -> Option<i64> {
        match self.at(slot)?.number()? {
            Number::Int(v) => Some(v),
            Number::Uint(v) => i64::try_from(v).ok(),
            Number::Real(_) => None,
        }
    }

    /// Store an integer into an integer entry of any width (truncating to the width, which
    /// is the two's-complement encoding for in-range values).
    pub fn set_int(&mut self, index: u16, sub: u8, value: i64) -> Result<(), Abort> {
        let slot = self.locate(index, sub)?;
        self.set_int_at(slot, value)
    }

    /// [`ObjectDictionary::set_int`] through a slot.
    pub fn set_int_at(&mut self, slot: Slot, value: i64) -> Result<(), Abort> {
        let width = self
            .at(slot)
            .and_then(|entry| entry.data_type.size())
            .ok_or(Abort::LengthMismatch)?;
        let bytes = value.to_le_bytes();
        self.set_at(
            slot,
            bytes.get(..width.min(8)).ok_or(Abort::LengthMismatch)?,
        )
    }

    /// Restore the defaults of every entry whose index is in `range` (NMT resets).
    pub fn restore_defaults(&mut self, range: core::ops::RangeInclusive<u16>) {
        self.generation = self.generation.wrapping_add(1);
        for object in self.objects.iter_mut().filter(|o| range.contains(&o.index)) {
            for entry in &mut object.entries {
                entry.restore();
                entry.changed = ChangeStamp(self.generation);
            }
        }
    }
}

/// Whether two values are equal, those of 1, 2, 4 or 8 bytes (every number but the odd-width
/// integers) compared as one word: a library call to compare a few bytes costs more than the
/// comparison, and drives set their values every millisecond.
fn same_value(a: &[u8], b: &[u8]) -> bool {
    match (word(a), word(b)) {
        (Some(x), Some(y)) => a.len() == b.len() && x == y,
        _ => a == b,
    }
}

/// A value of 1, 2, 4 or 8 bytes as one little-endian word.
fn word(bytes: &[u8]) -> Option<u64> {
    Some(match *bytes {
        [a] => u64::from(a),
        [a, b] => u64::from(u16::from_le_bytes([a, b])),
        [a, b, c, d] => u64::from(u32::from_le_bytes([a, b, c, d])),
        [a, b, c, d, e, f, g, h] => u64::from_le_bytes([a, b, c, d, e, f, g, h]),
        _ => return None,
    })
}

/// Copy `from` over `to` when both are `N` bytes long: a copy of a size known when compiled,
/// where a copy of a run-time length is a library call costing more than a number's bytes.
fn overwrite<const N: usize>(to: &mut [u8], from: &[u8]) -> bool {
    match (<&mut [u8; N]>::try_from(to), <[u8; N]>::try_from(from)) {
        (Ok(to), Ok(from)) => {
            *to = from;
            true
        }
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values compare as slices do: every pair of short byte strings (a trailing zero makes a
    /// different value), and long ones.
    #[test]
    fn same_value_is_slice_equality() {
        let values: Vec<Vec<u8>> = (0..=10usize)
            .flat_map(|len| {
                [0u8, 1, 0xFF].map(|fill| {
                    let mut v = vec![fill; len];
                    if let Some(last) = v.last_mut() {
                        *last ^= 0x80;
                    }
                    v
                })
            })
            .chain([vec![1], vec![1, 0], vec![0; 9], vec![0; 8]])
            .collect();
        for a in &values {
            for b in &values {
                assert_eq!(same_value(a, b), a == b, "{a:?} {b:?}");
            }
        }
    }

    /// Whatever its width, a stored value reads back as stored: numbers of every width (those
    /// written over in place and the odd widths), and strings growing and shrinking.
    #[test]
    fn stored_values_read_back_at_every_width() {
        let mut od = ObjectDictionary::new();
        for width in 1..=8u8 {
            od.add_var(
                0x2100 + u16::from(width),
                Entry::new(0, "Number", DataType::Unsigned(width), Access::ReadWrite),
            );
        }
        od.add_var(
            0x2200,
            Entry::new(0, "Text", DataType::OctetString, Access::ReadWrite),
        );
        for width in 1..=8u8 {
            let index = 0x2100 + u16::from(width);
            for value in [0x0102_0304_0506_0708u64, 0, u64::MAX, 0x80] {
                let bytes = value.to_le_bytes();
                let bytes = &bytes[..usize::from(width)];
                od.set(index, 0, bytes).unwrap();
                assert_eq!(od.read(index, 0).unwrap(), bytes, "width {width}");
            }
        }
        for len in [3usize, 8, 0, 10, 1, 4, 2, 9, 8] {
            let bytes: Vec<u8> = (0..len)
                .map(|i| u8::try_from((i * 37 + len) % 256).unwrap())
                .collect();
            od.set(0x2200, 0, &bytes).unwrap();
            assert_eq!(
                od.read(0x2200, 0).unwrap(),
                bytes.as_slice(),
                "length {len}"
            );
        }
    }

    fn sample() -> ObjectDictionary {
        let mut od = ObjectDictionary::new();
        od.add_var(
            0x1000,
            Entry::new(0, "Device type", DataType::U32, Access::Const).with_int(0x0002_0192),
        );
        od.add_var(
            0x6040,
            Entry::new(0, "Controlword", DataType::U16, Access::ReadWrite).mappable(),
        );
        od.add_var(
            0x2000,
            Entry::new(0, "Limited", DataType::I16, Access::ReadWrite)
                .with_limits(Some(Number::Int(-1000)), Some(Number::Int(1000))),
        );
        od.add_object(
            0x1018,
            "Identity",
            ObjectKind::Record,
            alloc::vec![
                Entry::new(1, "Vendor-ID", DataType::U32, Access::ReadOnly).with_int(0x2F7),
                Entry::new(2, "Product code", DataType::U32, Access::ReadOnly),
            ],
        );
        od
    }

    #[test]
    fn the_change_count_moves_with_every_change_and_only_then() {
        let mut od = sample();
        let start = od.generation();
        od.set_int(0x6040, 0, 0x0F).unwrap();
        let after_write = od.generation();
        assert_ne!(after_write, start);
        // The same value again, and refused writes, change nothing.
        od.set_int(0x6040, 0, 0x0F).unwrap();
        assert_eq!(
            od.set(0x2000, 0, &2000i16.to_le_bytes()),
            Err(Abort::ValueTooHigh)
        );
        assert_eq!(od.set(0x6040, 0, &[1]), Err(Abort::LengthTooLow));
        assert_eq!(od.generation(), after_write);
        assert_eq!(od.get_unsigned(0x6040, 0), Some(0x0F));
        od.restore_defaults(0x6000..=0x6FFF);
        assert_ne!(od.generation(), after_write);
        assert_eq!(od.get_unsigned(0x6040, 0), Some(0));
        // Equality is of content, not of history.
        assert_eq!(od, sample());
    }

    #[test]
    fn an_entry_knows_when_its_value_last_changed() {
        let mut od = sample();
        let added = od.entry(0x6040, 0).unwrap().changed();
        od.set_int(0x2000, 0, 5).unwrap();
        // Another entry's change moves the count, not this entry's stamp.
        assert!(od.generation() > added);
        assert_eq!(od.entry(0x6040, 0).unwrap().changed(), added);
        od.set_int(0x6040, 0, 0x0F).unwrap();
        let written = od.entry(0x6040, 0).unwrap().changed();
        assert_eq!(written, od.generation());
        // The same value again, or a refused one, is no change.
        od.set_int(0x6040, 0, 0x0F).unwrap();
        assert!(od.set(0x6040, 0, &[1]).is_err());
        assert_eq!(od.entry(0x6040, 0).unwrap().changed(), written);
        // Restoring defaults, and replacing an object, change its entries.
        od.restore_defaults(0x6000..=0x6FFF);
        assert_eq!(od.entry(0x6040, 0).unwrap().changed(), od.generation());
        od.add_var(
            0x2000,
            Entry::new(0, "Replaced", DataType::I16, Access::ReadWrite),
        );
        assert_eq!(od.entry(0x2000, 0).unwrap().changed(), od.generation());
        // Stamps are history, not content.
        let mut other = sample();
        other.set_int(0x2000, 0, 5).unwrap();
        other.set_int(0x2000, 0, 0).unwrap();
        assert_ne!(other.entry(0x2000, 0).unwrap().changed(), 0);
        assert_eq!(sample(), other);
    }

    #[test]
    fn access_length_and_limits_give_their_abort_codes() {
        let mut od = sample();
        assert_eq!(od.read(0x1000, 0).unwrap(), &[0x92, 0x01, 0x02, 0x00]);
        assert_eq!(
            od.check_write(0x1000, 0, &[0; 4]),
            Err(Abort::WriteReadOnly)
        );
        assert_eq!(od.check_write(0x6040, 0, &[1]), Err(Abort::LengthTooLow));
        assert_eq!(
            od.check_write(0x6040, 0, &[1, 2, 3]),
            Err(Abort::LengthTooHigh)
        );
        assert_eq!(
            od.check_write(0x2000, 0, &1001i16.to_le_bytes()),
            Err(Abort::ValueTooHigh)
        );
        assert_eq!(
            od.check_write(0x2000, 0, &(-1001i16).to_le_bytes()),
            Err(Abort::ValueTooLow)
        );
        assert_eq!(od.check_write(0x2000, 0, &(-1000i16).to_le_bytes()), Ok(()));
        assert_eq!(od.read(0x1234, 0), Err(Abort::NoObject));
        assert_eq!(od.read(0x1018, 9), Err(Abort::NoSubindex));
        assert_eq!(od.get_unsigned(0x1018, 0), Some(2));
        od.set_int(0x2000, 0, -700).unwrap();
        assert_eq!(od.get_signed(0x2000, 0), Some(-700));
        od.restore_defaults(0x2000..=0x2000);
        assert_eq!(od.get_signed(0x2000, 0), Some(0));
    }

    #[test]
    fn a_slot_found_before_is_kept_until_the_objects_move() {
        let mut od = sample();
        let controlword = od.locate(0x6040, 0).unwrap();
        assert_eq!(od.relocate(controlword, 0x6040, 0), Ok(controlword));
        // A hint for another entry is not taken for this one.
        let identity = od.locate(0x1018, 2).unwrap();
        assert_eq!(od.relocate(identity, 0x6040, 0), Ok(controlword));
        assert_eq!(od.relocate(identity, 0x1018, 1), od.locate(0x1018, 1));
        // An object added before it moves it: the hint is stale and the search finds it.
        od.add_var(
            0x1001,
            Entry::new(0, "Error register", DataType::U8, Access::ReadOnly),
        );
        let moved = od.relocate(controlword, 0x6040, 0).unwrap();
        assert_ne!(moved, controlword);
        od.set_int_at(moved, 0x0F).unwrap();
        assert_eq!(od.get_unsigned(0x6040, 0), Some(0x0F));
        assert_eq!(od.relocate(moved, 0x6041, 0), Err(Abort::NoObject));
        assert_eq!(od.relocate(moved, 0x6040, 1), Err(Abort::NoSubindex));
    }

    #[test]
    fn values_without_limits_are_checked_for_length_only_and_real_limits_refuse_nan() {
        let mut od = sample();
        od.add_var(
            0x2001,
            Entry::new(0, "Unlimited real", DataType::Real32, Access::ReadWrite),
        );
        od.add_var(
            0x2002,
            Entry::new(0, "Limited real", DataType::Real32, Access::ReadWrite)
                .with_limits(Some(Number::Real(-1.0)), None),
        );
        let nan = f32::NAN.to_le_bytes();
        assert_eq!(od.set(0x2001, 0, &nan), Ok(()));
        assert_eq!(od.set(0x2001, 0, &[0; 3]), Err(Abort::LengthTooLow));
        assert_eq!(od.set(0x2002, 0, &nan), Err(Abort::InvalidValue));
        assert_eq!(
            od.set(0x2002, 0, &(-2.0f32).to_le_bytes()),
            Err(Abort::ValueTooLow)
        );
        assert_eq!(od.set(0x2002, 0, &(0.5f32).to_le_bytes()), Ok(()));
    }

    #[test]
    fn values_parse_and_format_by_type() {
        assert_eq!(DataType::I32.parse("-1").unwrap(), [0xFF; 4]);
        assert_eq!(DataType::U16.parse("0x1234").unwrap(), [0x34, 0x12]);
        assert!(DataType::U8
            .parse("256")
            .unwrap_err()
            .contains("does not fit UNSIGNED8"));
        assert!(DataType::I8.parse("-129").is_err());
        assert_eq!(DataType::Integer(3).format(&[0xFF, 0xFF, 0xFF]), "-1");
        assert_eq!(DataType::Domain.parse("de ad").unwrap(), [0xDE, 0xAD]);
        assert_eq!(DataType::Domain.format(&[0xDE, 0xAD]), "DE AD");
        assert_eq!(DataType::VisibleString.format(b"tug"), "tug");
        assert_eq!(DataType::Real32.format(&1.5f32.to_le_bytes()), "1.5");
        for code in 0..=0x20 {
            if let Some(data_type) = DataType::from_code(code) {
                assert_eq!(data_type.code(), code);
            }
        }
    }
}
