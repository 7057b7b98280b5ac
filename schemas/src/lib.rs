//! robotid's table kinds: column names, units, Arrow schemas, metadata keys
//! and the errors raised when a table does not match its kind.
//!
//! No FFTs, no linear algebra: this crate only says what a table *is*, so
//! every stage, sink and reader agrees on it (the arrow-schema pattern).

pub mod columns;
mod error;
pub mod metadata;
mod processed;
mod raw;
mod tables;
mod units;

pub use error::SchemaError;
pub use processed::{Kinematics, NoiseTable, PeriodMean};
pub use raw::{RawSamples, TorqueChannel};
pub use tables::{ColumnSpec, Presence, TableKind};
pub use units::Unit;
