use std::path::Path;

use arrow::array::RecordBatch;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::arrow::arrow_writer::{compute_leaves, ArrowWriterOptions};
use parquet::arrow::ArrowWriter;
use parquet::basic::{Compression, ZstdLevel};
use parquet::file::metadata::KeyValue;
use parquet::file::properties::WriterProperties;

use robotid_schemas::metadata::CONTENT_CRC32;

use super::write_atomic;
use crate::{Error, Result};

/// CRC-32 of a batch's content: every column's name, metadata and values
/// (validity included), and the schema metadata but [`CONTENT_CRC32`]
/// itself. Computed from the values, so it does not depend on how a writer
/// laid them out.
pub fn content_crc32(batch: &RecordBatch) -> u32 {
    let mut crc = ContentCrc::new(batch.schema_ref());
    crc.update(batch);
    crc.finish()
}

/// [`content_crc32`] of a table fed a batch of rows at a time: each
/// column's validity and values are hashed apart and joined at the end
/// (CRC-32 combines), so the table need not be whole.
pub struct ContentCrc {
    schema: arrow::datatypes::SchemaRef,
    columns: Vec<ColumnCrc>,
}

#[derive(Default)]
struct ColumnCrc {
    /// Validity bytes, from the first null on (`rows` valid ones before it).
    validity: Option<crc32fast::Hasher>,
    values: crc32fast::Hasher,
    rows: usize,
}

impl ContentCrc {
    pub fn new(schema: &arrow::datatypes::SchemaRef) -> ContentCrc {
        ContentCrc {
            schema: schema.clone(),
            columns: schema.fields().iter().map(|_| ColumnCrc::default()).collect(),
        }
    }

    /// Adds the next rows (a batch of the same schema).
    pub fn update(&mut self, batch: &RecordBatch) {
        use arrow::array::{Array, AsArray};
        use arrow::datatypes::ToByteSlice;
        use arrow::datatypes::{DataType, Float64Type, Int64Type};
        for (c, column) in self.columns.iter_mut().zip(batch.columns()) {
            if column.null_count() > 0 && c.validity.is_none() {
                let mut v = crc32fast::Hasher::new();
                v.update(&vec![0u8; c.rows]);
                c.validity = Some(v);
            }
            if let Some(v) = &mut c.validity {
                let bytes: Vec<u8> = (0..column.len()).map(|i| column.is_null(i) as u8).collect();
                v.update(&bytes);
            }
            let h = &mut c.values;
            match column.data_type() {
                // A null slot's value is whatever a writer left there: hashed as 0.
                DataType::Float64 if column.null_count() > 0 => {
                    for v in column.as_primitive::<Float64Type>().iter() {
                        h.update(&v.unwrap_or(0.0).to_le_bytes());
                    }
                }
                DataType::Int64 if column.null_count() > 0 => {
                    for v in column.as_primitive::<Int64Type>().iter() {
                        h.update(&v.unwrap_or(0).to_le_bytes());
                    }
                }
                DataType::Float64 => h.update(column.as_primitive::<Float64Type>().values().as_ref().to_byte_slice()),
                DataType::Int64 => h.update(column.as_primitive::<Int64Type>().values().as_ref().to_byte_slice()),
                DataType::Utf8 => {
                    for v in column.as_string::<i32>().iter() {
                        let v = v.unwrap_or("");
                        h.update(&(v.len() as u64).to_le_bytes());
                        h.update(v.as_bytes());
                    }
                }
                // Other types (none in robotid's tables): their display form,
                // values apart by U+0001.
                _ => {
                    let text = arrow::util::display::ArrayFormatter::try_new(column.as_ref(), &Default::default())
                        .map(|f| {
                            (0..column.len())
                                .map(|i| f.value(i).to_string())
                                .collect::<Vec<_>>()
                                .join("\u{1}")
                        })
                        .unwrap_or_default();
                    if c.rows > 0 && !column.is_empty() {
                        h.update("\u{1}".as_bytes());
                    }
                    h.update(text.as_bytes());
                }
            }
            c.rows += column.len();
        }
    }

    pub fn finish(self) -> u32 {
        let mut h = crc32fast::Hasher::new();
        let mut md: Vec<(&String, &String)> = self
            .schema
            .metadata()
            .iter()
            .filter(|(k, _)| k.as_str() != CONTENT_CRC32)
            .collect();
        md.sort();
        for (k, v) in md {
            h.update(k.as_bytes());
            h.update(&[0]);
            h.update(v.as_bytes());
            h.update(&[0]);
        }
        for (field, c) in self.schema.fields().iter().zip(&self.columns) {
            h.update(field.name().as_bytes());
            let mut fmd: Vec<_> = field.metadata().iter().collect();
            fmd.sort();
            for (k, v) in fmd {
                h.update(k.as_bytes());
                h.update(v.as_bytes());
            }
            if let Some(v) = &c.validity {
                h.combine(v);
            }
            h.combine(&c.values);
        }
        h.finalize()
    }
}

/// Rows per row group (arrow-rs's default). The writer encodes one column
/// chunk at a time and hands it to the file before the next, so its memory
/// is one column chunk (at most 8 MB of f64), whatever the table's width:
/// an hour's regressor table has hundreds of period columns.
const ROW_GROUP_ROWS: usize = 1 << 20;

/// Writes one record batch as a Parquet file (zstd), atomically. The Arrow
/// schema, with its field and schema metadata, is stored in the file, with
/// the content's CRC-32 ([`CONTENT_CRC32`]) that [`read_parquet`] checks.
pub fn write_parquet(path: &Path, batch: &RecordBatch) -> Result<()> {
    let rows = batch.num_rows();
    let groups = (0..rows)
        .step_by(ROW_GROUP_ROWS)
        .map(|start| Ok(batch.slice(start, ROW_GROUP_ROWS.min(rows - start))));
    write_parquet_groups(path, batch.schema(), groups)
}

/// zstd level 1; dictionaries only for text columns.
fn writer_properties(schema: &arrow::datatypes::Schema) -> WriterProperties {
    // Dictionaries only for text (recording and joint names): measured
    // numbers are nearly all distinct, and the writer's dictionary hash
    // tables for them took more memory than the table (53 MB for a 130 s,
    // 6-joint identification) before falling back to plain pages anyway.
    // zstd level 1: on measured doubles it compresses within 0.2 % of
    // level 3 (the 130 s regressor table 7.79 vs 7.78 MB) and writes 13 %
    // faster.
    let mut props = WriterProperties::builder()
        .set_compression(Compression::ZSTD(ZstdLevel::try_new(1).expect("valid level")))
        .set_dictionary_enabled(false);
    for f in schema.fields() {
        if f.data_type() == &arrow::datatypes::DataType::Utf8 {
            props =
                props.set_column_dictionary_enabled(parquet::schema::types::ColumnPath::from(f.name().as_str()), true);
        }
    }
    props.build()
}

/// The same for a table given a row group at a time, each batch made when
/// the writer asks for it (a table never whole in memory). The metadata
/// goes in at the end, with the content's CRC-32 then known.
pub fn write_parquet_groups(
    path: &Path,
    schema: arrow::datatypes::SchemaRef,
    groups: impl IntoIterator<Item = Result<RecordBatch>>,
) -> Result<()> {
    let props = writer_properties(&schema);
    let fmt = |e: parquet::errors::ParquetError| Error::Decode {
        path: path.to_path_buf(),
        source: Box::new(e),
    };
    // A CRC left from the table this one was read from is not this one's.
    let mut md = schema.metadata().clone();
    md.remove(CONTENT_CRC32);
    let schema = std::sync::Arc::new(schema.as_ref().clone().with_metadata(md));
    write_atomic(path, |w| {
        // The ArrowWriter only sets up the file (schema, the Arrow schema in
        // its metadata); the rows go through its column writers one column
        // at a time, where the ArrowWriter would hold a whole row group's
        // encoded pages (a 12 MB regressor table cost 16 MB of buffers).
        let options = ArrowWriterOptions::new()
            .with_properties(props)
            .with_skip_arrow_metadata(true);
        let (mut file, columns) = ArrowWriter::try_new_with_options(w, schema.clone(), options)
            .and_then(|writer| writer.into_serialized_writer())
            .map_err(fmt)?;
        let mut crc = ContentCrc::new(&schema);
        let mut group = 0;
        for batch in groups {
            let batch = batch?;
            if batch.schema().fields() != schema.fields() {
                return Err(Error::Format {
                    path: path.to_path_buf(),
                    msg: format!("row group {group}: its columns are not the table's"),
                });
            }
            if batch.num_rows() == 0 {
                continue;
            }
            crc.update(&batch);
            let mut row_group = file.next_row_group().map_err(fmt)?;
            let mut writers = columns.create_column_writers(group).map_err(fmt)?.into_iter();
            for (field, column) in schema.fields().iter().zip(batch.columns()) {
                for leaf in compute_leaves(field, column).map_err(fmt)? {
                    let mut writer = writers.next().expect("a writer per leaf column");
                    writer.write(&leaf).map_err(fmt)?;
                    writer
                        .close()
                        .map_err(fmt)?
                        .append_to_row_group(&mut row_group)
                        .map_err(fmt)?;
                }
            }
            row_group.close().map_err(fmt)?;
            group += 1;
        }
        // The metadata last, with the CRC now known: the table's keys as
        // the file's own key-value metadata, where readers that do not
        // decode the Arrow schema find them (DuckDB's parquet_kv_metadata,
        // polars' read_parquet_metadata), then the Arrow schema.
        let mut md = schema.metadata().clone();
        md.insert(CONTENT_CRC32.to_string(), format!("{:08x}", crc.finish()));
        let mut keys: Vec<_> = md.iter().collect();
        keys.sort();
        for (k, v) in keys {
            file.append_key_value_metadata(KeyValue::new(k.clone(), v.clone()));
        }
        let schema = schema.as_ref().clone().with_metadata(md);
        file.append_key_value_metadata(KeyValue::new(
            parquet::arrow::ARROW_SCHEMA_META_KEY.to_string(),
            parquet::arrow::encode_arrow_schema(&schema),
        ));
        file.close().map_err(fmt)?;
        Ok(())
    })
}

thread_local! {
    static GUARDED: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Runs Parquet decoding, turning a panic inside the parquet crate into an
/// error naming the file: it `expect`s on some corrupt inputs (a data page
/// that says dictionary-encoded with no dictionary page before it, found by
/// fuzzing). Such a panic is not printed; any other still is.
pub(crate) fn guarded<T>(path: &Path, f: impl FnOnce() -> Result<T>) -> Result<T> {
    static HOOK: std::sync::Once = std::sync::Once::new();
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !GUARDED.with(|g| g.get()) {
                previous(info);
            }
        }));
    });
    GUARDED.with(|g| g.set(true));
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    GUARDED.with(|g| g.set(false));
    outcome.unwrap_or_else(|p| {
        let msg = p
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| p.downcast_ref::<String>().cloned())
            .unwrap_or_default();
        Err(Error::Format {
            path: path.to_path_buf(),
            msg: format!("corrupt: the Parquet decoder gave up ({msg})"),
        })
    })
}

/// Reads a whole Parquet file into one record batch. A file robotid wrote
/// is refused when its content no longer matches its CRC-32; pages that
/// carry a CRC (pyarrow's `write_page_checksum`) are checked by the reader.
pub fn read_parquet(path: &Path) -> Result<RecordBatch> {
    guarded(path, || read_unguarded(path, super::mapped(path)?))
}

/// A Parquet file's schema metadata (its footer only, not its rows).
pub fn read_schema_metadata(path: &Path) -> Result<std::collections::BTreeMap<String, String>> {
    guarded(path, || {
        let builder = open(path)?;
        let md = builder.schema().metadata().iter();
        Ok(md.map(|(k, v)| (k.clone(), v.clone())).collect())
    })
}

/// The same, of a file's bytes in memory; `path` names it in errors.
pub fn read_parquet_bytes(path: &Path, bytes: bytes::Bytes) -> Result<RecordBatch> {
    guarded(path, || read_unguarded(path, bytes))
}

/// A reader over a Parquet file whose footer and page headers have been
/// walked within a budget first (see [`super::thrift`]).
pub(crate) fn open(path: &Path) -> Result<ParquetRecordBatchReaderBuilder<bytes::Bytes>> {
    open_bytes(path, super::mapped(path)?)
}

/// A reader's error for a person: arrow's failure to decode the embedded
/// Arrow schema holds a Rust dump of the flatbuffer's fields, said here
/// as what it means; anything else on one line.
fn plain(e: impl std::fmt::Display) -> String {
    let s = e.to_string();
    if s.contains("UnionVariant") || s.contains("Unable to get root as") || s.contains("flatbuffer") {
        return "corrupt: its embedded Arrow schema (the `ARROW:schema` key of its metadata) does not decode".into();
    }
    let line = s.lines().next().unwrap_or_default();
    match line.char_indices().nth(300) {
        Some((at, _)) => format!("{}…", &line[..at]),
        None => line.to_string(),
    }
}

/// The same over a file's bytes, `path` naming it in errors.
pub(crate) fn open_bytes(path: &Path, file: bytes::Bytes) -> Result<ParquetRecordBatchReaderBuilder<bytes::Bytes>> {
    use super::thrift::{Refusal, Walk};
    let fmt = |msg: String| Error::Format {
        path: path.to_path_buf(),
        msg,
    };
    let refused = |r: Refusal, what: &str, at: usize| {
        fmt(match r {
            Refusal::Malformed => format!("corrupt: the {what} at byte {at} is malformed"),
            Refusal::TooMuchWork => {
                format!("corrupt: the {what} at byte {at} declares more fields than the file has bytes for")
            }
        })
    };
    // Valid headers take about one step per byte; four leaves room.
    let mut budget = 4 * file.len() as u64 + 1024;
    let n = file.len();
    if n >= 12 && file[n - 4..] == *b"PAR1" {
        let len = u32::from_le_bytes(file[n - 8..n - 4].try_into().expect("4 bytes")) as usize;
        if let Some(start) = (n - 8).checked_sub(len) {
            let mut w = Walk::new(&file[start..n - 8], budget);
            w.structure().map_err(|r| refused(r, "file metadata", start))?;
            budget = w.budget();
        }
    }
    let builder = ParquetRecordBatchReaderBuilder::try_new(file.clone()).map_err(|e| fmt(plain(e)))?;
    for rg in builder.metadata().row_groups() {
        for c in rg.columns() {
            let (start, len) = c.byte_range();
            let end = start.checked_add(len).filter(|&e| e <= n as u64);
            let Some(end) = end else {
                return Err(fmt(format!(
                    "corrupt: column {} lies past the end of the file ({start} + {len} bytes of {n})",
                    c.column_path()
                )));
            };
            let mut w = Walk::new(&file[..end as usize], budget);
            let mut pos = start as usize;
            while pos < end as usize {
                w.at(pos);
                let size = w.page_header().map_err(|r| refused(r, "page header", pos))?;
                pos = usize::try_from(size)
                    .ok()
                    .and_then(|s| w.pos.checked_add(s))
                    .ok_or_else(|| fmt(format!("corrupt: the page at byte {pos} declares {size} bytes")))?;
            }
            budget = w.budget();
        }
    }
    Ok(builder)
}

fn read_unguarded(path: &Path, bytes: bytes::Bytes) -> Result<RecordBatch> {
    let fmt = |msg: String| Error::Format {
        path: path.to_path_buf(),
        msg,
    };
    let builder = open_bytes(path, bytes)?;
    // The builder's schema carries the stored Arrow metadata.
    let schema = builder.schema().clone();
    let reader = builder.with_batch_size(65536).build().map_err(|e| fmt(e.to_string()))?;
    let batches = reader.collect::<Result<Vec<_>, _>>().map_err(|e| fmt(e.to_string()))?;
    let batch = arrow::compute::concat_batches(&schema, &batches).map_err(|e| fmt(e.to_string()))?;
    if let Some(stored) = schema.metadata().get(CONTENT_CRC32) {
        let found = format!("{:08x}", content_crc32(&batch));
        if *stored != found {
            return Err(fmt(format!(
                "corrupt: its content's CRC-32 is {found}, written as {stored} (a changed byte on disk or in transfer); restore it or make it again"
            )));
        }
    }
    Ok(batch)
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use arrow::array::{Float64Array, RecordBatch};
    use arrow::buffer::{NullBuffer, ScalarBuffer};
    use arrow::datatypes::{DataType, Field, Schema};

    /// Null slots hold whatever their writer left: two batches that differ
    /// only there have one checksum (polars and Parquet readers leave
    /// different values in them).
    #[test]
    fn null_slots_do_not_change_the_content_checksum() {
        let schema = Arc::new(Schema::new(vec![Field::new("x", DataType::Float64, true)]));
        let nulls = NullBuffer::from(vec![true, false, true]);
        let batch = |hidden: f64| {
            let values = ScalarBuffer::from(vec![1.0, hidden, 3.0]);
            let column = Float64Array::new(values, Some(nulls.clone()));
            RecordBatch::try_new(schema.clone(), vec![Arc::new(column)]).unwrap()
        };
        assert_eq!(super::content_crc32(&batch(0.0)), super::content_crc32(&batch(42.0)));
        let other = Float64Array::from(vec![Some(1.0), Some(0.0), Some(3.0)]);
        let valid = RecordBatch::try_new(schema.clone(), vec![Arc::new(other)]).unwrap();
        assert_ne!(super::content_crc32(&batch(0.0)), super::content_crc32(&valid));
    }

    /// The checksum fed a batch at a time is that of the whole table, for
    /// every column type, with the first null only in a later batch and
    /// empty batches between; the groups writer stores it, and the file
    /// reads back checked and whole.
    #[test]
    fn the_checksum_of_a_table_fed_in_parts_is_that_of_the_whole() {
        use arrow::array::{ArrayRef, Int64Array, StringArray};
        let rows = 1000;
        let schema = Arc::new(
            Schema::new(vec![
                Field::new("x", DataType::Float64, true),
                Field::new("k", DataType::Int64, false),
                Field::new("s", DataType::Utf8, true),
                Field::new("b", DataType::Boolean, false),
            ])
            .with_metadata(std::collections::HashMap::from([(
                robotid_schemas::metadata::TABLE.to_string(),
                "test".to_string(),
            )])),
        );
        let columns: Vec<ArrayRef> = vec![
            Arc::new(Float64Array::from_iter(
                (0..rows).map(|i| (i != 700).then_some(i as f64 * 0.5)),
            )),
            Arc::new(Int64Array::from_iter_values(0..rows as i64)),
            Arc::new(StringArray::from_iter(
                (0..rows).map(|i| (i % 97 != 5).then(|| format!("j{}", i % 6))),
            )),
            Arc::new(arrow::array::BooleanArray::from_iter(
                (0..rows).map(|i| Some(i % 3 == 0)),
            )),
        ];
        let whole = RecordBatch::try_new(schema.clone(), columns).unwrap();
        let cuts = [0, 0, 300, 300, 650, 999, 1000];
        let parts: Vec<RecordBatch> = cuts.windows(2).map(|w| whole.slice(w[0], w[1] - w[0])).collect();
        let mut crc = super::ContentCrc::new(&schema);
        parts.iter().for_each(|p| crc.update(p));
        assert_eq!(crc.finish(), super::content_crc32(&whole));
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("groups.parquet");
        super::write_parquet_groups(&path, schema.clone(), parts.into_iter().map(Ok)).unwrap();
        let back = super::read_parquet(&path).unwrap();
        assert_eq!(back.columns(), whole.columns());
        assert_eq!(
            back.schema().metadata().get(super::CONTENT_CRC32),
            Some(&format!("{:08x}", super::content_crc32(&whole)))
        );
        // Empty parts make no row group.
        assert_eq!(super::open(&path).unwrap().metadata().row_groups().len(), 4);
    }

    /// A table's file is the same bytes whatever pool writes it.
    #[test]
    fn the_same_bytes_at_any_thread_count() {
        let rows = 5000;
        let mut fields = vec![Field::new("joint", DataType::Utf8, false)];
        let mut columns: Vec<arrow::array::ArrayRef> = vec![Arc::new(arrow::array::StringArray::from_iter_values(
            (0..rows).map(|i| format!("j{}", i % 6)),
        ))];
        for c in 0..7 {
            fields.push(Field::new(format!("c{c}"), DataType::Float64, false));
            columns.push(Arc::new(Float64Array::from_iter_values(
                (0..rows).map(|i| ((i * (c + 2)) as f64 * 1e-3).sin()),
            )));
        }
        let batch = RecordBatch::try_new(Arc::new(Schema::new(fields)), columns).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let bytes: Vec<Vec<u8>> = [1, 2, 3]
            .iter()
            .map(|&threads| {
                let path = dir.path().join(format!("t{threads}.parquet"));
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                pool.install(|| super::write_parquet(&path, &batch)).unwrap();
                std::fs::read(&path).unwrap()
            })
            .collect();
        assert_eq!(bytes[0], bytes[1]);
        assert_eq!(bytes[0], bytes[2]);
        let back = super::read_parquet(&dir.path().join("t3.parquet")).unwrap();
        assert_eq!(back.columns(), batch.columns());
    }

    /// A long table is cut into row groups of ROW_GROUP_ROWS, and reads back
    /// whole; an empty one has none. (What the writer holds meanwhile:
    /// tests/write_memory.rs.)
    #[test]
    fn long_tables_are_written_in_row_groups() {
        let rows = super::ROW_GROUP_ROWS * 2 + 7;
        let fields = vec![
            Field::new("x", DataType::Float64, false),
            Field::new("k", DataType::Int64, false),
        ];
        let columns: Vec<arrow::array::ArrayRef> = vec![
            Arc::new(Float64Array::from_iter_values((0..rows).map(|i| i as f64 * 0.37))),
            Arc::new(arrow::array::Int64Array::from_iter_values(0..rows as i64)),
        ];
        let batch = RecordBatch::try_new(Arc::new(Schema::new(fields)), columns).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("long.parquet");
        super::write_parquet(&path, &batch).unwrap();
        let groups = super::open(&path).unwrap().metadata().row_groups().to_vec();
        let sizes: Vec<i64> = groups.iter().map(|g| g.num_rows()).collect();
        let full = super::ROW_GROUP_ROWS as i64;
        assert_eq!(sizes, [full, full, 7]);
        assert_eq!(super::read_parquet(&path).unwrap().columns(), batch.columns());
        let empty = batch.slice(0, 0);
        super::write_parquet(&path, &empty).unwrap();
        assert_eq!(super::open(&path).unwrap().metadata().row_groups().len(), 0);
        assert_eq!(super::read_parquet(&path).unwrap().num_rows(), 0);
    }
}
