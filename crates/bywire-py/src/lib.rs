//! `bywire._native`: the Python package's native module. The package (`python/bywire`) wraps
//! it; this crate only converts between Python and the libraries:
//!
//! - `Database`: a DBC loaded by bywire-dbc, decoding and encoding with cantools' call
//!   signatures, values and errors (`decode_message`, `encode_message`), and whole Arrow
//!   batches of frames decoded into one batch per message (`decode_arrow`);
//! - `LogBatches`: a log of any format bywire-log reads, as Arrow record batches of its
//!   frames (the raw frames' table layout);
//! - `run_sim`: a simulator run as fast as possible, its bus logs and report written.
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
    encode_named, selected_by, selector_values, Encoding, Given, Named, NamedError,
};
use bywire_dbc::{ByteOrder, Message, Mode, Multiplexing, Signal, ValueType};
use bywire_log::batches::FrameBatches;
use bywire_log::format::Format;
use bywire_log::parquet::raw_schema;
use pyo3::exceptions::{
    PyException, PyKeyError, PyOSError, PyOverflowError, PyTypeError, PyValueError,
};
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyByteArray, PyBytes, PyDict, PyString, PyType};

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

/// A DBC database: cantools' `Database` for the common calls, and Arrow decoding.
#[pyclass(frozen, module = "bywire._native")]
struct Database {
    decoder: Arc<Decoder>,
    codecs: Vec<MessageCodec>,
    /// Frame identifier → message, as cantools looks it up (the last message with it).
    by_frame_id: HashMap<u32, usize>,
    /// Name → message (the last with it, as in cantools).
    by_name: HashMap<String, usize>,
    diagnostics: Vec<String>,
}

fn format_named(name: &str) -> PyResult<bywire_dbc::Format> {
    bywire_dbc::Format::from_name(name).ok_or_else(|| {
        pyo3::exceptions::PyValueError::new_err(format!(
            "{name} is not a database format (dbc, kcd, sym)"
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
        let codecs = db.messages.iter().map(MessageCodec::new).collect();
        let by_frame_id = db.messages.iter().enumerate().map(|(i, m)| (m.id, i));
        let by_name = db
            .messages
            .iter()
            .enumerate()
            .map(|(i, m)| (m.display_name().to_string(), i));
        Ok(Database {
            by_frame_id: by_frame_id.collect(),
            by_name: by_name.collect(),
            codecs,
            diagnostics: diagnostics
                .iter()
                .map(|d| format!("{origin}:{}:{}: {}", d.line, d.column, d.message))
                .collect(),
            decoder: Arc::new(Decoder::new(db)),
        })
    }

    fn messages(&self) -> &[Message] {
        &self.decoder.database().messages
    }

    /// The message a frame identifier or name stands for; `KeyError` as cantools raises.
    fn lookup(&self, frame_id_or_name: &Bound<'_, PyAny>) -> PyResult<(&Message, &MessageCodec)> {
        let index = if let Ok(name) = frame_id_or_name.cast::<PyString>() {
            self.by_name.get(name.to_str()?).copied()
        } else {
            let id: u64 = frame_id_or_name.extract().map_err(|_| {
                PyTypeError::new_err("a frame identifier (int) or a message name (str)")
            })?;
            u32::try_from(id)
                .ok()
                .and_then(|id| self.by_frame_id.get(&id).copied())
        };
        index
            .and_then(|i| Some((self.messages().get(i)?, self.codecs.get(i)?)))
            .ok_or_else(|| PyKeyError::new_err(frame_id_or_name.clone().unbind()))
    }

    #[allow(clippy::too_many_arguments)]
    fn decode_with<'py>(
        &self,
        py: Python<'py>,
        message: &Message,
        codec: &MessageCodec,
        data: &[u8],
        decode_choices: bool,
        scaling: bool,
        allow_truncated: bool,
        allow_excess: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let size = codec.size();
        let mut payload = data.to_vec();
        if payload.len() != size {
            if allow_truncated && payload.len() < size {
                payload.resize(size, 0xFF);
            }
            if allow_excess {
                payload.truncate(size);
            }
            if payload.len() != size {
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
                    codec.write_raw(index, bits, &mut payload);
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
        let named = NAMED_VALUE.import(py, "bywire._values", "NamedSignalValue")?;
        let dict = PyDict::new(py);
        for (signal, decoded) in message.signals.iter().zip(&out) {
            let Some(decoded) = decoded else { continue };
            let choice = decode_choices
                .then(|| {
                    SignalValue {
                        signal,
                        value: *decoded,
                    }
                    .description_key()
                })
                .flatten()
                .and_then(|key| signal.value_descriptions.iter().find(|(k, _)| *k == key));
            let value = match choice {
                Some((key, name)) => named.call1((*key, name))?,
                None if scaling => number(py, decoded.physical)?,
                None => number(py, raw_number(signal, decoded.raw))?,
            };
            dict.set_item(signal.display_name(), value)?;
        }
        Ok(dict)
    }

    /// cantools' `encode_message` for one message, by [`encode_named`]: each value taken as
    /// Python gives it (a number, a choice's name or a `NamedSignalValue`), each error raised
    /// as cantools raises it.
    fn encode_with(
        &self,
        message: &Message,
        codec: &MessageCodec,
        data: &Bound<'_, PyDict>,
        scaling: bool,
        padding: bool,
        strict: bool,
    ) -> PyResult<Vec<u8>> {
        let named = NAMED_VALUE.import(data.py(), "bywire._values", "NamedSignalValue")?;
        // Each value with its name, its choice name if it is one, and its text and type as
        // Python shows them (the errors quote them).
        let mut items = Vec::with_capacity(data.len());
        for (key, value) in data.iter() {
            let name: String = key.extract()?;
            let choice = if value.is_instance(named)? {
                Some(value.getattr("name")?.extract::<String>()?)
            } else if let Ok(text) = value.cast::<PyString>() {
                Some(text.to_str()?.to_string())
            } else {
                None
            };
            let number = if choice.is_some() {
                None
            } else if let Ok(i) = value.extract::<i64>() {
                Some(Value::Int(i))
            } else if let Ok(u) = value.extract::<u64>() {
                Some(Value::UInt(u))
            } else {
                value.extract::<f64>().ok().map(Value::Float)
            };
            let shown = value.str()?.to_string();
            let type_name = value.get_type().name()?.to_string();
            items.push((name, choice, number, shown, type_name));
        }
        let values: Vec<Named<'_>> = items
            .iter()
            .map(|(name, choice, number, shown, _)| Named {
                signal: name,
                value: match (choice, number) {
                    (Some(choice), _) => Given::Choice(choice),
                    (None, Some(number)) => Given::Number(*number),
                    (None, None) => Given::Unusable,
                },
                shown,
            })
            .collect();
        let encoding = Encoding {
            scaling,
            padding,
            ..Encoding::cantools(strict)
        };
        encode_named(message, codec, &values, encoding).map_err(|error| match error {
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
                    .find(|item| item.0 == signal)
                    .map_or("object", |item| item.4.as_str());
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
    /// Load a database file: DBC, KCD or SYM, by `database_format` (`"dbc"`, `"kcd"`,
    /// `"sym"`), else the extension, else the content (`strict`: the first problem is an
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

    /// Load database text: DBC, KCD or SYM, by `database_format`, else by its content.
    #[staticmethod]
    #[pyo3(signature = (text, strict = false, database_format = None))]
    fn load_string(text: &str, strict: bool, database_format: Option<&str>) -> PyResult<Self> {
        let format = match database_format {
            Some(name) => format_named(name)?,
            None => bywire_dbc::Format::sniff(text.as_bytes()),
        };
        Database::new(text.as_bytes(), strict, "<string>", format)
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
        let (message, codec) = self.lookup(frame_id_or_name)?;
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
    #[pyo3(signature = (frame_id_or_name, data, decode_choices = true, scaling = true, decode_containers = false, allow_truncated = false, allow_excess = true))]
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
        allow_excess: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        // DBC files have no container messages: the flag changes nothing.
        let _ = decode_containers;
        let (message, codec) = self.lookup(frame_id_or_name)?;
        let bytes = bytes_of(data)?;
        self.decode_with(
            py,
            message,
            codec,
            &bytes,
            decode_choices,
            scaling,
            allow_truncated,
            allow_excess,
        )
    }

    /// Encode signal values as the message with this frame identifier or name, as cantools'
    /// `Database.encode_message` does.
    #[pyo3(signature = (frame_id_or_name, data, scaling = true, padding = false, strict = true))]
    fn encode_message<'py>(
        &self,
        py: Python<'py>,
        frame_id_or_name: &Bound<'py, PyAny>,
        data: &Bound<'py, PyAny>,
        scaling: bool,
        padding: bool,
        strict: bool,
    ) -> PyResult<Bound<'py, PyBytes>> {
        let (message, codec) = self.lookup(frame_id_or_name)?;
        let Ok(values) = data.cast::<PyDict>() else {
            return Err(EncodeError::new_err(
                "The payload for encoding non-container messages must be a signal name to signal value dictionary",
            ));
        };
        let payload = self.encode_with(message, codec, values, scaling, padding, strict)?;
        Ok(PyBytes::new(py, &payload))
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

/// The native module.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    // A malformed Parquet page raises LogError without parquet-rs's panic message on stderr.
    bywire_log::parquet::quiet_panics_taken_as_errors();
    m.add_class::<Database>()?;
    m.add_class::<LogBatches>()?;
    m.add_function(wrap_pyfunction!(run_sim, m)?)?;
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
