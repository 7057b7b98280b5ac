//! The robotid library, what the command line, Python and engines share:
//! pipeline files (`plan`), the entry point (`pipeline`: [`Pipeline`] →
//! [`Built`] → [`RunReport`]), the execution over many recordings (`run`,
//! told to an [`Observer`]), the one commit of a run's outputs (`output`),
//! merged summaries, validation statistics and every simulation a page
//! shows (`simulation`: rollouts, the closed loop, MuJoCo). Pictures,
//! reports and exports are the `robotid-report` crate's, identify (the
//! pipelines designed from recordings, and the one call from recordings
//! to a model) `robotid-identify`'s, the command line `robotid-cli`'s,
//! runs read as a dataset `robotid-dataset`'s.

pub mod error;
// The fuzz targets' entry points (fuzz/, pipeline/tests/suite/fuzz_regressions.rs):
// public for them, not part of the library's API.
#[doc(hidden)]
pub mod fuzz;
pub mod mujoco;
pub mod output;
pub mod pipeline;
pub mod plan;
pub mod run;
pub mod simulation;
pub mod summaries;
pub mod tables;
pub mod validation;
pub mod verdict;

pub use error::{Error, Problems, Result};
pub use pipeline::{Built, Pipeline, RunReport};
pub use run::{Observer, Quiet, RecordingResult, RunOptions};

// The pipeline-file documentation, whose Rust example is compiled and run
// as a doc test.
#[doc = include_str!("../../docs/pipeline-file.md")]
#[cfg(doctest)]
pub struct PipelineFileDoc;
