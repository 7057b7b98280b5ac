//! What people look at, apart from the numbers: each recording's pictures
//! and page (`plot`), the estimate's HTML report (`report`), the validation
//! table (`validation`), the exports for simulators (`export`), and the
//! [`Plots`] observer that draws a run's. Owns plotters; the library
//! (`robotid`) computes and simulates (`robotid::simulation`), this crate
//! shows.

pub mod export;
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

#[cfg(test)]
mod tests {
    /// Issue 62: pages draw what `robotid::simulation` ran and run nothing
    /// themselves. No entry point that simulates (rollouts, the closed
    /// loop, MuJoCo, the simulator) is named in this crate's code.
    #[test]
    fn the_pages_simulate_nothing() {
        let lib = include_str!("lib.rs");
        let sources = [
            ("lib.rs", &lib[..lib.find("#[cfg(test)]").unwrap_or(lib.len())]),
            ("report.rs", include_str!("report.rs")),
            ("plot.rs", include_str!("plot.rs")),
            ("validation.rs", include_str!("validation.rs")),
            ("export.rs", include_str!("export.rs")),
            ("sample.rs", include_str!("sample.rs")),
        ];
        let entries = [
            "simulation::simulate(",
            "validation::rollouts(",
            "rolled_alike(",
            "closed_loop_rollouts(",
            "mujoco::rollout(",
            "dynamics::rollout(",
            "simulation::run",
        ];
        for (file, text) in sources {
            for entry in entries {
                assert!(!text.contains(entry), "{file} calls {entry}");
            }
        }
        // The scan sees calls: one in the library it would find.
        assert!(include_str!("../../pipeline/src/simulation.rs").contains("validation::rollouts("));
    }
}
