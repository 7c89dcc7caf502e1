//! Rust code generation: a `no_std` module with one struct per message, for ECU code and for
//! `build.rs` scripts (`bywire_dbc::codegen::generate(&db)` returns the source text).
//!
//! Each message becomes a struct over its payload bytes with `ID`, `EXTENDED` and `SIZE`
//! constants, `from_bytes` / `as_bytes`, and per signal a raw getter, a physical getter (`f64`)
//! and a range-checked setter, and an exact raw setter (physical values pass through `f64`, which
//! holds raw values exactly only below 2^53). Bits are read and written one at a time by two small helpers, which
//! is slower than the compiled codec but obviously right for any layout and needs nothing but
//! `core`.

use std::collections::HashSet;
use std::fmt::Write;

use crate::model::{ByteOrder, Database, Message, Signal, ValueType};

const KEYWORDS: &[&str] = &[
    "as", "break", "const", "continue", "crate", "else", "enum", "extern", "false", "fn", "for",
    "if", "impl", "in", "let", "loop", "match", "mod", "move", "mut", "pub", "ref", "return",
    "self", "static", "struct", "super", "trait", "true", "type", "unsafe", "use", "where",
    "while", "async", "await", "dyn", "abstract", "become", "box", "do", "final", "macro",
    "override", "priv", "typeof", "unsized", "virtual", "yield", "try", "gen",
];

fn words(name: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut cur = String::new();
    let chars: Vec<char> = name.chars().collect();
    for (i, &c) in chars.iter().enumerate() {
        if !c.is_ascii_alphanumeric() {
            if !cur.is_empty() {
                out.push(std::mem::take(&mut cur));
            }
            continue;
        }
        let prev = i.checked_sub(1).and_then(|p| chars.get(p)).copied();
        let next = chars.get(i + 1).copied();
        let boundary = c.is_ascii_uppercase()
            && (prev.is_some_and(|p| p.is_ascii_lowercase() || p.is_ascii_digit())
                || (prev.is_some_and(|p| p.is_ascii_uppercase())
                    && next.is_some_and(|n| n.is_ascii_lowercase())));
        if boundary && !cur.is_empty() {
            out.push(std::mem::take(&mut cur));
        }
        cur.push(c);
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

fn snake(name: &str) -> String {
    let mut s = words(name)
        .iter()
        .map(|w| w.to_ascii_lowercase())
        .collect::<Vec<_>>()
        .join("_");
    if s.is_empty() || s.starts_with(|c: char| c.is_ascii_digit()) {
        s.insert(0, '_');
    }
    if KEYWORDS.contains(&s.as_str()) {
        s.push('_');
    }
    s
}

fn camel(name: &str) -> String {
    let mut s: String = words(name)
        .iter()
        .map(|w| {
            let lower = w.to_ascii_lowercase();
            let mut c = lower.chars();
            c.next()
                .map(|f| f.to_ascii_uppercase().to_string() + c.as_str())
                .unwrap_or_default()
        })
        .collect();
    if s.is_empty() || s.starts_with(|c: char| c.is_ascii_digit()) {
        s.insert(0, 'M');
    }
    s
}

/// A name not yet in `used`, derived from `base`.
fn unique(base: String, used: &mut HashSet<String>) -> String {
    let mut name = base.clone();
    let mut n = 2;
    while !used.insert(name.clone()) {
        name = format!("{base}_{n}");
        n += 1;
    }
    name
}

fn float(x: f64) -> String {
    if x.is_finite() {
        format!("{x:?}_f64")
    } else {
        "0.0_f64".into()
    }
}

const HELPERS: &str = r#"
/// A physical value outside a signal's declared range, or one its raw bits cannot hold.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutOfRange {
    /// The signal's name in the DBC file.
    pub signal: &'static str,
    /// The value refused.
    pub value: f64,
}

/// Bit `n` (LSB-first numbering within the signal) of a signal starting at `start`.
fn bit_position(start: u32, n: u32, len: u32, big_endian: bool) -> usize {
    if big_endian {
        // Walk from the MSB at `start` down the sawtooth numbering to bit `len - 1 - n`.
        let mut p = start;
        let mut k = len - 1;
        while k > n {
            p = if p % 8 == 0 { p + 15 } else { p - 1 };
            k -= 1;
        }
        p as usize
    } else {
        (start + n) as usize
    }
}

fn get_bits(data: &[u8], start: u32, len: u32, big_endian: bool) -> u64 {
    let mut raw = 0u64;
    for n in 0..len {
        let p = bit_position(start, n, len, big_endian);
        if data.get(p / 8).is_some_and(|b| (b >> (p % 8)) & 1 == 1) {
            raw |= 1 << n;
        }
    }
    raw
}

fn set_bits(data: &mut [u8], start: u32, len: u32, big_endian: bool, raw: u64) {
    for n in 0..len {
        let p = bit_position(start, n, len, big_endian);
        if let Some(b) = data.get_mut(p / 8) {
            if (raw >> n) & 1 == 1 {
                *b |= 1 << (p % 8);
            } else {
                *b &= !(1 << (p % 8));
            }
        }
    }
}

/// Round half to even (what the codec does), without std: exact for every f64, since values
/// of 2^52 and beyond are integers already.
fn round_half_even(x: f64) -> f64 {
    if !(x.abs() < 4_503_599_627_370_496.0) {
        return x;
    }
    let truncated = x as i64 as f64;
    let fraction = x - truncated;
    let step = if x < 0.0 { -1.0 } else { 1.0 };
    if fraction.abs() > 0.5 || (fraction.abs() == 0.5 && (truncated as i64) % 2 != 0) {
        truncated + step
    } else {
        truncated
    }
}

fn sign_extend(raw: u64, len: u32) -> i64 {
    let unused = 64 - len;
    ((raw << unused) as i64) >> unused
}
"#;

/// The Rust names generated for one message: its type and each signal's getter, in order
/// (`{getter}_raw` and `set_{getter}` go with each).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MessageNames {
    /// The struct's name.
    pub type_name: String,
    /// The physical getter of each signal.
    pub getters: Vec<String>,
}

/// The names [`generate`] uses, message by message (the independent-signals pseudo-message
/// excluded).
pub fn names(db: &Database) -> Vec<MessageNames> {
    let mut types = HashSet::new();
    db.messages
        .iter()
        .filter(|m| m.name != crate::INDEPENDENT_SIGNALS)
        .map(|m| {
            let mut used: HashSet<String> = ["from_bytes", "as_bytes", "default"]
                .iter()
                .map(|s| s.to_string())
                .collect();
            let getters = m
                .signals
                .iter()
                .map(|s| {
                    let name = unique(snake(s.display_name()), &mut used);
                    used.insert(format!("{name}_raw"));
                    used.insert(format!("set_{name}"));
                    used.insert(format!("set_{name}_raw"));
                    name
                })
                .collect();
            MessageNames {
                type_name: unique(camel(m.display_name()), &mut types),
                getters,
            }
        })
        .collect()
}

fn signal_code(o: &mut String, s: &Signal, name: &str) -> std::fmt::Result {
    let big = s.byte_order == ByteOrder::BigEndian;
    let (start, len) = (s.start_bit, s.length.clamp(1, 64));
    let (factor, offset) = (s.factor.as_f64(), s.offset.as_f64());
    let unit = if s.unit.is_empty() {
        String::new()
    } else {
        format!(" ({})", s.unit.replace('\n', " "))
    };
    writeln!(
        o,
        "    /// Set `{}` raw bits (masked to its width): exact, where the physical setter goes through f64.",
        s.display_name()
    )?;
    writeln!(o, "    pub fn set_{name}_raw(&mut self, raw: u64) {{ set_bits(&mut self.0, {start}, {len}, {big}, raw) }}")?;
    writeln!(o, "    /// `{}` raw bits.", s.display_name())?;
    writeln!(
        o,
        "    pub fn {name}_raw(&self) -> u64 {{ get_bits(&self.0, {start}, {len}, {big}) }}"
    )?;
    let (from_raw, to_raw) = match s.value_type {
        ValueType::Integer { signed: false } => (
            "self.{n}_raw() as f64".to_string(),
            "raw_f as u64".to_string(),
        ),
        ValueType::Integer { signed: true } => (
            format!("sign_extend(self.{{n}}_raw(), {len}) as f64"),
            "raw_f as i64 as u64".into(),
        ),
        ValueType::Float32 => (
            "f32::from_bits(self.{n}_raw() as u32) as f64".into(),
            "(raw_f as f32).to_bits() as u64".into(),
        ),
        ValueType::Float64 => (
            "f64::from_bits(self.{n}_raw())".into(),
            "raw_f.to_bits()".into(),
        ),
    };
    let from_raw = from_raw.replace("{n}", name);
    writeln!(o, "    /// `{}`{unit}: physical value.", s.display_name())?;
    writeln!(
        o,
        "    pub fn {name}(&self) -> f64 {{ {from_raw} * {} + {} }}",
        float(factor),
        float(offset)
    )?;
    let (min, max) = (s.minimum.as_f64(), s.maximum.as_f64());
    let declared = !(min == 0.0 && max == 0.0);
    let range_check = if declared {
        format!("!(value >= {} && value <= {})", float(min), float(max))
    } else {
        "!value.is_finite()".into()
    };
    let raw_limits = s.value_type.raw_range(len);
    writeln!(
        o,
        "    /// Set `{}`{unit}; refuses values outside its range or its raw width.",
        s.display_name()
    )?;
    writeln!(
        o,
        "    pub fn set_{name}(&mut self, value: f64) -> Result<(), OutOfRange> {{"
    )?;
    writeln!(
        o,
        "        let err = OutOfRange {{ signal: {:?}, value }};",
        s.display_name()
    )?;
    writeln!(o, "        if {range_check} {{ return Err(err); }}")?;
    let scaled = format!(
        "(value - {}) / {}",
        float(offset),
        float(if factor == 0.0 { 1.0 } else { factor })
    );
    if matches!(s.value_type, ValueType::Integer { .. }) {
        writeln!(o, "        let raw_f = round_half_even({scaled});")?;
    } else {
        writeln!(o, "        let raw_f = {scaled};")?;
    }
    if let Some((lo, hi)) = raw_limits {
        writeln!(
            o,
            "        if !(raw_f >= {} && raw_f <= {}) {{ return Err(err); }}",
            float(lo),
            float(hi)
        )?;
    }
    writeln!(
        o,
        "        set_bits(&mut self.0, {start}, {len}, {big}, {to_raw});"
    )?;
    writeln!(o, "        Ok(())")?;
    writeln!(o, "    }}")?;
    Ok(())
}

fn message_code(o: &mut String, m: &Message, names: &MessageNames) -> std::fmt::Result {
    let ty = &names.type_name;
    let size = m.size.min(64);
    writeln!(
        o,
        "\n/// `{}` (id {:#X}{}).",
        m.display_name(),
        m.id,
        if m.extended { ", extended" } else { "" }
    )?;
    writeln!(o, "#[derive(Debug, Clone, Copy, PartialEq, Eq)]")?;
    writeln!(o, "pub struct {ty}(pub [u8; {size}]);\n")?;
    writeln!(
        o,
        "impl Default for {ty} {{ fn default() -> Self {{ {ty}([0; {size}]) }} }}\n"
    )?;
    writeln!(o, "impl {ty} {{")?;
    writeln!(
        o,
        "    /// The identifier (without the extended flag).\n    pub const ID: u32 = {:#X};",
        m.id
    )?;
    writeln!(
        o,
        "    /// Whether the identifier is 29-bit.\n    pub const EXTENDED: bool = {};",
        m.extended
    )?;
    writeln!(
        o,
        "    /// Payload size in bytes.\n    pub const SIZE: usize = {size};"
    )?;
    writeln!(o, "    /// From a payload of at least `SIZE` bytes.")?;
    writeln!(o, "    pub fn from_bytes(data: &[u8]) -> Option<Self> {{ let mut m = Self::default(); m.0.copy_from_slice(data.get(..{size})?); Some(m) }}")?;
    writeln!(
        o,
        "    /// The payload.\n    pub fn as_bytes(&self) -> &[u8] {{ &self.0 }}"
    )?;
    for (s, name) in m.signals.iter().zip(&names.getters) {
        signal_code(o, s, name)?;
    }
    writeln!(o, "}}")
}

/// Rust source for every message of `db`.
pub fn generate(db: &Database) -> String {
    let mut o = String::new();
    let _ = generate_into(db, &mut o);
    o
}

fn generate_into(db: &Database, o: &mut String) -> std::fmt::Result {
    writeln!(
        o,
        "// Generated by bywire from a DBC file. Do not edit: regenerate instead."
    )?;
    writeln!(o, "#[allow(dead_code, clippy::all, clippy::pedantic, clippy::unreadable_literal, unused_comparisons)]")?;
    writeln!(o, "/// The messages of the DBC file, one struct each.")?;
    writeln!(o, "pub mod messages {{")?;
    o.push_str(HELPERS);
    let messages = db
        .messages
        .iter()
        .filter(|m| m.name != crate::INDEPENDENT_SIGNALS);
    for (m, n) in messages.zip(names(db)) {
        message_code(o, m, &n)?;
    }
    writeln!(o, "}}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_become_rust_identifiers() {
        assert_eq!(snake("VehicleSpeedKph"), "vehicle_speed_kph");
        assert_eq!(snake("ACC_Engaged"), "acc_engaged");
        assert_eq!(snake("type"), "type_");
        assert_eq!(snake("64_BIT_LE"), "_64_bit_le");
        assert_eq!(camel("AdsToVehicle_Control"), "AdsToVehicleControl");
        assert_eq!(camel("STEERING_CONTROL"), "SteeringControl");
        assert_eq!(camel("2ABC"), "M2Abc");
        let mut used = HashSet::new();
        assert_eq!(unique("a".into(), &mut used), "a");
        assert_eq!(unique("a".into(), &mut used), "a_2");
    }
}
