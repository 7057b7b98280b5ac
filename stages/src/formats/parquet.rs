use std::path::Path;

use arrow::array::RecordBatch;
use parquet::arrow::ArrowWriter;
use parquet::basic::{Compression, ZstdLevel};
use parquet::file::properties::WriterProperties;

use super::write_atomic;
use crate::{Error, Result};

/// Writes one record batch as a Parquet file (zstd), atomically. The Arrow
/// schema, with its field and schema metadata, is stored in the file.
pub fn write_parquet(path: &Path, batch: &RecordBatch) -> Result<()> {
    let props = WriterProperties::builder()
        .set_compression(Compression::ZSTD(ZstdLevel::try_new(3).expect("valid level")))
        .build();
    let fmt = |e: parquet::errors::ParquetError| Error::Format {
        path: path.to_path_buf(),
        msg: e.to_string(),
    };
    write_atomic(path, |w| {
        let mut writer = ArrowWriter::try_new(w, batch.schema(), Some(props)).map_err(fmt)?;
        writer.write(batch).map_err(fmt)?;
        writer.close().map_err(fmt)?;
        Ok(())
    })
}

/// Reads a whole Parquet file into one record batch.
pub fn read_parquet(path: &Path) -> Result<RecordBatch> {
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let fmt = |msg: String| Error::Format {
        path: path.to_path_buf(),
        msg,
    };
    let builder =
        parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file).map_err(|e| fmt(e.to_string()))?;
    // The builder's schema carries the stored Arrow metadata.
    let schema = builder.schema().clone();
    let reader = builder.with_batch_size(65536).build().map_err(|e| fmt(e.to_string()))?;
    let batches = reader.collect::<Result<Vec<_>, _>>().map_err(|e| fmt(e.to_string()))?;
    arrow::compute::concat_batches(&schema, &batches).map_err(|e| fmt(e.to_string()))
}
