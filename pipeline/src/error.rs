//! The pipeline crate's errors: problems of a pipeline file, each with its
//! place, and failures of a run.

use std::path::{Path, PathBuf};

use thiserror::Error;

/// Where in a pipeline file a problem is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Place {
    /// The file as a whole (it does not parse).
    File,
    /// A top-level key, e.g. `robot`, `version`, `output.tables`.
    Key(String),
    /// A key of `[read]`.
    Read(String),
    /// `[source]`.
    Source,
    /// A stage: its 1-based index, kind, line, and the key (empty for the stage itself).
    Stage {
        index: usize,
        kind: String,
        line: usize,
        key: String,
    },
}

impl std::fmt::Display for Place {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Place::File => Ok(()),
            Place::Key(k) => write!(f, "`{k}`: "),
            Place::Read(k) => write!(f, "[read] {k}: "),
            Place::Source => write!(f, "[source] "),
            Place::Stage { index, kind, line, key } if key.is_empty() => {
                write!(f, "stage {index} (`{kind}`, line {line}): ")
            }
            Place::Stage { index, kind, line, key } => write!(f, "stage {index} (`{kind}`, line {line}) `{key}`: "),
        }
    }
}

/// One problem of a pipeline file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Placed {
    pub file: PathBuf,
    pub place: Place,
    pub message: String,
}

impl std::fmt::Display for Placed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}{}", self.file.display(), self.place, self.message)
    }
}

/// Every problem found in a pipeline file, at once.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problems(pub Vec<Placed>);

impl std::fmt::Display for Problems {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} problem(s):", self.0.len())?;
        for p in &self.0 {
            write!(f, "\n  {p}")?;
        }
        Ok(())
    }
}

impl std::error::Error for Problems {}

impl Problems {
    /// Whether a problem sits at a stage's key (`kind`, `key`).
    pub fn at_stage(&self, kind: &str, key: &str) -> bool {
        self.0
            .iter()
            .any(|p| matches!(&p.place, Place::Stage { kind: k, key: q, .. } if k == kind && q == key))
    }

    /// Whether a problem sits at a place.
    pub fn at(&self, place: &Place) -> bool {
        self.0.iter().any(|p| &p.place == place)
    }
}

/// Errors of the pipeline crate.
#[derive(Debug, Error)]
pub enum Error {
    /// The pipeline file has problems (every one of them).
    #[error(transparent)]
    Problems(#[from] Problems),
    /// A stage, a reader or an estimator failed.
    #[error(transparent)]
    Stage(#[from] robotid_stages::Error),
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Recordings failed: nothing was estimated from the rest.
    #[error("estimate: recording(s) {} failed, so no parameters were estimated (fix them or leave them out of the source)", .names.join(", "))]
    RecordingsFailed { names: Vec<String> },
    /// Two recordings of one estimate hold the same bytes.
    #[error("{} and {} hold the same bytes: one recording given twice (its rows would count twice and the intervals shrink by √2); nothing was estimated", first.display(), again.display())]
    SameRecording { first: PathBuf, again: PathBuf },
    /// A plan made in code could not be written as a pipeline file.
    #[error("writing a pipeline file: {0}")]
    Write(#[from] toml::ser::Error),
    /// A table a run wrote does not read as the kind it should be.
    #[error("{}: {source}", path.display())]
    Table {
        path: PathBuf,
        #[source]
        source: robotid_stages::Error,
    },
    /// A parameters table identified for another robot (or another
    /// regressor configuration) than the one given with it.
    #[error("robot `{robot}` with the regressor configuration of {} has base parameters {}, not the table's {}: is it the robot they were identified for?", parameters.display(), expected.join(", "), found.join(", "))]
    NotTheRobot {
        robot: String,
        parameters: PathBuf,
        expected: Vec<String>,
        found: Vec<String>,
    },
    /// An estimate's settings out of range: the option and why.
    #[error("estimate setting `{key}`: {message}")]
    Settings { key: String, message: String },
    /// Regressor tables made for another parameter set than the estimate's.
    #[error("the regressor tables' parameters {tables:?} are not the estimate's {estimate:?}: make them with the same regressor configuration")]
    OtherParameters { tables: Vec<String>, estimate: Vec<String> },
    /// Validation recordings whose torque runs against the prediction.
    #[error("{recordings}: the measured torque runs against the identified model's prediction on {}: a reversed channel, or two joints' columns swapped, in the recording; fix the log", joints.join(", "))]
    Reversed { recordings: String, joints: Vec<String> },
    /// A file that cannot serve what it was given for: which, and why.
    #[error("{}: {msg}", path.display())]
    Unfit { path: PathBuf, msg: String },
    /// Pictures or a report could not be made.
    #[error("{what}: {msg}")]
    Output { what: String, msg: String },
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// The files under `from` named under `to` instead
    /// ([`robotid_stages::Error::relocate`]).
    pub fn relocate(&mut self, from: &Path, to: &Path) {
        use robotid_stages::relocate_path as moved;
        match self {
            Error::Stage(e) => e.relocate(from, to),
            Error::Io { path, .. } | Error::Unfit { path, .. } | Error::NotTheRobot { parameters: path, .. } => {
                moved(path, from, to)
            }
            Error::Table { path, source } => {
                moved(path, from, to);
                source.relocate(from, to);
            }
            _ => {}
        }
    }
}
