//! Parquet written here rather than through parquet-rs, for the files whose columns bywire
//! knows: a data lake's long files ([`crate::lake`]) and the decoded tables
//! ([`crate::batch_file`]). Their texts (channels, signal names, value descriptions) are
//! dictionary keys before they are written, and parquet-rs and pyarrow hash each row's text
//! again to find its key (profiled: a third of writing the lake's files, a sixth of decoding a
//! log to Parquet). Here the keys are written as they are.
//!
//! What is written is format version 1, as Spark writes it: pages with their headers, a
//! dictionary page before a column chunk's data pages, definition levels of optional columns
//! as RLE/bit-packed runs, `PLAIN`, `PLAIN_DICTIONARY` or `DELTA_BINARY_PACKED` values, each
//! chunk's statistics, and the footer. Each piece is checked by reading files back with
//! parquet-rs (the unit tests), pyarrow, polars and Spark (the Python tests).

use std::io::{self, Write};

use crate::thrift::{varint, Kind, Thrift};

// Parquet's numbers (parquet.thrift).
const INT64: i32 = 2;
const DOUBLE: i32 = 5;
const BYTE_ARRAY: i32 = 6;
pub(crate) const PLAIN: i32 = 0;
pub(crate) const PLAIN_DICTIONARY: i32 = 2;
const RLE: i32 = 3;
pub(crate) const DELTA_BINARY_PACKED: i32 = 5;
const DATA_PAGE: i32 = 0;
const DICTIONARY_PAGE: i32 = 2;
const REQUIRED: i32 = 0;
const OPTIONAL: i32 = 1;
const UTF8: i32 = 0;
const TIMESTAMP_MILLIS: i32 = 9;
const TIMESTAMP_MICROS: i32 = 10;
const UINT_64: i32 = 14;

/// A column's physical type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Physical {
    Int64,
    Double,
    ByteArray,
}

impl Physical {
    fn code(self) -> i32 {
        match self {
            Self::Int64 => INT64,
            Self::Double => DOUBLE,
            Self::ByteArray => BYTE_ARRAY,
        }
    }
}

/// A time's unit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum TimeUnit {
    Millis,
    Micros,
    Nanos,
}

/// What a column's values mean, beyond their physical type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Logical {
    /// Nothing more: signed integers, doubles.
    None,
    /// UTF-8 text.
    String,
    /// Unsigned 64-bit integers.
    UInt64,
    /// Times since the epoch, UTC when `utc`.
    Timestamp { unit: TimeUnit, utc: bool },
}

/// A column of a flat schema.
#[derive(Debug, Clone)]
pub(crate) struct Column {
    pub(crate) name: String,
    pub(crate) physical: Physical,
    pub(crate) logical: Logical,
    pub(crate) optional: bool,
}

/// The least and greatest value of a column chunk, typed until written (so that each type
/// compares as its column order says: signed, unsigned, IEEE, bytewise).
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Range {
    Int(i64, i64),
    UInt(u64, u64),
    Float(f64, f64),
    Bytes(Vec<u8>, Vec<u8>),
}

impl Range {
    /// The range of both.
    fn merge(self, other: Range) -> Range {
        match (self, other) {
            (Range::Int(a, b), Range::Int(c, d)) => Range::Int(a.min(c), b.max(d)),
            (Range::UInt(a, b), Range::UInt(c, d)) => Range::UInt(a.min(c), b.max(d)),
            (Range::Float(a, b), Range::Float(c, d)) => Range::Float(a.min(c), b.max(d)),
            (Range::Bytes(a, b), Range::Bytes(c, d)) => Range::Bytes(a.min(c), b.max(d)),
            (first, _) => first,
        }
    }

    /// Minimum and maximum as Parquet's statistics hold them (plain-encoded).
    fn encoded(&self) -> (Vec<u8>, Vec<u8>) {
        match self {
            Range::Int(lo, hi) => (lo.to_le_bytes().to_vec(), hi.to_le_bytes().to_vec()),
            Range::UInt(lo, hi) => (lo.to_le_bytes().to_vec(), hi.to_le_bytes().to_vec()),
            // A zero bound is written as -0 below and +0 above, as the format asks (readers
            // cannot tell which zero the column holds).
            Range::Float(lo, hi) => {
                let lo = if *lo == 0.0 { -0.0f64 } else { *lo };
                let hi = if *hi == 0.0 { 0.0f64 } else { *hi };
                (lo.to_le_bytes().to_vec(), hi.to_le_bytes().to_vec())
            }
            Range::Bytes(lo, hi) => (lo.clone(), hi.clone()),
        }
    }
}

/// The range of `values` (none when empty).
pub(crate) fn int_range(values: impl Iterator<Item = i64>) -> Option<Range> {
    values
        .map(|v| (v, v))
        .reduce(|(a, b), (c, d)| (a.min(c), b.max(d)))
        .map(|(lo, hi)| Range::Int(lo, hi))
}

/// The range of `values` (none when empty).
pub(crate) fn uint_range(values: impl Iterator<Item = u64>) -> Option<Range> {
    values
        .map(|v| (v, v))
        .reduce(|(a, b), (c, d)| (a.min(c), b.max(d)))
        .map(|(lo, hi)| Range::UInt(lo, hi))
}

/// The range of `values` without their NaNs (none when nothing else is left).
pub(crate) fn float_range(values: impl Iterator<Item = f64>) -> Option<Range> {
    values
        .filter(|v| !v.is_nan())
        .map(|v| (v, v))
        .reduce(|(a, b), (c, d)| (a.min(c), b.max(d)))
        .map(|(lo, hi)| Range::Float(lo, hi))
}

/// The range of the dictionary's texts that were `used`.
pub(crate) fn texts_range<'t>(
    texts: impl Iterator<Item = &'t [u8]>,
    used: &[bool],
) -> Option<Range> {
    texts
        .zip(used)
        .filter(|(_, &u)| u)
        .map(|(t, _)| (t, t))
        .reduce(|(a, b), (c, d)| (a.min(c), b.max(d)))
        .map(|(lo, hi)| Range::Bytes(lo.to_vec(), hi.to_vec()))
}

/// A column chunk's statistics: its nulls, and the range of its values.
#[derive(Debug, Clone, Default)]
pub(crate) struct Statistics {
    pub(crate) nulls: i64,
    pub(crate) range: Option<Range>,
}

impl Statistics {
    /// Add a page's statistics.
    pub(crate) fn add(&mut self, nulls: usize, range: Option<Range>) {
        self.nulls = self.nulls.saturating_add(as_i64(nulls as u64));
        self.range = match (self.range.take(), range) {
            (Some(a), Some(b)) => Some(a.merge(b)),
            (a, b) => a.or(b),
        };
    }
}

pub(crate) fn too_big(what: &str) -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidInput,
        format!("{what} too big for a Parquet page"),
    )
}

pub(crate) fn as_i32(n: usize, what: &str) -> io::Result<i32> {
    i32::try_from(n).map_err(|_| too_big(what))
}

pub(crate) fn as_i64(n: u64) -> i64 {
    i64::try_from(n).unwrap_or(i64::MAX)
}

/// Parquet's RLE / bit-packing hybrid of `values` (each below 2^`width`): runs of 8 or more
/// equal values as runs, the rest bit-packed in groups of 8 (the last group padded).
pub(crate) fn hybrid(values: &[u32], width: u32, out: &mut Vec<u8>) {
    let value_bytes = width.div_ceil(8) as usize;
    let mut at = 0;
    while let Some(&first) = values.get(at) {
        let rest = values.get(at..).unwrap_or_default();
        let run = rest.iter().take_while(|&&v| v == first).count();
        if run >= 8 {
            varint(out, (run as u64) << 1);
            out.extend(first.to_le_bytes().iter().take(value_bytes));
            at += run;
            continue;
        }
        // Groups of 8 until 8 equal values start a group (a run is cheaper) or 63 groups
        // (what parquet-mr's readers expect a run to hold at most).
        let start = at;
        let mut groups = 0u64;
        loop {
            groups += 1;
            at += 8;
            let next = values.get(at..at + 8);
            if groups == 63 || next.is_none_or(|n| n.iter().all(|&v| Some(&v) == n.first())) {
                break;
            }
        }
        let end = at.min(values.len());
        varint(out, (groups << 1) | 1);
        let packed = values.get(start..end).unwrap_or_default();
        let padding = std::iter::repeat_n(0, at - end);
        let (mut bits, mut filled) = (0u64, 0u32);
        for value in packed.iter().copied().chain(padding) {
            bits |= u64::from(value) << filled;
            filled += width;
            while filled >= 8 {
                out.push((bits & 0xff) as u8);
                bits >>= 8;
                filled -= 8;
            }
        }
    }
}

/// The bits a key below `entries` needs (at least 1: every reader takes it).
pub(crate) fn key_width(entries: usize) -> u32 {
    (usize::BITS - entries.saturating_sub(1).leading_zeros()).max(1)
}

/// Values a `DELTA_BINARY_PACKED` block holds, in miniblocks of [`MINIBLOCK`].
const DELTA_BLOCK: usize = 128;
const MINIBLOCK: usize = 32;

fn zigzag(out: &mut Vec<u8>, value: i64) {
    #[allow(clippy::cast_sign_loss)] // zigzag: the sign moves to the lowest bit
    varint(out, ((value << 1) ^ (value >> 63)) as u64);
}

/// Parquet's `DELTA_BINARY_PACKED` of the `count` values `values` yields: the first value,
/// then blocks of 128 differences, each block as its least difference and four miniblocks of
/// 32 differences above it, bit-packed at the width the miniblock's greatest needs.
/// Differences wrap, as readers add them back wrapping (so any 64-bit values round-trip).
pub(crate) fn delta_binary_packed(
    count: usize,
    mut values: impl Iterator<Item = i64>,
    out: &mut Vec<u8>,
) {
    varint(out, DELTA_BLOCK as u64);
    varint(out, (DELTA_BLOCK / MINIBLOCK) as u64);
    varint(out, count as u64);
    let Some(first) = values.next() else {
        zigzag(out, 0);
        return;
    };
    zigzag(out, first);
    let mut previous = first;
    let mut deltas = [0i64; DELTA_BLOCK];
    loop {
        let mut filled = 0;
        for (slot, value) in deltas.iter_mut().zip(values.by_ref()) {
            *slot = value.wrapping_sub(previous);
            previous = value;
            filled += 1;
        }
        let Some(block) = deltas.get(..filled).filter(|b| !b.is_empty()) else {
            return;
        };
        let least = block.iter().copied().min().unwrap_or(0);
        zigzag(out, least);
        let widths_at = out.len();
        out.extend_from_slice(&[0; DELTA_BLOCK / MINIBLOCK]);
        for (index, miniblock) in block.chunks(MINIBLOCK).enumerate() {
            #[allow(clippy::cast_sign_loss)] // a difference above the least, as unsigned bits
            let above = |d: i64| d.wrapping_sub(least) as u64;
            let width = 64
                - miniblock
                    .iter()
                    .fold(0, |all, &d| all | above(d))
                    .leading_zeros();
            if let Some(slot) = out.get_mut(widths_at + index) {
                #[allow(clippy::cast_possible_truncation)] // at most 64
                {
                    *slot = width as u8;
                }
            }
            // The last miniblock is padded to 32 values (the format's rule).
            let padded = miniblock
                .iter()
                .map(|&d| above(d))
                .chain(std::iter::repeat(0))
                .take(MINIBLOCK);
            pack(padded, width, out);
        }
        if filled < DELTA_BLOCK {
            return;
        }
    }
}

/// 32 values bit-packed at `width` bits each, lowest bits first: `4 × width` bytes.
fn pack(values: impl Iterator<Item = u64>, width: u32, out: &mut Vec<u8>) {
    if width == 0 {
        return;
    }
    let (mut bits, mut filled) = (0u128, 0u32);
    for value in values {
        bits |= u128::from(value) << filled;
        filled += width;
        if filled >= 64 {
            #[allow(clippy::cast_possible_truncation)] // the lowest 64 bits
            out.extend_from_slice(&(bits as u64).to_le_bytes());
            bits >>= 64;
            filled -= 64;
        }
    }
    let tail = (filled / 8) as usize;
    out.extend_from_slice(bits.to_le_bytes().get(..tail).unwrap_or_default());
}

/// The definition levels of an optional column's page, length first (format version 1):
/// one run when every row has a value, else `present` (1 a value, 0 a null) as runs and
/// groups.
pub(crate) fn levels(present: Option<&[u32]>, rows: usize, out: &mut Vec<u8>) {
    let mut levels = Vec::new();
    match present {
        None => {
            varint(&mut levels, (rows as u64) << 1);
            levels.push(1);
        }
        Some(present) => hybrid(present, 1, &mut levels),
    }
    let length = u32::try_from(levels.len()).unwrap_or(u32::MAX);
    out.extend_from_slice(&length.to_le_bytes());
    out.extend_from_slice(&levels);
}

/// A dictionary page's body: `texts`, each length first.
pub(crate) fn plain_texts<'t>(
    texts: impl Iterator<Item = &'t [u8]>,
    out: &mut Vec<u8>,
) -> io::Result<()> {
    for text in texts {
        let length = u32::try_from(text.len()).map_err(|_| too_big("a text"))?;
        out.extend_from_slice(&length.to_le_bytes());
        out.extend_from_slice(text);
    }
    Ok(())
}

/// A data page's keys into a dictionary of `entries` texts: their width, then the keys.
pub(crate) fn dictionary_keys(keys: &[u32], entries: usize, out: &mut Vec<u8>) {
    let width = key_width(entries);
    #[allow(clippy::cast_possible_truncation)] // at most 32
    out.push(width as u8);
    hybrid(keys, width, out);
}

enum Compressor {
    Uncompressed,
    Snappy(Box<snap::raw::Encoder>),
    Zstd(zstd::bulk::Compressor<'static>),
    Gzip,
}

impl Compressor {
    fn new(compression: LakeCompression) -> io::Result<Self> {
        Ok(match compression {
            LakeCompression::Uncompressed => Self::Uncompressed,
            LakeCompression::Snappy => Self::Snappy(Box::new(snap::raw::Encoder::new())),
            // Level 1, as parquet-rs and Spark compress by default.
            LakeCompression::Zstd => Self::Zstd(zstd::bulk::Compressor::new(1)?),
            LakeCompression::Gzip => Self::Gzip,
        })
    }

    /// `page` compressed (`None`: as it is).
    fn compress(&mut self, page: &[u8]) -> io::Result<Option<Vec<u8>>> {
        match self {
            Self::Uncompressed => Ok(None),
            Self::Snappy(encoder) => encoder
                .compress_vec(page)
                .map(Some)
                .map_err(io::Error::other),
            Self::Zstd(compressor) => compressor.compress(page).map(Some),
            Self::Gzip => {
                let mut encoder =
                    flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
                encoder.write_all(page)?;
                encoder.finish().map(Some)
            }
        }
    }
}

/// A column chunk's pages (headers and compressed bodies) as they are made, until its row
/// group is written; its dictionary page, when it has one, is made last and written first.
#[derive(Default)]
pub(crate) struct Chunk {
    data: Vec<u8>,
    dictionary: Vec<u8>,
    /// The dictionary page's header and uncompressed body.
    dictionary_uncompressed: i64,
    /// The data pages' headers and uncompressed bodies.
    uncompressed: i64,
    /// Values (rows, nulls included) in the data pages.
    values: i64,
    encoding: i32,
    pub(crate) statistics: Statistics,
}

impl Chunk {
    /// Bytes held.
    pub(crate) fn size(&self) -> usize {
        self.data.len() + self.dictionary.len()
    }
}

/// What a file's pages share while they are made: the compressor, and the page being built
/// (`body`, which the caller fills before [`Pages::data_page`] or [`Pages::dictionary_page`]).
pub(crate) struct Pages {
    compression: LakeCompression,
    compressor: Compressor,
    pub(crate) body: Vec<u8>,
}

impl Pages {
    /// Pages compressed with `compression`.
    pub(crate) fn new(compression: LakeCompression) -> io::Result<Self> {
        Ok(Pages {
            compression,
            compressor: Compressor::new(compression)?,
            body: Vec::new(),
        })
    }

    pub(crate) fn compression(&self) -> LakeCompression {
        self.compression
    }

    /// `body` compressed behind its header, onto `out`: its size uncompressed (with header).
    fn page(
        &mut self,
        kind: i32,
        values: usize,
        encoding: i32,
        out: &mut Vec<u8>,
    ) -> io::Result<i64> {
        let compressed = self.compressor.compress(&self.body)?;
        let stored = compressed.as_deref().unwrap_or(&self.body);
        let mut header = Thrift::default();
        header.i32(1, kind);
        header.i32(2, as_i32(self.body.len(), "a page")?);
        header.i32(3, as_i32(stored.len(), "a page")?);
        let values = as_i32(values, "a page's values")?;
        if kind == DICTIONARY_PAGE {
            header.begin(7);
            header.i32(1, values);
            header.i32(2, encoding);
        } else {
            header.begin(5);
            header.i32(1, values);
            header.i32(2, encoding);
            header.i32(3, RLE);
            header.i32(4, RLE);
        }
        header.end();
        header.end();
        out.extend_from_slice(&header.bytes);
        out.extend_from_slice(stored);
        Ok(as_i64((header.bytes.len() + self.body.len()) as u64))
    }

    /// `body` as a data page of `values` rows in `encoding`, onto `chunk`.
    pub(crate) fn data_page(
        &mut self,
        chunk: &mut Chunk,
        values: usize,
        encoding: i32,
    ) -> io::Result<()> {
        let uncompressed = self.page(DATA_PAGE, values, encoding, &mut chunk.data)?;
        chunk.uncompressed = chunk.uncompressed.saturating_add(uncompressed);
        chunk.values = chunk.values.saturating_add(as_i64(values as u64));
        chunk.encoding = encoding;
        Ok(())
    }

    /// `body` as `chunk`'s dictionary page, of `entries` texts.
    pub(crate) fn dictionary_page(&mut self, chunk: &mut Chunk, entries: usize) -> io::Result<()> {
        chunk.dictionary.clear();
        chunk.dictionary_uncompressed = self.page(
            DICTIONARY_PAGE,
            entries,
            PLAIN_DICTIONARY,
            &mut chunk.dictionary,
        )?;
        Ok(())
    }
}

/// A column chunk in the file, for the footer.
struct ChunkPlace {
    encodings: Vec<i32>,
    values: i64,
    uncompressed: i64,
    compressed: i64,
    data_page: i64,
    dictionary_page: Option<i64>,
    statistics: Statistics,
}

struct RowGroup {
    chunks: Vec<ChunkPlace>,
    rows: i64,
}

/// A Parquet file being written, a row group at a time: where it is and what its footer will
/// say. The output is the caller's, given to each call, so that it can be closed between
/// row groups and opened again to append.
pub(crate) struct FileLayout {
    at: u64,
    groups: Vec<RowGroup>,
}

impl FileLayout {
    /// A file starting on `out` (its first bytes).
    pub(crate) fn start(out: &mut impl Write) -> io::Result<Self> {
        out.write_all(b"PAR1")?;
        Ok(FileLayout {
            at: 4,
            groups: Vec::new(),
        })
    }

    /// Row groups written.
    pub(crate) fn row_groups(&self) -> usize {
        self.groups.len()
    }

    /// Write a row group of `rows` rows: its column chunks, in the schema's order (each
    /// emptied, to be filled again).
    pub(crate) fn row_group(
        &mut self,
        out: &mut impl Write,
        rows: usize,
        chunks: &mut [Chunk],
    ) -> io::Result<()> {
        let mut places = Vec::with_capacity(chunks.len());
        for chunk in chunks.iter_mut() {
            let dictionary_page = (!chunk.dictionary.is_empty()).then_some(as_i64(self.at));
            out.write_all(&chunk.dictionary)?;
            self.at += chunk.dictionary.len() as u64;
            let data_page = as_i64(self.at);
            out.write_all(&chunk.data)?;
            self.at += chunk.data.len() as u64;
            let encodings = if dictionary_page.is_some() {
                vec![PLAIN_DICTIONARY, RLE]
            } else {
                vec![chunk.encoding, RLE]
            };
            places.push(ChunkPlace {
                encodings,
                values: chunk.values,
                uncompressed: chunk.uncompressed + chunk.dictionary_uncompressed,
                compressed: as_i64(chunk.size() as u64),
                data_page,
                dictionary_page,
                statistics: std::mem::take(&mut chunk.statistics),
            });
            chunk.data.clear();
            chunk.dictionary.clear();
            chunk.dictionary_uncompressed = 0;
            chunk.uncompressed = 0;
            chunk.values = 0;
        }
        self.groups.push(RowGroup {
            chunks: places,
            rows: as_i64(rows as u64),
        });
        Ok(())
    }

    /// Write the footer on `out` (flushed), for `columns` compressed with `compression`
    /// and `metadata` as the file's key-value metadata: the file is whole.
    pub(crate) fn finish(
        self,
        columns: &[Column],
        compression: LakeCompression,
        metadata: &[(&str, &str)],
        out: &mut impl Write,
    ) -> io::Result<()> {
        let mut meta = Thrift::default();
        meta.i32(1, 1);
        meta.list(2, Kind::Struct, columns.len() + 1);
        meta.begin_item();
        meta.binary(4, b"schema");
        meta.i32(5, as_i32(columns.len(), "a schema")?);
        meta.end();
        for column in columns {
            schema_element(&mut meta, column);
        }
        let rows: i64 = self.groups.iter().map(|g| g.rows).sum();
        meta.i64(3, rows);
        meta.list(4, Kind::Struct, self.groups.len());
        for group in &self.groups {
            meta.begin_item();
            meta.list(1, Kind::Struct, group.chunks.len());
            for (chunk, column) in group.chunks.iter().zip(columns) {
                chunk_metadata(&mut meta, chunk, column, compression);
            }
            let start = group
                .chunks
                .first()
                .map_or(0, |c| c.dictionary_page.unwrap_or(c.data_page));
            meta.i64(2, group.chunks.iter().map(|c| c.uncompressed).sum());
            meta.i64(3, group.rows);
            meta.i64(5, start);
            meta.i64(6, group.chunks.iter().map(|c| c.compressed).sum());
            meta.end();
        }
        if !metadata.is_empty() {
            meta.list(5, Kind::Struct, metadata.len());
            for (key, value) in metadata {
                meta.begin_item();
                meta.binary(1, key.as_bytes());
                meta.binary(2, value.as_bytes());
                meta.end();
            }
        }
        meta.binary(
            6,
            format!("bywire version {}", env!("CARGO_PKG_VERSION")).as_bytes(),
        );
        // Every column's statistics in its type's order (signed or unsigned integers, IEEE
        // doubles, bytewise texts).
        meta.list(7, Kind::Struct, columns.len());
        for _ in columns {
            meta.begin_item();
            meta.begin(1);
            meta.end();
            meta.end();
        }
        meta.end();
        let length = u32::try_from(meta.bytes.len()).map_err(|_| too_big("the footer"))?;
        out.write_all(&meta.bytes)?;
        out.write_all(&length.to_le_bytes())?;
        out.write_all(b"PAR1")?;
        out.flush()
    }
}

/// A column's `SchemaElement`.
fn schema_element(meta: &mut Thrift, column: &Column) {
    meta.begin_item();
    meta.i32(1, column.physical.code());
    meta.i32(3, if column.optional { OPTIONAL } else { REQUIRED });
    meta.binary(4, column.name.as_bytes());
    let converted = match column.logical {
        Logical::None => None,
        Logical::String => Some(UTF8),
        Logical::UInt64 => Some(UINT_64),
        Logical::Timestamp { unit, .. } => match unit {
            TimeUnit::Millis => Some(TIMESTAMP_MILLIS),
            TimeUnit::Micros => Some(TIMESTAMP_MICROS),
            // No converted type for nanoseconds (readers take the logical type).
            TimeUnit::Nanos => None,
        },
    };
    if let Some(converted) = converted {
        meta.i32(6, converted);
    }
    match column.logical {
        Logical::None => {}
        Logical::String => {
            meta.begin(10);
            meta.begin(1); // STRING
            meta.end();
            meta.end();
        }
        Logical::UInt64 => {
            meta.begin(10);
            meta.begin(10); // INTEGER
            meta.i8(1, 64);
            meta.bool(2, false);
            meta.end();
            meta.end();
        }
        Logical::Timestamp { unit, utc } => {
            meta.begin(10);
            meta.begin(8); // TIMESTAMP
            meta.bool(1, utc);
            meta.begin(2);
            meta.begin(match unit {
                TimeUnit::Millis => 1,
                TimeUnit::Micros => 2,
                TimeUnit::Nanos => 3,
            });
            meta.end();
            meta.end();
            meta.end();
            meta.end();
        }
    }
    meta.end();
}

/// A column chunk's `ColumnChunk` with its `ColumnMetaData`.
fn chunk_metadata(
    meta: &mut Thrift,
    chunk: &ChunkPlace,
    column: &Column,
    compression: LakeCompression,
) {
    let start = chunk.dictionary_page.unwrap_or(chunk.data_page);
    meta.begin_item();
    meta.i64(2, start);
    meta.begin(3);
    meta.i32(1, column.physical.code());
    meta.list(2, Kind::I32, chunk.encodings.len());
    for &encoding in &chunk.encodings {
        meta.list_item_i32(encoding);
    }
    meta.list(3, Kind::Binary, 1);
    meta.list_item_binary(column.name.as_bytes());
    meta.i32(4, compression.codec());
    meta.i64(5, chunk.values);
    meta.i64(6, chunk.uncompressed);
    meta.i64(7, chunk.compressed);
    meta.i64(9, chunk.data_page);
    if let Some(offset) = chunk.dictionary_page {
        meta.i64(11, offset);
    }
    meta.begin(12);
    meta.i64(3, chunk.statistics.nulls);
    if let Some(range) = &chunk.statistics.range {
        let (min, max) = range.encoded();
        meta.binary(5, &max);
        meta.binary(6, &min);
    }
    meta.end();
    meta.end();
    meta.end();
}

/// How a lake's pages are compressed (Spark's `compression` option's names).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LakeCompression {
    /// Spark's and pyarrow's default.
    Snappy,
    /// Zstandard at level 1.
    Zstd,
    /// gzip.
    Gzip,
    /// No compression.
    Uncompressed,
}

impl LakeCompression {
    /// `snappy`, `zstd`, `gzip` or `none` (`uncompressed`).
    pub fn from_name(name: &str) -> Option<Self> {
        match name.to_ascii_lowercase().as_str() {
            "snappy" => Some(Self::Snappy),
            "zstd" => Some(Self::Zstd),
            "gzip" => Some(Self::Gzip),
            "none" | "uncompressed" => Some(Self::Uncompressed),
            _ => None,
        }
    }

    /// What Spark puts in a file's name before `.parquet`.
    pub(crate) fn extension(self) -> &'static str {
        match self {
            Self::Snappy => ".snappy",
            Self::Zstd => ".zstd",
            Self::Gzip => ".gz",
            Self::Uncompressed => "",
        }
    }

    /// Parquet's `CompressionCodec`.
    pub(crate) fn codec(self) -> i32 {
        match self {
            Self::Uncompressed => 0,
            Self::Snappy => 1,
            Self::Gzip => 2,
            Self::Zstd => 6,
        }
    }
}

impl From<bywire_log::parquet::ParquetCompression> for LakeCompression {
    fn from(compression: bywire_log::parquet::ParquetCompression) -> Self {
        match compression {
            bywire_log::parquet::ParquetCompression::Zstd => Self::Zstd,
            bywire_log::parquet::ParquetCompression::Snappy => Self::Snappy,
            bywire_log::parquet::ParquetCompression::Uncompressed => Self::Uncompressed,
        }
    }
}
