//! robotid's dataset layer, on polars: many run trees read as one dataset.
//!
//! - [`summary`]: one row per run, recording and joint (samples, periods,
//!   noise floor, residual variance, adequacy, parameter values) and the
//!   parameters' drift across runs ordered by time.
//! - [`compare`]: a regression test of one output tree against another,
//!   every table joined on its keys and compared with tolerances.
//!
//! `robotid dataset …` runs this crate's binary, so that only it pays
//! polars' build time.

pub mod compare;
pub mod error;
pub mod runs;
pub mod summary;

pub use compare::{compare, Report, Tolerances};
pub use error::{Error, Result};
pub use runs::{discover, Run};
pub use summary::{summarize, Summary};
