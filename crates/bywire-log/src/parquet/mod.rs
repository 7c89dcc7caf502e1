//! Parquet (feature `parquet`): raw frames read and written as one table. The decoded tables,
//! one per message, and the data lake are `bywire-data`'s, built from the columns and records
//! this module reads.
//!
//! The raw table has one row a frame, zstd-compressed unless asked otherwise
//! ([`ParquetCompression`]), in row groups of [`ROW_GROUP_ROWS`]:
//!
//! | column | type | |
//! |---|---|---|
//! | `ts` | timestamp (ns, UTC; µs when asked, floored) | when the frame was on the bus |
//! | `channel` | dictionary string | the interface (`can0`) |
//! | `id` | uint32 | the identifier (an error frame: its SocketCAN class bits) |
//! | `extended`, `remote`, `error`, `fd`, `brs`, `esi` | bool | the frame's kind and flags |
//! | `dir` | dictionary string, nullable | `rx`, `tx`, or null when the log did not say |
//! | `dlc` | uint8 | the DLC (a remote frame has one and no data) |
//! | `data` | binary | the data bytes |
//!
//! Parquet keeps its index at the end of the file, so a reader needs a file it can seek in
//! ([`ParquetReader::open`]); it holds one batch of rows at a time. The writer holds one row
//! group's encoded columns at most, and [`ParquetWriter::finish`] writes the footer (a file
//! without one is not a Parquet file, which is why conversions write to a temporary name).

mod footer;

use std::collections::{HashMap, VecDeque};
use std::fs::File;
use std::io::Write;
use std::sync::Arc;

use ::parquet::arrow::arrow_reader::{ParquetRecordBatchReader, ParquetRecordBatchReaderBuilder};
use ::parquet::arrow::ArrowWriter;
use ::parquet::basic::{Compression, ZstdLevel};
use ::parquet::file::metadata::KeyValue;
use ::parquet::file::properties::WriterProperties;
use arrow_array::builder::{
    ArrayBuilder, BinaryBuilder, BooleanBuilder, UInt32Builder, UInt8Builder,
};
use arrow_array::cast::AsArray;
use arrow_array::types::{Int32Type, UInt32Type, UInt8Type};
use arrow_array::{
    Array, ArrayAccessor, ArrayRef, RecordBatch, TimestampMicrosecondArray,
    TimestampNanosecondArray,
};
use arrow_schema::{DataType, Field, Schema, SchemaRef, TimeUnit};
use bywire_core::frame::{ClassicFrame, Dlc, ErrorFrame, FdFrame};
use bywire_core::{Frame, Id, Timestamp};

use crate::candump::{LogError, LogRecord, Precision};
pub use crate::options::{ParquetCompression, ParquetOptions};

/// Rows a row group holds (about 20–40 MB of frames before compression).
pub const ROW_GROUP_ROWS: usize = 1 << 20;
/// Rows built up before they are handed to the encoder (and read at once).
const BATCH_ROWS: usize = 8192;
/// The key-value metadata key naming the table's layout, and its value.
pub const LAYOUT_KEY: &str = "bywire.layout";
/// The raw frames' layout, as [`LAYOUT_KEY`] names it.
pub const RAW_LAYOUT: &str = "can-frames/1";

/// A `ts` column's type in `precision` (UTC).
pub fn timestamp_type_in(precision: Precision) -> DataType {
    let unit = match precision {
        Precision::Nanos => TimeUnit::Nanosecond,
        Precision::Micros => TimeUnit::Microsecond,
    };
    DataType::Timestamp(unit, Some("UTC".into()))
}

/// A `ts` column from nanoseconds, in `precision` (microseconds floored: a time never moves
/// past the next frame's).
pub fn time_array(mut nanos: Vec<i64>, precision: Precision) -> ArrayRef {
    match precision {
        Precision::Nanos => {
            Arc::new(TimestampNanosecondArray::new(nanos.into(), None).with_timezone("UTC"))
        }
        Precision::Micros => {
            nanos.iter_mut().for_each(|t| *t = t.div_euclid(1000));
            Arc::new(TimestampMicrosecondArray::new(nanos.into(), None).with_timezone("UTC"))
        }
    }
}

/// A dictionary-encoded string column's type (what pandas opens as a category).
pub fn dictionary_type() -> DataType {
    DataType::Dictionary(Box::new(DataType::Int32), Box::new(DataType::Utf8))
}

/// The raw frames' schema.
pub fn raw_schema() -> SchemaRef {
    raw_schema_in(Precision::Nanos)
}

/// The raw frames' schema with its times in `precision`.
pub fn raw_schema_in(precision: Precision) -> SchemaRef {
    let flag = |name: &str| Field::new(name, DataType::Boolean, false);
    Arc::new(Schema::new(vec![
        Field::new("ts", timestamp_type_in(precision), false),
        Field::new("channel", dictionary_type(), false),
        Field::new("id", DataType::UInt32, false),
        flag("extended"),
        flag("remote"),
        flag("error"),
        flag("fd"),
        flag("brs"),
        flag("esi"),
        Field::new("dir", dictionary_type(), true),
        Field::new("dlc", DataType::UInt8, false),
        Field::new("data", DataType::Binary, false),
    ]))
}

/// parquet-rs's writer properties (the raw frames' files and numeric tables): pages
/// compressed as asked, row groups of [`ROW_GROUP_ROWS`], the layout in the metadata,
/// dictionary pages when asked.
pub fn properties(
    layout: &str,
    dictionary_pages: bool,
    compression: ParquetCompression,
) -> WriterProperties {
    properties_with_dictionaries(layout, dictionary_pages, &[], &[], compression)
}

/// As [`properties`], with dictionary pages for the columns named in `dictionaries` whatever
/// `dictionary_pages` says, and the integer columns named in `deltas` delta-encoded
/// (`DELTA_BINARY_PACKED`).
pub fn properties_with_dictionaries(
    layout: &str,
    dictionary_pages: bool,
    dictionaries: &[&str],
    deltas: &[&str],
    compression: ParquetCompression,
) -> WriterProperties {
    let mut builder = WriterProperties::builder();
    for name in deltas {
        let path = ::parquet::schema::types::ColumnPath::from(*name);
        builder = builder
            .set_column_dictionary_enabled(path.clone(), false)
            .set_column_encoding(path, ::parquet::basic::Encoding::DELTA_BINARY_PACKED);
    }
    for name in dictionaries {
        builder = builder
            .set_column_dictionary_enabled(::parquet::schema::types::ColumnPath::from(*name), true);
    }
    builder
        .set_compression(match compression {
            ParquetCompression::Zstd => Compression::ZSTD(ZstdLevel::default()),
            ParquetCompression::Snappy => Compression::SNAPPY,
            ParquetCompression::Uncompressed => Compression::UNCOMPRESSED,
        })
        .set_max_row_group_row_count(Some(ROW_GROUP_ROWS))
        .set_dictionary_enabled(dictionary_pages)
        .set_key_value_metadata(Some(vec![KeyValue::new(
            LAYOUT_KEY.to_string(),
            layout.to_string(),
        )]))
        .build()
}

/// A Parquet error as an I/O error (what the writers return).
pub fn io_error(e: impl std::fmt::Display) -> std::io::Error {
    std::io::Error::other(format!("Parquet: {e}"))
}

/// The timestamp as Parquet's signed nanoseconds (a time past 2262 saturates).
pub fn nanos(timestamp: Timestamp) -> i64 {
    i64::try_from(timestamp.as_nanos()).unwrap_or(i64::MAX)
}

/// A dictionary-string column whose strings are known or few: keys built directly into a list
/// of values, with no hashing per row (profiled: hashing each row's string in arrow's
/// dictionary builder took 40 % of the time).
pub struct Labels {
    /// Keys as plain vectors, not an Arrow builder: a push is a store (the builder's
    /// bookkeeping cost several times that on every row).
    keys: Vec<i32>,
    /// Which keys are values, once one is null (until then, all are).
    valid: Option<Vec<bool>>,
    values: Vec<String>,
    /// The values' keys, for texts not known in advance (channels), once there are many.
    index: HashMap<String, usize>,
    /// The last text's key: rows of one channel follow each other, found with one comparison.
    last: Option<usize>,
    /// Keys of the texts of an input dictionary's keys, as they were seen (input key → ours):
    /// a dictionary-encoded input's texts are compared once, not once per row.
    seen: Vec<Option<usize>>,
}

/// Input dictionary keys remembered by [`Labels::push_channel`] (beyond, texts compared).
const LABELS_SEEN: usize = 1024;

/// Up to this many values a text is found by comparing (a log's few channels); beyond, by hash.
const LABELS_SCANNED: usize = 16;

impl Labels {
    /// Labels from `values` (more are added as texts come), room for `rows` keys.
    pub fn new(values: Vec<String>, rows: usize) -> Self {
        Labels {
            keys: Vec::with_capacity(rows),
            valid: None,
            index: values.iter().cloned().zip(0..).collect(),
            values,
            last: None,
            seen: Vec::new(),
        }
    }

    /// As [`Labels::push_text`], for a row's channel: a dictionary-encoded input's keys are
    /// matched once each (texts compared on a key's first row, not on every row).
    #[inline(always)]
    pub fn push_channel(&mut self, channel: ChannelRef<'_>) {
        let ChannelRef::Key(input, _) = channel else {
            return self.push_text(channel.text());
        };
        if let Some(Some(key)) = self.seen.get(input) {
            return self.push_key(Some(*key));
        }
        self.push_text(channel.text());
        if input < LABELS_SEEN {
            if self.seen.len() <= input {
                self.seen.resize(input + 1, None);
            }
            if let Some(slot) = self.seen.get_mut(input) {
                *slot = self.last;
            }
        }
    }

    /// The key of `text`, added to the values if new.
    pub fn push_text(&mut self, text: &str) {
        if let Some(key) = self.last {
            if self.values.get(key).is_some_and(|v| v == text) {
                return self.push_key(Some(key));
            }
        }
        let found = if self.values.len() <= LABELS_SCANNED {
            self.values.iter().position(|v| v == text)
        } else {
            self.index.get(text).copied()
        };
        let key = found.unwrap_or_else(|| {
            self.values.push(text.to_string());
            self.index.insert(text.to_string(), self.values.len() - 1);
            self.values.len() - 1
        });
        self.last = Some(key);
        self.push_key(Some(key));
    }

    /// Add keys already found (indexes into the values; a null key, no value).
    pub fn append_keys(&mut self, keys: &arrow_array::Int32Array) {
        let before = self.keys.len();
        self.keys.extend_from_slice(keys.values());
        match (keys.nulls(), &mut self.valid) {
            (None, None) => {}
            (None, Some(valid)) => valid.resize(self.keys.len(), true),
            (Some(nulls), valid) => valid
                .get_or_insert_with(|| vec![true; before])
                .extend(nulls.iter()),
        }
    }

    /// Append a row with this key (`None`: null).
    #[inline(always)]
    pub fn push_key(&mut self, key: Option<usize>) {
        match key.and_then(|k| i32::try_from(k).ok()) {
            Some(key) => {
                self.keys.push(key);
                if let Some(valid) = &mut self.valid {
                    valid.push(true);
                }
            }
            None => {
                let valid = self
                    .valid
                    .get_or_insert_with(|| vec![true; self.keys.len()]);
                valid.push(false);
                self.keys.push(0);
            }
        }
    }

    /// The column so far, as a dictionary array (emptied for the next).
    pub fn finish(&mut self) -> std::io::Result<ArrayRef> {
        let values = arrow_array::StringArray::from_iter_values(&self.values);
        let keys = arrow_array::Int32Array::new(
            std::mem::take(&mut self.keys).into(),
            self.valid.take().map(arrow_buffer::NullBuffer::from),
        );
        let array = arrow_array::DictionaryArray::<Int32Type>::try_new(keys, Arc::new(values))
            .map_err(io_error)?;
        Ok(Arc::new(array))
    }
}

/// Raw frames' columns being built: records in, [`raw_schema`] batches out (the writer's
/// buffer, and how other Arrow users get a log's frames without a file).
pub struct FrameColumns {
    /// Nanoseconds, put in the schema's unit when a batch is made.
    ts: Vec<i64>,
    precision: Precision,
    channel: Labels,
    id: UInt32Builder,
    extended: BooleanBuilder,
    remote: BooleanBuilder,
    error: BooleanBuilder,
    fd: BooleanBuilder,
    brs: BooleanBuilder,
    esi: BooleanBuilder,
    dir: Labels,
    dlc: UInt8Builder,
    data: BinaryBuilder,
}

impl Default for FrameColumns {
    fn default() -> Self {
        Self::new()
    }
}

impl FrameColumns {
    /// No rows yet; times in nanoseconds ([`raw_schema`]).
    pub fn new() -> Self {
        Self::with_precision(Precision::Nanos)
    }

    /// No rows yet; times in `precision` ([`raw_schema_in`]).
    pub fn with_precision(precision: Precision) -> Self {
        FrameColumns {
            ts: Vec::with_capacity(BATCH_ROWS),
            precision,
            channel: Labels::new(Vec::new(), BATCH_ROWS),
            id: UInt32Builder::with_capacity(BATCH_ROWS),
            extended: BooleanBuilder::with_capacity(BATCH_ROWS),
            remote: BooleanBuilder::with_capacity(BATCH_ROWS),
            error: BooleanBuilder::with_capacity(BATCH_ROWS),
            fd: BooleanBuilder::with_capacity(BATCH_ROWS),
            brs: BooleanBuilder::with_capacity(BATCH_ROWS),
            esi: BooleanBuilder::with_capacity(BATCH_ROWS),
            dir: Labels::new(vec!["rx".into(), "tx".into()], BATCH_ROWS),
            dlc: UInt8Builder::with_capacity(BATCH_ROWS),
            data: BinaryBuilder::with_capacity(BATCH_ROWS, BATCH_ROWS * 8),
        }
    }

    /// Add one record's row.
    pub fn push(&mut self, record: &LogRecord) {
        let frame = &record.frame;
        self.ts.push(nanos(record.timestamp));
        self.channel.push_text(&record.interface);
        let (id, extended) = match frame.id() {
            Some(id) => (id.as_raw(), id.is_extended()),
            None => (frame.socketcan_id() & 0x1FFF_FFFF, false),
        };
        self.id.append_value(id);
        self.extended.append_value(extended);
        self.remote.append_value(frame.is_remote());
        self.error.append_value(frame.is_error());
        self.fd.append_value(frame.is_fd());
        let (brs, esi) = match frame {
            Frame::Fd(f) => (f.brs(), f.esi()),
            _ => (false, false),
        };
        self.brs.append_value(brs);
        self.esi.append_value(esi);
        self.dir.push_key(match record.direction {
            Some('R') => Some(0),
            Some('T') => Some(1),
            _ => None,
        });
        self.dlc.append_value(frame.dlc().as_raw());
        self.data.append_value(if frame.is_remote() {
            &[][..]
        } else {
            frame.data()
        });
    }

    /// Rows added since the last batch.
    pub fn rows(&self) -> usize {
        self.id.len()
    }

    /// The rows added so far as one batch of `schema` ([`raw_schema`], or [`raw_schema_in`]
    /// the columns' precision); the columns start empty again.
    pub fn finish(&mut self, schema: &SchemaRef) -> std::io::Result<RecordBatch> {
        let ts = std::mem::replace(&mut self.ts, Vec::with_capacity(BATCH_ROWS));
        let columns: Vec<ArrayRef> = vec![
            time_array(ts, self.precision),
            self.channel.finish()?,
            Arc::new(self.id.finish()),
            Arc::new(self.extended.finish()),
            Arc::new(self.remote.finish()),
            Arc::new(self.error.finish()),
            Arc::new(self.fd.finish()),
            Arc::new(self.brs.finish()),
            Arc::new(self.esi.finish()),
            self.dir.finish()?,
            Arc::new(self.dlc.finish()),
            Arc::new(self.data.finish()),
        ];
        RecordBatch::try_new(schema.clone(), columns).map_err(io_error)
    }
}

/// Writes records as the raw frames' table.
pub struct ParquetWriter<W: Write + Send> {
    writer: ArrowWriter<W>,
    schema: SchemaRef,
    columns: FrameColumns,
}

impl<W: Write + Send> ParquetWriter<W> {
    /// A writer to `output` (the file's header is written at once), zstd-compressed.
    pub fn new(output: W) -> std::io::Result<Self> {
        Self::with_compression(output, ParquetCompression::default())
    }

    /// A writer to `output` whose pages are compressed with `compression`.
    pub fn with_compression(output: W, compression: ParquetCompression) -> std::io::Result<Self> {
        Self::with_options(output, compression.into())
    }

    /// A writer to `output` with its pages compressed and its times in the units `options`
    /// say.
    pub fn with_options(output: W, options: ParquetOptions) -> std::io::Result<Self> {
        let ParquetOptions { compression, times } = options;
        let schema = raw_schema_in(times);
        let writer = ArrowWriter::try_new(
            output,
            schema.clone(),
            // Times as deltas: frames follow each other by little.
            Some(properties_with_dictionaries(
                RAW_LAYOUT,
                true,
                &[],
                &["ts"],
                compression,
            )),
        )
        .map_err(io_error)?;
        Ok(ParquetWriter {
            writer,
            schema,
            columns: FrameColumns::with_precision(times),
        })
    }

    /// Write one record.
    pub fn write(&mut self, record: &LogRecord) -> std::io::Result<()> {
        self.columns.push(record);
        if self.columns.rows() >= BATCH_ROWS {
            self.flush_batch()?;
        }
        Ok(())
    }

    fn flush_batch(&mut self) -> std::io::Result<()> {
        if self.columns.rows() > 0 {
            let batch = self.columns.finish(&self.schema)?;
            self.writer.write(&batch).map_err(io_error)?;
        }
        Ok(())
    }

    /// Write the rows so far as a row group (the file still needs its footer to be read).
    pub fn flush(&mut self) -> std::io::Result<()> {
        self.flush_batch()?;
        self.writer.flush().map_err(io_error)
    }

    /// Write what is left and the footer; the output back.
    pub fn finish(mut self) -> std::io::Result<W> {
        self.flush_batch()?;
        self.writer.into_inner().map_err(io_error)
    }
}

/// Reads the raw frames' table (bywire's, or any table with its columns: `ts` may be in any
/// unit, `channel` and `dir` plain strings, and the flags left out are false).
pub struct ParquetReader {
    batches: ParquetRecordBatchReader,
    pending: VecDeque<Result<LogRecord, LogError>>,
    row: u64,
    failed: bool,
}

impl ParquetReader {
    /// A reader of `file` (its footer is read at once, so a file that is not Parquet fails
    /// here).
    pub fn open(mut file: File) -> Result<Self, LogError> {
        // The crate reserves what a footer or a page header declares: both checked against
        // their bytes first.
        footer::check(&mut file)?;
        let unreadable = |e: ::parquet::errors::ParquetError| LogError::Table {
            row: 0,
            what: format!("not a readable Parquet file: {e}"),
        };
        let mut pages = file.try_clone().map_err(|e| LogError::Binary {
            offset: 0,
            what: format!("cannot read: {e}"),
        })?;
        let builder = ParquetRecordBatchReaderBuilder::try_new(file).map_err(unreadable)?;
        let chunks = builder.metadata().row_groups().iter().flat_map(|group| {
            // Not `byte_range`: the crate asserts there that the footer's numbers are not
            // negative; they are checked where they are used instead.
            group.columns().iter().map(|chunk| {
                let start = chunk
                    .dictionary_page_offset()
                    .unwrap_or(chunk.data_page_offset());
                (start, chunk.compressed_size())
            })
        });
        footer::check_pages(&mut pages, chunks)?;
        let batches = builder
            .with_batch_size(BATCH_ROWS)
            .build()
            .map_err(unreadable)?;
        Ok(ParquetReader {
            batches,
            pending: VecDeque::new(),
            row: 0,
            failed: false,
        })
    }

    fn read_batch(&mut self, batch: &RecordBatch) -> Result<(), LogError> {
        self.pending.extend(records_of_batch(batch, self.row)?);
        self.row += batch.num_rows() as u64;
        Ok(())
    }
}

/// The records of a raw frames batch (bywire's [`raw_schema`], or any batch with its columns:
/// `ts` in any unit, `channel` and `dir` plain strings, the flags left out false), its rows
/// numbered from `first_row` in errors. A batch without the columns is an error; a row that is
/// no frame is an error in its place.
pub fn records_of_batch(
    batch: &RecordBatch,
    first_row: u64,
) -> Result<Vec<Result<LogRecord, LogError>>, LogError> {
    let columns = FrameColumnsRef::with_rows_from(batch, first_row)?;
    let mut records = Vec::with_capacity(batch.num_rows());
    for i in 0..batch.num_rows() {
        let row = first_row + i as u64;
        let at = |what: String| LogError::Table { row, what };
        let record = match (columns.ts.get(i), columns.channel.get(i)) {
            (Some(t), Some(c)) => columns.raw_row(i).frame().map(|frame| LogRecord {
                timestamp: Timestamp::from_nanos(u64::try_from(t).unwrap_or(0)),
                interface: c.to_string(),
                frame,
                direction: match columns.dir.as_ref().and_then(|d| d.get(i)) {
                    Some(d) if d.eq_ignore_ascii_case("tx") => Some('T'),
                    Some(d) if d.eq_ignore_ascii_case("rx") => Some('R'),
                    _ => None,
                },
            }),
            _ => Err("no timestamp or no channel".to_string()),
        };
        records.push(record.map_err(at));
    }
    Ok(records)
}

/// A raw frames batch's columns, found and type-checked once: what [`records_of_batch`] and
/// the columnar decoder (`bywire_data::decoded::decode_frames_batch`) read.
pub struct FrameColumnsRef<'a> {
    ts: Times<'a>,
    channel: Strings<'a>,
    id: &'a arrow_array::PrimitiveArray<UInt32Type>,
    data: &'a arrow_array::BinaryArray,
    extended: Option<&'a arrow_array::BooleanArray>,
    remote: Option<&'a arrow_array::BooleanArray>,
    error: Option<&'a arrow_array::BooleanArray>,
    fd: Option<&'a arrow_array::BooleanArray>,
    brs: Option<&'a arrow_array::BooleanArray>,
    esi: Option<&'a arrow_array::BooleanArray>,
    dir: Option<Strings<'a>>,
    dlc: Option<&'a arrow_array::PrimitiveArray<UInt8Type>>,
}

impl<'a> FrameColumnsRef<'a> {
    /// The columns of `batch` (a missing or mistyped column is an error at its first row).
    pub fn of(batch: &'a RecordBatch) -> Result<Self, LogError> {
        Self::with_rows_from(batch, 0)
    }

    /// As [`FrameColumnsRef::of`], the batch's rows numbered from `first` in errors.
    fn with_rows_from(batch: &'a RecordBatch, first: u64) -> Result<Self, LogError> {
        let fail = |what: String| LogError::Table { row: first, what };
        let column = |name: &str| {
            batch.column_by_name(name).ok_or_else(|| {
                fail(format!(
                    "no '{name}' column (a raw frames table has ts, channel, id, data and flags)"
                ))
            })
        };
        let flag = |name: &str| -> Result<Option<&'a arrow_array::BooleanArray>, LogError> {
            match batch.column_by_name(name) {
                None => Ok(None),
                // A flag set on no row is read as absent: no test per row (most logs' flags).
                Some(c) => c
                    .as_boolean_opt()
                    .map(|c| (c.true_count() > 0).then_some(c))
                    .ok_or_else(|| fail(format!("the '{name}' column is not boolean"))),
            }
        };
        Ok(FrameColumnsRef {
            ts: Times::of(column("ts")?.as_ref()).map_err(fail)?,
            channel: Strings::of(column("channel")?.as_ref(), "channel").map_err(fail)?,
            id: column("id")?
                .as_primitive_opt::<UInt32Type>()
                .ok_or_else(|| fail("the 'id' column is not uint32".into()))?,
            data: column("data")?
                .as_binary_opt::<i32>()
                .ok_or_else(|| fail("the 'data' column is not binary".into()))?,
            extended: flag("extended")?,
            remote: flag("remote")?,
            error: flag("error")?,
            fd: flag("fd")?,
            brs: flag("brs")?,
            esi: flag("esi")?,
            dir: match batch.column_by_name("dir") {
                Some(c) => Some(Strings::of(c.as_ref(), "dir").map_err(fail)?),
                None => None,
            },
            dlc: match batch.column_by_name("dlc") {
                Some(c) => Some(
                    c.as_primitive_opt::<UInt8Type>()
                        .ok_or_else(|| fail("the 'dlc' column is not uint8".into()))?,
                ),
                None => None,
            },
        })
    }

    fn set(column: Option<&arrow_array::BooleanArray>, i: usize) -> bool {
        column.is_some_and(|c| c.is_valid(i) && c.value(i))
    }

    fn raw_row(&self, i: usize) -> RawRow<'a> {
        let id = self.id;
        RawRow {
            id: id.is_valid(i).then(|| id.value(i)),
            extended: Self::set(self.extended, i),
            remote: Self::set(self.remote, i),
            error: Self::set(self.error, i),
            fd: Self::set(self.fd, i),
            brs: Self::set(self.brs, i),
            esi: Self::set(self.esi, i),
            dlc: self.dlc.and_then(|d| d.is_valid(i).then(|| d.value(i))),
            data: if self.data.is_valid(i) {
                self.data.value(i)
            } else {
                &[]
            },
        }
    }

    /// The identifier of row `i` and whether it is extended; `None` for an error frame or a
    /// row without one.
    pub fn id(&self, i: usize) -> Option<(u32, bool)> {
        if Self::set(self.error, i) || !self.id.is_valid(i) {
            return None;
        }
        Some((self.id.value(i), Self::set(self.extended, i)))
    }

    /// What decoding needs of row `i` (whose identifier [`FrameColumnsRef::id`] gave): time
    /// (ns), channel, and the data (none for a remote frame). `None` for a row without them.
    #[inline]
    pub fn row(&self, i: usize) -> Option<FrameRow<'a>> {
        let ts = self.ts.get(i)?;
        let channel = self.channel.channel(i)?;
        let data = if Self::set(self.remote, i) || !self.data.is_valid(i) {
            &[][..]
        } else {
            self.data.value(i)
        };
        Some(FrameRow { ts, channel, data })
    }
}

/// A row of a raw frames batch, as decoding reads it.
pub struct FrameRow<'a> {
    /// Time, ns since the epoch.
    pub ts: i64,
    /// Its channel.
    pub channel: ChannelRef<'a>,
    /// Its data bytes.
    pub data: &'a [u8],
}

/// A row's channel: its text, or (a dictionary-encoded column) its key in the column's values,
/// so that its text is read only when the key is new.
#[derive(Clone, Copy)]
pub enum ChannelRef<'a> {
    /// The text itself.
    Text(&'a str),
    /// A key `Strings::channel` found within `values`.
    Key(usize, &'a arrow_array::StringArray),
}

impl<'a> ChannelRef<'a> {
    /// Its text.
    pub fn text(self) -> &'a str {
        match self {
            ChannelRef::Text(text) => text,
            ChannelRef::Key(key, values) if key < values.len() => values.value(key),
            ChannelRef::Key(..) => "",
        }
    }
}

impl Iterator for ParquetReader {
    type Item = Result<LogRecord, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(record) = self.pending.pop_front() {
                return Some(record);
            }
            if self.failed {
                return None;
            }
            match next_batch(&mut self.batches) {
                None => return None,
                Some(Ok(batch)) => {
                    if let Err(e) = self.read_batch(&batch) {
                        self.failed = true;
                        return Some(Err(e));
                    }
                }
                Some(Err(what)) => {
                    self.failed = true;
                    return Some(Err(LogError::Table {
                        row: self.row,
                        what: format!("cannot read: {what}"),
                    }));
                }
            }
        }
    }
}

thread_local! {
    /// Set while parquet-rs decodes a batch for the reader ([`next_batch`]).
    static DECODING: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Whether this thread is inside the reader's parquet-rs decoding, whose panics the reader
/// takes as the file's error.
fn panic_is_caught_by_reader() -> bool {
    DECODING.with(std::cell::Cell::get)
}

/// Leave unreported the panics inside parquet-rs that the reader takes as the file's error:
/// the error that follows says what was wrong, and the panic message would only say the same
/// less clearly, on stderr, in the middle of the program's output. Every other panic goes to
/// the hook there was before. Installed once per process, however often it is called (the
/// command line and the Python module each call it as they start).
pub fn quiet_panics_taken_as_errors() {
    static INSTALL: std::sync::Once = std::sync::Once::new();
    INSTALL.call_once(|| {
        let report = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !panic_is_caught_by_reader() {
                report(info);
            }
        }));
    });
}

/// The next batch parquet-rs reads, or why it cannot.
///
/// parquet-rs 60 asserts where some malformed pages should be errors (an over-long varint in a
/// DELTA_BINARY_PACKED page's header panics in its bit reader): a file is outside input, so
/// such a panic is taken as the file's error here. The caller reads no further from `batches`
/// afterwards, since its state after the panic is not to be trusted.
fn next_batch(batches: &mut ParquetRecordBatchReader) -> Option<Result<RecordBatch, String>> {
    DECODING.with(|d| d.set(true));
    let next = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| batches.next()));
    DECODING.with(|d| d.set(false));
    match next {
        Ok(next) => next.map(|batch| batch.map_err(|e| e.to_string())),
        Err(panic) => {
            let text = panic
                .downcast_ref::<String>()
                .map(String::as_str)
                .or_else(|| panic.downcast_ref::<&str>().copied())
                .unwrap_or("the decoder failed");
            Some(Err(format!("a malformed page ({text})")))
        }
    }
}

/// One row's frame fields.
struct RawRow<'a> {
    id: Option<u32>,
    extended: bool,
    remote: bool,
    error: bool,
    fd: bool,
    brs: bool,
    esi: bool,
    dlc: Option<u8>,
    data: &'a [u8],
}

impl RawRow<'_> {
    fn frame(&self) -> Result<Frame, String> {
        let raw = self.id.ok_or("no identifier")?;
        if self.error {
            return ErrorFrame::new(raw & 0x1FFF_FFFF, self.data)
                .map(Frame::Error)
                .map_err(|e| e.to_string());
        }
        let id = if self.extended {
            Id::extended(raw)
        } else {
            Id::standard(raw)
        }
        .map_err(|e| e.to_string())?;
        if self.fd {
            return FdFrame::new(id, self.data, self.brs, self.esi)
                .map(Frame::Fd)
                .map_err(|e| e.to_string());
        }
        let length = u8::try_from(self.data.len()).unwrap_or(u8::MAX);
        let dlc = match self.dlc {
            Some(d) => Dlc::new(d).ok_or_else(|| format!("DLC {d} (at most 15)"))?,
            None if self.remote => Dlc::from_nibble(0),
            None => Dlc::from_classic_len(self.data.len())
                .ok_or_else(|| format!("{length} data bytes in a classic frame (at most 8)"))?,
        };
        if self.remote {
            return Ok(Frame::remote(id, dlc));
        }
        ClassicFrame::with_dlc(id, dlc, self.data)
            .map(Frame::Classic)
            .map_err(|e| e.to_string())
    }
}

/// A timestamp column read in nanoseconds, whatever its unit (read in place: a batch's times
/// are not copied).
struct Times<'a> {
    values: &'a [i64],
    nulls: Option<&'a arrow_buffer::NullBuffer>,
    /// Nanoseconds in the column's unit.
    scale: i64,
}

impl<'a> Times<'a> {
    fn of(column: &'a dyn Array) -> Result<Self, String> {
        use arrow_array::types::{
            TimestampMicrosecondType as Micro, TimestampMillisecondType as Milli,
            TimestampNanosecondType as Nano, TimestampSecondType as Second,
        };
        // Every unit's values are i64 nanoseconds, microseconds... since the epoch.
        fn values<T: arrow_array::ArrowPrimitiveType<Native = i64>>(
            column: &dyn Array,
        ) -> Option<&[i64]> {
            column.as_primitive_opt::<T>().map(|a| &a.values()[..])
        }
        let (values, scale) = match column.data_type() {
            DataType::Timestamp(TimeUnit::Nanosecond, _) => (values::<Nano>(column), 1),
            DataType::Timestamp(TimeUnit::Microsecond, _) => (values::<Micro>(column), 1_000),
            DataType::Timestamp(TimeUnit::Millisecond, _) => (values::<Milli>(column), 1_000_000),
            DataType::Timestamp(TimeUnit::Second, _) => (values::<Second>(column), 1_000_000_000),
            _ => (None, 0),
        };
        let values = values
            .ok_or_else(|| format!("the 'ts' column is {}, not a timestamp", column.data_type()))?;
        Ok(Times {
            values,
            nulls: column.nulls(),
            scale,
        })
    }

    /// Row `i`'s time in nanoseconds; `None` when it has none or it does not fit.
    #[inline]
    fn get(&self, i: usize) -> Option<i64> {
        if self.nulls.is_some_and(|n| n.is_null(i)) {
            return None;
        }
        self.values.get(i)?.checked_mul(self.scale)
    }
}

/// A string column: plain or dictionary-encoded.
enum Strings<'a> {
    Plain(&'a arrow_array::StringArray),
    Dictionary(arrow_array::TypedDictionaryArray<'a, Int32Type, arrow_array::StringArray>),
}

impl<'a> Strings<'a> {
    fn of(column: &'a dyn Array, name: &str) -> Result<Self, String> {
        if let Some(plain) = column.as_string_opt::<i32>() {
            return Ok(Strings::Plain(plain));
        }
        column
            .as_dictionary_opt::<Int32Type>()
            .and_then(|d| d.downcast_dict::<arrow_array::StringArray>())
            .map(Strings::Dictionary)
            .ok_or_else(|| format!("the '{name}' column is not strings"))
    }

    fn get(&self, i: usize) -> Option<&'a str> {
        match self {
            Strings::Plain(a) => a.is_valid(i).then(|| a.value(i)),
            Strings::Dictionary(d) => d.is_valid(i).then(|| d.value(i)),
        }
    }

    /// Row `i` as a [`ChannelRef`]; `None` when it has no text.
    #[inline]
    fn channel(&self, i: usize) -> Option<ChannelRef<'a>> {
        match self {
            Strings::Plain(a) => a.is_valid(i).then(|| ChannelRef::Text(a.value(i))),
            Strings::Dictionary(d) => {
                let keys = d.keys();
                let values = d.values();
                let key = keys
                    .is_valid(i)
                    .then(|| keys.values().get(i))
                    .flatten()
                    .and_then(|k| usize::try_from(*k).ok())
                    .filter(|k| *k < values.len())?;
                Some(ChannelRef::Key(key, values))
            }
        }
    }
}
