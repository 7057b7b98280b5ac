//! What people look at, apart from the numbers: each recording's pictures
//! and page (`plot`), the estimate's HTML report (`report`), the validation
//! table (`validation`), the exports for simulators (`export`) and their
//! rollout in MuJoCo itself (`mujoco`), and the [`Plots`] observer that draws a run's.
//! Owns plotters; the library (`robotid`) computes, this crate shows.

pub mod export;
pub mod mujoco;
pub mod plot;
pub mod report;
pub mod sample;
pub mod validation;

use std::path::{Path, PathBuf};

use robotid::{Observer, RecordingResult, Result};
use robotid_stages::signal::Spectra;
use robotid_stages::stage::Chain;

/// Draws a run's pictures (`--plot`): each recording's figures and page,
/// and the run's report when it estimates.
pub struct Plots;

impl Observer for Plots {
    fn pictures(&self, dir: &Path, chain: &Chain, harmonics: &[u32], spectra: &Spectra) -> Result<Vec<PathBuf>> {
        let inputs = plot::Inputs {
            name: &chain.name,
            periods: chain.periods.as_ref(),
            mean: chain.mean.as_ref(),
            noise: chain.noise.as_ref(),
            kinematics: chain.kinematics.as_ref(),
            harmonics,
            spectra,
        };
        let mut files = plot::plot_recording(dir, &inputs)?;
        files.push(plot::write_report(dir, &chain.name, &chain.report, &files)?);
        Ok(files)
    }

    fn report(
        &self,
        parameters: &Path,
        shown: &Path,
        recordings: &[RecordingResult],
        dir: &Path,
    ) -> Result<Option<PathBuf>> {
        report::write_run_report(parameters, shown, recordings, dir).map(Some)
    }
}
