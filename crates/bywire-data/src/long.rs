//! A decoded table (one row a frame, one column a signal: what [`crate::decoded`] builds) in
//! long form: one row a signal value, in the frames' order and, within a frame, the signals'.
//! This is the layout data lakes partition by message and query by signal:
//!
//! | column | type | |
//! |---|---|---|
//! | `ts` | timestamp (µs, UTC) | the frame's time (microseconds: what Spark holds) |
//! | `vehicle` | string, nullable | labelled only: the vehicle (null when not known) |
//! | `date` | string | labelled only: the day given, or the frame's UTC day |
//! | `channel` | string | the interface |
//! | `message` | string | labelled only: the message |
//! | `signal` | string | the signal's column name |
//! | `value` | float64 | the value (a multiplexed signal not in the frame is no row) |
//!
//! Labelled rows are for a data engine (Spark takes these batches as they are: plain strings).
//! Unlabelled rows are what a file in a lake's `vehicle=/date=/message=` folder holds, with
//! `channel` and `signal` as dictionary strings (a few texts each: a Parquet writer writes
//! their keys as they are, with no hashing of each row's text).
//!
//! Built in one pass over the frames, with no per-row allocation: each row's texts are kept as
//! keys, made into strings (labelled) or dictionaries (unlabelled) at the end.

use std::collections::HashMap;
use std::sync::Arc;

use arrow_array::cast::AsArray;
use arrow_array::types::{Float64Type, Int32Type, Int64Type, TimestampNanosecondType, UInt64Type};
use arrow_array::{
    Array, ArrayRef, DictionaryArray, Float64Array, Int32Array, RecordBatch, StringArray,
    TimestampMicrosecondArray,
};
use arrow_schema::{DataType, Field, Schema, SchemaRef, TimeUnit};

use bywire_log::calendar;
use bywire_log::candump::LogError;

/// What labels a long table's rows carry besides the decoded table's own columns.
#[derive(Debug, Clone, Copy)]
pub struct LongLabels<'a> {
    /// The message the decoded table is of.
    pub message: &'a str,
    /// The vehicle (null when `None`).
    pub vehicle: Option<&'a str>,
    /// The day; `None`: each row's UTC day from its time.
    pub date: Option<&'a str>,
}

/// The long table's schema: labelled (every column of the module's table, strings plain) or
/// not (`ts`, `channel`, `signal`, `value`, strings as dictionaries).
pub fn long_schema(labelled: bool) -> SchemaRef {
    let text = |name: &str| Field::new(name, DataType::Utf8, true);
    let label = |name: &str| {
        if labelled {
            text(name)
        } else {
            Field::new(name, bywire_log::parquet::dictionary_type(), true)
        }
    };
    let mut fields = vec![Field::new(
        "ts",
        DataType::Timestamp(TimeUnit::Microsecond, Some("UTC".into())),
        true,
    )];
    if labelled {
        fields.extend([text("vehicle"), text("date")]);
    }
    fields.push(label("channel"));
    if labelled {
        fields.push(text("message"));
    }
    fields.extend([
        label("signal"),
        Field::new("value", DataType::Float64, true),
    ]);
    Arc::new(Schema::new(fields))
}

/// A decoded table's columns, read where they are (also what [`crate::lake`] writes from).
pub(crate) struct Wide<'a> {
    pub(crate) ts: &'a arrow_array::PrimitiveArray<TimestampNanosecondType>,
    pub(crate) channel: Channels<'a>,
    /// Each value column's name and its values (multiplexed ones with nulls).
    pub(crate) values: Vec<(&'a str, ValueColumn<'a>)>,
}

/// Each row's channel as a key into `texts`: the keys of a dictionary column as they are, or
/// a plain column's texts numbered as they are first seen.
pub(crate) struct Channels<'a> {
    pub(crate) texts: Vec<&'a str>,
    rows: ChannelRows<'a>,
}

enum ChannelRows<'a> {
    Dictionary(&'a arrow_array::PrimitiveArray<Int32Type>),
    Plain {
        texts: &'a arrow_array::StringArray,
        keys: HashMap<&'a str, i32>,
    },
}

impl<'a> Channels<'a> {
    fn of(column: &'a ArrayRef) -> Result<Self, String> {
        match column.data_type() {
            DataType::Utf8 => Ok(Channels {
                texts: Vec::new(),
                rows: ChannelRows::Plain {
                    texts: column.as_string(),
                    keys: HashMap::new(),
                },
            }),
            DataType::Dictionary(key, value)
                if **key == DataType::Int32 && **value == DataType::Utf8 =>
            {
                let dictionary = column.as_dictionary::<Int32Type>();
                let texts = dictionary
                    .values()
                    .as_string_opt::<i32>()
                    .ok_or("`channel`'s dictionary holds strings")?;
                Ok(Channels {
                    // A null text is never a row's: `key` sends its rows to null.
                    texts: texts.iter().map(|t| t.unwrap_or_default()).collect(),
                    rows: ChannelRows::Dictionary(dictionary.keys()),
                })
            }
            other => Err(format!("`channel` is a string column, not {other}")),
        }
    }

    /// The row's key into `texts`, or none (a null channel).
    pub(crate) fn key(&mut self, row: usize) -> Option<i32> {
        match &mut self.rows {
            ChannelRows::Dictionary(keys) => {
                let key = keys.is_valid(row).then(|| keys.value(row))?;
                let text = usize::try_from(key).ok()?;
                (text < self.texts.len()).then_some(key)
            }
            ChannelRows::Plain { texts, keys } => {
                let text = texts.is_valid(row).then(|| texts.value(row))?;
                if let Some(key) = keys.get(text) {
                    return Some(*key);
                }
                let key = i32::try_from(self.texts.len()).ok()?;
                keys.insert(text, key);
                self.texts.push(text);
                Some(key)
            }
        }
    }
}

/// A signal's values as the decoded table typed them.
pub(crate) enum ValueColumn<'a> {
    Int(&'a arrow_array::PrimitiveArray<Int64Type>),
    UInt(&'a arrow_array::PrimitiveArray<UInt64Type>),
    Float(&'a arrow_array::PrimitiveArray<Float64Type>),
}

impl ValueColumn<'_> {
    fn of(column: &ArrayRef) -> Option<ValueColumn<'_>> {
        match column.data_type() {
            DataType::Int64 => Some(ValueColumn::Int(column.as_primitive())),
            DataType::UInt64 => Some(ValueColumn::UInt(column.as_primitive())),
            DataType::Float64 => Some(ValueColumn::Float(column.as_primitive())),
            _ => None,
        }
    }

    fn present(&self) -> usize {
        match self {
            ValueColumn::Int(a) => a.len() - a.null_count(),
            ValueColumn::UInt(a) => a.len() - a.null_count(),
            ValueColumn::Float(a) => a.len() - a.null_count(),
        }
    }

    /// The row's value as a double (what cantools' values give through `float()`), or none.
    #[allow(clippy::cast_precision_loss)] // as Python's float(int): the nearest double
    pub(crate) fn value(&self, row: usize) -> Option<f64> {
        match self {
            ValueColumn::Int(a) => a.is_valid(row).then(|| a.value(row) as f64),
            ValueColumn::UInt(a) => a.is_valid(row).then(|| a.value(row) as f64),
            ValueColumn::Float(a) => a.is_valid(row).then(|| a.value(row)),
        }
    }
}

impl<'a> Wide<'a> {
    pub(crate) fn of(table: &'a RecordBatch) -> Result<Self, LogError> {
        let wrong = |what: String| LogError::Table { row: 0, what };
        let schema = table.schema_ref();
        let column = |name: &str| {
            schema
                .index_of(name)
                .ok()
                .and_then(|at| table.columns().get(at))
                .ok_or_else(|| wrong(format!("a decoded table has a `{name}` column")))
        };
        let ts = column("ts")?;
        let ts = match ts.data_type() {
            DataType::Timestamp(TimeUnit::Nanosecond, _) => ts.as_primitive(),
            other => {
                return Err(wrong(format!(
                    "`ts` is a nanosecond timestamp, not {other}"
                )))
            }
        };
        let channel = Channels::of(column("channel")?).map_err(wrong)?;
        // Every numeric column is a signal's; `ts`, `channel` and the choices' dictionary
        // columns are not.
        let values = schema
            .fields()
            .iter()
            .zip(table.columns())
            .filter(|(field, _)| field.name() != "ts")
            .filter_map(|(field, column)| Some((field.name().as_str(), ValueColumn::of(column)?)))
            .collect();
        Ok(Wide {
            ts,
            channel,
            values,
        })
    }
}

/// `table` (a decoded table: `ts` in nanoseconds, `channel`, then the signals' numeric
/// columns) in long form, labelled with `labels` or not (see [`long_schema`]). Times are
/// floored to the microsecond.
pub fn signals_long(
    table: &RecordBatch,
    labels: Option<&LongLabels<'_>>,
) -> Result<RecordBatch, LogError> {
    let mut wide = Wide::of(table)?;
    let rows: usize = wide.values.iter().map(|(_, column)| column.present()).sum();
    let mut ts = Vec::with_capacity(rows);
    let mut channels: Vec<Option<i32>> = Vec::with_capacity(rows);
    let mut signals: Vec<i32> = Vec::with_capacity(rows);
    let mut values = Vec::with_capacity(rows);
    // Each row's day (labelled, without a date given): its number, and each day's text once.
    let by_day = matches!(labels, Some(LongLabels { date: None, .. }));
    let mut days: Vec<i32> = Vec::new();
    let mut day_texts: Vec<(i64, String)> = Vec::new();
    for row in 0..table.num_rows() {
        if wide.ts.is_null(row) {
            continue;
        }
        let nanos = wide.ts.value(row);
        let channel = wide.channel.key(row);
        let day = if by_day {
            let number = nanos.div_euclid(86_400_000_000_000);
            if day_texts.last().is_none_or(|(n, _)| *n != number) {
                let (year, month, of_month) = calendar::civil_from_days(number);
                day_texts.push((number, format!("{year:04}-{month:02}-{of_month:02}")));
            }
            i32::try_from(day_texts.len() - 1).unwrap_or(i32::MAX)
        } else {
            0
        };
        for (signal, (_, column)) in (0i32..).zip(&wide.values) {
            let Some(value) = column.value(row) else {
                continue;
            };
            ts.push(nanos.div_euclid(1000));
            channels.push(channel);
            signals.push(signal);
            values.push(value);
            if by_day {
                days.push(day);
            }
        }
    }
    let signal_texts: Vec<&str> = wide.values.iter().map(|(name, _)| *name).collect();
    let ts = TimestampMicrosecondArray::from(ts).with_timezone("UTC");
    let mut columns: Vec<ArrayRef> = vec![Arc::new(ts)];
    match labels {
        Some(labels) => {
            let repeated = |text: Option<&str>| -> ArrayRef {
                Arc::new(StringArray::from_iter(std::iter::repeat_n(
                    text,
                    values.len(),
                )))
            };
            columns.push(repeated(labels.vehicle));
            columns.push(match labels.date {
                Some(date) => repeated(Some(date)),
                None => Arc::new(StringArray::from_iter(days.iter().map(|d| {
                    usize::try_from(*d)
                        .ok()
                        .and_then(|d| day_texts.get(d))
                        .map(|(_, text)| text.as_str())
                }))),
            });
            columns.push(plain(&channels, &wide.channel.texts));
            columns.push(repeated(Some(labels.message)));
            let signals: Vec<Option<i32>> = signals.into_iter().map(Some).collect();
            columns.push(plain(&signals, &signal_texts));
        }
        None => {
            columns.push(dictionary(
                channels.into_iter().collect(),
                &wide.channel.texts,
            )?);
            columns.push(dictionary(
                signals.into_iter().map(Some).collect(),
                &signal_texts,
            )?);
        }
    }
    columns.push(Arc::new(Float64Array::from(values)));
    RecordBatch::try_new(long_schema(labels.is_some()), columns).map_err(|e| LogError::Table {
        row: 0,
        what: e.to_string(),
    })
}

/// Keys into `texts` as a plain string column.
fn plain(keys: &[Option<i32>], texts: &[&str]) -> ArrayRef {
    let text = |key: &Option<i32>| {
        key.and_then(|k| usize::try_from(k).ok())
            .and_then(|k| texts.get(k).copied())
    };
    Arc::new(StringArray::from_iter(keys.iter().map(text)))
}

/// Keys into `texts` as a dictionary string column.
fn dictionary(keys: Int32Array, texts: &[&str]) -> Result<ArrayRef, LogError> {
    let values: ArrayRef = Arc::new(StringArray::from_iter_values(texts));
    DictionaryArray::try_new(keys, values)
        .map(|array| Arc::new(array) as ArrayRef)
        .map_err(|e| LogError::Table {
            row: 0,
            what: e.to_string(),
        })
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;
    use arrow_array::{DictionaryArray, Float64Array, Int64Array, StringArray, UInt64Array};

    /// Two frames of a message with a plain and a multiplexed signal and a choice column.
    fn decoded() -> RecordBatch {
        let ts = arrow_array::TimestampNanosecondArray::from(vec![
            1_764_633_599_999_999_999, // 2025-12-01T23:59:59.999999999Z
            1_764_633_600_000_001_500, // 2025-12-02, 1.5 µs on
        ])
        .with_timezone("UTC");
        let channel: DictionaryArray<Int32Type> = vec!["can0", "can1"].into_iter().collect();
        let schema = Schema::new(vec![
            Field::new("ts", ts.data_type().clone(), false),
            Field::new("channel", channel.data_type().clone(), false),
            Field::new("Speed", DataType::Float64, true),
            Field::new("Gear", DataType::Int64, true),
            Field::new("Gear_choice", channel.data_type().clone(), true),
            Field::new("Counter", DataType::UInt64, true),
        ]);
        let choices: DictionaryArray<Int32Type> = vec![Some("Drive"), None].into_iter().collect();
        RecordBatch::try_new(
            Arc::new(schema),
            vec![
                Arc::new(ts),
                Arc::new(channel),
                Arc::new(Float64Array::from(vec![1.5, -0.25])),
                Arc::new(Int64Array::from(vec![Some(3), None])),
                Arc::new(choices),
                Arc::new(UInt64Array::from(vec![u64::MAX, 7])),
            ],
        )
        .unwrap()
    }

    /// A plain or dictionary string column's texts.
    fn texts(batch: &RecordBatch, name: &str) -> Vec<Option<String>> {
        let column = batch.column_by_name(name).unwrap();
        if let Some(dictionary) = column.as_dictionary_opt::<Int32Type>() {
            let values = dictionary.values().as_string::<i32>();
            let keys = dictionary.keys().iter();
            return keys
                .map(|k| k.map(|k| values.value(usize::try_from(k).unwrap()).to_string()))
                .collect();
        }
        let column = column.as_string::<i32>();
        column.iter().map(|t| t.map(str::to_string)).collect()
    }

    #[test]
    fn each_value_is_a_row_in_frame_order() {
        let long = signals_long(&decoded(), None).unwrap();
        assert_eq!(long.schema(), long_schema(false));
        let signals = texts(&long, "signal");
        let names: Vec<_> = signals.iter().map(|s| s.as_deref().unwrap()).collect();
        assert_eq!(names, ["Speed", "Gear", "Counter", "Speed", "Counter"]);
        let values = long
            .column_by_name("value")
            .unwrap()
            .as_primitive::<Float64Type>();
        assert_eq!(
            values.values().to_vec(),
            [1.5, 3.0, u64::MAX as f64, -0.25, 7.0]
        );
        let channels = texts(&long, "channel");
        assert_eq!(channels[0].as_deref(), Some("can0"));
        assert_eq!(channels[4].as_deref(), Some("can1"));
        let ts = long
            .column(0)
            .as_primitive::<arrow_array::types::TimestampMicrosecondType>();
        assert_eq!(ts.value(0), 1_764_633_599_999_999);
        assert_eq!(ts.value(3), 1_764_633_600_000_001);
    }

    #[test]
    fn labels_are_given_or_taken_from_the_time() {
        let table = decoded();
        let by_time = LongLabels {
            message: "Drive",
            vehicle: None,
            date: None,
        };
        let long = signals_long(&table, Some(&by_time)).unwrap();
        assert_eq!(long.schema(), long_schema(true));
        let dates = texts(&long, "date");
        let days: Vec<_> = dates.iter().map(|d| d.as_deref().unwrap()).collect();
        assert_eq!(
            days,
            [
                "2025-12-01",
                "2025-12-01",
                "2025-12-01",
                "2025-12-02",
                "2025-12-02"
            ]
        );
        assert!(texts(&long, "vehicle").iter().all(Option::is_none));
        assert!(texts(&long, "message")
            .iter()
            .all(|m| m.as_deref() == Some("Drive")));
        let given = LongLabels {
            message: "Drive",
            vehicle: Some("tug7"),
            date: Some("2026-01-01"),
        };
        let long = signals_long(&table, Some(&given)).unwrap();
        assert!(texts(&long, "date")
            .iter()
            .all(|d| d.as_deref() == Some("2026-01-01")));
        assert!(texts(&long, "vehicle")
            .iter()
            .all(|v| v.as_deref() == Some("tug7")));
    }

    #[test]
    fn a_plain_channel_column_reads_as_a_dictionary_one() {
        let table = decoded();
        let mut columns = table.columns().to_vec();
        columns[1] = Arc::new(StringArray::from(vec!["can1", "can0"]));
        let mut fields: Vec<Field> = table
            .schema()
            .fields()
            .iter()
            .map(|f| f.as_ref().clone())
            .collect();
        fields[1] = Field::new("channel", DataType::Utf8, false);
        let plain = RecordBatch::try_new(Arc::new(Schema::new(fields)), columns).unwrap();
        let by_key = signals_long(&plain, None).unwrap();
        let channels = texts(&by_key, "channel");
        let channels: Vec<_> = channels.iter().map(|c| c.as_deref().unwrap()).collect();
        assert_eq!(channels, ["can1", "can1", "can1", "can0", "can0"]);
        let labels = LongLabels {
            message: "Drive",
            vehicle: None,
            date: Some("2026-01-01"),
        };
        let labelled = signals_long(&plain, Some(&labels)).unwrap();
        assert_eq!(texts(&labelled, "channel"), texts(&by_key, "channel"));
        assert_eq!(texts(&labelled, "signal"), texts(&by_key, "signal"));
    }

    #[test]
    fn a_table_that_is_not_decoded_is_named() {
        let plain = RecordBatch::try_new(
            Arc::new(Schema::new(vec![Field::new(
                "channel",
                DataType::Utf8,
                false,
            )])),
            vec![Arc::new(StringArray::from(vec!["can0"]))],
        )
        .unwrap();
        let error = signals_long(&plain, None).unwrap_err().to_string();
        assert!(error.contains("`ts`"), "{error}");
    }
}
