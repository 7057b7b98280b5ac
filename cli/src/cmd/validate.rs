use std::path::{Path, PathBuf};

use anyhow::bail;
use robotid::validation::{Validated, Verdict};
use robotid_schemas::metadata;

#[derive(clap::Args)]
pub struct Args {
    /// Identified parameters (`parameters.parquet`).
    #[arg(long, short)]
    pub parameters: PathBuf,
    /// Regressor tables of the recordings to validate on (a non-periodic
    /// validation run, or the excitation data itself), made with the same
    /// regressor configuration as the estimate.
    #[arg(required = true)]
    pub regressors: Vec<PathBuf>,
    /// Write measured-vs-predicted torques and residue histograms (SVG) and
    /// a report into this folder.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Exit non-zero when the model error dominates the noise on any joint
    /// (mean squared residue over 1.2× the noise floor).
    #[arg(long)]
    pub fail_on_inadequate: bool,
    /// Also judge the model by simulation error: its forward dynamics,
    /// driven by the measured torque, from the measured state, restarted
    /// from it every `--window-s` (on the kinematics table beside each
    /// regressor table), beside the robot file's own parameters.
    #[arg(long, requires = "robot")]
    pub rollout: bool,
    /// The robot file the parameters were identified for (for `--rollout`).
    #[arg(long)]
    pub robot: Option<PathBuf>,
    /// The rollout's window, s: each restarts from the measured state. By
    /// default the longest (0.05–5 s) over which the record's own noise
    /// moves an exact model by at most 1 % of each joint's motion, said.
    #[arg(long)]
    pub window_s: Option<f64>,
    /// Also simulate the model in closed loop on these raw recordings
    /// (positions and the recorded reference, `ref_<joint>`, as `robotid
    /// simulate` writes them), under the controller declared with
    /// --controller, from the first sample's state over the whole record;
    /// beside the robot file's own parameters.
    #[arg(long, requires_all = ["robot", "controller"])]
    pub closed_loop: Vec<PathBuf>,
    /// The recording's controller: a TOML file with a `[controller]` table
    /// of per-joint `kp`, `kd`, `ki` (the simulator's `<name>.truth.toml`).
    #[arg(long)]
    pub controller: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let v = robotid::validation::validate(Path::new(""), &args.parameters, &args.regressors)?;
    print!("{}", said(&v, &args.parameters));
    let robot = match &args.robot {
        Some(r) => Some(robotid_stages::dynamics::Robot::read(r)?),
        None => None,
    };
    let rolled = match robot.as_ref().filter(|_| args.rollout) {
        Some(robot) => {
            robotid::validation::rollouts(Path::new(""), &args.parameters, robot, &args.regressors, args.window_s)?
        }
        None => Vec::new(),
    };
    print!("{}", rollouts_said(&rolled));
    if let (Some(robot), Some(controller)) = (&robot, &args.controller) {
        let runs = robotid::validation::closed_loop_rollouts(&args.parameters, robot, &args.closed_loop, controller)?;
        print!("{}", closed_loop_said(&runs));
    }
    if let Some(dir) = &args.plot {
        let mut files = robotid_report::plot::plot_validation(dir, &v.sys, &v.predicted, &v.stats)?;
        files.extend(robotid_report::plot::plot_rollouts(dir, &rolled)?);
        println!(
            "pictures and report: {}",
            files
                .iter()
                .map(|f| f.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    if let Some(msg) = inadequate(&v).filter(|_| args.fail_on_inadequate) {
        bail!("{msg}");
    }
    Ok(())
}

/// The joints whose model error dominates the noise, said; None if none.
fn inadequate(v: &Validated) -> Option<String> {
    let joints: Vec<String> = v
        .stats
        .iter()
        .filter(|s| s.verdict() == Verdict::ModelErrorDominates)
        .map(|s| match s.within > robotid::validation::ADEQUATE_RATIO {
            true => format!("{} (over {:.2}×, this short record's bound)", s.joint, s.within),
            false => s.joint.clone(),
        })
        .collect();
    (!joints.is_empty()).then(|| {
        format!(
            "the model error dominates the noise on joint(s) {} (mean squared residue over {}× the noise floor)",
            joints.join(", "),
            robotid::validation::ADEQUATE_RATIO
        )
    })
}

/// A validation as text: what was validated on what, the residues per
/// joint and recording, and the verdicts.
pub fn said(v: &Validated, parameters: &Path) -> String {
    let mut s = format!(
        "validation of {} ({} method) on {}\n",
        parameters.display(),
        v.parameters
            .metadata
            .get(metadata::ESTIMATE_METHOD)
            .map(String::as_str)
            .unwrap_or("?"),
        v.sys.recordings.join(", ")
    );
    s.push_str(&robotid_report::validation::table(&v.stats));
    s.push_str(&robotid_report::validation::per_recording(&v.sys, &v.predicted));
    let over: Vec<String> = v
        .stats
        .iter()
        .filter(|s| s.verdict() == Verdict::OverBorrowedFloor)
        .map(|s| format!("{} ({:.1}×)", s.joint, s.msr / s.noise_floor.unwrap_or(f64::NAN)))
        .collect();
    if !over.is_empty() {
        s.push_str(&format!(
            "verdict: the residue is over the excitation's noise floor on {}: model error, or noise this record has and the excitation had not (it has no still stretch, every joint's encoder still, to measure its own floor on), which a borrowed floor cannot tell apart; validate on a record that rests between moves, or a periodic one, to judge the model alone\n",
            over.join(", ")
        ));
    }
    if let Some(msg) = inadequate(v) {
        s.push_str(&format!("verdict: {msg}\n"));
    }
    s
}

/// Closed-loop rollouts as text: per recording and joint, the simulated
/// positions' RMS error against the measured, the estimate's beside the
/// robot file's.
pub fn closed_loop_said(runs: &[robotid::validation::ClosedLoopRun]) -> String {
    let mut s = String::new();
    for r in runs {
        s.push_str(&format!(
            "closed loop on {}: the declared controller tracking the recorded reference, from the first sample's state (held there) over {:.1} s\n",
            r.recording.display(),
            r.time.last().unwrap_or(&0.0) - r.time[0]
        ));
        match r.rows() {
            Err(stop) => s.push_str(&format!("  estimate {}\n", r.stopped_said(stop))),
            Ok(rows) => {
                s.push_str("  joint                    position RMS (mrad)  robot file's (mrad)  ratio\n");
                for row in rows {
                    s.push_str(&format!(
                        "  {:<24} {:>19.4}  {:>19}  {}\n",
                        row.joint, row.q_mrad, row.file, row.ratio
                    ));
                }
            }
        }
    }
    s
}

/// Rollouts as text: per record and joint, the simulated positions' and
/// velocities' RMS error against the measured, the estimate's beside the
/// robot file's.
pub fn rollouts_said(rolled: &[robotid::validation::RolledOut]) -> String {
    let mut s = String::new();
    for r in rolled {
        s.push_str(&format!(
            "rollout on {}: forward dynamics driven by the measured torque, restarted from the measured state every {} samples ({:.3} s)\n  window: {}\n",
            r.table.display(),
            r.window,
            r.window_s,
            r.window_said
        ));
        match r.rows() {
            Err(stop) => s.push_str(&format!("  estimate {}\n", r.stopped_said(stop))),
            Ok(rows) => {
                s.push_str("  joint                    position RMS (mrad)  velocity RMS (mrad/s)  robot file's position RMS  ratio\n");
                for row in rows {
                    s.push_str(&format!(
                        "  {:<24} {:>19.3}  {:>21.3}  {:>25}  {}\n",
                        row.joint, row.q_mrad, row.qd_mrad_s, row.file, row.ratio
                    ));
                }
            }
        }
    }
    s
}
