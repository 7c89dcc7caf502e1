//! How Parquet output is written, a choice the formats' common options carry whether or not
//! Parquet is built in.

use crate::candump::Precision;

/// How Parquet output compresses its pages (the other formats have no such choice).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ParquetCompression {
    /// Zstandard at level 1: the smallest files of the three, what datasets are kept in.
    #[default]
    Zstd,
    /// Snappy: Spark's and pyarrow's default; larger files, cheaper to write and read.
    Snappy,
    /// No compression.
    Uncompressed,
}

/// How Parquet output is written (the other formats ignore it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ParquetOptions {
    /// What the pages are compressed with.
    pub compression: ParquetCompression,
    /// The unit of the `ts` column: nanoseconds (the default), or microseconds, floored
    /// (what Spark reads as times).
    pub times: Precision,
}

impl Default for ParquetOptions {
    /// zstd, nanoseconds (not [`Precision`]'s own default, which is candump text's).
    fn default() -> Self {
        ParquetOptions {
            compression: ParquetCompression::default(),
            times: Precision::Nanos,
        }
    }
}

impl From<ParquetCompression> for ParquetOptions {
    fn from(compression: ParquetCompression) -> Self {
        ParquetOptions {
            compression,
            ..ParquetOptions::default()
        }
    }
}
