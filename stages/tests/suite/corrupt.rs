//! Corrupt Parquet is refused, never read as valid: robotid's own tables
//! carry their content's CRC-32, and pages written with a CRC (pyarrow's
//! `write_page_checksum`) are checked by the reader.

use std::sync::Arc;

use arrow::array::{Float64Array, Int64Array, RecordBatch, StringArray};
use arrow::datatypes::{DataType, Field, Schema};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use robotid_stages::formats::parquet::{read_parquet, write_parquet};

fn table(rows: usize) -> RecordBatch {
    let schema = Schema::new(vec![
        Field::new("sample", DataType::Int64, false),
        Field::new("joint", DataType::Utf8, false),
        Field::new("torque", DataType::Float64, false),
    ]);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    RecordBatch::try_new(
        Arc::new(schema),
        vec![
            Arc::new(Int64Array::from_iter_values(0..rows as i64)),
            Arc::new(StringArray::from_iter_values((0..rows).map(|i| format!("j{}", i % 6)))),
            Arc::new(Float64Array::from_iter_values(
                (0..rows).map(|_| rng.random_range(-50.0..50.0)),
            )),
        ],
    )
    .unwrap()
}

/// One bit flipped at 300 places of a robotid table: each read either
/// fails or gives the very same table (a flip in bytes nobody reads);
/// never other numbers.
#[test]
fn a_flipped_bit_is_refused_or_harmless() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.parquet");
    let original = table(20_000);
    write_parquet(&path, &original).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let read_back = read_parquet(&path).unwrap();
    assert_eq!(read_back.columns(), original.columns());
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let (mut refused, mut harmless) = (0, 0);
    let flipped = dir.path().join("flipped.parquet");
    for _ in 0..300 {
        let at = rng.random_range(4..bytes.len() - 8); // past the magic
        let mut b = bytes.clone();
        b[at] ^= 1 << rng.random_range(0..8);
        std::fs::write(&flipped, &b).unwrap();
        match read_parquet(&flipped) {
            Err(e) => {
                assert!(e.to_string().contains("flipped.parquet"), "{e}");
                refused += 1;
            }
            Ok(t) => {
                assert_eq!(
                    t.columns(),
                    original.columns(),
                    "byte {at}: read as valid with other values"
                );
                harmless += 1;
            }
        }
    }
    println!("300 single-bit flips: {refused} refused, {harmless} in bytes that do not change the table");
    assert!(refused > 250);
}

/// Every bit of the embedded Arrow schema (`ARROW:schema`, base64 in the
/// footer) flipped in turn: refused with a message for a person, never a
/// dump of the flatbuffer's fields (`UnionVariant { variant: … }`).
#[test]
fn a_flipped_arrow_schema_is_refused_plainly() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.parquet");
    write_parquet(&path, &table(100)).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let key = b"ARROW:schema";
    let at = bytes
        .windows(key.len())
        .rposition(|w| w == key)
        .expect("an Arrow schema")
        + key.len();
    let flipped = dir.path().join("flipped.parquet");
    let mut refused = 0;
    // The value follows its thrift header: the next 240 bytes are inside it.
    for i in at + 8..(at + 248).min(bytes.len() - 8) {
        for bit in [0, 3, 6] {
            let mut b = bytes.clone();
            b[i] ^= 1 << bit;
            std::fs::write(&flipped, &b).unwrap();
            if let Err(e) = read_parquet(&flipped) {
                let e = e.to_string();
                refused += 1;
                assert!(e.contains("flipped.parquet"), "{e}");
                assert!(
                    !e.contains("UnionVariant") && !e.contains("{ ") && e.lines().count() == 1,
                    "byte {i} bit {bit}: {e}"
                );
            }
        }
    }
    println!("{refused} flips of the Arrow schema refused, each in one plain line");
    assert!(refused > 100, "{refused}");
}

/// A file written by pyarrow with page checksums, one byte of a data page
/// changed: refused by the reader's CRC check.
#[test]
fn pyarrow_page_checksums_are_checked() {
    let python = robotid_tests::python();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("py.parquet");
    let script = format!(
        "import pyarrow as pa, pyarrow.parquet as pq\nt = pa.table({{'torque': [float(i) * 0.5 for i in range(50000)]}})\npq.write_table(t, '{}', write_page_checksum=True, compression='none')\n",
        path.display()
    );
    let o = std::process::Command::new(&python)
        .args(["-c", &script])
        .output()
        .unwrap();
    if !o.status.success() {
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!err.contains("Error") || err.contains("No module named"), "{err}");
        robotid_tests::absent(&format!("no pyarrow in {python} (bash scripts/test.sh installs it)"));
        return;
    }
    assert_eq!(read_parquet(&path).unwrap().num_rows(), 50_000);
    let mut b = std::fs::read(&path).unwrap();
    let mid = b.len() / 3; // inside the data page
    b[mid] ^= 0x10;
    std::fs::write(&path, &b).unwrap();
    let e = read_parquet(&path).unwrap_err();
    println!("{e}");
    assert!(
        e.to_string().to_lowercase().contains("crc") || e.to_string().contains("checksum"),
        "{e}"
    );
}
