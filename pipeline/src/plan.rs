//! Pipeline files (format version 1, `docs/pipeline-file.md`): parsed into a
//! plain-data plan and validated in two steps, structure then context,
//! reporting every error at once with its stage and key. Nothing is read
//! from a log until the whole chain checks.

use std::path::{Path, PathBuf};

use robotid_schemas::TableKind;
use robotid_stages::align::AlignConfig;
use robotid_stages::decimate::DecimateConfig;
use robotid_stages::differentiate::{DifferentiateConfig, Method};
use robotid_stages::dynamics::{load_robot, Model};
use robotid_stages::estimate::EstimateConfig;
use robotid_stages::inverse_filter::InverseFilterConfig;
use robotid_stages::read::ReadConfig;
use robotid_stages::regressor::RegressorConfig;
use serde::Deserialize;

pub const FORMAT_VERSION: u32 = 1;

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct PipelineFile {
    version: u32,
    robot: Option<PathBuf>,
    source: SourceConfig,
    #[serde(default)]
    read: ReadConfig,
    #[serde(default)]
    stage: Vec<toml::Spanned<toml::Table>>,
    #[serde(default)]
    output: OutputConfig,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SourceConfig {
    /// A log file, a folder of logs, or a glob; relative to the pipeline file.
    pub path: String,
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputConfig {
    /// Tables written per recording: raw_samples, period_mean, noise, kinematics.
    #[serde(default)]
    pub tables: Vec<String>,
}

/// Stages in the order the pipeline file lists them. A closed set: adding
/// one is a visible change to every `match`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum StageConfig {
    Align(AlignConfig),
    InverseFilter(InverseFilterConfig),
    Decimate(DecimateConfig),
    Average(NoOptions),
    Noise(NoiseConfig),
    Differentiate(DifferentiateConfig),
    Regressor(RegressorConfig),
    /// A reduce over all recordings: their regressor tables stacked, one
    /// `parameters.parquet` in the output folder.
    Estimate(EstimateConfig),
}

#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoOptions {}

#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseConfig {
    /// Excited harmonics (default: the recording's `robotid.harmonics`).
    pub harmonics: Option<Vec<u32>>,
}

/// What the data is at a point of the chain.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Data {
    Raw,
    Periods,
    PeriodMean,
    Noise,
    Kinematics,
    Regressor,
}

impl StageConfig {
    pub fn name(&self) -> &'static str {
        match self {
            StageConfig::Align(_) => "align",
            StageConfig::InverseFilter(_) => "inverse_filter",
            StageConfig::Decimate(_) => "decimate",
            StageConfig::Average(_) => "average",
            StageConfig::Noise(_) => "noise",
            StageConfig::Differentiate(_) => "differentiate",
            StageConfig::Regressor(_) => "regressor",
            StageConfig::Estimate(_) => "estimate",
        }
    }

    /// What the stage needs and what it adds.
    pub fn signature(&self) -> (&'static [Data], Option<Data>) {
        match self {
            StageConfig::Align(_) => (&[Data::Raw], Some(Data::Periods)),
            // Periodic (after align) or record mode (before it): either input.
            StageConfig::InverseFilter(_) | StageConfig::Decimate(_) => (&[], None),
            StageConfig::Average(_) => (&[Data::Periods], Some(Data::PeriodMean)),
            StageConfig::Noise(_) => (&[Data::Periods, Data::PeriodMean], Some(Data::Noise)),
            StageConfig::Differentiate(c) if c.method == Method::Filtered => (&[Data::Raw], Some(Data::Kinematics)),
            StageConfig::Differentiate(_) => (&[Data::PeriodMean], Some(Data::Kinematics)),
            StageConfig::Regressor(_) => (&[Data::Kinematics], Some(Data::Regressor)),
            StageConfig::Estimate(_) => (&[Data::Regressor], None),
        }
    }

    fn check(&self) -> Result<(), String> {
        match self {
            StageConfig::Align(c) => c.check(),
            StageConfig::InverseFilter(c) => c.check(),
            StageConfig::Decimate(c) => c.check(),
            StageConfig::Average(_) | StageConfig::Noise(_) | StageConfig::Regressor(_) => Ok(()),
            StageConfig::Differentiate(c) => c.check(),
            StageConfig::Estimate(c) => c.check(),
        }
    }
}

/// A validated pipeline.
#[derive(Debug, Clone)]
pub struct Plan {
    pub file: PathBuf,
    /// SHA-256 of the pipeline file's bytes.
    pub hash: String,
    pub robot: Option<PathBuf>,
    pub source: String,
    pub read: ReadConfig,
    pub stages: Vec<StageConfig>,
    pub tables: Vec<TableKind>,
}

/// Every problem found, each prefixed with its place.
#[derive(Debug, Clone, PartialEq)]
pub struct Problems(pub Vec<String>);

impl std::fmt::Display for Problems {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} problem(s): {}", self.0.len(), self.0.join("; "))
    }
}

impl std::error::Error for Problems {}

fn line_of(text: &str, offset: usize) -> usize {
    text[..offset.min(text.len())].matches('\n').count() + 1
}

/// Step 1, structure: the file parses, every stage and key is known, values
/// are in range, the chain of stages fits together.
pub fn parse(text: &str, file: &Path) -> Result<Plan, Problems> {
    let at = |msg: String| format!("{}: {msg}", file.display());
    let raw: PipelineFile =
        toml::from_str(text).map_err(|e| Problems(vec![at(robotid_stages::error_message_of_toml(text, &e))]))?;
    let mut problems = Vec::new();
    if raw.version != FORMAT_VERSION {
        problems.push(at(format!(
            "version {} is not supported (this build reads version {FORMAT_VERSION})",
            raw.version
        )));
    }
    if let Err(errs) = raw.read.check() {
        problems.extend(errs.into_iter().map(|e| at(format!("[read] {e}"))));
    }
    let mut stages = Vec::new();
    for (i, spanned) in raw.stage.iter().enumerate() {
        let line = line_of(text, spanned.span().start);
        let table = spanned.get_ref();
        let kind = table.get("kind").and_then(|v| v.as_str()).unwrap_or("?").to_string();
        let place = format!("stage {} (`{kind}`, line {line})", i + 1);
        match toml::Value::Table(table.clone()).try_into::<StageConfig>() {
            Ok(s) => {
                if let Err(e) = s.check() {
                    problems.push(at(format!("{place}: {e}")));
                }
                stages.push(s);
            }
            Err(e) => problems.push(at(format!("{place}: {}", e.message().trim()))),
        }
    }
    let mut tables = Vec::new();
    for t in &raw.output.tables {
        match t.parse::<TableKind>() {
            Ok(TableKind::Parameters) => problems.push(at(
                "[output] tables: `parameters` is made by estimation, not by a pipeline".into(),
            )),
            Ok(k) => tables.push(k),
            Err(_) => problems.push(at(format!("[output] tables: unknown table `{t}`"))),
        }
    }
    if !problems.is_empty() {
        return Err(Problems(problems));
    }
    Ok(Plan {
        file: file.to_path_buf(),
        hash: robotid_stages::formats::sha256_hex(text.as_bytes()),
        robot: raw.robot.map(|r| file.parent().unwrap_or(Path::new(".")).join(r)),
        source: raw.source.path,
        read: raw.read,
        stages,
        tables,
    })
}

/// Each stage finds what it needs before it; each requested table is made.
/// `start` is what the source holds.
pub fn check_chain(stages: &[StageConfig], tables: &[TableKind], start: Data) -> Vec<String> {
    let mut have = vec![start];
    let mut problems = Vec::new();
    for (i, s) in stages.iter().enumerate() {
        let (needs, adds) = s.signature();
        for need in needs {
            if !have.contains(need) {
                problems.push(format!(
                    "stage {} (`{}`) needs {:?} data, which no stage before it makes (order: read, align, inverse_filter, decimate, average, noise, differentiate, regressor, estimate)",
                    i + 1,
                    s.name(),
                    need
                ));
            }
        }
        if matches!(s, StageConfig::Estimate(_)) && i + 1 != stages.len() {
            problems.push(format!(
                "stage {} (`estimate`): it must be the last stage (it runs once, over all recordings)",
                i + 1
            ));
        }
        if matches!(s, StageConfig::Align(_)) && have.contains(&Data::Periods) {
            problems.push(format!("stage {} (`align`): the data is already aligned", i + 1));
        }
        if let Some(a) = adds {
            have.push(a);
        }
    }
    for t in tables {
        let need = match t {
            TableKind::RawSamples => Data::Raw,
            TableKind::PeriodMean => Data::PeriodMean,
            TableKind::Noise => Data::Noise,
            TableKind::Regressor | TableKind::RFactor => Data::Regressor,
            _ => Data::Kinematics,
        };
        if !have.contains(&need) {
            problems.push(format!("[output] tables: `{t}` is not made by any stage"));
        }
    }
    problems
}

/// What a source file holds: a raw log, or a robotid table from an earlier
/// run (`period_mean`, `kinematics`), which a pipeline may continue.
pub fn source_kind(path: &Path) -> Result<Data, String> {
    if !path.extension().is_some_and(|e| e.eq_ignore_ascii_case("parquet")) {
        return Ok(Data::Raw);
    }
    let file = std::fs::File::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let builder = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(match TableKind::of(builder.schema()) {
        Ok(TableKind::PeriodMean) => Data::PeriodMean,
        Ok(TableKind::Kinematics) => Data::Kinematics,
        Ok(TableKind::RawSamples) | Err(_) => Data::Raw,
        Ok(other) => {
            return Err(format!(
                "{}: a `{other}` table cannot start a preprocessing pipeline",
                path.display()
            ))
        }
    })
}

/// Step 2, context: the robot loads, the source names existing logs of one
/// kind, the chain of stages fits what they hold, the joints match.
/// Returns the robot, the logs and what they hold.
pub fn resolve(plan: &Plan) -> Result<(Option<Model>, Vec<PathBuf>, Data), Problems> {
    let mut problems = Vec::new();
    let at = |msg: String| format!("{}: {msg}", plan.file.display());
    let model = match &plan.robot {
        Some(r) => match load_robot(r) {
            Ok(m) => Some(m),
            Err(e) => {
                problems.push(at(format!("robot: {e}")));
                None
            }
        },
        None => None,
    };
    if let (Some(m), Some(j)) = (&model, &plan.read.joints) {
        let names = m.joint_names();
        for name in j {
            if !names.contains(name) {
                problems.push(at(format!(
                    "[read] joints: `{name}` is not a joint of robot `{}` ({names:?})",
                    m.name
                )));
            }
        }
    }
    if model.is_none() && plan.stages.iter().any(|s| matches!(s, StageConfig::Regressor(_))) {
        problems.push(at("the regressor stage needs the robot: set `robot`".into()));
    }
    if model.is_none() && plan.read.joints.is_none() && problems.is_empty() {
        problems.push(at("no robot and no [read] joints: the joint names are unknown".into()));
    }
    let logs = match source_files(plan) {
        Ok(l) => l,
        Err(e) => {
            problems.push(at(format!("[source] {e}")));
            Vec::new()
        }
    };
    let mut start = Data::Raw;
    let kinds: Vec<Result<Data, String>> = logs.iter().map(|l| source_kind(l)).collect();
    for k in &kinds {
        if let Err(e) = k {
            problems.push(at(format!("[source] {e}")));
        }
    }
    let kinds: Vec<Data> = kinds.into_iter().filter_map(Result::ok).collect();
    if let Some(first) = kinds.first() {
        start = *first;
        if kinds.iter().any(|k| k != first) {
            problems.push(at("[source] mixes raw logs and tables of other kinds".into()));
        }
    }
    problems.extend(check_chain(&plan.stages, &plan.tables, start).into_iter().map(at));
    for (i, s) in plan.stages.iter().enumerate() {
        if let StageConfig::Align(c) = s {
            if let Some(rel) = &c.reference_trajectory {
                if let Err(e) = reference_trajectory(plan, rel) {
                    problems.push(at(format!("stage {} (`align`): reference_trajectory: {e}", i + 1)));
                }
            }
        }
    }
    if problems.is_empty() {
        Ok((model, logs, start))
    } else {
        Err(Problems(problems))
    }
}

/// The logs a source names, sorted: a file, every csv/parquet/mcap file in
/// a folder, or the matches of a glob.
pub fn source_files(plan: &Plan) -> Result<Vec<PathBuf>, String> {
    let base = plan.file.parent().unwrap_or(Path::new("."));
    let full = base.join(&plan.source);
    let is_log = |p: &Path| {
        p.extension()
            .map(|e| {
                matches!(
                    e.to_string_lossy().to_ascii_lowercase().as_str(),
                    "csv" | "parquet" | "mcap"
                )
            })
            .unwrap_or(false)
    };
    let mut files: Vec<PathBuf> = if full.is_file() {
        vec![full.clone()]
    } else if full.is_dir() {
        std::fs::read_dir(&full)
            .map_err(|e| format!("{}: {e}", full.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.is_file() && is_log(p))
            .collect()
    } else {
        let pattern = full.to_string_lossy().into_owned();
        glob::glob(&pattern)
            .map_err(|e| format!("bad glob `{pattern}`: {e}"))?
            .filter_map(Result::ok)
            .filter(|p| p.is_file())
            .collect()
    };
    files.sort();
    if files.is_empty() {
        return Err(format!("path `{}` names no log file", full.display()));
    }
    Ok(files)
}

/// The periodic trajectory an `align` stage registers against, relative to
/// the pipeline file.
pub fn reference_trajectory(plan: &Plan, rel: &Path) -> Result<robotid_stages::trajectory::FourierSeries, String> {
    let path = plan.file.parent().unwrap_or(Path::new(".")).join(rel);
    match robotid_stages::trajectory::load_trajectory(&path).map_err(|e| e.to_string())? {
        robotid_stages::trajectory::Trajectory::Fourier(f) => Ok(f),
        _ => Err(format!(
            "{}: the trajectory is not periodic (kind = \"fourier\" needed)",
            path.display()
        )),
    }
}
