//! The pipeline runner behind the `robotid` command: pipeline files
//! (`plan`), the library entry point (`pipeline`: [`Pipeline`] → [`Built`]
//! → [`RunReport`]), the execution over many recordings (`run`), and the
//! dataset-level comparison of runs (`compare`).

pub mod compare;
pub mod error;
pub mod pipeline;
pub mod plan;
pub mod plot;
pub mod report;
pub mod run;
pub mod validation;

pub use error::{Error, Problems, Result};
pub use pipeline::{Built, Pipeline, RunReport};
pub use run::RunOptions;
