//! Decoded frames as a Parquet dataset: one table per message, one typed column per signal,
//! partitioned the way data lakes read (Hive-style directories):
//!
//! ```text
//! OUT/message=VehicleToAds_State/part-00000.parquet
//! OUT/message=VehicleToAds_State/channel=can0/date=2024-05-01/part-00000.parquet   (when asked)
//! ```
//!
//! A table's columns are `ts` (timestamp, UTC; ns, or µs when asked), `channel` (unless the channel is a partition),
//! then each signal under its display name: `int64` where the signal's scale and offset are
//! whole numbers and every value fits (`uint64` for the widest unsigned ones), else `float64`,
//! null where a multiplexed signal is not in the frame. A signal with value descriptions gets a
//! dictionary-string column `NAME_choice` beside it, the description of the raw value (null
//! when it has none). A frame that cannot be decoded (shorter than its message, an unknown multiplexer value) is
//! not a row; it is counted
//! ([`DatasetSummary::undecodable`]), as are frames of no message in the DBC.
//!
//! Memory stays bounded whatever the input: the open tables share [`BUILT_ROWS`] rows being
//! built (at most [`TABLE_BATCH`] each) and end their row groups when their encoded columns
//! pass a share of [`MEMORY_BUDGET`]; at most [`OPEN_TABLES`] tables are open, the least
//! recently written closed first (a later frame of its partition starts the next
//! `part-NNNNN` file). A table holds no file descriptor between writes (its file is opened to
//! append each buffer), so a DBC of hundreds of messages on several channels needs no more
//! than one descriptor at a time.
//!
//! The files are encoded by bywire (its `batch_file` module): times and integer signals as
//! deltas, channels and descriptions as the keys they already are behind a dictionary page.

use std::collections::{BTreeMap, HashMap};
use std::fs::{File, OpenOptions};
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow_array::builder::{Float64Builder, Int64Builder, UInt64Builder};
use arrow_array::types::{ArrowPrimitiveType, Float64Type, Int64Type, UInt64Type};
use arrow_array::{new_null_array, ArrayRef, Int32Array, PrimitiveArray, RecordBatch};
use arrow_buffer::NullBuffer;
use arrow_schema::{DataType, Field, Schema, SchemaRef};
use bywire_dbc::codec::{whole_scaling, DecodeError, Decoded, MessageCodec, PayloadWord, Value};
use bywire_dbc::decoder::{field_names, Decoder, SignalValue};
use bywire_dbc::{Message, Signal, ValueType};

use crate::batch_file::BatchFile;
use bywire_log::calendar;
use bywire_log::candump::{LogError, LogRecord, LogRecordRef, Precision};
use bywire_log::parquet::{
    dictionary_type, io_error, nanos, time_array, timestamp_type_in, ChannelRef, FrameColumnsRef,
    Labels, ParquetCompression, LAYOUT_KEY,
};

/// Rows a table builds up before they are encoded (fewer when many tables are open).
pub const TABLE_BATCH: usize = 16_384;
/// Rows all open tables may hold unencoded.
pub const BUILT_ROWS: usize = 1 << 19;
/// Encoded bytes all open tables may hold before their row groups are written out.
pub const MEMORY_BUDGET: usize = 256 << 20;
/// Tables open at once.
pub const OPEN_TABLES: usize = 4096;
/// Column chunks the open tables' finished row groups may hold: a writer keeps each one's
/// metadata (its place, sizes and statistics) until its file's footer, so a file that
/// grew without end would grow the memory with it. Past this, the table holding the most is
/// finished and its next rows start the partition's next `part-NNNNN` file.
pub const HELD_CHUNKS: usize = 32_768;
/// Bytes a table buffers before appending them to its file.
const FILE_BUFFER: usize = 64 << 10;
/// The decoded tables' layout, as the metadata names it.
pub const DECODED_LAYOUT: &str = "can-decoded/1";

/// Which partitions the dataset has below `message=`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Partitioning {
    /// A `channel=` directory per channel.
    pub channel: bool,
    /// A `date=YYYY-MM-DD` directory per (UTC) day.
    pub date: bool,
}

/// What a dataset holds once finished.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct DatasetSummary {
    /// Rows written per message (display name).
    pub rows: BTreeMap<String, u64>,
    /// Frames of no message in the DBC (and error frames).
    pub unknown: u64,
    /// Frames of a message that could not be decoded (shorter than the message, an unknown
    /// multiplexer value), per message: how many, and why the first could not.
    pub undecodable: BTreeMap<String, (u64, String)>,
    /// Files written.
    pub files: Vec<PathBuf>,
}

impl DatasetSummary {
    /// Count a frame of `message` that did not decode (the first one's reason kept).
    fn count_undecodable(&mut self, message: &Message, error: &impl std::fmt::Display) {
        self.undecodable
            .entry(message.display_name().to_string())
            .or_insert_with(|| (0, error.to_string()))
            .0 += 1;
    }
}

/// A column's type, from the signal's definition (so every file of a message agrees).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Int,
    UInt,
    Float,
}

fn kind(signal: &Signal) -> Kind {
    let (Some((factor, offset)), ValueType::Integer { signed }) =
        (whole_scaling(signal), signal.value_type)
    else {
        return Kind::Float;
    };
    let bits = signal.length.clamp(1, 64);
    let (low, high): (i128, i128) = if signed {
        (-(1i128 << (bits - 1)), (1i128 << (bits - 1)) - 1)
    } else {
        (0, (1i128 << bits) - 1)
    };
    let ends = [low, high].map(|raw| raw.checked_mul(factor)?.checked_add(offset));
    let [Some(a), Some(b)] = ends else {
        return Kind::Float;
    };
    let (min, max) = (a.min(b), a.max(b));
    if min >= i128::from(i64::MIN) && max <= i128::from(i64::MAX) {
        Kind::Int
    } else if min >= 0 && max <= i128::from(u64::MAX) {
        Kind::UInt
    } else {
        Kind::Float
    }
}

enum ValueColumn {
    Int(Int64Builder),
    UInt(UInt64Builder),
    Float(Float64Builder),
}

impl ValueColumn {
    fn new(kind: Kind, rows: usize) -> Self {
        match kind {
            Kind::Int => ValueColumn::Int(Int64Builder::with_capacity(rows)),
            Kind::UInt => ValueColumn::UInt(UInt64Builder::with_capacity(rows)),
            Kind::Float => ValueColumn::Float(Float64Builder::with_capacity(rows)),
        }
    }

    #[inline]
    fn push(&mut self, value: Option<Value>) {
        // The kind was chosen so that every value the signal can take fits it exactly.
        match (self, value) {
            (ValueColumn::Int(b), Some(v)) => {
                b.append_option(v.as_i128().and_then(|i| i64::try_from(i).ok()))
            }
            (ValueColumn::UInt(b), Some(v)) => {
                b.append_option(v.as_i128().and_then(|i| u64::try_from(i).ok()))
            }
            (ValueColumn::Float(b), Some(v)) => b.append_value(v.as_f64()),
            (ValueColumn::Int(b), None) => b.append_null(),
            (ValueColumn::UInt(b), None) => b.append_null(),
            (ValueColumn::Float(b), None) => b.append_null(),
        }
    }

    fn finish(&mut self) -> ArrayRef {
        match self {
            ValueColumn::Int(b) => Arc::new(b.finish()),
            ValueColumn::UInt(b) => Arc::new(b.finish()),
            ValueColumn::Float(b) => Arc::new(b.finish()),
        }
    }

    fn data_type(kind: Kind) -> DataType {
        match kind {
            Kind::Int => DataType::Int64,
            Kind::UInt => DataType::UInt64,
            Kind::Float => DataType::Float64,
        }
    }
}

/// A frame's values as a table takes them: the payload of a message that [decodes by
/// word](MessageCodec::decodes_by_word), decoded later a column at a time, or the values
/// decoded now (multiplexed messages, longer payloads).
enum Row {
    Word(PayloadWord),
    Decoded,
}

/// Check `data` as `codec`'s message: its payload words, or its values decoded into `values`.
fn decode_row(
    codec: &MessageCodec,
    data: &[u8],
    values: &mut Vec<Option<Decoded>>,
) -> Result<Row, DecodeError> {
    if codec.decodes_by_word() {
        return codec.word_of(data).map(Row::Word);
    }
    values.clear();
    values.resize(codec.signal_count(), None);
    codec.decode(data, values).map(|()| Row::Decoded)
}

/// The index of a value's description among the signal's value descriptions.
#[inline]
fn choice_of(signal: &Signal, value: Decoded) -> Option<usize> {
    let key = SignalValue { signal, value }.description_key()?;
    signal
        .value_descriptions
        .iter()
        .position(|(k, _)| *k == key)
}

/// Integer signals of at most this many bits find their descriptions in a table by raw value.
const CHOICE_TABLE_BITS: u32 = 8;

/// Signal `index`'s description keys (what [`choice_of`] gives) of payloads decoded by word;
/// `None` when the signal is never present. A short integer signal's keys are looked up in a
/// table of its every raw value, made once per batch (of more rows than the table has), instead
/// of searched for on every row.
fn choice_column(
    codec: &MessageCodec,
    index: usize,
    signal: &Signal,
    words: &[PayloadWord],
) -> Option<Int32Array> {
    let key = |d| choice_of(signal, d).and_then(|k| i32::try_from(k).ok());
    // The table pays once it has fewer entries than the batch has rows.
    let short = matches!(signal.value_type, ValueType::Integer { .. })
        && signal.length <= CHOICE_TABLE_BITS
        && 1usize << signal.length <= words.len();
    let (keys, nulls) = if short {
        // An integer signal's description key is its raw bits alone (`description_key`).
        let table: Vec<Option<i32>> = (0..1u64 << signal.length)
            .map(|raw| {
                key(Decoded {
                    raw,
                    physical: Value::UInt(raw),
                })
            })
            .collect();
        decoded_column(codec, index, words, |d| {
            usize::try_from(d.raw)
                .ok()
                .and_then(|raw| table.get(raw).copied().flatten())
        })?
    } else {
        decoded_column(codec, index, words, key)?
    };
    Some(Int32Array::new(keys.into(), nulls))
}

/// One message's rows until they become a batch: its schema, times, channels, and the
/// payloads decoded a column at a time when the batch is made (or the values decoded as the
/// rows came, for messages that do not decode by word).
struct MessageColumns {
    schema: SchemaRef,
    kinds: Vec<Kind>,
    /// Times (ns): never null, so a plain vector (a push is a store).
    ts: Vec<i64>,
    /// The unit of the table's times (microseconds floored when the batch is made).
    precision: Precision,
    channel: Option<Labels>,
    words: Vec<PayloadWord>,
    /// Values of rows decoded as they came (empty until a batch is made, for the others).
    values: Vec<ValueColumn>,
    /// Per signal, its description column when it has value descriptions.
    choices: Vec<Option<Labels>>,
    rows: usize,
}

impl MessageColumns {
    /// A message's table, with room for `rows` rows, its times to `precision`.
    fn new(message: &Message, with_channel: bool, rows: usize, precision: Precision) -> Self {
        let names = field_names(message);
        let kinds: Vec<Kind> = message.signals.iter().map(kind).collect();
        let mut fields = vec![Field::new("ts", timestamp_type_in(precision), false)];
        if with_channel {
            fields.push(Field::new("channel", dictionary_type(), false));
        }
        for ((signal, name), kind) in message.signals.iter().zip(&names).zip(&kinds) {
            fields.push(Field::new(name, ValueColumn::data_type(*kind), true));
            if !signal.value_descriptions.is_empty() {
                fields.push(Field::new(
                    format!("{name}_choice"),
                    dictionary_type(),
                    true,
                ));
            }
        }
        MessageColumns {
            schema: Arc::new(Schema::new(fields)),
            ts: Vec::with_capacity(rows),
            precision,
            channel: with_channel.then(|| Labels::new(Vec::new(), rows)),
            words: Vec::with_capacity(rows),
            // Built up as rows come (multiplexed messages), or made with the batch's size when
            // its payloads are decoded by column.
            values: kinds.iter().map(|k| ValueColumn::new(*k, 0)).collect(),
            kinds,
            choices: message
                .signals
                .iter()
                .map(|s| {
                    let labels = s.value_descriptions.iter().map(|(_, l)| l.clone());
                    (!s.value_descriptions.is_empty()).then(|| Labels::new(labels.collect(), rows))
                })
                .collect(),
            rows: 0,
        }
    }

    /// Add a row: `row` as [`decode_row`] made it, with `decoded` the values it decoded.
    #[inline(always)]
    fn push(
        &mut self,
        message: &Message,
        ts: i64,
        channel: ChannelRef<'_>,
        row: Row,
        decoded: &[Option<Decoded>],
    ) {
        self.ts.push(ts);
        if let Some(labels) = &mut self.channel {
            labels.push_channel(channel);
        }
        self.rows += 1;
        match row {
            Row::Word(word) => self.words.push(word),
            Row::Decoded => self.push_decoded(message, decoded),
        }
    }

    /// The values of a row decoded as it came.
    fn push_decoded(&mut self, message: &Message, decoded: &[Option<Decoded>]) {
        let columns = self.values.iter_mut().zip(&mut self.choices);
        for ((signal, value), (column, choice)) in message.signals.iter().zip(decoded).zip(columns)
        {
            column.push(value.map(|v| v.physical));
            if let Some(choice) = choice {
                choice.push_key(value.and_then(|v| choice_of(signal, v)));
            }
        }
    }

    /// Decode the payloads kept a column at a time into the columns.
    fn decode_words(&mut self, message: &Message, codec: &MessageCodec) -> Vec<ArrayRef> {
        let rows = self.words.len();
        let mut columns = Vec::new();
        for (index, ((signal, kind), choice)) in message
            .signals
            .iter()
            .zip(&self.kinds)
            .zip(&mut self.choices)
            .enumerate()
        {
            let words = &self.words;
            // The column's type is matched once, not once per value. Every value the signal
            // can take fits its type (see `kind`).
            let values: Option<ArrayRef> = match kind {
                Kind::Int => typed_column::<Int64Type>(codec, index, words, |v| match v {
                    Value::Int(i) => Some(i),
                    _ => None,
                }),
                Kind::UInt => typed_column::<UInt64Type>(codec, index, words, |v| {
                    v.as_i128().and_then(|i| u64::try_from(i).ok())
                }),
                Kind::Float => {
                    typed_column::<Float64Type>(codec, index, words, |v| Some(v.as_f64()))
                }
            };
            columns.push(
                values.unwrap_or_else(|| new_null_array(&ValueColumn::data_type(*kind), rows)),
            );
            if let Some(choice) = choice {
                // Finished below, beside its values.
                let keys = choice_column(codec, index, signal, words)
                    .unwrap_or_else(|| Int32Array::new_null(rows));
                choice.append_keys(&keys);
            }
        }
        self.words.clear();
        columns
    }

    fn finish(&mut self, message: &Message, codec: &MessageCodec) -> std::io::Result<RecordBatch> {
        // Columns decoded now from the payloads kept, or (none kept) built as rows came.
        let decoded = if self.words.is_empty() {
            Vec::new()
        } else {
            self.decode_words(message, codec)
        };
        let mut columns: Vec<ArrayRef> =
            vec![time_array(std::mem::take(&mut self.ts), self.precision)];
        if let Some(channel) = &mut self.channel {
            columns.push(channel.finish()?);
        }
        let mut decoded = decoded.into_iter();
        for (value, choice) in self.values.iter_mut().zip(&mut self.choices) {
            match decoded.next() {
                Some(column) => columns.push(column),
                None => columns.push(value.finish()),
            }
            if let Some(choice) = choice {
                columns.push(choice.finish()?);
            }
        }
        self.rows = 0;
        RecordBatch::try_new(self.schema.clone(), columns).map_err(io_error)
    }
}

/// Signal `index` of payloads decoded by word as an Arrow array: values through `convert`, a
/// value it refuses null; `None` when the signal is never present.
fn typed_column<T: ArrowPrimitiveType>(
    codec: &MessageCodec,
    index: usize,
    words: &[PayloadWord],
    convert: impl Fn(Value) -> Option<T::Native>,
) -> Option<ArrayRef> {
    let (values, nulls) = decoded_column(codec, index, words, |d| convert(d.physical))?;
    Some(Arc::new(PrimitiveArray::<T>::new(values.into(), nulls)))
}

/// Signal `index` of payloads decoded by word, each through `convert`, with the rows it
/// refused as nulls (no null buffer when it refused none); `None` when the signal is never
/// present.
fn decoded_column<T: Default>(
    codec: &MessageCodec,
    index: usize,
    words: &[PayloadWord],
    convert: impl Fn(Decoded) -> Option<T>,
) -> Option<(Vec<T>, Option<NullBuffer>)> {
    let mut values = Vec::with_capacity(words.len());
    let mut refused = false;
    let decoded = codec.decode_column(index, words, &mut values, |d| {
        convert(d).unwrap_or_else(|| {
            refused = true;
            T::default()
        })
    });
    if !decoded {
        return None;
    }
    // Most columns refuse nothing (a value outside its column's type never happens; a value
    // without a description can): refused rows are found in a second pass, only when there
    // are some, rather than tracked on every row.
    let nulls = refused.then(|| {
        let mut valid = Vec::with_capacity(words.len());
        codec.decode_column(index, words, &mut valid, |d| convert(d).is_some());
        NullBuffer::from(valid)
    });
    Some((values, nulls))
}

/// Where a row goes: the message and, when partitioned, its channel and day.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
struct PartitionKey {
    message: usize,
    channel: Option<String>,
    /// The UTC day, counted from 1970-01-01.
    day: Option<u64>,
}

/// A file written by appending: opened for each write and closed again, so that thousands
/// of tables do not hold thousands of descriptors.
struct AppendFile {
    path: PathBuf,
}

impl std::io::Write for AppendFile {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        let mut file = OpenOptions::new().append(true).open(&self.path)?;
        file.write_all(bytes)?;
        Ok(bytes.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// An open table of one partition.
struct OpenTable {
    message: usize,
    columns: MessageColumns,
    writer: BatchFile<BufWriter<AppendFile>>,
    last_used: u64,
}

impl OpenTable {
    /// Column chunks of the row groups written so far (their metadata is held until the end).
    fn held_chunks(&self) -> usize {
        self.writer.row_groups() * self.columns.schema.fields().len()
    }
}

/// Writes decoded records into a dataset directory.
pub struct DecodedDataset<'a> {
    decoder: &'a Decoder,
    root: PathBuf,
    partitioning: Partitioning,
    open: HashMap<PartitionKey, OpenTable, foldhash::fast::RandomState>,
    /// Files started per partition (the next file's number).
    parts: HashMap<PartitionKey, u32>,
    decoded: Vec<Option<Decoded>>,
    /// Rows written, by message index (named in the summary at the end).
    rows: Vec<u64>,
    summary: DatasetSummary,
    clock: u64,
    /// Column chunks the open tables hold, at most [`HELD_CHUNKS`] (a field for the tests).
    held_budget: usize,
    /// [`MEMORY_BUDGET`] (a field for the tests).
    memory_budget: usize,
    compression: ParquetCompression,
    precision: Precision,
}

impl<'a> DecodedDataset<'a> {
    /// A dataset under `root` (made if missing; files of an earlier run in it are replaced
    /// partition by partition, so give an empty or new directory).
    pub fn create(
        root: &Path,
        decoder: &'a Decoder,
        partitioning: Partitioning,
    ) -> std::io::Result<Self> {
        std::fs::create_dir_all(root)?;
        Ok(DecodedDataset {
            decoder,
            root: root.to_path_buf(),
            partitioning,
            open: HashMap::default(),
            parts: HashMap::new(),
            decoded: Vec::new(),
            rows: vec![0; decoder.message_count()],
            summary: DatasetSummary::default(),
            clock: 0,
            held_budget: HELD_CHUNKS,
            memory_budget: MEMORY_BUDGET,
            compression: ParquetCompression::default(),
            precision: Precision::Nanos,
        })
    }

    /// Compress the pages of the tables opened from now on with `compression` (zstd unless
    /// set).
    pub fn set_compression(&mut self, compression: ParquetCompression) {
        self.compression = compression;
    }

    /// Give the `ts` of the tables opened from now on to `precision`: nanoseconds unless set;
    /// microseconds (each time floored) are what Spark reads as times.
    pub fn set_time_precision(&mut self, precision: Precision) {
        self.precision = precision;
    }

    /// Decode one record and add its row.
    pub fn write(&mut self, record: &LogRecord) -> std::io::Result<()> {
        self.write_lent(&record.as_record_ref())
    }

    /// [`DecodedDataset::write`] for a record lent by a reader ([`Reader::for_each_ref`]): no
    /// copy of its interface name is made unless the dataset is partitioned by channel.
    ///
    /// [`Reader::for_each_ref`]: bywire_log::Reader::for_each_ref
    pub fn write_lent(&mut self, record: &LogRecordRef<'_>) -> std::io::Result<()> {
        let decoder = self.decoder;
        let Some((index, message, codec, data)) = decoder.message_of(&record.frame) else {
            self.summary.unknown += 1;
            return Ok(());
        };
        // A container frame: a row in each of its PDUs' tables.
        if let Some(pdus) = decoder.contained(index, data) {
            for pdu in pdus {
                match pdu {
                    Ok(pdu) => match pdu.message {
                        Some((pdu_message, pdu_codec, pdu_index)) => {
                            self.add_row(
                                record,
                                (pdu_index, pdu_message, pdu_codec),
                                pdu.pdu.data,
                            )?;
                        }
                        None => self.summary.unknown += 1,
                    },
                    Err(e) => self.summary.count_undecodable(message, &e),
                }
            }
            return Ok(());
        }
        self.add_row(record, (index, message, codec), data)
    }

    /// A row of `message` (its index in the decoder's numbering, the message, its codec) from
    /// `data`, in its table.
    fn add_row(
        &mut self,
        record: &LogRecordRef<'_>,
        (index, message, codec): (usize, &'a Message, &'a MessageCodec),
        data: &[u8],
    ) -> std::io::Result<()> {
        let row = match decode_row(codec, data, &mut self.decoded) {
            Ok(row) => row,
            Err(e) => {
                self.summary.count_undecodable(message, &e);
                return Ok(());
            }
        };
        let key = PartitionKey {
            message: index,
            channel: self
                .partitioning
                .channel
                .then(|| record.interface.to_string()),
            day: self
                .partitioning
                .date
                .then(|| record.timestamp.as_nanos() / 86_400_000_000_000),
        };
        self.clock += 1;
        // One lookup for a table already open (most rows); a new one is opened, then found.
        let mut open = self.open.len();
        let table = match self.open.get_mut(&key) {
            Some(table) => table,
            None => {
                self.open_table(&key, message)?;
                open = self.open.len();
                match self.open.get_mut(&key) {
                    Some(table) => table,
                    None => return Ok(()),
                }
            }
        };
        let open = open.max(1);
        let (budget, batch) = (
            self.memory_budget / open,
            (BUILT_ROWS / open).clamp(16, TABLE_BATCH),
        );
        table.last_used = self.clock;
        let ts = nanos(record.timestamp);
        table.columns.push(
            message,
            ts,
            ChannelRef::Text(record.interface),
            row,
            &self.decoded,
        );
        let mut finished_row_group = false;
        if table.columns.rows >= batch {
            let row_groups = table.writer.row_groups();
            let batch = table.columns.finish(message, codec)?;
            table.writer.write(&batch)?;
            if table.writer.in_progress_size() > budget {
                table.writer.flush()?;
            }
            finished_row_group = table.writer.row_groups() > row_groups;
        }
        if let Some(rows) = self.rows.get_mut(index) {
            *rows += 1;
        }
        // What the open tables hold only grows when a row group is finished.
        if finished_row_group {
            self.bound_held_chunks()?;
        }
        Ok(())
    }

    /// Finish the tables holding the most row groups' metadata until the open tables hold at
    /// most the budget (bounded: each pass closes a table).
    fn bound_held_chunks(&mut self) -> std::io::Result<()> {
        while self
            .open
            .values()
            .map(OpenTable::held_chunks)
            .sum::<usize>()
            > self.held_budget
        {
            let fullest = self
                .open
                .iter()
                .max_by_key(|(_, t)| t.held_chunks())
                .map(|(k, _)| k.clone());
            match fullest.and_then(|k| self.open.remove(&k)) {
                Some(table) => close(table, self.decoder)?,
                None => break,
            }
        }
        Ok(())
    }

    fn open_table(&mut self, key: &PartitionKey, message: &Message) -> std::io::Result<()> {
        if self.open.len() >= OPEN_TABLES {
            let oldest = self
                .open
                .iter()
                .min_by_key(|(_, t)| t.last_used)
                .map(|(k, _)| k.clone());
            if let Some(table) = oldest.and_then(|k| self.open.remove(&k)) {
                close(table, self.decoder)?;
            }
        }
        let mut dir = self
            .root
            .join(format!("message={}", path_value(message.display_name())));
        if let Some(channel) = &key.channel {
            dir.push(format!("channel={}", path_value(channel)));
        }
        if let Some(day) = key.day {
            let (year, month, day) = calendar::civil_from_days(i64::try_from(day).unwrap_or(0));
            dir.push(format!("date={year:04}-{month:02}-{day:02}"));
        }
        std::fs::create_dir_all(&dir)?;
        let part = self.parts.entry(key.clone()).or_insert(0);
        let path = dir.join(format!("part-{part:05}.parquet"));
        *part += 1;
        let columns = MessageColumns::new(
            message,
            !self.partitioning.channel,
            TABLE_BATCH,
            self.precision,
        );
        // Channels and value descriptions are dictionaries (their keys as they are), times
        // and integer signals deltas: they change by little from frame to frame, so their pages
        // shrink to a few bits a row before compression (measured on the tug's traffic: files
        // 40 % the size with zstd, and 20 % less time, writing and compressing).
        File::create(&path)?;
        let writer = BatchFile::try_new(
            BufWriter::with_capacity(FILE_BUFFER, AppendFile { path: path.clone() }),
            columns.schema.clone(),
            self.compression.into(),
            &[(LAYOUT_KEY, DECODED_LAYOUT)],
        )?;
        self.summary.files.push(path);
        self.open.insert(
            key.clone(),
            OpenTable {
                message: key.message,
                columns,
                writer,
                last_used: self.clock,
            },
        );
        Ok(())
    }

    /// Write every table's last rows and footer; what the dataset holds.
    pub fn finish(mut self) -> std::io::Result<DatasetSummary> {
        let mut open: Vec<_> = self.open.drain().collect();
        open.sort_by(|a, b| a.0.cmp(&b.0));
        for (_, table) in open {
            close(table, self.decoder)?;
        }
        let decoder = self.decoder;
        let messages = (0..).map_while(|i| decoder.message_at(i).map(|(m, _)| m));
        for (message, rows) in messages.zip(&self.rows) {
            if *rows > 0 {
                *self
                    .summary
                    .rows
                    .entry(message.display_name().to_string())
                    .or_default() += rows;
            }
        }
        Ok(self.summary)
    }
}

/// A row of no message (in [`decode_frames_batch`]'s rows' messages).
const NO_MESSAGE: u32 = u32::MAX;

/// A batch of raw frames (the layout [`bywire_log::parquet::raw_schema`] gives, or any batch
/// [`bywire_log::parquet::records_of_batch`] reads) decoded straight from its columns into one batch per
/// message with the columns a dataset's table has (`channel` always), in the database's order,
/// and the counts ([`DatasetSummary::files`] empty). For callers that take Arrow in memory (the
/// Python package): no record is built per frame.
pub fn decode_frames_batch(
    decoder: &Decoder,
    batch: &RecordBatch,
) -> Result<(Vec<(String, RecordBatch)>, DatasetSummary), LogError> {
    let frames = FrameColumnsRef::of(batch)?;
    let messages = &decoder.database().messages;
    let mut summary = DatasetSummary::default();
    // Each row's message and each message's row count first, so that each table is built
    // with its size known; then the rows are read once, in order, each into its table (a
    // table's rows are spread over the batch: reading them message by message would fetch
    // the batch's memory once per message).
    let mut counts = vec![0usize; messages.len()];
    let message_of_row: Vec<u32> = (0..batch.num_rows())
        .map(|row| {
            let message = frames
                .id(row)
                .and_then(|(id, extended)| decoder.message_with_id(id, extended))
                .and_then(|(index, ..)| Some((u32::try_from(index).ok()?, counts.get_mut(index)?)));
            match message {
                Some((index, count)) => {
                    *count += 1;
                    index
                }
                None => {
                    summary.unknown += 1;
                    NO_MESSAGE
                }
            }
        })
        .collect();
    // Each table with its message and codec, found once rather than on every row.
    let mut tables: Vec<Option<(&Message, &MessageCodec, MessageColumns)>> = counts
        .iter()
        .enumerate()
        .map(|(index, &rows)| {
            let (message, codec) = decoder.message_at(index).filter(|_| rows > 0)?;
            let columns = MessageColumns::new(message, true, rows, Precision::Nanos);
            Some((message, codec, columns))
        })
        .collect();
    let mut values: Vec<Option<Decoded>> = Vec::new();
    for (row, &index) in message_of_row.iter().enumerate() {
        let Some(Some((message, codec, table))) = tables.get_mut(index as usize) else {
            continue;
        };
        let Some(frame) = frames.row(row) else {
            // No time or no channel: not a frame a table can hold.
            summary.unknown += 1;
            continue;
        };
        match decode_row(codec, frame.data, &mut values) {
            Ok(decoded) => table.push(message, frame.ts, frame.channel, decoded, &values),
            Err(e) => summary.count_undecodable(message, &e),
        }
    }
    let mut batches = Vec::new();
    for (message, codec, table) in tables.iter_mut().flatten() {
        if table.rows == 0 {
            continue;
        }
        *summary
            .rows
            .entry(message.display_name().to_string())
            .or_default() += table.rows as u64;
        let batch = table.finish(message, codec).map_err(|e| LogError::Table {
            row: 0,
            what: e.to_string(),
        })?;
        batches.push((message.display_name().to_string(), batch));
    }
    Ok((batches, summary))
}

fn close(mut table: OpenTable, decoder: &Decoder) -> std::io::Result<()> {
    if table.columns.rows > 0 {
        if let Some((message, codec)) = decoder.message_at(table.message) {
            let batch = table.columns.finish(message, codec)?;
            table.writer.write(&batch)?;
        }
    }
    table.writer.finish()?;
    Ok(())
}

/// A partition value as a directory name: Hive's escaping (`%XX` for anything but letters,
/// digits and `_-.`), so a name can never leave the dataset's directory.
fn path_value(value: &str) -> String {
    let mut out = String::with_capacity(value.len());
    for byte in value.bytes() {
        if byte.is_ascii_alphanumeric()
            || matches!(byte, b'_' | b'-')
            || (byte == b'.' && !out.is_empty())
        {
            out.push(char::from(byte));
        } else {
            out.push_str(&format!("%{byte:02X}"));
        }
    }
    if out.is_empty() {
        out.push_str("__HIVE_DEFAULT_PARTITION__");
    }
    out
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::test_support::{cell, row_texts};

    #[test]
    fn partition_values_cannot_climb_out_of_the_dataset() {
        assert_eq!(path_value("can0"), "can0");
        assert_eq!(path_value("../etc"), "%2E.%2Fetc");
        assert_eq!(path_value("a/b c"), "a%2Fb%20c");
        assert_eq!(path_value(""), "__HIVE_DEFAULT_PARTITION__");
    }

    #[test]
    fn a_table_past_the_held_metadata_budget_continues_in_its_next_file() {
        let text = "BO_ 1 M: 2 X\n SG_ A : 0|8@1+ (1,0) [0|0] \"\" X\n SG_ B : 8|8@1+ (1,0) [0|0] \"\" X\n";
        let decoder = decoder_of(text);
        let root = fresh_dir("held");
        let mut dataset = DecodedDataset::create(&root, &decoder, Partitioning::default()).unwrap();
        // Every batch (TABLE_BATCH rows) a row group of 4 column chunks (ts, channel, A, B); a
        // table holding more than 8 is finished after its third.
        dataset.memory_budget = 1;
        dataset.held_budget = 8;
        let id = bywire_core::Id::standard(1).unwrap();
        let rows = u32::try_from(TABLE_BATCH * 15).unwrap();
        for i in 0..rows {
            let byte = u8::try_from(i % 251).unwrap();
            dataset
                .write(&LogRecord {
                    timestamp: bywire_core::Timestamp::from_nanos(u64::from(i)),
                    interface: "can0".into(),
                    frame: bywire_core::Frame::classic(id, &[byte, 7]).unwrap(),
                    direction: None,
                })
                .unwrap();
        }
        let summary = dataset.finish().unwrap();
        assert!(summary.files.len() > 3, "{:?}", summary.files);
        let mut ts = Vec::new();
        for path in &summary.files {
            let file = File::open(path).unwrap();
            let reader =
                ::parquet::arrow::arrow_reader::ParquetRecordBatchReader::try_new(file, 1 << 16)
                    .unwrap();
            for batch in reader {
                let batch = batch.unwrap();
                let column = batch.column(0).to_data();
                let values = arrow_array::Int64Array::from(
                    column
                        .into_builder()
                        .data_type(DataType::Int64)
                        .build()
                        .unwrap(),
                );
                ts.extend(values.values().iter().copied());
            }
            // Each file holds at most three row groups.
            let file = File::open(path).unwrap();
            let metadata = ::parquet::file::reader::FileReader::metadata(
                &::parquet::file::reader::SerializedFileReader::new(file).unwrap(),
            )
            .num_row_groups();
            assert!(metadata <= 3, "{metadata} row groups in {}", path.display());
        }
        assert_eq!(ts, (0..i64::from(rows)).collect::<Vec<_>>());
        std::fs::remove_dir_all(&root).unwrap();
    }

    /// Each table's cell as text: values, descriptions and channels alike.
    /// A decoder of the DBC `text`.
    /// The dataset's one file and its Parquet metadata.
    fn only_file(
        summary: &DatasetSummary,
    ) -> (PathBuf, ::parquet::file::metadata::ParquetMetaData) {
        let [path] = &summary.files[..] else {
            panic!("{:?}", summary.files)
        };
        let reader =
            ::parquet::file::reader::SerializedFileReader::new(File::open(path).unwrap()).unwrap();
        let metadata = ::parquet::file::reader::FileReader::metadata(&reader).clone();
        (path.clone(), metadata)
    }

    fn decoder_of(text: &str) -> Decoder {
        let (db, _) = bywire_dbc::parse_str(text, bywire_dbc::Mode::Lenient).unwrap();
        Decoder::new(db)
    }

    /// An empty folder, named for one test, for its dataset.
    fn fresh_dir(name: &str) -> PathBuf {
        let root = std::env::temp_dir().join(format!("bywire-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        root
    }

    /// What a table's row should hold, from decoding its frame alone.
    fn expected_row(decoder: &Decoder, record: &LogRecord) -> Option<(String, Vec<String>)> {
        let mut values = Vec::new();
        let (_, message, decoded) = decoder.decode_into(&record.frame, &mut values)?;
        decoded.ok()?;
        let mut row = vec![
            nanos(record.timestamp).to_string(),
            record.interface.clone(),
        ];
        for (signal, (value, kind)) in message
            .signals
            .iter()
            .zip(values.iter().zip(message.signals.iter().map(kind)))
        {
            row.push(match (value, kind) {
                (None, _) => "null".into(),
                (Some(v), Kind::Float) => format!("{:?}", v.physical.as_f64()),
                (Some(v), _) => v.physical.as_i128().unwrap().to_string(),
            });
            if !signal.value_descriptions.is_empty() {
                let text = value.and_then(|v| {
                    SignalValue { signal, value: v }
                        .description()
                        .map(str::to_string)
                });
                row.push(text.unwrap_or_else(|| "null".into()));
            }
        }
        Some((message.display_name().to_string(), row))
    }

    #[test]
    fn a_batch_decodes_as_its_frames_do_one_by_one() {
        let text = concat!(
            "BO_ 256 Plain: 8 X\n",
            " SG_ Mode : 0|3@1+ (1,0) [0|0] \"\" X\n",
            " SG_ Angle : 8|12@1- (0.5,-3) [0|0] \"\" X\n",
            " SG_ Big : 39|16@0+ (2,100) [0|0] \"\" X\n",
            " SG_ Tail : 56|8@1- (1,0) [0|0] \"\" X\n",
            "BO_ 512 Short: 3 X\n",
            " SG_ S : 4|16@1+ (0.25,0) [0|0] \"\" X\n",
            "BO_ 768 Muxed: 8 X\n",
            " SG_ Sel M : 0|2@1+ (1,0) [0|0] \"\" X\n",
            " SG_ Zero m0 : 8|8@1+ (1,0) [0|0] \"\" X\n",
            " SG_ One m1 : 8|16@1- (0.1,0) [0|0] \"\" X\n",
            "BO_ 2147484672 Long: 12 X\n",
            " SG_ Far : 80|16@1+ (1,0) [0|0] \"\" X\n",
            "VAL_ 256 Mode 0 \"Off\" 1 \"On\" 5 \"Crab\" ;\n",
            // Signed, short: looked up by raw bits (-1 is 0xFF); longer: searched.
            "VAL_ 256 Tail -1 \"Invalid\" 3 \"Three\" 127 \"Max\" -128 \"Min\" ;\n",
            "VAL_ 256 Angle 0 \"Zero\" -1 \"MinusOne\" 2047 \"Top\" ;\n",
            "VAL_ 768 Zero 1 \"One\" 200 \"Many\" ;\n",
        );
        let decoder = decoder_of(text);
        let mut state = 0x1234_5678_9ABC_DEF1u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let mut records = Vec::new();
        for i in 0..3000u64 {
            let pick = next();
            let bytes: Vec<u8> = (0..12).map(|_| next().to_le_bytes()[0]).collect();
            let (id, length) = match pick % 7 {
                0 | 1 => (bywire_core::Id::standard(256), 8),
                2 => (bywire_core::Id::standard(512), 3),
                3 => (bywire_core::Id::standard(256), 5), // too short
                4 => (bywire_core::Id::standard(768), 8),
                5 => (bywire_core::Id::extended(1024), 12),
                _ => (bywire_core::Id::standard(0x7FF), 8), // no message
            };
            let id = id.unwrap();
            let frame = if length == 12 {
                bywire_core::Frame::fd(id, &bytes, true, false).unwrap()
            } else if pick % 53 == 0 {
                bywire_core::Frame::remote(id, bywire_core::Dlc::new(8).unwrap())
            } else {
                bywire_core::Frame::classic(id, &bytes[..length]).unwrap()
            };
            records.push(LogRecord {
                timestamp: bywire_core::Timestamp::from_nanos(1_000_000 * i),
                interface: format!("can{}", (pick >> 8) % 3),
                frame,
                direction: None,
            });
        }
        let expected_of = |records: &[LogRecord]| {
            let mut expected: BTreeMap<String, Vec<Vec<String>>> = BTreeMap::new();
            for record in records {
                if let Some((message, row)) = expected_row(&decoder, record) {
                    expected.entry(message).or_default().push(row);
                }
            }
            expected
        };
        let cells_of = |tables: &[(String, RecordBatch)]| {
            let mut got: BTreeMap<String, Vec<Vec<String>>> = BTreeMap::new();
            for (name, table) in tables {
                let rows = got.entry(name.clone()).or_default();
                for row in 0..table.num_rows() {
                    rows.push(
                        table
                            .columns()
                            .iter()
                            .map(|c| cell(c.as_ref(), row))
                            .collect(),
                    );
                }
            }
            got
        };
        let expected = expected_of(&records);
        assert_eq!(expected.len(), 4, "every kind of message has rows");
        let mut columns = bywire_log::parquet::FrameColumns::new();
        for record in &records {
            columns.push(record);
        }
        let dictionary = columns.finish(&bywire_log::parquet::raw_schema()).unwrap();
        // The same frames with the channel as plain strings (as Spark and pandas give them).
        let plain = {
            let at = dictionary.schema().index_of("channel").unwrap();
            let mut fields: Vec<Field> = dictionary
                .schema()
                .fields()
                .iter()
                .map(|f| f.as_ref().clone())
                .collect();
            fields[at] = Field::new("channel", DataType::Utf8, false);
            let mut arrays = dictionary.columns().to_vec();
            let texts: Vec<String> = records.iter().map(|r| r.interface.clone()).collect();
            arrays[at] = Arc::new(arrow_array::StringArray::from(texts));
            RecordBatch::try_new(Arc::new(Schema::new(fields)), arrays).unwrap()
        };
        // A short batch: its 8-bit choice signal is searched for on each row rather than
        // looked up in a table of 256 entries.
        let few = 40;
        let (tables, _) = decode_frames_batch(&decoder, &dictionary.slice(0, few)).unwrap();
        assert_eq!(cells_of(&tables), expected_of(&records[..few]));
        for batch in [dictionary, plain] {
            let (tables, summary) = decode_frames_batch(&decoder, &batch).unwrap();
            assert_eq!(cells_of(&tables), expected);
            let short = summary.undecodable.get("Plain").map(|(n, _)| *n);
            assert!(short.is_some_and(|n| n > 0), "{summary:?}");
            assert!(summary.unknown > 0);
            let decoded: u64 = summary.rows.values().sum();
            let undecodable: u64 = summary.undecodable.values().map(|(n, _)| n).sum();
            assert_eq!(
                decoded + undecodable + summary.unknown,
                records.len() as u64
            );
        }
    }

    #[test]
    fn rows_without_a_time_or_a_channel_are_no_rows_and_times_come_in_any_unit() {
        use arrow_array::cast::AsArray;
        use arrow_array::types::TimestampNanosecondType;
        use arrow_array::{
            BinaryArray, DictionaryArray, StringArray, TimestampMicrosecondArray,
            TimestampSecondArray, UInt32Array,
        };
        let text = "BO_ 256 M: 1 X\n SG_ A : 0|8@1+ (1,0) [0|0] \"\" X\n";
        let decoder = decoder_of(text);
        let data = BinaryArray::from_iter_values([[1u8], [2], [3], [4], [5]]);
        let id = UInt32Array::from(vec![256; 5]);
        let batch = |ts: ArrayRef, channel: ArrayRef| {
            let fields = vec![
                Field::new("ts", ts.data_type().clone(), true),
                Field::new("channel", channel.data_type().clone(), true),
                Field::new("id", DataType::UInt32, false),
                Field::new("data", DataType::Binary, false),
            ];
            let columns = vec![ts, channel, Arc::new(id.clone()), Arc::new(data.clone())];
            RecordBatch::try_new(Arc::new(Schema::new(fields)), columns).unwrap()
        };
        // Row 1 has no time, row 3 no channel (a null key; row 4's key names a null text).
        let keys = arrow_array::Int32Array::from(vec![Some(1), Some(0), Some(1), None, Some(2)]);
        let texts = StringArray::from(vec![Some("can1"), Some("can0"), None]);
        let keyed: ArrayRef = Arc::new(DictionaryArray::try_new(keys, Arc::new(texts)).unwrap());
        let plain: ArrayRef = Arc::new(StringArray::from(vec![
            Some("can0"),
            Some("can1"),
            Some("can0"),
            None,
            Some(""),
        ]));
        let micros: ArrayRef = Arc::new(
            TimestampMicrosecondArray::from(vec![Some(10), None, Some(30), Some(40), Some(50)])
                .with_timezone("UTC"),
        );
        for channel in [keyed, plain] {
            let (tables, summary) =
                decode_frames_batch(&decoder, &batch(micros.clone(), channel)).unwrap();
            assert_eq!(summary.unknown, 2);
            let table = &tables[0].1;
            let ts = table.column(0).as_primitive::<TimestampNanosecondType>();
            assert_eq!(ts.values().to_vec(), [10_000, 30_000, 50_000]);
            let values = table.column(2).as_primitive::<Int64Type>();
            assert_eq!(values.values().to_vec(), [1, 3, 5]);
            let channel = |row| cell(table.column(1).as_ref(), row);
            assert_eq!(channel(2), "");
        }
        // Seconds too large for nanoseconds are no time either.
        let seconds: ArrayRef =
            Arc::new(TimestampSecondArray::from(vec![1, i64::MAX / 10, 3, 4, 5]));
        let plain: ArrayRef = Arc::new(StringArray::from(vec!["can0"; 5]));
        let (tables, summary) = decode_frames_batch(&decoder, &batch(seconds, plain)).unwrap();
        assert_eq!(summary.unknown, 1);
        let ts = tables[0]
            .1
            .column(0)
            .as_primitive::<TimestampNanosecondType>();
        assert_eq!(
            ts.values().to_vec(),
            [1, 3, 4, 5].map(|s| s * 1_000_000_000)
        );
    }

    #[test]
    fn channels_and_descriptions_are_dictionaries_times_and_integers_deltas_and_read_back() {
        use arrow_array::cast::AsArray;
        let text = "BO_ 1 M: 2 X\n SG_ A : 0|8@1+ (0.5,0) [0|0] \"\" X\n SG_ B : 8|2@1+ (1,0) [0|0] \"\" X\nVAL_ 1 B 0 \"Off\" 1 \"On\" ;\n";
        let decoder = decoder_of(text);
        let root = fresh_dir("labels");
        let mut dataset = DecodedDataset::create(&root, &decoder, Partitioning::default()).unwrap();
        let id = bywire_core::Id::standard(1).unwrap();
        for i in 0..1000u32 {
            let [low, ..] = i.to_le_bytes();
            dataset
                .write(&LogRecord {
                    timestamp: bywire_core::Timestamp::from_nanos(u64::from(i)),
                    interface: format!("can{}", i % 3),
                    frame: bywire_core::Frame::classic(id, &[low, low % 4]).unwrap(),
                    direction: None,
                })
                .unwrap();
        }
        let (path, metadata) = only_file(&dataset.finish().unwrap());
        let schema = metadata.file_metadata().schema_descr();
        for chunk in metadata.row_groups().iter().flat_map(|g| g.columns()) {
            let name = chunk.column_path().string();
            let dictionary = chunk.dictionary_page_offset().is_some();
            assert_eq!(
                dictionary,
                name == "channel" || name == "B_choice",
                "{name}"
            );
            // Times and integers as deltas (the scaled A is a float: plain).
            let delta = chunk
                .encodings()
                .any(|e| e == ::parquet::basic::Encoding::DELTA_BINARY_PACKED);
            assert_eq!(delta, name == "ts" || name == "B", "{name}");
        }
        assert_eq!(schema.num_columns(), 5);
        let batches = ::parquet::arrow::arrow_reader::ParquetRecordBatchReader::try_new(
            File::open(&path).unwrap(),
            1 << 16,
        )
        .unwrap();
        let (mut channels, mut choices) = (Vec::new(), Vec::new());
        for batch in batches {
            let batch = batch.unwrap();
            for row in 0..batch.num_rows() {
                channels.push(cell(batch.column(1).as_ref(), row));
                choices.push(cell(batch.column(4).as_ref(), row));
            }
            assert!(batch.column(1).as_any_dictionary_opt().is_some());
        }
        let expected_choice = |i: u32| match i % 4 {
            0 => "Off".to_string(),
            1 => "On".to_string(),
            _ => "null".to_string(),
        };
        assert_eq!(
            channels,
            (0..1000)
                .map(|i| format!("can{}", i % 3))
                .collect::<Vec<_>>()
        );
        assert_eq!(choices, (0..1000).map(expected_choice).collect::<Vec<_>>());
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn every_compression_holds_the_same_rows_in_pages_compressed_as_asked() {
        use ::parquet::basic::Compression;
        let text = "BO_ 1 M: 2 X\n SG_ A : 0|8@1+ (0.5,0) [0|0] \"\" X\n SG_ B : 8|2@1+ (1,0) [0|0] \"\" X\nVAL_ 1 B 0 \"Off\" 1 \"On\" ;\n";
        let decoder = decoder_of(text);
        let id = bywire_core::Id::standard(1).unwrap();
        let mut tables = Vec::new();
        for (compression, codec) in [
            (
                ParquetCompression::Zstd,
                Compression::ZSTD(Default::default()),
            ),
            (ParquetCompression::Snappy, Compression::SNAPPY),
            (ParquetCompression::Uncompressed, Compression::UNCOMPRESSED),
        ] {
            let root = fresh_dir(&format!("compression-{compression:?}"));
            let mut dataset =
                DecodedDataset::create(&root, &decoder, Partitioning::default()).unwrap();
            dataset.set_compression(compression);
            for i in 0..2000u32 {
                let [low, high, ..] = i.to_le_bytes();
                dataset
                    .write(&LogRecord {
                        timestamp: bywire_core::Timestamp::from_nanos(u64::from(i) * 1000),
                        interface: format!("can{}", i % 2),
                        frame: bywire_core::Frame::classic(id, &[low, high]).unwrap(),
                        direction: None,
                    })
                    .unwrap();
            }
            let (path, metadata) = only_file(&dataset.finish().unwrap());
            for chunk in metadata.row_groups().iter().flat_map(|g| g.columns()) {
                assert_eq!(chunk.compression(), codec, "{compression:?}");
            }
            let batches = ::parquet::arrow::arrow_reader::ParquetRecordBatchReader::try_new(
                File::open(&path).unwrap(),
                1 << 16,
            )
            .unwrap();
            let batches: Vec<RecordBatch> = batches.map(Result::unwrap).collect();
            let rows = row_texts(&batches);
            assert_eq!(rows.len(), 2000);
            tables.push(rows);
            std::fs::remove_dir_all(&root).unwrap();
        }
        assert_eq!(tables[0], tables[1]);
        assert_eq!(tables[0], tables[2]);
    }

    #[test]
    fn times_in_microseconds_are_floored_and_typed_as_such() {
        use arrow_array::cast::AsArray;
        use arrow_array::types::TimestampMicrosecondType;
        let decoder = decoder_of("BO_ 1 M: 1 X\n SG_ A : 0|8@1+ (1,0) [0|0] \"\" X\n");
        let root = fresh_dir("micros");
        let mut dataset = DecodedDataset::create(&root, &decoder, Partitioning::default()).unwrap();
        dataset.set_time_precision(Precision::Micros);
        let id = bywire_core::Id::standard(1).unwrap();
        let nanos = [1_999u64, 2_000, 1_700_000_000_123_456_789];
        for (at, value) in nanos.iter().zip(1u8..) {
            dataset
                .write(&LogRecord {
                    timestamp: bywire_core::Timestamp::from_nanos(*at),
                    interface: "can0".into(),
                    frame: bywire_core::Frame::classic(id, &[value]).unwrap(),
                    direction: None,
                })
                .unwrap();
        }
        let (path, _) = only_file(&dataset.finish().unwrap());
        let batches: Vec<RecordBatch> =
            ::parquet::arrow::arrow_reader::ParquetRecordBatchReader::try_new(
                File::open(&path).unwrap(),
                1024,
            )
            .unwrap()
            .map(Result::unwrap)
            .collect();
        let ts = batches[0].column(0);
        assert_eq!(
            ts.data_type(),
            &DataType::Timestamp(arrow_schema::TimeUnit::Microsecond, Some("UTC".into()))
        );
        let micros = ts
            .as_primitive::<TimestampMicrosecondType>()
            .values()
            .to_vec();
        assert_eq!(micros, [1, 2, 1_700_000_000_123_456]);
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn column_types_hold_every_value_a_signal_can_take() {
        let text = "BO_ 1 M: 8 X\n SG_ A : 0|8@1+ (1,0) [0|0] \"\" X\n SG_ B : 8|8@1- (0.5,0) [0|0] \"\" X\n SG_ C : 0|64@1+ (1,0) [0|0] \"\" X\n SG_ D : 0|64@1+ (2,0) [0|0] \"\" X\n SG_ E : 0|64@1- (1,-3) [0|0] \"\" X\n";
        let (db, _) = bywire_dbc::parse_str(text, bywire_dbc::Mode::Lenient).unwrap();
        let kinds: Vec<Kind> = db.messages[0].signals.iter().map(kind).collect();
        assert_eq!(
            kinds,
            [Kind::Int, Kind::Float, Kind::UInt, Kind::Float, Kind::Float]
        );
    }
}
