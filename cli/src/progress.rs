//! The run's progress on a terminal: one bar per recording, its steps
//! counted and named; with `--plot`, the pictures drawn by
//! [`robotid_report::Plots`].

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use robotid::{Observer, RecordingResult};
use robotid_stages::signal::Spectra;
use robotid_stages::stage::Chain;

/// Progress bars (on a terminal only), the pictures when asked, and
/// whatever is to be said once every recording is through.
pub struct Bars<F: Fn(&[RecordingResult]) + Sync> {
    bars: MultiProgress,
    style: ProgressStyle,
    by_name: Mutex<HashMap<String, ProgressBar>>,
    plots: Option<robotid_report::Plots>,
    recorded: F,
    /// The spinner of a step with nothing to count.
    spinner: Mutex<Option<ProgressBar>>,
}

impl<F: Fn(&[RecordingResult]) + Sync> Bars<F> {
    pub fn new(plot: bool, recorded: F) -> Self {
        let bars = MultiProgress::new();
        if !std::io::IsTerminal::is_terminal(&std::io::stderr()) {
            bars.set_draw_target(ProgressDrawTarget::hidden());
        }
        Bars {
            bars,
            style: ProgressStyle::with_template("{prefix:>24} [{bar:24}] {pos}/{len} {msg}").expect("valid template"),
            by_name: Mutex::new(HashMap::new()),
            plots: plot.then_some(robotid_report::Plots),
            recorded,
            spinner: Mutex::new(None),
        }
    }

    fn bar(&self, name: &str) -> Option<ProgressBar> {
        self.by_name.lock().expect("not poisoned").get(name).cloned()
    }
}

impl<F: Fn(&[RecordingResult]) + Sync> Observer for Bars<F> {
    fn busy(&self, what: Option<&str>) {
        let mut spinner = self.spinner.lock().expect("not poisoned");
        if let Some(s) = spinner.take() {
            s.finish_and_clear();
        }
        if let Some(what) = what.filter(|_| std::io::IsTerminal::is_terminal(&std::io::stderr())) {
            let s = ProgressBar::new_spinner();
            s.set_message(what.to_string());
            s.enable_steady_tick(std::time::Duration::from_millis(120));
            *spinner = Some(s);
        }
    }

    fn started(&self, name: &str, steps: usize) {
        let bar = self.bars.add(ProgressBar::new(steps as u64));
        bar.set_style(self.style.clone());
        bar.set_prefix(name.to_string());
        self.by_name.lock().expect("not poisoned").insert(name.to_string(), bar);
    }

    fn step(&self, name: &str, step: &'static str) {
        if let Some(bar) = self.bar(name) {
            bar.set_message(step);
            bar.inc(1);
        }
    }

    fn finished(&self, name: &str, ok: bool) {
        if let Some(bar) = self.bar(name) {
            bar.set_position(bar.length().unwrap_or(0));
            bar.finish_with_message(if ok { "done" } else { "failed" });
        }
    }

    fn recorded(&self, recordings: &[RecordingResult]) {
        (self.recorded)(recordings);
    }

    fn pictures(
        &self,
        dir: &Path,
        chain: &Chain,
        harmonics: &[u32],
        spectra: &Spectra,
    ) -> robotid::Result<Vec<PathBuf>> {
        match &self.plots {
            Some(p) => p.pictures(dir, chain, harmonics, spectra),
            None => Ok(Vec::new()),
        }
    }

    fn report(
        &self,
        parameters: &Path,
        shown: &Path,
        recordings: &[RecordingResult],
        dir: &Path,
    ) -> robotid::Result<Option<PathBuf>> {
        match &self.plots {
            Some(p) => p.report(parameters, shown, recordings, dir),
            None => Ok(None),
        }
    }
}

/// Runs `work` with a spinner saying `what` on a terminal (nothing
/// elsewhere): for the steps that take seconds with nothing to count.
pub fn spinning<T>(what: &str, work: impl FnOnce() -> T) -> T {
    if !std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        return work();
    }
    let spinner = ProgressBar::new_spinner();
    spinner.set_message(what.to_string());
    spinner.enable_steady_tick(std::time::Duration::from_millis(120));
    let out = work();
    spinner.finish_and_clear();
    out
}
