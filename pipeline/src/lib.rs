//! The pipeline runner behind the `robotid` command: pipeline files
//! (`plan`), the library entry point (`pipeline`: [`Pipeline`] → [`Built`]
//! → [`RunReport`]), and the execution over many recordings (`run`). Runs
//! read as a dataset (summaries, comparisons) are the `robotid-dataset`
//! crate's.

pub mod error;
// The fuzz targets' entry points (fuzz/, pipeline/tests/fuzz_regressions.rs):
// public for them, not part of the library's API.
#[doc(hidden)]
pub mod fuzz;
pub mod identify;
pub mod output;
pub mod pipeline;
pub mod plan;
pub mod plot;
pub mod report;
pub mod run;
pub mod summaries;
pub mod validation;

pub use error::{Error, Problems, Result};
pub use pipeline::{Built, Pipeline, RunReport};
pub use run::{RecordingResult, RunOptions};

// The pipeline-file documentation, whose Rust example is compiled and run
// as a doc test.
#[doc = include_str!("../../docs/pipeline-file.md")]
#[cfg(doctest)]
pub struct PipelineFileDoc;
