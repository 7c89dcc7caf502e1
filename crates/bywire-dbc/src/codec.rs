//! Compiled decode/encode plans.
//!
//! [`MessageCodec::new`] turns a message into one plan per signal: the byte where a 16-byte
//! window around the signal starts, the shift and the mask, so decoding a signal is one load,
//! one shift, one mask and the scaling. Decoding writes into a caller-provided slice and never
//! allocates; no byte string makes it panic.
//!
//! Physical values follow Python's (and so cantools') number rules, which the vectors in the
//! corpus are made with: a signal whose scale and offset are whole numbers decodes to an exact
//! integer ([`Value::Int`]); otherwise `raw * scale + offset` is computed in `f64`, converting
//! an integer operand at each operation exactly as Python does, so floats agree bit for bit.

use crate::model::{ByteOrder, Message, Multiplexing, Num, Signal, ValueType};
use crate::parser::signal_bits;

/// Bytes of slack after the largest (64-byte) payload so every window load stays in bounds.
const WINDOW: usize = 16;
const BUFFER: usize = 64 + WINDOW;

/// A physical value. Integers are exact over the whole range a raw value or a whole-number
/// scaling of one can take in practice (i64 and u64); an integer result beyond both, which only
/// an enormous whole-number scale could produce, becomes the nearest float.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Value {
    /// An exact integer.
    Int(i64),
    /// An exact integer above `i64::MAX` (64-bit unsigned signals).
    UInt(u64),
    /// A floating-point value.
    Float(f64),
}

impl Value {
    /// The value as `f64` (Python's `float(int)`: correctly rounded, as `as` is).
    #[inline]
    #[allow(clippy::cast_precision_loss)]
    pub fn as_f64(self) -> f64 {
        match self {
            Value::Int(i) => i as f64,
            Value::UInt(u) => u as f64,
            Value::Float(f) => f,
        }
    }

    /// The exact integer, if this is one.
    pub fn as_i128(self) -> Option<i128> {
        match self {
            Value::Int(i) => Some(i128::from(i)),
            Value::UInt(u) => Some(i128::from(u)),
            Value::Float(_) => None,
        }
    }

    /// An integer in the narrowest variant that holds it.
    #[inline]
    pub fn integer(i: i128) -> Value {
        match i64::try_from(i) {
            Ok(small) => Value::Int(small),
            Err(_) => match u64::try_from(i) {
                Ok(big) => Value::UInt(big),
                // Beyond u64: the nearest float (see the type's documentation).
                #[allow(clippy::cast_precision_loss)]
                Err(_) => Value::Float(i as f64),
            },
        }
    }
}

/// One decoded signal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decoded {
    /// The raw bits, zero-extended (two's complement for signed signals).
    pub raw: u64,
    /// The physical value.
    pub physical: Value,
}

/// How [`MessageCodec::encode_checked`] treats values outside a signal's range.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EncodeMode {
    /// Refuse a value outside the declared physical range or the raw width.
    Strict,
    /// Clamp it to the declared range and the raw width.
    Clamp,
}

/// A value [`MessageCodec::encode_checked`] refused.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("signal {signal}: value {value} is outside [{min}, {max}]")]
pub struct RangeError {
    /// Index of the signal.
    pub signal: usize,
    /// The value given.
    pub value: f64,
    /// Lowest accepted.
    pub min: f64,
    /// Highest accepted.
    pub max: f64,
}

/// Why [`MessageCodec::encode_checked`] wrote nothing.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum EncodeError {
    /// A value outside its signal's range (strict mode).
    #[error(transparent)]
    Range(#[from] RangeError),
    /// The output buffer is shorter than the message.
    #[error(transparent)]
    Buffer(#[from] DecodeError),
}

/// Why a frame does not decode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum DecodeError {
    /// Fewer bytes than the message's size.
    #[error("{got} bytes, but the message has {needed}")]
    TooShort {
        /// The message's size.
        needed: usize,
        /// Bytes given.
        got: usize,
    },
    /// A multiplexor's value selects no signal.
    #[error("multiplexer value {value} selects no signal")]
    UnknownMultiplexerValue {
        /// Index of the multiplexor signal.
        signal: usize,
        /// Its raw value.
        value: u64,
    },
    /// The output slice is shorter than the message's signal count.
    #[error("output has room for {got} signals, the message has {needed}")]
    Output {
        /// Signals in the message.
        needed: usize,
        /// Room given.
        got: usize,
    },
}

#[derive(Debug, Clone, PartialEq)]
enum Conversion {
    /// Scale 1, offset 0: the raw value itself.
    Identity,
    /// Whole-number scale and offset on an integer signal: exact integer arithmetic.
    Integer { scale: i128, offset: i128 },
    /// A fractional scale on an integer signal: Python computes
    /// `float(raw) * scale + float(offset)`.
    Float { scale: f64, offset: f64 },
    /// Anything else: Python float arithmetic.
    Linear { scale: Num, offset: Num },
}

#[derive(Debug, Clone, PartialEq)]
enum Presence {
    Always,
    /// Present when signal `switch` has raw value `value`.
    Selected {
        switch: usize,
        value: u64,
    },
    /// Present when signal `switch` has a raw value in one of `ranges`.
    Ranges {
        switch: usize,
        ranges: Vec<(u64, u64)>,
    },
}

/// The common value type and conversion pairs, resolved when the plan is made so decoding
/// takes one branch per signal for them.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Kernel {
    /// Unsigned, scale 1, offset 0.
    UnsignedRaw,
    /// Signed (sign bit at `64 - unused`), scale 1, offset 0.
    SignedRaw { unused: u32 },
    /// Unsigned with a fractional scale.
    UnsignedFloat { scale: f64, offset: f64 },
    /// Signed with a fractional scale.
    SignedFloat {
        unused: u32,
        scale: f64,
        offset: f64,
    },
    /// Everything else, through the general path.
    General,
}

#[derive(Debug, Clone, PartialEq)]
struct Plan {
    kernel: Kernel,
    window: usize,
    shift: u32,
    mask: u128,
    big_endian: bool,
    /// The signal lies within the first 8 bytes of its window: a 64-bit load suffices.
    narrow: bool,
    /// For messages of at most 8 bytes: the shift that brings the signal's LSB to bit 0 of the
    /// whole payload read as one little-endian (Intel) or big-endian (Motorola) word.
    word_shift: u32,
    length: u32,
    value_type: ValueType,
    conversion: Conversion,
    presence: Presence,
    /// Runs past the message's size: never decoded.
    past_end: bool,
    /// Declared physical range, when the file declares one (not `[0|0]`).
    range: Option<(f64, f64)>,
    /// Physical values the raw width can express (integer signals).
    reachable: Option<(f64, f64)>,
}

/// What the fast path for payloads of at most 8 bytes needs of a signal, kept small so a whole
/// database's plans stay in the first-level cache.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Hot {
    kernel: Kernel,
    mask: u64,
    word_shift: u32,
    big_endian: bool,
    past_end: bool,
}

impl Hot {
    /// The signal's raw bits in a payload read as a word.
    #[inline(always)]
    fn raw_of(&self, payload: PayloadWord) -> u64 {
        let word = payload.word(self.big_endian);
        (word >> self.word_shift) & self.mask
    }
}

/// One signal of many payloads: each payload's raw bits as `h` places them, read from the
/// byte-swapped word when `BIG`, its value by `value` (one kernel's arithmetic: each caller
/// passes its own, so every loop is compiled for one kernel and has no dispatch inside).
#[inline(always)]
fn column<const BIG: bool, T>(
    h: &Hot,
    payloads: &[PayloadWord],
    out: &mut Vec<T>,
    value: impl Fn(u64) -> Value,
    convert: &mut impl FnMut(Decoded) -> T,
) {
    let (shift, mask) = (h.word_shift, h.mask);
    out.extend(payloads.iter().map(|payload| {
        let word = payload.word(BIG);
        let raw = (word >> shift) & mask;
        convert(Decoded {
            raw,
            physical: value(raw),
        })
    }));
}

/// [`column`] for `h`'s byte order.
#[inline(always)]
fn column_in_order<T>(
    h: &Hot,
    payloads: &[PayloadWord],
    out: &mut Vec<T>,
    value: impl Fn(u64) -> Value,
    convert: &mut impl FnMut(Decoded) -> T,
) {
    if h.big_endian {
        column::<true, T>(h, payloads, out, value, convert);
    } else {
        column::<false, T>(h, payloads, out, value, convert);
    }
}

/// A payload of at most 8 bytes, zero-padded, read as a little-endian word: each signal of
/// it is then one shift and one mask of that word or (big-endian signals) of its bytes
/// swapped, one instruction. Eight bytes a payload, so a table keeps its payloads compactly.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PayloadWord(u64);

impl PayloadWord {
    /// The payload read in the byte order of a big-endian signal when `big`, else of a
    /// little-endian one.
    #[inline(always)]
    fn word(self, big: bool) -> u64 {
        if big {
            self.0.swap_bytes()
        } else {
            self.0
        }
    }
}

#[inline(always)]
fn payload_word(payload: &[u8]) -> PayloadWord {
    // Eight bytes (the common case) convert without a copy loop or a library call.
    let bytes: [u8; 8] = payload.try_into().unwrap_or_else(|_| {
        let mut padded = [0u8; 8];
        for (dst, src) in padded.iter_mut().zip(payload) {
            *dst = *src;
        }
        padded
    });
    PayloadWord(u64::from_le_bytes(bytes))
}

/// A message compiled for decoding and encoding.
#[derive(Debug, Clone, PartialEq)]
pub struct MessageCodec {
    size: usize,
    plans: Vec<Plan>,
    /// Decode order: every switch before the signals it selects.
    order: Vec<usize>,
    /// Multiplexors with the values their dependents accept.
    multiplexors: Vec<(usize, Vec<(u64, u64)>)>,
    /// No multiplexing: every signal decodes in message order.
    plain: bool,
    /// The fast path's view of `plans`.
    hot: Vec<Hot>,
}

/// The scale and offset of a signal whose values decode to exact integers (an integer signal
/// whose scale and offset are whole numbers, `1.0` included, as Python sees them); `None` when
/// its values are floats. What a typed column or schema of the signal's values is made from.
pub fn whole_scaling(s: &Signal) -> Option<(i128, i128)> {
    match (conversion(s), s.value_type) {
        (_, ValueType::Float32 | ValueType::Float64) => None,
        (Conversion::Identity, _) => Some((1, 0)),
        (Conversion::Integer { scale, offset }, _) => Some((scale, offset)),
        _ => None,
    }
}

fn conversion(s: &Signal) -> Conversion {
    let is_float = !matches!(s.value_type, ValueType::Integer { .. });
    let whole = |n: Num| match n {
        Num::Int(i) => Some(i),
        // A float with no fraction: exact as an integer below 2^53.
        #[allow(clippy::cast_possible_truncation)]
        Num::Float(f) if f.is_finite() && f.fract() == 0.0 && f.abs() < 9.0e15 => Some(f as i128),
        Num::Float(_) => None,
    };
    match (whole(s.factor), whole(s.offset)) {
        (Some(1), Some(0)) => Conversion::Identity,
        (Some(scale), Some(offset)) if !is_float => Conversion::Integer { scale, offset },
        _ if !is_float && matches!(s.factor, Num::Float(_)) => Conversion::Float {
            scale: s.factor.as_f64(),
            offset: s.offset.as_f64(),
        },
        _ => Conversion::Linear {
            scale: s.factor,
            offset: s.offset,
        },
    }
}

fn plan(s: &Signal, size: usize) -> Plan {
    let length = s.length.clamp(1, 64);
    let mask = (1u128 << length) - 1;
    let past_end =
        signal_bits(s).is_none_or(|(_, last)| usize::try_from(last).map_or(true, |l| l >= size));
    let (window, shift, big_endian) = match s.byte_order {
        ByteOrder::LittleEndian => {
            let start = usize::try_from(s.start_bit).unwrap_or(usize::MAX);
            (start / 8, s.start_bit % 8, false)
        }
        ByteOrder::BigEndian => {
            // Linear numbering: bit 0 is the MSB of byte 0.
            let msb = (s.start_bit / 8) * 8 + (7 - s.start_bit % 8);
            // (Saturating: a model read from JSON may put a signal anywhere.)
            let lsb = msb.saturating_add(length - 1);
            let window = usize::try_from(msb / 8).unwrap_or(usize::MAX);
            let lsb_in_window = lsb - (msb / 8) * 8;
            (window, 127 - lsb_in_window, true)
        }
    };
    // Whether the signal's bits lie in the first 8 bytes of its 16-byte window.
    let narrow = if big_endian {
        shift >= 64
    } else {
        shift + length <= 64
    };
    let word_shift = if big_endian {
        // shift = 127 - (LSB within the window); in the payload word: 63 - LSB overall.
        let lsb = u32::try_from(window).unwrap_or(0) * 8 + (127 - shift);
        63u32.saturating_sub(lsb)
    } else {
        s.start_bit.min(63)
    };
    let conversion = conversion(s);
    let unused = 64 - length;
    let kernel = match (s.value_type, &conversion) {
        (ValueType::Integer { signed: false }, Conversion::Identity) => Kernel::UnsignedRaw,
        (ValueType::Integer { signed: true }, Conversion::Identity) => Kernel::SignedRaw { unused },
        // Below 64 bits the top bit is never set: the raw value converts as a signed one.
        (ValueType::Integer { signed: false }, Conversion::Float { scale, offset })
            if length < 64 =>
        {
            Kernel::UnsignedFloat {
                scale: *scale,
                offset: *offset,
            }
        }
        (ValueType::Integer { signed: true }, Conversion::Float { scale, offset }) => {
            Kernel::SignedFloat {
                unused,
                scale: *scale,
                offset: *offset,
            }
        }
        _ => Kernel::General,
    };
    Plan {
        kernel,
        window: if window + WINDOW <= BUFFER { window } else { 0 },
        shift,
        mask,
        big_endian,
        narrow,
        word_shift,
        length,
        value_type: s.value_type,
        conversion,
        range: {
            let (min, max) = (s.minimum.as_f64(), s.maximum.as_f64());
            (min != 0.0 || max != 0.0).then_some((min, max))
        },
        reachable: s.reachable_range(),
        presence: Presence::Always,
        past_end: past_end || window + WINDOW > BUFFER,
    }
}

impl MessageCodec {
    /// Compile a message.
    pub fn new(message: &Message) -> Self {
        let size = usize::try_from(message.size).unwrap_or(usize::MAX).min(64);
        let mut plans: Vec<Plan> = message.signals.iter().map(|s| plan(s, size)).collect();
        let index = |name: &str| message.signals.iter().position(|s| s.name == name);
        // Simple multiplexing: the message's `M` signal selects the `mN` ones.
        let simple_switch = message
            .signals
            .iter()
            .position(|s| s.multiplexing == Multiplexing::Multiplexor)
            .or_else(|| {
                message
                    .signals
                    .iter()
                    .position(|s| matches!(s.multiplexing, Multiplexing::MultiplexedMultiplexor(_)))
            });
        for (i, s) in message.signals.iter().enumerate() {
            let presence = match (&s.mux_condition, s.multiplexing) {
                (Some(c), _) => match index(&c.switch) {
                    Some(switch) => Presence::Ranges {
                        switch,
                        ranges: c.ranges.clone(),
                    },
                    None => Presence::Always,
                },
                (
                    None,
                    Multiplexing::Multiplexed(value) | Multiplexing::MultiplexedMultiplexor(value),
                ) => match simple_switch.filter(|&sw| sw != i) {
                    Some(switch) => Presence::Selected { switch, value },
                    None => Presence::Always,
                },
                (None, _) => Presence::Always,
            };
            if let Some(p) = plans.get_mut(i) {
                p.presence = presence;
            }
        }
        let mut multiplexors: Vec<(usize, Vec<(u64, u64)>)> = Vec::new();
        for p in &plans {
            let (switch, accepted) = match &p.presence {
                Presence::Always => continue,
                Presence::Selected { switch, value } => (*switch, vec![(*value, *value)]),
                Presence::Ranges { switch, ranges } => (*switch, ranges.clone()),
            };
            match multiplexors.iter_mut().find(|(s, _)| *s == switch) {
                Some((_, values)) => values.extend(accepted),
                None => multiplexors.push((switch, accepted)),
            }
        }
        // A multiplexor value listed in its value descriptions is valid even when it selects no
        // signal (cantools accepts it too).
        for (switch, values) in &mut multiplexors {
            if let Some(sig) = message.signals.get(*switch) {
                for (v, _) in &sig.value_descriptions {
                    if let Ok(v) = u64::try_from(*v) {
                        values.push((v, v));
                    }
                }
            }
        }
        let order = decode_order(&plans);
        let plain = multiplexors.is_empty() && plans.iter().all(|p| p.presence == Presence::Always);
        // The mask keeps at most 64 bits.
        #[allow(clippy::cast_possible_truncation)]
        let hot = plans
            .iter()
            .map(|p| Hot {
                kernel: p.kernel,
                mask: p.mask as u64,
                word_shift: p.word_shift,
                big_endian: p.big_endian,
                past_end: p.past_end,
            })
            .collect();
        MessageCodec {
            size,
            plans,
            order,
            multiplexors,
            plain,
            hot,
        }
    }

    /// The multiplexor that selects signal `index` (its index), if the signal is multiplexed:
    /// the switch decoding uses, from `mN`/`mNM` or `SG_MUL_VAL_`.
    pub fn switch_of(&self, index: usize) -> Option<usize> {
        match &self.plans.get(index)?.presence {
            Presence::Always => None,
            Presence::Selected { switch, .. } | Presence::Ranges { switch, .. } => Some(*switch),
        }
    }

    /// Number of signals (the length `decode` needs).
    pub fn signal_count(&self) -> usize {
        self.plans.len()
    }

    /// The message's size in bytes.
    pub fn size(&self) -> usize {
        self.size
    }

    /// Decode `data` into `out` (one entry per signal, in the message's order; `None` for a
    /// signal that multiplexing leaves out or that runs past the message's end).
    pub fn decode(&self, data: &[u8], out: &mut [Option<Decoded>]) -> Result<(), DecodeError> {
        if out.len() < self.plans.len() {
            return Err(DecodeError::Output {
                needed: self.plans.len(),
                got: out.len(),
            });
        }
        let payload = data.get(..self.size).ok_or(DecodeError::TooShort {
            needed: self.size,
            got: data.len(),
        })?;
        if self.decodes_by_word() {
            let word = payload_word(payload);
            for ((h, p), slot) in self.hot.iter().zip(&self.plans).zip(out.iter_mut()) {
                *slot = (!h.past_end).then(|| {
                    let raw = h.raw_of(word);
                    Decoded {
                        raw,
                        physical: value_of(h.kernel, p, raw),
                    }
                });
            }
            return Ok(());
        }
        let mut buf = [0u8; BUFFER];
        if let Some(dst) = buf.get_mut(..payload.len()) {
            dst.copy_from_slice(payload);
        }
        if self.plain {
            for (p, slot) in self.plans.iter().zip(out.iter_mut()) {
                *slot = (!p.past_end).then(|| decode_signal(p, payload, &buf));
            }
            return Ok(());
        }
        for &i in &self.order {
            let (Some(p), Some(slot)) = (self.plans.get(i), out.get(i)) else {
                continue;
            };
            let _ = slot;
            let present = !p.past_end
                && match &p.presence {
                    Presence::Always => true,
                    Presence::Selected { switch, value } => out
                        .get(*switch)
                        .copied()
                        .flatten()
                        .is_some_and(|d| d.raw == *value),
                    Presence::Ranges { switch, ranges } => {
                        out.get(*switch).copied().flatten().is_some_and(|d| {
                            ranges.iter().any(|(lo, hi)| (*lo..=*hi).contains(&d.raw))
                        })
                    }
                };
            let value = present.then(|| decode_signal(p, payload, &buf));
            if let Some(slot) = out.get_mut(i) {
                *slot = value;
            }
        }
        for (switch, accepted) in &self.multiplexors {
            if let Some(Some(d)) = out.get(*switch) {
                if !accepted.iter().any(|(lo, hi)| (*lo..=*hi).contains(&d.raw)) {
                    return Err(DecodeError::UnknownMultiplexerValue {
                        signal: *switch,
                        value: d.raw,
                    });
                }
            }
        }
        Ok(())
    }

    /// Whether every signal is read from the payload as one word (no multiplexing, at most 8
    /// bytes): the fast path of [`MessageCodec::decode`], and the messages
    /// [`MessageCodec::decode_column`] decodes.
    pub fn decodes_by_word(&self) -> bool {
        self.plain && self.size <= 8
    }

    /// The message's payload in `data` as the word [`MessageCodec::decode_column`] reads; an
    /// error when `data` is shorter than the message.
    pub fn word_of(&self, data: &[u8]) -> Result<PayloadWord, DecodeError> {
        match data.get(..self.size) {
            Some(payload) => Ok(payload_word(payload)),
            None => Err(DecodeError::TooShort {
                needed: self.size,
                got: data.len(),
            }),
        }
    }

    /// Signal `index` of many payloads of a message that [decodes by
    /// word](MessageCodec::decodes_by_word), appended to `out` in order: each payload's value,
    /// as [`MessageCodec::decode`] gives it, through `convert`. Column-at-a-time decoding for
    /// tables: the signal's plan is looked up once, not once per frame, and `out` grows once.
    /// False (and nothing appended) when the message does not decode by word or the signal
    /// is never present (past the message's end, or no such signal).
    pub fn decode_column<T>(
        &self,
        index: usize,
        payloads: &[PayloadWord],
        out: &mut Vec<T>,
        mut convert: impl FnMut(Decoded) -> T,
    ) -> bool {
        let (Some(h), Some(p)) = (self.hot.get(index), self.plans.get(index)) else {
            return false;
        };
        if !self.decodes_by_word() || h.past_end {
            return false;
        }
        // One loop per kernel and byte order: each loop's work is its kernel's alone.
        let c = &mut convert;
        match h.kernel {
            Kernel::UnsignedRaw => column_in_order(h, payloads, out, unsigned_raw, c),
            Kernel::SignedRaw { unused } => {
                column_in_order(h, payloads, out, |raw| signed_raw(raw, unused), c);
            }
            Kernel::UnsignedFloat { scale, offset } => {
                let value = |raw| unsigned_float(raw, scale, offset);
                column_in_order(h, payloads, out, value, c);
            }
            Kernel::SignedFloat {
                unused,
                scale,
                offset,
            } => {
                let value = |raw| signed_float(raw, unused, scale, offset);
                column_in_order(h, payloads, out, value, c);
            }
            Kernel::General => column_in_order(h, payloads, out, |raw| general(p, raw), c),
        }
        true
    }

    /// The mask of signal `index`'s raw width (`None` for no such signal).
    pub fn raw_mask(&self, index: usize) -> Option<u64> {
        // The mask keeps at most 64 bits.
        #[allow(clippy::cast_possible_truncation)]
        self.plans.get(index).map(|p| p.mask as u64)
    }

    /// The raw bits of signal `index` in `payload` (`None` past the payload or the signal list).
    pub fn read_raw(&self, index: usize, payload: &[u8]) -> Option<u64> {
        let p = self.plans.get(index).filter(|p| !p.past_end)?;
        let bytes = payload.get(..self.size)?;
        let mut buf = [0u8; BUFFER];
        buf.get_mut(..bytes.len())?.copy_from_slice(bytes);
        // The mask keeps at most 64 bits.
        #[allow(clippy::cast_possible_truncation)]
        Some(((read_window(p, &buf) >> p.shift) & p.mask) as u64)
    }

    /// Overwrite the bits of signal `index` in `payload` with `raw` (masked to its width);
    /// false when the signal or the payload does not allow it.
    pub fn write_raw(&self, index: usize, raw: u64, payload: &mut [u8]) -> bool {
        let Some(p) = self.plans.get(index).filter(|p| !p.past_end) else {
            return false;
        };
        let Some(bytes) = payload.get_mut(..self.size) else {
            return false;
        };
        let mut buf = [0u8; BUFFER];
        let Some(dst) = buf.get_mut(..bytes.len()) else {
            return false;
        };
        dst.copy_from_slice(bytes);
        write_window(p, &mut buf, u128::from(raw) & p.mask);
        match buf.get(..bytes.len()) {
            Some(src) => {
                bytes.copy_from_slice(src);
                true
            }
            None => false,
        }
    }

    /// Encode with range checks: in [`EncodeMode::Strict`] a value outside the signal's
    /// declared physical range, or whose raw value does not fit its width, is an error naming
    /// the signal; in [`EncodeMode::Clamp`] it is clamped to both. Returns the size.
    pub fn encode_checked(
        &self,
        values: &[Option<Value>],
        out: &mut [u8],
        mode: EncodeMode,
    ) -> Result<usize, EncodeError> {
        let mut adjusted: Vec<Option<Value>> = values.to_vec();
        for (signal, (p, v)) in self.plans.iter().zip(adjusted.iter_mut()).enumerate() {
            let Some(value) = v else { continue };
            let physical = value.as_f64();
            // The raw width's limits, in physical units.
            let raw_limits = p.reachable;
            let (min, max) = match (p.range, raw_limits) {
                (Some((a, b)), Some((c, d))) => (a.max(c), b.min(d)),
                (Some(r), None) | (None, Some(r)) => r,
                (None, None) => (f64::NEG_INFINITY, f64::INFINITY),
            };
            if physical >= min && physical <= max {
                continue;
            }
            match mode {
                EncodeMode::Strict => {
                    return Err(EncodeError::Range(RangeError {
                        signal,
                        value: physical,
                        min,
                        max,
                    }))
                }
                EncodeMode::Clamp if physical.is_nan() => {
                    *v = Some(Value::Float(min.max(0.0).min(max)))
                }
                EncodeMode::Clamp => *v = Some(Value::Float(physical.clamp(min, max))),
            }
        }
        Ok(self.encode(&adjusted, out)?)
    }

    /// Encode physical values (one entry per signal; `None` leaves its bits 0) into `out`,
    /// which must hold the message's size; returns the size. Values are converted as cantools
    /// does (`round` half to even) and masked to the signal's width.
    pub fn encode(&self, values: &[Option<Value>], out: &mut [u8]) -> Result<usize, DecodeError> {
        let target = out.get_mut(..self.size).ok_or(DecodeError::TooShort {
            needed: self.size,
            got: 0,
        })?;
        let mut buf = [0u8; BUFFER];
        for (p, v) in self.plans.iter().zip(values) {
            let Some(v) = v else { continue };
            if p.past_end {
                continue;
            }
            let raw = to_raw(p, *v);
            write_window(p, &mut buf, u128::from(raw) & p.mask);
        }
        if let Some(src) = buf.get(..self.size) {
            target.copy_from_slice(src);
        }
        Ok(self.size)
    }
}

/// Switches before the signals they select (depth-first; bounded by the signal count).
fn decode_order(plans: &[Plan]) -> Vec<usize> {
    let mut order = Vec::with_capacity(plans.len());
    let mut placed = vec![false; plans.len()];
    let switch_of = |i: usize| match plans.get(i).map(|p| &p.presence) {
        Some(Presence::Selected { switch, .. } | Presence::Ranges { switch, .. }) => Some(*switch),
        _ => None,
    };
    for i in 0..plans.len() {
        let mut chain = Vec::new();
        let mut cur = Some(i);
        // A chain of switches is at most as long as the message; cycles stop there.
        while let Some(c) = cur {
            if chain.len() > plans.len()
                || placed.get(c).copied().unwrap_or(true)
                || chain.contains(&c)
            {
                break;
            }
            chain.push(c);
            cur = switch_of(c);
        }
        for &c in chain.iter().rev() {
            if let Some(slot) = placed.get_mut(c) {
                if !*slot {
                    *slot = true;
                    order.push(c);
                }
            }
        }
    }
    order
}

#[inline(always)]
fn read_window(p: &Plan, buf: &[u8; BUFFER]) -> u128 {
    let mut w = [0u8; WINDOW];
    if let Some(src) = buf.get(p.window..p.window + WINDOW) {
        w.copy_from_slice(src);
    }
    if p.big_endian {
        u128::from_be_bytes(w)
    } else {
        u128::from_le_bytes(w)
    }
}

fn write_window(p: &Plan, buf: &mut [u8; BUFFER], raw: u128) {
    let Some(dst) = buf.get_mut(p.window..p.window + WINDOW) else {
        return;
    };
    let mut w = [0u8; WINDOW];
    w.copy_from_slice(dst);
    let mut word = if p.big_endian {
        u128::from_be_bytes(w)
    } else {
        u128::from_le_bytes(w)
    };
    word = (word & !(p.mask << p.shift)) | (raw << p.shift);
    let bytes = if p.big_endian {
        word.to_be_bytes()
    } else {
        word.to_le_bytes()
    };
    dst.copy_from_slice(&bytes);
}

#[inline(always)]
fn read_narrow(p: &Plan, payload: &[u8], buf: &[u8; BUFFER]) -> u64 {
    // Straight from the payload when the 8 bytes are in it, else from the zero-padded copy.
    let w: [u8; 8] = match payload
        .get(p.window..p.window + 8)
        .and_then(|b| b.try_into().ok())
    {
        Some(w) => w,
        None => buf
            .get(p.window..p.window + 8)
            .and_then(|b| b.try_into().ok())
            .unwrap_or([0; 8]),
    };
    // The mask keeps at most 64 bits; a big-endian signal in the first 8 bytes has shift >= 64.
    #[allow(clippy::cast_possible_truncation)]
    let mask = p.mask as u64;
    if p.big_endian {
        (u64::from_be_bytes(w) >> (p.shift - 64)) & mask
    } else {
        (u64::from_le_bytes(w) >> p.shift) & mask
    }
}

#[inline(always)]
fn decode_signal(p: &Plan, payload: &[u8], buf: &[u8; BUFFER]) -> Decoded {
    // The mask keeps at most 64 bits.
    #[allow(clippy::cast_possible_truncation)]
    let raw = if p.narrow {
        read_narrow(p, payload, buf)
    } else {
        ((read_window(p, buf) >> p.shift) & p.mask) as u64
    };
    physical(p, raw)
}

/// The physical value of a signal's raw bits.
#[inline(always)]
fn physical(p: &Plan, raw: u64) -> Decoded {
    Decoded {
        raw,
        physical: value_of(p.kernel, p, raw),
    }
}

/// The physical value of `raw` by the signal's kernel: one flat match, so the value stays in
/// registers (a nested dispatch made the compiler build it in memory and reload it).
#[inline(always)]
fn value_of(kernel: Kernel, p: &Plan, raw: u64) -> Value {
    match kernel {
        Kernel::UnsignedRaw => unsigned_raw(raw),
        Kernel::SignedRaw { unused } => signed_raw(raw, unused),
        Kernel::UnsignedFloat { scale, offset } => unsigned_float(raw, scale, offset),
        Kernel::SignedFloat {
            unused,
            scale,
            offset,
        } => signed_float(raw, unused, scale, offset),
        Kernel::General => general(p, raw),
    }
}

/// [`Kernel::UnsignedRaw`]'s value.
#[inline(always)]
fn unsigned_raw(raw: u64) -> Value {
    match i64::try_from(raw) {
        Ok(small) => Value::Int(small),
        Err(_) => Value::UInt(raw),
    }
}

/// Two's complement from `64 - unused` bits: the sign bit moved to bit 63 and shifted back.
#[inline(always)]
#[allow(clippy::cast_possible_wrap)]
fn sign_extended(raw: u64, unused: u32) -> i64 {
    ((raw << unused) as i64) >> unused
}

/// [`Kernel::SignedRaw`]'s value.
#[inline(always)]
fn signed_raw(raw: u64, unused: u32) -> Value {
    Value::Int(sign_extended(raw, unused))
}

/// [`Kernel::UnsignedFloat`]'s value. Fewer than 64 bits (see the kernel's choice): the
/// one-instruction signed conversion gives what the unsigned one would.
#[inline(always)]
#[allow(clippy::cast_precision_loss, clippy::cast_possible_wrap)]
fn unsigned_float(raw: u64, scale: f64, offset: f64) -> Value {
    Value::Float((raw as i64) as f64 * scale + offset)
}

/// [`Kernel::SignedFloat`]'s value.
#[inline(always)]
#[allow(clippy::cast_precision_loss)]
fn signed_float(raw: u64, unused: u32, scale: f64, offset: f64) -> Value {
    Value::Float(sign_extended(raw, unused) as f64 * scale + offset)
}

/// Any value type with any conversion, by Python's rules.
fn general(p: &Plan, raw: u64) -> Value {
    let number = match p.value_type {
        ValueType::Integer { signed: false } => unsigned_raw(raw),
        ValueType::Integer { signed: true } => signed_raw(raw, 64 - p.length),
        // The raw bits of a float signal are its IEEE representation; 32 low bits for f32.
        #[allow(clippy::cast_possible_truncation)]
        ValueType::Float32 => Value::Float(f64::from(f32::from_bits(raw as u32))),
        ValueType::Float64 => Value::Float(f64::from_bits(raw)),
    };
    scale(&p.conversion, number)
}

/// Python's `a * b` and `a + b` on int/float operands.
#[inline(always)]
fn mul(a: Value, b: Num) -> Value {
    match (a, b) {
        (a, Num::Int(y)) => match a.as_i128().and_then(|x| x.checked_mul(y)) {
            Some(product) => Value::integer(product),
            None => Value::Float(a.as_f64() * Num::Int(y).as_f64()),
        },
        (a, b) => Value::Float(a.as_f64() * b.as_f64()),
    }
}

#[inline(always)]
fn add(a: Value, b: Num) -> Value {
    match (a, b) {
        (a, Num::Int(y)) => match a.as_i128().and_then(|x| x.checked_add(y)) {
            Some(sum) => Value::integer(sum),
            None => Value::Float(a.as_f64() + Num::Int(y).as_f64()),
        },
        (a, b) => Value::Float(a.as_f64() + b.as_f64()),
    }
}

#[inline(always)]
fn scale(c: &Conversion, raw: Value) -> Value {
    match c {
        Conversion::Identity => raw,
        Conversion::Integer { scale, offset } => add(mul(raw, Num::Int(*scale)), Num::Int(*offset)),
        Conversion::Float { scale, offset } => Value::Float(raw.as_f64() * scale + offset),
        Conversion::Linear { scale, offset } => add(mul(raw, *scale), *offset),
    }
}

/// Python's `round()` of a float to an integer: half to even; non-finite and huge values clamp.
fn round_even(f: f64) -> i128 {
    let r = f.round_ties_even();
    if r.is_nan() {
        0
    } else {
        // Saturating float-to-int conversion is what we want for out-of-range values.
        #[allow(clippy::cast_possible_truncation)]
        let i = r as i128;
        i
    }
}

fn to_raw(p: &Plan, v: Value) -> u64 {
    let as_bits = |i: i128| {
        // Two's complement truncated to 64 bits, then masked by the caller.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let r = i as u64;
        r
    };
    let physical_to_float = |v: Value| match &p.conversion {
        Conversion::Identity => v.as_f64(),
        Conversion::Integer { scale, offset } => {
            (v.as_f64() - Num::Int(*offset).as_f64()) / Num::Int(*scale).as_f64()
        }
        Conversion::Float { scale, offset } => (v.as_f64() - offset) / scale,
        Conversion::Linear { scale, offset } => (v.as_f64() - offset.as_f64()) / scale.as_f64(),
    };
    match p.value_type {
        #[allow(clippy::cast_possible_truncation)]
        ValueType::Float32 => u64::from((physical_to_float(v) as f32).to_bits()),
        ValueType::Float64 => physical_to_float(v).to_bits(),
        ValueType::Integer { .. } => match (&p.conversion, v.as_i128()) {
            (Conversion::Identity, Some(i)) => as_bits(i),
            (Conversion::Integer { scale, offset }, Some(i)) if *scale != 0 => {
                let shifted = i - offset;
                if shifted % scale == 0 {
                    as_bits(shifted.div_euclid(*scale))
                } else {
                    as_bits(round_even(physical_to_float(v)))
                }
            }
            _ => as_bits(round_even(physical_to_float(v))),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{parse_str, Mode};

    #[test]
    fn a_signal_placed_anywhere_compiles_and_decodes_as_past_the_end() {
        // A model from JSON is not checked as a file is: the last bits a u32 can name.
        let (mut db, _) = parse_str(
            "BO_ 1 M: 8 X\n SG_ S : 7|16@0+ (1,0) [0|0] \"\" X\n",
            Mode::Lenient,
        )
        .unwrap();
        for start in [u32::MAX, u32::MAX - 7, 1 << 31] {
            for order in [ByteOrder::BigEndian, ByteOrder::LittleEndian] {
                db.messages[0].signals[0].start_bit = start;
                db.messages[0].signals[0].byte_order = order;
                let c = MessageCodec::new(&db.messages[0]);
                let mut out = vec![None; 1];
                let _ = c.decode(&[0; 8], &mut out);
                assert!(out[0].is_none());
            }
        }
    }

    fn codec(sg: &str) -> MessageCodec {
        let text = format!("BO_ 1 M: 8 X\n{sg}\n");
        let (db, diags) = parse_str(&text, Mode::Lenient).unwrap();
        assert!(diags.is_empty(), "{diags:?}");
        MessageCodec::new(&db.messages[0])
    }

    fn decode(c: &MessageCodec, data: &[u8]) -> Vec<Option<Value>> {
        let mut out = vec![None; c.signal_count()];
        c.decode(data, &mut out).unwrap();
        out.into_iter().map(|d| d.map(|d| d.physical)).collect()
    }

    #[test]
    fn intel_and_motorola_with_python_numbers() {
        let c = codec(" SG_ A : 0|12@1+ (1,0) [0|0] \"\" X\n SG_ B : 23|12@0- (0.5,-1) [0|0] \"\" X\n SG_ C : 63|8@0+ (2,3) [0|0] \"\" X");
        let data = [0x34, 0x02, 0x34, 0x10, 0, 0, 0, 0x05];
        let d = decode(&c, &data);
        // A: the 12 low bits of the little-endian bytes 0-1.
        assert_eq!(d[0], Some(Value::Int(0x234)));
        // B: byte 2, then the high nibble of byte 3: 0x341 = 833, signed 12 bits stays positive.
        assert_eq!(d[1], Some(Value::Float(833.0 * 0.5 - 1.0)));
        assert_eq!(d[2], Some(Value::Int(5 * 2 + 3)));
        let mut out = [0u8; 8];
        c.encode(&d, &mut out).unwrap();
        assert_eq!(out, data);
    }

    #[test]
    fn strict_encoding_refuses_and_clamping_clamps() {
        let c = codec(
            " SG_ Speed : 0|8@1+ (0.5,0) [0|100] \"km/h\" X\n SG_ Free : 8|4@1- (1,0) [0|0] \"\" X",
        );
        let mut out = [0u8; 8];
        let ok = [Some(Value::Float(100.0)), Some(Value::Int(-8))];
        assert_eq!(c.encode_checked(&ok, &mut out, EncodeMode::Strict), Ok(8));
        assert_eq!(out[..2], [200, 0x08]);
        let high = [Some(Value::Float(100.5)), None];
        let Err(EncodeError::Range(e)) = c.encode_checked(&high, &mut out, EncodeMode::Strict)
        else {
            panic!("a range error")
        };
        assert_eq!((e.signal, e.min, e.max), (0, 0.0, 100.0));
        // No declared range: the raw width (4 bits signed: -8..7) is the limit.
        let wide = [None, Some(Value::Int(9))];
        let Err(EncodeError::Range(e)) = c.encode_checked(&wide, &mut out, EncodeMode::Strict)
        else {
            panic!("a range error")
        };
        assert_eq!(e.max, 7.0);
        // A buffer shorter than the message is said to be that, not a range problem.
        assert!(matches!(
            c.encode_checked(&ok, &mut [0u8; 4], EncodeMode::Strict),
            Err(EncodeError::Buffer(DecodeError::TooShort { .. }))
        ));
        c.encode_checked(
            &[Some(Value::Float(250.0)), Some(Value::Int(-100))],
            &mut out,
            EncodeMode::Clamp,
        )
        .unwrap();
        assert_eq!(out[..2], [200, 0x08]);
    }

    #[test]
    fn short_payload_is_an_error_and_mux_selects() {
        let c = codec(" SG_ Mux M : 0|4@1+ (1,0) [0|0] \"\" X\n SG_ A m1 : 8|8@1+ (1,0) [0|0] \"\" X\n SG_ B m2 : 8|8@1+ (1,0) [0|0] \"\" X");
        let mut out = vec![None; 3];
        assert_eq!(
            c.decode(&[1, 2], &mut out),
            Err(DecodeError::TooShort { needed: 8, got: 2 })
        );
        let d = decode(&c, &[2, 7, 0, 0, 0, 0, 0, 0]);
        assert_eq!(d, vec![Some(Value::Int(2)), None, Some(Value::Int(7))]);
        assert_eq!(
            c.decode(&[3, 0, 0, 0, 0, 0, 0, 0], &mut out),
            Err(DecodeError::UnknownMultiplexerValue {
                signal: 0,
                value: 3
            })
        );
    }
}
