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
