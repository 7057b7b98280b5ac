//! What writing a table costs in memory beyond the table: one column chunk
//! at a time, not a row group (an 80 MB table once took 80 MB more, then 16
//! MB with row groups flushed every 8 MB). Counted by a global allocator, so
//! this file holds this one test.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;

use arrow::array::{ArrayRef, Float64Array, RecordBatch};
use arrow::datatypes::{DataType, Field, Schema};
use robotid_stages::formats::parquet::{read_parquet, write_parquet};

struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards to the system allocator; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let live = LIVE.fetch_add(layout.size(), Ordering::SeqCst) + layout.size();
        PEAK.fetch_max(live, Ordering::SeqCst);
        System.alloc(layout)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        LIVE.fetch_sub(layout.size(), Ordering::SeqCst);
        System.dealloc(ptr, layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if new_size > layout.size() {
            let live = LIVE.fetch_add(new_size - layout.size(), Ordering::SeqCst) + new_size - layout.size();
            PEAK.fetch_max(live, Ordering::SeqCst);
        } else {
            LIVE.fetch_sub(layout.size() - new_size, Ordering::SeqCst);
        }
        System.realloc(ptr, layout, new_size)
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

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
    let before = LIVE.load(Ordering::SeqCst);
    PEAK.store(before, Ordering::SeqCst);
    write_parquet(&path, &batch).unwrap();
    let extra = PEAK.load(Ordering::SeqCst) - before;
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
