//! What the Parquet modules' tests share.

#![allow(clippy::unwrap_used)]

use arrow_array::cast::AsArray;
use arrow_array::types::{Float64Type, Int32Type, Int64Type, TimestampNanosecondType, UInt64Type};
use arrow_array::{Array, RecordBatch};
use arrow_schema::DataType;

/// A table's cell as text: values, descriptions and channels alike ("null" for none).
pub(crate) fn cell(column: &dyn Array, row: usize) -> String {
    if column.is_null(row) {
        return "null".into();
    }
    match column.data_type() {
        DataType::Int64 => column.as_primitive::<Int64Type>().value(row).to_string(),
        DataType::UInt64 => column.as_primitive::<UInt64Type>().value(row).to_string(),
        DataType::Float64 => format!("{:?}", column.as_primitive::<Float64Type>().value(row)),
        DataType::Timestamp(..) => column
            .as_primitive::<TimestampNanosecondType>()
            .value(row)
            .to_string(),
        DataType::Dictionary(..) => {
            let d = column.as_dictionary::<Int32Type>();
            let key = usize::try_from(d.keys().value(row)).unwrap();
            d.values().as_string::<i32>().value(key).to_string()
        }
        other => panic!("unexpected column type {other}"),
    }
}

/// Each row of `batches` as its cells' text, joined by commas.
pub(crate) fn row_texts<'b>(batches: impl IntoIterator<Item = &'b RecordBatch>) -> Vec<String> {
    let mut rows = Vec::new();
    for batch in batches {
        for row in 0..batch.num_rows() {
            let cells: Vec<String> = batch
                .columns()
                .iter()
                .map(|c| cell(c.as_ref(), row))
                .collect();
            rows.push(cells.join(","));
        }
    }
    rows
}

/// A xorshift generator from `seed`: test data of many shapes, the same for a seed.
pub(crate) fn xorshift(seed: u64) -> impl FnMut() -> u64 {
    let mut state = seed | 1;
    move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    }
}
