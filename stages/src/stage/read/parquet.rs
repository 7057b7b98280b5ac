//! Parquet logs: any Float64 or Int64 columns, mapped like CSV, streamed
//! batch by batch with only the mapped columns decoded. A robotid
//! `raw_samples` file keeps its provenance (rate, period, harmonics).

use robotid_schemas::metadata;
use std::collections::BTreeMap;

use arrow::array::{Array, Float64Array, Int64Array, RecordBatch};
use parquet::arrow::ProjectionMask;

use super::text::{into_columns, resolve, Mapping};
use super::{Columns, Log, ReadConfig};
use crate::{Error, Result};

pub(crate) fn read_parquet_log(log: Log, cfg: &ReadConfig, joints: &[String]) -> Result<Columns> {
    crate::formats::parquet::guarded(log.path(), || read_log(log, cfg, joints))
}

/// The batch's values of each of `columns` appended to it (Float64, or
/// Int64 as f64; a null as NaN, which the checks then refuse).
fn append(batch: &RecordBatch, columns: &mut BTreeMap<String, Vec<f64>>, source: &str) -> Result<()> {
    for (name, out) in columns.iter_mut() {
        let a = batch.column(batch.schema().index_of(name).expect("projected"));
        if let Some(f) = a.as_any().downcast_ref::<Float64Array>() {
            out.extend(f.iter().map(|v| v.unwrap_or(f64::NAN)));
        } else if let Some(i) = a.as_any().downcast_ref::<Int64Array>() {
            out.extend(i.iter().map(|v| v.map_or(f64::NAN, |x| x as f64)));
        } else {
            return Err(Error::Data {
                source_name: source.to_string(),
                channel: name.clone(),
                sample: None,
                msg: format!("expected Float64 or Int64, found {}", a.data_type()),
            });
        }
    }
    Ok(())
}

fn read_log(log: Log, cfg: &ReadConfig, joints: &[String]) -> Result<Columns> {
    let path = log.path();
    let source = path.display().to_string();
    let fmt = |msg: String| Error::Format {
        path: path.to_path_buf(),
        msg,
    };
    let data = match log {
        Log::File(path) => crate::formats::mapped(path)?,
        Log::Bytes { bytes, .. } => bytes.clone(),
    };
    let bytes = data.len();
    let builder = crate::formats::parquet::open_bytes(path, data)?;
    let schema = builder.schema().clone();
    let header: Vec<String> = schema.fields().iter().map(|f| f.name().clone()).collect();
    let mapping = resolve(&header, cfg, joints, &source)?;
    let mut wanted: Vec<String> = mapping
        .time
        .iter()
        .chain(&mapping.position)
        .chain(&mapping.effort)
        .chain(mapping.reference.iter().flatten())
        .cloned()
        .collect();
    wanted.sort();
    wanted.dedup();
    let indices: Vec<usize> = wanted.iter().map(|w| schema.index_of(w).expect("resolved")).collect();
    // A log robotid wrote carries its content's CRC: then every column is
    // read, to check it (a flipped bit changed results silently), else
    // only the mapped ones.
    let stored = schema.metadata().get(metadata::CONTENT_CRC32).cloned();
    let mut crc = stored
        .as_ref()
        .map(|_| crate::formats::parquet::ContentCrc::new(&schema));
    let mask = match stored {
        Some(_) => ProjectionMask::all(),
        None => ProjectionMask::roots(builder.parquet_schema(), indices),
    };
    // The row count is the file's word: no more than its bytes can hold.
    let rows = (builder.metadata().file_metadata().num_rows().max(0) as usize).min(bytes);
    let reader = builder
        .with_projection(mask)
        .with_batch_size(65536)
        .build()
        .map_err(|e| fmt(e.to_string()))?;
    let mut columns: BTreeMap<String, Vec<f64>> =
        wanted.iter().map(|w| (w.clone(), Vec::with_capacity(rows))).collect();
    for batch in reader {
        let batch = batch.map_err(|e| fmt(format!("corrupt or truncated: {e}")))?;
        if let Some(c) = crc.as_mut() {
            c.update(&batch);
        }
        append(&batch, &mut columns, &source)?;
    }
    if let (Some(stored), Some(c)) = (stored, crc) {
        let found = format!("{:08x}", c.finish());
        if stored != found {
            return Err(fmt(format!(
                "corrupt: its content's CRC-32 is {found}, written as {stored} (a changed byte on disk or in transfer); restore it or make it again"
            )));
        }
    }
    let md: BTreeMap<String, String> = schema
        .metadata()
        .iter()
        .filter(|(k, _)| k.starts_with("robotid.") && *k != metadata::TABLE && *k != metadata::VERSION)
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect();
    Ok(into_columns_moved(mapping, columns, md))
}

/// The mapped columns out of `columns`, each moved out on its last use (a
/// column mapped twice is cloned once).
fn into_columns_moved(
    mapping: Mapping,
    mut columns: BTreeMap<String, Vec<f64>>,
    md: BTreeMap<String, String>,
) -> Columns {
    let mut uses: BTreeMap<String, usize> = BTreeMap::new();
    for n in mapping
        .time
        .iter()
        .chain(&mapping.position)
        .chain(&mapping.effort)
        .chain(mapping.reference.iter().flatten())
    {
        *uses.entry(n.clone()).or_default() += 1;
    }
    into_columns(
        mapping,
        |n| {
            let left = uses.get_mut(n).expect("mapped");
            *left -= 1;
            if *left == 0 {
                columns.remove(n).expect("read")
            } else {
                columns[n].clone()
            }
        },
        md,
    )
}
