//! Parquet logs: any Float64 or Int64 columns, mapped like CSV. A robotid
//! `raw_samples` file keeps its provenance (rate, period, harmonics).

use std::collections::BTreeMap;
use std::path::Path;

use arrow::array::{Array, Float64Array, Int64Array};

use super::csv::{into_columns, resolve};
use super::{Columns, ReadConfig};
use crate::formats::parquet::read_parquet;
use crate::{Error, Result};

pub(crate) fn read_parquet_log(path: &Path, cfg: &ReadConfig, joints: &[String]) -> Result<Columns> {
    let source = path.display().to_string();
    let batch = read_parquet(path)?;
    let schema = batch.schema();
    let header: Vec<String> = schema.fields().iter().map(|f| f.name().clone()).collect();
    let mapping = resolve(&header, cfg, joints, &source)?;
    let mut columns: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    let names = std::iter::once(&mapping.time)
        .chain(&mapping.position)
        .chain(&mapping.effort)
        .chain(mapping.reference.iter().flatten());
    for name in names {
        let a = batch.column(schema.index_of(name).expect("resolved"));
        let values: Vec<f64> = if let Some(f) = a.as_any().downcast_ref::<Float64Array>() {
            f.iter().map(|v| v.unwrap_or(f64::NAN)).collect()
        } else if let Some(i) = a.as_any().downcast_ref::<Int64Array>() {
            i.iter().map(|v| v.map_or(f64::NAN, |x| x as f64)).collect()
        } else {
            return Err(Error::Data {
                source_name: source,
                channel: name.clone(),
                sample: None,
                msg: format!("expected Float64 or Int64, found {}", a.data_type()),
            });
        };
        columns.insert(name.clone(), values);
    }
    let md: BTreeMap<String, String> = schema
        .metadata()
        .iter()
        .filter(|(k, _)| {
            k.starts_with("robotid.") && !k.starts_with("robotid.table") && !k.starts_with("robotid.version")
        })
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect();
    Ok(into_columns(mapping, |n| columns[n].clone(), md))
}
