//! A numeric table as Parquet: a time column, the run, an episode and its split, and named `f64`
//! columns with their units in the schema's field metadata (`unit`) — what a training dataset
//! is (`bywire dataset`). `NaN` is written as null, so pandas and polars see a missing value.
//! Rows are buffered a row group at a time; the file is written beside its place and renamed
//! into it on [`TableWriter::finish`], so a reader never finds half a table.

use std::collections::HashMap;
use std::fs::File;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use ::parquet::arrow::ArrowWriter;
use arrow_array::{ArrayRef, Float64Array, RecordBatch, StringArray, UInt32Array};
use arrow_schema::{DataType, Field, Schema, SchemaRef};

use bywire_log::parquet::{io_error as parquet_error, properties, ParquetCompression};

/// One value column: its name and unit.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TableColumn {
    /// The column's name.
    pub name: String,
    /// Its unit (empty: none).
    pub unit: String,
}

/// A table being written.
pub struct TableWriter {
    writer: ArrowWriter<File>,
    schema: SchemaRef,
    tmp: PathBuf,
    path: PathBuf,
    time: Vec<f64>,
    timestamp: Vec<f64>,
    run: Vec<Option<String>>,
    episode: Vec<Option<u32>>,
    split: Vec<Option<&'static str>>,
    values: Vec<Vec<f64>>,
    rows: u64,
}

/// Rows a row group holds: written (and their memory freed) a group at a time.
const GROUP_ROWS: usize = 65_536;

/// The layout name written in the file's metadata.
pub const TABLE_LAYOUT: &str = "bywire-dataset-1";

impl TableWriter {
    /// A table at `path` with `columns` after `t_s`, `timestamp_s`, `run`, `episode` and
    /// `split`.
    pub fn create(path: &Path, columns: &[TableColumn]) -> io::Result<TableWriter> {
        let mut fields = vec![
            Field::new("t_s", DataType::Float64, false),
            Field::new("timestamp_s", DataType::Float64, false),
            Field::new("run", DataType::Utf8, true),
            Field::new("episode", DataType::UInt32, true),
            Field::new("split", DataType::Utf8, true),
        ];
        for c in columns {
            let mut field = Field::new(&c.name, DataType::Float64, true);
            if !c.unit.is_empty() {
                field = field.with_metadata(HashMap::from([("unit".to_string(), c.unit.clone())]));
            }
            fields.push(field);
        }
        let schema: SchemaRef = Arc::new(Schema::new(fields));
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let tmp = path.with_file_name(format!(".{name}.{}.tmp", std::process::id()));
        let file = File::create(&tmp)?;
        let writer = ArrowWriter::try_new(
            file,
            schema.clone(),
            Some(properties(
                TABLE_LAYOUT,
                true,
                ParquetCompression::default(),
            )),
        )
        .map_err(parquet_error)?;
        Ok(TableWriter {
            writer,
            schema,
            tmp,
            path: path.to_path_buf(),
            time: Vec::new(),
            timestamp: Vec::new(),
            run: Vec::new(),
            episode: Vec::new(),
            split: Vec::new(),
            values: vec![Vec::new(); columns.len()],
            rows: 0,
        })
    }

    /// One row: times (relative and absolute, s), the run it comes from, episode and split, and
    /// one value a column (`values` shorter than the columns leaves the rest null).
    pub fn push(
        &mut self,
        t_s: f64,
        timestamp_s: f64,
        run: Option<&str>,
        episode: Option<u32>,
        split: Option<&'static str>,
        values: &[f64],
    ) -> io::Result<()> {
        self.time.push(t_s);
        self.timestamp.push(timestamp_s);
        self.run.push(run.map(str::to_string));
        self.episode.push(episode);
        self.split.push(split);
        for (i, column) in self.values.iter_mut().enumerate() {
            column.push(values.get(i).copied().unwrap_or(f64::NAN));
        }
        self.rows += 1;
        if self.time.len() >= GROUP_ROWS {
            self.flush()?;
        }
        Ok(())
    }

    fn flush(&mut self) -> io::Result<()> {
        if self.time.is_empty() {
            return Ok(());
        }
        let mut arrays: Vec<ArrayRef> = vec![
            Arc::new(Float64Array::from(std::mem::take(&mut self.time))),
            Arc::new(Float64Array::from(std::mem::take(&mut self.timestamp))),
            Arc::new(StringArray::from(std::mem::take(&mut self.run))),
            Arc::new(UInt32Array::from(std::mem::take(&mut self.episode))),
            Arc::new(StringArray::from(std::mem::take(&mut self.split))),
        ];
        for column in &mut self.values {
            let values = std::mem::take(column);
            arrays.push(Arc::new(
                values
                    .into_iter()
                    .map(|v| (!v.is_nan()).then_some(v))
                    .collect::<Float64Array>(),
            ));
        }
        let batch = RecordBatch::try_new(self.schema.clone(), arrays).map_err(io::Error::other)?;
        self.writer.write(&batch).map_err(parquet_error)?;
        // Close the row group: the writer holds no more than one group's rows.
        self.writer.flush().map_err(parquet_error)
    }

    /// Rows written so far.
    pub fn rows(&self) -> u64 {
        self.rows
    }

    /// Write the rest, close the file and move it into place.
    pub fn finish(mut self) -> io::Result<u64> {
        let result = self
            .flush()
            .and_then(|()| self.writer.finish().map(|_| ()).map_err(parquet_error))
            .and_then(|()| std::fs::rename(&self.tmp, &self.path));
        if result.is_err() {
            let _ = std::fs::remove_file(&self.tmp);
        }
        result.map(|()| self.rows)
    }
}

impl Drop for TableWriter {
    /// A table not finished (an error, an interruption) leaves nothing behind.
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.tmp);
    }
}
