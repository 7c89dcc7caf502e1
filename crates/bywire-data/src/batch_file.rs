//! A Parquet file written from Arrow batches of flat columns: times and 64-bit integers as
//! `DELTA_BINARY_PACKED` (they change by little from row to row: a few bits a row before
//! compression), doubles plain, and dictionary texts as their keys behind a dictionary page.
//! The decoded tables are written so ([`crate::decoded`]); see [`crate::encode`] for why the
//! encoding is ours.
//!
//! Each batch becomes a page a column (a longer batch, pages of [`PAGE_ROWS`]), held
//! compressed until its row group is written; the Arrow schema goes in the footer as
//! `ARROW:schema`, as parquet-rs writes it, so that Arrow readers get the batches' types back
//! (dictionaries, unsigned integers, time zones).

use std::collections::HashMap;
use std::io::{self, Write};

use arrow_array::cast::AsArray;
use arrow_array::types::{
    Float64Type, Int32Type, Int64Type, TimestampMicrosecondType, TimestampMillisecondType,
    TimestampNanosecondType, UInt64Type,
};
use arrow_array::{Array, RecordBatch};
use arrow_buffer::NullBuffer;
use arrow_schema::{DataType, SchemaRef, TimeUnit as ArrowTimeUnit};

use crate::encode::LakeCompression;
use crate::encode::{
    delta_binary_packed, dictionary_keys, float_range, int_range, levels, plain_texts, texts_range,
    uint_range, Chunk, Column, FileLayout, Logical, Pages, Physical, TimeUnit, DELTA_BINARY_PACKED,
    PLAIN, PLAIN_DICTIONARY,
};
use bywire_log::parquet::ROW_GROUP_ROWS;

/// Rows a page holds at most (parquet-rs's default too).
pub(crate) const PAGE_ROWS: usize = 20_000;

/// How a column's values are written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Values {
    /// Signed 64-bit integers (and times), as deltas.
    Int,
    /// Unsigned 64-bit integers, as deltas of their bits.
    UInt,
    /// Doubles, plain.
    Float,
    /// Texts, as keys into the chunk's dictionary.
    Texts,
}

/// A dictionary column's distinct texts in the row group being written, in key order, and
/// which of them rows use (for the statistics). Distinct: Arrow's readers take a dictionary
/// page's texts as a set, and keys past a repeated text would point past its end.
#[derive(Default)]
struct Dictionary {
    texts: Vec<Vec<u8>>,
    used: Vec<bool>,
    index: HashMap<Vec<u8>, u32>,
    /// Our key of each text of the last batch's dictionary, by its place there.
    map: Vec<u32>,
}

impl Dictionary {
    /// Our key of each text of a batch's dictionary, by its place there (in `map`). The places whose
    /// text is what it was in the last batch keep their key (the decoded tables' labels only
    /// grow, so only new texts are looked up); the others are found, and added if new.
    fn map_batch(&mut self, batch_texts: &arrow_array::StringArray) {
        let texts = &self.texts;
        let kept = self
            .map
            .iter()
            .take(batch_texts.len())
            .enumerate()
            .take_while(|&(place, &key)| {
                texts
                    .get(key as usize)
                    .is_some_and(|t| batch_texts.value(place).as_bytes() == t.as_slice())
            })
            .count();
        self.map.truncate(kept);
        for place in kept..batch_texts.len() {
            let text = batch_texts.value(place).as_bytes();
            let key = match self.index.get(text) {
                Some(&key) => key,
                None => {
                    let key = u32::try_from(self.texts.len()).unwrap_or(u32::MAX);
                    self.texts.push(text.to_vec());
                    self.index.insert(text.to_vec(), key);
                    key
                }
            };
            self.map.push(key);
        }
        self.used.resize(self.texts.len(), false);
    }

    fn clear(&mut self) {
        self.texts.clear();
        self.used.clear();
        self.index.clear();
        self.map.clear();
    }
}

/// A Parquet file being written from Arrow batches.
pub(crate) struct BatchFile<W: Write> {
    out: W,
    layout: FileLayout,
    pages: Pages,
    schema: SchemaRef,
    columns: Vec<Column>,
    values: Vec<Values>,
    chunks: Vec<Chunk>,
    dictionaries: Vec<Dictionary>,
    /// Rows in the row group being written.
    rows: usize,
    metadata: Vec<(String, String)>,
    /// A page's keys and definition levels, kept between pages.
    keys: Vec<u32>,
    present: Vec<u32>,
}

fn unsupported(name: &str, data_type: &DataType) -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidInput,
        format!("Parquet: column {name} of type {data_type} is not written by this writer"),
    )
}

/// A column's Parquet type and how its values are written.
fn column_of(field: &arrow_schema::Field) -> io::Result<(Column, Values)> {
    let time = |unit: &ArrowTimeUnit, zone: &Option<std::sync::Arc<str>>| {
        let unit = match unit {
            ArrowTimeUnit::Millisecond => Some(TimeUnit::Millis),
            ArrowTimeUnit::Microsecond => Some(TimeUnit::Micros),
            ArrowTimeUnit::Nanosecond => Some(TimeUnit::Nanos),
            ArrowTimeUnit::Second => None,
        }?;
        Some(Logical::Timestamp {
            unit,
            utc: zone.is_some(),
        })
    };
    let (physical, logical, values) = match field.data_type() {
        DataType::Int64 => (Physical::Int64, Logical::None, Values::Int),
        DataType::UInt64 => (Physical::Int64, Logical::UInt64, Values::UInt),
        DataType::Float64 => (Physical::Double, Logical::None, Values::Float),
        DataType::Timestamp(unit, zone) => match time(unit, zone) {
            Some(logical) => (Physical::Int64, logical, Values::Int),
            None => return Err(unsupported(field.name(), field.data_type())),
        },
        DataType::Dictionary(key, value)
            if **key == DataType::Int32 && **value == DataType::Utf8 =>
        {
            (Physical::ByteArray, Logical::String, Values::Texts)
        }
        other => return Err(unsupported(field.name(), other)),
    };
    Ok((
        Column {
            name: field.name().clone(),
            physical,
            logical,
            optional: field.is_nullable(),
        },
        values,
    ))
}

/// A column's 64-bit values (integers and times of any unit).
fn int64s(array: &dyn Array) -> Option<&[i64]> {
    if let Some(a) = array.as_primitive_opt::<Int64Type>() {
        return Some(a.values());
    }
    if let Some(a) = array.as_primitive_opt::<TimestampNanosecondType>() {
        return Some(a.values());
    }
    if let Some(a) = array.as_primitive_opt::<TimestampMicrosecondType>() {
        return Some(a.values());
    }
    array
        .as_primitive_opt::<TimestampMillisecondType>()
        .map(|a| a.values().as_ref())
}

/// The values of the rows `nulls` says are present (all without one).
fn present_values<'a, T: Copy>(
    values: &'a [T],
    nulls: Option<&'a NullBuffer>,
) -> impl Iterator<Item = T> + 'a {
    values
        .iter()
        .enumerate()
        .filter(move |(row, _)| nulls.is_none_or(|n| n.is_valid(*row)))
        .map(|(_, v)| *v)
}

impl<W: Write> BatchFile<W> {
    /// A file of `schema`'s batches on `out`, its pages compressed with `compression`, with
    /// `metadata` (and the Arrow schema) in its footer.
    pub(crate) fn try_new(
        mut out: W,
        schema: SchemaRef,
        compression: LakeCompression,
        metadata: &[(&str, &str)],
    ) -> io::Result<Self> {
        let (columns, values): (Vec<Column>, Vec<Values>) = schema
            .fields()
            .iter()
            .map(|f| column_of(f))
            .collect::<io::Result<Vec<_>>>()?
            .into_iter()
            .unzip();
        let mut metadata: Vec<(String, String)> = metadata
            .iter()
            .map(|(k, v)| ((*k).to_string(), (*v).to_string()))
            .collect();
        metadata.push((
            ::parquet::arrow::ARROW_SCHEMA_META_KEY.to_string(),
            ::parquet::arrow::encode_arrow_schema(&schema),
        ));
        Ok(BatchFile {
            layout: FileLayout::start(&mut out)?,
            out,
            pages: Pages::new(compression)?,
            chunks: columns.iter().map(|_| Chunk::default()).collect(),
            dictionaries: columns.iter().map(|_| Dictionary::default()).collect(),
            schema,
            columns,
            values,
            rows: 0,
            metadata,
            keys: Vec::new(),
            present: Vec::new(),
        })
    }

    /// Add `batch`'s rows (a row group is written once it holds [`ROW_GROUP_ROWS`]).
    pub(crate) fn write(&mut self, batch: &RecordBatch) -> io::Result<()> {
        let same = batch.num_columns() == self.columns.len()
            && batch
                .schema()
                .fields()
                .iter()
                .zip(self.schema.fields())
                .all(|(a, b)| a.data_type() == b.data_type());
        if !same {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                "Parquet: a batch whose columns are not the file's",
            ));
        }
        let mut start = 0;
        while start < batch.num_rows() {
            let rows = PAGE_ROWS.min(batch.num_rows() - start);
            let page = batch.slice(start, rows);
            for index in 0..self.columns.len() {
                self.write_page(index, page.column(index).as_ref())?;
            }
            self.rows += rows;
            start += rows;
            if self.rows >= ROW_GROUP_ROWS {
                self.flush()?;
            }
        }
        Ok(())
    }

    /// One page of column `index`.
    fn write_page(&mut self, index: usize, array: &dyn Array) -> io::Result<()> {
        let (Some(column), Some(&values), Some(chunk), Some(dictionary)) = (
            self.columns.get(index),
            self.values.get(index),
            self.chunks.get_mut(index),
            self.dictionaries.get_mut(index),
        ) else {
            return Ok(());
        };
        let rows = array.len();
        // A dictionary's rows are null where their key is, or the text it points to.
        let nulls = array.logical_nulls().filter(|n| n.null_count() > 0);
        if !column.optional && nulls.is_some() {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("Parquet: nulls in column {}, which has none", column.name),
            ));
        }
        let body = &mut self.pages.body;
        body.clear();
        if column.optional {
            let present = nulls.as_ref().map(|n| {
                self.present.clear();
                self.present.extend(n.iter().map(u32::from));
                self.present.as_slice()
            });
            levels(present, rows, body);
        }
        let null_count = nulls.as_ref().map_or(0, NullBuffer::null_count);
        let count = rows - null_count;
        let nulls = nulls.as_ref();
        let wrong = || unsupported(&column.name, array.data_type());
        let (encoding, range) = match values {
            Values::Int => {
                let all = int64s(array).ok_or_else(wrong)?;
                delta_binary_packed(count, present_values(all, nulls), body);
                (DELTA_BINARY_PACKED, int_range(present_values(all, nulls)))
            }
            Values::UInt => {
                let all = array.as_primitive_opt::<UInt64Type>().ok_or_else(wrong)?;
                #[allow(clippy::cast_possible_wrap)] // the bits, as readers take them back
                let bits = present_values(all.values(), nulls).map(|v| v as i64);
                delta_binary_packed(count, bits, body);
                let range = uint_range(present_values(all.values(), nulls));
                (DELTA_BINARY_PACKED, range)
            }
            Values::Float => {
                let all = array.as_primitive_opt::<Float64Type>().ok_or_else(wrong)?;
                for value in present_values(all.values(), nulls) {
                    body.extend_from_slice(&value.to_le_bytes());
                }
                (PLAIN, float_range(present_values(all.values(), nulls)))
            }
            Values::Texts => {
                let texts = array.as_dictionary_opt::<Int32Type>().ok_or_else(wrong)?;
                let strings = texts.values().as_string_opt::<i32>().ok_or_else(wrong)?;
                dictionary.map_batch(strings);
                let (map, used) = (&dictionary.map, &mut dictionary.used);
                self.keys.clear();
                for (row, &key) in texts.keys().values().iter().enumerate() {
                    if nulls.is_some_and(|n| n.is_null(row)) {
                        continue;
                    }
                    let ours = usize::try_from(key)
                        .ok()
                        .and_then(|k| map.get(k).copied())
                        .ok_or_else(|| {
                            io::Error::new(
                                io::ErrorKind::InvalidInput,
                                format!("Parquet: a key outside its dictionary in {}", column.name),
                            )
                        })?;
                    if let Some(used) = used.get_mut(ours as usize) {
                        *used = true;
                    }
                    self.keys.push(ours);
                }
                dictionary_keys(&self.keys, dictionary.texts.len(), body);
                // The range is the used texts', found when the row group is written.
                (PLAIN_DICTIONARY, None)
            }
        };
        chunk.statistics.add(null_count, range);
        self.pages.data_page(chunk, rows, encoding)
    }

    /// Bytes held for the row group being written.
    pub(crate) fn in_progress_size(&self) -> usize {
        self.chunks.iter().map(Chunk::size).sum()
    }

    /// Row groups written.
    pub(crate) fn row_groups(&self) -> usize {
        self.layout.row_groups()
    }

    /// Write the rows held as a row group.
    pub(crate) fn flush(&mut self) -> io::Result<()> {
        if self.rows == 0 {
            return Ok(());
        }
        for ((chunk, dictionary), values) in self
            .chunks
            .iter_mut()
            .zip(&mut self.dictionaries)
            .zip(&self.values)
        {
            if *values != Values::Texts {
                continue;
            }
            self.pages.body.clear();
            plain_texts(
                dictionary.texts.iter().map(Vec::as_slice),
                &mut self.pages.body,
            )?;
            self.pages.dictionary_page(chunk, dictionary.texts.len())?;
            chunk.statistics.range =
                texts_range(dictionary.texts.iter().map(Vec::as_slice), &dictionary.used);
            dictionary.clear();
        }
        self.layout
            .row_group(&mut self.out, self.rows, &mut self.chunks)?;
        self.rows = 0;
        Ok(())
    }

    /// Write the last rows and the footer: the file is whole; its output, flushed.
    pub(crate) fn finish(mut self) -> io::Result<W> {
        self.flush()?;
        let metadata: Vec<(&str, &str)> = self
            .metadata
            .iter()
            .map(|(k, v)| (k.as_str(), v.as_str()))
            .collect();
        self.layout.finish(
            &self.columns,
            self.pages.compression(),
            &metadata,
            &mut self.out,
        )?;
        Ok(self.out)
    }
}

#[cfg(test)]
#[allow(
    clippy::unwrap_used,
    clippy::cast_possible_wrap,
    clippy::cast_sign_loss,
    clippy::cast_possible_truncation,
    clippy::cast_precision_loss
)]
mod tests {
    use std::sync::Arc;

    use ::parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
    use ::parquet::basic::Encoding;
    use ::parquet::file::statistics::Statistics;
    use arrow_array::{
        DictionaryArray, Float64Array, Int32Array, Int64Array, StringArray,
        TimestampNanosecondArray, UInt64Array,
    };
    use arrow_schema::{Field, Schema};
    use bytes::Bytes;
    use proptest::prelude::*;

    use super::*;
    use crate::test_support::{row_texts, xorshift};

    fn schema() -> SchemaRef {
        let texts = DataType::Dictionary(Box::new(DataType::Int32), Box::new(DataType::Utf8));
        Arc::new(Schema::new(vec![
            Field::new(
                "ts",
                DataType::Timestamp(ArrowTimeUnit::Nanosecond, Some("UTC".into())),
                false,
            ),
            Field::new("channel", texts.clone(), false),
            Field::new("int", DataType::Int64, true),
            Field::new("uint", DataType::UInt64, true),
            Field::new("float", DataType::Float64, true),
            Field::new("choice", texts, true),
        ]))
    }

    /// A batch of `rows`: `ints`, `uints`, `floats` and `choices` cycled (None: null), the
    /// choices' texts `labels`.
    #[allow(clippy::too_many_arguments)]
    fn batch(
        schema: &SchemaRef,
        ts: &[i64],
        channels: &[i32],
        channel_texts: &[&str],
        ints: &[Option<i64>],
        uints: &[Option<u64>],
        floats: &[Option<f64>],
        choices: &[Option<i32>],
        labels: &[&str],
    ) -> RecordBatch {
        let channel = DictionaryArray::new(
            Int32Array::from(channels.to_vec()),
            Arc::new(StringArray::from(channel_texts.to_vec())),
        );
        let choice = DictionaryArray::new(
            Int32Array::from(choices.to_vec()),
            Arc::new(StringArray::from(labels.to_vec())),
        );
        RecordBatch::try_new(
            schema.clone(),
            vec![
                Arc::new(TimestampNanosecondArray::from(ts.to_vec()).with_timezone("UTC")),
                Arc::new(channel),
                Arc::new(Int64Array::from(ints.to_vec())),
                Arc::new(UInt64Array::from(uints.to_vec())),
                Arc::new(Float64Array::from(floats.to_vec())),
                Arc::new(choice),
            ],
        )
        .unwrap()
    }

    fn write(batches: &[RecordBatch], compression: LakeCompression) -> Bytes {
        let mut file =
            BatchFile::try_new(Vec::new(), schema(), compression, &[("k", "v")]).unwrap();
        for batch in batches {
            file.write(batch).unwrap();
        }
        Bytes::from(file.finish().unwrap())
    }

    fn read(bytes: Bytes) -> Vec<RecordBatch> {
        ParquetRecordBatchReaderBuilder::try_new(bytes)
            .unwrap()
            .build()
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// Whatever the values (extremes, nulls, runs, any number of rows across pages),
        /// parquet-rs reads back the batches written, with their types.
        #[test]
        fn parquet_rs_reads_back_every_value_written(
            rows in 0usize..3000,
            seed in any::<u64>(),
            spread in 0u32..64,
            compression in prop_oneof![
                Just(LakeCompression::Zstd),
                Just(LakeCompression::Snappy),
                Just(LakeCompression::Gzip),
                Just(LakeCompression::Uncompressed),
            ],
        ) {
            let mut next = xorshift(seed);
            let wide = |v: u64| if spread == 63 { v } else { v & ((1u64 << spread) - 1) };
            let schema = schema();
            let labels = ["off", "on", "fault", "é"];
            let mut batches = Vec::new();
            let mut start = 0;
            let mut t = next() as i64;
            while start < rows {
                let known = (batches.len() + 1).min(3);
                let n = ((next() % 700) as usize + 1).min(rows - start);
                let mut ts = Vec::new();
                let (mut channels, mut ints, mut uints, mut floats, mut choices) =
                    (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
                for _ in 0..n {
                    t = t.wrapping_add(wide(next()) as i64);
                    ts.push(t);
                    channels.push((next() % known as u64) as i32);
                    let r = next();
                    ints.push((!r.is_multiple_of(5)).then(|| match r % 7 {
                        0 => i64::MIN,
                        1 => i64::MAX,
                        _ => (wide(next()) as i64).wrapping_sub(7),
                    }));
                    uints.push((!r.is_multiple_of(6)).then(|| match r % 11 {
                        0 => u64::MAX,
                        1 => 0,
                        _ => wide(next()),
                    }));
                    floats.push((!r.is_multiple_of(4)).then(|| match r % 13 {
                        0 => f64::NAN,
                        1 => -0.0,
                        2 => f64::INFINITY,
                        _ => (next() as f64) / 3.0 - 1e18,
                    }));
                    choices.push((!r.is_multiple_of(3)).then(|| (next() % 4) as i32));
                }
                // Channel texts grow from batch to batch, as the decoded tables' do.
                let channel_texts = &["can0", "can1", "can2"][..known];
                batches.push(batch(
                    &schema, &ts, &channels, channel_texts, &ints, &uints, &floats, &choices,
                    &labels,
                ));
                start += n;
            }
            let bytes = write(&batches, compression);
            let read = read(bytes);
            if let Some(first) = read.first() {
                prop_assert_eq!(first.schema(), schema.clone());
            }
            prop_assert_eq!(row_texts(&read), row_texts(&batches));
        }
    }

    #[test]
    fn a_batch_dictionary_that_does_not_extend_the_texts_is_mapped_to_them() {
        let schema = schema();
        let first = batch(
            &schema,
            &[1, 2],
            &[0, 1],
            &["a", "b"],
            &[None, Some(1)],
            &[Some(1), None],
            &[Some(1.5), None],
            &[Some(0), None],
            &["x"],
        );
        // The second batch's dictionaries are in another order, and one text is new.
        let second = batch(
            &schema,
            &[3, 4, 5],
            &[0, 1, 2],
            &["b", "c", "a"],
            &[Some(2), Some(3), None],
            &[None, Some(2), Some(3)],
            &[None, Some(-0.0), Some(2.0)],
            &[Some(1), Some(0), Some(2)],
            &["y", "x", "y"],
        );
        let read = read(write(
            &[first.clone(), second.clone()],
            LakeCompression::Snappy,
        ));
        assert_eq!(row_texts(&read), row_texts(&[first, second]));
        // Each text once in the dictionary ("y" twice in the batch's).
        let choice = read[0].column(5).as_dictionary::<Int32Type>();
        assert_eq!(choice.values().len(), 2);
    }

    #[test]
    fn chunks_say_their_encodings_statistics_and_metadata() {
        let schema = schema();
        let batch = batch(
            &schema,
            &[10, 30, 20],
            &[1, 1, 0],
            &["can0", "can1", "unused"],
            &[Some(-5), None, Some(7)],
            &[Some(u64::MAX), Some(3), None],
            &[Some(f64::NAN), Some(0.0), Some(-2.5)],
            &[None, Some(1), Some(1)],
            &["off", "on", "never"],
        );
        let bytes = write(&[batch], LakeCompression::Zstd);
        let reader = ParquetRecordBatchReaderBuilder::try_new(bytes).unwrap();
        let meta = reader.metadata();
        let kv = meta.file_metadata().key_value_metadata().unwrap();
        assert!(kv
            .iter()
            .any(|k| k.key == "k" && k.value.as_deref() == Some("v")));
        let group = meta.row_group(0);
        assert_eq!(group.num_rows(), 3);
        let column = |name: &str| {
            group
                .columns()
                .iter()
                .find(|c| c.column_path().string() == name)
                .unwrap()
        };
        for name in ["ts", "int", "uint"] {
            assert!(
                column(name)
                    .encodings()
                    .any(|e| e == Encoding::DELTA_BINARY_PACKED),
                "{name}"
            );
            assert!(column(name).dictionary_page_offset().is_none(), "{name}");
        }
        for name in ["channel", "choice"] {
            assert!(column(name).dictionary_page_offset().is_some(), "{name}");
        }
        let Some(Statistics::Int64(ts)) = column("ts").statistics() else {
            panic!("ts statistics");
        };
        assert_eq!((ts.min_opt(), ts.max_opt()), (Some(&10), Some(&30)));
        let Some(Statistics::Int64(int)) = column("int").statistics() else {
            panic!("int statistics");
        };
        assert_eq!(
            (int.min_opt(), int.max_opt(), int.null_count_opt()),
            (Some(&-5), Some(&7), Some(1))
        );
        let Some(Statistics::Int64(uint)) = column("uint").statistics() else {
            panic!("uint statistics");
        };
        // Unsigned: the bits of u64::MAX are the greatest.
        assert_eq!((uint.min_opt(), uint.max_opt()), (Some(&3), Some(&-1)));
        let Some(Statistics::Double(float)) = column("float").statistics() else {
            panic!("float statistics");
        };
        // NaN left out; a zero bound is -0 below.
        assert_eq!(
            float.min_opt().map(|v| v.to_bits()),
            Some((-2.5f64).to_bits())
        );
        assert_eq!(float.max_opt().map(|v| v.to_bits()), Some(0.0f64.to_bits()));
        let Some(Statistics::ByteArray(channel)) = column("channel").statistics() else {
            panic!("channel statistics");
        };
        // Only the texts rows use.
        assert_eq!(channel.min_opt().map(|b| b.data()), Some(&b"can0"[..]));
        assert_eq!(channel.max_opt().map(|b| b.data()), Some(&b"can1"[..]));
        let Some(Statistics::ByteArray(choice)) = column("choice").statistics() else {
            panic!("choice statistics");
        };
        assert_eq!(choice.min_opt().map(|b| b.data()), Some(&b"on"[..]));
        assert_eq!(choice.null_count_opt(), Some(1));
    }

    #[test]
    fn batches_of_other_columns_and_columns_of_other_types_are_refused() {
        let mut file =
            BatchFile::try_new(Vec::new(), schema(), LakeCompression::Zstd, &[]).unwrap();
        let other = Arc::new(Schema::new(vec![Field::new("ts", DataType::Int64, true)]));
        let batch =
            RecordBatch::try_new(other, vec![Arc::new(Int64Array::from(vec![Some(1)]))]).unwrap();
        assert!(file.write(&batch).is_err());
        let strings = Arc::new(Schema::new(vec![Field::new("s", DataType::Utf8, true)]));
        let Err(error) = BatchFile::try_new(Vec::new(), strings, LakeCompression::Zstd, &[]) else {
            panic!("a text column was taken");
        };
        assert!(error.to_string().contains("column s"), "{error}");
    }
}
