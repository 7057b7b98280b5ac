//! The dataset layer's errors, each naming the file or folder at fault.

use std::path::PathBuf;

use polars::prelude::PolarsError;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file or folder that could not be read.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Not what a dataset holds: a file where a folder goes, a root
    /// without runs.
    #[error("{}: {msg}", path.display())]
    Invalid { path: PathBuf, msg: String },
    /// JSON that is not what robotid wrote (a run manifest, a metadata key).
    #[error("{}: {what}: {source}", path.display())]
    Json {
        path: PathBuf,
        what: &'static str,
        #[source]
        source: serde_json::Error,
    },
    /// A Parquet file polars could not read.
    #[error("{}: {source}", path.display())]
    Read {
        path: PathBuf,
        #[source]
        source: PolarsError,
    },
    /// What polars failed on, with what was being done.
    #[error("{what}: {source}")]
    Polars {
        what: String,
        #[source]
        source: PolarsError,
    },
    #[error(transparent)]
    Arrow(#[from] arrow::error::ArrowError),
    #[error(transparent)]
    Stages(#[from] robotid_stages::Error),
    /// Settings that select nothing, or a frame with no Arrow mapping.
    #[error("{0}")]
    Setting(String),
}

impl From<PolarsError> for Error {
    fn from(source: PolarsError) -> Error {
        Error::Polars {
            what: "the dataset's frames".into(),
            source,
        }
    }
}

pub type Result<T> = std::result::Result<T, Error>;

/// `Error::Io` for `path`.
pub fn io(path: &std::path::Path) -> impl FnOnce(std::io::Error) -> Error + '_ {
    move |source| Error::Io {
        path: path.to_path_buf(),
        source,
    }
}
