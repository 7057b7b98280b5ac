//! The `read` stage: a raw log (CSV, Parquet or MCAP) → `raw_samples` in
//! SI units, with the effort channel as joint torque (N·m).
//!
//! The pipeline file maps the log's columns (CSV, Parquet) or topics and
//! fields (MCAP) to joints and says their units; counts and currents are
//! converted with the robot's drives (or the constants given here). Every
//! value is checked: a NaN or infinity names the file, channel and sample.

mod guess;
mod mcap;
mod parquet;
mod text;
mod transmission;

pub use guess::{guess_read, headerless_layouts, named_joints, NoColumn};

use std::path::Path;

use robotid_schemas::{metadata, RawSamples, TorqueChannel};
use serde::{Deserialize, Serialize};

use super::Problem;
use crate::dynamics::Model;
use crate::{Error, Result};

/// Where one channel is in the log and its unit. `column` (CSV, Parquet)
/// may hold `{joint}` (the joint name) or `{index}` (1-based joint number).
/// `topic` and `field` (MCAP): a `sensor_msgs/msg/JointState` topic and one
/// of `position`, `velocity`, `effort`, values matched to joints by name; or
/// a JSON topic and the key of an array with one value per joint, in joint
/// order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Channel {
    /// Text and Parquet logs: a column name or template (`q_{joint}`,
    /// `q{index}_rad`), a 0-based column number, or one of either per joint.
    pub column: Option<Column>,
    /// MCAP logs: the topic and the message field (`position`, `velocity`,
    /// `effort`; JSON: the array's key).
    pub topic: Option<String>,
    pub field: Option<String>,
    /// Default: s (time; MCAP log times ns), rad (position, reference),
    /// N·m for a JointState `effort` field or a torque-named column, A for
    /// a current-named one; other effort columns must say.
    pub unit: Option<String>,
    /// Which side of the transmission the channel measures: `motor` goes
    /// through the robot file's transmission (coupled motors, gear ratios,
    /// motor offsets) to the joints. Default: motor for encoder counts and
    /// currents, joint otherwise.
    pub side: Option<Side>,
}

impl Channel {
    /// The channel at `column` in `unit`: what `{ column = …, unit = … }`
    /// says in a `[read]` table.
    pub fn at(column: impl Into<Column>, unit: &str) -> Channel {
        Channel {
            column: Some(column.into()),
            topic: None,
            field: None,
            unit: Some(unit.into()),
            side: None,
        }
    }
}

/// The side of the transmission a position or effort channel measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Side {
    Joint,
    Motor,
}

/// Where a channel is in a text or Parquet log.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Column {
    /// 0-based column number.
    Index(usize),
    /// A name, or a template with `{joint}` (name) or `{index}` (1-based joint number).
    Name(String),
    /// One column per joint, in joint order.
    Each(Vec<OneColumn>),
}

/// One column by number or name.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum OneColumn {
    Index(usize),
    Name(String),
}

impl From<&str> for Column {
    fn from(s: &str) -> Column {
        Column::Name(s.to_string())
    }
}

/// How the fields of a text log are separated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Separator {
    Comma,
    Semicolon,
    Tab,
    /// Runs of spaces or tabs.
    Whitespace,
}

/// The decimal mark of a text log's numbers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Decimal {
    Point,
    Comma,
}

#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReadConfig {
    /// Joint names, in model order (default: the robot's).
    pub joints: Option<Vec<String>>,
    /// Time column (default `time` in s; MCAP: the message log time).
    pub time: Option<Channel>,
    /// Positions (default: `q_{joint}` in rad; MCAP: `/joint_states` position).
    pub position: Option<Channel>,
    /// Motor current or joint torque (default: `current_{joint}` in A, else
    /// `torque_{joint}` in N·m; MCAP: `/joint_states` effort in N·m).
    pub effort: Option<Channel>,
    /// Reference positions (optional).
    pub reference: Option<Channel>,
    /// Joint torque per ampere (N·m/A) per joint, when there is no robot file.
    pub torque_per_amp: Option<Vec<f64>>,
    /// Joint angle per encoder count (rad) per joint, when there is no robot file.
    pub radians_per_count: Option<Vec<f64>>,
    /// Text logs: whether the first line names the columns (default:
    /// detected; a first line of numbers is data).
    pub header: Option<bool>,
    /// Text logs: `comma`, `semicolon`, `tab` or `whitespace` (default:
    /// detected from the first line).
    pub separator: Option<Separator>,
    /// Text logs: `point` or `comma` (default: detected; a comma can only be
    /// the decimal mark when it is not the separator).
    pub decimal: Option<Decimal>,
    /// Text logs: a last line with too few fields (a write cut short) is
    /// dropped with a note instead of refused.
    #[serde(default)]
    pub drop_truncated_last_line: bool,
    /// Isolated spikes (a sample far from both neighbours, which agree):
    /// `refuse` (default: an error naming the sample) or `repair` (each
    /// replaced by its neighbours' mean, with a note counting them).
    #[serde(default)]
    pub spikes: Spikes,
    /// Torques beyond this multiple of the robot file's torque limit are
    /// refused at their sample (default 3; a current read in the wrong
    /// unit, a corrupt value).
    pub max_torque_factor: Option<f64>,
    /// Text and Parquet logs stamped by their rate, Hz: without a `time`
    /// channel, row k is at k / rate s; with `time = { column = …, unit =
    /// "sample" }`, the column's sample numbers at that rate (a gap in
    /// them is a gap in time).
    pub sample_rate_hz: Option<f64>,
}

/// The highest `sample_rate_hz` read (1 MHz: over any joint controller's).
pub const MAX_SAMPLE_RATE_HZ: f64 = 1e6;

/// What the read stage does with an isolated spike.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Spikes {
    #[default]
    Refuse,
    Repair,
}

/// Default of `max_torque_factor`.
pub const MAX_TORQUE_FACTOR: f64 = 3.0;

/// The samples of `col` that are isolated spikes: far (T) from both
/// neighbours, on the same side of them, while the neighbours agree
/// (within T/4). T is 50× the median step (a signal's own steps, noise
/// included, are seldom 10× it), at least 1e-3 of the column's range (so
/// that encoder counts on a slow motion are not spikes) and 3 of its
/// smallest steps (a held joint's encoder flickering by a count, whose
/// median step is 0 and range one count, is not either).
pub fn spikes(col: &[f64]) -> Vec<usize> {
    let n = col.len();
    if n < 5 {
        return Vec::new();
    }
    let mut steps: Vec<f64> = col.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
    let quantum = steps.iter().copied().filter(|&s| s > 0.0).fold(f64::INFINITY, f64::min);
    let mid = steps.len() / 2;
    let median = *steps.select_nth_unstable_by(mid, f64::total_cmp).1;
    // The range without the spikes themselves: from the 1st to 99th percentile.
    let mut sorted = col.to_vec();
    let lo = *sorted.select_nth_unstable_by(n / 100, f64::total_cmp).1;
    let hi = *sorted.select_nth_unstable_by(n - 1 - n / 100, f64::total_cmp).1;
    let t = (50.0 * median).max(1e-3 * (hi - lo)).max(3.0 * quantum);
    if !(t > 0.0 && t.is_finite()) {
        return Vec::new();
    }
    (1..n - 1)
        .filter(|&k| {
            let (d1, d2) = (col[k] - col[k - 1], col[k] - col[k + 1]);
            d1.abs() > t && d2.abs() > t && d1.signum() == d2.signum() && (col[k + 1] - col[k - 1]).abs() < t / 4.0
        })
        .collect()
}

/// Extensions of the delimited-text logs (all read alike).
pub const TEXT_EXTENSIONS: &[&str] = &["csv", "txt", "dat", "tsv"];

/// Unit conversions the read stage knows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Scale {
    /// Multiply by this factor.
    Factor(f64),
    /// Encoder counts: per joint radians per count.
    Counts,
    /// Motor current: per joint torque per ampere, times the factor (mA → 1e-3).
    Current(f64),
    /// Sample numbers: over `sample_rate_hz`.
    Sample,
}

/// What a unit string means for a channel kind.
pub fn unit_scale(kind: &str, unit: &str) -> Result<Scale> {
    let u = unit.trim();
    let s = match (kind, u) {
        ("time", "s") => Scale::Factor(1.0),
        ("time", "ms") => Scale::Factor(1e-3),
        ("time", "us") => Scale::Factor(1e-6),
        ("time", "ns") => Scale::Factor(1e-9),
        ("time", "sample" | "samples") => Scale::Sample,
        ("position" | "reference", "rad") => Scale::Factor(1.0),
        ("position" | "reference", "deg") => Scale::Factor(std::f64::consts::PI / 180.0),
        ("position" | "reference", "count" | "counts") => Scale::Counts,
        ("effort", "N*m" | "Nm" | "N.m" | "N·m") => Scale::Factor(1.0),
        ("effort", "A") => Scale::Current(1.0),
        ("effort", "mA") => Scale::Current(1e-3),
        _ => {
            let known = match kind {
                "time" => "s, ms, us, ns, sample (with `sample_rate_hz`)",
                "effort" => "A, mA, N*m",
                _ => "rad, deg, count",
            };
            return Err(Error::setting(
                format!("{kind}.unit"),
                format!("one of {known}"),
                format!("`{u}`"),
            ));
        }
    };
    Ok(s)
}

impl ReadConfig {
    /// The `[read]` table of a TOML file (as in a pipeline file): where
    /// the channels are for every recording of an identify.
    pub fn from_file(path: &std::path::Path) -> Result<ReadConfig> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        let config = |msg: String| Error::Config {
            path: path.to_path_buf(),
            msg,
        };
        let mut t: toml::Table = text
            .parse()
            .map_err(|e| config(crate::error::toml_message(&text, &e)))?;
        let r = t.remove("read").ok_or_else(|| config("no `[read]` table".into()))?;
        r.try_into()
            .map_err(|e: toml::de::Error| config(format!("its `[read]` table: {}", e.message())))
    }

    /// Each channel kind with what is said of it, in the file's order.
    pub fn channels(&self) -> [(&'static str, &Option<Channel>); 4] {
        [
            ("time", &self.time),
            ("position", &self.position),
            ("effort", &self.effort),
            ("reference", &self.reference),
        ]
    }

    /// Structural problems (units known, channel given one way), keyed.
    pub fn problems(&self) -> Vec<Problem> {
        let mut out = Vec::new();
        for (kind, ch) in self.channels() {
            if let Some(c) = ch {
                if let Some(u) = &c.unit {
                    if let Err(e) = unit_scale(kind, u) {
                        out.push(Problem::new(format!("{kind}.unit"), e.to_string()));
                    }
                }
                if c.column.is_some() && (c.topic.is_some() || c.field.is_some()) {
                    out.push(Problem::new(
                        kind,
                        "give `column` (CSV, Parquet) or `topic`/`field` (MCAP), not both",
                    ));
                }
            }
        }
        if self.joints.as_ref().is_some_and(|j| j.is_empty()) {
            out.push(Problem::new("joints", "is empty: name the recorded joints"));
        }
        out.extend(self.rate_problems());
        if let Some(f) = self.max_torque_factor.filter(|f| !(*f >= 1.0 && f.is_finite())) {
            out.push(Problem::new(
                "max_torque_factor",
                format!("must be a finite multiple ≥ 1 of the torque limits, not {f}"),
            ));
        }
        out
    }

    /// A declared rate out of range, or said beside stamps it would
    /// contradict; sample numbers without a rate.
    fn rate_problems(&self) -> Vec<Problem> {
        let sample_numbers = self
            .time
            .as_ref()
            .and_then(|c| c.unit.as_deref())
            .is_some_and(|u| matches!(unit_scale("time", u), Ok(Scale::Sample)));
        let stamped = self
            .time
            .as_ref()
            .is_some_and(|c| c.column.is_some() || c.topic.is_some());
        let mut out = Vec::new();
        match self.sample_rate_hz {
            Some(r) if !(r > 0.0 && r <= MAX_SAMPLE_RATE_HZ) => out.push(Problem::new(
                "sample_rate_hz",
                format!("must be over 0 and at most {MAX_SAMPLE_RATE_HZ:e} Hz, not {r}"),
            )),
            Some(_) if stamped && !sample_numbers => out.push(Problem::new(
                "sample_rate_hz",
                "is said beside a `time` channel of stamps: give the stamps or the rate (or the time column's unit as `sample`, its sample numbers at that rate)",
            )),
            None if sample_numbers => out.push(Problem::new(
                "time.unit",
                "`sample` needs the rate: give `sample_rate_hz`",
            )),
            _ => {}
        }
        out
    }

    /// Problems of the joints against the robot; `all_needed` when a
    /// stage (the regressor) needs every joint of it.
    pub fn problems_with(&self, model: &Model, all_needed: bool) -> Vec<Problem> {
        let names = model.joint_names();
        let mut out = Vec::new();
        if let Some(j) = &self.joints {
            for name in j {
                if !names.contains(name) {
                    out.push(Problem::new(
                        "joints",
                        format!(
                            "`{name}` is not a joint of robot `{}` ({})",
                            model.name,
                            names.join(", ")
                        ),
                    ));
                }
            }
            if all_needed && out.is_empty() && *j != names {
                out.push(Problem::new(
                    "joints",
                    format!(
                        "{j:?} are not all of robot `{}`'s joints in its order ({names:?}): the regressor needs every joint (lock the others in the robot file)",
                        model.name
                    ),
                ));
            }
        }
        out
    }
}

/// Raw columns as found in a log, before unit conversion.
pub(crate) struct Columns {
    pub time: Vec<f64>,
    pub position: Vec<Vec<f64>>,
    pub effort: Vec<Vec<f64>>,
    pub reference: Option<Vec<Vec<f64>>>,
    /// Channel names for error messages, per joint.
    pub names: [Vec<String>; 3],
    pub metadata: std::collections::BTreeMap<String, String>,
}

/// The column names of a text or Parquet log; None for a text log without
/// a header line and for MCAP (topics, not columns).
pub fn log_columns<'a>(log: impl Into<Log<'a>>) -> Result<Option<Vec<String>>> {
    let log = log.into();
    match log.format().as_str() {
        e if TEXT_EXTENSIONS.contains(&e) => text::header_of(log),
        "parquet" => {
            let builder = match log {
                Log::File(path) => crate::formats::parquet::open(path)?,
                Log::Bytes { name, bytes, .. } => crate::formats::parquet::open_bytes(name, bytes.clone())?,
            };
            Ok(Some(
                builder.schema().fields().iter().map(|f| f.name().clone()).collect(),
            ))
        }
        _ => Ok(None),
    }
}

/// A name from a log as a message shows it: characters that print as
/// nothing or move the text (a zero-width space, a control character, a
/// byte-order mark) escaped as `\u{200b}`, so that `q_a3` and `q_a3\u{200b}`
/// do not look the same.
pub fn shown(name: &str) -> String {
    if name.chars().all(|c| !c.is_control() && !invisible(c)) {
        return name.to_string();
    }
    name.chars()
        .map(|c| {
            if c.is_control() || invisible(c) {
                format!("\\u{{{:x}}}", c as u32)
            } else {
                c.to_string()
            }
        })
        .collect()
}

/// Format characters that print as nothing (Unicode Cf: zero-width
/// spaces and joiners, direction marks, the byte-order mark, soft hyphen).
fn invisible(c: char) -> bool {
    matches!(c, '\u{ad}' | '\u{200b}'..='\u{200f}' | '\u{202a}'..='\u{202e}' | '\u{2060}'..='\u{2064}' | '\u{feff}')
}

/// The rate a log's positions are sampled at, Hz, when it can be told
/// without reading them (an MCAP summary's statistics); None otherwise.
pub fn log_rate<'a>(log: impl Into<Log<'a>>, cfg: &ReadConfig) -> Option<f64> {
    let log = log.into();
    if log.format() != "mcap" {
        return None;
    }
    let topic = cfg
        .position
        .as_ref()
        .and_then(|c| c.topic.clone())
        .unwrap_or_else(|| "/joint_states".into());
    mcap::mcap_rate(log, &topic)
}

/// What the read settings ask of a log that its format or its summary
/// refuses before a sample is read (what `lint` checks): columns on an
/// MCAP log, topics and fields on a text or Parquet one, an MCAP topic
/// the file does not have, a JointState field that is not one.
pub fn log_problems<'a>(log: impl Into<Log<'a>>, cfg: &ReadConfig) -> Vec<Problem> {
    let log = log.into();
    let name = log.path().display();
    let mcap = log.format() == "mcap";
    let mut out = Vec::new();
    for (key, ch) in cfg.channels() {
        let Some(c) = ch else { continue };
        if mcap && c.column.is_some() {
            out.push(Problem::new(
                key,
                format!("`column` on the MCAP log {name}: its channels are given by `topic` and `field`"),
            ));
        }
        if !mcap && (c.topic.is_some() || c.field.is_some()) {
            out.push(Problem::new(
                key,
                format!("`topic` or `field` on {name}, a table of columns: give its channel by `column`"),
            ));
        }
    }
    if !mcap {
        return out;
    }
    let Ok(Some(topics)) = mcap::mcap_topics(log) else {
        return out;
    };
    let wanted = [
        ("position", &cfg.position, "/joint_states", "position"),
        ("effort", &cfg.effort, "/joint_states", "effort"),
    ]
    .into_iter()
    .chain(
        cfg.reference
            .iter()
            .map(|_| ("reference", &cfg.reference, "/joint_reference", "position")),
    );
    for (key, ch, topic, field) in wanted {
        let c = ch.as_ref();
        let topic = c.and_then(|c| c.topic.clone()).unwrap_or_else(|| topic.into());
        let field = c.and_then(|c| c.field.clone()).unwrap_or_else(|| field.into());
        match topics.iter().find(|t| t.topic == topic) {
            None => out.push(Problem::new(
                key,
                format!(
                    "topic `{topic}` is not in {name}, which has {}",
                    topics
                        .iter()
                        .map(|t| format!("{} ({})", t.topic, t.schema))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            )),
            Some(t)
                if t.schema == "sensor_msgs/msg/JointState"
                    && !["position", "velocity", "effort"].contains(&field.as_str()) =>
            {
                out.push(Problem::new(
                    key,
                    format!("field `{field}` of `{topic}` in {name}: a JointState has position, velocity and effort"),
                ))
            }
            Some(mcap::Topic {
                schema,
                fields: Some(fields),
                ..
            }) if !fields.contains(&field) => out.push(Problem::new(
                key,
                format!(
                    "field `{field}` is not in `{topic}` of {name}: its {schema} has {}",
                    fields.join(", ")
                ),
            )),
            Some(_) => {}
        }
    }
    out
}

/// Whether an MCAP log at `path` holds the reference topic robotid reads
/// by default (`/joint_reference`, as `robotid simulate` writes it).
pub fn mcap_has_reference(path: &Path) -> bool {
    let is_mcap = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("mcap"));
    is_mcap
        && matches!(mcap::mcap_topics(Log::File(path)), Ok(Some(topics)) if topics.iter().any(|t| t.topic == crate::formats::mcap::TOPIC_REFERENCE))
}

/// The joint names an MCAP log's position messages carry (JointState and
/// its kin); None for other formats and for messages without names.
pub fn log_joint_names<'a>(log: impl Into<Log<'a>>, cfg: &ReadConfig) -> Result<Option<Vec<String>>> {
    let log = log.into();
    if log.format() == "mcap" {
        mcap::mcap_joint_names(log, cfg)
    } else {
        Ok(None)
    }
}

/// The number of fields of a text log's lines (None for other formats).
pub fn log_width<'a>(log: impl Into<Log<'a>>) -> Result<Option<usize>> {
    let log = log.into();
    if TEXT_EXTENSIONS.contains(&log.format().as_str()) {
        text::width_of(log)
    } else {
        Ok(None)
    }
}

/// A log file mapped into memory once, for the many reads one design
/// makes of it (its header, its joint names, each layout tried): each
/// reads the mapping rather than opening the file again. Its checksum
/// file, where it has one, is verified here, once. A rosbag2 folder
/// stays a folder, read file by file.
pub struct MappedLog {
    path: std::path::PathBuf,
    format: String,
    bytes: Option<bytes::Bytes>,
}

impl MappedLog {
    /// Mapped, its checksum file (where it has one) verified: for reading
    /// its samples.
    pub fn open(path: &Path) -> Result<MappedLog> {
        let log = MappedLog::unverified(path)?;
        if let Some(bytes) = log.bytes.as_ref().filter(|_| checksum_path(path).is_file()) {
            verify_checksum(path, &crate::formats::sha256_hex(bytes))?;
        }
        Ok(log)
    }

    /// Mapped, not hashed: for what reads only a summary (the lint's MCAP
    /// topics and rate), whose read later verifies the bytes it reads.
    pub fn unverified(path: &Path) -> Result<MappedLog> {
        let bytes = match path.is_dir() {
            true => None,
            false => Some(crate::formats::mapped(path)?),
        };
        Ok(MappedLog {
            path: path.to_path_buf(),
            format: Log::File(path).format(),
            bytes,
        })
    }

    /// The log to read: the mapping, named by the file's path.
    pub fn log(&self) -> Log<'_> {
        match &self.bytes {
            Some(bytes) => Log::Bytes {
                name: &self.path,
                format: &self.format,
                bytes,
            },
            None => Log::File(&self.path),
        }
    }
}

/// A log's content: a file (for MCAP also a rosbag2 folder), or its bytes
/// in memory (Python's `bytes`, the fuzzers), with the name errors give
/// it and its format as a file extension (`csv`, `parquet`, `mcap`, …).
#[derive(Debug, Clone, Copy)]
pub enum Log<'a> {
    File(&'a Path),
    Bytes {
        name: &'a Path,
        format: &'a str,
        bytes: &'a bytes::Bytes,
    },
}

impl<'a> From<&'a Path> for Log<'a> {
    fn from(path: &'a Path) -> Log<'a> {
        Log::File(path)
    }
}

impl<'a> From<&'a std::path::PathBuf> for Log<'a> {
    fn from(path: &'a std::path::PathBuf) -> Log<'a> {
        Log::File(path)
    }
}

impl Log<'_> {
    /// The path its errors name.
    pub fn path(&self) -> &Path {
        match self {
            Log::File(p) => p,
            Log::Bytes { name, .. } => name,
        }
    }

    /// Its format as a lower-case extension; a rosbag2 folder's is `mcap`.
    pub fn format(&self) -> String {
        match self {
            Log::File(p) if p.is_dir() => "mcap".into(),
            Log::File(p) => p
                .extension()
                .map(|e| e.to_string_lossy().to_ascii_lowercase())
                .unwrap_or_default(),
            Log::Bytes { format, .. } => format.to_ascii_lowercase(),
        }
    }

    /// SHA-256 of its content ([`hash_recording`] for a file).
    pub fn sha256(&self) -> Result<String> {
        match self {
            Log::File(p) => hash_recording(p),
            Log::Bytes { bytes, .. } => Ok(crate::formats::sha256_hex(bytes)),
        }
    }
}

/// Reads `path` into `raw_samples`. `model` supplies joint names and drive
/// constants when given.
pub fn read(path: &Path, cfg: &ReadConfig, model: Option<&Model>) -> Result<RawSamples> {
    read_log(Log::File(path), cfg, model)
}

/// The joints a log is read for (the source's, else the robot file's),
/// once its rate settings are checked: a positive rate, and none on an
/// MCAP log, whose messages carry their log times.
fn checked_joints(path: &Path, ext: &str, cfg: &ReadConfig, model: Option<&Model>) -> Result<Vec<String>> {
    let joints: Vec<String> = cfg
        .joints
        .clone()
        .or_else(|| model.map(Model::joint_names))
        .ok_or_else(|| Error::Config {
            path: path.to_path_buf(),
            msg: "no joint names: give `joints` in the source or a robot file".into(),
        })?;
    if let Some(p) = cfg.rate_problems().first() {
        return Err(Error::Config {
            path: path.to_path_buf(),
            msg: format!("`{}` {}", p.key, p.message),
        });
    }
    if ext == "mcap" && cfg.sample_rate_hz.is_some() {
        return Err(Error::Config {
            path: path.to_path_buf(),
            msg: "`sample_rate_hz` on an MCAP log, whose messages carry their log times".into(),
        });
    }
    Ok(joints)
}

/// The log's times in s from its first: its time column in its unit, or
/// with no time column `rows` rows at the declared rate (said in `md`,
/// with the rate). Text logs stamp absolute times: their origin is kept in
/// `md` and the times made relative to it (MCAP's are subtracted in
/// integer nanoseconds).
fn read_times(
    units: &Units,
    ext: &str,
    (time, rows): (&mut Vec<f64>, usize),
    md: &mut std::collections::BTreeMap<String, String>,
) -> Result<()> {
    let cfg = units.cfg;
    let unit = cfg.time.as_ref().and_then(|c| c.unit.clone());
    let time_unit = unit.unwrap_or_else(|| (if ext == "mcap" { "ns" } else { "s" }).to_string());
    match (cfg.sample_rate_hz, cfg.time.as_ref().and_then(|c| c.column.as_ref())) {
        // No time column: the rows' numbers at the rate.
        (Some(rate), None) => {
            *time = (0..rows).map(|k| k as f64 / rate).collect();
            add_note(md, format!("read: no time column, row k at k / {rate} Hz"));
        }
        _ => units.convert(("time", None), &time_unit, std::slice::from_mut(time), md)?,
    }
    // A declared rate is the recording's, as a robotid log's provenance.
    if let Some(rate) = cfg.sample_rate_hz {
        md.insert(metadata::SAMPLE_RATE_HZ.into(), rate.to_string());
    }
    if let Some(&t0) = time.first().filter(|_| TEXT_EXTENSIONS.contains(&ext)) {
        md.insert(metadata::TIME_ORIGIN_S.into(), t0.to_string());
        if t0 != 0.0 {
            time.iter_mut().for_each(|v| *v -= t0);
        }
    }
    Ok(())
}

/// Reads a log, a file or bytes in memory, into `raw_samples`: its
/// channels in SI units, checked (finite, increasing stamps, within the
/// robot's limits), isolated spikes refused or repaired.
pub fn read_log(log: Log, cfg: &ReadConfig, model: Option<&Model>) -> Result<RawSamples> {
    let (path, ext) = (log.path(), log.format());
    let joints = checked_joints(path, &ext, cfg, model)?;
    let (cols, bytes_hash) = columns_of(log, &ext, cfg, &joints)?;
    if let Log::File(p) = log {
        verify_checksum(p, &bytes_hash)?;
    }
    let source = path.display().to_string();
    let units = Units {
        cfg,
        model,
        joints: &joints,
        source: &source,
    };
    let Columns {
        mut time,
        mut position,
        mut effort,
        mut reference,
        names,
        metadata: mut md,
    } = cols;
    let unit = |ch: &Option<Channel>, default: &str| {
        ch.as_ref()
            .and_then(|c| c.unit.clone())
            .unwrap_or_else(|| default.to_string())
    };
    let rows = position.first().map_or(0, Vec::len);
    read_times(&units, &ext, (&mut time, rows), &mut md)?;
    let side = |ch: &Option<Channel>| ch.as_ref().and_then(|c| c.side);
    units.convert(
        ("position", side(&cfg.position)),
        &unit(&cfg.position, "rad"),
        &mut position,
        &mut md,
    )?;
    let effort_unit = units.effort_unit(&mut md, &names[1])?;
    units.convert(("effort", side(&cfg.effort)), &effort_unit, &mut effort, &mut md)?;
    note_gains(cfg, &effort_unit, &mut md);
    if let Some(r) = &mut reference {
        units.convert(
            ("reference", side(&cfg.reference)),
            &unit(&cfg.reference, "rad"),
            r,
            &mut md,
        )?;
    }
    check_channels(&units, &time, &position, &effort, reference.as_deref(), &names)?;
    repair_spikes(
        &source,
        cfg.spikes,
        [(&mut position, &names[0]), (&mut effort, &names[1])],
        &mut md,
    )?;
    md.insert(
        metadata::SOURCE_FILE.into(),
        path.file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default(),
    );
    md.insert(metadata::SOURCE_SHA256.into(), bytes_hash);
    let raw = RawSamples {
        joints,
        time,
        q: position,
        effort_kind: TorqueChannel::Torque,
        effort,
        reference,
        counts: None,
        metadata: md,
    };
    raw.check_shape()?;
    Ok(raw)
}

/// A torque from a current is only as good as its gain: said, so that
/// what depends on the torque's absolute scale (a payload's mass) can
/// carry the gain's uncertainty.
fn note_gains(cfg: &ReadConfig, effort_unit: &str, md: &mut std::collections::BTreeMap<String, String>) {
    if let Ok(Scale::Current(_)) = unit_scale("effort", effort_unit) {
        let from = match cfg.torque_per_amp {
            Some(_) => "the torque_per_amp given",
            None => "the robot file's torque constant × gear ratio",
        };
        md.insert(metadata::EFFORT_GAINS.into(), format!("{effort_unit} × {from}"));
    }
}

/// The mapped channels of a log in format `ext`, and its hash.
fn columns_of(log: Log, ext: &str, cfg: &ReadConfig, joints: &[String]) -> Result<(Columns, String)> {
    // An MCAP or Parquet file is mapped once: its channels are read from
    // the mapping and its hash taken of the same bytes (text is streamed,
    // a rosbag2 folder read file by file).
    let mapped;
    let log = match log {
        Log::File(p) if (ext == "mcap" || ext == "parquet") && p.is_file() => {
            mapped = crate::formats::mapped(p)?;
            Log::Bytes {
                name: p,
                format: ext,
                bytes: &mapped,
            }
        }
        other => other,
    };
    // The recording's hash on a thread of its own while its channels are
    // read (a tenth of an MCAP read, a quarter of a Parquet one).
    let beside = |read: &dyn Fn() -> Result<Columns>| {
        std::thread::scope(|scope| {
            let hash = scope.spawn(|| log.sha256());
            let cols = read()?;
            Ok::<_, Error>((cols, hash.join().expect("hashing does not panic")?))
        })
    };
    match ext {
        e if TEXT_EXTENSIONS.contains(&e) => beside(&|| text::read_text(log, cfg, joints)),
        "parquet" => beside(&|| parquet::read_parquet_log(log, cfg, joints)),
        "mcap" => beside(&|| mcap::read_mcap(log, cfg, joints)),
        other => Err(Error::Format {
            path: log.path().to_path_buf(),
            msg: format!(
                "unknown log format `.{other}` ({}, parquet, mcap)",
                TEXT_EXTENSIONS.join(", ")
            ),
        }),
    }
}

/// What converting a log's channels to SI units needs: the `[read]` table,
/// the robot's drives, the joints, the log's name for errors.
struct Units<'a> {
    cfg: &'a ReadConfig,
    model: Option<&'a Model>,
    joints: &'a [String],
    source: &'a str,
}

impl Units<'_> {
    fn data_err(&self, channel: &str, sample: Option<usize>, msg: String) -> Error {
        Error::Data {
            source_name: self.source.to_string(),
            channel: channel.to_string(),
            sample,
            msg,
        }
    }

    /// A constant per joint: given in `[read]`, else the robot's.
    fn per_joint(
        &self,
        given: &Option<Vec<f64>>,
        from_model: &dyn Fn(&Model, usize) -> f64,
        what: &str,
        kind: &str,
    ) -> Result<Vec<f64>> {
        let vals: Option<Vec<f64>> = given.clone().or_else(|| {
            self.model.map(|m| {
                self.joints
                    .iter()
                    .map(|j| {
                        m.joint_names()
                            .iter()
                            .position(|n| n == j)
                            .map_or(f64::NAN, |i| from_model(m, i))
                    })
                    .collect()
            })
        });
        match vals {
            Some(v) if v.len() == self.joints.len() && v.iter().all(|x| x.is_finite() && *x != 0.0) => Ok(v),
            Some(v) if v.len() != self.joints.len() => Err(self.data_err(
                kind,
                None,
                format!("`{what}` lists {} values for {} joints", v.len(), self.joints.len()),
            )),
            _ => Err(self.data_err(
                kind,
                None,
                format!(
                    "converting needs `{what}` per joint: give a robot file whose joints match, or `{what}` in the source"
                ),
            )),
        }
    }

    /// `values` (per joint) from `unit` to SI: a factor, encoder counts by
    /// each joint's radians per count, motor currents by its torque per
    /// ampere; a motor-side channel through the transmission where the
    /// joint's own gear does not say it all ([`Units::through_motors`]).
    fn convert(
        &self,
        (kind, side): (&str, Option<Side>),
        unit: &str,
        values: &mut [Vec<f64>],
        md: &mut std::collections::BTreeMap<String, String>,
    ) -> Result<()> {
        let scale = unit_scale(kind, unit).map_err(|e| self.data_err(kind, None, e.to_string()))?;
        let motor = match (side, scale) {
            (Some(Side::Joint), Scale::Counts | Scale::Current(_)) => {
                return Err(self.data_err(
                    kind,
                    None,
                    format!("`side = \"joint\"` with {unit}: encoder counts and currents are the motor's; give the channel in rad or N·m"),
                ))
            }
            (Some(Side::Motor), Scale::Sample) => {
                return Err(self.data_err(kind, None, "`side` is for positions and efforts".into()))
            }
            (Some(s), _) => s == Side::Motor,
            (None, Scale::Counts | Scale::Current(_)) => true,
            (None, _) => false,
        };
        if motor && self.through_motors(kind, scale)? {
            let said = self.to_joint_side(kind, scale, values)?;
            add_note(md, format!("read: {kind} {unit} motor side, {said}"));
            return Ok(());
        }
        let (k, f) = match scale {
            Scale::Factor(f) => {
                values.iter_mut().for_each(|c| c.iter_mut().for_each(|v| *v *= f));
                return Ok(());
            }
            Scale::Counts => (
                self.per_joint(
                    &self.cfg.radians_per_count,
                    &|m, i| m.drives[i].radians_per_count(),
                    "radians_per_count",
                    kind,
                )?,
                1.0,
            ),
            Scale::Current(f) => (
                self.per_joint(
                    &self.cfg.torque_per_amp,
                    &|m, i| m.drives[i].joint_torque_per_amp(),
                    "torque_per_amp",
                    kind,
                )?,
                f,
            ),
            Scale::Sample => {
                let rate = self.cfg.sample_rate_hz.ok_or_else(|| {
                    self.data_err(kind, None, "sample numbers need the rate: give `sample_rate_hz`".into())
                })?;
                values.iter_mut().for_each(|c| c.iter_mut().for_each(|v| *v /= rate));
                return Ok(());
            }
        };
        for (c, kj) in values.iter_mut().zip(k) {
            c.iter_mut().for_each(|v| *v *= f * kj);
        }
        Ok(())
    }

    /// Whether a motor-side channel of `kind` in `scale` goes through the
    /// robot file's transmission: always where the robot has coupled
    /// motors or (positions) motor offsets, and for motor radians or motor
    /// torques. Counts and currents of an uncoupled robot keep their
    /// per-joint factor (gear × constant), the same numbers to the bit.
    /// Joint-side factors given in `[read]` cannot be mixed with it.
    fn through_motors(&self, kind: &str, scale: Scale) -> Result<bool> {
        let given = match scale {
            Scale::Counts => self.cfg.radians_per_count.is_some(),
            Scale::Current(_) => self.cfg.torque_per_amp.is_some(),
            _ => false,
        };
        let Some(model) = self.model else {
            return match (given, scale) {
                (true, _) | (_, Scale::Counts | Scale::Current(_)) => Ok(false),
                _ => Err(self.data_err(
                    kind,
                    None,
                    "a motor-side channel goes through the robot file's transmission: give a robot file".into(),
                )),
            };
        };
        let position = kind != "effort";
        let needed = !model.couplings.is_empty()
            || (position && model.drives.iter().any(|d| d.motor_offset != 0.0))
            || matches!(scale, Scale::Factor(_));
        match (needed, given) {
            (true, true) => Err(self.data_err(
                kind,
                None,
                format!(
                    "`{}` are joint-side factors, but the channel is the motor's and the robot file has a transmission for it: drop them",
                    if position { "radians_per_count" } else { "torque_per_amp" }
                ),
            )),
            (needed, _) => Ok(needed),
        }
    }

    /// The effort channels' unit: the reader's, the `[read]` table's, or
    /// the one their name implies (said in a note when not stated).
    fn effort_unit(&self, md: &mut std::collections::BTreeMap<String, String>, names: &[String]) -> Result<String> {
        let cfg = self.cfg;
        let first = names.first().map(String::as_str).unwrap_or("?");
        let explicit = cfg.effort.as_ref().is_some_and(|c| c.unit.is_some());
        let unit = match (md.remove(metadata::READ_EFFORT_UNIT), cfg.effort.as_ref()) {
            (Some(u), _) => u,
            (None, Some(Channel { unit: Some(u), .. })) => u.clone(),
            (None, Some(c)) => effort_unit_of(c, names).ok_or_else(|| {
                self.data_err(
                    "effort",
                    None,
                    format!("no unit given and none implied by the channel ({first}): give `unit = \"A\"` (motor current) or `\"N*m\"` (joint torque)"),
                )
            })?,
            (None, None) => "A".to_string(),
        };
        if !explicit {
            add_note(md, format!("read: default effort unit {unit} (channels {first})"));
        }
        // Gains stated for torques would be dropped without a word: the user
        // thinks the channels are currents.
        if cfg.torque_per_amp.is_some() && matches!(unit_scale("effort", &unit), Ok(Scale::Factor(_))) {
            return Err(self.data_err(
                "effort",
                None,
                format!(
                    "`torque_per_amp` is given, but the effort channels ({first}) are in {unit}, a torque: the gains would not be used. Drop them, or say the channels are currents (`unit = \"A\"`)"
                ),
            ));
        }
        Ok(unit)
    }
}

/// `note` appended to the read's notes in `md`.
fn add_note(md: &mut std::collections::BTreeMap<String, String>, note: String) {
    let all = match md.remove(metadata::READ_NOTES) {
        Some(n) => format!("{n}; {note}"),
        None => note,
    };
    md.insert(metadata::READ_NOTES.into(), all);
}

/// Every value finite, the stamps increasing at a steady rate; with a
/// robot, positions within its limits and speeds, torques within its.
fn check_channels(
    units: &Units,
    time: &[f64],
    position: &[Vec<f64>],
    effort: &[Vec<f64>],
    reference: Option<&[Vec<f64>]>,
    [q_names, tau_names, ref_names]: &[Vec<String>; 3],
) -> Result<()> {
    let source = units.source;
    check_finite(source, &[time], &[String::from("time")])?;
    check_increasing(source, time)?;
    check_rate(source, time)?;
    check_finite(source, position, q_names)?;
    if let Some(m) = units.model {
        check_limits(source, position, q_names, units.joints, m)?;
        check_speeds(source, time, position, q_names)?;
    }
    check_finite(source, effort, tau_names)?;
    if let Some(r) = reference {
        check_finite(source, r, ref_names)?;
    }
    if let Some(m) = units.model {
        let factor = units.cfg.max_torque_factor.unwrap_or(MAX_TORQUE_FACTOR);
        check_torques(source, effort, tau_names, units.joints, m, factor)?;
    }
    Ok(())
}

/// Isolated spikes in `channels`: refused at the first, or replaced by
/// their neighbours' mean with a note counting them.
fn repair_spikes(
    source: &str,
    policy: Spikes,
    channels: [(&mut Vec<Vec<f64>>, &Vec<String>); 2],
    md: &mut std::collections::BTreeMap<String, String>,
) -> Result<()> {
    let mut repaired = Vec::new();
    for (cols, channel_names) in channels {
        for (col, name) in cols.iter_mut().zip(channel_names) {
            let found = spikes(col);
            let Some(&k) = found.first() else { continue };
            if policy == Spikes::Refuse {
                return Err(Error::Data {
                    source_name: source.to_string(),
                    channel: name.clone(),
                    sample: Some(k),
                    msg: format!(
                        "{} is an isolated spike (its neighbours read {} and {}){}: a corrupt sample; `spikes = \"repair\"` in [read] replaces such samples by their neighbours' mean, with a note",
                        col[k],
                        col[k - 1],
                        col[k + 1],
                        if found.len() > 1 { format!("; {} such samples in this channel", found.len()) } else { String::new() }
                    ),
                });
            }
            for &k in &found {
                col[k] = 0.5 * (col[k - 1] + col[k + 1]);
            }
            repaired.push(format!(
                "{name}: {} at sample(s) {:?}",
                found.len(),
                &found[..found.len().min(5)]
            ));
        }
    }
    if !repaired.is_empty() {
        add_note(
            md,
            format!(
                "isolated spikes replaced by their neighbours' mean ({})",
                repaired.join("; ")
            ),
        );
    }
    Ok(())
}

/// The unit an effort channel's name implies: a JointState `effort` field
/// or a torque-named column is N·m, a current-named one A.
fn effort_unit_of(c: &Channel, columns: &[String]) -> Option<String> {
    let name = c
        .field
        .clone()
        .or_else(|| columns.first().cloned())
        .unwrap_or_default()
        .to_ascii_lowercase();
    if ["tau", "torque", "nm", "effort"].iter().any(|k| name.contains(k)) {
        Some("N*m".into())
    } else if ["current", "curr", "amp"].iter().any(|k| name.contains(k)) || name.ends_with("_a") {
        Some("A".into())
    } else {
        None
    }
}

/// SHA-256 of a recording: of its file, or for a rosbag2 folder of its
/// .mcap files' hashes in order.
pub fn hash_recording(path: &Path) -> Result<String> {
    let files = mcap::bag_files(path)?;
    if let [one] = &files[..] {
        return hash_file(one);
    }
    let parts = files.iter().map(|f| hash_file(f)).collect::<Result<String>>()?;
    Ok(crate::formats::sha256_hex(parts.as_bytes()))
}

/// Where a recording's checksum is kept (`robotid checksum`): beside it,
/// `<name>.sha256`, in `sha256sum`'s format.
pub fn checksum_path(path: &Path) -> std::path::PathBuf {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(".sha256");
    path.with_file_name(name)
}

/// A recording whose checksum file is beside it must hold the bytes it
/// was written for: text has no checksum of its own, and a flipped digit
/// reads as another number.
fn verify_checksum(path: &Path, sha256: &str) -> Result<()> {
    let file = checksum_path(path);
    let Ok(text) = std::fs::read_to_string(&file) else {
        return Ok(());
    };
    let kept = text.split_whitespace().next().unwrap_or_default();
    if kept.eq_ignore_ascii_case(sha256) {
        return Ok(());
    }
    Err(Error::Format {
        path: path.to_path_buf(),
        msg: format!(
            "its bytes do not match {} (SHA-256 {sha256}, kept {kept}): the recording changed after its checksum was made; restore it, or make the checksum anew with `robotid checksum` if the change is meant",
            file.display()
        ),
    })
}

/// SHA-256 of a file, streamed (not read whole: an hour's recording is
/// hundreds of MB).
fn hash_file(path: &Path) -> Result<String> {
    use sha2::Digest;
    let mut file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut hasher = sha2::Sha256::new();
    std::io::copy(&mut file, &mut hasher).map_err(|e| Error::io(path, e))?;
    Ok(hex::encode(hasher.finalize()))
}

/// Positions outside the robot's joint limits by more than a tenth of the
/// range (and 0.05 rad): the wrong unit (degrees read as radians), the
/// wrong joint, or a spike. Refused at the first such sample.
fn check_limits(source: &str, q: &[Vec<f64>], names: &[String], joints: &[String], model: &Model) -> Result<()> {
    for ((col, name), joint) in q.iter().zip(names).zip(joints) {
        let Some(i) = model.joints.iter().position(|j| &j.name == joint) else {
            continue;
        };
        let Some((lo, hi)) = model.limits[i].position else {
            continue;
        };
        let margin = 0.1 * (hi - lo) + 0.05;
        if let Some(k) = col.iter().position(|v| *v < lo - margin || *v > hi + margin) {
            let top = col.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            let hint = if top > 2.0 * std::f64::consts::PI && top < 400.0 {
                format!("; the positions reach {top:.1}: degrees read as radians? give `unit = \"deg\"`")
            } else {
                String::new()
            };
            return Err(Error::Data {
                source_name: source.to_string(),
                channel: name.clone(),
                sample: Some(k),
                msg: format!(
                    "position {} rad is outside joint `{joint}`'s limits [{lo}, {hi}] rad (by more than {margin:.3} rad){hint}",
                    col[k]
                ),
            });
        }
    }
    Ok(())
}

/// Torques beyond `factor` times the joint's torque limit in the robot
/// file, refused at the first such sample.
fn check_torques(
    source: &str,
    tau: &[Vec<f64>],
    names: &[String],
    joints: &[String],
    model: &Model,
    factor: f64,
) -> Result<()> {
    for ((col, name), joint) in tau.iter().zip(names).zip(joints) {
        let Some(i) = model.joints.iter().position(|j| &j.name == joint) else {
            continue;
        };
        let Some(limit) = model.limits[i].torque.filter(|l| *l > 0.0) else {
            continue;
        };
        if let Some(k) = col.iter().position(|v| v.abs() > factor * limit) {
            return Err(Error::Data {
                source_name: source.to_string(),
                channel: name.clone(),
                sample: Some(k),
                msg: format!(
                    "torque {:.6e} N·m is beyond {factor}× joint `{joint}`'s limit of {limit} N·m: a corrupt sample or the wrong unit (current read as torque, a torque constant too large); `max_torque_factor` in [read] sets the bound",
                    col[k]
                ),
            });
        }
    }
    Ok(())
}

/// Joint speeds over this (rad/s, or m/s) are a unit read wrong: no arm's
/// joint turns at 2300°/s; degrees read as radians on a robot without
/// limits do (57× its speed).
pub const MAX_SPEED: f64 = 40.0;

/// Positions whose 99th-percentile speed is over [`MAX_SPEED`], refused at
/// the first sample that fast (a percentile: a corrupt sample is a spike,
/// said later).
fn check_speeds(source: &str, time: &[f64], q: &[Vec<f64>], names: &[String]) -> Result<()> {
    for (col, name) in q.iter().zip(names) {
        let speed = |k: usize| (col[k + 1] - col[k]).abs() / (time[k + 1] - time[k]);
        let mut speeds: Vec<f64> = (0..col.len().saturating_sub(1))
            .filter(|&k| time[k + 1] > time[k])
            .map(speed)
            .collect();
        if speeds.is_empty() {
            continue;
        }
        let at = (0.99 * (speeds.len() - 1) as f64) as usize;
        let fast = *speeds.select_nth_unstable_by(at, f64::total_cmp).1;
        if fast > MAX_SPEED {
            let k = (0..col.len() - 1).find(|&k| time[k + 1] > time[k] && speed(k) > MAX_SPEED);
            return Err(Error::Data {
                source_name: source.to_string(),
                channel: name.clone(),
                sample: k,
                msg: format!(
                    "the positions move at {fast:.1} per s (99th percentile), faster than any arm's joint ({MAX_SPEED} rad/s): positions in degrees (or counts) read as radians? (Or a time column in s declared as ms.) Give the channel's `unit` (\"deg\")"
                ),
            });
        }
    }
    Ok(())
}

/// No arm is logged this slowly (Hz): stamps in ms or µs read as seconds
/// are (a 500 Hz log in ms reads as 0.5 Hz).
pub const MIN_RATE_HZ: f64 = 2.0;

/// Every stage after the read takes the stamps as strictly increasing (a
/// repeated stamp is a zero step, a division by zero downstream): a log
/// with fewer than two samples, or whose stamps repeat or go back, is
/// refused at the first such sample.
fn check_increasing(source: &str, time: &[f64]) -> Result<()> {
    let err = |sample: Option<usize>, msg: String| Error::Data {
        source_name: source.to_string(),
        channel: "time".into(),
        sample,
        msg,
    };
    if time.len() < 2 {
        return Err(err(None, format!("{} sample(s): nothing to identify from", time.len())));
    }
    match time.windows(2).position(|w| !(w[1] > w[0])) {
        Some(k) => Err(err(
            Some(k + 1),
            format!(
                "timestamps must increase: {} s {} {} s (a message logged twice, or out of order: drop the repeat or sort the log by time)",
                time[k + 1],
                if time[k + 1] == time[k] { "repeats" } else { "follows" },
                time[k]
            ),
        )),
        None => Ok(()),
    }
}

/// Stamps whose median step is over 1/[`MIN_RATE_HZ`] s, refused at the
/// first such step.
fn check_rate(source: &str, time: &[f64]) -> Result<()> {
    let mut steps: Vec<f64> = time.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 0.0).collect();
    if steps.is_empty() {
        return Ok(());
    }
    let mid = steps.len() / 2;
    let step = *steps.select_nth_unstable_by(mid, f64::total_cmp).1;
    if step > 1.0 / MIN_RATE_HZ {
        return Err(Error::Data {
            source_name: source.to_string(),
            channel: "time".into(),
            sample: time.windows(2).position(|w| w[1] - w[0] >= step).map(|k| k + 1),
            msg: format!(
                "the stamps step by {step} s (median), a {:.3} Hz log: no arm is logged under {MIN_RATE_HZ} Hz. A time column in ms or µs read as seconds? Give its `unit` (\"ms\", \"us\")",
                1.0 / step
            ),
        });
    }
    Ok(())
}

/// The first NaN or infinity, named by channel and sample.
fn check_finite<C: AsRef<[f64]>>(source: &str, cols: &[C], names: &[String]) -> Result<()> {
    for (c, name) in cols.iter().zip(names) {
        let c = c.as_ref();
        if let Some(k) = c.iter().position(|v| !v.is_finite()) {
            return Err(Error::Data {
                source_name: source.to_string(),
                channel: name.clone(),
                sample: Some(k),
                msg: format!("value is {}", c[k]),
            });
        }
    }
    Ok(())
}

/// Expands a column template for joint `j` (0-based) named `name`.
pub(crate) fn column_name(template: &str, j: usize, name: &str) -> String {
    template
        .replace("{joint}", name)
        .replace("{index}", &(j + 1).to_string())
}
