//! Rows made on demand are never whole: making the regressor rows, folding
//! the estimate's summary and writing the table each hold at most a few
//! blocks of A beyond what they keep, where A whole is the largest thing a
//! run would hold (on a 130 s recording, larger than its samples). Counted
//! by a global allocator, so this file holds this one test.

use robotid_stages::estimation::Summary;
use robotid_stages::formats::parquet::{read_parquet, write_parquet_groups};
use robotid_stages::signal::Spectra;
use robotid_stages::stage::regressor::regressor_rows;
use robotid_tests::extra_memory;

#[global_allocator]
static ALLOCATOR: robotid_tests::Counting = robotid_tests::Counting;

#[test]
fn rows_made_on_demand_are_never_whole() {
    // 8000 UR5 samples: A is 48 000 rows × the base parameters, ~20 MB,
    // sixteen blocks of 512 samples.
    let (base, cfg, kin) = robotid_tests::regressor_case("robots/ur5.urdf", 8000);
    let spectra = Spectra::new();
    let a_bytes = 8000 * 6 * base.parameters() * 8;
    let rows = |on_demand| regressor_rows(&kin, None, None, &base, &cfg, None, &spectra, "r", on_demand).unwrap();
    // The measure works: A made whole is counted.
    let (whole, with_a) = extra_memory(|| rows(false));
    assert!(with_a > a_bytes, "A whole: {with_a} B, A {a_bytes} B");
    drop(whole);
    // Its own columns (b, variance, time, recording, sample, joint: 2.3
    // MB), a copy of the motion (1.2 MB), and a block per thread (1.3 MB
    // each): 7.3 MB when written.
    let (made, making) = extra_memory(|| rows(true));
    eprintln!("A {a_bytes} B; beyond it: making {making} B");
    assert!(making < a_bytes / 2, "making the rows: {making} B, A {a_bytes} B");
    // A block, its weighted copy and each joint's rows of it: 2.9 MB.
    let (summary, folding) = extra_memory(|| Summary::of_rows(&made.system, made.source(), None).unwrap());
    eprintln!("the summary {folding} B");
    assert!(folding < a_bytes / 4, "the summary: {folding} B, A {a_bytes} B");
    assert_eq!(summary.factor.rows, 48_000);
    // A group's batch (1.3 MB of A, 0.4 MB of other columns), the Parquet
    // writer's column writers and one encoded column chunk: 2.6 MB when
    // written.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("regressor.parquet");
    let ((), writing) = extra_memory(|| {
        let (schema, groups) = made.into_groups().unwrap();
        write_parquet_groups(&path, schema, groups).unwrap();
    });
    eprintln!("writing {writing} B");
    assert!(writing < a_bytes / 3, "writing the table: {writing} B, A {a_bytes} B");
    assert_eq!(read_parquet(&path).unwrap().num_rows(), 48_000);
}
