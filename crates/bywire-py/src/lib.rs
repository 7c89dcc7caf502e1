//! `bywire._native`: the Python package's native module. The package (`python/bywire`) wraps
//! it; this crate only converts between Python and the libraries:
//!
//! - `Database`: a DBC loaded by bywire-dbc, decoding and encoding with cantools' call
//!   signatures, values and errors (`decode_message`, `encode_message`), and whole Arrow
//!   batches of frames decoded into one batch per message (`decode_arrow`);
//! - `LogBatches`: a log of any format bywire-log reads, as Arrow record batches of its
//!   frames (the raw frames' table layout);
//! - `run_sim`: a simulator run as fast as possible, its bus logs and report written;
//! - `run_cli`: the `bywire` command line, for the package's console script;
//! - `CanBus`: a bus endpoint of any backend, for python-can's `interface="bywire"`.
//!
//! Arrow crosses to pyarrow through the Arrow C data interface (`arrow-pyarrow`): no copy.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow_array::RecordBatch;
use arrow_pyarrow::PyArrowType;
use bywire_core::Timestamp;
use bywire_data::decoded::decode_frames_batch;
use bywire_data::lake::{self, LakeCompression, LakeFiles, LakePart, LAKE_GROUP_ROWS};
use bywire_data::long::{self, LongLabels};
use bywire_dbc::codec::{DecodeError as CodecError, MessageCodec, Value};
use bywire_dbc::decoder::{Decoder, SignalValue};
use bywire_dbc::named::{
    encode_named_at, selected_by, selector_values, Encoding, Given, Named, NamedError,
};
use bywire_dbc::{ByteOrder, Message, Mode, Multiplexing, Signal, ValueType};
use bywire_log::batches::FrameBatches;
use bywire_log::format::Format;
use bywire_log::parquet::raw_schema;
use pyo3::exceptions::{
    PyException, PyIndexError, PyKeyError, PyOSError, PyOverflowError, PyTypeError, PyValueError,
};
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyByteArray, PyBytes, PyDict, PyFloat, PyInt, PyString, PyType};

/// The columns handed to Python are megabytes allocated and freed on every call. The system
/// allocator gives such blocks back to the kernel when they are freed and faults them in again
/// on the next call: half of `decode_arrow`'s time went to page faults. mimalloc keeps freed
/// memory for the calls that follow.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

pyo3::create_exception!(_native, Error, PyException, "Every bywire error.");
pyo3::create_exception!(
    _native,
    ParseError,
    Error,
    "A DBC file that cannot be loaded."
);
pyo3::create_exception!(_native, DecodeError, Error, "Data that does not decode.");
pyo3::create_exception!(_native, EncodeError, Error, "Values that do not encode.");
pyo3::create_exception!(_native, LogError, Error, "A log that cannot be read.");
pyo3::create_exception!(
    _native,
    ScenarioError,
    Error,
    "A simulation that cannot run."
);

/// cantools' `NamedSignalValue` equivalent, defined in Python (`bywire._values`).
static NAMED_VALUE: PyOnceLock<Py<PyType>> = PyOnceLock::new();

/// Rows a batch from [`LogBatches`] holds unless asked otherwise.
const DEFAULT_BATCH_ROWS: usize = 65_536;
/// The most rows a batch may be asked to hold (a batch is built in memory).
const MAX_BATCH_ROWS: usize = 1 << 24;

/// The bytes of a `bytes`, `bytearray` or any object `bytes()` takes.
fn bytes_of(data: &Bound<'_, PyAny>) -> PyResult<Vec<u8>> {
    if let Ok(b) = data.cast::<PyBytes>() {
        return Ok(b.as_bytes().to_vec());
    }
    if let Ok(b) = data.cast::<PyByteArray>() {
        return Ok(b.to_vec());
    }
    let builtins = data.py().import("builtins")?;
    let converted = builtins.getattr("bytes")?.call1((data,))?;
    Ok(converted.cast::<PyBytes>()?.as_bytes().to_vec())
}

/// cantools' `format_or`: `1, 2 or 3`.
fn format_or(items: &[String]) -> String {
    match items {
        [] => String::new(),
        [one] => one.clone(),
        [rest @ .., last] => format!("{} or {last}", rest.join(", ")),
    }
}

/// A number as Python has it: `int` for exact integers, `float` otherwise.
fn number<'py>(py: Python<'py>, value: Value) -> PyResult<Bound<'py, PyAny>> {
    Ok(match value {
        Value::Int(i) => i.into_pyobject(py)?.into_any(),
        Value::UInt(u) => u.into_pyobject(py)?.into_any(),
        Value::Float(f) => f.into_pyobject(py)?.into_any(),
    })
}

/// A decoded signal's raw value as cantools gives it unscaled: the float of a float signal,
/// the sign-extended integer of a signed one.
fn raw_number(signal: &Signal, raw: u64) -> Value {
    match signal.value_type {
        ValueType::Float32 => Value::Float(f64::from(f32::from_bits(
            u32::try_from(raw & u64::from(u32::MAX)).unwrap_or(0),
        ))),
        ValueType::Float64 => Value::Float(f64::from_bits(raw)),
        ValueType::Integer { signed: true } => {
            let unused = 64u32.saturating_sub(signal.length.clamp(1, 64));
            let bits = i64::from_ne_bytes((raw << unused).to_ne_bytes());
            Value::Int(bits >> unused)
        }
        ValueType::Integer { signed: false } => Value::integer(i128::from(raw)),
    }
}

/// Whether the signal's bits end past `bytes` bytes (cantools' rule for truncated data: the
/// signal counted from its start bit in network order).
fn past_available(signal: &Signal, bytes: usize) -> bool {
    u64::from(signal.network_start_bit()) + u64::from(signal.length)
        > (bytes as u64).saturating_mul(8)
}

/// The multiplexor cantools reports when a frame's multiplexing does not decode: the first in
/// its order (by start bit in network order) that is in effect and whose value selects nothing — its index, its
/// value and the values it accepts.
fn failing_multiplexor(
    message: &Message,
    codec: &MessageCodec,
    payload: &[u8],
) -> Option<(usize, i128, Vec<i128>)> {
    let value_of = |i: usize| -> Option<i128> {
        let raw = codec.read_raw(i, payload)?;
        raw_number(message.signals.get(i)?, raw).as_i128()
    };
    let mut by_start: Vec<usize> = (0..message.signals.len()).collect();
    by_start.sort_by_key(|i| message.signals.get(*i).map(Signal::network_start_bit));
    by_start.into_iter().find_map(|i| {
        let switch = message.signals.get(i)?;
        let in_effect = match codec.switch_of(i) {
            None => true,
            Some(parent) => value_of(parent).is_some_and(|v| selected_by(switch, v)),
        };
        let number = value_of(i)?;
        let accepted = selector_values(message, codec, i);
        (in_effect && !accepted.is_empty() && !accepted.contains(&number))
            .then_some((i, number, accepted))
    })
}

/// A value to encode, as Python gave it (`key: value` of the dict).
struct Item<'py> {
    key: Bound<'py, PyString>,
    choice: Option<Choice<'py>>,
    number: Option<Value>,
    /// The signal's index in its message (None: no signal of that name).
    position: Option<usize>,
    /// The value's `str()` and type name, filled only to report an error.
    shown: String,
    type_name: String,
}

/// A choice given by name: a Python string (`NamedSignalValue` of bywire is one) or the name
/// of cantools' `NamedSignalValue`.
enum Choice<'py> {
    Text(Bound<'py, PyString>),
    Named(String),
}

impl Choice<'_> {
    fn as_str(&self) -> PyResult<&str> {
        match self {
            Choice::Text(text) => text.to_str(),
            Choice::Named(name) => Ok(name),
        }
    }
}

/// A value given to encode: the choice it names (a string, bywire's `NamedSignalValue` or
/// cantools' — whose number must be the one its name has, as cantools checks) or its number.
fn given_value<'py>(
    message: &Message,
    signal: &str,
    value: &Bound<'py, PyAny>,
) -> PyResult<(Option<Choice<'py>>, Option<Value>)> {
    if let Ok(text) = value.cast::<PyString>() {
        return Ok((Some(Choice::Text(text.clone())), None));
    }
    if let Ok(f) = value.cast::<PyFloat>() {
        return Ok((None, Some(Value::Float(f.value()))));
    }
    if value.cast::<PyInt>().is_ok() {
        if let Ok(i) = value.extract::<i64>() {
            return Ok((None, Some(Value::Int(i))));
        }
        if let Ok(u) = value.extract::<u64>() {
            return Ok((None, Some(Value::UInt(u))));
        }
        return Ok((None, value.extract::<f64>().ok().map(Value::Float)));
    }
    // cantools' NamedSignalValue (or anything with a name and a value).
    if let (Ok(name), Ok(number)) = (value.getattr("name"), value.getattr("value")) {
        if let (Ok(name), Ok(number)) = (name.extract::<String>(), number.extract::<i128>()) {
            let declared = message
                .signals
                .iter()
                .filter(|s| s.display_name() == signal)
                .any(|s| s.value_descriptions.contains(&(number, name.clone())));
            if !declared {
                return Err(EncodeError::new_err(format!(
                    "Invalid 'NamedSignalValue' name/value pair not found! Name {name}, value {number}"
                )));
            }
            return Ok((Some(Choice::Named(name)), None));
        }
    }
    Ok((None, value.extract::<f64>().ok().map(Value::Float)))
}

/// A DBC database: cantools `Database` for the common calls, and Arrow decoding.
#[pyclass(frozen, module = "bywire._native")]
struct Database {
    decoder: Arc<Decoder>,
    codecs: Vec<MessageCodec>,
    /// Frame identifier (bit 31 set for an extended one) → message, as cantools looks it up
    /// (the last message with it).
    by_frame_id: HashMap<u32, usize>,
    /// Name → message (the last with it, as in cantools).
    by_name: HashMap<String, usize>,
    diagnostics: Vec<String>,
    /// Each message's keys, decode order and choice objects, made on its first decode.
    prepared: Vec<PyOnceLock<Prepared>>,
}

/// What decoding a message into a dict needs from Python, made once: the signals' names as
/// Python strings, the order cantools fills the dict in, and each value description as the
/// `NamedSignalValue` every decode returns.
struct Prepared {
    keys: Vec<Py<PyString>>,
    order: Vec<usize>,
    choices: Vec<Vec<(i128, Py<PyAny>)>>,
    /// The keys in order with None values, for a message without multiplexing.
    template: Option<Py<PyDict>>,
    /// Each signal's name → its index (the first signal of a name).
    index_of: Py<PyDict>,
}

impl Prepared {
    fn new(py: Python<'_>, message: &Message, codec: &MessageCodec) -> PyResult<Self> {
        let named = NAMED_VALUE.import(py, "bywire._values", "NamedSignalValue")?;
        let keys: Vec<Py<PyString>> = message
            .signals
            .iter()
            .map(|s| PyString::intern(py, s.display_name()).unbind())
            .collect();
        let mut choices = Vec::with_capacity(message.signals.len());
        for signal in &message.signals {
            let mut objects = Vec::with_capacity(signal.value_descriptions.len());
            for (key, name) in &signal.value_descriptions {
                objects.push((*key, named.call1((*key, name))?.unbind()));
            }
            choices.push(objects);
        }
        let order = dict_order(codec, message.signals.len());
        let multiplexed = (0..message.signals.len()).any(|i| codec.switch_of(i).is_some());
        let template = if multiplexed {
            None
        } else {
            let template = PyDict::new(py);
            for &i in &order {
                if let Some(key) = keys.get(i) {
                    template.set_item(key.bind(py), py.None())?;
                }
            }
            Some(template.unbind())
        };
        // By full name, then by the DBC's short name where it differs (as encode_named finds).
        let index_of = PyDict::new(py);
        for (i, key) in keys.iter().enumerate() {
            if !index_of.contains(key.bind(py))? {
                index_of.set_item(key.bind(py), i)?;
            }
        }
        for (i, signal) in message.signals.iter().enumerate() {
            if !index_of.contains(&signal.name)? {
                index_of.set_item(&signal.name, i)?;
            }
        }
        Ok(Prepared {
            keys,
            order,
            choices,
            template,
            index_of: index_of.unbind(),
        })
    }
}

/// The order cantools fills a decoded dict in: the signals no multiplexor selects, in the
/// message's order, then what each of those multiplexors selects, depth first.
fn dict_order(codec: &MessageCodec, count: usize) -> Vec<usize> {
    let mut order = Vec::with_capacity(count);
    let mut listed = vec![false; count];
    // Each pass appends the children of one parent; a parent is expanded once, so the loop
    // runs at most count + 1 times.
    let mut parents: Vec<Option<usize>> = vec![None];
    while let Some(parent) = parents.pop() {
        let children: Vec<usize> = (0..count)
            .filter(|&i| codec.switch_of(i) == parent && !listed.get(i).copied().unwrap_or(true))
            .collect();
        for &child in &children {
            if let Some(seen) = listed.get_mut(child) {
                *seen = true;
            }
        }
        order.extend(&children);
        // Expanded in the children's order: pushed reversed onto the stack.
        for &child in children.iter().rev() {
            parents.push(Some(child));
        }
    }
    order
}

fn format_named(name: &str) -> PyResult<bywire_dbc::Format> {
    bywire_dbc::Format::from_name(name).ok_or_else(|| {
        pyo3::exceptions::PyValueError::new_err(format!(
            "{name} is not a database format (dbc, kcd, sym, arxml, cdd)"
        ))
    })
}

impl Database {
    fn new(bytes: &[u8], strict: bool, origin: &str, format: bywire_dbc::Format) -> PyResult<Self> {
        let mode = if strict { Mode::Strict } else { Mode::Lenient };
        let (db, diagnostics) = bywire_dbc::format::load(bytes, format, mode).map_err(|e| {
            ParseError::new_err(format!(
                "{origin}:{}:{}: {}",
                e.0.line, e.0.column, e.0.message
            ))
        })?;
        let diagnostics = diagnostics
            .iter()
            .map(|d| format!("{origin}:{}:{}: {}", d.line, d.column, d.message))
            .collect();
        Ok(Database::of(db, diagnostics))
    }

    fn of(db: bywire_dbc::Database, diagnostics: Vec<String>) -> Self {
        let codecs = db.messages.iter().map(MessageCodec::new).collect();
        let by_frame_id = db.messages.iter().enumerate().map(|(i, m)| (m.raw_id(), i));
        let by_name = db
            .messages
            .iter()
            .enumerate()
            .map(|(i, m)| (m.display_name().to_string(), i));
        Database {
            prepared: db.messages.iter().map(|_| PyOnceLock::new()).collect(),
            by_frame_id: by_frame_id.collect(),
            by_name: by_name.collect(),
            codecs,
            diagnostics,
            decoder: Arc::new(Decoder::new(db)),
        }
    }

    fn messages(&self) -> &[Message] {
        &self.decoder.database().messages
    }

    /// The index of the message a frame identifier or name stands for, as cantools finds it
    /// (an identifier above 0x7FF, or any with `force_extended`, is an extended one);
    /// `KeyError` naming what was looked up, as cantools raises.
    fn lookup(&self, frame_id_or_name: &Bound<'_, PyAny>, force_extended: bool) -> PyResult<usize> {
        if let Ok(name) = frame_id_or_name.cast::<PyString>() {
            return self
                .by_name
                .get(name.to_str()?)
                .copied()
                .ok_or_else(|| PyKeyError::new_err(frame_id_or_name.clone().unbind()));
        }
        let Ok(id) = frame_id_or_name.extract::<u64>() else {
            return Err(PyValueError::new_err(format!(
                "Invalid frame_id_or_name '{}'",
                frame_id_or_name.str()?
            )));
        };
        let key = if force_extended || id > 0x7FF {
            id | 0x8000_0000
        } else {
            id
        };
        u32::try_from(key)
            .ok()
            .and_then(|key| self.by_frame_id.get(&key).copied())
            .ok_or_else(|| PyKeyError::new_err(key))
    }

    fn message_at(&self, index: usize) -> PyResult<(&Message, &MessageCodec)> {
        self.messages()
            .get(index)
            .zip(self.codecs.get(index))
            .ok_or_else(|| PyIndexError::new_err(index))
    }

    fn prepared_at(&self, py: Python<'_>, index: usize) -> PyResult<&Prepared> {
        let (message, codec) = self.message_at(index)?;
        let cell = self
            .prepared
            .get(index)
            .ok_or_else(|| PyIndexError::new_err(index))?;
        if let Some(prepared) = cell.get(py) {
            return Ok(prepared);
        }
        let prepared = Prepared::new(py, message, codec)?;
        Ok(cell.get_or_init(py, || prepared))
    }

    /// [`Database::decode_with`] on any bytes-like object (bytes and bytearray without a copy).
    #[allow(clippy::too_many_arguments)]
    fn decode_bytes<'py>(
        &self,
        py: Python<'py>,
        index: usize,
        data: &Bound<'py, PyAny>,
        decode_choices: bool,
        scaling: bool,
        allow_truncated: bool,
        allow_excess: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        if let Ok(bytes) = data.cast::<PyBytes>() {
            let bytes = bytes.as_bytes();
            return self.decode_with(
                py,
                index,
                bytes,
                decode_choices,
                scaling,
                allow_truncated,
                allow_excess,
            );
        }
        let bytes = bytes_of(data)?;
        self.decode_with(
            py,
            index,
            &bytes,
            decode_choices,
            scaling,
            allow_truncated,
            allow_excess,
        )
    }

    fn encode_dict<'py>(
        &self,
        py: Python<'py>,
        index: usize,
        data: &Bound<'py, PyAny>,
        scaling: bool,
        padding: bool,
        strict: bool,
    ) -> PyResult<Bound<'py, PyBytes>> {
        let (message, codec) = self.message_at(index)?;
        let Ok(values) = data.cast::<PyDict>() else {
            return Err(EncodeError::new_err(
                "The payload for encoding non-container messages must be a signal name to signal value dictionary",
            ));
        };
        let payload =
            self.encode_with(py, index, message, codec, values, scaling, padding, strict)?;
        Ok(PyBytes::new(py, &payload))
    }

    #[allow(clippy::too_many_arguments)]
    fn decode_with<'py>(
        &self,
        py: Python<'py>,
        index: usize,
        data: &[u8],
        decode_choices: bool,
        scaling: bool,
        allow_truncated: bool,
        allow_excess: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (message, codec) = self.message_at(index)?;
        let size = codec.size();
        // Copied only when it must change (cut or padded, or a multiplexor rewritten).
        let mut payload = std::borrow::Cow::Borrowed(data);
        if payload.len() != size {
            let payload = payload.to_mut();
            if allow_truncated && payload.len() < size {
                payload.resize(size, 0xFF);
            }
            if allow_excess {
                payload.truncate(size);
            }
        }
        if payload.len() != size {
            {
                return Err(DecodeError::new_err(format!(
                    "Wrong data size: {} instead of {size} bytes",
                    data.len()
                )));
            }
        }
        let mut out = vec![None; codec.signal_count()];
        let truncated = data.len() < size && allow_truncated;
        // A multiplexor past truncated data is skipped, as cantools does: its bits are set to a
        // value it accepts and it is left out below (once per multiplexor at most).
        for _ in 0..=message.signals.len() {
            let Err(error) = codec.decode(&payload, &mut out) else {
                break;
            };
            let CodecError::UnknownMultiplexerValue { signal, value } = error else {
                return Err(DecodeError::new_err(error.to_string()));
            };
            let (index, got, accepted) = failing_multiplexor(message, codec, &payload)
                .unwrap_or_else(|| {
                    let number = message
                        .signals
                        .get(signal)
                        .and_then(|s| raw_number(s, value).as_i128())
                        .unwrap_or(i128::from(value));
                    (signal, number, selector_values(message, codec, signal))
                });
            let past = message
                .signals
                .get(index)
                .is_some_and(|s| past_available(s, data.len()));
            match accepted.first() {
                Some(valid) if truncated && past => {
                    let bits = u64::from_ne_bytes(i64::try_from(*valid).unwrap_or(0).to_ne_bytes());
                    codec.write_raw(index, bits, payload.to_mut());
                }
                _ => {
                    let expected: Vec<String> = accepted.iter().map(i128::to_string).collect();
                    return Err(DecodeError::new_err(format!(
                        "expected multiplexer id {}, but got {got}",
                        format_or(&expected)
                    )));
                }
            }
        }
        if truncated {
            // Signals past the data are left out, and so is what their multiplexor selects.
            for (i, signal) in message.signals.iter().enumerate() {
                if past_available(signal, data.len()) {
                    if let Some(slot) = out.get_mut(i) {
                        *slot = None;
                    }
                }
            }
            for i in 0..message.signals.len() {
                let switch_gone = codec
                    .switch_of(i)
                    .is_some_and(|s| out.get(s).copied().flatten().is_none());
                if switch_gone {
                    if let Some(slot) = out.get_mut(i) {
                        *slot = None;
                    }
                }
            }
        }
        let prepared = self.prepared_at(py, index)?;
        // Every signal present: a copy of the message's dict of keys, whose values are then
        // replaced (no growing the dict key by key).
        let dict = match &prepared.template {
            Some(template) if out.iter().all(Option::is_some) => template.bind(py).copy()?,
            _ => PyDict::new(py),
        };
        for &i in &prepared.order {
            let (Some(Some(decoded)), Some(signal), Some(key), Some(choices)) = (
                out.get(i),
                message.signals.get(i),
                prepared.keys.get(i),
                prepared.choices.get(i),
            ) else {
                continue;
            };
            let choice = (decode_choices && !choices.is_empty())
                .then(|| {
                    SignalValue {
                        signal,
                        value: *decoded,
                    }
                    .description_key()
                })
                .flatten()
                .and_then(|key| {
                    choices
                        .iter()
                        .find(|(k, _)| *k == key)
                        .map(|(_, object)| object.bind(py).clone())
                });
            let value = match choice {
                Some(object) => object,
                None if scaling => number(py, decoded.physical)?,
                None => number(py, raw_number(signal, decoded.raw))?,
            };
            dict.set_item(key.bind(py), value)?;
        }
        Ok(dict)
    }

    /// cantools' `encode_message` for one message, by [`encode_named_at`]: each value taken
    /// as Python gives it (a number, a choice's name or a `NamedSignalValue`), each error
    /// raised as cantools raises it.
    #[allow(clippy::too_many_arguments)]
    fn encode_with<'py>(
        &self,
        py: Python<'py>,
        index: usize,
        message: &Message,
        codec: &MessageCodec,
        data: &Bound<'py, PyDict>,
        scaling: bool,
        padding: bool,
        strict: bool,
    ) -> PyResult<Vec<u8>> {
        let index_of = self.prepared_at(py, index)?.index_of.bind(py);
        // Each value with its signal, its choice name if it is one, and (only to report an
        // error, in a second pass) its text and type as Python shows them.
        let mut items = Vec::with_capacity(data.len());
        for (key, value) in data.iter() {
            let key = key.cast_into::<PyString>()?;
            let position = match index_of.get_item(&key)? {
                Some(i) => Some(i.extract::<usize>()?),
                None => None,
            };
            let (choice, number) = given_value(message, key.to_str()?, &value)?;
            items.push(Item {
                key,
                choice,
                number,
                position,
                shown: String::new(),
                type_name: String::new(),
            });
        }
        let result = self.encode_items(message, codec, &items, scaling, padding, strict);
        if result.is_ok() {
            return result;
        }
        for ((_, value), item) in data.iter().zip(items.iter_mut()) {
            item.shown = value.str()?.to_string();
            item.type_name = value.get_type().name()?.to_string();
        }
        self.encode_items(message, codec, &items, scaling, padding, strict)
    }

    fn encode_items(
        &self,
        message: &Message,
        codec: &MessageCodec,
        items: &[Item<'_>],
        scaling: bool,
        padding: bool,
        strict: bool,
    ) -> PyResult<Vec<u8>> {
        let mut values = Vec::with_capacity(items.len());
        for item in items {
            values.push(Named {
                signal: item.key.to_str()?,
                value: match (&item.choice, item.number) {
                    (Some(choice), _) => Given::Choice(choice.as_str()?),
                    (None, Some(number)) => Given::Number(number),
                    (None, None) => Given::Unusable,
                },
                shown: &item.shown,
            });
        }
        let positions: Vec<Option<usize>> = items.iter().map(|item| item.position).collect();
        let encoding = Encoding {
            scaling,
            padding,
            ..Encoding::cantools(strict)
        };
        encode_named_at(message, codec, &values, &positions, encoding).map_err(|error| match error {
            NamedError::Unused { names, .. } => {
                let quoted: Vec<String> = names.iter().map(|n| format!("'{n}'")).collect();
                EncodeError::new_err(format!(
                    "The following signals were specified but are not required to encode the message:{{{}}}",
                    quoted.join(", ")
                ))
            }
            NamedError::UnknownChoice { name, .. } => PyKeyError::new_err(name),
            NamedError::Unusable { signal } => {
                let type_name = items
                    .iter()
                    .find(|item| item.key.to_str().is_ok_and(|key| key == signal))
                    .map_or("object", |item| item.type_name.as_str());
                PyTypeError::new_err(format!(
                    "Unable to encode signal '{signal}' with type '{type_name}'."
                ))
            }
            // An integer signal holds no NaN or infinity: cantools raises as Python's int()
            // does, strict or not.
            NamedError::NotFinite {
                integer: true,
                value,
                ..
            } if value.is_nan() => PyValueError::new_err("cannot convert float NaN to integer"),
            NamedError::NotFinite { integer: true, .. } => {
                PyOverflowError::new_err("cannot convert float infinity to integer")
            }
            NamedError::Codec { error, .. } => EncodeError::new_err(error.to_string()),
            other => EncodeError::new_err(other.to_string()),
        })
    }
}

#[pymethods]
impl Database {
    /// Load a database file: DBC, KCD, SYM or ARXML, by `database_format` (`"dbc"`, `"kcd"`,
    /// `"sym"`, `"arxml"`), else the extension, else the content (`strict`: the first problem is an
    /// error; otherwise what a reasonable engineer accepts loads, each problem in
    /// `diagnostics`).
    #[staticmethod]
    #[pyo3(signature = (path, strict = false, database_format = None))]
    fn load(path: PathBuf, strict: bool, database_format: Option<&str>) -> PyResult<Self> {
        let bytes = std::fs::read(&path)
            .map_err(|e| PyOSError::new_err(format!("{}: {e}", path.display())))?;
        let forced = database_format.map(format_named).transpose()?;
        let format = bywire_dbc::Format::of_file(forced, &path, &bytes);
        Database::new(&bytes, strict, &path.display().to_string(), format)
    }

    /// Load database text: DBC, KCD, SYM or ARXML, by `database_format`, else by its content.
    #[staticmethod]
    #[pyo3(signature = (text, strict = false, database_format = None))]
    fn load_string(text: &str, strict: bool, database_format: Option<&str>) -> PyResult<Self> {
        let format = match database_format {
            Some(name) => format_named(name)?,
            None => bywire_dbc::Format::sniff(text.as_bytes()),
        };
        Database::new(text.as_bytes(), strict, "<string>", format)
    }

    /// Load a database from its bytes: DBC, KCD, SYM or ARXML, by `database_format`, else by its
    /// content; `origin` names it in errors and diagnostics.
    #[staticmethod]
    #[pyo3(signature = (data, origin, strict = false, database_format = None))]
    fn load_bytes(
        data: &[u8],
        origin: &str,
        strict: bool,
        database_format: Option<&str>,
    ) -> PyResult<Self> {
        let format = match database_format {
            Some(name) => format_named(name)?,
            None => bywire_dbc::Format::sniff(data),
        };
        Database::new(data, strict, origin, format)
    }

    /// A database from its model as JSON (what `to_json` gives), messages and signals in the
    /// order given; the loaded file's diagnostics are kept when `diagnostics` is passed.
    #[staticmethod]
    #[pyo3(signature = (text, diagnostics = Vec::new()))]
    fn from_json(text: &str, diagnostics: Vec<String>) -> PyResult<Self> {
        let db: bywire_dbc::Database = serde_json::from_str(text)
            .map_err(|e| ParseError::new_err(format!("database model: {e}")))?;
        Ok(Database::of(db, diagnostics))
    }

    /// The database's model as JSON: everything the file said (`bywire dbc convert`'s JSON).
    fn to_json(&self) -> PyResult<String> {
        serde_json::to_string(self.decoder.database())
            .map_err(|e| PyValueError::new_err(e.to_string()))
    }

    /// The database written as `database_format` (dbc, kcd, sym): `(text, left_out)`, what the
    /// format cannot say listed in `left_out`.
    fn write(&self, database_format: &str) -> PyResult<(String, Vec<String>)> {
        let format = format_named(database_format)?;
        if !format.is_written() {
            return Err(PyValueError::new_err(format!(
                "{format} is read, not written (dbc, kcd, sym are written)"
            )));
        }
        let (text, omissions) = bywire_dbc::format::write(self.decoder.database(), format);
        Ok((text, omissions.iter().map(ToString::to_string).collect()))
    }

    /// The layout errors cantools refuses when strict: `(code, sentence)` for each signal past
    /// its message's end (`past-end`) or sharing bits with another (`overlap`).
    fn layout_errors(&self) -> Vec<(&'static str, String)> {
        bywire_dbc::lint::lint(self.decoder.database())
            .into_iter()
            .filter(|f| matches!(f.code, "past-end" | "overlap"))
            .map(|f| (f.code, f.text))
            .collect()
    }

    /// The index of the message with this frame identifier or name (`KeyError` if none).
    fn index_of(&self, frame_id_or_name: &Bound<'_, PyAny>) -> PyResult<usize> {
        self.lookup(frame_id_or_name, false)
    }

    /// The message at `index` as an object whose `decode` and `encode` are cantools'
    /// `Message.decode` and `Message.encode`.
    fn message(slf: Bound<'_, Self>, index: usize) -> PyResult<MessageCodecs> {
        slf.get().message_at(index)?;
        Ok(MessageCodecs {
            database: slf.unbind(),
            index,
        })
    }

    /// The problems found while loading, `FILE:LINE:COLUMN: what`.
    #[getter]
    fn diagnostics(&self) -> Vec<String> {
        self.diagnostics.clone()
    }

    /// The messages' names, in the file's order.
    #[getter]
    fn message_names(&self) -> Vec<String> {
        self.messages()
            .iter()
            .map(|m| m.display_name().to_string())
            .collect()
    }

    /// One message's description: name, frame_id, is_extended_frame, length, cycle_time (ms
    /// or None), senders, and its signals (name, start, length, byte_order, is_signed,
    /// is_float, scale, offset, minimum, maximum, unit, is_multiplexer, multiplexer_ids,
    /// choices).
    fn message_info<'py>(
        &self,
        py: Python<'py>,
        frame_id_or_name: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (message, codec) = self.message_at(self.lookup(frame_id_or_name, false)?)?;
        let info = PyDict::new(py);
        info.set_item("name", message.display_name())?;
        info.set_item("frame_id", message.id)?;
        info.set_item("is_extended_frame", message.extended)?;
        info.set_item("length", message.size)?;
        info.set_item(
            "cycle_time",
            self.decoder
                .cycle_time(message)
                .map(|d| d.as_secs_f64() * 1000.0),
        )?;
        info.set_item("senders", message.senders.clone())?;
        let mut signals = Vec::with_capacity(message.signals.len());
        for (i, s) in message.signals.iter().enumerate() {
            let d = PyDict::new(py);
            d.set_item("name", s.display_name())?;
            d.set_item("start", s.start_bit)?;
            d.set_item("length", s.length)?;
            d.set_item(
                "byte_order",
                match s.byte_order {
                    ByteOrder::LittleEndian => "little_endian",
                    ByteOrder::BigEndian => "big_endian",
                },
            )?;
            d.set_item(
                "is_signed",
                matches!(s.value_type, ValueType::Integer { signed: true }),
            )?;
            d.set_item(
                "is_float",
                matches!(s.value_type, ValueType::Float32 | ValueType::Float64),
            )?;
            d.set_item("scale", s.factor.as_f64())?;
            d.set_item("offset", s.offset.as_f64())?;
            d.set_item("minimum", s.minimum.as_f64())?;
            d.set_item("maximum", s.maximum.as_f64())?;
            d.set_item("unit", &s.unit)?;
            d.set_item(
                "is_multiplexer",
                matches!(
                    s.multiplexing,
                    Multiplexing::Multiplexor | Multiplexing::MultiplexedMultiplexor(_)
                ),
            )?;
            let ids: Option<Vec<i128>> = codec.switch_of(i).map(|_| match s.multiplexing {
                Multiplexing::Multiplexed(v) | Multiplexing::MultiplexedMultiplexor(v) => {
                    vec![i128::from(v)]
                }
                _ => s.mux_condition.as_ref().map_or_else(Vec::new, |c| {
                    c.ranges
                        .iter()
                        .filter(|(l, h)| h.saturating_sub(*l) < 256)
                        .flat_map(|(l, h)| (*l..=*h).map(i128::from))
                        .collect()
                }),
            });
            d.set_item("multiplexer_ids", ids)?;
            let choices = PyDict::new(py);
            for (k, name) in &s.value_descriptions {
                choices.set_item(*k, name)?;
            }
            d.set_item("choices", choices)?;
            signals.push(d);
        }
        info.set_item("signals", signals)?;
        Ok(info)
    }

    /// Decode `data` as the message with this frame identifier or name: a dict of signal
    /// values, as cantools' `Database.decode_message` gives it.
    /// `allow_excess` (last, by name) is `Message.decode`'s: cantools' `Database` passes its
    /// default.
    #[pyo3(signature = (frame_id_or_name, data, decode_choices = true, scaling = true, decode_containers = false, allow_truncated = false, force_extended_id = false, allow_excess = true))]
    #[allow(clippy::too_many_arguments)]
    fn decode_message<'py>(
        &self,
        py: Python<'py>,
        frame_id_or_name: &Bound<'py, PyAny>,
        data: &Bound<'py, PyAny>,
        decode_choices: bool,
        scaling: bool,
        decode_containers: bool,
        allow_truncated: bool,
        force_extended_id: bool,
        allow_excess: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        // The formats read have no container messages: the flag changes nothing.
        let _ = decode_containers;
        let index = self.lookup(frame_id_or_name, force_extended_id)?;
        self.decode_bytes(
            py,
            index,
            data,
            decode_choices,
            scaling,
            allow_truncated,
            allow_excess,
        )
    }

    /// Encode signal values as the message with this frame identifier or name, as cantools'
    /// `Database.encode_message` does.
    #[pyo3(signature = (frame_id_or_name, data, scaling = true, padding = false, strict = true, force_extended_id = false))]
    #[allow(clippy::too_many_arguments)]
    fn encode_message<'py>(
        &self,
        py: Python<'py>,
        frame_id_or_name: &Bound<'py, PyAny>,
        data: &Bound<'py, PyAny>,
        scaling: bool,
        padding: bool,
        strict: bool,
        force_extended_id: bool,
    ) -> PyResult<Bound<'py, PyBytes>> {
        let index = self.lookup(frame_id_or_name, force_extended_id)?;
        self.encode_dict(py, index, data, scaling, padding, strict)
    }

    /// Decode a batch of raw frames (the layout `read_log` gives) into one batch per message:
    /// `(batches, unknown, undecodable)` with `batches` a list of `(message, RecordBatch)`,
    /// `unknown` the frames of no message, `undecodable` `{message: (count, why)}`.
    #[allow(clippy::type_complexity)]
    fn decode_arrow(
        &self,
        py: Python<'_>,
        batch: PyArrowType<RecordBatch>,
    ) -> PyResult<(
        Vec<(String, PyArrowType<RecordBatch>)>,
        u64,
        HashMap<String, (u64, String)>,
    )> {
        let decoder = Arc::clone(&self.decoder);
        let batch = batch.0;
        let result =
            py.detach(move || decode_frames_batch(&decoder, &batch).map_err(|e| e.to_string()));
        let (batches, summary) = result.map_err(PyValueError::new_err)?;
        Ok((
            batches
                .into_iter()
                .map(|(name, batch)| (name, PyArrowType(batch)))
                .collect(),
            summary.unknown,
            summary.undecodable.into_iter().collect(),
        ))
    }

    fn __repr__(&self) -> String {
        format!("<bywire.Database: {} messages>", self.messages().len())
    }
}

/// One message of a [`Database`]: cantools' `Message.decode` and `Message.encode`.
#[pyclass(frozen, module = "bywire._native")]
struct MessageCodecs {
    database: Py<Database>,
    index: usize,
}

#[pymethods]
impl MessageCodecs {
    /// Decode `data` as cantools' `Message.decode` does.
    #[pyo3(signature = (data, decode_choices = true, scaling = true, decode_containers = false, allow_truncated = false, allow_excess = true))]
    #[allow(clippy::too_many_arguments)]
    fn decode<'py>(
        &self,
        py: Python<'py>,
        data: &Bound<'py, PyAny>,
        decode_choices: bool,
        scaling: bool,
        decode_containers: bool,
        allow_truncated: bool,
        allow_excess: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let _ = decode_containers;
        let database = self.database.get();
        database.decode_bytes(
            py,
            self.index,
            data,
            decode_choices,
            scaling,
            allow_truncated,
            allow_excess,
        )
    }

    /// Encode signal values as cantools' `Message.encode` does.
    #[pyo3(signature = (data, scaling = true, padding = false, strict = true))]
    fn encode<'py>(
        &self,
        py: Python<'py>,
        data: &Bound<'py, PyAny>,
        scaling: bool,
        padding: bool,
        strict: bool,
    ) -> PyResult<Bound<'py, PyBytes>> {
        self.database
            .get()
            .encode_dict(py, self.index, data, scaling, padding, strict)
    }
}

/// The most a single wait inside `CanBus::recv` lasts before Python gets to run its signal
/// handlers (Ctrl-C interrupts a `recv` that waits forever).
const RECV_SLICE: std::time::Duration = std::time::Duration::from_millis(100);

/// A frame as it crosses to Python: `(timestamp_s, id, extended, remote, error, fd, brs, esi,
/// dlc, data, own)`.
type PyFrame = (
    f64,
    u32,
    bool,
    bool,
    bool,
    bool,
    bool,
    bool,
    u8,
    Vec<u8>,
    bool,
);

/// A bus endpoint opened by its spec (any backend `bywire_bus::spec` opens), for python-can's
/// `interface="bywire"`: sending and receiving halves apart, so that python-can's notifier
/// thread receives while another thread sends.
#[pyclass(frozen, module = "bywire._native")]
struct CanBus {
    tx: std::sync::Mutex<Option<Box<dyn bywire_bus::BusTx>>>,
    rx: std::sync::Mutex<Option<Box<dyn bywire_bus::BusRx>>>,
    spec: String,
}

fn bus_error(spec: &str, error: impl std::fmt::Display) -> PyErr {
    PyOSError::new_err(format!("{spec}: {error}"))
}

#[pymethods]
impl CanBus {
    /// Open the bus `spec` names (`virtual:NAME`, `sim:NAME@BITRATE`, `socketcan:IFACE`,
    /// `socketcand:HOST:PORT/BUS`, `slcan:PORT@BITRATE`, `udp:[GROUP[:PORT]]`); with
    /// `receive_own`, this endpoint's own frames come back (as transmit confirmations).
    #[new]
    #[pyo3(signature = (spec, receive_own = false))]
    fn new(spec: &str, receive_own: bool) -> PyResult<Self> {
        let mut bus = bywire_bus::open(spec).map_err(|e| match e {
            bywire_bus::OpenError::Spec(_) => PyValueError::new_err(e.to_string()),
            other => PyOSError::new_err(other.to_string()),
        })?;
        bus.set_receive_own(receive_own)
            .map_err(|e| bus_error(spec, e))?;
        let (tx, rx) = bus.split();
        Ok(CanBus {
            tx: std::sync::Mutex::new(Some(tx)),
            rx: std::sync::Mutex::new(Some(rx)),
            spec: spec.to_string(),
        })
    }

    /// Send a frame: a classic data or remote frame, or an FD frame (`data` its payload,
    /// `dlc` a classic frame's DLC above 8 or a remote frame's, else from the data).
    #[pyo3(signature = (id, extended, remote, fd, brs, esi, data, dlc = None))]
    #[allow(clippy::too_many_arguments)]
    fn send(
        &self,
        py: Python<'_>,
        id: u32,
        extended: bool,
        remote: bool,
        fd: bool,
        brs: bool,
        esi: bool,
        data: Vec<u8>,
        dlc: Option<u8>,
    ) -> PyResult<()> {
        use bywire_core::{Dlc, Frame, Id};
        let invalid = |e: &dyn std::fmt::Display| PyValueError::new_err(e.to_string());
        let id = if extended {
            Id::extended(id)
        } else {
            Id::standard(id)
        }
        .map_err(|e| invalid(&e))?;
        let frame = if fd {
            Frame::fd(id, &data, brs, esi).map_err(|e| invalid(&e))?
        } else if remote {
            let dlc = dlc.or(u8::try_from(data.len()).ok()).unwrap_or(0);
            Frame::remote(
                id,
                Dlc::new(dlc).ok_or_else(|| invalid(&format!("DLC {dlc}: 0 to 15")))?,
            )
        } else {
            match dlc.and_then(Dlc::new) {
                Some(dlc) if data.len() == 8 && dlc.as_raw() > 8 => {
                    bywire_core::ClassicFrame::with_dlc(id, dlc, &data)
                        .map(Frame::Classic)
                        .map_err(|e| invalid(&e))?
                }
                _ => Frame::classic(id, &data).map_err(|e| invalid(&e))?,
            }
        };
        let mut tx = self
            .tx
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let Some(tx) = tx.as_mut() else {
            return Err(bus_error(&self.spec, "the bus is shut down"));
        };
        py.detach(|| tx.send(&frame))
            .map_err(|e| bus_error(&self.spec, e))
    }

    /// The next frame, waiting up to `timeout` seconds (None: until one comes); None when none
    /// came in time. Ctrl-C interrupts the wait.
    #[pyo3(signature = (timeout = None))]
    fn recv(&self, py: Python<'_>, timeout: Option<f64>) -> PyResult<Option<PyFrame>> {
        let deadline = match timeout {
            None => None,
            Some(t) if t.is_finite() && t >= 0.0 => Some(
                std::time::Instant::now()
                    + std::time::Duration::try_from_secs_f64(t)
                        .unwrap_or(std::time::Duration::MAX)
                        .min(std::time::Duration::from_secs(86_400 * 365)),
            ),
            Some(t) => {
                return Err(PyValueError::new_err(format!(
                    "timeout {t}: 0 or more seconds"
                )))
            }
        };
        let mut rx = self
            .rx
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let Some(rx) = rx.as_mut() else {
            return Err(bus_error(&self.spec, "the bus is shut down"));
        };
        // One slice at a time, so that Python's signal handlers run between them; the number of
        // slices is bounded by the deadline (or, without one, by the caller's patience).
        loop {
            let slice = deadline.map_or(RECV_SLICE, |d| {
                d.saturating_duration_since(std::time::Instant::now())
                    .min(RECV_SLICE)
            });
            let received = py
                .detach(|| rx.recv(Some(slice)))
                .map_err(|e| bus_error(&self.spec, e))?;
            if let Some(received) = received {
                return Ok(Some(py_frame(&received)));
            }
            if deadline.is_some_and(|d| std::time::Instant::now() >= d) {
                return Ok(None);
            }
            py.check_signals()?;
        }
    }

    /// Close the endpoint (both halves); sending or receiving afterwards raises.
    fn shutdown(&self) {
        *self
            .tx
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner) = None;
        *self
            .rx
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner) = None;
    }

    /// The spec the bus was opened with.
    #[getter]
    fn spec(&self) -> &str {
        &self.spec
    }
}

fn py_frame(received: &bywire_bus::Received) -> PyFrame {
    use bywire_core::Frame;
    let frame = &received.frame;
    let (brs, esi) = match frame {
        Frame::Fd(fd) => (fd.brs(), fd.esi()),
        _ => (false, false),
    };
    // Nanoseconds since the Unix epoch to seconds, as python-can stamps messages.
    #[allow(clippy::cast_precision_loss)]
    let seconds = received.timestamp.as_nanos() as f64 / 1e9;
    (
        seconds,
        frame
            .id()
            .map_or(frame.socketcan_id() & 0x1FFF_FFFF, bywire_core::Id::as_raw),
        frame.id().is_some_and(bywire_core::Id::is_extended),
        frame.is_remote(),
        frame.is_error(),
        frame.is_fd(),
        brs,
        esi,
        frame.dlc().as_raw(),
        frame.data().to_vec(),
        received.own,
    )
}

/// A log's frames as Arrow record batches (the raw frames' table layout); an iterator.
#[pyclass(unsendable, module = "bywire._native")]
struct LogBatches {
    path: String,
    format: &'static str,
    batches: FrameBatches,
}

#[pymethods]
impl LogBatches {
    /// Open the log at `path` (its format sniffed from its content); with `byte_range`
    /// `(start, end)`, only the lines starting in it (candump logs: a share of a split).
    #[new]
    #[pyo3(signature = (path, batch_rows = DEFAULT_BATCH_ROWS, byte_range = None))]
    fn new(path: PathBuf, batch_rows: usize, byte_range: Option<(u64, u64)>) -> PyResult<Self> {
        if !(1..=MAX_BATCH_ROWS).contains(&batch_rows) {
            return Err(PyValueError::new_err(format!(
                "batch_rows {batch_rows}: 1 to {MAX_BATCH_ROWS}"
            )));
        }
        let opened = FrameBatches::open(&path, byte_range, batch_rows);
        let (format, batches) = opened.map_err(|e| match e.kind() {
            std::io::ErrorKind::InvalidInput => {
                PyValueError::new_err(format!("{}: {e}", path.display()))
            }
            _ => PyOSError::new_err(format!("{}: {e}", path.display())),
        })?;
        let name = Format::ALL
            .iter()
            .find(|(f, _)| *f == format)
            .map_or("candump", |(_, n)| *n);
        Ok(LogBatches {
            path: path.display().to_string(),
            format: name,
            batches,
        })
    }

    /// The batches' schema.
    #[staticmethod]
    fn schema() -> PyArrowType<arrow_schema::Schema> {
        PyArrowType(raw_schema().as_ref().clone())
    }

    /// The format the log was read as (`candump`, `blf`, ...).
    #[getter]
    fn format(&self) -> &'static str {
        self.format
    }

    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__(&mut self) -> PyResult<Option<PyArrowType<RecordBatch>>> {
        match self.batches.next() {
            None => Ok(None),
            Some(Ok(batch)) => Ok(Some(PyArrowType(batch))),
            Some(Err(e)) => Err(LogError::new_err(format!("{}: {e}", self.path))),
        }
    }
}

/// Run a scenario as fast as possible: `(report_json, files)`, the bus logs (candump) and
/// `metrics.json` written into `out`.
#[pyfunction]
#[pyo3(signature = (scenario, seed, out, payload = None, secoc = false, max_seconds = 300.0, start_time = 0.0))]
fn run_sim(
    scenario: &str,
    seed: u64,
    out: PathBuf,
    payload: Option<f64>,
    secoc: bool,
    max_seconds: f64,
    start_time: f64,
) -> PyResult<(String, Vec<String>)> {
    use bywire_sim::scenario::Scenario;
    let scenario = match Scenario::builtin(scenario) {
        Some(s) => s,
        None if Path::new(scenario).is_file() => {
            let text = std::fs::read_to_string(scenario)
                .map_err(|e| PyOSError::new_err(format!("{scenario}: {e}")))?;
            Scenario::parse(&text, scenario).map_err(|e| ScenarioError::new_err(e.to_string()))?
        }
        None => {
            return Err(ScenarioError::new_err(format!(
                "{scenario}: not a built-in scenario (apron-loop, fault-tour) nor a file"
            )))
        }
    };
    let payload = payload.unwrap_or(scenario.tug.payload);
    if !(0.0..=4_500.0).contains(&payload) {
        return Err(ScenarioError::new_err(format!(
            "payload {payload}: 0 to 4500 kg"
        )));
    }
    if !(max_seconds.is_finite() && max_seconds > 0.0 && max_seconds <= 86_400.0) {
        return Err(ScenarioError::new_err(format!(
            "max_seconds {max_seconds}: more than 0, at most 86400"
        )));
    }
    // Unix seconds to nanoseconds since the epoch (1970 to 2262).
    let start = std::time::Duration::try_from_secs_f64(start_time)
        .ok()
        .and_then(|since_epoch| u64::try_from(since_epoch.as_nanos()).ok())
        .map(Timestamp::from_nanos)
        .ok_or_else(|| {
            ScenarioError::new_err(format!(
                "start_time {start_time}: Unix seconds from 1970 to 2262"
            ))
        })?;
    let mut params = scenario.params(seed, payload);
    params.secoc |= secoc;
    let mut tug =
        bywire_sim::tug::Tug::new(params).map_err(|e| ScenarioError::new_err(e.to_string()))?;
    let limit = std::time::Duration::from_secs_f64(max_seconds).as_nanos();
    let limit = Timestamp::from_nanos(u64::try_from(limit).unwrap_or(u64::MAX));
    let wall = std::time::Instant::now();
    let completed = scenario.run_fast(&mut tug, limit);
    let report = bywire_sim::report::RunReport::of(
        &tug,
        &scenario.name,
        seed,
        start,
        completed,
        wall.elapsed(),
    );
    let files = bywire_sim::output::write_run(&tug, &report, &out)
        .map_err(|e| PyOSError::new_err(e.to_string()))?
        .iter()
        .map(|p| p.display().to_string())
        .collect();
    let json =
        serde_json::to_string_pretty(&report).map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok((json, files))
}

/// A decoded batch (what `decode_arrow` gives for `message`) in long form: one row a signal
/// value, labelled with `message`, `vehicle` and `date` (none: each row's UTC day) or, with
/// `labelled=False`, only `ts, channel, signal, value`.
#[pyfunction]
#[pyo3(signature = (table, message, vehicle = None, date = None, labelled = true))]
fn signals_long(
    py: Python<'_>,
    table: PyArrowType<RecordBatch>,
    message: &str,
    vehicle: Option<&str>,
    date: Option<&str>,
    labelled: bool,
) -> PyResult<PyArrowType<RecordBatch>> {
    let labels = LongLabels {
        message,
        vehicle,
        date,
    };
    let table = table.0;
    py.detach(|| long::signals_long(&table, labelled.then_some(&labels)))
        .map(PyArrowType)
        .map_err(|e| PyValueError::new_err(format!("{message}: {e}")))
}

/// Decode `parts` (`(path, byte_range, vehicle, date)`: a log, or a byte range of a candump
/// log, and the vehicle and day its path gives, none: each row's UTC day) into a data lake's
/// files under `staging` (one task's work; `bywire.spark.write_lake` runs it on each
/// executor): `[(file, rows)]`, the files relative to `staging`.
#[pyfunction]
#[pyo3(signature = (database, parts, staging, prefix, compression = "snappy", batch_rows = DEFAULT_BATCH_ROWS, open_files = 256))]
#[allow(clippy::type_complexity, clippy::too_many_arguments)]
fn write_lake_files(
    py: Python<'_>,
    database: &Database,
    parts: Vec<(PathBuf, Option<(u64, u64)>, Option<String>, Option<String>)>,
    staging: PathBuf,
    prefix: &str,
    compression: &str,
    batch_rows: usize,
    open_files: usize,
) -> PyResult<Vec<(String, u64)>> {
    let compression = LakeCompression::from_name(compression).ok_or_else(|| {
        PyValueError::new_err(format!(
            "compression {compression}: snappy, zstd, gzip or none"
        ))
    })?;
    if !(1..=MAX_BATCH_ROWS).contains(&batch_rows) {
        return Err(PyValueError::new_err(format!(
            "batch_rows {batch_rows}: 1 to {MAX_BATCH_ROWS}"
        )));
    }
    if !(1..=4096).contains(&open_files) {
        return Err(PyValueError::new_err(format!(
            "open_files {open_files}: 1 to 4096"
        )));
    }
    let parts: Vec<LakePart> = parts
        .into_iter()
        .map(|(path, byte_range, vehicle, date)| LakePart {
            path,
            byte_range,
            vehicle,
            date,
        })
        .collect();
    let decoder = Arc::clone(&database.decoder);
    py.detach(move || {
        let mut files = LakeFiles::new(&staging, prefix, compression, open_files, LAKE_GROUP_ROWS)?;
        lake::write_parts(&decoder, &parts, &mut files, batch_rows)?;
        files.finish()
    })
    .map_err(|e| match e.kind() {
        std::io::ErrorKind::InvalidData | std::io::ErrorKind::InvalidInput => {
            LogError::new_err(e.to_string())
        }
        _ => PyOSError::new_err(e.to_string()),
    })
}

/// `column=value` as Spark names a partition's folder (a null or empty value:
/// `__HIVE_DEFAULT_PARTITION__`; the characters Spark escapes as `%XX`).
#[pyfunction]
#[pyo3(signature = (column, value = None))]
fn partition_folder(column: &str, value: Option<&str>) -> String {
    lake::partition_folder(column, value)
}

/// Run the `bywire` command line on `argv` (the program's name first): its exit status. The
/// package's `bywire` console script (`bywire._cli`) calls it, so the wheel carries the whole
/// command line.
#[pyfunction]
fn run_cli(py: Python<'_>, argv: Vec<std::ffi::OsString>) -> u8 {
    py.detach(|| bywire::run(argv))
}

/// The native module.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    // A malformed Parquet page raises LogError without parquet-rs's panic message on stderr.
    bywire_log::parquet::quiet_panics_taken_as_errors();
    m.add_class::<Database>()?;
    m.add_class::<MessageCodecs>()?;
    m.add_class::<CanBus>()?;
    m.add_class::<LogBatches>()?;
    m.add_function(wrap_pyfunction!(run_sim, m)?)?;
    m.add_function(wrap_pyfunction!(run_cli, m)?)?;
    m.add_function(wrap_pyfunction!(signals_long, m)?)?;
    m.add_function(wrap_pyfunction!(write_lake_files, m)?)?;
    m.add_function(wrap_pyfunction!(partition_folder, m)?)?;
    m.add("Error", py.get_type::<Error>())?;
    m.add("ParseError", py.get_type::<ParseError>())?;
    m.add("DecodeError", py.get_type::<DecodeError>())?;
    m.add("EncodeError", py.get_type::<EncodeError>())?;
    m.add("LogError", py.get_type::<LogError>())?;
    m.add("ScenarioError", py.get_type::<ScenarioError>())?;
    Ok(())
}
