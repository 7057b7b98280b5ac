//! What a run of a built pipeline is told and gives (`Built::run_recordings`
//! executes it, in parallel): its options, the [`Observer`] told how each
//! recording goes, each recording's outcome, and its tables, written
//! atomically only after its whole chain succeeded (a failing recording
//! leaves no file). Every recording is processed on its own, so the output
//! bytes do not depend on the number of threads.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use arrow::array::RecordBatch;
use robotid_schemas::TableKind;
use robotid_stages::formats::parquet::write_parquet;
use robotid_stages::signal::Spectra;
use robotid_stages::stage::estimate::Part;
use robotid_stages::stage::regressor::{r_factor_table, RegressorRows};
use robotid_stages::stage::{Chain, Report};

#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    pub out: PathBuf,
    /// Worker threads (default: one per core).
    pub threads: Option<usize>,
    /// Keep each recording's chain whole for the observer's pictures, and
    /// put them (and the run's report) into this folder.
    pub plot: Option<PathBuf>,
}

/// What a run shows as it goes and the pictures it leaves: the command
/// line's progress bars and plots (the `robotid-report` crate draws
/// them); [`Quiet`] for none. Called from the workers: `Sync`.
pub trait Observer: Sync {
    /// A step with nothing to count begins (`Some(what)`) or ends (`None`):
    /// `identify`'s physical fit.
    fn busy(&self, _what: Option<&str>) {}
    /// A recording starts: `steps` steps (the read, its stages, the write).
    fn started(&self, _name: &str, _steps: usize) {}
    /// A step of a recording begins.
    fn step(&self, _name: &str, _step: &'static str) {}
    /// A recording is through, or failed.
    fn finished(&self, _name: &str, _ok: bool) {}
    /// Every recording's result, as soon as all are through (before the
    /// estimate, which may fail).
    fn recorded(&self, _recordings: &[RecordingResult]) {}
    /// With [`RunOptions::plot`]: a finished recording's pictures (and its
    /// page) into `dir`, from its whole chain; `harmonics` the excited lines.
    fn pictures(
        &self,
        _dir: &Path,
        _chain: &Chain,
        _harmonics: &[u32],
        _spectra: &Spectra,
    ) -> crate::Result<Vec<PathBuf>> {
        Ok(Vec::new())
    }
    /// With [`RunOptions::plot`] and an estimate: the run's report into
    /// `dir`, from the parameters table and every recording's rows.
    /// `shown`: the table's path once the run is committed, for the page.
    fn report(
        &self,
        _parameters: &Path,
        _shown: &Path,
        _recordings: &[RecordingResult],
        _dir: &Path,
    ) -> crate::Result<Option<PathBuf>> {
        Ok(None)
    }
}

/// An observer that shows nothing and draws nothing.
pub struct Quiet;

impl Observer for Quiet {}

/// What one recording gave.
#[derive(Debug, Clone, Default)]
pub struct Outcome {
    pub report: Report,
    pub files: Vec<PathBuf>,
    /// The `estimate` stage's part of this recording.
    pub part: Option<Part>,
    /// The regressor rows, kept for the run's report (`--plot`).
    pub regressor: Option<RegressorRows>,
}

#[derive(Debug)]
pub struct RecordingResult {
    pub source: PathBuf,
    pub name: String,
    pub outcome: crate::Result<Outcome>,
}

/// Output folder names: the file stem, or stem and extension where two
/// logs share a stem, numbered from the second where two share both.
pub fn recording_names(logs: &[PathBuf]) -> Vec<String> {
    let stem = |p: &PathBuf| {
        p.file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default()
    };
    let first: Vec<String> = logs
        .iter()
        .map(|p| {
            let clash = logs.iter().filter(|q| stem(q) == stem(p)).count() > 1;
            let ext = p
                .extension()
                .map(|e| e.to_string_lossy().into_owned())
                .unwrap_or_default();
            if clash {
                format!("{}_{ext}", stem(p))
            } else {
                stem(p)
            }
        })
        .collect();
    // The same file name in two folders (`a/run.csv`, `b/run.csv`): the
    // later ones numbered.
    first
        .iter()
        .enumerate()
        .map(|(i, n)| {
            let before = first[..i].iter().filter(|m| *m == n).count();
            if before == 0 {
                n.clone()
            } else {
                format!("{n}_{}", before + 1)
            }
        })
        .collect()
}

/// The requested tables of a finished chain, with the run's provenance.
/// The regressor table is made from `regressor` when given (moved into the
/// table), else from a copy of the chain's.
pub fn tables_of(
    chain: &Chain,
    regressor: Option<RegressorRows>,
    kinds: &[TableKind],
    provenance: &BTreeMap<String, String>,
) -> robotid_stages::Result<Vec<(TableKind, RecordBatch)>> {
    let with = |md: &BTreeMap<String, String>| {
        let mut md = md.clone();
        md.extend(provenance.iter().map(|(k, v)| (k.clone(), v.clone())));
        md
    };
    let mut out = Vec::new();
    // The regressor table is made once, for itself and its R factor.
    let mut rows = regressor;
    let mut regressor: Option<RecordBatch> = None;
    for &kind in kinds {
        let batch = match kind {
            TableKind::RawSamples => {
                let mut raw = chain.raw()?.clone();
                raw.metadata = with(&raw.metadata);
                raw.to_record_batch()?
            }
            TableKind::PeriodMean => {
                let mut m = chain.mean()?.clone();
                m.metadata = with(&m.metadata);
                m.to_record_batch()?
            }
            TableKind::Noise => {
                let mut m = chain
                    .noise
                    .clone()
                    .ok_or_else(|| robotid_stages::Error::missing("noise variances", "add a `noise` stage"))?;
                m.metadata = with(&m.metadata);
                m.to_record_batch()?
            }
            TableKind::Parameters | TableKind::Payload => {
                return Err(robotid_stages::Error::setting(
                    "output.tables",
                    "a table made per recording (parameters come from the estimate, over all recordings)",
                    kind.name(),
                ))
            }
            TableKind::Kinematics => {
                let mut m = chain.kinematics()?.clone();
                m.metadata = with(&m.metadata);
                m.to_record_batch()?
            }
            TableKind::Regressor | TableKind::RFactor => {
                let full = match &regressor {
                    Some(t) => t.clone(),
                    None => {
                        let made = match rows.take() {
                            Some(r) => r.into_record_batch()?,
                            None => chain.regressor()?.to_record_batch()?,
                        };
                        regressor.insert(made).clone()
                    }
                };
                let b = if kind == TableKind::RFactor {
                    r_factor_table(&full)?
                } else {
                    full
                };
                let md: BTreeMap<String, String> = with(&b.schema().metadata().clone().into_iter().collect());
                let schema = arrow::datatypes::Schema::new(b.schema().fields().clone())
                    .with_metadata(md.into_iter().collect::<std::collections::HashMap<_, _>>());
                RecordBatch::try_new(std::sync::Arc::new(schema), b.columns().to_vec())
                    .map_err(robotid_schemas::SchemaError::from)?
            }
        };
        refuse_infinities(&batch, 0, kind, &chain.source)?;
        out.push((kind, batch));
    }
    Ok(out)
}

/// Writes the requested tables of a finished chain into `dir` (made when
/// there is one), and returns their paths. The regressor table is written
/// from `regressor` (else a copy of the chain's rows) a row group at a
/// time, each group's rows of A made when written where the rows are made
/// on demand: A is never whole. With an `r_factor` table, which is made
/// from the whole regressor table, it is made whole.
pub fn write_tables(
    chain: &Chain,
    regressor: Option<RegressorRows>,
    kinds: &[TableKind],
    provenance: &BTreeMap<String, String>,
    dir: &Path,
) -> robotid_stages::Result<Vec<PathBuf>> {
    if !kinds.is_empty() {
        std::fs::create_dir_all(dir).map_err(|e| robotid_stages::Error::io(dir, e))?;
    }
    let path = |kind: TableKind| dir.join(format!("{}.parquet", kind.name()));
    let mut files = Vec::new();
    if kinds.contains(&TableKind::RFactor) {
        for (kind, batch) in tables_of(chain, regressor, kinds, provenance)? {
            write_parquet(&path(kind), &batch)?;
            files.push(path(kind));
        }
        return Ok(files);
    }
    let mut regressor = regressor;
    for &kind in kinds {
        if kind != TableKind::Regressor {
            for (kind, batch) in tables_of(chain, None, &[kind], provenance)? {
                write_parquet(&path(kind), &batch)?;
            }
            files.push(path(kind));
            continue;
        }
        let rows = match regressor.take() {
            Some(r) => r,
            None => chain.regressor()?.clone(),
        };
        let (schema, groups) = rows.into_groups()?;
        let mut md = schema.metadata().clone();
        md.extend(provenance.iter().map(|(k, v)| (k.clone(), v.clone())));
        let schema = std::sync::Arc::new(schema.as_ref().clone().with_metadata(md));
        let mut first = 0;
        let groups = groups.map(|batch| {
            let batch = RecordBatch::try_new(schema.clone(), batch?.columns().to_vec())
                .map_err(robotid_schemas::SchemaError::from)?;
            refuse_infinities(&batch, first, kind, &chain.source)?;
            first += batch.num_rows();
            Ok(batch)
        });
        robotid_stages::formats::parquet::write_parquet_groups(&path(kind), schema.clone(), groups)?;
        files.push(path(kind));
    }
    Ok(files)
}

/// No infinity is written to a table (a sample of 1e200 A gives every
/// variance = inf): refused with the table, column and row. NaN stays the
/// schemas' "not known" (a spread with one period, a variance without a
/// noise stage).
fn refuse_infinities(batch: &RecordBatch, first: usize, kind: TableKind, source: &str) -> robotid_stages::Result<()> {
    use arrow::array::{Array, Float64Array};
    for (i, field) in batch.schema().fields().iter().enumerate() {
        let Some(col) = batch.column(i).as_any().downcast_ref::<Float64Array>() else {
            continue;
        };
        if let Some(row) = (0..col.len()).find(|&r| col.value(r).is_infinite()) {
            return Err(robotid_stages::Error::NotFinite {
                what: format!("{source}: the `{kind}` table's column `{}`", field.name()),
                value: col.value(row),
                at: format!("row {} (a sample far out of range upstream?)", first + row),
            });
        }
    }
    Ok(())
}
