//! Executes a built pipeline over its recordings, in parallel (rayon),
//! telling an [`Observer`] how each goes. A recording's tables are written, atomically, only
//! after its whole chain succeeded; a failing recording leaves no file.
//! Every recording is processed on its own, so the output bytes do not
//! depend on the number of threads.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use arrow::array::RecordBatch;
use rayon::prelude::*;
use robotid_schemas::{metadata, Kinematics, PeriodMean, TableKind};
use robotid_stages::formats::parquet::{read_parquet, write_parquet};
use robotid_stages::signal::Spectra;
use robotid_stages::stage::estimate::Part;
use robotid_stages::stage::read::{read_log, Log};
use robotid_stages::stage::regressor::{r_factor_table, RegressorRows};
use robotid_stages::stage::{Chain, Product, Report};

use crate::pipeline::Built;

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
/// logs share a stem.
pub fn recording_names(logs: &[PathBuf]) -> Vec<String> {
    let stem = |p: &PathBuf| {
        p.file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default()
    };
    logs.iter()
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
        .collect()
}

/// Every recording of `built`, in parallel.
pub fn run_recordings(built: &Built, opts: &RunOptions, observer: &dyn Observer) -> Vec<RecordingResult> {
    let names = recording_names(&built.logs);
    let work = || {
        built
            .logs
            .par_iter()
            .zip(names.par_iter())
            .map(|(log, name)| {
                observer.started(name, built.stages.len() + 2);
                let outcome = run_one(built, log, name, opts, observer);
                observer.finished(name, outcome.is_ok());
                RecordingResult {
                    source: log.clone(),
                    name: name.clone(),
                    outcome,
                }
            })
            .collect::<Vec<_>>()
    };
    match opts.threads {
        Some(n) => match rayon::ThreadPoolBuilder::new().num_threads(n).build() {
            Ok(pool) => pool.install(work),
            Err(_) => work(),
        },
        None => work(),
    }
}

/// The chain a log starts: raw samples, or a table of an earlier run.
pub fn start_chain(built: &Built, log: Log, name: &str) -> robotid_stages::Result<Chain> {
    let path = log.path();
    let source = path.display().to_string();
    let mut chain = Chain::new(&source, name);
    let placed = |e: robotid_schemas::SchemaError| robotid_stages::Error::Decode {
        path: path.to_path_buf(),
        source: Box::new(e),
    };
    match built.start {
        Product::Raw => {
            let mut raw = read_log(log, &built.plan.read, built.model.as_deref())?;
            if let Some(n) = raw.metadata.remove(metadata::READ_NOTES) {
                chain.report.notes.push(n);
            }
            chain.report.samples = raw.len();
            chain.report.source_sha256 = raw.metadata.get(metadata::SOURCE_SHA256).cloned();
            chain.raw = Some(raw);
        }
        Product::PeriodMean => {
            chain.report.source_sha256 = Some(log.sha256()?);
            let m = PeriodMean::from_record_batch(&chain_table(log)?).map_err(placed)?;
            chain.facts.period_s = m.metadata.get(metadata::PERIOD_S).and_then(|v| v.parse().ok());
            chain.mean = Some(m);
        }
        Product::Kinematics => {
            chain.report.source_sha256 = Some(log.sha256()?);
            let k = Kinematics::from_record_batch(&chain_table(log)?).map_err(placed)?;
            chain.facts.period_s = k
                .metadata
                .get(metadata::PERIOD_S)
                .filter(|_| k.metadata.get(metadata::DIFFERENTIATION).map(String::as_str) != Some("filtered"))
                .and_then(|v| v.parse().ok());
            chain.kinematics = Some(k);
        }
        other => {
            return Err(robotid_stages::Error::Format {
                path: path.to_path_buf(),
                msg: format!("a pipeline cannot start from {other}"),
            })
        }
    }
    Ok(chain)
}

/// A table of an earlier run, from its file or its bytes.
fn chain_table(log: Log) -> robotid_stages::Result<RecordBatch> {
    match log {
        Log::File(path) => read_parquet(path),
        Log::Bytes { name, bytes, .. } => robotid_stages::formats::parquet::read_parquet_bytes(name, bytes.clone()),
    }
}

/// Hands the allocator's free pages back to the system. glibc keeps freed
/// blocks under its dynamic mmap threshold (up to 32 MB: an hour's column
/// vectors) in its heap; between the stages and the tables a run has freed
/// the raw and aligned samples, and the tables need fresh memory.
fn release_free_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim only returns free memory; it is thread-safe.
    unsafe {
        libc::malloc_trim(0);
    }
}

fn run_one(
    built: &Built,
    log: &Path,
    name: &str,
    opts: &RunOptions,
    observer: &dyn Observer,
) -> crate::Result<Outcome> {
    let progress = |stage| observer.step(name, stage);
    // Only the pictures read the aligned periods past their stages: without
    // them, they are freed as soon as no stage reads them (an hour at 1 kHz:
    // 350 MB).
    let mut chain = match opts.plot {
        Some(_) => built.run_log(log, name, progress)?,
        None => built.run_log_for_tables(log, name, progress)?,
    };
    release_free_memory();
    // Sinks: only now, with every stage done.
    let t = Instant::now();
    observer.step(name, "write");
    let dir = opts.out.join(name);
    let mut outcome = Outcome::default();
    // The regressor rows move into their table unless the report keeps them.
    let regressor = match opts.plot {
        Some(_) => chain.regressor.clone(),
        None => chain.regressor.take(),
    };
    outcome.files = write_tables(&chain, regressor, &built.plan.tables, &built.provenance(), &dir)?;
    chain.report.timings.push(("write".into(), t.elapsed().as_secs_f64()));
    if let Some(plot_dir) = &opts.plot {
        let t = Instant::now();
        let dir = plot_dir.join(name);
        // Excited harmonics: the noise stage's, else the recording's.
        let from_stage = built.plan.stages.iter().find_map(|s| match s {
            crate::plan::StageConfig::Noise(c) => c.harmonics.clone(),
            _ => None,
        });
        let h = chain.harmonics(from_stage.as_ref()).unwrap_or_default();
        outcome
            .files
            .extend(observer.pictures(&dir, &chain, &h, &built.context.spectra)?);
        chain.report.timings.push(("plot".into(), t.elapsed().as_secs_f64()));
        outcome.regressor = chain.regressor.take();
    }
    outcome.part = chain.estimate.take();
    outcome.report = std::mem::take(&mut chain.report);
    Ok(outcome)
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
            TableKind::Parameters => {
                return Err(robotid_stages::Error::setting(
                    "output.tables",
                    "a table made per recording (parameters come from the estimate, over all recordings)",
                    "parameters",
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
