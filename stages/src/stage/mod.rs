//! The pipeline stages. Each module holds one stage whole:
//!
//! - its serde config `XxxConfig` (`deny_unknown_fields`, `Default` where
//!   every key has one, units in the field docs);
//! - [`Component`] for that config: the [`Product`]s it takes and makes,
//!   `lint` (every problem knowable without reading a sample, with its key)
//!   and `build` (everything that does not depend on the recording: filter
//!   responses, the base regressor, the reference trajectory);
//! - the built stage, a [`Stage`] whose `run` transforms one recording's
//!   [`Chain`];
//! - its kernels as free functions, usable without a pipeline.
//!
//! The `robotid` crate keeps the one closed enum of stage configs that
//! dispatches to these (`pipeline/src/plan.rs`).

pub mod align;
pub mod average;
mod chain;
pub mod decimate;
pub mod differentiate;
pub mod estimate;
pub mod inverse_filter;
pub mod motion;
pub mod noise;
pub mod read;
pub mod regressor;

use std::path::Path;

pub use chain::{AlignReport, Chain, ChannelNoise, Context, Facts, Periods, PeriodsUse, Product, Report, Stretch};

use crate::dynamics::Model;
pub use crate::Problem;
use crate::Result;

/// A built stage: runs on one recording at a time, from many threads.
pub trait Stage: Send + Sync {
    fn run(&self, chain: &mut Chain) -> Result<()>;
}

/// What `lint` knows about the rest of the pipeline, before any sample is read.
pub struct LintContext<'a> {
    pub model: Option<&'a Model>,
    /// The pipeline file's folder.
    pub base_dir: &'a Path,
    /// What the stages before this one make (and the source holds).
    pub before: &'a [Product],
    /// Whether the sources carry robotid's provenance (period, harmonics);
    /// `None` when that cannot be told without reading them.
    pub provenance: Option<bool>,
    /// Every stage of the pipeline, by name.
    pub stages: &'a [&'static str],
}

/// A stage config: what it takes and makes, what can be checked before
/// running, and how it is built.
pub trait Component {
    /// The name in pipeline files (`kind = "…"`).
    const NAME: &'static str;
    /// What must be there before it (all of these).
    fn takes(&self) -> &'static [Product];
    /// What it adds.
    fn makes(&self) -> Option<Product>;
    /// Problems of the settings alone (the structure step).
    fn problems(&self) -> Vec<Problem> {
        Vec::new()
    }
    /// Problems against the rest of the pipeline, the robot and the
    /// sources: everything else that can be known without reading samples.
    fn lint(&self, ctx: &LintContext) -> Vec<Problem>;
    /// What it reads of the aligned periods' samples, which are freed once
    /// no later stage reads them (they are as large as the recording).
    fn reads_periods(&self) -> PeriodsUse {
        PeriodsUse::All
    }
    /// Precomputes what does not depend on the recording.
    fn build(&self, ctx: &Context) -> Result<Box<dyn Stage>>;
}

/// Problems of a stage's `harmonics`: empty, or holding 0.
pub fn harmonics_settings(h: Option<&Vec<u32>>) -> Vec<Problem> {
    match h {
        Some(h) if h.is_empty() => vec![Problem::new("harmonics", "is empty: list the excited harmonic numbers")],
        Some(h) if h.contains(&0) => vec![Problem::new("harmonics", "harmonic numbers start at 1 (0 is the mean)")],
        _ => Vec::new(),
    }
}

/// `harmonics` absent where the source cannot supply them.
pub fn harmonics_from_source(h: Option<&Vec<u32>>, ctx: &LintContext) -> Vec<Problem> {
    match h {
        None if ctx.provenance == Some(false) => vec![Problem::new(
            "harmonics",
            "the source does not say which harmonics were excited (no robotid provenance): give harmonics",
        )],
        _ => Vec::new(),
    }
}
