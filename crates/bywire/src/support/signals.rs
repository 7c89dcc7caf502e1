//! Frames to named signal values with a DBC, shared by `decode`, `dump --dbc`, `monitor`,
//! `sniff` and `plot`: one place that finds a frame's message, decodes it and shows values the
//! way cantools does (value descriptions, units, Python's float text).

use std::collections::HashMap;
use std::time::Duration;

use anyhow::{anyhow, Result};
use bywire_core::{FdFrame, Frame, Id};
use bywire_dbc::codec::{Decoded, EncodeError, EncodeMode, MessageCodec, Value};
use bywire_dbc::e2e::Protection;
use bywire_dbc::{AttrValue, Database, Message, Signal, ValueType};
use serde_json::json;

/// One signal of a decoded frame.
pub struct SignalValue<'a> {
    /// The signal.
    pub signal: &'a Signal,
    /// Its raw and physical value.
    pub value: Decoded,
}

impl SignalValue<'_> {
    /// The value as cantools shows it: the value description if there is one (unless
    /// `choices` is off), else the number with its unit.
    pub fn text(&self, choices: bool) -> String {
        let v = self.value;
        // As cantools: the description of the raw value (sign applied), not of the physical
        // one (they differ whenever there is an offset or a scale); a float's raw value is
        // the number itself.
        let key = match self.signal.value_type {
            ValueType::Integer { signed: true } => {
                let unused = 64u32.saturating_sub(self.signal.length.clamp(1, 64));
                // Reinterpret the bits, then shift back arithmetically: sign extension.
                Some(i128::from(
                    i64::from_ne_bytes((v.raw << unused).to_ne_bytes()) >> unused,
                ))
            }
            ValueType::Integer { signed: false } => Some(i128::from(v.raw)),
            ValueType::Float32 | ValueType::Float64 => v.physical.as_i128(),
        };
        let choice = choices
            .then(|| {
                self.signal
                    .value_descriptions
                    .iter()
                    .find(|(k, _)| key == Some(*k))
            })
            .flatten();
        match choice {
            Some((_, name)) => name.clone(),
            None if self.signal.unit.is_empty() => number_text(v.physical),
            None => format!("{} {}", number_text(v.physical), self.signal.unit),
        }
    }
}

/// A frame decoded with its message.
pub struct DecodedFrame<'a> {
    /// The message.
    pub message: &'a Message,
    /// The signals present in this frame (multiplexed ones only when selected).
    pub signals: Vec<SignalValue<'a>>,
    /// Why decoding failed (e.g. the frame is shorter than the message).
    pub error: Option<String>,
}

/// A DBC compiled for decoding.
pub struct Dbc {
    db: Database,
    codecs: Vec<MessageCodec>,
    by_id: HashMap<(u32, bool), usize>,
}

impl Dbc {
    /// Compile every message of `db`.
    pub fn new(db: Database) -> Self {
        let codecs = db.messages.iter().map(MessageCodec::new).collect();
        let by_id = db
            .messages
            .iter()
            .enumerate()
            .map(|(i, m)| ((m.id, m.extended), i))
            .collect();
        Dbc { db, codecs, by_id }
    }

    /// The database.
    pub fn database(&self) -> &Database {
        &self.db
    }

    /// Decode `frame`; `None` when no message has its identifier (or it is an error frame).
    pub fn decode(&self, frame: &Frame) -> Option<DecodedFrame<'_>> {
        let id = frame.id()?;
        let index = *self.by_id.get(&(id.as_raw(), id.is_extended()))?;
        let (message, codec) = (self.db.messages.get(index)?, self.codecs.get(index)?);
        let mut values = vec![None; codec.signal_count()];
        let data = if frame.is_remote() {
            &[][..]
        } else {
            frame.data()
        };
        let error = codec.decode(data, &mut values).err().map(|e| e.to_string());
        let signals = message
            .signals
            .iter()
            .zip(values)
            .filter_map(|(signal, value)| {
                Some(SignalValue {
                    signal,
                    value: value?,
                })
            })
            .collect();
        Some(DecodedFrame {
            message,
            signals,
            error,
        })
    }
}

impl Dbc {
    /// The message named `name` (or with identifier `name` in hex, `0x` optional).
    pub fn find(&self, name: &str) -> Result<&Message> {
        let by_id = u32::from_str_radix(name.trim_start_matches("0x"), 16).ok();
        self.db
            .messages
            .iter()
            .find(|m| m.name == name || m.display_name() == name)
            .or_else(|| by_id.and_then(|id| self.db.messages.iter().find(|m| m.id == id)))
            .ok_or_else(|| {
                let known: Vec<&str> = self
                    .db
                    .messages
                    .iter()
                    .take(8)
                    .map(|m| m.name.as_str())
                    .collect();
                anyhow!(
                    "no message '{name}' in the DBC (it has: {}{})",
                    known.join(", "),
                    if self.db.messages.len() > known.len() {
                        ", ..."
                    } else {
                        ""
                    }
                )
            })
    }

    fn index_of(&self, message: &Message) -> Option<usize> {
        self.by_id.get(&(message.id, message.extended)).copied()
    }

    /// The message's cycle time (`GenMsgCycleTime`), when it has a positive one.
    pub fn cycle_time(&self, message: &Message) -> Option<Duration> {
        let ms: f64 = self
            .db
            .message_attribute_text(message, "GenMsgCycleTime")?
            .parse()
            .ok()?;
        (ms > 0.0 && ms.is_finite()).then(|| Duration::from_secs_f64(ms / 1000.0))
    }

    /// Whether the message is sent as CAN FD (`VFrameFormat` says so, or it is over 8 bytes),
    /// and with bit rate switching.
    pub fn fd_format(&self, message: &Message) -> (bool, bool) {
        let format = self
            .db
            .message_attribute_text(message, "VFrameFormat")
            .unwrap_or_default();
        let fd = format.contains("FD") || message.size > 8;
        (fd, fd && !format.contains("NoBRS"))
    }

    /// Encode a message from `SIGNAL=VALUE` assignments (numbers, or value-description names).
    /// Signals not given take their `GenSigStartValue` or 0 bits; values outside a signal's
    /// range are refused naming the signal (or clamped, with `EncodeMode::Clamp`). The counter and checksum, when the message has
    /// them, are filled in with `counter`.
    pub fn encode(
        &self,
        message: &Message,
        assignments: &[String],
        counter: u64,
        range: EncodeMode,
    ) -> Result<Frame> {
        let index = self
            .index_of(message)
            .ok_or_else(|| anyhow!("message {} is not in the DBC", message.name))?;
        let codec = self.codecs.get(index).ok_or_else(|| anyhow!("no codec"))?;
        let mut values: Vec<Option<Value>> = message.signals.iter().map(start_value).collect();
        for assignment in assignments {
            let (name, text) = assignment
                .split_once('=')
                .ok_or_else(|| anyhow!("'{assignment}' is not SIGNAL=VALUE"))?;
            let position = message
                .signals
                .iter()
                .position(|s| s.name == name || s.display_name() == name)
                .ok_or_else(|| {
                    let names: Vec<&str> =
                        message.signals.iter().map(|s| s.name.as_str()).collect();
                    anyhow!(
                        "message {} has no signal '{name}' (it has: {})",
                        message.name,
                        names.join(", ")
                    )
                })?;
            let signal = message
                .signals
                .get(position)
                .ok_or_else(|| anyhow!("no signal"))?;
            let value = parse_value(signal, text).ok_or_else(|| {
                anyhow!("signal {name}: '{text}' is not a number or one of its value names")
            })?;
            if let Some(slot) = values.get_mut(position) {
                *slot = Some(value);
            }
        }
        let mut payload = [0u8; 64];
        let size = codec
            .encode_checked(&values, &mut payload, range)
            .map_err(|e| match e {
                EncodeError::Range(r) => anyhow!(
                    "message {}: signal {}: value {} is outside [{}, {}]",
                    message.name,
                    message
                        .signals
                        .get(r.signal)
                        .map_or("?", |s| s.display_name()),
                    r.value,
                    r.min,
                    r.max
                ),
                other => anyhow!("message {}: {other}", message.name),
            })?;
        if let Some(protection) = Protection::of(message) {
            protection
                .fill(codec, counter, &mut payload)
                .map_err(|e| anyhow!("message {}: {e}", message.name))?;
        }
        let data = payload.get(..size).unwrap_or(&[]);
        let id = if message.extended {
            Id::extended(message.id)
        } else {
            Id::standard(message.id)
        }
        .map_err(|e| anyhow!("message {}: {e}", message.name))?;
        let (fd, brs) = self.fd_format(message);
        let frame = if fd {
            Frame::Fd(FdFrame::padded(id, data, brs, false)?)
        } else {
            Frame::classic(id, data)?
        };
        Ok(frame)
    }
}

/// A signal's `GenSigStartValue` (a raw value) as a physical one.
fn start_value(signal: &Signal) -> Option<Value> {
    let raw = signal.attributes.iter().find_map(|(n, v)| match v {
        AttrValue::Number(n2) if n == "GenSigStartValue" => Some(n2.as_f64()),
        _ => None,
    })?;
    Some(Value::Float(
        raw * signal.factor.as_f64() + signal.offset.as_f64(),
    ))
}

/// A number, or the name of one of the signal's value descriptions.
fn parse_value(signal: &Signal, text: &str) -> Option<Value> {
    if let Some((raw, _)) = signal.value_descriptions.iter().find(|(_, n)| n == text) {
        let raw = f64::from(i32::try_from(*raw).ok()?);
        return Some(Value::Float(
            raw * signal.factor.as_f64() + signal.offset.as_f64(),
        ));
    }
    if let Ok(i) = text.parse::<i64>() {
        return Some(Value::Int(i));
    }
    text.parse::<f64>()
        .ok()
        .filter(|f| f.is_finite())
        .map(Value::Float)
}

impl DecodedFrame<'_> {
    /// cantools' single-line form: `Name(sig: value, ...)`.
    pub fn single_line(&self, choices: bool) -> String {
        format!(
            "{}({})",
            self.message.display_name(),
            self.items(choices).join(", ")
        )
    }

    /// cantools' multi-line form: `Name(\n    sig: value,\n ...\n)`, each line after the
    /// first prefixed with `indent`.
    pub fn multi_line(&self, choices: bool, indent: &str) -> String {
        format!(
            "{}(\n{indent}    {}\n{indent})",
            self.message.display_name(),
            self.items(choices).join(&format!(",\n{indent}    "))
        )
    }

    fn items(&self, choices: bool) -> Vec<String> {
        self.signals
            .iter()
            .map(|s| format!("{}: {}", s.signal.display_name(), s.text(choices)))
            .collect()
    }

    /// The signals as a JSON object of name to physical value.
    pub fn json_signals(&self) -> serde_json::Map<String, serde_json::Value> {
        self.signals
            .iter()
            .map(|s| {
                (
                    s.signal.display_name().to_string(),
                    json_number(s.value.physical),
                )
            })
            .collect()
    }
}

/// A value as JSON (non-finite floats as strings, which JSON has no number for).
pub fn json_number(v: Value) -> serde_json::Value {
    match v {
        Value::Int(i) => json!(i),
        Value::UInt(u) => json!(u),
        Value::Float(f) if f.is_nan() => json!("NaN"),
        Value::Float(f) if f.is_infinite() => json!(if f > 0.0 { "inf" } else { "-inf" }),
        Value::Float(f) => json!(f),
    }
}

/// A value as Python prints it (what cantools shows): integers plainly, floats as `repr`.
pub fn number_text(v: Value) -> String {
    match v {
        Value::Int(i) => i.to_string(),
        Value::UInt(u) => u.to_string(),
        Value::Float(f) => python_float(f),
    }
}

/// Python's `repr` of a float: the shortest digits that read back the same (Rust finds the
/// same ones), in fixed notation for decimal exponents -4 to 15 and as `1.5e+20` otherwise.
fn python_float(f: f64) -> String {
    if f.is_nan() {
        return "nan".into();
    }
    if f.is_infinite() {
        return if f > 0.0 { "inf" } else { "-inf" }.into();
    }
    let scientific = format!("{f:e}");
    let (mantissa, exponent) = scientific.split_once('e').unwrap_or((&scientific, "0"));
    let exponent: i32 = exponent.parse().unwrap_or(0);
    if (-4..16).contains(&exponent) {
        let fixed = format!("{f}");
        if fixed.contains('.') {
            fixed
        } else {
            fixed + ".0"
        }
    } else {
        let sign = if exponent < 0 { '-' } else { '+' };
        format!("{mantissa}e{sign}{:02}", exponent.unsigned_abs())
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn floats_print_as_python_repr_does() {
        for (f, text) in [
            (0.0, "0.0"),
            (-0.0, "-0.0"),
            (1.5, "1.5"),
            (250.1, "250.1"),
            (1e16, "1e+16"),
            (1.5e20, "1.5e+20"),
            (123_456_789_012_345.6, "123456789012345.6"),
            (0.0001, "0.0001"),
            (0.00001, "1e-05"),
            (-2.5e-7, "-2.5e-07"),
            (1.561_586_132_418_2e36, "1.5615861324182e+36"),
            (f64::INFINITY, "inf"),
        ] {
            assert_eq!(super::python_float(f), text);
        }
    }
}
