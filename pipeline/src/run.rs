//! Executes a validated plan over its recordings, in parallel (rayon), one
//! progress bar each. A recording's tables are written, atomically, only
//! after its whole chain succeeded; a failing recording leaves no file.
//! Every recording is processed on its own, so the output bytes do not
//! depend on the number of threads.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use rayon::prelude::*;
use robotid_schemas::{metadata, Kinematics, NoiseTable, PeriodMean, RawSamples, TableKind};
use robotid_stages::align::{align, register_phase, Periods};
use robotid_stages::average::average;
use robotid_stages::decimate::{decimate_periods, decimate_record};
use robotid_stages::differentiate::{differentiate, differentiate_record, Method};
use robotid_stages::dynamics::Model;
use robotid_stages::estimate::{estimate, parameters_table, Estimate, InputNoise, System};
use robotid_stages::formats::parquet::{read_parquet, write_parquet};
use robotid_stages::inverse_filter::{inverse_filter_periods, inverse_filter_record};
use robotid_stages::noise::{noise, ChannelNoise};
use robotid_stages::read::read;
use robotid_stages::signal::Spectra;

use crate::plan::{Data, Plan, StageConfig};

#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    pub out: PathBuf,
    /// Worker threads (default: one per core).
    pub threads: Option<usize>,
    pub progress: bool,
    /// Write pictures and a report per recording into this folder.
    pub plot: Option<PathBuf>,
}

/// What one recording gave.
#[derive(Debug, Clone, Default)]
pub struct Outcome {
    pub samples: usize,
    pub periods_kept: Option<usize>,
    pub periods_found: Option<usize>,
    pub dropped_s: Option<f64>,
    pub jitter_rms_s: Option<f64>,
    pub noise: Vec<ChannelNoise>,
    pub notes: Vec<String>,
    /// (stage, seconds)
    pub timings: Vec<(String, f64)>,
    pub files: Vec<PathBuf>,
    /// Kept for the `estimate` stage: the regressor table and, for maximum
    /// likelihood, the noise on its inputs.
    pub regressor: Option<arrow::array::RecordBatch>,
    pub input_noise: Option<robotid_stages::estimate::InputNoise>,
}

#[derive(Debug, Clone)]
pub struct RecordingResult {
    pub source: PathBuf,
    pub name: String,
    pub outcome: Result<Outcome, String>,
}

/// The tables of one recording as they come out of the chain.
#[derive(Default)]
struct State {
    raw: Option<RawSamples>,
    periods: Option<Periods>,
    mean: Option<PeriodMean>,
    noise: Option<NoiseTable>,
    kinematics: Option<Kinematics>,
    regressor: Option<arrow::array::RecordBatch>,
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

pub fn run(
    plan: &Plan,
    model: Option<&Model>,
    logs: &[PathBuf],
    start: Data,
    opts: &RunOptions,
) -> Vec<RecordingResult> {
    let names = recording_names(logs);
    let spectra = Spectra::new();
    let bars = MultiProgress::new();
    if !opts.progress {
        bars.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let style = ProgressStyle::with_template("{prefix:>24} [{bar:24}] {pos}/{len} {msg}").expect("valid template");
    let work = || {
        logs.par_iter()
            .zip(names.par_iter())
            .map(|(log, name)| {
                let bar = bars.add(ProgressBar::new(plan.stages.len() as u64 + 2));
                bar.set_style(style.clone());
                bar.set_prefix(name.clone());
                let outcome = run_one(
                    plan,
                    model,
                    log,
                    name,
                    start,
                    &opts.out,
                    opts.plot.as_deref(),
                    &spectra,
                    &bar,
                );
                bar.finish_with_message(if outcome.is_ok() { "done" } else { "failed" });
                RecordingResult {
                    source: log.clone(),
                    name: name.clone(),
                    outcome,
                }
            })
            .collect::<Vec<_>>()
    };
    match opts.threads {
        Some(n) => rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .expect("thread pool")
            .install(work),
        None => work(),
    }
}

#[allow(clippy::too_many_arguments)]
fn run_one(
    plan: &Plan,
    model: Option<&Model>,
    log: &Path,
    name: &str,
    start: Data,
    out: &Path,
    plot: Option<&Path>,
    spectra: &Spectra,
    bar: &ProgressBar,
) -> Result<Outcome, String> {
    let mut outcome = Outcome::default();
    let mut st = State::default();
    let source = log.display().to_string();
    let timed = |stage: &str, outcome: &mut Outcome, t: Instant| {
        outcome.timings.push((stage.to_string(), t.elapsed().as_secs_f64()));
        bar.inc(1);
    };
    let t = Instant::now();
    bar.set_message("read");
    match start {
        Data::Raw => {
            let raw = read(log, &plan.read, model).map_err(|e| e.to_string())?;
            outcome.samples = raw.len();
            st.raw = Some(raw);
        }
        Data::PeriodMean => {
            let b = read_parquet(log).map_err(|e| e.to_string())?;
            st.mean = Some(PeriodMean::from_record_batch(&b).map_err(|e| format!("{source}: {e}"))?);
        }
        Data::Kinematics => {
            let b = read_parquet(log).map_err(|e| e.to_string())?;
            st.kinematics = Some(Kinematics::from_record_batch(&b).map_err(|e| format!("{source}: {e}"))?);
        }
        other => return Err(format!("{source}: cannot start from {other:?}")),
    }
    timed("read", &mut outcome, t);
    for stage in &plan.stages {
        let t = Instant::now();
        bar.set_message(stage.name());
        let fail = |e: String| format!("{source}: stage `{}`: {e}", stage.name());
        match stage {
            StageConfig::Align(c) => {
                let raw = st.raw.as_ref().expect("chain checked");
                let mut p = align(raw, c, &source).map_err(|e| e.to_string())?;
                if let Some(rel) = &c.reference_trajectory {
                    let traj = crate::plan::reference_trajectory(plan, rel).map_err(fail)?;
                    register_phase(&mut p, &traj, &source).map_err(|e| e.to_string())?;
                    outcome.notes.push(format!(
                        "phase registered against {} (shift {} samples, correlation {:.4})",
                        rel.display(),
                        p.report.phase_shift_samples.unwrap_or(0),
                        p.report.phase_correlation.unwrap_or(0.0)
                    ));
                }
                outcome.periods_kept = Some(p.periods);
                outcome.periods_found = Some(p.report.periods_found);
                outcome.dropped_s = Some(p.report.dropped_s);
                outcome.jitter_rms_s = Some(p.report.jitter_rms_s);
                outcome.notes.extend(p.report.notes.iter().cloned());
                st.periods = Some(p);
                // Free the raw samples early unless a table or stage still needs them.
                let raw_needed = plan.tables.contains(&TableKind::RawSamples)
                    || plan
                        .stages
                        .iter()
                        .any(|s| matches!(s, StageConfig::Differentiate(c) if c.method == Method::Filtered));
                if !raw_needed {
                    st.raw = None;
                }
            }
            StageConfig::InverseFilter(c) => match (&mut st.periods, &mut st.raw) {
                (Some(p), _) => inverse_filter_periods(p, c, spectra).map_err(fail)?,
                (None, Some(raw)) => {
                    inverse_filter_record(raw, record_rate(raw), c, spectra).map_err(fail)?;
                    outcome.notes.push(
                        "inverse filter on a non-periodic record: approximate within a few filter time constants of both ends".into(),
                    );
                }
                (None, None) => return Err(fail("no samples to filter".into())),
            },
            StageConfig::Decimate(c) => match (&mut st.periods, &mut st.raw) {
                (Some(p), _) => decimate_periods(p, c, spectra).map_err(fail)?,
                (None, Some(raw)) => {
                    decimate_record(raw, record_rate(raw), c, spectra).map_err(fail)?;
                    outcome
                        .notes
                        .push("decimated a non-periodic record: approximate near both ends".into());
                }
                (None, None) => return Err(fail("no samples to decimate".into())),
            },
            StageConfig::Differentiate(c) if c.method == Method::Filtered => {
                let raw = st.raw.as_ref().expect("chain checked");
                let filter = c.filter.as_ref().expect("checked");
                st.kinematics = Some(differentiate_record(raw, record_rate(raw), filter, spectra).map_err(fail)?);
            }
            StageConfig::Regressor(c) => {
                let kin = st.kinematics.as_ref().expect("chain checked");
                let model = model.expect("checked: the regressor stage needs the robot");
                let batch = robotid_stages::regressor::regressor_table(
                    kin,
                    st.noise.as_ref(),
                    st.periods.as_ref(),
                    model,
                    c,
                    name,
                )
                .map_err(fail)?;
                let cond = batch
                    .schema()
                    .metadata()
                    .get("robotid.condition_number")
                    .cloned()
                    .unwrap_or_default();
                outcome.notes.push(format!(
                    "regressor: {} rows, {} base parameters, condition number {cond} (column-normalised)",
                    batch.num_rows(),
                    robotid_stages::regressor::columns_of(&batch.schema(), robotid_stages::regressor::PARAMETER_COLUMN)
                        .len()
                ));
                st.regressor = Some(batch);
            }
            StageConfig::Estimate(c) => {
                // The reduce runs after all recordings (`estimate_all`);
                // here each recording hands over what it needs.
                outcome.regressor = st.regressor.clone();
                if c.method == robotid_stages::estimate::Method::Ml {
                    outcome.input_noise = Some(ml_input_noise(plan, model, &st).map_err(fail)?);
                }
            }
            StageConfig::Average(_) => {
                let p = st.periods.as_ref().expect("chain checked");
                let (mean, _drift) = average(p);
                st.mean = Some(mean);
            }
            StageConfig::Noise(c) => {
                let p = st.periods.as_ref().expect("chain checked");
                let mean = st.mean.as_ref().expect("chain checked");
                let h = harmonics(c.harmonics.as_ref(), &p.metadata).map_err(fail)?;
                let (table, summary) = noise(p, mean, &h, spectra);
                outcome.noise = summary;
                st.noise = Some(table);
            }
            StageConfig::Differentiate(c) => {
                let mean = st.mean.as_ref().expect("chain checked");
                let h = match c.method {
                    Method::FourierFit => harmonics(c.harmonics.as_ref(), &mean.metadata).map_err(fail)?,
                    Method::Dft | Method::Filtered => Vec::new(),
                };
                let period = mean
                    .metadata
                    .get(metadata::PERIOD_S)
                    .and_then(|v| v.parse::<f64>().ok())
                    .ok_or_else(|| fail("the averaged period does not say its period".into()))?;
                st.kinematics = Some(differentiate(mean, period, c.method, &h, c.bandwidth_hz, spectra));
            }
        }
        timed(stage.name(), &mut outcome, t);
    }
    // Sinks: only now, with every stage done.
    let t = Instant::now();
    bar.set_message("write");
    let dir = out.join(name);
    let mut batches = Vec::new();
    let provenance = |md: &mut BTreeMap<String, String>| {
        md.insert(metadata::CONFIG_SHA256.into(), plan.hash.clone());
        md.insert(
            "robotid.pipeline_file".into(),
            plan.file
                .file_name()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default(),
        );
    };
    for kind in &plan.tables {
        let batch = match kind {
            TableKind::RawSamples => {
                let mut raw = st.raw.clone().expect("chain checked");
                provenance(&mut raw.metadata);
                raw.to_record_batch()
            }
            TableKind::PeriodMean => {
                let mut m = st.mean.clone().expect("chain checked");
                provenance(&mut m.metadata);
                m.to_record_batch()
            }
            TableKind::Noise => {
                let mut m = st.noise.clone().expect("chain checked");
                provenance(&mut m.metadata);
                m.to_record_batch()
            }
            TableKind::Regressor | TableKind::RFactor => {
                let full = st.regressor.as_ref().expect("chain checked");
                let b = if *kind == TableKind::RFactor {
                    robotid_stages::regressor::r_factor_table(full).map_err(|e| format!("{source}: {e}"))?
                } else {
                    full.clone()
                };
                let mut md: BTreeMap<String, String> = b.schema().metadata().clone().into();
                provenance(&mut md);
                let schema = arrow::datatypes::Schema::new(b.schema().fields().clone()).with_metadata(md);
                arrow::array::RecordBatch::try_new(std::sync::Arc::new(schema), b.columns().to_vec())
                    .map_err(|e| robotid_schemas::SchemaError::Arrow(e.to_string()))
            }
            _ => {
                let mut m = st.kinematics.clone().expect("chain checked");
                provenance(&mut m.metadata);
                m.to_record_batch()
            }
        }
        .map_err(|e| format!("{source}: {e}"))?;
        batches.push((dir.join(format!("{}.parquet", kind.name())), batch));
    }
    if !batches.is_empty() {
        std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    for (path, batch) in batches {
        write_parquet(&path, &batch).map_err(|e| e.to_string())?;
        outcome.files.push(path);
    }
    timed("write", &mut outcome, t);
    if let Some(plot_dir) = plot {
        let t = Instant::now();
        let dir = plot_dir.join(name);
        // Excited harmonics: the noise stage's, else the recording's.
        let from_stage = plan.stages.iter().find_map(|s| match s {
            StageConfig::Noise(c) => c.harmonics.clone(),
            _ => None,
        });
        let h = from_stage.unwrap_or_else(|| {
            harmonics(None, &st.mean.as_ref().map(|m| m.metadata.clone()).unwrap_or_default()).unwrap_or_default()
        });
        let inputs = crate::plot::Inputs {
            name,
            periods: st.periods.as_ref(),
            mean: st.mean.as_ref(),
            noise: st.noise.as_ref(),
            kinematics: st.kinematics.as_ref(),
            harmonics: &h,
            spectra,
        };
        let pictures = crate::plot::plot_recording(&dir, &inputs).map_err(|e| format!("{source}: plots: {e}"))?;
        let report =
            crate::plot::write_report(&dir, name, &outcome, &pictures).map_err(|e| format!("{source}: report: {e}"))?;
        outcome.files.extend(pictures);
        outcome.files.push(report);
        outcome.timings.push(("plot".into(), t.elapsed().as_secs_f64()));
    }
    Ok(outcome)
}

/// The noise on the regressor's inputs for maximum likelihood: the noise
/// stage's position variance (mean over the period, per joint) through the
/// differentiation's gains, with the regressor's Jacobians.
fn ml_input_noise(
    plan: &Plan,
    model: Option<&Model>,
    st: &State,
) -> Result<robotid_stages::estimate::InputNoise, String> {
    let kin = st.kinematics.as_ref().expect("chain checked");
    let noise = st
        .noise
        .as_ref()
        .ok_or("method = \"ml\" needs the position noise: add a `noise` stage")?;
    let (rc, dc) = plan.stages.iter().fold((None, None), |(r, d), s| match s {
        StageConfig::Regressor(c) => (Some(c), d),
        StageConfig::Differentiate(c) => (r, Some(c)),
        _ => (r, d),
    });
    let (rc, dc) = (rc.expect("chain checked"), dc.expect("chain checked"));
    if dc.method == Method::Filtered {
        return Err("method = \"ml\" needs periodic data (differentiate by `dft` or `fourier_fit`)".into());
    }
    let period = kin
        .metadata
        .get(metadata::PERIOD_S)
        .and_then(|v| v.parse::<f64>().ok())
        .ok_or("the kinematics does not say its period")?;
    let h = harmonics(dc.harmonics.as_ref(), &kin.metadata).unwrap_or_default();
    let gains = robotid_stages::differentiate::noise_gains(kin.time.len(), period, dc.method, &h, dc.bandwidth_hz);
    let var_q: Vec<f64> = noise
        .var_q
        .iter()
        .map(|v| v.iter().sum::<f64>() / v.len().max(1) as f64)
        .collect();
    let base = robotid_stages::regressor::BaseRegressor::new(model.expect("checked"), rc)?;
    Ok(robotid_stages::estimate::input_noise(&base, kin, &var_q, gains))
}

/// The `estimate` stage, once all recordings are through: their regressor
/// tables stacked, estimated, written as `<out>/parameters.parquet`. Refused
/// when a recording failed (an estimate silently missing data is worse than
/// none).
pub fn estimate_all(
    plan: &Plan,
    model: Option<&Model>,
    results: &[RecordingResult],
    out: &Path,
) -> Result<Option<(PathBuf, Estimate)>, String> {
    let Some(cfg) = plan.stages.iter().find_map(|s| match s {
        StageConfig::Estimate(c) => Some(c),
        _ => None,
    }) else {
        return Ok(None);
    };
    let mut tables = Vec::new();
    let mut noises = Vec::new();
    for r in results {
        let o = r.outcome.as_ref().map_err(|_| {
            format!(
                "estimate: recording `{}` failed, so no parameters were estimated (fix it or leave it out of the source)",
                r.name
            )
        })?;
        tables.push((r.name.clone(), o.regressor.clone().expect("estimate stage ran")));
        noises.extend(o.input_noise.clone());
    }
    let mut sys = System::from_tables(&tables)?;
    if let Some(rel) = &cfg.known {
        let path = plan.file.parent().unwrap_or(Path::new(".")).join(rel);
        let known = load_known(&path)?;
        let fixed = sys.fix(&known)?;
        if fixed.is_empty() {
            return Err(format!(
                "estimate: known = {}: none of its parameters is in the model",
                path.display()
            ));
        }
    }
    let noise = merge_noise(noises);
    let mut est = estimate(&sys, cfg, noise.as_ref()).map_err(|e| format!("estimate: {e}"))?;
    let mut md = sys.metadata.clone();
    if cfg.physical {
        let model = model.ok_or("estimate: physical = true needs the robot")?;
        let (fit, note) = physical_fit(model, &sys, &est)?;
        est.values = fit.base.clone();
        md.insert("robotid.physical".into(), note);
    }
    for k in [metadata::SOURCE_FILE, metadata::SOURCE_SHA256] {
        md.remove(k);
    }
    md.insert("robotid.recordings".into(), sys.recordings.join(","));
    md.insert(metadata::CONFIG_SHA256.into(), plan.hash.clone());
    let batch = parameters_table(&est, cfg.confidence, &sys.expressions, &md)?;
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let path = out.join("parameters.parquet");
    write_parquet(&path, &batch).map_err(|e| e.to_string())?;
    Ok(Some((path, est)))
}

/// The physically consistent estimate nearest `est` (robot file as the
/// a-priori model), and a note saying what it cost.
fn physical_fit(
    model: &Model,
    sys: &System,
    est: &Estimate,
) -> Result<(robotid_stages::estimate::PhysicalFit, String), String> {
    use robotid_stages::dynamics::{parameter_names, standard_parameters};
    let cfg: robotid_stages::regressor::RegressorConfig = serde_json::from_str(
        sys.metadata
            .get(robotid_stages::regressor::CONFIG_KEY)
            .ok_or("estimate: the regressor tables do not carry their configuration")?,
    )
    .map_err(|e| e.to_string())?;
    let base = robotid_stages::regressor::BaseRegressor::new(model, &cfg)?;
    let map = base.map().ok_or("estimate: physical = true needs the chain model")?;
    if base.names() != est.names {
        return Err("estimate: physical = true cannot be combined with known parameters".into());
    }
    let names = parameter_names(&base.model, base.terms);
    let prior = standard_parameters(&base.model, base.terms);
    let fit = robotid_stages::estimate::physically_consistent(&names, &prior, map, &est.values, &est.covariance, 1e-3)?;
    let note = format!(
        "nearest physically consistent estimate: χ² = {:.4} against the covariance, {} iterations, smallest pseudo-inertia eigenvalues {:?}",
        fit.chi2, fit.iterations, fit.min_eigen
    );
    Ok((fit, note))
}

/// A `parameters` table's values and covariance, to be taken as known.
pub fn load_known(path: &Path) -> Result<robotid_stages::estimate::Known, String> {
    let batch = read_parquet(path).map_err(|e| e.to_string())?;
    let p = robotid_stages::estimate::parameters_from_table(&batch).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(robotid_stages::estimate::Known {
        names: p.names,
        values: p.values,
        covariance: p.covariance,
    })
}

/// Input noise of several recordings, in the order their rows are stacked.
fn merge_noise(parts: Vec<InputNoise>) -> Option<InputNoise> {
    let mut it = parts.into_iter();
    let mut all = it.next()?;
    for p in it {
        all.var.extend(p.var);
        all.jacobian.extend(p.jacobian);
    }
    Some(all)
}

/// Harmonic numbers from the stage, else from the table's metadata.
fn harmonics(given: Option<&Vec<u32>>, md: &BTreeMap<String, String>) -> Result<Vec<u32>, String> {
    if let Some(h) = given {
        return Ok(h.clone());
    }
    let text = md
        .get(metadata::HARMONICS)
        .ok_or("no excited harmonics: give `harmonics` (the recording does not say)")?;
    text.split(',')
        .map(|s| {
            s.trim()
                .parse::<u32>()
                .map_err(|_| format!("bad harmonics `{text}` in the recording's metadata"))
        })
        .collect()
}

/// A record's sample rate: its metadata's, else from its span.
fn record_rate(raw: &RawSamples) -> f64 {
    raw.metadata
        .get(metadata::SAMPLE_RATE_HZ)
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| (raw.len() - 1) as f64 / (raw.time[raw.len() - 1] - raw.time[0]))
}
