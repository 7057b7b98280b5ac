//! The library entry point: a pipeline file → a checked plan → a built
//! pipeline (every stage's recording-independent work done once) → a run
//! over its recordings, the estimate included, or over samples in memory.
//!
//! ```no_run
//! use robotid::{Pipeline, RunOptions};
//!
//! # fn main() -> Result<(), robotid::Error> {
//! let built = Pipeline::from_path("fixtures/pipelines/kuka_axis3.toml")?.build()?;
//! let report = built.run(&RunOptions { out: "out/kuka".into(), ..Default::default() })?;
//! if let Some(est) = &report.estimate {
//!     println!("{} parameters from {} recording(s)", est.estimate.values.len(), report.recordings.len());
//! }
//! # Ok(()) }
//! ```

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use arrow::array::RecordBatch;
use rayon::prelude::*;
use robotid_schemas::{metadata, Kinematics, PeriodMean, RawSamples, TableKind};
use robotid_stages::dynamics::{Model, Robot};
use robotid_stages::formats::parquet::{read_parquet, write_parquet};
use robotid_stages::signal::Spectra;
use robotid_stages::stage::estimate::{Outcome as Estimated, Part, Reducer};
use robotid_stages::stage::read::{read_log, Log};
use robotid_stages::stage::{Chain, Context, PeriodsUse, Product, Stage};

use crate::error::{Error, Problems, Result};
use crate::plan::{lint_with, output_problems, parse, Plan, Resolved, StageConfig};
use crate::run::{recording_names, tables_of, write_tables, Observer, Outcome, Quiet, RecordingResult, RunOptions};

/// A parsed pipeline file.
#[derive(Debug, Clone)]
pub struct Pipeline {
    pub plan: Plan,
    /// The plan's robot file, already read ([`Pipeline::with_robot`]).
    robot: Option<Arc<Robot>>,
}

/// A pipeline ready to run: robot loaded, logs found, stages built.
pub struct Built {
    pub plan: Plan,
    pub model: Option<Arc<Model>>,
    pub logs: Vec<PathBuf>,
    /// What the logs hold.
    pub start: Product,
    pub context: Context,
    /// (name, stage) in order; the estimate's map step is the last.
    pub stages: Vec<(&'static str, Box<dyn Stage>)>,
    pub reducer: Option<Reducer>,
    /// SHA-256 of the robot file's bytes, when the pipeline names one.
    pub robot_sha256: Option<String>,
    /// Per stage: whether a later stage or sink still needs the raw samples.
    raw_needed_after: Vec<bool>,
    /// Per stage: what later stages read of the aligned periods.
    periods_needed_after: Vec<PeriodsUse>,
}

/// What a run gave: each recording's result and, when the pipeline
/// estimates, the estimate and where its table went.
#[derive(Debug)]
pub struct RunReport {
    pub recordings: Vec<RecordingResult>,
    pub estimate: Option<Estimated>,
    pub parameters: Option<PathBuf>,
    /// The run's report (with `opts.plot` and an estimate).
    pub report: Option<PathBuf>,
    /// What went wrong without failing the run (a report not written).
    pub warnings: Vec<String>,
    pub seconds: f64,
}

impl Pipeline {
    /// Reads and parses a pipeline file (step 1: structure).
    pub fn from_path(path: impl AsRef<Path>) -> Result<Pipeline> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_toml(&text, path)
    }

    /// Parses pipeline text; relative paths resolve against `file`'s folder
    /// (the file need not exist).
    pub fn from_toml(text: &str, file: impl AsRef<Path>) -> Result<Pipeline> {
        Ok(Pipeline {
            plan: parse(text, file.as_ref())?,
            robot: None,
        })
    }

    /// A plan made in code ([`Plan::draft`]) to run in memory, as
    /// identify's probes do: each stage's and `[read]`'s settings checked as
    /// a file's are, with no text written and parsed back (so no hash, and
    /// its stages at line 0). What is written as a file goes through
    /// [`Plan::to_toml`] and [`Pipeline::from_toml`].
    pub fn from_plan(plan: Plan) -> Result<Pipeline> {
        let at = |place, message| crate::error::Placed {
            file: plan.file.clone(),
            place,
            message,
        };
        let mut problems: Vec<crate::error::Placed> = plan
            .read
            .problems()
            .into_iter()
            .map(|p| at(crate::error::Place::Read(p.key), p.message))
            .collect();
        for (i, s) in plan.stages.iter().enumerate() {
            for p in s.problems() {
                let place = crate::error::Place::Stage {
                    index: i + 1,
                    kind: s.name().to_string(),
                    line: 0,
                    key: p.key,
                };
                problems.push(at(place, p.message));
            }
        }
        if !problems.is_empty() {
            return Err(Problems(problems).into());
        }
        let lines = vec![0; plan.stages.len()];
        Ok(Pipeline {
            plan: Plan { lines, ..plan },
            robot: None,
        })
    }

    /// The same pipeline with its robot file already read: where `robot`
    /// is the plan's, linting and building take it instead of reading the
    /// file again.
    pub fn with_robot(self, robot: Arc<Robot>) -> Pipeline {
        Pipeline {
            robot: Some(robot),
            ..self
        }
    }

    /// Step 2, context: every problem knowable without reading samples,
    /// for a run into a folder (it must write something there).
    pub fn lint(&self) -> Result<Resolved> {
        let nothing = output_problems(&self.plan);
        match lint_with(&self.plan, self.robot.as_deref(), true) {
            Ok(r) if nothing.is_empty() => Ok(r),
            Ok(_) => Err(Problems(nothing).into()),
            Err(Problems(mut all)) => {
                all.extend(nothing);
                Err(Problems(all).into())
            }
        }
    }

    /// Lints (as for a run in memory), then builds every stage once.
    pub fn build(&self) -> Result<Built> {
        let resolved = lint_with(&self.plan, self.robot.as_deref(), true)?;
        self.build_with(resolved)
    }

    /// [`build`](Self::build) for a run on samples already read
    /// ([`Built::run_stages`], as identify's probes run): the source's logs
    /// are not read again to check their channels and rate.
    pub fn build_for_samples(&self) -> Result<Built> {
        let resolved = lint_with(&self.plan, self.robot.as_deref(), false)?;
        self.build_with(resolved)
    }

    /// Builds against an already linted context.
    pub fn build_with(&self, resolved: Resolved) -> Result<Built> {
        let plan = self.plan.clone();
        let model = resolved.model;
        let context = Context {
            model: model.clone(),
            base_dir: plan.base_dir().to_path_buf(),
            spectra: Spectra::new(),
        };
        let mut stages = Vec::new();
        let mut reducer = None;
        for (i, s) in plan.stages.iter().enumerate() {
            let built = match s {
                StageConfig::Estimate(c) => c.reducer(&context).map(|r| {
                    reducer = Some(r.clone());
                    Box::new(r) as Box<dyn Stage>
                }),
                other => other.build(&context),
            }
            .map_err(|e| {
                Error::Problems(crate::error::Problems(vec![crate::error::Placed {
                    file: plan.file.clone(),
                    place: plan.place(i, ""),
                    message: e.to_string(),
                }]))
            })?;
            stages.push((s.name(), built));
        }
        // Raw samples are large: freed after `align` unless a later stage
        // (differentiate `filtered`) or the raw_samples table needs them.
        let raw_table = plan.tables.contains(&TableKind::RawSamples);
        let raw_needed_after = (0..plan.stages.len())
            .map(|i| raw_table || plan.stages[i + 1..].iter().any(|s| s.takes().contains(&Product::Raw)))
            .collect();
        let periods_needed_after = (0..plan.stages.len())
            .map(|i| {
                plan.stages[i + 1..]
                    .iter()
                    .map(StageConfig::reads_periods)
                    .max()
                    .unwrap_or(PeriodsUse::None)
            })
            .collect();
        Ok(Built {
            plan,
            robot_sha256: resolved.robot_sha256,
            model,
            logs: resolved.logs,
            start: resolved.start,
            context,
            stages,
            reducer,
            raw_needed_after,
            periods_needed_after,
        })
    }
}

impl Built {
    /// The run's provenance written into every table.
    pub fn provenance(&self) -> BTreeMap<String, String> {
        let inferred = self
            .plan
            .inferred
            .iter()
            .map(|(k, v)| (format!("{}.{k}", metadata::INFERRED_PREFIX), v.clone()));
        let mut md = BTreeMap::from([
            (metadata::CONFIG_SHA256.to_string(), self.plan.hash.clone()),
            (
                metadata::PIPELINE_FILE.to_string(),
                self.plan
                    .file
                    .file_name()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_default(),
            ),
        ]);
        md.extend(inferred);
        md
    }

    /// Runs every stage on one chain; `progress` is told each stage's name.
    pub fn run_stages(&self, chain: &mut Chain, progress: impl FnMut(&'static str)) -> robotid_stages::Result<()> {
        self.stages_on(chain, false, progress)
    }

    /// `lean`: the aligned periods' samples are freed once no later stage
    /// reads them (pictures do, and callers that look at them).
    fn stages_on(
        &self,
        chain: &mut Chain,
        lean: bool,
        mut progress: impl FnMut(&'static str),
    ) -> robotid_stages::Result<()> {
        chain.lean = lean;
        for (i, (name, stage)) in self.stages.iter().enumerate() {
            let t = Instant::now();
            progress(name);
            stage.run(chain).map_err(|e| e.in_stage(name, &chain.source))?;
            if chain.periods.is_some() && !self.raw_needed_after[i] {
                chain.raw = None;
            }
            if let Some(p) = chain.periods.as_mut().filter(|_| lean) {
                p.release_samples(self.periods_needed_after[i]);
            }
            chain.report.timings.push((name.to_string(), t.elapsed().as_secs_f64()));
        }
        Ok(())
    }

    /// One recording read and run through every stage, nothing written;
    /// `progress` is told "read", then each stage's name.
    pub fn run_log<'a>(
        &self,
        log: impl Into<Log<'a>>,
        name: &str,
        progress: impl FnMut(&'static str),
    ) -> robotid_stages::Result<Chain> {
        self.log_on(log.into(), name, false, progress)
    }

    /// The same, holding only what the tables and the estimate need: the
    /// aligned periods' samples are freed after the last stage that reads
    /// them (they are as large as the recording, and the regressor too).
    pub fn run_log_for_tables<'a>(
        &self,
        log: impl Into<Log<'a>>,
        name: &str,
        progress: impl FnMut(&'static str),
    ) -> robotid_stages::Result<Chain> {
        self.log_on(log.into(), name, true, progress)
    }

    fn log_on(
        &self,
        log: Log,
        name: &str,
        lean: bool,
        mut progress: impl FnMut(&'static str),
    ) -> robotid_stages::Result<Chain> {
        let t = Instant::now();
        progress("read");
        let mut chain = start_chain(self, log, name)?;
        chain.report.timings.push(("read".into(), t.elapsed().as_secs_f64()));
        self.stages_on(&mut chain, lean, progress)?;
        Ok(chain)
    }

    /// The tables the pipeline writes for a finished chain.
    pub fn tables(&self, chain: &Chain) -> robotid_stages::Result<Vec<(TableKind, RecordBatch)>> {
        tables_of(chain, None, &self.plan.tables, &self.provenance())
    }

    /// The same, the chain's regressor rows moved into the regressor table
    /// rather than copied (the chain has none after).
    pub fn take_tables(&self, chain: &mut Chain) -> robotid_stages::Result<Vec<(TableKind, RecordBatch)>> {
        let rows = chain.regressor.take();
        tables_of(chain, rows, &self.plan.tables, &self.provenance())
    }

    /// Runs the stages on samples in memory and returns the chain, nothing
    /// written: its typed values, its report, its tables through [`Built::tables`].
    pub fn run_raw(&self, name: &str, raw: RawSamples) -> robotid_stages::Result<Chain> {
        let mut chain = Chain::from_raw(name, name, raw);
        self.run_stages(&mut chain, |_| {})?;
        Ok(chain)
    }

    /// Every recording, then the estimate when the pipeline has one. Tables
    /// go under `opts.out`, one folder per recording, all at once when
    /// everything succeeded; when a recording fails nothing is written (the
    /// report says which and why). Nothing shown, no pictures: see
    /// [`Built::run_with`].
    pub fn run(&self, opts: &RunOptions) -> Result<RunReport> {
        self.run_with(opts, &Quiet)
    }

    /// The one run flow: [`Built::run`], `observer` told of each step and
    /// shown every recording's result as soon as all are through; with
    /// `opts.plot` it draws each recording's pictures and the run's report.
    pub fn run_with(&self, opts: &RunOptions, observer: &dyn Observer) -> Result<RunReport> {
        let nothing = output_problems(&self.plan);
        if !nothing.is_empty() {
            return Err(Problems(nothing).into());
        }
        let started = Instant::now();
        let staging = crate::output::prepare(&opts.out, opts.plot.as_deref(), &self.logs)?;
        let staged = RunOptions {
            out: staging.staged_out().to_path_buf(),
            plot: staging.staged_plot(),
            ..opts.clone()
        };
        let mut recordings = run_all(self, &staged, observer);
        observer.recorded(&recordings);
        if recordings.iter().any(|r| r.outcome.is_err()) {
            // Nothing is written: the staging folder goes with `staging`.
            return Ok(RunReport {
                recordings,
                estimate: None,
                parameters: None,
                report: None,
                warnings: Vec::new(),
                seconds: started.elapsed().as_secs_f64(),
            });
        }
        let estimate = self.finish_run(&recordings, staging.staged_out())?;
        let placed = |p: &Path| crate::output::placed(p, &staging, opts);
        let (mut report, mut warnings) = (None, Vec::new());
        if let (Some((_, path)), Some(dir)) = (&estimate, staging.staged_plot()) {
            match observer.report(path, &placed(path), &recordings, &dir) {
                Ok(r) => report = r.map(|r| placed(&r)),
                Err(e) => warnings.push(format!("no report: {e}")),
            }
        }
        let (estimate, parameters) = match estimate {
            Some((e, p)) => (Some(e), Some(placed(&p))),
            None => (None, None),
        };
        for r in &mut recordings {
            if let Ok(o) = &mut r.outcome {
                o.files = o.files.iter().map(|f| placed(f)).collect();
            }
        }
        staging.commit()?;
        Ok(RunReport {
            recordings,
            estimate,
            parameters,
            report,
            warnings,
            seconds: started.elapsed().as_secs_f64(),
        })
    }

    /// The end of a run whose recordings all succeeded: the estimate
    /// ([`Built::estimate_all`]), then the manifest, both into `out`.
    pub fn finish_run(&self, recordings: &[RecordingResult], out: &Path) -> Result<Option<(Estimated, PathBuf)>> {
        let estimate = self.estimate_all(recordings, out)?;
        self.write_manifest(out, recordings, estimate.as_ref().map(|e| e.1.as_path()))?;
        Ok(estimate)
    }

    /// `run.json`, beside the recordings' folders: what made the run and
    /// what it wrote, for tools that scan runs as a dataset. Nothing in it
    /// depends on the machine, the time or the thread count.
    fn write_manifest(&self, out: &Path, recordings: &[RecordingResult], parameters: Option<&Path>) -> Result<()> {
        let relative = |p: &Path| p.strip_prefix(out).ok().map(|r| r.display().to_string());
        let rows: Vec<serde_json::Value> = recordings
            .iter()
            .filter_map(|r| {
                let o = r.outcome.as_ref().ok()?;
                let tables: serde_json::Map<String, serde_json::Value> = o
                    .files
                    .iter()
                    .filter(|f| f.extension().is_some_and(|e| e == "parquet"))
                    .filter_map(|f| {
                        let kind = f.file_stem()?.to_string_lossy().into_owned();
                        Some((kind, relative(f)?.into()))
                    })
                    .collect();
                Some(serde_json::json!({
                    "name": r.name,
                    "source": r.source.display().to_string(),
                    "source_sha256": o.report.source_sha256,
                    "samples": o.report.samples,
                    "tables": tables,
                }))
            })
            .collect();
        let manifest = serde_json::json!({
            "robotid_version": env!("CARGO_PKG_VERSION"),
            "pipeline_file": self.plan.file.display().to_string(),
            "config_sha256": self.plan.hash,
            "robot_file": self.plan.robot.as_ref().map(|r| r.display().to_string()),
            "robot_sha256": self.robot_sha256,
            "recordings": rows,
            "parameters": parameters.and_then(relative),
        });
        let path = out.join(crate::output::MANIFEST);
        let text = serde_json::to_string_pretty(&manifest).expect("JSON of strings and numbers");
        std::fs::write(&path, text + "\n").map_err(|source| Error::Io { path, source })
    }

    /// Every recording, in parallel; each writes its tables when it succeeds.
    pub fn run_recordings(&self, opts: &RunOptions, observer: &dyn Observer) -> Vec<RecordingResult> {
        run_all(self, opts, observer)
    }

    /// The `estimate` stage's reduce over finished recordings, its table
    /// written as `<out>/parameters.parquet`. Refused when a recording
    /// failed: an estimate silently missing data is worse than none.
    pub fn estimate_all(&self, recordings: &[RecordingResult], out: &Path) -> Result<Option<(Estimated, PathBuf)>> {
        let Some(reducer) = &self.reducer else {
            return Ok(None);
        };
        let failed: Vec<String> = recordings
            .iter()
            .filter(|r| r.outcome.is_err())
            .map(|r| r.name.clone())
            .collect();
        if !failed.is_empty() {
            return Err(Error::RecordingsFailed { names: failed });
        }
        // The same data under two names would count twice: the intervals
        // shrink by √2.
        let hashes: Vec<(&Path, &str)> = recordings
            .iter()
            .filter_map(|r| {
                Some((
                    r.source.as_path(),
                    r.outcome.as_ref().ok()?.report.source_sha256.as_deref()?,
                ))
            })
            .collect();
        for (i, (first, h)) in hashes.iter().enumerate() {
            if let Some((again, _)) = hashes[i + 1..].iter().find(|(_, g)| g == h) {
                return Err(Error::SameRecording {
                    first: first.to_path_buf(),
                    again: again.to_path_buf(),
                });
            }
        }
        let parts: Vec<Part> = recordings
            .iter()
            .filter_map(|r| r.outcome.as_ref().ok().and_then(|o| o.part.clone()))
            .collect();
        let est = self.estimate(reducer, &parts)?;
        std::fs::create_dir_all(out).map_err(|source| Error::Io {
            path: out.to_path_buf(),
            source,
        })?;
        let path = out.join("parameters.parquet");
        write_parquet(&path, &est.table)?;
        Ok(Some((est, path)))
    }

    /// The reduce over recordings' parts.
    pub fn estimate(&self, reducer: &Reducer, parts: &[Part]) -> Result<Estimated> {
        let provenance = BTreeMap::from([(metadata::CONFIG_SHA256.to_string(), self.plan.hash.clone())]);
        reducer
            .reduce(parts, &provenance)
            .map_err(|e| Error::Stage(e.in_stage("estimate", "estimate")))
    }
}

/// Every recording of `built`, in parallel.
fn run_all(built: &Built, opts: &RunOptions, observer: &dyn Observer) -> Vec<RecordingResult> {
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
fn start_chain(built: &Built, log: Log, name: &str) -> robotid_stages::Result<Chain> {
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
