//! What writing a table costs in memory beyond the table: one column chunk
//! at a time, not a row group (an 80 MB table once took 80 MB more, then 16
//! MB with row groups flushed every 8 MB). Counted by a global allocator, so
//! this file holds this one test.

use std::sync::Arc;

use arrow::array::{ArrayRef, Float64Array, RecordBatch};
use arrow::datatypes::{DataType, Field, Schema};
use robotid_stages::formats::parquet::{read_parquet, write_parquet};

#[global_allocator]
static ALLOCATOR: robotid_tests::Counting = robotid_tests::Counting;

#[test]
fn writing_holds_about_one_column_chunk() {
    const ROWS: usize = 250_000;
    const COLUMNS: usize = 40;
    let fields: Vec<Field> = (0..COLUMNS)
        .map(|c| Field::new(format!("c{c}"), DataType::Float64, false))
        .collect();
    // Values that hardly compress, as measured torques do.
    let columns: Vec<ArrayRef> = (0..COLUMNS)
        .map(|c| {
            Arc::new(Float64Array::from_iter_values(
                (0..ROWS).map(|i| ((i * COLUMNS + c) as f64 * 0.618_033_988_7).sin()),
            )) as _
        })
        .collect();
    let batch = RecordBatch::try_new(Arc::new(Schema::new(fields)), columns).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("wide.parquet");
    let ((), extra) = robotid_tests::extra_memory(|| write_parquet(&path, &batch).unwrap());
    let table = ROWS * COLUMNS * 8;
    let column = ROWS * 8;
    // The column's encoded pages plus the writer's per-page and zstd
    // buffers: within three columns' values.
    assert!(
        extra < 3 * column,
        "writing an {:.0} MB table took {:.2} MB beyond it; a column is {:.2} MB",
        table as f64 / 1e6,
        extra as f64 / 1e6,
        column as f64 / 1e6
    );
    eprintln!(
        "writing an {:.0} MB table took {:.2} MB beyond it (a column: {:.2} MB)",
        table as f64 / 1e6,
        extra as f64 / 1e6,
        column as f64 / 1e6
    );
    assert_eq!(read_parquet(&path).unwrap().columns(), batch.columns());
}
