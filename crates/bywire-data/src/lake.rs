//! A data lake's files: decoded signals in long form (`ts, channel, signal, value`, see
//! [`crate::long`]), partitioned into `vehicle=/date=/message=` folders as Spark's
//! `partitionBy("vehicle", "date", "message")` lays them out, written straight from the
//! decoded tables.
//!
//! The Parquet files are encoded by bywire (its `encode` module): a long file's `channel` and
//! `signal` are a few texts whose keys are known (profiled, parquet-rs finding them again
//! was a third of writing these files, and pyarrow's writer is no faster). The files are what
//! Spark's writer makes of the same rows (format version 1, dictionary pages for the texts,
//! plain times and values, one data page a column a row group) and are read by Spark,
//! pyarrow, parquet-rs and polars (the tests read them back with parquet-rs; the Python tests
//! with Spark and pyarrow).
//!
//! [`LakeFiles`] holds a task's files, one a folder as Spark's writer makes them: each
//! folder's rows are held until there are a row group's worth (and all folders hold at most
//! 8 row groups' worth: then the fullest write theirs), each file is written under a hidden
//! name until it is whole, and at most a given number hold a descriptor (past that, the least
//! recently written file's is closed, and the file is opened again to append its next row
//! group: a DBC of hundreds of messages over many days neither runs a task out of descriptors
//! nor splits a folder into many small files).

use std::collections::HashMap;
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

use arrow_array::{Array, RecordBatch};
use bywire_dbc::decoder::Decoder;

pub use crate::encode::LakeCompression;
use crate::encode::{
    dictionary_keys, float_range, int_range, levels, plain_texts, texts_range, too_big, Chunk,
    Column, FileLayout, Logical, Pages, Physical, Range, TimeUnit, PLAIN, PLAIN_DICTIONARY,
};
use crate::long::Wide;
use bywire_log::batches::FrameBatches;
use bywire_log::calendar;

/// Rows a folder holds back before writing them as a row group (and all of a task's folders
/// hold at most 8 times as many: then every folder writes what it holds).
pub const LAKE_GROUP_ROWS: usize = 1 << 17;
/// Rows a row group may hold (a page holds a column's row group: 8 bytes a row at most).
const MAX_GROUP_ROWS: usize = 1 << 20;
/// Spark's name for a partition whose value is null (or empty).
pub const NULL_PARTITION: &str = "__HIVE_DEFAULT_PARTITION__";
const NANOS_PER_DAY: i64 = 86_400_000_000_000;
/// A row whose channel is null.
const NULL_KEY: u32 = u32::MAX;

/// `column=value` as Spark names a partition's folder: a null or empty value is
/// [`NULL_PARTITION`], and the characters Spark escapes are `%XX`.
pub fn partition_folder(column: &str, value: Option<&str>) -> String {
    let Some(value) = value.filter(|v| !v.is_empty()) else {
        return format!("{column}={NULL_PARTITION}");
    };
    let mut folder = format!("{column}=");
    for c in value.chars() {
        let escaped = matches!(
            c,
            '"' | '#'
                | '%'
                | '\''
                | '*'
                | '/'
                | ':'
                | '='
                | '?'
                | '\\'
                | '\x7f'
                | '{'
                | '['
                | ']'
                | '^'
        ) || ('\x01'..'\x20').contains(&c);
        if escaped {
            folder.push_str(&format!("%{:02X}", u32::from(c)));
        } else {
            folder.push(c);
        }
    }
    folder
}

/// Long rows as keys: into the task's channels and the folder's signals.
#[derive(Default)]
struct LongColumns {
    ts: Vec<i64>,
    channels: Vec<u32>,
    signals: Vec<u32>,
    values: Vec<f64>,
}

impl LongColumns {
    fn len(&self) -> usize {
        self.ts.len()
    }
}

/// The long files' columns (all optional, as Spark writes them).
fn long_columns() -> [Column; 4] {
    let column = |name: &str, physical, logical| Column {
        name: name.to_string(),
        physical,
        logical,
        optional: true,
    };
    [
        column(
            "ts",
            Physical::Int64,
            Logical::Timestamp {
                unit: TimeUnit::Micros,
                utc: true,
            },
        ),
        column("channel", Physical::ByteArray, Logical::String),
        column("signal", Physical::ByteArray, Logical::String),
        column("value", Physical::Double, Logical::None),
    ]
}

/// What a task's files share while they are written: the compressor, the page and the
/// column chunks being built (a compressor a file would cost each folder its own context).
pub struct LongEncoder {
    pages: Pages,
    chunks: [Chunk; 4],
}

impl LongEncoder {
    /// Pages compressed with `compression`.
    pub fn new(compression: LakeCompression) -> io::Result<Self> {
        Ok(LongEncoder {
            pages: Pages::new(compression)?,
            chunks: Default::default(),
        })
    }

    /// A plain page of 8-byte values as `chunk`'s.
    fn plain_chunk(
        &mut self,
        chunk: usize,
        rows: usize,
        values: impl Iterator<Item = [u8; 8]>,
        range: Option<Range>,
    ) -> io::Result<()> {
        let Some(chunk) = self.chunks.get_mut(chunk) else {
            return Ok(());
        };
        let body = &mut self.pages.body;
        body.clear();
        levels(None, rows, body);
        for value in values {
            body.extend_from_slice(&value);
        }
        chunk.statistics.add(0, range);
        self.pages.data_page(chunk, rows, PLAIN)
    }

    /// `texts` as `chunk`'s dictionary page, `keys` (null: [`NULL_KEY`]) as its data page;
    /// the range of the texts used.
    fn dictionary_chunk(&mut self, chunk: usize, keys: &[u32], texts: &[String]) -> io::Result<()> {
        let Some(chunk) = self.chunks.get_mut(chunk) else {
            return Ok(());
        };
        let body = &mut self.pages.body;
        body.clear();
        plain_texts(texts.iter().map(String::as_bytes), body)?;
        self.pages.dictionary_page(chunk, texts.len())?;
        let mut used = vec![false; texts.len()];
        let mut nulls = 0usize;
        for &key in keys {
            match used.get_mut(key as usize) {
                Some(seen) => *seen = true,
                None => nulls += 1,
            }
        }
        let body = &mut self.pages.body;
        body.clear();
        if nulls == 0 {
            levels(None, keys.len(), body);
            dictionary_keys(keys, texts.len(), body);
        } else {
            let present: Vec<u32> = keys.iter().map(|&k| u32::from(k != NULL_KEY)).collect();
            levels(Some(&present), keys.len(), body);
            let present: Vec<u32> = keys.iter().copied().filter(|&k| k != NULL_KEY).collect();
            dictionary_keys(&present, texts.len(), body);
        }
        let range = texts_range(texts.iter().map(String::as_bytes), &used);
        chunk.statistics.add(nulls, range);
        self.pages.data_page(chunk, keys.len(), PLAIN_DICTIONARY)
    }
}

/// A Parquet file of long rows (`ts, channel, signal, value`) being written, a row group at a
/// time. The file itself is the caller's, given to each call, so that it can be closed
/// between row groups and opened again to append.
pub struct LongFile {
    layout: FileLayout,
}

impl LongFile {
    /// A file starting on `out` (its first bytes).
    pub fn start(out: &mut impl Write) -> io::Result<Self> {
        Ok(LongFile {
            layout: FileLayout::start(out)?,
        })
    }

    /// Write `rows` as a row group: their channels' keys index `channels`, their signals'
    /// `signals`.
    fn row_group(
        &mut self,
        encoder: &mut LongEncoder,
        out: &mut impl Write,
        rows: &LongColumns,
        channels: &[String],
        signals: &[String],
    ) -> io::Result<()> {
        let count = rows.len();
        if count == 0 {
            return Ok(());
        }
        if count > MAX_GROUP_ROWS {
            return Err(too_big("a row group"));
        }
        let ts = rows.ts.iter().map(|t| t.to_le_bytes());
        encoder.plain_chunk(0, count, ts, int_range(rows.ts.iter().copied()))?;
        encoder.dictionary_chunk(1, &rows.channels, channels)?;
        encoder.dictionary_chunk(2, &rows.signals, signals)?;
        let values = rows.values.iter().map(|v| v.to_le_bytes());
        encoder.plain_chunk(3, count, values, float_range(rows.values.iter().copied()))?;
        self.layout.row_group(out, count, &mut encoder.chunks)
    }

    /// Write the footer on `out` (flushed): the file is whole.
    pub fn finish(self, encoder: &LongEncoder, out: &mut impl Write) -> io::Result<()> {
        self.layout
            .finish(&long_columns(), encoder.pages.compression(), &[], out)
    }
}

/// A part to write: a log (or a byte range of a candump log) and the vehicle and day its
/// path gives (no day: each row's UTC day).
#[derive(Debug, Clone)]
pub struct LakePart {
    /// The log.
    pub path: PathBuf,
    /// Only the lines starting in `[start, end)` (a split candump log).
    pub byte_range: Option<(u64, u64)>,
    /// The vehicle (null partition when none).
    pub vehicle: Option<String>,
    /// The day; none: each row's UTC day.
    pub date: Option<String>,
}

/// A folder's file being written, and its descriptor while it holds one.
struct FolderFile {
    long: LongFile,
    handle: Option<BufWriter<File>>,
    hidden: PathBuf,
    name: String,
    rows: u64,
}

/// One `vehicle=/date=/message=` folder's rows.
struct Folder {
    path: String,
    signals: Vec<String>,
    held: LongColumns,
    file: Option<FolderFile>,
    /// When it was last written (the least recent descriptor is the one closed).
    written_at: u64,
}

/// A task's files in a lake's staging folder (see the module's documentation).
pub struct LakeFiles {
    staging: PathBuf,
    prefix: String,
    encoder: LongEncoder,
    open_files: usize,
    group_rows: usize,
    channels: Vec<String>,
    channel_keys: HashMap<String, u32>,
    folders: Vec<Folder>,
    folder_of: HashMap<String, usize>,
    held: usize,
    open: usize,
    clock: u64,
    written: Vec<(String, u64)>,
}

impl LakeFiles {
    /// Files named `PREFIX.c000.CODEC.parquet` (Spark's names) under `staging`'s partition
    /// folders, one a folder, rows written a row group of `group_rows` at a time; at most
    /// `open_files` descriptors held (past that, the least recently written file's is closed,
    /// and the file opened again to append its next row group).
    pub fn new(
        staging: &Path,
        prefix: &str,
        compression: LakeCompression,
        open_files: usize,
        group_rows: usize,
    ) -> io::Result<Self> {
        Ok(LakeFiles {
            staging: staging.to_path_buf(),
            prefix: prefix.to_string(),
            encoder: LongEncoder::new(compression)?,
            open_files: open_files.max(1),
            group_rows: group_rows.clamp(1, MAX_GROUP_ROWS),
            channels: Vec::new(),
            channel_keys: HashMap::new(),
            folders: Vec::new(),
            folder_of: HashMap::new(),
            held: 0,
            open: 0,
            clock: 0,
            written: Vec::new(),
        })
    }

    fn folder(&mut self, vehicle: Option<&str>, date: Option<&str>, message: &str) -> usize {
        let path = format!(
            "{}/{}/{}",
            partition_folder("vehicle", vehicle),
            partition_folder("date", date),
            partition_folder("message", Some(message))
        );
        if let Some(&index) = self.folder_of.get(&path) {
            return index;
        }
        self.folder_of.insert(path.clone(), self.folders.len());
        self.folders.push(Folder {
            path,
            signals: Vec::new(),
            held: LongColumns::default(),
            file: None,
            written_at: 0,
        });
        self.folders.len() - 1
    }

    /// The task's key of a channel's text.
    fn channel_key(&mut self, text: &str) -> u32 {
        if let Some(&key) = self.channel_keys.get(text) {
            return key;
        }
        let key = u32::try_from(self.channels.len()).unwrap_or(NULL_KEY - 1);
        self.channels.push(text.to_string());
        self.channel_keys.insert(text.to_string(), key);
        key
    }

    /// Add a decoded table of `message` (what [`crate::decoded::decode_frames_batch`]
    /// gives) to the folders of `vehicle` and `date` (none: each row's UTC day).
    pub fn add(
        &mut self,
        vehicle: Option<&str>,
        date: Option<&str>,
        message: &str,
        table: &RecordBatch,
    ) -> io::Result<()> {
        let mut wide = Wide::of(table)
            .map_err(|e| io::Error::new(io::ErrorKind::InvalidData, format!("{message}: {e}")))?;
        let names: Vec<&str> = wide.values.iter().map(|(name, _)| *name).collect();
        // The table's channel keys and signal indexes as the task's and the folder's keys.
        let mut channel_keys: Vec<Option<u32>> = Vec::new();
        let mut current: Option<(i64, usize, Vec<u32>)> = None;
        let mut touched: Vec<usize> = Vec::new();
        for row in 0..wide.ts.len() {
            if wide.ts.is_null(row) {
                continue;
            }
            let nanos = wide.ts.value(row);
            let day = if date.is_some() {
                0
            } else {
                nanos.div_euclid(NANOS_PER_DAY)
            };
            if current.as_ref().is_none_or(|(d, ..)| *d != day) {
                let day_text = match date {
                    Some(date) => date.to_string(),
                    None => {
                        let (year, month, of_month) = calendar::civil_from_days(day);
                        format!("{year:04}-{month:02}-{of_month:02}")
                    }
                };
                let index = self.folder(vehicle, Some(&day_text), message);
                let folder = self
                    .folders
                    .get_mut(index)
                    .ok_or_else(|| io::Error::other("folder"))?;
                let keys = names
                    .iter()
                    .map(|name| signal_key(&mut folder.signals, name))
                    .collect();
                if !touched.contains(&index) {
                    touched.push(index);
                }
                current = Some((day, index, keys));
            }
            let channel = match wide.channel.key(row).and_then(|k| usize::try_from(k).ok()) {
                None => NULL_KEY,
                Some(key) => {
                    if channel_keys.len() <= key {
                        channel_keys.resize(key + 1, None);
                    }
                    match channel_keys.get(key).copied().flatten() {
                        Some(ours) => ours,
                        None => {
                            let text = wide.channel.texts.get(key).copied().unwrap_or_default();
                            let ours = self.channel_key(text);
                            if let Some(slot) = channel_keys.get_mut(key) {
                                *slot = Some(ours);
                            }
                            ours
                        }
                    }
                }
            };
            let Some((_, index, keys)) = &current else {
                continue;
            };
            let Some(folder) = self.folders.get_mut(*index) else {
                continue;
            };
            let micros = nanos.div_euclid(1000);
            let held = &mut folder.held;
            let before = held.len();
            for ((_, column), &key) in wide.values.iter().zip(keys) {
                if let Some(value) = column.value(row) {
                    held.ts.push(micros);
                    held.channels.push(channel);
                    held.signals.push(key);
                    held.values.push(value);
                }
            }
            self.held += held.len() - before;
        }
        for index in touched {
            let full = self
                .folders
                .get(index)
                .is_some_and(|f| f.held.len() >= self.group_rows);
            if full {
                self.write(index)?;
            }
        }
        if self.held >= 8 * self.group_rows {
            // The folders holding most first, until half the bound is held: the others'
            // row groups grow meanwhile.
            let mut by_size: Vec<usize> = (0..self.folders.len()).collect();
            by_size.sort_by_key(|&i| {
                std::cmp::Reverse(self.folders.get(i).map_or(0, |f| f.held.len()))
            });
            for index in by_size {
                if self.held <= 4 * self.group_rows {
                    break;
                }
                self.write(index)?;
            }
        }
        Ok(())
    }

    /// `index`'s file with a descriptor: made, or opened again to append (another file's
    /// descriptor closed first when `open_files` are held).
    fn handle(&mut self, index: usize) -> io::Result<()> {
        let held = self
            .folders
            .get(index)
            .and_then(|f| f.file.as_ref())
            .map(|f| f.handle.is_some());
        if held == Some(true) {
            return Ok(());
        }
        while self.open >= self.open_files {
            let oldest = self
                .folders
                .iter()
                .enumerate()
                .filter(|(_, f)| f.file.as_ref().is_some_and(|f| f.handle.is_some()))
                .min_by_key(|(_, f)| f.written_at)
                .map(|(i, _)| i);
            let Some(handle) = oldest
                .and_then(|i| self.folders.get_mut(i))
                .and_then(|f| f.file.as_mut())
                .and_then(|f| f.handle.take())
            else {
                break;
            };
            self.open -= 1;
            handle
                .into_inner()
                .map_err(io::IntoInnerError::into_error)?;
        }
        let Some(folder) = self.folders.get_mut(index) else {
            return Ok(());
        };
        match folder.file.as_mut() {
            Some(file) => {
                let reopened = std::fs::OpenOptions::new()
                    .append(true)
                    .open(&file.hidden)?;
                file.handle = Some(BufWriter::new(reopened));
            }
            None => {
                let name = format!(
                    "{}.c000{}.parquet",
                    self.prefix,
                    self.encoder.pages.compression().extension()
                );
                let directory = self.staging.join(&folder.path);
                std::fs::create_dir_all(&directory)?;
                let hidden = directory.join(format!(".{name}.{}.inprogress", std::process::id()));
                let mut handle = BufWriter::new(File::create(&hidden)?);
                let long = LongFile::start(&mut handle)?;
                folder.file = Some(FolderFile {
                    long,
                    handle: Some(handle),
                    hidden,
                    name: format!("{}/{name}", folder.path),
                    rows: 0,
                });
            }
        }
        self.open += 1;
        Ok(())
    }

    /// Write what `index`'s folder holds as a row group of its file.
    fn write(&mut self, index: usize) -> io::Result<()> {
        if self.folders.get(index).is_none_or(|f| f.held.len() == 0) {
            return Ok(());
        }
        self.handle(index)?;
        self.clock += 1;
        let Some(folder) = self.folders.get_mut(index) else {
            return Ok(());
        };
        folder.written_at = self.clock;
        let held = std::mem::take(&mut folder.held);
        self.held = self.held.saturating_sub(held.len());
        let Some(file) = folder.file.as_mut() else {
            return Ok(());
        };
        let Some(handle) = file.handle.as_mut() else {
            return Ok(());
        };
        file.long.row_group(
            &mut self.encoder,
            handle,
            &held,
            &self.channels,
            &folder.signals,
        )?;
        file.rows += held.len() as u64;
        Ok(())
    }

    /// Finish `index`'s file: its footer, then its own name.
    fn finish_file(&mut self, index: usize) -> io::Result<()> {
        if self.folders.get(index).is_none_or(|f| f.file.is_none()) {
            return Ok(());
        }
        self.handle(index)?;
        let Some(file) = self.folders.get_mut(index).and_then(|f| f.file.take()) else {
            return Ok(());
        };
        let FolderFile {
            long,
            handle,
            hidden,
            name,
            rows,
        } = file;
        self.open = self.open.saturating_sub(1);
        let done = match handle {
            Some(mut handle) => long.finish(&self.encoder, &mut handle),
            None => Err(io::Error::other("a lake file without a descriptor")),
        };
        if let Err(e) = done {
            let _ = std::fs::remove_file(&hidden);
            return Err(e);
        }
        // Not synced: as Spark's writers, the job's commit is the renames.
        std::fs::rename(&hidden, self.staging.join(&name))?;
        self.written.push((name, rows));
        Ok(())
    }

    /// Write what is held and finish every file: `(file, rows)` for each file made, the files
    /// relative to the staging folder.
    pub fn finish(mut self) -> io::Result<Vec<(String, u64)>> {
        for index in 0..self.folders.len() {
            self.write(index)?;
            self.finish_file(index)?;
        }
        Ok(std::mem::take(&mut self.written))
    }
}

impl Drop for LakeFiles {
    /// Files not finished (an error, or a panic elsewhere) are removed: no file that looks
    /// whole is left.
    fn drop(&mut self) {
        for folder in &mut self.folders {
            if let Some(file) = folder.file.take() {
                drop(file.handle);
                let _ = std::fs::remove_file(&file.hidden);
            }
        }
    }
}

/// A signal's key in a folder's signals (added when new).
fn signal_key(signals: &mut Vec<String>, name: &str) -> u32 {
    let at = signals.iter().position(|s| s == name).unwrap_or_else(|| {
        signals.push(name.to_string());
        signals.len() - 1
    });
    u32::try_from(at).unwrap_or(NULL_KEY - 1)
}

/// Decode `parts` with `decoder` into `files` (a task's work), reading `batch_rows` frames at
/// a time. An error names the part's file.
pub fn write_parts(
    decoder: &Decoder,
    parts: &[LakePart],
    files: &mut LakeFiles,
    batch_rows: usize,
) -> io::Result<()> {
    for part in parts {
        let named =
            |e: io::Error| io::Error::new(e.kind(), format!("{}: {e}", part.path.display()));
        let (_, batches) =
            FrameBatches::open(&part.path, part.byte_range, batch_rows).map_err(named)?;
        for batch in batches {
            let batch = batch.map_err(named)?;
            let (tables, _) = crate::decoded::decode_frames_batch(decoder, &batch)
                .map_err(|e| named(io::Error::new(io::ErrorKind::InvalidData, e.to_string())))?;
            for (message, table) in &tables {
                files.add(
                    part.vehicle.as_deref(),
                    part.date.as_deref(),
                    message,
                    table,
                )?;
            }
        }
    }
    Ok(())
}

#[cfg(test)]
#[allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::panic,
    clippy::cast_precision_loss,
    clippy::cast_possible_truncation,
    clippy::cast_possible_wrap
)]
mod tests {
    use super::*;
    use ::parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
    use ::parquet::file::reader::{FileReader, SerializedFileReader};
    use ::parquet::file::statistics::Statistics;
    use arrow_array::cast::AsArray;
    use arrow_array::types::{Float64Type, Int32Type, TimestampMicrosecondType};
    use arrow_array::{DictionaryArray, Float64Array, TimestampNanosecondArray};
    use arrow_schema::{DataType, Field, Schema, TimeUnit};
    use std::sync::Arc;

    /// An empty folder for one test, removed with it.
    fn fresh_dir(name: &str) -> tempfile::TempDir {
        tempfile::Builder::new()
            .prefix(&format!("bywire-lake-{name}-"))
            .tempdir()
            .unwrap()
    }

    /// Every row of a Parquet file, as parquet-rs reads it: (µs, channel, signal, value).
    type Row = (i64, Option<String>, Option<String>, Option<f64>);

    fn read_rows(path: &Path) -> Vec<Row> {
        let reader = ParquetRecordBatchReaderBuilder::try_new(File::open(path).unwrap())
            .unwrap()
            .build()
            .unwrap();
        let mut rows = Vec::new();
        for batch in reader {
            let batch = batch.unwrap();
            let schema = batch.schema();
            assert_eq!(
                schema.field(0).data_type(),
                &DataType::Timestamp(TimeUnit::Microsecond, Some("UTC".into()))
            );
            assert_eq!(schema.field(1).data_type(), &DataType::Utf8);
            assert_eq!(schema.field(2).data_type(), &DataType::Utf8);
            assert_eq!(schema.field(3).data_type(), &DataType::Float64);
            let ts = batch.column(0).as_primitive::<TimestampMicrosecondType>();
            let channel = batch.column(1).as_string::<i32>();
            let signal = batch.column(2).as_string::<i32>();
            let value = batch.column(3).as_primitive::<Float64Type>();
            for row in 0..batch.num_rows() {
                rows.push((
                    ts.value(row),
                    channel
                        .is_valid(row)
                        .then(|| channel.value(row).to_string()),
                    signal.is_valid(row).then(|| signal.value(row).to_string()),
                    value.is_valid(row).then(|| value.value(row)),
                ));
            }
        }
        rows
    }

    /// Rows with keys of many shapes: runs (longer and shorter than 8), cycles, null
    /// channels, so that every branch of the hybrid encoding is read back.
    fn columns(rows: usize, channels: usize, signals: usize, seed: u64) -> LongColumns {
        let mut next = crate::test_support::xorshift(seed);
        let mut out = LongColumns::default();
        let mut channel = 0u32;
        for row in 0..rows {
            if next().is_multiple_of(16) {
                channel = (next() % (channels as u64 + 1)) as u32;
            }
            let signal = if (row / 100) % 2 == 0 {
                row % signals
            } else {
                (next() % signals as u64) as usize
            };
            out.ts
                .push(1_764_633_600_000_000 + (row as i64) * 10 - 5_000);
            out.channels.push(if channel as usize == channels {
                NULL_KEY
            } else {
                channel
            });
            out.signals.push(u32::try_from(signal).unwrap());
            out.values.push((next() % 1000) as f64 / 8.0 - 60.0);
        }
        out
    }

    fn texts(prefix: &str, n: usize) -> Vec<String> {
        (0..n).map(|i| format!("{prefix}{i}")).collect()
    }

    fn expected(columns: &LongColumns, channels: &[String], signals: &[String]) -> Vec<Row> {
        (0..columns.len())
            .map(|i| {
                (
                    columns.ts[i],
                    channels.get(columns.channels[i] as usize).cloned(),
                    Some(signals[columns.signals[i] as usize].clone()),
                    Some(columns.values[i]),
                )
            })
            .collect()
    }

    #[test]
    fn parquet_rs_reads_every_row_of_every_compression() {
        let scratch = fresh_dir("compressions");
        let dir = scratch.path();
        for compression in [
            LakeCompression::Snappy,
            LakeCompression::Zstd,
            LakeCompression::Gzip,
            LakeCompression::Uncompressed,
        ] {
            let path = dir.join(format!("{compression:?}.parquet"));
            let mut encoder = LongEncoder::new(compression).unwrap();
            let mut out = File::create(&path).unwrap();
            let mut file = LongFile::start(&mut out).unwrap();
            let mut all = Vec::new();
            // Dictionaries of 1, 2, 3, 17 and 300 texts: key widths 1 to 9 bits.
            for (group, (channels, signals)) in
                [(1, 1), (2, 2), (3, 17), (2, 300)].into_iter().enumerate()
            {
                let rows = columns(1000 + group * 777, channels, signals, group as u64 + 7);
                let (channels, signals) = (texts("can", channels), texts("Signal", signals));
                file.row_group(&mut encoder, &mut out, &rows, &channels, &signals)
                    .unwrap();
                all.extend(expected(&rows, &channels, &signals));
            }
            file.finish(&encoder, &mut out).unwrap();
            assert_eq!(read_rows(&path), all, "{compression:?}");
            let reader = SerializedFileReader::new(File::open(&path).unwrap()).unwrap();
            let meta = reader.metadata();
            assert_eq!(meta.num_row_groups(), 4);
            let column = meta.row_group(0).column(0);
            assert_eq!(column.compression(), compression.codec_name());
        }
    }

    impl LakeCompression {
        fn codec_name(self) -> ::parquet::basic::Compression {
            use ::parquet::basic::{Compression, GzipLevel, ZstdLevel};
            match self {
                Self::Snappy => Compression::SNAPPY,
                Self::Zstd => Compression::ZSTD(ZstdLevel::default()),
                Self::Gzip => Compression::GZIP(GzipLevel::default()),
                Self::Uncompressed => Compression::UNCOMPRESSED,
            }
        }
    }

    #[test]
    fn statistics_give_the_times_and_texts_present_and_the_nulls() {
        let scratch = fresh_dir("statistics");
        let dir = scratch.path();
        let path = dir.join("s.parquet");
        let mut rows = LongColumns::default();
        for (ts, channel, signal) in [(30, 1, 0), (-5, NULL_KEY, 2), (12, 1, 2)] {
            rows.ts.push(ts);
            rows.channels.push(channel);
            rows.signals.push(signal);
            rows.values.push(1.0);
        }
        let mut encoder = LongEncoder::new(LakeCompression::Snappy).unwrap();
        let mut out = File::create(&path).unwrap();
        let mut file = LongFile::start(&mut out).unwrap();
        let channels = texts("can", 3);
        let signals = ["b".into(), "z".into(), "a".into()];
        file.row_group(&mut encoder, &mut out, &rows, &channels, &signals)
            .unwrap();
        file.finish(&encoder, &mut out).unwrap();
        let reader = SerializedFileReader::new(File::open(&path).unwrap()).unwrap();
        let group = reader.metadata().row_group(0);
        match group.column(0).statistics().unwrap() {
            Statistics::Int64(s) => {
                assert_eq!((s.min_opt(), s.max_opt()), (Some(&-5), Some(&30)));
                assert_eq!(s.null_count_opt(), Some(0));
            }
            other => panic!("{other:?}"),
        }
        let texts_of = |column: usize| match group.column(column).statistics().unwrap() {
            Statistics::ByteArray(s) => (
                s.min_opt().unwrap().as_utf8().unwrap().to_string(),
                s.max_opt().unwrap().as_utf8().unwrap().to_string(),
                s.null_count_opt(),
            ),
            other => panic!("{other:?}"),
        };
        // Only the texts used: can1 (not can0 nor can2), a and... a (not b nor z).
        assert_eq!(texts_of(1), ("can1".into(), "can1".into(), Some(1)));
        assert_eq!(texts_of(2), ("a".into(), "b".into(), Some(0)));
    }

    #[test]
    fn folders_are_escaped_as_spark_names_them() {
        assert_eq!(
            partition_folder("vehicle", None),
            "vehicle=__HIVE_DEFAULT_PARTITION__"
        );
        assert_eq!(
            partition_folder("vehicle", Some("")),
            "vehicle=__HIVE_DEFAULT_PARTITION__"
        );
        assert_eq!(
            partition_folder("message", Some("a/b=c d%")),
            "message=a%2Fb%3Dc d%25"
        );
        assert_eq!(partition_folder("m", Some("\u{1}\u{7f}é")), "m=%01%7Fé");
    }

    /// A decoded table of two signals (one multiplexed) over the times given (ns).
    fn decoded(times: &[i64], channels: &[&str]) -> RecordBatch {
        let ts = TimestampNanosecondArray::from(times.to_vec()).with_timezone("UTC");
        let channel: DictionaryArray<Int32Type> = channels.iter().copied().collect();
        let speed = Float64Array::from_iter_values((0..times.len()).map(|i| i as f64));
        let gear =
            Float64Array::from_iter((0..times.len()).map(|i| (i % 2 == 0).then_some(-(i as f64))));
        let schema = Schema::new(vec![
            Field::new("ts", ts.data_type().clone(), false),
            Field::new("channel", channel.data_type().clone(), false),
            Field::new("Speed", DataType::Float64, true),
            Field::new("Gear", DataType::Float64, true),
        ]);
        RecordBatch::try_new(
            Arc::new(schema),
            vec![
                Arc::new(ts),
                Arc::new(channel),
                Arc::new(speed),
                Arc::new(gear),
            ],
        )
        .unwrap()
    }

    fn lake_files(root: &Path) -> Vec<String> {
        let mut found = Vec::new();
        let mut stack = vec![root.to_path_buf()];
        while let Some(dir) = stack.pop() {
            for entry in std::fs::read_dir(&dir).unwrap() {
                let path = entry.unwrap().path();
                if path.is_dir() {
                    stack.push(path);
                } else {
                    found.push(path.strip_prefix(root).unwrap().display().to_string());
                }
            }
        }
        found.sort();
        found
    }

    #[test]
    fn rows_go_to_their_day_folders_and_files_are_opened_again_to_append() {
        let scratch = fresh_dir("days");
        let staging = scratch.path();
        let day = NANOS_PER_DAY;
        let start = 20_000 * day; // 2024-10-04
        let times = [start - 1, start, start + 1_500, start + day];
        // At most one descriptor: the folders take turns, each file closed and opened again
        // to append its next row group.
        let mut files =
            LakeFiles::new(staging, "part-00003-job", LakeCompression::Snappy, 1, 2).unwrap();
        let table = decoded(&times, &["can0", "can1", "can0", "can0"]);
        files.add(Some("tug 1"), None, "Drive", &table).unwrap();
        files
            .add(
                Some("tug 1"),
                None,
                "Drive",
                &decoded(&[start - 2], &["can1"]),
            )
            .unwrap();
        let mut written = files.finish().unwrap();
        written.sort();
        let folder = |d: &str| format!("vehicle=tug 1/date={d}/message=Drive");
        let names: Vec<_> = written.iter().map(|(f, _)| f.clone()).collect();
        assert_eq!(names, lake_files(staging), "no hidden file left");
        let by_folder = |d: &str| -> Vec<&(String, u64)> {
            written
                .iter()
                .filter(|(f, _)| f.starts_with(&folder(d)))
                .collect()
        };
        assert_eq!(written.len(), 3, "a file a folder: {written:?}");
        let first_day = format!(
            "{}/part-00003-job.c000.snappy.parquet",
            folder("2024-10-03")
        );
        assert_eq!(by_folder("2024-10-03")[0].0, first_day);
        let reader = SerializedFileReader::new(File::open(staging.join(&first_day)).unwrap());
        assert_eq!(reader.unwrap().metadata().num_row_groups(), 2);
        let rows_of = |d: &str| -> Vec<Row> {
            by_folder(d)
                .iter()
                .flat_map(|(f, _)| read_rows(&staging.join(f)))
                .collect()
        };
        let row = |ts: i64, channel: &str, signal: &str, value: f64| {
            (
                ts.div_euclid(1000),
                Some(channel.to_string()),
                Some(signal.to_string()),
                Some(value),
            )
        };
        assert_eq!(
            rows_of("2024-10-03"),
            [
                row(start - 1, "can0", "Speed", 0.0),
                row(start - 1, "can0", "Gear", 0.0),
                row(start - 2, "can1", "Speed", 0.0),
                row(start - 2, "can1", "Gear", 0.0)
            ]
        );
        assert_eq!(
            rows_of("2024-10-04"),
            [
                row(start, "can1", "Speed", 1.0),
                row(start + 1_500, "can0", "Speed", 2.0),
                row(start + 1_500, "can0", "Gear", -2.0)
            ]
        );
        assert_eq!(
            rows_of("2024-10-05"),
            [row(start + day, "can0", "Speed", 3.0)]
        );
        let total: u64 = written.iter().map(|(_, rows)| rows).sum();
        assert_eq!(total, 8);
    }

    #[test]
    fn a_given_date_is_every_row_s_and_an_unfinished_task_leaves_nothing() {
        let scratch = fresh_dir("given");
        let staging = scratch.path();
        let mut files = LakeFiles::new(staging, "p", LakeCompression::Zstd, 8, 1).unwrap();
        let day = NANOS_PER_DAY;
        files
            .add(
                None,
                Some("2026-12-04"),
                "M",
                &decoded(&[0, 3 * day], &["a", "b"]),
            )
            .unwrap();
        let written = files.finish().unwrap();
        assert_eq!(
            written,
            [(
                "vehicle=__HIVE_DEFAULT_PARTITION__/date=2026-12-04/message=M/p.c000.zstd.parquet"
                    .to_string(),
                3
            )]
        );

        let scratch = fresh_dir("dropped");

        let staging = scratch.path();
        let mut files = LakeFiles::new(staging, "p", LakeCompression::Snappy, 8, 1).unwrap();
        files
            .add(None, None, "M", &decoded(&[0, 1], &["a", "b"]))
            .unwrap();
        assert_eq!(lake_files(staging).len(), 1, "a file being written");
        drop(files);
        assert!(lake_files(staging).is_empty());
    }
}
