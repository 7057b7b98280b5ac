use std::path::PathBuf;

use thiserror::Error;

/// Errors of the stages crate and its cores. Each names its place: the
/// file, the recording and channel and sample, the stage and key, or the
/// parameter at fault, with what was expected and what was found.
#[derive(Debug, Error)]
pub enum Error {
    #[error("{}: {msg}", path.display())]
    Robot { path: PathBuf, msg: String },
    #[error("{}: {msg}", path.display())]
    Config { path: PathBuf, msg: String },
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: {msg}", path.display())]
    Format { path: PathBuf, msg: String },
    /// A file a library could not decode (Parquet, MCAP, JSON, TOML): its
    /// error kept as the source.
    #[error("{}: {source}", path.display())]
    Decode {
        path: PathBuf,
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// Bad data in a recording: the source, channel and sample at fault.
    #[error("{source_name}: channel `{channel}`{}: {msg}", sample.map(|k| format!(", sample {k}")).unwrap_or_default())]
    Data {
        source_name: String,
        channel: String,
        sample: Option<usize>,
        msg: String,
    },
    #[error(transparent)]
    Schema(#[from] robotid_schemas::SchemaError),
    /// A setting that cannot be used: its key, what it must be, what it is.
    #[error("`{key}` must be {expected}, not {found}")]
    Setting {
        key: String,
        expected: String,
        found: String,
    },
    /// Something a computation needs is not there; `hint` says how to get it.
    #[error("{what} is needed: {hint}")]
    Missing { what: String, hint: String },
    /// Two things that must agree do not.
    #[error("{what}: expected {expected}, found {found}")]
    Mismatch {
        what: String,
        expected: String,
        found: String,
    },
    /// A non-finite or otherwise unusable number, and where it sits.
    #[error("{what} holds {value} at {at}")]
    NotFinite { what: String, value: f64, at: String },
    /// Estimation: a parameter whose column is zero on every row.
    #[error("parameter `{parameter}` is not excited: its regressor column is zero on all {rows} rows; drop it from the model or excite it")]
    NotExcited { parameter: String, rows: usize },
    /// Estimation: fewer rows than parameters.
    #[error("too few samples: {rows} rows for {parameters} parameters; least squares needs more rows than parameters (and many more for useful intervals)")]
    TooFewRows { rows: usize, parameters: usize },
    /// Estimation: parameters the data cannot tell apart.
    #[error("the regressor is rank-deficient (condition number {condition:.3e} of the column-scaled system): parameters {} cannot be told apart; the data says nothing about {combination} (scaled). Excite them differently or drop one from the model", parameters.iter().map(|p| format!("`{p}`")).collect::<Vec<_>>().join(", "))]
    RankDeficient {
        condition: f64,
        parameters: Vec<String>,
        combination: String,
    },
    /// A failure inside one stage of one recording. Its message holds the
    /// cause's (not an error `source`: a printed chain would say it twice).
    #[error("{source_name}: stage `{stage}`: {}", unplaced(cause, source_name))]
    Stage {
        stage: &'static str,
        source_name: String,
        cause: Box<Error>,
    },
    /// Every problem of a settings file or table, each with its key.
    #[error("{what}: {}", problems.iter().map(|p| if p.key.is_empty() { p.message.clone() } else { format!("`{}`: {}", p.key, p.message) }).collect::<Vec<_>>().join("; "))]
    Problems { what: String, problems: Vec<Problem> },
    /// A numerical method that could not do its work (with its reason).
    #[error("{method}: {msg}")]
    Numerical { method: &'static str, msg: String },
}

impl From<Problem> for Error {
    fn from(p: Problem) -> Error {
        Error::Problems {
            what: "settings".into(),
            problems: vec![p],
        }
    }
}

/// `path` under `from` named under `to` instead (else as it is).
pub fn relocate_path(path: &mut PathBuf, from: &std::path::Path, to: &std::path::Path) {
    if let Ok(rel) = path.strip_prefix(from) {
        *path = to.join(rel);
    }
}

impl Error {
    /// The files under `from` named under `to` instead: what a staging
    /// folder made, said where it is once committed.
    pub fn relocate(&mut self, from: &std::path::Path, to: &std::path::Path) {
        let named = |s: &mut String| {
            let mut p = PathBuf::from(s.as_str());
            relocate_path(&mut p, from, to);
            *s = p.display().to_string();
        };
        match self {
            Error::Robot { path, .. }
            | Error::Config { path, .. }
            | Error::Io { path, .. }
            | Error::Format { path, .. }
            | Error::Decode { path, .. } => relocate_path(path, from, to),
            Error::Data { source_name, .. } => named(source_name),
            Error::Stage { source_name, cause, .. } => {
                named(source_name);
                cause.relocate(from, to);
            }
            _ => {}
        }
    }

    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Error {
        Error::Io {
            path: path.into(),
            source,
        }
    }

    pub fn setting(key: impl Into<String>, expected: impl Into<String>, found: impl ToString) -> Error {
        Error::Setting {
            key: key.into(),
            expected: expected.into(),
            found: found.to_string(),
        }
    }

    pub fn missing(what: impl Into<String>, hint: impl Into<String>) -> Error {
        Error::Missing {
            what: what.into(),
            hint: hint.into(),
        }
    }

    pub fn mismatch(what: impl Into<String>, expected: impl ToString, found: impl ToString) -> Error {
        Error::Mismatch {
            what: what.into(),
            expected: expected.to_string(),
            found: found.to_string(),
        }
    }

    pub fn numerical(method: &'static str, msg: impl Into<String>) -> Error {
        Error::Numerical {
            method,
            msg: msg.into(),
        }
    }

    /// This error, placed in a stage of a recording.
    pub fn in_stage(self, stage: &'static str, source_name: &str) -> Error {
        match self {
            e @ Error::Stage { .. } => e,
            e => Error::Stage {
                stage,
                source_name: source_name.to_string(),
                cause: Box::new(e),
            },
        }
    }
}

/// A stage's cause as its message says it: without the source when it
/// names the stage's own.
fn unplaced(cause: &Error, source: &str) -> String {
    match cause {
        Error::Data {
            source_name,
            channel,
            sample,
            msg,
        } if source_name == source => format!(
            "channel `{channel}`{}: {msg}",
            sample.map(|k| format!(", sample {k}")).unwrap_or_default()
        ),
        e => e.to_string(),
    }
}

/// A problem of a setting: the key at fault and what is wrong. Settings
/// files (pipeline, robot, simulation, excitation) report these.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problem {
    /// The key, e.g. `harmonics`, or `` for the stage as a whole.
    pub key: String,
    pub message: String,
    /// The setting needs the robot file: not said again when the file was
    /// given but failed to load (that is reported once, on its own).
    pub needs_robot: bool,
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.key.is_empty() {
            f.write_str(&self.message)
        } else {
            write!(f, "`{}`: {}", self.key, self.message)
        }
    }
}

impl Problem {
    /// The same problem under a parent key (`filter` → `filter.order`).
    pub fn under(self, parent: &str) -> Problem {
        Problem {
            key: if self.key.is_empty() {
                parent.to_string()
            } else {
                format!("{parent}.{}", self.key)
            },
            message: self.message,
            needs_robot: self.needs_robot,
        }
    }

    pub fn new(key: impl Into<String>, message: impl Into<String>) -> Problem {
        Problem {
            key: key.into(),
            message: message.into(),
            needs_robot: false,
        }
    }

    /// A setting that needs the robot file, which the pipeline lacks.
    pub fn needs_robot(key: impl Into<String>, message: impl Into<String>) -> Problem {
        Problem {
            needs_robot: true,
            ..Problem::new(key, message)
        }
    }
}

/// A TOML parse error as one line: `line L, column C: message`.
pub fn toml_message(text: &str, e: &toml::de::Error) -> String {
    match e.span() {
        Some(span) => {
            let before = &text[..span.start.min(text.len())];
            let line = before.matches('\n').count() + 1;
            let col = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
            format!("line {line}, column {col}: {}", e.message().trim())
        }
        None => e.message().trim().to_string(),
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
