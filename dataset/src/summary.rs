//! `robotid dataset summary`: one row per run, recording and joint — what
//! the recording gave (samples, periods, noise floor), what the estimate
//! made of it (residual variance, adequacy verdict, the joint's parameter
//! values) — and the parameters' drift across runs ordered by time.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use crate::error::{io, Error, Result};
use arrow::array::{ArrayRef, Float64Array, Int64Array, RecordBatch, StringArray};
use arrow::datatypes::{Field, Schema};
use polars::prelude::*;
use serde::Deserialize;

use crate::runs::{RecordingEntry, Run};
use robotid_schemas::metadata;

/// The two tables of a summary.
pub struct Summary {
    /// Kind `dataset_summary`: one row per run × recording × joint.
    pub recordings: DataFrame,
    /// Kind `parameter_drift`: one row per parameter × run, runs of the
    /// same robot file and pipeline ordered by time.
    pub drift: DataFrame,
    /// Units of the columns that have one.
    pub units: BTreeMap<String, String>,
}

/// A Parquet file's key-value metadata (its footer only).
fn file_keys(path: &Path) -> Result<BTreeMap<String, String>> {
    let file = std::fs::File::open(path).map_err(io(path))?;
    let md = ParquetReader::new(file)
        .get_metadata()
        .map_err(|source| Error::Read {
            path: path.to_path_buf(),
            source,
        })?
        .clone();
    Ok(md
        .key_value_metadata()
        .iter()
        .flatten()
        .filter_map(|kv| Some((kv.key.clone(), kv.value.clone()?)))
        .collect())
}

/// One joint's entry of `robotid.estimate.adequacy`.
#[derive(Deserialize)]
struct Adequacy {
    joint: String,
    msr: f64,
    noise_floor: Option<f64>,
    ratio: Option<f64>,
    verdict: String,
}

/// One parameter of one run.
struct Parameter {
    name: String,
    unit: String,
    value: f64,
    std: f64,
}

/// The parameters of every run that estimated, in one lazy scan.
fn scan_parameters(runs: &[Run]) -> Result<BTreeMap<usize, Vec<Parameter>>> {
    let files: Vec<(usize, String)> = runs
        .iter()
        .enumerate()
        .filter_map(|(i, r)| Some((i, r.dir.join(r.manifest.parameters.as_ref()?).display().to_string())))
        .collect();
    let mut out = BTreeMap::new();
    if files.is_empty() {
        return Ok(out);
    }
    // One lazy scan per file (their covariance columns differ), each cut
    // to the columns read here, then concatenated.
    let scans = files
        .iter()
        .map(|(i, p)| {
            // The `key=value` folders are the runs' columns already.
            let args = ScanArgsParquet {
                hive_options: HiveOptions::new_disabled(),
                ..Default::default()
            };
            let lf = LazyFrame::scan_parquet(PlRefPath::new(p.as_str()), args)?;
            Ok(lf.select([
                lit(*i as i64).cast(DataType::Int64).alias("run"),
                col("name"),
                col("unit"),
                col("value"),
                col("std"),
            ]))
        })
        .collect::<PolarsResult<Vec<_>>>();
    let df = scans
        .and_then(|lfs| concat(lfs, UnionArgs::default())?.collect())
        .map_err(|source| Error::Polars {
            what: "reading the runs' parameters tables".into(),
            source,
        })?;
    let (run, name, unit) = (
        df.column("run")?.i64()?,
        df.column("name")?.str()?,
        df.column("unit")?.str()?,
    );
    let (value, std) = (df.column("value")?.f64()?, df.column("std")?.f64()?);
    for i in 0..df.height() {
        out.entry(run.get(i).unwrap_or_default() as usize)
            .or_insert_with(Vec::new)
            .push(Parameter {
                name: name.get(i).unwrap_or_default().to_string(),
                unit: unit.get(i).unwrap_or_default().to_string(),
                value: value.get(i).unwrap_or(f64::NAN),
                std: std.get(i).unwrap_or(f64::NAN),
            });
    }
    Ok(out)
}

/// Column builders keyed by name, in insertion order of first use.
#[derive(Default)]
struct Columns {
    order: Vec<String>,
    text: BTreeMap<String, Vec<Option<String>>>,
    float: BTreeMap<String, Vec<Option<f64>>>,
    int: BTreeMap<String, Vec<Option<i64>>>,
    rows: usize,
}

/// Appends `v` to the column `name` of `map`, padding it with nulls to
/// `rows` first (a run that lacked the column until now).
fn push<T: Clone>(map: &mut BTreeMap<String, Vec<Option<T>>>, rows: usize, name: &str, v: Option<T>) {
    let c = map.entry(name.to_string()).or_default();
    c.resize(rows, None);
    c.push(v);
}

impl Columns {
    fn note(&mut self, name: &str) {
        if !self.order.iter().any(|n| n == name) {
            self.order.push(name.to_string());
        }
    }
    fn text(&mut self, name: &str, v: Option<String>) {
        self.note(name);
        push(&mut self.text, self.rows, name, v);
    }
    fn float(&mut self, name: &str, v: Option<f64>) {
        self.note(name);
        push(&mut self.float, self.rows, name, v);
    }
    fn int(&mut self, name: &str, v: Option<i64>) {
        self.note(name);
        push(&mut self.int, self.rows, name, v);
    }
    fn end_row(&mut self) {
        self.rows += 1;
    }
    fn frame(mut self) -> PolarsResult<DataFrame> {
        let n = self.rows;
        let mut cols = Vec::with_capacity(self.order.len());
        for name in &self.order {
            let s = if let Some(mut v) = self.text.remove(name) {
                v.resize(n, None);
                Column::new(name.as_str().into(), v)
            } else if let Some(mut v) = self.float.remove(name) {
                v.resize(n, None);
                Column::new(name.as_str().into(), v)
            } else {
                let mut v = self.int.remove(name).unwrap_or_default();
                v.resize(n, None);
                Column::new(name.as_str().into(), v)
            };
            cols.push(s);
        }
        DataFrame::new(n, cols)
    }
}

/// The hive keys of every run, in the order first seen.
fn hive_keys(runs: &[Run]) -> Vec<String> {
    let mut seen = Vec::new();
    for r in runs {
        for (k, _) in &r.hive {
            if !seen.contains(k) {
                seen.push(k.clone());
            }
        }
    }
    seen
}

/// The units of the recordings table's fixed columns.
fn fixed_units() -> BTreeMap<String, String> {
    let mut units = BTreeMap::new();
    for (k, u) in [
        ("time_origin_s", "s"),
        ("samples", "count"),
        ("periods", "count"),
        ("noise_var_q", "rad^2"),
        ("noise_var_torque", "N^2*m^2"),
        ("noise_floor", "N^2*m^2"),
        ("residual_variance", "N^2*m^2"),
        ("adequacy_ratio", "1"),
    ] {
        units.insert(k.to_string(), u.to_string());
    }
    units
}

/// The per-joint adequacy the run's estimate wrote (none without one).
fn adequacy_of(run: &Run) -> Result<Vec<Adequacy>> {
    let m = &run.manifest;
    let param_keys = match &m.parameters {
        Some(p) => file_keys(&run.dir.join(p))?,
        None => BTreeMap::new(),
    };
    Ok(match param_keys.get(metadata::ADEQUACY) {
        Some(text) => serde_json::from_str(text).map_err(|source| Error::Json {
            path: run.dir.clone(),
            what: metadata::ADEQUACY,
            source,
        })?,
        None => Vec::new(),
    })
}

/// One recording of a run, with what its tables' footers say.
struct Recorded<'a> {
    run: &'a Run,
    rec: &'a RecordingEntry,
    keys: &'a BTreeMap<String, String>,
    adequacy: &'a [Adequacy],
    params: &'a [Parameter],
}

/// A recording's rows, one per joint: its hive keys, hashes, noise,
/// adequacy and the joint's parameters (their units into `units`).
fn recording_rows(rows: &mut Columns, units: &mut BTreeMap<String, String>, at: &Recorded, hive_keys: &[String]) {
    let number = |k: &str| at.keys.get(k).and_then(|v| v.parse::<f64>().ok());
    let time = number(metadata::TIME_ORIGIN_S);
    let mut joints: Vec<String> = at
        .keys
        .get(metadata::JOINTS)
        .map(|j| j.split(',').map(str::to_string).collect())
        .unwrap_or_default();
    if joints.is_empty() {
        joints = at.adequacy.iter().map(|a| a.joint.clone()).collect();
    }
    for joint in &joints {
        for k in hive_keys {
            let v = at.run.hive.iter().find(|(hk, _)| hk == k).map(|(_, v)| v.clone());
            rows.text(k, v);
        }
        rows.text("run", Some(at.run.name.clone()));
        rows.text("recording", Some(at.rec.name.clone()));
        rows.text("joint", Some(joint.clone()));
        rows.text("robot_sha256", at.run.manifest.robot_sha256.clone());
        rows.text("config_sha256", Some(at.run.manifest.config_sha256.clone()));
        rows.text("source_sha256", Some(at.rec.source_sha256.clone()));
        rows.float("time_origin_s", time);
        rows.int("samples", Some(at.rec.samples as i64));
        rows.int("periods", number(metadata::PERIODS).map(|p| p as i64));
        rows.float(
            "noise_var_q",
            number(&format!("{}.{joint}.q.var_time", metadata::NOISE_PREFIX)),
        );
        rows.float(
            "noise_var_torque",
            number(&format!("{}.{joint}.torque.var_time", metadata::NOISE_PREFIX)),
        );
        let a = at.adequacy.iter().find(|a| &a.joint == joint);
        rows.float("residual_variance", a.map(|a| a.msr));
        rows.float("noise_floor", a.and_then(|a| a.noise_floor));
        rows.float("adequacy_ratio", a.and_then(|a| a.ratio));
        rows.text("verdict", a.map(|a| a.verdict.clone()));
        // The joint's parameters, one column per name without the
        // joint suffix (ZZ, Fv, …).
        for p in at.params {
            if let Some(stem) = p.name.strip_suffix(&format!("_{joint}")) {
                rows.float(stem, Some(p.value));
                units.entry(stem.to_string()).or_insert_with(|| p.unit.clone());
            }
        }
        rows.end_row();
    }
}

/// One drift row per parameter of a run (`run_time`: its earliest
/// recording's time origin).
fn drift_rows_of(
    drift_rows: &mut Columns,
    run: &Run,
    params: &[Parameter],
    hive_keys: &[String],
    run_time: Option<f64>,
) {
    let m = &run.manifest;
    for p in params {
        for k in hive_keys {
            let v = run.hive.iter().find(|(hk, _)| hk == k).map(|(_, v)| v.clone());
            drift_rows.text(k, v);
        }
        drift_rows.text("robot_sha256", m.robot_sha256.clone());
        drift_rows.text("config_sha256", Some(m.config_sha256.clone()));
        drift_rows.text("parameter", Some(p.name.clone()));
        drift_rows.text("unit", Some(p.unit.clone()));
        drift_rows.text("run", Some(run.name.clone()));
        let names: Vec<&str> = m.recordings.iter().map(|r| r.name.as_str()).collect();
        drift_rows.text("recordings", Some(names.join(",")));
        drift_rows.float("time_origin_s", run_time);
        drift_rows.float("value", Some(p.value));
        drift_rows.float("std", Some(p.std));
        drift_rows.end_row();
    }
}

/// Builds both tables from runs found by [`crate::runs::discover`].
pub fn summarize(runs: &[Run]) -> Result<Summary> {
    let parameters = scan_parameters(runs)?;
    let hive_keys = hive_keys(runs);
    let mut units = fixed_units();
    let mut rows = Columns::default();
    let mut drift_rows = Columns::default();
    for (i, run) in runs.iter().enumerate() {
        let m = &run.manifest;
        let params = parameters.get(&i).map(Vec::as_slice).unwrap_or_default();
        let adequacy = adequacy_of(run)?;
        let mut run_time: Option<f64> = None;
        for rec in &m.recordings {
            // Every table's footer: the keys the stages wrote.
            let mut keys = BTreeMap::new();
            for path in rec.tables.values() {
                keys.extend(file_keys(&run.dir.join(path))?);
            }
            let number = |k: &str| keys.get(k).and_then(|v| v.parse::<f64>().ok());
            let time = number(metadata::TIME_ORIGIN_S);
            run_time = match (run_time, time) {
                (Some(a), Some(b)) => Some(a.min(b)),
                (a, b) => a.or(b),
            };
            let at = Recorded {
                run,
                rec,
                keys: &keys,
                adequacy: &adequacy,
                params,
            };
            recording_rows(&mut rows, &mut units, &at, &hive_keys);
        }
        drift_rows_of(&mut drift_rows, run, params, &hive_keys, run_time);
    }
    let recordings = rows.frame()?;
    let drift = drift_rows.frame()?;
    let drift = if drift.height() == 0 {
        drift
    } else {
        drift_over_time(drift)?
    };
    // The drift table's values carry each row's own unit in `unit`.
    units.insert("z".to_string(), "1".to_string());
    Ok(Summary {
        recordings,
        drift,
        units,
    })
}

/// Orders each parameter's runs by time (then name) within its robot file
/// and pipeline, and measures each against the first: `change` = value −
/// first value, `z` = change / √(std² + first std²).
fn drift_over_time(df: DataFrame) -> PolarsResult<DataFrame> {
    let group = [col("robot_sha256"), col("config_sha256"), col("parameter")];
    let first = |c: &str| col(c).first().over(group.clone());
    let (value, std) = (first("value")?, first("std")?);
    df.lazy()
        .sort(
            ["robot_sha256", "config_sha256", "parameter", "time_origin_s", "run"],
            SortMultipleOptions::default()
                .with_nulls_last(true)
                .with_maintain_order(true),
        )
        .with_columns([
            (col("value") - value.clone()).alias("change"),
            ((col("value") - value) / (col("std") * col("std") + std.clone() * std).sqrt()).alias("z"),
        ])
        .collect()
}

/// Runs whose parameters moved by more than `z` combined standard
/// deviations from their first run: (parameter, run, value, change, z).
pub fn drifted(drift: &DataFrame, z: f64) -> PolarsResult<DataFrame> {
    if drift.height() == 0 {
        return Ok(drift.clone());
    }
    drift
        .clone()
        .lazy()
        .filter(col("z").abs().gt(lit(z)))
        .select([
            col("parameter"),
            col("run"),
            col("unit"),
            col("value"),
            col("change"),
            col("z"),
        ])
        .collect()
}

/// A frame as an Arrow record batch with units in the field metadata and
/// `meta` as schema metadata, for robotid's own (atomic, checksummed)
/// Parquet writer.
pub fn to_record_batch(
    df: &DataFrame,
    units: &BTreeMap<String, String>,
    meta: BTreeMap<String, String>,
) -> Result<RecordBatch> {
    let mut fields = Vec::new();
    let mut arrays: Vec<ArrayRef> = Vec::new();
    for c in df.columns() {
        let name = c.name().as_str();
        let (dtype, array): (arrow::datatypes::DataType, ArrayRef) = match c.dtype() {
            DataType::String => (
                arrow::datatypes::DataType::Utf8,
                Arc::new(StringArray::from_iter(c.str()?.iter())),
            ),
            DataType::Float64 => (
                arrow::datatypes::DataType::Float64,
                Arc::new(Float64Array::from_iter(c.f64()?.iter())),
            ),
            DataType::Int64 => (
                arrow::datatypes::DataType::Int64,
                Arc::new(Int64Array::from_iter(c.i64()?.iter())),
            ),
            other => {
                return Err(Error::Setting(format!(
                    "column `{name}`: type {other} has no Arrow mapping here"
                )))
            }
        };
        let mut md = std::collections::HashMap::new();
        if let Some(u) = units.get(name) {
            md.insert("unit".to_string(), u.clone());
        }
        fields.push(Field::new(name, dtype, true).with_metadata(md));
        arrays.push(array);
    }
    let schema = Schema::new(fields).with_metadata(meta.into_iter().collect::<std::collections::HashMap<_, _>>());
    Ok(RecordBatch::try_new(Arc::new(schema), arrays)?)
}
