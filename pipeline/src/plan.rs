//! Pipeline files (format version 1, `docs/pipeline-file.md`): parsed into a
//! plain-data [`Plan`] and checked in two steps, structure ([`parse`]) then
//! context ([`lint`]: the robot, the logs, every stage against them),
//! reporting every problem at once with its place. Nothing is read from a
//! log's samples until the whole pipeline checks.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use robotid_schemas::{metadata, TableKind};
use robotid_stages::dynamics::{Model, Robot};
use robotid_stages::stage::align::AlignConfig;
use robotid_stages::stage::average::AverageConfig;
use robotid_stages::stage::decimate::DecimateConfig;
use robotid_stages::stage::differentiate::DifferentiateConfig;
use robotid_stages::stage::estimate::EstimateConfig;
use robotid_stages::stage::inverse_filter::InverseFilterConfig;
use robotid_stages::stage::noise::NoiseConfig;
use robotid_stages::stage::read::ReadConfig;
use robotid_stages::stage::regressor::RegressorConfig;
use robotid_stages::stage::{Component, Context, LintContext, Problem, Product, Stage};
use serde::{Deserialize, Serialize};

use crate::error::{Place, Placed, Problems};

pub const FORMAT_VERSION: u32 = 1;

/// File extensions a raw log may have (`read` decides the format by it).
pub const LOG_EXTENSIONS: &[&str] = &["csv", "txt", "dat", "tsv", "parquet", "mcap"];

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
    /// Joints of the robot's URDF held still in the recordings: name →
    /// position (rad or m). Joints not in `[read] joints` are locked too.
    #[serde(default)]
    lock: std::collections::BTreeMap<String, f64>,
    /// What `robotid identify` found in the data and wrote into this file
    /// as settings: key → value with its uncertainty and how it was found.
    /// Copied into every table's metadata as `robotid.inferred.<key>`.
    #[serde(default)]
    inferred: std::collections::BTreeMap<String, String>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SourceConfig {
    /// A log file, a folder of logs, or a glob; relative to the pipeline file.
    pub path: String,
}

#[derive(Debug, Clone, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputConfig {
    /// Tables written per recording: raw_samples, period_mean, noise, kinematics, regressor, r_factor.
    #[serde(default)]
    pub tables: Vec<String>,
}

/// The stages, in the order the pipeline file lists them. A closed set:
/// adding one is a new variant here and a line in [`each_stage!`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum StageConfig {
    Align(AlignConfig),
    InverseFilter(InverseFilterConfig),
    Decimate(DecimateConfig),
    Average(AverageConfig),
    Noise(NoiseConfig),
    Differentiate(DifferentiateConfig),
    Regressor(RegressorConfig),
    /// A reduce over all recordings: one `parameters.parquet` in the output folder.
    Estimate(EstimateConfig),
}

/// Applies `$f` to the [`Component`] inside any [`StageConfig`]: the one
/// exhaustive match every dispatch goes through.
macro_rules! each_stage {
    ($s:expr, $c:ident => $f:expr) => {
        match $s {
            StageConfig::Align($c) => $f,
            StageConfig::InverseFilter($c) => $f,
            StageConfig::Decimate($c) => $f,
            StageConfig::Average($c) => $f,
            StageConfig::Noise($c) => $f,
            StageConfig::Differentiate($c) => $f,
            StageConfig::Regressor($c) => $f,
            StageConfig::Estimate($c) => $f,
        }
    };
}

fn name_of<C: Component>(_: &C) -> &'static str {
    C::NAME
}

impl StageConfig {
    pub fn name(&self) -> &'static str {
        each_stage!(self, c => name_of(c))
    }

    pub fn takes(&self) -> &'static [Product] {
        each_stage!(self, c => c.takes())
    }

    pub fn makes(&self) -> Option<Product> {
        each_stage!(self, c => c.makes())
    }

    pub fn reads_periods(&self) -> robotid_stages::stage::PeriodsUse {
        each_stage!(self, c => c.reads_periods())
    }

    pub fn problems(&self) -> Vec<Problem> {
        each_stage!(self, c => c.problems())
    }

    pub fn lint(&self, ctx: &LintContext) -> Vec<Problem> {
        each_stage!(self, c => c.lint(ctx))
    }

    pub fn build(&self, ctx: &Context) -> robotid_stages::Result<Box<dyn Stage>> {
        each_stage!(self, c => c.build(ctx))
    }
}

/// A parsed pipeline: plain data, nothing loaded.
#[derive(Debug, Clone)]
pub struct Plan {
    pub file: PathBuf,
    /// SHA-256 of the pipeline file's bytes.
    pub hash: String,
    pub robot: Option<PathBuf>,
    pub source: String,
    pub read: ReadConfig,
    pub stages: Vec<StageConfig>,
    /// Line of each stage in the file.
    pub lines: Vec<usize>,
    pub tables: Vec<TableKind>,
    /// Locked joints and their positions (`[lock]`).
    pub lock: std::collections::BTreeMap<String, f64>,
    /// `[inferred]`: what `robotid identify` found in the data.
    pub inferred: std::collections::BTreeMap<String, String>,
}

/// A pipeline file as [`Plan::to_toml`] writes it (the fields of the file
/// [`parse`] reads, in its order).
#[derive(Serialize)]
struct Written<'a> {
    version: u32,
    #[serde(skip_serializing_if = "Option::is_none")]
    robot: Option<&'a Path>,
    source: SourceConfig,
    #[serde(skip_serializing_if = "Option::is_none")]
    read: Option<&'a ReadConfig>,
    stage: &'a [StageConfig],
    output: OutputConfig,
    #[serde(skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    lock: &'a std::collections::BTreeMap<String, f64>,
    #[serde(skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    inferred: &'a std::collections::BTreeMap<String, String>,
}

impl Plan {
    /// A plan made in code (`robotid identify`'s) rather than parsed: no
    /// stages yet, the tables none; `file` is where it will be written
    /// (relative paths and messages refer to it). Its text, hash and
    /// lines are those of [`Plan::to_toml`] once parsed; in memory,
    /// [`crate::Pipeline::from_plan`].
    pub fn draft(file: &Path, robot: Option<PathBuf>, source: String, read: ReadConfig) -> Plan {
        Plan {
            file: file.to_path_buf(),
            hash: String::new(),
            robot,
            source,
            read,
            stages: Vec::new(),
            lines: Vec::new(),
            tables: Vec::new(),
            lock: Default::default(),
            inferred: Default::default(),
        }
    }

    /// The pipeline file of this plan: parsed at the plan's `file`, it
    /// gives the plan back (test `pipeline_files_round_trip`). `[read]`
    /// is written when it is not the default.
    pub fn to_toml(&self) -> Result<String, toml::ser::Error> {
        // `robot` was resolved against the file's folder: a relative one
        // is written back relative to it; an absolute one stays absolute
        // (identify's plans are written elsewhere than `file`).
        let robot = self.robot.as_deref().map(|r| {
            if r.is_absolute() {
                r
            } else {
                r.strip_prefix(self.base_dir()).unwrap_or(r)
            }
        });
        toml::to_string(&Written {
            version: FORMAT_VERSION,
            robot,
            source: SourceConfig {
                path: self.source.clone(),
            },
            read: (self.read != ReadConfig::default()).then_some(&self.read),
            stage: &self.stages,
            output: OutputConfig {
                tables: self.tables.iter().map(|t| t.name().to_string()).collect(),
            },
            lock: &self.lock,
            inferred: &self.inferred,
        })
    }

    /// Which joints of the robot's description move, which are locked.
    pub fn locks(&self) -> robotid_stages::dynamics::Locks {
        robotid_stages::dynamics::Locks {
            keep: self.read.joints.clone(),
            positions: self.lock.clone(),
        }
    }

    /// The folder relative paths are resolved against.
    pub fn base_dir(&self) -> &Path {
        self.file.parent().unwrap_or(Path::new("."))
    }

    pub fn place(&self, i: usize, key: &str) -> Place {
        Place::Stage {
            index: i + 1,
            kind: self.stages[i].name().to_string(),
            line: self.lines[i],
            key: key.to_string(),
        }
    }

    pub fn estimate(&self) -> Option<&EstimateConfig> {
        self.stages.iter().find_map(|s| match s {
            StageConfig::Estimate(c) => Some(c),
            _ => None,
        })
    }
}

fn line_of(text: &str, offset: usize) -> usize {
    text[..offset.min(text.len())].matches('\n').count() + 1
}

/// Each `[[stage]]` table as its config, with the line it starts on; what
/// is wrong with any into `problems`.
fn parse_stages(
    text: &str,
    raw: &[toml::Spanned<toml::Table>],
    at: &dyn Fn(Place, String) -> Placed,
    problems: &mut Vec<Placed>,
) -> (Vec<StageConfig>, Vec<usize>) {
    let mut stages = Vec::new();
    let mut lines = Vec::new();
    for (i, spanned) in raw.iter().enumerate() {
        let line = line_of(text, spanned.span().start);
        let table = spanned.get_ref();
        let kind = table.get("kind").and_then(|v| v.as_str()).unwrap_or("?").to_string();
        match toml::Value::Table(table.clone()).try_into::<StageConfig>() {
            Ok(s) => {
                for p in s.problems() {
                    problems.push(at(
                        Place::Stage {
                            index: i + 1,
                            kind: kind.clone(),
                            line,
                            key: p.key,
                        },
                        p.message,
                    ));
                }
                stages.push(s);
                lines.push(line);
            }
            Err(e) => problems.push(at(
                Place::Stage {
                    index: i + 1,
                    kind,
                    line,
                    key: String::new(),
                },
                e.message().trim().to_string(),
            )),
        }
    }
    (stages, lines)
}

/// Step 1, structure: the file parses, every stage and key is known, values
/// are in range, the chain of stages fits together.
pub fn parse(text: &str, file: &Path) -> Result<Plan, Problems> {
    let at = |place: Place, message: String| Placed {
        file: file.to_path_buf(),
        place,
        message,
    };
    let raw: PipelineFile = toml::from_str(text)
        .map_err(|e| Problems(vec![at(Place::File, robotid_stages::error_message_of_toml(text, &e))]))?;
    let mut problems = Vec::new();
    if raw.version != FORMAT_VERSION {
        problems.push(at(
            Place::Key("version".into()),
            format!(
                "{} is not supported (this build reads version {FORMAT_VERSION})",
                raw.version
            ),
        ));
    }
    for p in raw.read.problems() {
        problems.push(at(Place::Read(p.key), p.message));
    }
    let (stages, lines) = parse_stages(text, &raw.stage, &at, &mut problems);
    let mut tables = Vec::new();
    for t in &raw.output.tables {
        match t.parse::<TableKind>() {
            Ok(TableKind::Parameters) => problems.push(at(
                Place::Key("output.tables".into()),
                "`parameters` is made by estimation, not by a pipeline".into(),
            )),
            Ok(k) => tables.push(k),
            Err(_) => problems.push(at(Place::Key("output.tables".into()), format!("unknown table `{t}`"))),
        }
    }
    let every_stage_parsed = stages.len() == raw.stage.len();
    let plan = Plan {
        file: file.to_path_buf(),
        hash: robotid_stages::formats::sha256_hex(text.as_bytes()),
        robot: raw.robot.map(|r| file.parent().unwrap_or(Path::new(".")).join(r)),
        source: raw.source.path,
        read: raw.read,
        stages,
        lines,
        tables,
        lock: raw.lock,
        inferred: raw.inferred,
    };
    if problems.is_empty() {
        return Ok(plan);
    }
    // Every problem at once: when each stage parsed, the context's problems
    // too (with a stage missing, the chain's would only echo that).
    if every_stage_parsed {
        if let Err(more) = lint(&plan) {
            for p in more.0 {
                if !problems.contains(&p) {
                    problems.push(p);
                }
            }
        }
    }
    Err(Problems(problems))
}

/// What step 2 found: the robot, the logs and what they hold.
#[derive(Debug, Clone)]
pub struct Resolved {
    pub model: Option<Arc<Model>>,
    /// SHA-256 of the robot file's bytes, when the plan names one.
    pub robot_sha256: Option<String>,
    pub logs: Vec<PathBuf>,
    pub start: Product,
}

/// The product a table kind is made from.
fn table_needs(t: TableKind) -> Product {
    match t {
        TableKind::RawSamples => Product::Raw,
        TableKind::PeriodMean => Product::PeriodMean,
        TableKind::Noise => Product::Noise,
        TableKind::Regressor | TableKind::RFactor => Product::Regressor,
        TableKind::Kinematics | TableKind::Parameters | TableKind::Payload => Product::Kinematics,
    }
}

/// Each stage finds what it needs before it, lints itself, and each
/// requested table is made. `start` is what the source holds.
pub fn check_chain(plan: &Plan, model: Option<&Model>, start: Product, provenance: Option<bool>) -> Vec<Placed> {
    let at = |place: Place, message: String| Placed {
        file: plan.file.clone(),
        place,
        message,
    };
    let names: Vec<&'static str> = plan.stages.iter().map(StageConfig::name).collect();
    let mut have = vec![start];
    let mut problems = Vec::new();
    for (i, s) in plan.stages.iter().enumerate() {
        for need in s.takes() {
            if !have.contains(need) {
                problems.push(at(
                    plan.place(i, ""),
                    format!(
                        "needs {need}, which no stage before it makes (order: read, align, inverse_filter, decimate, average, noise, differentiate, regressor, estimate)"
                    ),
                ));
            }
        }
        if matches!(s, StageConfig::Estimate(_)) && i + 1 != plan.stages.len() {
            problems.push(at(
                plan.place(i, ""),
                "it must be the last stage (it runs once, over all recordings)".into(),
            ));
        }
        let ctx = LintContext {
            model,
            base_dir: plan.base_dir(),
            before: &have,
            provenance,
            stages: &names,
        };
        // A robot that failed to load is reported once, by the caller, not
        // again by every stage that needs it.
        let robot_failed = plan.robot.is_some() && model.is_none();
        for p in s.lint(&ctx).into_iter().filter(|p| !(robot_failed && p.needs_robot)) {
            problems.push(at(plan.place(i, &p.key), p.message));
        }
        if let Some(a) = s.makes() {
            have.push(a);
        }
    }
    for t in &plan.tables {
        if !have.contains(&table_needs(*t)) {
            problems.push(at(
                Place::Key("output.tables".into()),
                format!("`{t}` is not made by any stage"),
            ));
        }
    }
    problems
}

/// What a source file holds: a raw log, or a robotid table from an earlier
/// run (`period_mean`, `kinematics`), which a pipeline may continue; and
/// whether it carries robotid's provenance (period, harmonics), when that
/// can be told without reading samples.
pub fn source_kind(path: &Path) -> robotid_stages::Result<(Product, Option<bool>)> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    if path.is_dir() {
        return Ok((Product::Raw, None)); // a rosbag2 folder
    }
    if robotid_stages::stage::read::TEXT_EXTENSIONS.contains(&ext.as_str()) {
        return Ok((Product::Raw, Some(false)));
    }
    if ext != "parquet" {
        return Ok((Product::Raw, None));
    }
    let file = std::fs::File::open(path).map_err(|e| robotid_stages::Error::io(path, e))?;
    let builder = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file).map_err(|e| {
        robotid_stages::Error::Decode {
            path: path.to_path_buf(),
            source: Box::new(e),
        }
    })?;
    let schema = builder.schema();
    let provenance = Some(schema.metadata().contains_key(metadata::HARMONICS));
    Ok(match TableKind::of(schema) {
        Ok(TableKind::PeriodMean) => (Product::PeriodMean, provenance),
        Ok(TableKind::Kinematics) => (Product::Kinematics, provenance),
        Ok(TableKind::RawSamples) => (Product::Raw, provenance),
        Err(_) => (Product::Raw, Some(false)),
        Ok(other) => {
            return Err(robotid_stages::Error::Format {
                path: path.to_path_buf(),
                msg: format!("a `{other}` table cannot start a preprocessing pipeline"),
            })
        }
    })
}

/// Step 2, context: the robot loads, the source names existing logs of one
/// kind, every stage lints clean against them, the joints match.
pub fn lint(plan: &Plan) -> Result<Resolved, Problems> {
    lint_with(plan, None, true)
}

/// The plan's robot `path` with its locks, and the file's digest: from
/// `read` where that is the file, else read now.
fn robot_of(plan: &Plan, path: &Path, read: Option<&Robot>) -> robotid_stages::Result<(Arc<Model>, String)> {
    let fresh;
    let robot = match read.filter(|x| x.path() == path) {
        Some(x) => x,
        None => {
            fresh = Robot::read(path)?;
            &fresh
        }
    };
    Ok((robot.model(&plan.locks())?, robot.sha256().to_string()))
}

/// [`lint`] with the robot file already read: `robot`, where it is the
/// plan's (else the plan's is read); the logs' channels and rate checked
/// where `read_logs` (not for a run on samples already read).
pub fn lint_with(plan: &Plan, robot: Option<&Robot>, read_logs: bool) -> Result<Resolved, Problems> {
    let mut problems = Vec::new();
    let at = |place: Place, message: String| Placed {
        file: plan.file.clone(),
        place,
        message,
    };
    let (model, robot_sha256) = match plan.robot.as_deref().map(|r| robot_of(plan, r, robot)) {
        Some(Ok((m, sha))) => (Some(m), Some(sha)),
        Some(Err(e)) => {
            problems.push(at(Place::Key("robot".into()), e.to_string()));
            (None, None)
        }
        None => (None, None),
    };
    let needs_all = plan.stages.iter().any(|s| matches!(s, StageConfig::Regressor(_)));
    if let Some(m) = &model {
        for p in plan.read.problems_with(m, needs_all) {
            problems.push(at(Place::Read(p.key), p.message));
        }
    }
    if plan.robot.is_none() && plan.read.joints.is_none() {
        problems.push(at(
            Place::Key("robot".into()),
            "no robot and no [read] joints: the joint names are unknown".into(),
        ));
    }
    let logs = match source_files(plan) {
        Ok(l) => l,
        Err(e) => {
            problems.push(at(Place::Source, e.to_string()));
            Vec::new()
        }
    };
    let mut start = Product::Raw;
    let mut provenance = None;
    let mut kinds = Vec::new();
    for l in &logs {
        match source_kind(l) {
            Ok(k) => kinds.push(k),
            Err(e) => problems.push(at(Place::Source, e.to_string())),
        }
    }
    if let Some(first) = kinds.first() {
        start = first.0;
        if kinds.iter().any(|k| k.0 != first.0) {
            problems.push(at(Place::Source, "mixes raw logs and tables of other kinds".into()));
        }
        // Provenance known to be absent from any log: the settings it would give are needed.
        provenance = if kinds.iter().any(|k| k.1 == Some(false)) {
            Some(false)
        } else if kinds.iter().all(|k| k.1 == Some(true)) {
            Some(true)
        } else {
            None
        };
    }
    problems.extend(check_chain(plan, model.as_deref(), start, provenance));
    if start == Product::Raw {
        problems.extend(source_problems(plan, &logs, read_logs));
    }
    if problems.is_empty() {
        Ok(Resolved {
            model,
            robot_sha256,
            logs,
            start,
        })
    } else {
        Err(Problems(problems))
    }
}

/// A pipeline run into a folder must write something there: one with no
/// tables and no `estimate` ran and wrote nothing, silently. (Pipelines
/// run in memory, as identify's probes, need neither.)
pub fn output_problems(plan: &Plan) -> Vec<Placed> {
    if plan.tables.is_empty() && !plan.stages.iter().any(|s| matches!(s, StageConfig::Estimate(_))) {
        vec![Placed {
            file: plan.file.clone(),
            place: Place::Key("output.tables".into()),
            message: "the pipeline writes nothing: list the tables to write under [output], or end it with an `estimate` stage".into(),
        }]
    } else {
        Vec::new()
    }
}

/// What the logs refuse before a sample is read: the `[read]` settings
/// their format or summary does not have (`read::log_problems`), and the
/// stages' bands and harmonics beyond the Nyquist frequency of the rate
/// declared (`align.sample_rate_hz`) or told by an MCAP summary.
fn source_problems(plan: &Plan, logs: &[PathBuf], read_logs: bool) -> Vec<Placed> {
    use robotid_stages::stage::read::{log_problems, log_rate, Log, MappedLog};
    let at = |place: Place, message: String| Placed {
        file: plan.file.clone(),
        place,
        message,
    };
    let mut out = Vec::new();
    let logs = if read_logs { logs } else { &[] };
    // An MCAP log's summary tells its topics and its rate: mapped once for
    // both, not hashed (the run's read verifies its checksum); a text or
    // Parquet log is not opened here.
    let mapped: Vec<Option<MappedLog>> = logs
        .iter()
        .map(|l| {
            (Log::File(l).format() == "mcap")
                .then(|| MappedLog::unverified(l).ok())
                .flatten()
        })
        .collect();
    let log = |i: usize| mapped[i].as_ref().map_or(Log::File(&logs[i]), MappedLog::log);
    for i in 0..logs.len() {
        out.extend(
            log_problems(log(i), &plan.read)
                .into_iter()
                .map(|p| at(Place::Read(p.key), p.message)),
        );
    }
    let declared = plan.stages.iter().find_map(|s| match s {
        StageConfig::Align(a) => Some((a.sample_rate_hz, a.period_s)),
        _ => None,
    });
    let (rate, period) = declared.unwrap_or((None, None));
    let Some((fs, whose)) = rate.map(|r| (r, "align.sample_rate_hz".to_string())).or_else(|| {
        (0..logs.len())
            .find_map(|i| log_rate(log(i), &plan.read).map(|r| (r, format!("the rate of {}", logs[i].display()))))
    }) else {
        return out;
    };
    // A rate from message counts is a float's hair off the nominal one.
    let fs = (fs * 1e6).round() / 1e6;
    let nyquist = 0.5 * fs;
    let beyond = |hz: f64| hz > nyquist * (1.0 + 1e-9);
    let said = format!("beyond the Nyquist frequency, {nyquist} Hz ({whose}, {fs} Hz)");
    for (i, s) in plan.stages.iter().enumerate() {
        let mut bands: Vec<(&str, f64)> = Vec::new();
        let mut harmonics: Option<&Vec<u32>> = None;
        match s {
            StageConfig::InverseFilter(c) => {
                bands.push(("bandwidth_hz", c.bandwidth_hz));
                bands.extend(c.filter.as_ref().map(|f| ("filter.cutoff_hz", f.cutoff_hz)));
            }
            StageConfig::Differentiate(c) => {
                bands.extend(c.bandwidth_hz.map(|b| ("bandwidth_hz", b)));
                harmonics = c.harmonics.as_ref();
            }
            StageConfig::Noise(c) => harmonics = c.harmonics.as_ref(),
            _ => {}
        }
        for (key, hz) in bands.into_iter().filter(|(_, hz)| beyond(*hz)) {
            out.push(at(plan.place(i, key), format!("{hz} Hz is {said}")));
        }
        if let (Some(h), Some(p)) = (harmonics, period) {
            if let Some(top) = h.iter().max().filter(|&&top| beyond(top as f64 / p)) {
                out.push(at(
                    plan.place(i, "harmonics"),
                    format!("harmonic {top} of the {p} s period, {} Hz, is {said}", *top as f64 / p),
                ));
            }
        }
    }
    out
}

/// The logs a source names, sorted: a file, every log file in a folder, or
/// the matches of a glob. A file of an extension no reader takes is refused.
pub fn source_files(plan: &Plan) -> robotid_stages::Result<Vec<PathBuf>> {
    let full = plan.base_dir().join(&plan.source);
    let is_log = |p: &Path| {
        p.extension()
            .map(|e| LOG_EXTENSIONS.contains(&e.to_string_lossy().to_ascii_lowercase().as_str()))
            .unwrap_or(false)
    };
    let bag = |p: &Path| p.is_dir() && p.join("metadata.yaml").is_file();
    let mut files: Vec<PathBuf> = if full.is_file() || bag(&full) {
        vec![full.clone()]
    } else if full.is_dir() {
        std::fs::read_dir(&full)
            .map_err(|e| robotid_stages::Error::io(&full, e))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| (p.is_file() && is_log(p)) || bag(p))
            .collect()
    } else {
        let pattern = full.to_string_lossy().into_owned();
        glob::glob(&pattern)
            .map_err(|e| {
                robotid_stages::Error::setting(
                    "source.path",
                    "a file, a folder or a glob",
                    format!("`{pattern}` ({e})"),
                )
            })?
            .filter_map(Result::ok)
            .filter(|p| p.is_file() || bag(p))
            .collect()
    };
    files.sort();
    if files.is_empty() {
        return Err(robotid_stages::Error::missing(
            "a log file",
            format!("path `{}` names no log file", full.display()),
        ));
    }
    let unreadable: Vec<String> = files
        .iter()
        .filter(|p| !is_log(p) && !bag(p))
        .map(|p| p.display().to_string())
        .collect();
    if !unreadable.is_empty() {
        return Err(robotid_stages::Error::setting(
            "source.path",
            format!("logs a reader takes ({})", LOG_EXTENSIONS.join(", ")),
            unreadable.join(", "),
        ));
    }
    Ok(files)
}
