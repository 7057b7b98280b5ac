use thiserror::Error;

/// Why a table does not match its kind. Every variant names the column or
/// key at fault, so a caller can point at the place in the file.
#[derive(Debug, Error, PartialEq)]
pub enum SchemaError {
    #[error("table is not a robotid table: schema metadata has no `{key}`")]
    NotRobotid { key: &'static str },
    #[error("expected a `{expected}` table, found `{found}`")]
    WrongKind { expected: String, found: String },
    #[error("unknown table kind `{found}` (the kinds: {})", crate::TableKind::ALL.map(|k| k.name()).join(", "))]
    UnknownKind { found: String },
    #[error("table `{table}` has version {found}, this build reads version {expected}")]
    WrongVersion {
        table: String,
        expected: u32,
        found: String,
    },
    #[error("column `{column}` is missing ({why})")]
    MissingColumn { column: String, why: String },
    #[error("column `{column}`: expected type {expected}, found {found}")]
    WrongType {
        column: String,
        expected: String,
        found: String,
    },
    #[error("column `{column}`: expected unit `{expected}`, found `{found}`")]
    WrongUnit {
        column: String,
        expected: String,
        found: String,
    },
    #[error("column `{column}`: unknown unit `{found}`")]
    UnknownUnit { column: String, found: String },
    #[error("column `{column}` has {found} rows, expected {expected}")]
    WrongLength {
        column: String,
        expected: usize,
        found: usize,
    },
    #[error("table has no joints: no column matches `{pattern}`")]
    NoJoints { pattern: String },
    #[error("arrow: {0}")]
    Arrow(String),
}

impl From<arrow::error::ArrowError> for SchemaError {
    fn from(e: arrow::error::ArrowError) -> Self {
        SchemaError::Arrow(e.to_string())
    }
}
