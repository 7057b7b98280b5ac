//! The pipeline runner behind the `robotid` command: pipeline files
//! (`plan`), their execution over many recordings (`run`), and the
//! dataset-level comparison of runs (`check`).

pub mod check;
pub mod plan;
pub mod plot;
pub mod report;
pub mod run;
pub mod validation;
