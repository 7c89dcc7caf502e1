//! Decoded frames as a Parquet dataset: one table per message, one typed column per signal,
//! partitioned the way data lakes read (Hive-style directories):
//!
//! ```text
//! OUT/message=VehicleToAds_State/part-00000.parquet
//! OUT/message=VehicleToAds_State/channel=can0/date=2024-05-01/part-00000.parquet   (when asked)
//! ```
//!
//! A table's columns are `ts` (timestamp, ns, UTC), `channel` (unless the channel is a partition),
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

use std::collections::{BTreeMap, HashMap};
use std::fs::{File, OpenOptions};
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use ::parquet::arrow::ArrowWriter;
use arrow_array::builder::{
    Float64Builder, Int64Builder, TimestampNanosecondBuilder, UInt64Builder,
};
use arrow_array::{ArrayRef, RecordBatch};
use arrow_schema::{DataType, Field, Schema, SchemaRef};
use bywire_dbc::codec::{whole_scaling, Decoded, Value};
use bywire_dbc::decoder::{field_names, Decoder, SignalValue};
use bywire_dbc::{Message, Signal, ValueType};

use super::{
    dictionary_type, io_error, nanos, properties, timestamp_type, FrameColumnsRef, Labels,
};
use crate::calendar;
use crate::candump::{LogError, LogRecord};

/// Rows a table builds up before they are encoded (fewer when many tables are open).
pub const TABLE_BATCH: usize = 4096;
/// Rows all open tables may hold unencoded.
pub const BUILT_ROWS: usize = 1 << 19;
/// Encoded bytes all open tables may hold before their row groups are written out.
pub const MEMORY_BUDGET: usize = 256 << 20;
/// Tables open at once.
pub const OPEN_TABLES: usize = 4096;
/// Column chunks the open tables' finished row groups may hold: a writer keeps each one's
/// metadata (about 1.5 KB: statistics, page indexes) until its file's footer, so a file that
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
    fn new(kind: Kind) -> Self {
        match kind {
            Kind::Int => ValueColumn::Int(Int64Builder::with_capacity(TABLE_BATCH)),
            Kind::UInt => ValueColumn::UInt(UInt64Builder::with_capacity(TABLE_BATCH)),
            Kind::Float => ValueColumn::Float(Float64Builder::with_capacity(TABLE_BATCH)),
        }
    }

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

/// One message's columns: the schema and what is being built.
struct MessageColumns {
    schema: SchemaRef,
    ts: TimestampNanosecondBuilder,
    channel: Option<Labels>,
    values: Vec<ValueColumn>,
    /// Per signal, its description column when it has value descriptions.
    choices: Vec<Option<Labels>>,
    rows: usize,
}

impl MessageColumns {
    fn new(message: &Message, with_channel: bool) -> Self {
        let names = field_names(message);
        let kinds: Vec<Kind> = message.signals.iter().map(kind).collect();
        let mut fields = vec![Field::new("ts", timestamp_type(), false)];
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
            ts: TimestampNanosecondBuilder::with_capacity(TABLE_BATCH).with_timezone("UTC"),
            channel: with_channel.then(|| Labels::new(Vec::new())),
            values: kinds.into_iter().map(ValueColumn::new).collect(),
            choices: message
                .signals
                .iter()
                .map(|s| {
                    let labels = s.value_descriptions.iter().map(|(_, l)| l.clone());
                    (!s.value_descriptions.is_empty()).then(|| Labels::new(labels.collect()))
                })
                .collect(),
            rows: 0,
        }
    }

    fn push(&mut self, message: &Message, record: &LogRecord, decoded: &[Option<Decoded>]) {
        self.push_values(message, nanos(record.timestamp), &record.interface, decoded);
    }

    fn push_values(
        &mut self,
        message: &Message,
        ts: i64,
        channel: &str,
        decoded: &[Option<Decoded>],
    ) {
        self.ts.append_value(ts);
        if let Some(labels) = &mut self.channel {
            labels.push_text(channel);
        }
        let columns = self.values.iter_mut().zip(&mut self.choices);
        for ((signal, value), (column, choice)) in message.signals.iter().zip(decoded).zip(columns)
        {
            column.push(value.map(|v| v.physical));
            if let Some(choice) = choice {
                // The description's index among the signal's value descriptions.
                let key = value
                    .and_then(|value| SignalValue { signal, value }.description_key())
                    .and_then(|key| {
                        signal
                            .value_descriptions
                            .iter()
                            .position(|(k, _)| *k == key)
                    });
                choice.push_key(key);
            }
        }
        self.rows += 1;
    }

    fn finish(&mut self) -> std::io::Result<RecordBatch> {
        let mut columns: Vec<ArrayRef> = vec![Arc::new(self.ts.finish())];
        if let Some(channel) = &mut self.channel {
            columns.push(channel.finish()?);
        }
        for (value, choice) in self.values.iter_mut().zip(&mut self.choices) {
            columns.push(value.finish());
            if let Some(choice) = choice {
                columns.push(choice.finish()?);
            }
        }
        self.rows = 0;
        RecordBatch::try_new(self.schema.clone(), columns).map_err(io_error)
    }
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
    columns: MessageColumns,
    writer: ArrowWriter<BufWriter<AppendFile>>,
    last_used: u64,
}

impl OpenTable {
    /// Column chunks of the row groups written so far (their metadata is held until the end).
    fn held_chunks(&self) -> usize {
        self.writer.flushed_row_groups().len() * self.columns.schema.fields().len()
    }
}

/// Writes decoded records into a dataset directory.
pub struct DecodedDataset<'a> {
    decoder: &'a Decoder,
    root: PathBuf,
    partitioning: Partitioning,
    open: HashMap<PartitionKey, OpenTable>,
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
            open: HashMap::new(),
            parts: HashMap::new(),
            decoded: Vec::new(),
            rows: vec![0; decoder.database().messages.len()],
            summary: DatasetSummary::default(),
            clock: 0,
            held_budget: HELD_CHUNKS,
            memory_budget: MEMORY_BUDGET,
        })
    }

    /// Decode one record and add its row.
    pub fn write(&mut self, record: &LogRecord) -> std::io::Result<()> {
        let Some((index, message)) =
            decode_counted(self.decoder, record, &mut self.decoded, &mut self.summary)
        else {
            return Ok(());
        };
        let key = PartitionKey {
            message: index,
            channel: self.partitioning.channel.then(|| record.interface.clone()),
            day: self
                .partitioning
                .date
                .then(|| record.timestamp.as_nanos() / 86_400_000_000_000),
        };
        self.clock += 1;
        if !self.open.contains_key(&key) {
            self.open_table(&key, message)?;
        }
        let open = self.open.len().max(1);
        let (budget, batch) = (
            self.memory_budget / open,
            (BUILT_ROWS / open).clamp(16, TABLE_BATCH),
        );
        let Some(table) = self.open.get_mut(&key) else {
            return Ok(());
        };
        table.last_used = self.clock;
        table.columns.push(message, record, &self.decoded);
        let mut finished_row_group = false;
        if table.columns.rows >= batch {
            let row_groups = table.writer.flushed_row_groups().len();
            let batch = table.columns.finish()?;
            table.writer.write(&batch).map_err(io_error)?;
            if table.writer.in_progress_size() > budget {
                table.writer.flush().map_err(io_error)?;
            }
            finished_row_group = table.writer.flushed_row_groups().len() > row_groups;
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
                Some(table) => close(table)?,
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
                close(table)?;
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
        let columns = MessageColumns::new(message, !self.partitioning.channel);
        File::create(&path)?;
        let writer = ArrowWriter::try_new(
            BufWriter::with_capacity(FILE_BUFFER, AppendFile { path: path.clone() }),
            columns.schema.clone(),
            Some(properties(DECODED_LAYOUT, false)),
        )
        .map_err(io_error)?;
        self.summary.files.push(path);
        self.open.insert(
            key.clone(),
            OpenTable {
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
            close(table)?;
        }
        let messages = &self.decoder.database().messages;
        for (message, rows) in messages.iter().zip(&self.rows) {
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

/// Decode `record` into `values`: its message's index and the message, or `None` when it is of
/// no message or does not decode (counted in `summary`).
fn decode_counted<'d>(
    decoder: &'d Decoder,
    record: &LogRecord,
    values: &mut Vec<Option<Decoded>>,
    summary: &mut DatasetSummary,
) -> Option<(usize, &'d Message)> {
    let Some((index, message, decoded)) = decoder.decode_into(&record.frame, values) else {
        summary.unknown += 1;
        return None;
    };
    if let Err(e) = decoded {
        summary.count_undecodable(message, &e);
        return None;
    }
    Some((index, message))
}

/// A batch of raw frames (the layout [`super::raw_schema`] gives, or any batch
/// [`super::records_of_batch`] reads) decoded straight from its columns into one batch per
/// message with the columns a dataset's table has (`channel` always), in the database's order,
/// and the counts ([`DatasetSummary::files`] empty). For callers that take Arrow in memory (the
/// Python package): no record is built per frame.
pub fn decode_frames_batch(
    decoder: &Decoder,
    batch: &RecordBatch,
) -> Result<(Vec<(String, RecordBatch)>, DatasetSummary), LogError> {
    let frames = FrameColumnsRef::of(batch)?;
    let messages = &decoder.database().messages;
    let mut tables: Vec<Option<MessageColumns>> = Vec::new();
    tables.resize_with(messages.len(), || None);
    let mut summary = DatasetSummary::default();
    let mut values: Vec<Option<Decoded>> = Vec::new();
    for row in 0..batch.num_rows() {
        let Some((ts, channel, id, extended, data)) = frames.row(row) else {
            summary.unknown += 1;
            continue;
        };
        let Some((index, message, codec)) = decoder.message_with_id(id, extended) else {
            summary.unknown += 1;
            continue;
        };
        values.clear();
        values.resize(codec.signal_count(), None);
        if let Err(e) = codec.decode(data, &mut values) {
            summary.count_undecodable(message, &e);
            continue;
        }
        let Some(slot) = tables.get_mut(index) else {
            continue;
        };
        slot.get_or_insert_with(|| MessageColumns::new(message, true))
            .push_values(message, ts, channel, &values);
    }
    let mut batches = Vec::new();
    for (message, table) in messages.iter().zip(&mut tables) {
        if let Some(table) = table {
            *summary
                .rows
                .entry(message.display_name().to_string())
                .or_default() += table.rows as u64;
            let batch = table.finish().map_err(|e| LogError::Table {
                row: 0,
                what: e.to_string(),
            })?;
            batches.push((message.display_name().to_string(), batch));
        }
    }
    Ok((batches, summary))
}

fn close(mut table: OpenTable) -> std::io::Result<()> {
    if table.columns.rows > 0 {
        let batch = table.columns.finish()?;
        table.writer.write(&batch).map_err(io_error)?;
    }
    let mut file = table.writer.into_inner().map_err(io_error)?;
    std::io::Write::flush(&mut file)?;
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
        let (db, _) = bywire_dbc::parse_str(text, bywire_dbc::Mode::Lenient).unwrap();
        let decoder = Decoder::new(db);
        let root = std::env::temp_dir().join(format!("bywire-held-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let mut dataset = DecodedDataset::create(&root, &decoder, Partitioning::default()).unwrap();
        // Every batch (4096 rows) a row group of 4 column chunks (ts, channel, A, B); a table
        // holding more than 8 is finished after its third.
        dataset.memory_budget = 1;
        dataset.held_budget = 8;
        let id = bywire_core::Id::standard(1).unwrap();
        for i in 0..60_000u32 {
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
        assert_eq!(ts, (0..60_000i64).collect::<Vec<_>>());
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
