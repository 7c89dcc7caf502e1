//! A message encoded from values given by signal name: the one encoder the command line
//! (`send`, `gen`: `SIGNAL=VALUE` text) and the Python package (cantools' `encode_message`)
//! share. It decides which signals the payload needs (every signal not multiplexed, and those
//! the given multiplexor values select, as cantools gathers them), takes value descriptions by
//! name, checks ranges as asked, fills what the caller left out (an error, or the signal's
//! `GenSigStartValue`), pads, and fills a counter and checksum the message declares.
//!
//! ```
//! use bywire_dbc::codec::{MessageCodec, Value};
//! use bywire_dbc::named::{encode_named, Encoding, Given, Named};
//!
//! let text = "BO_ 256 Cmd: 2 ADS\n SG_ Gear : 0|4@1+ (1,0) [0|3] \"\" ECU\n \
//!             SG_ Speed : 4|12@1+ (0.1,0) [0|400] \"km/h\" ECU\n\
//!             VAL_ 256 Gear 0 \"P\" 1 \"R\" 2 \"N\" 3 \"D\" ;\n";
//! let (db, _) = bywire_dbc::parse(text.as_bytes(), bywire_dbc::Mode::Lenient).unwrap();
//! let (message, codec) = (&db.messages[0], MessageCodec::new(&db.messages[0]));
//! let values = [
//!     Named { signal: "Gear", value: Given::Choice("D"), shown: "D" },
//!     Named { signal: "Speed", value: Given::Number(Value::Float(12.5)), shown: "12.5" },
//! ];
//! let payload = encode_named(message, &codec, &values, Encoding::cantools(true)).unwrap();
//! assert_eq!(payload, [0xD3, 0x07]); // Gear 3, Speed 125 (12.5 / 0.1)
//! // Speed left out: cantools needs every signal the payload has.
//! let error = encode_named(message, &codec, &values[..1], Encoding::cantools(true)).unwrap_err();
//! assert_eq!(error.to_string(), "The signal \"Speed\" is required for encoding.");
//! ```

use crate::codec::{EncodeError, EncodeMode, MessageCodec, Value};
use crate::e2e::{Protection, ProtectionError};
use crate::{AttrValue, Message, Multiplexing, Num, Signal, ValueType};

/// A value given for a signal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Given<'a> {
    /// A number: physical, or raw when the encoding does not scale.
    Number(Value),
    /// One of the signal's value descriptions, by name: its raw value is written.
    Choice(&'a str),
    /// Neither (a caller's value of another type): it counts as given, and is refused if the
    /// payload needs it.
    Unusable,
}

impl<'a> Given<'a> {
    /// A value as written (`12`, `-0.5`, `Drive`): a whole number, a finite number, or else a
    /// value description's name.
    pub fn from_text(text: &'a str) -> Self {
        if let Ok(i) = text.parse::<i64>() {
            return Given::Number(Value::Int(i));
        }
        match text.parse::<f64>() {
            Ok(f) if f.is_finite() => Given::Number(Value::Float(f)),
            _ => Given::Choice(text),
        }
    }
}

/// One signal's value, by name (its name or its display name), and the value as the caller
/// wrote it, for errors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Named<'a> {
    /// The signal.
    pub signal: &'a str,
    /// Its value.
    pub value: Given<'a>,
    /// The value as written (`12.5`, `D`).
    pub shown: &'a str,
}

/// What is done with a signal the payload needs but no value was given for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Missing {
    /// An error naming it (cantools).
    Refuse,
    /// Its `GenSigStartValue`, else zero bits.
    StartValue,
}

/// How values out of a signal's range are treated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RangeCheck {
    /// Not checked: the raw value is masked to the signal's width (cantools, not strict).
    Unchecked,
    /// cantools' strict check: the declared range (none when it is `[0|0]`) with a millionth
    /// of the factor's tolerance; a value a description names passes.
    Declared,
    /// The declared range and the raw width, refused ([`EncodeMode::Strict`]) or clamped.
    Codec(EncodeMode),
}

/// How values become a payload.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Encoding {
    /// Values are physical (scaled by factor and offset); off: raw.
    pub scaling: bool,
    /// Bits no encoded signal covers are ones, not zeros.
    pub padding: bool,
    /// A name given that the payload does not take (not a signal of the message, or one its
    /// multiplexor does not select) is an error; off: it is ignored.
    pub refuse_unused: bool,
    /// What a needed signal given no value takes.
    pub missing: Missing,
    /// How values out of range are treated.
    pub range: RangeCheck,
    /// The counter a declared rolling counter takes (its checksum filled after it); `None`:
    /// both as given.
    pub counter: Option<u64>,
}

impl Encoding {
    /// cantools' `encode_message` (scaling on, no padding): `strict` refuses unused names
    /// and checks ranges.
    pub fn cantools(strict: bool) -> Encoding {
        Encoding {
            scaling: true,
            padding: false,
            refuse_unused: strict,
            missing: Missing::Refuse,
            range: if strict {
                RangeCheck::Declared
            } else {
                RangeCheck::Unchecked
            },
            counter: None,
        }
    }

    /// A tool's frame from `SIGNAL=VALUE` text: unused names refused, start values for the
    /// rest, ranges refused or clamped, the counter and checksum filled.
    pub fn frame(range: EncodeMode, counter: u64) -> Encoding {
        Encoding {
            scaling: true,
            padding: false,
            refuse_unused: true,
            missing: Missing::StartValue,
            range: RangeCheck::Codec(range),
            counter: Some(counter),
        }
    }
}

/// Why a message was not encoded. The texts of the variants cantools also raises are its
/// own.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum NamedError {
    /// Names the payload does not take (in the order given).
    #[error(
        "message {message} has no signal {} to encode (it has: {})",
        quoted(names),
        listed(signals)
    )]
    Unused {
        /// The message.
        message: String,
        /// The names.
        names: Vec<String>,
        /// The message's signals.
        signals: Vec<String>,
    },
    /// A needed signal with no value.
    #[error("The signal \"{signal}\" is required for encoding.")]
    Required {
        /// The signal.
        signal: String,
    },
    /// A multiplexor given a value that selects nothing.
    #[error("A valid value for the multiplexer selector signal \"{signal}\" is required: Expected one of {{{}}}, but got {shown}", or_listed(expected))]
    Selector {
        /// The multiplexor.
        signal: String,
        /// The values that select something.
        expected: Vec<i128>,
        /// The value given, as written.
        shown: String,
    },
    /// A value of no kind the encoder takes ([`Given::Unusable`]) for a signal it needs.
    #[error("signal {signal}: the value is neither a number nor a value name")]
    Unusable {
        /// The signal.
        signal: String,
    },
    /// A name the signal's value descriptions do not have.
    #[error("signal {signal}: '{name}' is not a number or one of its value names")]
    UnknownChoice {
        /// The signal.
        signal: String,
        /// The name.
        name: String,
    },
    /// NaN or an infinity for a signal that holds integers, or a raw value that is not a
    /// number.
    #[error("signal \"{signal}\": {value} is not a number that encodes")]
    NotFinite {
        /// The signal.
        signal: String,
        /// The value.
        value: f64,
        /// Whether the signal holds integers.
        integer: bool,
    },
    /// Out of the declared range ([`RangeCheck::Declared`]).
    #[error("Expected signal \"{signal}\" value {} or equal to {bound} in message \"{message}\", but got {shown}.", if *below { "greater than" } else { "smaller than" })]
    Declared {
        /// The message.
        message: String,
        /// The signal.
        signal: String,
        /// Below the minimum (else above the maximum).
        below: bool,
        /// The bound passed.
        bound: Num,
        /// The value as written.
        shown: String,
    },
    /// Out of the range [`RangeCheck::Codec`] refuses.
    #[error("message {message}: signal {signal}: value {value} is outside [{min}, {max}]")]
    Range {
        /// The message.
        message: String,
        /// The signal.
        signal: String,
        /// The physical value.
        value: f64,
        /// Lowest accepted.
        min: f64,
        /// Highest accepted.
        max: f64,
    },
    /// The counter or checksum could not be filled.
    #[error("message {message}: {error}")]
    Protection {
        /// The message.
        message: String,
        /// Why.
        error: ProtectionError,
    },
    /// The codec refused the payload.
    #[error("message {message}: {error}")]
    Codec {
        /// The message.
        message: String,
        /// Why.
        error: EncodeError,
    },
}

fn quoted(names: &[String]) -> String {
    let quoted: Vec<String> = names.iter().map(|n| format!("'{n}'")).collect();
    quoted.join(", ")
}

fn listed(signals: &[String]) -> String {
    let shown: Vec<&str> = signals.iter().take(8).map(String::as_str).collect();
    let more = if signals.len() > shown.len() {
        ", ..."
    } else {
        ""
    };
    format!("{}{more}", shown.join(", "))
}

/// `a, b or c`, as cantools lists the values a multiplexor takes.
fn or_listed(values: &[i128]) -> String {
    let texts: Vec<String> = values.iter().map(i128::to_string).collect();
    match texts.as_slice() {
        [] => String::new(),
        [one] => one.clone(),
        [rest @ .., last] => format!("{} or {last}", rest.join(", ")),
    }
}

/// Whether `signal` is in the payload when its multiplexor's raw value is `value`.
pub fn selected_by(signal: &Signal, value: i128) -> bool {
    if let Some(condition) = &signal.mux_condition {
        return condition
            .ranges
            .iter()
            .any(|(low, high)| i128::from(*low) <= value && value <= i128::from(*high));
    }
    match signal.multiplexing {
        Multiplexing::Multiplexed(v) | Multiplexing::MultiplexedMultiplexor(v) => {
            i128::from(v) == value
        }
        _ => true,
    }
}

/// The values of multiplexor `switch` that select something (its value descriptions', and
/// those its signals are selected by; ranges of more than 256 values left out), ascending.
pub fn selector_values(message: &Message, codec: &MessageCodec, switch: usize) -> Vec<i128> {
    let mut values: Vec<i128> = message
        .signals
        .get(switch)
        .map(|s| s.value_descriptions.iter().map(|(k, _)| *k).collect())
        .unwrap_or_default();
    for (i, signal) in message.signals.iter().enumerate() {
        if codec.switch_of(i) != Some(switch) {
            continue;
        }
        if let Some(condition) = &signal.mux_condition {
            for (low, high) in &condition.ranges {
                if high.saturating_sub(*low) < 256 {
                    values.extend((*low..=*high).map(i128::from));
                }
            }
        } else if let Multiplexing::Multiplexed(v) | Multiplexing::MultiplexedMultiplexor(v) =
            signal.multiplexing
        {
            values.push(i128::from(v));
        }
    }
    values.sort_unstable();
    values.dedup();
    values
}

/// A signal's `GenSigStartValue` (a raw value).
fn start_raw(signal: &Signal) -> Option<f64> {
    signal.attributes.iter().find_map(|(n, v)| match v {
        AttrValue::Number(start) if n == "GenSigStartValue" => Some(start.as_f64()),
        _ => None,
    })
}

/// A value resolved for its signal: the number, and whether a description named it.
#[derive(Clone, Copy)]
struct Resolved {
    number: Value,
    choice: bool,
}

fn resolve(signal: &Signal, given: Given<'_>) -> Result<Resolved, NamedError> {
    match given {
        Given::Number(number) => Ok(Resolved {
            number,
            choice: false,
        }),
        Given::Choice(name) => signal
            .value_descriptions
            .iter()
            .find(|(_, n)| n == name)
            .and_then(|(raw, _)| i64::try_from(*raw).ok())
            .map(|raw| Resolved {
                number: Value::Int(raw),
                choice: true,
            })
            .ok_or_else(|| NamedError::UnknownChoice {
                signal: signal.display_name().to_string(),
                name: name.to_string(),
            }),
        Given::Unusable => Err(NamedError::Unusable {
            signal: signal.display_name().to_string(),
        }),
    }
}

/// Encode `message` (compiled as `codec`) from `values`: the payload, the message's size.
pub fn encode_named(
    message: &Message,
    codec: &MessageCodec,
    values: &[Named<'_>],
    encoding: Encoding,
) -> Result<Vec<u8>, NamedError> {
    // Each value's signal, found once.
    let positions: Vec<Option<usize>> = values
        .iter()
        .map(|named| {
            message
                .signals
                .iter()
                .position(|s| s.name == named.signal || s.display_name() == named.signal)
        })
        .collect();
    encode_named_at(message, codec, values, &positions, encoding)
}

/// [`encode_named`] with each value's signal already found (`positions`, one per value: the
/// signal's index, None for a name the message does not have), for callers that keep an
/// index of names.
pub fn encode_named_at(
    message: &Message,
    codec: &MessageCodec,
    values: &[Named<'_>],
    positions: &[Option<usize>],
    encoding: Encoding,
) -> Result<Vec<u8>, NamedError> {
    let signals = &message.signals;
    // Each signal's value (the last given for it wins, as in a dict).
    let mut given: Vec<Option<&Named<'_>>> = vec![None; signals.len()];
    for (named, position) in values.iter().zip(positions) {
        if let Some(slot) = position.and_then(|i| given.get_mut(i)) {
            *slot = Some(named);
        }
    }
    let needed = needed_signals(message, codec, &given, encoding.missing);
    check_selectors(message, codec, &given, &needed)?;
    if encoding.refuse_unused {
        let unused: Vec<String> = values
            .iter()
            .zip(positions)
            .filter(|(_, at)| at.is_none_or(|i| needed.get(i) != Some(&true)))
            .map(|(n, _)| n.signal.to_string())
            .collect();
        if !unused.is_empty() {
            return Err(NamedError::Unused {
                message: message.display_name().to_string(),
                names: unused,
                signals: signals
                    .iter()
                    .map(|s| s.display_name().to_string())
                    .collect(),
            });
        }
    }
    // Physical values for the codec; choices and unscaled values written raw after it.
    let mut physical: Vec<Option<Value>> = vec![None; signals.len()];
    let mut raw: Vec<Option<u64>> = vec![None; signals.len()];
    for (i, signal) in signals.iter().enumerate() {
        if needed.get(i) != Some(&true) {
            continue;
        }
        let Some(named) = given.get(i).copied().flatten() else {
            match encoding.missing {
                Missing::Refuse => {
                    return Err(NamedError::Required {
                        signal: signal.display_name().to_string(),
                    })
                }
                Missing::StartValue => {
                    if let (Some(start), Some(slot)) = (start_raw(signal), physical.get_mut(i)) {
                        *slot = Some(Value::Float(
                            start * signal.factor.as_f64() + signal.offset.as_f64(),
                        ));
                    }
                    continue;
                }
            }
        };
        let value = resolve(signal, named.value)?;
        check_integer(signal, value.number)?;
        if value.choice || !encoding.scaling {
            if let Some(slot) = raw.get_mut(i) {
                *slot = Some(raw_bits(signal, value.number)?);
            }
            if encoding.range == RangeCheck::Declared && !value.choice {
                let scaled =
                    value.number.as_f64() * signal.factor.as_f64() + signal.offset.as_f64();
                check_declared(message, signal, scaled, value.number.as_i128(), named.shown)?;
            }
        } else {
            if encoding.range == RangeCheck::Declared {
                // The raw value the physical one encodes to, for the descriptions.
                let raw_key = f64::round_ties_even(
                    (value.number.as_f64() - signal.offset.as_f64()) / signal.factor.as_f64(),
                );
                // Whole and within ±1e18 (checked), so the conversion is exact.
                #[allow(clippy::cast_possible_truncation)]
                let raw_key =
                    (raw_key.is_finite() && raw_key.abs() < 1e18).then_some(raw_key as i128);
                check_declared(message, signal, value.number.as_f64(), raw_key, named.shown)?;
            }
            if let Some(slot) = physical.get_mut(i) {
                *slot = Some(value.number);
            }
        }
    }
    let mut payload = vec![0u8; codec.size()];
    let encoded = match encoding.range {
        RangeCheck::Codec(mode) => codec.encode_checked(&physical, &mut payload, mode),
        RangeCheck::Unchecked | RangeCheck::Declared => codec
            .encode(&physical, &mut payload)
            .map_err(EncodeError::from),
    };
    encoded.map_err(|error| match error {
        EncodeError::Range(r) => NamedError::Range {
            message: message.display_name().to_string(),
            signal: signals
                .get(r.signal)
                .map_or("?", |s| s.display_name())
                .to_string(),
            value: r.value,
            min: r.min,
            max: r.max,
        },
        error => NamedError::Codec {
            message: message.display_name().to_string(),
            error,
        },
    })?;
    for (i, bits) in raw.iter().enumerate() {
        if let Some(bits) = bits {
            codec.write_raw(i, *bits, &mut payload);
        }
    }
    if encoding.padding {
        // Bits no encoded signal covers are ones.
        let mut covered = vec![0u8; codec.size()];
        for (i, _) in needed.iter().enumerate().filter(|(_, n)| **n) {
            codec.write_raw(i, u64::MAX, &mut covered);
        }
        for (byte, cover) in payload.iter_mut().zip(&covered) {
            *byte |= !cover;
        }
    }
    let protection = encoding
        .counter
        .and_then(|counter| Some((counter, Protection::of(message)?)));
    if let Some((counter, protection)) = protection {
        protection
            .fill(codec, counter, &mut payload)
            .map_err(|error| NamedError::Protection {
                message: message.display_name().to_string(),
                error,
            })?;
    }
    Ok(payload)
}

/// The signals the payload needs: every signal not multiplexed, and those their multiplexor's
/// value selects (the value given; with start values, its start value when none is).
fn needed_signals(
    message: &Message,
    codec: &MessageCodec,
    given: &[Option<&Named<'_>>],
    missing: Missing,
) -> Vec<bool> {
    let signals = &message.signals;
    let mut needed = vec![false; signals.len()];
    for (i, (signal, slot)) in signals.iter().zip(needed.iter_mut()).enumerate() {
        let Some(switch) = codec.switch_of(i) else {
            *slot = true;
            continue;
        };
        let Some(switch_signal) = signals.get(switch) else {
            continue;
        };
        // A name the multiplexor's descriptions do not have selects nothing (and is refused
        // as a selector that selects nothing).
        let selector = match given.get(switch).copied().flatten() {
            Some(named) => resolve(switch_signal, named.value)
                .ok()
                .and_then(|r| selector_number(r.number)),
            // A start value is raw; a whole one selects.
            None if missing == Missing::StartValue => start_raw(switch_signal)
                .filter(|s| s.fract() == 0.0 && s.abs() < 1e18)
                .map(|s| {
                    // Whole and within ±1e18 (checked), so the conversion is exact.
                    #[allow(clippy::cast_possible_truncation)]
                    let whole = s as i128;
                    whole
                }),
            None => None,
        };
        *slot = selector.is_some_and(|v| selected_by(signal, v));
    }
    needed
}

/// A needed multiplexor given a value that selects nothing is refused (cantools).
fn check_selectors(
    message: &Message,
    codec: &MessageCodec,
    given: &[Option<&Named<'_>>],
    needed: &[bool],
) -> Result<(), NamedError> {
    for (i, signal) in message.signals.iter().enumerate() {
        let is_switch = matches!(
            signal.multiplexing,
            Multiplexing::Multiplexor | Multiplexing::MultiplexedMultiplexor(_)
        );
        if !is_switch || needed.get(i) != Some(&true) {
            continue;
        }
        let Some(named) = given.get(i).copied().flatten() else {
            continue;
        };
        let expected = selector_values(message, codec, i);
        if expected.is_empty() {
            continue;
        }
        let selects = resolve(signal, named.value)
            .ok()
            .and_then(|r| selector_number(r.number))
            .is_some_and(|v| expected.contains(&v));
        if !selects {
            return Err(NamedError::Selector {
                signal: signal.display_name().to_string(),
                expected,
                shown: named.shown.to_string(),
            });
        }
    }
    Ok(())
}

/// A multiplexor's value as the number that selects: a float truncated, as Python's `int()`
/// (cantools') does; none for NaN, an infinity or beyond ±1e30.
fn selector_number(number: Value) -> Option<i128> {
    match number {
        Value::Int(v) => Some(i128::from(v)),
        Value::UInt(v) => Some(i128::from(v)),
        // Finite and within ±1e30 (checked), so the truncation is exact.
        #[allow(clippy::cast_possible_truncation)]
        Value::Float(f) => (f.is_finite() && f.abs() < 1e30).then(|| f.trunc() as i128),
    }
}

/// An integer signal holds no NaN or infinity.
fn check_integer(signal: &Signal, number: Value) -> Result<(), NamedError> {
    match (signal.value_type, number) {
        (ValueType::Integer { .. }, Value::Float(f)) if !f.is_finite() => {
            Err(NamedError::NotFinite {
                signal: signal.display_name().to_string(),
                value: f,
                integer: true,
            })
        }
        _ => Ok(()),
    }
}

/// A raw value's bits: a float signal's value rounded to its precision, as Python's struct
/// packs it; an integer past i64 saturates before it is masked to the signal's width.
fn raw_bits(signal: &Signal, number: Value) -> Result<u64, NamedError> {
    #[allow(clippy::cast_possible_truncation)]
    Ok(match (signal.value_type, number) {
        (ValueType::Float32, v) => u64::from((v.as_f64() as f32).to_bits()),
        (ValueType::Float64, v) => v.as_f64().to_bits(),
        (_, Value::Int(v)) => u64::from_ne_bytes(v.to_ne_bytes()),
        (_, Value::UInt(v)) => v,
        (_, Value::Float(f)) => {
            let rounded = f64::round_ties_even(f);
            if !rounded.is_finite() {
                return Err(NamedError::NotFinite {
                    signal: signal.display_name().to_string(),
                    value: f,
                    integer: false,
                });
            }
            u64::from_ne_bytes((rounded as i64).to_ne_bytes())
        }
    })
}

/// cantools' strict range check of `scaled`; a raw value a description names passes.
fn check_declared(
    message: &Message,
    signal: &Signal,
    scaled: f64,
    raw_key: Option<i128>,
    shown: &str,
) -> Result<(), NamedError> {
    if raw_key.is_some_and(|k| signal.value_descriptions.iter().any(|(key, _)| *key == k)) {
        return Ok(());
    }
    let (min, max) = (signal.minimum, signal.maximum);
    if min.as_f64() == 0.0 && max.as_f64() == 0.0 {
        return Ok(());
    }
    let tolerance = signal.factor.as_f64().abs() * 1e-6;
    let (below, bound) = if scaled < min.as_f64() - tolerance {
        (true, min)
    } else if scaled > max.as_f64() + tolerance {
        (false, max)
    } else {
        return Ok(());
    };
    Err(NamedError::Declared {
        message: message.display_name().to_string(),
        signal: signal.display_name().to_string(),
        below,
        bound,
        shown: shown.to_string(),
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]

    use super::*;

    const DBC: &str = "BO_ 256 Cmd: 2 ADS
 SG_ Gear : 0|4@1+ (1,0) [0|3] \"\" ECU
 SG_ Speed : 4|12@1+ (0.1,0) [0|400] \"km/h\" ECU
BO_ 512 Muxed: 3 ADS
 SG_ Page M : 0|8@1+ (1,0) [0|0] \"\" ECU
 SG_ A m1 : 8|16@1+ (1,0) [0|0] \"\" ECU
 SG_ B m2 : 8|8@1+ (1,0) [0|100] \"\" ECU
VAL_ 256 Gear 0 \"P\" 1 \"R\" 2 \"N\" 3 \"D\" ;
BA_DEF_ SG_ \"GenSigStartValue\" INT 0 10000;
BA_ \"GenSigStartValue\" SG_ 256 Speed 100;
BA_ \"GenSigStartValue\" SG_ 512 Page 2;
";

    fn db() -> crate::Database {
        crate::parse(DBC.as_bytes(), crate::Mode::Lenient)
            .unwrap()
            .0
    }

    fn number(signal: &'static str, v: f64) -> Named<'static> {
        Named {
            signal,
            value: Given::Number(Value::Float(v)),
            shown: "v",
        }
    }

    fn encode(
        message: usize,
        values: &[Named<'_>],
        encoding: Encoding,
    ) -> Result<Vec<u8>, NamedError> {
        let db = db();
        let message = &db.messages[message];
        encode_named(message, &MessageCodec::new(message), values, encoding)
    }

    #[test]
    fn a_tools_frame_takes_start_values_for_the_rest_and_refuses_or_clamps_ranges() {
        // Speed's start value is raw 100 (10 km/h); Gear's none (0).
        let frame = Encoding::frame(EncodeMode::Strict, 0);
        assert_eq!(encode(0, &[], frame).unwrap(), [0x40, 0x06]);
        let error = encode(0, &[number("Speed", 500.0)], frame).unwrap_err();
        assert!(matches!(error, NamedError::Range { .. }), "{error}");
        assert!(error
            .to_string()
            .contains("signal Speed: value 500 is outside [0, 400]"));
        let clamped = encode(
            0,
            &[number("Speed", 500.0)],
            Encoding::frame(EncodeMode::Clamp, 0),
        );
        assert_eq!(clamped.unwrap(), [0x00, 0xFA]);
        let error = encode(0, &[number("Nope", 1.0)], frame).unwrap_err();
        assert!(
            error.to_string().contains("has no signal 'Nope'"),
            "{error}"
        );
        // The page's start value selects B.
        assert_eq!(
            encode(1, &[number("B", 7.0)], frame).unwrap(),
            [0x02, 0x07, 0x00]
        );
    }

    #[test]
    fn cantools_needs_every_selected_signal_and_strict_refuses_the_rest() {
        let strict = Encoding::cantools(true);
        let error = encode(1, &[number("Page", 1.0)], strict).unwrap_err();
        assert_eq!(
            error.to_string(),
            "The signal \"A\" is required for encoding."
        );
        assert_eq!(
            encode(1, &[number("Page", 1.0), number("A", 258.0)], strict).unwrap(),
            [0x01, 0x02, 0x01]
        );
        let error = encode(
            1,
            &[number("Page", 1.0), number("A", 1.0), number("B", 1.0)],
            strict,
        )
        .unwrap_err();
        assert!(
            matches!(&error, NamedError::Unused { names, .. } if names == &["B"]),
            "{error}"
        );
        // Not strict: B is not the page's, and left out.
        let lenient = Encoding::cantools(false);
        assert!(encode(
            1,
            &[number("Page", 1.0), number("A", 1.0), number("B", 1.0)],
            lenient
        )
        .is_ok());
        let error = encode(1, &[number("Page", 3.0)], lenient).unwrap_err();
        assert!(
            matches!(&error, NamedError::Selector { expected, .. } if expected == &[1, 2]),
            "{error}"
        );
    }

    #[test]
    fn choices_raw_values_padding_and_bad_numbers() {
        let mut raw = Encoding::cantools(true);
        raw.scaling = false;
        raw.padding = true;
        let gear = Named {
            signal: "Gear",
            value: Given::Choice("R"),
            shown: "R",
        };
        // Raw 125 for Speed, unscaled; Gear R; nothing uncovered in a 2-byte message.
        assert_eq!(
            encode(0, &[gear, number("Speed", 125.0)], raw).unwrap(),
            [0xD1, 0x07]
        );
        let bad = Named {
            signal: "Gear",
            value: Given::Choice("X"),
            shown: "X",
        };
        assert!(matches!(
            encode(0, &[bad, number("Speed", 1.0)], raw),
            Err(NamedError::UnknownChoice { .. })
        ));
        assert!(matches!(
            encode(
                0,
                &[gear, number("Speed", f64::NAN)],
                Encoding::cantools(false)
            ),
            Err(NamedError::NotFinite { integer: true, .. })
        ));
        let error =
            encode(0, &[gear, number("Speed", 400.5)], Encoding::cantools(true)).unwrap_err();
        assert_eq!(
            error.to_string(),
            "Expected signal \"Speed\" value smaller than or equal to 400 in message \"Cmd\", but got v."
        );
    }
}
