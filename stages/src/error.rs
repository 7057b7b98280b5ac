use std::path::PathBuf;

use thiserror::Error;

/// Errors of the stages crate. Each names the file and, where there is one,
/// the key, channel or sample at fault.
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
    #[error(transparent)]
    Schema(#[from] robotid_schemas::SchemaError),
    #[error("{0}")]
    Invalid(String),
}

impl Error {
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Error {
        Error::Io {
            path: path.into(),
            source,
        }
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
