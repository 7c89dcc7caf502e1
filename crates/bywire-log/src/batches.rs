//! A log of any format as Arrow batches of raw frames (feature `parquet`): what the Python
//! module and a data lake's tasks read logs through.

use arrow_array::RecordBatch;

use crate::format::{Format, Records};
use crate::parquet::{raw_schema, FrameColumns};

/// A log's frames as [`raw_schema`] batches of at most `batch_rows` rows, read as they are
/// asked for (what the Python module and a lake's tasks read logs through).
pub struct FrameBatches {
    records: Records<'static>,
    columns: FrameColumns,
    batch_rows: usize,
    done: bool,
}

impl FrameBatches {
    /// Open the log at `path` (its format sniffed from its content); with `byte_range`
    /// `(start, end)`, only the lines starting in it (a share of a split candump log).
    pub fn open(
        path: &std::path::Path,
        byte_range: Option<(u64, u64)>,
        batch_rows: usize,
    ) -> std::io::Result<(Format, Self)> {
        use Format;
        let (format, records) = match byte_range {
            None => Format::open_file(path)?,
            Some((start, end)) => (Format::Candump, Format::open_file_range(path, start, end)?),
        };
        let batches = FrameBatches {
            records,
            columns: FrameColumns::new(),
            batch_rows: batch_rows.max(1),
            done: false,
        };
        Ok((format, batches))
    }
}

impl Iterator for FrameBatches {
    /// A batch, or why the log could not be read (`InvalidData`, naming the line or offset).
    type Item = std::io::Result<RecordBatch>;

    fn next(&mut self) -> Option<Self::Item> {
        let invalid = |e: &dyn std::fmt::Display| {
            std::io::Error::new(std::io::ErrorKind::InvalidData, e.to_string())
        };
        while !self.done && self.columns.rows() < self.batch_rows {
            match self.records.next() {
                Some(Ok(record)) => self.columns.push(&record),
                Some(Err(e)) => {
                    self.done = true;
                    return Some(Err(invalid(&e)));
                }
                None => self.done = true,
            }
        }
        if self.columns.rows() == 0 {
            return None;
        }
        Some(self.columns.finish(&raw_schema()).map_err(|e| invalid(&e)))
    }
}
