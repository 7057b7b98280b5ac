//! Rows made on demand are never whole: making the regressor rows, folding
//! the estimate's summary and writing the table each hold at most a few
//! blocks of A beyond what they keep, where A whole is the largest thing a
//! run would hold (on a 130 s recording, larger than its samples). Counted
//! by a global allocator, so this file holds this one test.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;

use robotid_stages::estimation::Summary;
use robotid_stages::formats::parquet::{read_parquet, write_parquet_groups};
use robotid_stages::signal::Spectra;
use robotid_stages::stage::regressor::regressor_rows;

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

/// What `f` allocates at its peak beyond what was live before it.
fn extra<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let before = LIVE.load(Ordering::SeqCst);
    PEAK.store(before, Ordering::SeqCst);
    let out = f();
    (out, PEAK.load(Ordering::SeqCst) - before)
}

#[test]
fn rows_made_on_demand_are_never_whole() {
    // 8000 UR5 samples: A is 48 000 rows × the base parameters, ~20 MB,
    // sixteen blocks of 512 samples.
    let (base, cfg, kin) = robotid_tests::regressor_case("robots/ur5.urdf", 8000);
    let base = Arc::new(base);
    let spectra = Spectra::new();
    let a_bytes = 8000 * 6 * base.parameters() * 8;
    let rows = |on_demand| regressor_rows(&kin, None, None, &base, &cfg, None, &spectra, "r", on_demand).unwrap();
    // The measure works: A made whole is counted.
    let (whole, with_a) = extra(|| rows(false));
    assert!(with_a > a_bytes, "A whole: {with_a} B, A {a_bytes} B");
    drop(whole);
    // Its own columns (b, variance, time, recording, sample, joint: 2.3
    // MB), a copy of the motion (1.2 MB), and a block per thread (1.3 MB
    // each): 7.3 MB when written.
    let (made, making) = extra(|| rows(true));
    eprintln!("A {a_bytes} B; beyond it: making {making} B");
    assert!(making < a_bytes / 2, "making the rows: {making} B, A {a_bytes} B");
    // A block, its weighted copy and each joint's rows of it: 2.9 MB.
    let (summary, folding) = extra(|| Summary::of_rows(&made.system, made.source(), None).unwrap());
    eprintln!("the summary {folding} B");
    assert!(folding < a_bytes / 4, "the summary: {folding} B, A {a_bytes} B");
    assert_eq!(summary.factor.rows, 48_000);
    // A group's batch (1.3 MB of A, 0.4 MB of other columns), the Parquet
    // writer's column writers and one encoded column chunk: 2.6 MB when
    // written.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("regressor.parquet");
    let ((), writing) = extra(|| {
        let (schema, groups) = made.into_groups().unwrap();
        write_parquet_groups(&path, schema, groups).unwrap();
    });
    eprintln!("writing {writing} B");
    assert!(writing < a_bytes / 3, "writing the table: {writing} B, A {a_bytes} B");
    assert_eq!(read_parquet(&path).unwrap().num_rows(), 48_000);
}
