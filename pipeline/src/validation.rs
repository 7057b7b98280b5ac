//! Validation of identified parameters on recordings: per-joint residue
//! statistics (mean squared residue, its ratio to the noise floor, shape
//! against a Gaussian).

use std::path::{Path, PathBuf};

use nalgebra::DVector;
use robotid_stages::dynamics::Robot;
use robotid_stages::estimation::{Parameters, System};

use crate::error::{Error, Result};

/// Identified parameters checked on recordings: the tables, the predicted
/// torque and the residues per joint (a non-repeating record's floor
/// borrowed from the excitation's, [`borrow_floor`]).
pub struct Validated {
    pub parameters: Parameters,
    pub sys: System,
    pub predicted: DVector<f64>,
    pub stats: Vec<JointResidue>,
}

/// The parameters table at `parameters` validated on the regressor tables
/// `regressors` (both read `within` a folder, named as given); refused when
/// the tables are of another parameter set, or when a joint's measured
/// torque runs against the prediction (a reversed or swapped channel reads
/// as model error, and is not one).
pub fn validate(within: &Path, parameters: &Path, regressors: &[PathBuf]) -> Result<Validated> {
    let parameters = crate::tables::read_parameters(&within.join(parameters))?;
    let sys = crate::tables::load_system(within, regressors)?;
    if sys.names != parameters.names {
        return Err(Error::OtherParameters {
            tables: sys.names.clone(),
            estimate: parameters.names.clone(),
        });
    }
    let predicted = &sys.a * &parameters.values;
    let mut stats = residues(&sys, &predicted);
    borrow_floor(&mut stats, &parameters.metadata, &sys.metadata);
    let reversed: Vec<String> = stats
        .iter()
        .filter(|s| s.reversed())
        .map(|s| format!("{} (correlation {:.2})", s.joint, s.correlation))
        .collect();
    if !reversed.is_empty() {
        return Err(Error::Reversed {
            recordings: sys.recordings.join(", "),
            joints: reversed,
        });
    }
    Ok(Validated {
        parameters,
        sys,
        predicted,
        stats,
    })
}

/// Residue statistics of one joint.
pub struct JointResidue {
    pub joint: String,
    pub rows: usize,
    pub measured_rms: f64,
    /// Mean squared residue, (N·m)² — the figure Swevers reports.
    pub msr: f64,
    pub mean: f64,
    /// Mean noise variance of the measured torque (noise stage), if known.
    pub noise_floor: Option<f64>,
    pub skewness: f64,
    pub excess_kurtosis: f64,
    /// Kolmogorov–Smirnov distance of the standardised residue to N(0, 1).
    pub ks: f64,
    /// Correlation of the measured torque with the predicted one.
    pub correlation: f64,
    /// The floor is the excitation's, not this data's ([`borrow_floor`]).
    pub floor_borrowed: bool,
    /// The ratio of `msr` to the floor that is adequate: [`ADEQUATE_RATIO`],
    /// or more where the record is short for its floor and residue to be
    /// known that well (`robotid.regressor.adequate_within`).
    pub within: f64,
}

pub use robotid_stages::estimation::{Verdict, ADEQUATE_RATIO};

impl JointResidue {
    pub fn verdict(&self) -> Verdict {
        match self.noise_floor {
            None => Verdict::NoiseFloorUnknown,
            Some(f) if self.msr <= self.within * f => Verdict::Adequate,
            Some(_) if self.floor_borrowed => Verdict::OverBorrowedFloor,
            Some(_) => Verdict::ModelErrorDominates,
        }
    }

    /// The measured torque runs against the prediction (correlation below
    /// −0.5): no model error does that, a reversed or swapped channel does.
    pub fn reversed(&self) -> bool {
        self.correlation < -0.5
    }
}

/// The relative error pooled over every row of `stats`:
/// √(Σ squared residue / Σ squared torque); joints without rows (a
/// joint-wise record's held ones) add nothing.
pub fn relative_error(stats: &[JointResidue]) -> f64 {
    let sum = |f: &dyn Fn(&JointResidue) -> f64| {
        stats
            .iter()
            .filter(|r| r.rows > 0)
            .map(|r| r.rows as f64 * f(r))
            .sum::<f64>()
    };
    (sum(&|r| r.msr) / sum(&|r| r.measured_rms.powi(2))).sqrt()
}

/// One recording's figures pooled over its rows and joints.
#[derive(Debug, Clone)]
pub struct RecordingFigures {
    pub name: String,
    /// Σ squared residue, (N·m)².
    pub residue: f64,
    /// Σ squared measured torque, (N·m)².
    pub torque: f64,
    /// Σ noise variance, (N·m)² (None: some row has no floor).
    pub floor: Option<f64>,
}

impl RecordingFigures {
    /// √(Σ squared residue / Σ squared torque).
    pub fn relative_error(&self) -> f64 {
        (self.residue / self.torque).sqrt()
    }
}

/// The pooled figures of each recording stacked in `sys`.
pub fn per_recording(sys: &System, predicted: &DVector<f64>) -> Vec<RecordingFigures> {
    sys.recordings
        .iter()
        .enumerate()
        .map(|(r, name)| {
            let rows = || (0..sys.rows()).filter(move |&i| sys.recording[i] == r);
            let floor = rows().map(|i| sys.var[i]).sum::<f64>();
            RecordingFigures {
                name: name.clone(),
                residue: rows().map(|i| (sys.b[i] - predicted[i]).powi(2)).sum(),
                torque: rows().map(|i| sys.b[i].powi(2)).sum(),
                floor: floor.is_finite().then_some(floor),
            }
        })
        .collect()
}

impl Validated {
    /// Each validation recording's pooled figures.
    pub fn per_recording(&self) -> Vec<RecordingFigures> {
        per_recording(&self.sys, &self.predicted)
    }
}

/// Residue statistics per joint of `sys` for torques `predicted`.
pub fn residues(sys: &System, predicted: &DVector<f64>) -> Vec<JointResidue> {
    let residue = &sys.b - predicted;
    let within: std::collections::BTreeMap<String, f64> = sys
        .metadata
        .get(robotid_schemas::metadata::ADEQUATE_WITHIN)
        .and_then(|w| serde_json::from_str(w).ok())
        .unwrap_or_default();
    let mut stats = Vec::new();
    for (j, joint) in sys.joints.iter().enumerate() {
        let rows: Vec<usize> = (0..sys.rows()).filter(|&i| sys.joint[i] == j).collect();
        let r: Vec<f64> = rows.iter().map(|&i| residue[i]).collect();
        let n = r.len() as f64;
        let mean = r.iter().sum::<f64>() / n;
        let msr = r.iter().map(|x| x * x).sum::<f64>() / n;
        let var = r.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
        let sd = var.sqrt();
        let m3 = r.iter().map(|x| ((x - mean) / sd).powi(3)).sum::<f64>() / n;
        let m4 = r.iter().map(|x| ((x - mean) / sd).powi(4)).sum::<f64>() / n;
        let mut z: Vec<f64> = r.iter().map(|x| (x - mean) / sd).collect();
        z.sort_by(f64::total_cmp);
        let normal = robotid_stages::estimation::normal_cdf;
        let ks = z
            .iter()
            .enumerate()
            .map(|(k, &v)| {
                let f = normal(v);
                (f - k as f64 / n).abs().max(((k + 1) as f64 / n - f).abs())
            })
            .fold(0.0, f64::max);
        let floor: Vec<f64> = rows.iter().map(|&i| sys.var[i]).filter(|v| v.is_finite()).collect();
        let (mb, mp) = rows
            .iter()
            .fold((0.0, 0.0), |(b, p), &i| (b + sys.b[i] / n, p + predicted[i] / n));
        let (sbp, sbb, spp) = rows.iter().fold((0.0, 0.0, 0.0), |(bp, bb, pp), &i| {
            let (db, dp) = (sys.b[i] - mb, predicted[i] - mp);
            (bp + db * dp, bb + db * db, pp + dp * dp)
        });
        stats.push(JointResidue {
            joint: joint.clone(),
            rows: rows.len(),
            measured_rms: (rows.iter().map(|&i| sys.b[i].powi(2)).sum::<f64>() / n).sqrt(),
            msr,
            mean,
            noise_floor: (floor.len() == rows.len()).then(|| floor.iter().sum::<f64>() / n),
            skewness: m3,
            excess_kurtosis: m4 - 3.0,
            ks,
            correlation: sbp / (sbb * spp).sqrt().max(f64::MIN_POSITIVE),
            floor_borrowed: false,
            within: within.get(joint).copied().unwrap_or(ADEQUATE_RATIO).max(ADEQUATE_RATIO),
        });
    }
    stats
}

/// How far (s) the measured torque leads the predicted one: the
/// least-squares shift Δt of r ≈ Δt·dp/dt over rows whose neighbours (the
/// same joint, the samples before and after) are there, each joint
/// weighted by its floor. A record's channels out of step (an effort
/// logged late, undone by the wrong delay) show as such a shift; None
/// without rows to tell or without floors.
pub fn time_shift(sys: &System, predicted: &DVector<f64>) -> Option<f64> {
    use std::collections::HashMap;
    let at: HashMap<(usize, usize, i64), usize> = (0..sys.rows())
        .map(|i| ((sys.recording[i], sys.joint[i], sys.sample[i]), i))
        .collect();
    let (mut rp, mut pp) = (0.0, 0.0);
    for i in 0..sys.rows() {
        let key = |s: i64| at.get(&(sys.recording[i], sys.joint[i], s)).copied();
        let (Some(prev), Some(next)) = (key(sys.sample[i] - 1), key(sys.sample[i] + 1)) else {
            continue;
        };
        let w = 1.0 / sys.var[i];
        if !w.is_finite() {
            return None;
        }
        let slope = (predicted[next] - predicted[prev]) / (sys.time[next] - sys.time[prev]);
        rp += w * (sys.b[i] - predicted[i]) * slope;
        pp += w * slope * slope;
    }
    (pp > 0.0).then(|| rp / pp)
}

/// Joints without a noise floor of their own (a validation record that
/// does not repeat has no periods to take it from) take the excitation's,
/// from the parameters table: the noise variance of its averaged torque
/// times the number of periods averaged (the variance of one sample),
/// times the share its chain's low-pass lets through (`data`'s
/// `robotid.torque_noise_gain`; a chain that does not say is not judged).
/// Returns whether any did; the verdicts then judge against it.
pub fn borrow_floor(
    stats: &mut [JointResidue],
    parameters: &std::collections::BTreeMap<String, String>,
    data: &std::collections::BTreeMap<String, String>,
) -> bool {
    use robotid_schemas::metadata;
    let periods: Option<f64> = parameters
        .get(metadata::PERIODS)
        .and_then(|p| p.parse().ok())
        .filter(|p: &f64| *p >= 2.0);
    let floors: Vec<serde_json::Value> = parameters
        .get(metadata::ADEQUACY)
        .and_then(|a| serde_json::from_str(a).ok())
        .unwrap_or_default();
    let Some(gain) = data
        .get(metadata::TORQUE_NOISE_GAIN)
        .and_then(|g| g.parse::<f64>().ok())
        .filter(|g| *g > 0.0)
    else {
        return false;
    };
    let mut any = false;
    for s in stats.iter_mut().filter(|s| s.noise_floor.is_none()) {
        let floor = floors
            .iter()
            .find(|a| a.get("joint").and_then(|j| j.as_str()) == Some(&s.joint))
            .and_then(|a| a.get("noise_floor")?.as_f64());
        if let (Some(f), Some(p)) = (floor, periods) {
            s.noise_floor = Some(f * p * gain);
            s.floor_borrowed = true;
            any = true;
        }
    }
    any
}

/// One record rolled out: the estimate's and the robot file's models.
pub struct RolledOut {
    /// The kinematics table rolled out on.
    pub table: PathBuf,
    pub joints: Vec<String>,
    /// Samples per window, and its length (s).
    pub window: usize,
    pub window_s: f64,
    /// How the window was chosen (from the noise, or given), said.
    pub window_said: String,
    pub time: Vec<f64>,
    /// The measured positions, `[joint][sample]`.
    pub measured: Vec<Vec<f64>>,
    /// The estimate's rollout, or where it stopped.
    pub estimate: std::result::Result<robotid_stages::dynamics::Rollout, robotid_stages::dynamics::Stopped>,
    /// The robot file's own parameters rolled out the same way (None for
    /// a model without base parameters of its own: the decoupled one).
    pub prior: Option<std::result::Result<robotid_stages::dynamics::Rollout, robotid_stages::dynamics::Stopped>>,
}

/// One joint's rollout figures, as said: the estimate's position and
/// velocity RMS error (mrad, mrad/s), the robot file's position error
/// (mrad, or why it was not simulated) and the ratio of the two.
pub struct RolloutRow {
    pub joint: String,
    pub q_mrad: f64,
    pub qd_mrad_s: f64,
    pub file: String,
    pub ratio: String,
}

/// Why a model was not simulated, said (`joints`: the record's).
fn stopped_said(joints: &[String], stopped: &robotid_stages::dynamics::Stopped) -> String {
    match stopped {
        robotid_stages::dynamics::Stopped::NotPositiveDefinite { sample, joint } => format!(
            "not simulated: the mass matrix is not positive definite at sample {sample} (pivot of {})",
            joints[*joint]
        ),
        robotid_stages::dynamics::Stopped::Diverged { sample, joint } => format!(
            "not simulated: the state diverged by sample {sample} (on {})",
            joints[*joint]
        ),
    }
}

/// The robot file's model's figure beside the estimate's `ours` (rad):
/// its own (mrad, `digits` decimals) and the ratio, or why not.
fn beside_file<T>(
    joints: &[String],
    prior: &Option<std::result::Result<T, robotid_stages::dynamics::Stopped>>,
    q_rms: impl Fn(&T) -> f64,
    ours: f64,
    digits: usize,
) -> (String, String) {
    match prior {
        Some(Ok(p)) => (format!("{:.digits$}", 1e3 * q_rms(p)), figure(ours / q_rms(p))),
        Some(Err(e)) => (stopped_said(joints, e), "-".into()),
        None => ("-".into(), "-".into()),
    }
}

impl RolledOut {
    /// Why a model was not simulated, said.
    pub fn stopped_said(&self, stopped: &robotid_stages::dynamics::Stopped) -> String {
        stopped_said(&self.joints, stopped)
    }

    /// Per joint, the figures; Err: where the estimate stopped
    /// ([`RolledOut::stopped_said`] says it).
    pub fn rows(&self) -> std::result::Result<Vec<RolloutRow>, &robotid_stages::dynamics::Stopped> {
        let est = self.estimate.as_ref()?;
        Ok(self
            .joints
            .iter()
            .enumerate()
            .map(|(j, joint)| {
                let (file, ratio) = beside_file(&self.joints, &self.prior, |p| p.q_rms[j], est.q_rms[j], 3);
                RolloutRow {
                    joint: joint.clone(),
                    q_mrad: 1e3 * est.q_rms[j],
                    qd_mrad_s: 1e3 * est.qd_rms[j],
                    file,
                    ratio,
                }
            })
            .collect())
    }
}

/// The windows a rollout may restart every, s: the longest one at which
/// the noise alone moves an exact model by at most [`NOISE_SHARE`] of
/// each joint's motion is taken.
const WINDOWS_S: [f64; 7] = [0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0];

/// The share of a joint's motion (the standard deviation of its angle
/// over the record) that the noise may move an exact model by within a
/// window: a model error smaller than this is not told from the noise in
/// longer windows.
pub const NOISE_SHARE: f64 = 0.01;

/// The rollout window of a record (samples): given (`window_s`), else
/// the longest of [`WINDOWS_S`] (at most a quarter of the record) over
/// which the torque the model leaves unexplained (its residue on the
/// record, its spectrum kept and its phases drawn: the noise as the chain
/// delivers it, filtered or not, and what model error there is) and the
/// start states' noise move the model by at most [`NOISE_SHARE`] of each
/// moving joint's motion; with what decided it, said.
fn rollout_window(
    dynamics: &mut robotid_stages::dynamics::BaseDynamics,
    kin: &robotid_schemas::Kinematics,
    tau: &[Vec<f64>],
    window_s: Option<f64>,
) -> std::result::Result<(usize, String), robotid_stages::dynamics::Stopped> {
    let step = (kin.time.last().copied().unwrap_or(0.0) - kin.time[0]) / (kin.time.len().max(2) - 1) as f64;
    let samples = |t: f64| ((t / step).round() as usize).max(2);
    if let Some(w) = window_s {
        return Ok((samples(w), format!("{:.3} s, as given", samples(w) as f64 * step)));
    }
    let longest = WINDOWS_S
        .iter()
        .copied()
        .rfind(|&t| samples(t) <= kin.time.len() / 4)
        .unwrap_or(WINDOWS_S[0]);
    let n = kin.q.len();
    let mut residue = vec![vec![0.0; kin.time.len()]; n];
    let (mut q, mut qd, mut qdd) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    for s in 0..kin.time.len() {
        for j in 0..n {
            (q[j], qd[j], qdd[j]) = (kin.q[j][s], kin.qd[j][s], kin.qdd[j][s]);
        }
        for (j, t) in dynamics.torque(&q, &qd, &qdd).iter().enumerate() {
            residue[j][s] = tau[j][s] - t;
        }
    }
    let growth = robotid_stages::dynamics::noise_growth(
        dynamics,
        &kin.time,
        (&kin.q, &kin.qd, tau),
        Some(&residue),
        (samples(longest), 0x5eed),
    )?;
    let motion: Vec<f64> = kin.q.iter().map(|q| std_dev(q)).collect();
    let moving = |j: &usize| motion[*j] > 1e-6;
    // The noise's share of the motion after `t` seconds, on the worst joint.
    let share = |t: f64| {
        let row = &growth[(samples(t) - 2).min(growth.len() - 1)];
        (0..row.len())
            .filter(moving)
            .map(|j| row[j] / motion[j])
            .fold(0.0, f64::max)
    };
    let fits: Vec<f64> = WINDOWS_S.iter().copied().filter(|&t| t <= longest).collect();
    let chosen = fits
        .iter()
        .copied()
        .take_while(|&t| share(t) <= NOISE_SHARE)
        .last()
        .unwrap_or(fits[0]);
    let next = fits.iter().copied().find(|&t| t > chosen);
    let rms: Vec<f64> = residue.iter().map(|r| std_dev(r)).collect();
    let said = format!(
        "{chosen} s, chosen from the noise: the torque the model leaves unexplained on this record (RMS {} N·m, its spectrum kept, its phases drawn) and the start states' noise move it by {:.2} % of the motion of the joint they move most within it{}",
        span(&rms),
        100.0 * share(chosen),
        match next {
            Some(t) => format!(" ({:.2} % within {t} s; at most {:.0} % taken)", 100.0 * share(t), 100.0 * NOISE_SHARE),
            None => format!(" (the longest window tried: a quarter of the record at most; at most {:.0} % taken)", 100.0 * NOISE_SHARE),
        }
    );
    Ok((samples(chosen), said))
}

/// The smallest and largest of `x`, or the one value they share.
fn span(x: &[f64]) -> String {
    let (lo, hi) = (
        x.iter().copied().fold(f64::INFINITY, f64::min),
        x.iter().copied().fold(f64::NEG_INFINITY, f64::max),
    );
    match format!("{lo:.2e}") == format!("{hi:.2e}") {
        true => format!("{lo:.2e}"),
        false => format!("{lo:.2e}–{hi:.2e}"),
    }
}

fn std_dev(x: &[f64]) -> f64 {
    let m = x.iter().sum::<f64>() / x.len().max(1) as f64;
    (x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / x.len().max(1) as f64).sqrt()
}

/// A ratio with three significant digits.
fn figure(x: f64) -> String {
    match x.abs() {
        a if a == 0.0 || !a.is_finite() => format!("{x}"),
        a if a < 0.01 => format!("{x:.2e}"),
        _ => format!("{x:.3}"),
    }
}

/// The kinematics table at `path` and its torque, refused without one or
/// for other joints than `model`'s.
fn kinematics_of(
    path: &Path,
    model: &robotid_stages::dynamics::Model,
) -> Result<(robotid_schemas::Kinematics, Vec<Vec<f64>>)> {
    let mut kin =
        robotid_schemas::Kinematics::from_record_batch(&robotid_stages::formats::parquet::read_parquet(path)?)
            .map_err(|e| Error::Table {
                path: path.to_path_buf(),
                source: e.into(),
            })?;
    let Some(tau) = kin.torque.take() else {
        return Err(Error::Unfit {
            path: path.to_path_buf(),
            msg: "the kinematics table holds no torque to drive a rollout with".into(),
        });
    };
    if kin.joints != model.joints.iter().map(|j| j.name.clone()).collect::<Vec<_>>() {
        return Err(Error::Unfit {
            path: path.to_path_buf(),
            msg: format!(
                "joints {} are not the robot's {}",
                kin.joints.join(", "),
                model
                    .joints
                    .iter()
                    .map(|j| j.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        });
    }
    Ok((kin, tau))
}

/// The parameters table at `parameters` (of `robot`, both read `within`
/// a folder) rolled out as each of `rolled` was: its record, its windows
/// (another estimate beside theirs, the robot file's not again).
pub fn rolled_alike(
    within: &Path,
    parameters: &Path,
    robot: &Robot,
    rolled: &[RolledOut],
) -> Result<Vec<std::result::Result<robotid_stages::dynamics::Rollout, robotid_stages::dynamics::Stopped>>> {
    use robotid_stages::dynamics::{rollout, BaseDynamics};
    let (params, model, base) = crate::tables::identified_with(robot, &within.join(parameters))?;
    let theta: Vec<f64> = params.values.iter().copied().collect();
    rolled
        .iter()
        .map(|r| {
            let (kin, tau) = kinematics_of(&within.join(&r.table), &model)?;
            let dynamics = BaseDynamics::new(&base, &theta);
            Ok(rollout(&dynamics, &kin.time, &kin.q, &kin.qd, &tau, r.window))
        })
        .collect()
}

/// The parameters table at `parameters` (of `robot`) rolled out on the
/// kinematics table beside each regressor table of `regressors` (both
/// read `within` a folder): the model's forward dynamics driven by the
/// measured torque from the measured state, restarted from it every
/// window (`window_s` seconds, else chosen from the record's noise: see
/// [`NOISE_SHARE`]); the robot file's parameters the same way.
pub fn rollouts(
    within: &Path,
    parameters: &Path,
    robot: &Robot,
    regressors: &[PathBuf],
    window_s: Option<f64>,
) -> Result<Vec<RolledOut>> {
    use robotid_stages::dynamics::{rollout, BaseDynamics};
    let (params, model, base) = crate::tables::identified_with(robot, &within.join(parameters))?;
    let theta: Vec<f64> = params.values.iter().copied().collect();
    let prior: Option<Vec<f64>> = base.base_values(&model).map(|v| v.iter().copied().collect());
    let mut out = Vec::new();
    for r in regressors {
        let table = r.with_file_name("kinematics.parquet");
        let (kin, tau) = kinematics_of(&within.join(&table), &model)?;
        let tau = &tau;
        let step = (kin.time.last().copied().unwrap_or(0.0) - kin.time[0]) / (kin.time.len().max(2) - 1) as f64;
        // Chosen with the estimate's own model; where that cannot be
        // simulated, the robot file's, else the given or shortest window.
        let mut chosen = Err(robotid_stages::dynamics::Stopped::NotPositiveDefinite { sample: 0, joint: 0 });
        for t in std::iter::once(&theta).chain(prior.as_ref()) {
            chosen = rollout_window(&mut BaseDynamics::new(&base, t), &kin, tau, window_s);
            if chosen.is_ok() {
                break;
            }
        }
        let (window, window_said) = chosen.unwrap_or_else(|_| {
            let t = window_s.unwrap_or(WINDOWS_S[0]);
            (
                ((t / step).round() as usize).max(2),
                format!("{t} s: neither model could be simulated to choose it"),
            )
        });
        let run = |theta: &[f64]| {
            rollout(
                &BaseDynamics::new(&base, theta),
                &kin.time,
                &kin.q,
                &kin.qd,
                tau,
                window,
            )
        };
        out.push(RolledOut {
            table,
            joints: kin.joints.clone(),
            window,
            window_s: window as f64 * step,
            window_said,
            estimate: run(&theta),
            prior: prior.as_deref().map(run),
            time: kin.time.clone(),
            measured: kin.q.clone(),
        });
    }
    Ok(out)
}

/// A controller as a recording declares it: a TOML file with a
/// `[controller]` table of per-joint `kp`, `kd`, `ki` in the robot's
/// joint order (robotid's simulator writes one beside each recording,
/// `<name>.truth.toml`).
pub fn read_controller(path: &Path, joints: usize) -> Result<robotid_stages::dynamics::Pid> {
    let bad = |msg: String| Error::Unfit {
        path: path.to_path_buf(),
        msg,
    };
    let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let table: toml::Table = text.parse().map_err(|e| bad(format!("not TOML: {e}")))?;
    let c = table
        .get("controller")
        .and_then(|c| c.as_table())
        .ok_or_else(|| bad("no [controller] table (kp, kd, ki per joint)".into()))?;
    // A simulation file's controller is a design (a bandwidth the
    // simulator turns into gains from the true mass matrix), not the gains
    // the loop ran with: gains made here from the robot file would differ.
    if let Some(kind) = c.get("kind") {
        let kind = kind.as_str().map_or_else(|| kind.to_string(), |k| format!("\"{k}\""));
        return Err(bad(format!(
            "[controller] kind = {kind} is a simulation file's controller design, not the gains the loop ran with; give the truth file `robotid simulate` wrote beside the recording (<name>.truth.toml), or a [controller] table of kp, kd and ki, {joints} each"
        )));
    }
    let gains = |k: &str| -> Result<Vec<f64>> {
        let expected = format!("[controller] {k}: {joints} gains ≥ 0 expected, one per joint in the robot's order");
        let list = match c.get(k) {
            None => return Err(bad(format!("{expected}; none given"))),
            Some(v) => v
                .as_array()
                .ok_or_else(|| bad(format!("{expected}; {v} given, not a list")))?,
        };
        let v: Vec<f64> = list
            .iter()
            .enumerate()
            .map(|(i, x)| {
                x.as_float()
                    .or(x.as_integer().map(|i| i as f64))
                    .filter(|g| g.is_finite() && *g >= 0.0)
                    .ok_or_else(|| bad(format!("{expected}; its gain {} is {x}", i + 1)))
            })
            .collect::<Result<_>>()?;
        match v.len() == joints {
            true => Ok(v),
            false => Err(bad(format!("{expected}; {} given", v.len()))),
        }
    };
    Ok(robotid_stages::dynamics::Pid {
        kp: gains("kp")?,
        kd: gains("kd")?,
        ki: gains("ki")?,
    })
}

/// One record rolled out in closed loop: the estimate's model and the
/// robot file's under the declared controller, tracking the recorded
/// reference.
pub struct ClosedLoopRun {
    pub recording: PathBuf,
    pub joints: Vec<String>,
    pub time: Vec<f64>,
    pub measured: Vec<Vec<f64>>,
    pub estimate: std::result::Result<robotid_stages::dynamics::ClosedLoop, robotid_stages::dynamics::Stopped>,
    pub prior: Option<std::result::Result<robotid_stages::dynamics::ClosedLoop, robotid_stages::dynamics::Stopped>>,
}

/// One joint's closed-loop figures, said: the estimate's position RMS
/// error (mrad), the robot file's (or why not), their ratio.
pub struct ClosedLoopRow {
    pub joint: String,
    pub q_mrad: f64,
    pub file: String,
    pub ratio: String,
}

impl ClosedLoopRun {
    /// Why a model was not simulated, said.
    pub fn stopped_said(&self, stopped: &robotid_stages::dynamics::Stopped) -> String {
        stopped_said(&self.joints, stopped)
    }

    /// Per joint, the figures; Err: where the estimate stopped
    /// ([`ClosedLoopRun::stopped_said`] says it).
    pub fn rows(&self) -> std::result::Result<Vec<ClosedLoopRow>, &robotid_stages::dynamics::Stopped> {
        let est = self.estimate.as_ref()?;
        Ok(self
            .joints
            .iter()
            .enumerate()
            .map(|(j, joint)| {
                let (file, ratio) = beside_file(&self.joints, &self.prior, |p| p.q_rms[j], est.q_rms[j], 4);
                ClosedLoopRow {
                    joint: joint.clone(),
                    q_mrad: 1e3 * est.q_rms[j],
                    file,
                    ratio,
                }
            })
            .collect())
    }
}

/// The parameters table at `parameters` (of `robot`) simulated in closed
/// loop on each raw recording of `recordings` (a table with each joint's
/// position and reference, `q_<joint>` and `ref_<joint>`, as `robotid
/// simulate` writes): under the controller the file `controller` declares
/// ([`read_controller`]), tracking the recorded reference from the first
/// sample's state; the robot file's parameters the same way.
pub fn closed_loop_rollouts(
    parameters: &Path,
    robot: &Robot,
    recordings: &[PathBuf],
    controller: &Path,
) -> Result<Vec<ClosedLoopRun>> {
    use robotid_stages::dynamics::{closed_loop, BaseDynamics};
    let (params, model, base) = crate::tables::identified_with(robot, parameters)?;
    let controller = &read_controller(controller, model.dof())?;
    let theta: Vec<f64> = params.values.iter().copied().collect();
    let prior: Option<Vec<f64>> = base.base_values(&model).map(|v| v.iter().copied().collect());
    let mut out = Vec::new();
    for path in recordings {
        let raw =
            robotid_schemas::RawSamples::from_record_batch(&robotid_stages::formats::parquet::read_parquet(path)?)
                .map_err(|e| Error::Table {
                    path: path.clone(),
                    source: e.into(),
                })?;
        let reference = raw.reference.as_ref().ok_or_else(|| Error::Unfit {
            path: path.to_path_buf(),
            msg: "no reference columns (`ref_<joint>`): a closed-loop rollout tracks the recorded reference".into(),
        })?;
        if raw.joints != model.joint_names() || raw.time.len() < 3 {
            return Err(Error::Unfit {
                path: path.to_path_buf(),
                msg: format!(
                    "joints {} over {} samples: not the robot's {} over 3 or more",
                    raw.joints.join(", "),
                    raw.time.len(),
                    model.joint_names().join(", ")
                ),
            });
        }
        // The start velocity from the first two samples (a record that
        // starts at rest: zero up to the position noise).
        let qd: Vec<Vec<f64>> = raw
            .q
            .iter()
            .map(|q| vec![(q[1] - q[0]) / (raw.time[1] - raw.time[0])])
            .collect();
        let run = |theta: &[f64]| {
            closed_loop(
                &mut BaseDynamics::new(&base, theta),
                &raw.time,
                reference,
                controller,
                (&raw.q, &qd),
            )
        };
        out.push(ClosedLoopRun {
            recording: path.clone(),
            joints: raw.joints.clone(),
            estimate: run(&theta),
            prior: prior.as_deref().map(run),
            time: raw.time.clone(),
            measured: raw.q.clone(),
        });
    }
    Ok(out)
}

/// Closed-loop rollouts as one table, a row per recording, model and
/// joint: `recording`, `model` (`estimate` or `robot_file`), `joint`,
/// `q_rms` (rad) and the RK4 `substeps` per sample step, units in each
/// field's metadata. A model that could not be simulated has no rows.
pub fn closed_loop_table(runs: &[ClosedLoopRun]) -> Result<arrow::record_batch::RecordBatch> {
    use arrow::array::{ArrayRef, Float64Array, StringArray, UInt32Array};

    use std::sync::Arc;
    let (mut recording, mut model, mut joint, mut q, mut substeps) = (vec![], vec![], vec![], vec![], vec![]);
    for r in runs {
        for (name, run) in [("estimate", Some(&r.estimate)), ("robot_file", r.prior.as_ref())] {
            let Some(Ok(run)) = run else { continue };
            for (j, name_j) in r.joints.iter().enumerate() {
                recording.push(r.recording.display().to_string());
                model.push(name);
                joint.push(name_j.clone());
                q.push(run.q_rms[j]);
                substeps.push(run.substeps as u32);
            }
        }
    }
    units_table(
        "the closed-loop table",
        vec![
            ("recording", "1", Arc::new(StringArray::from(recording)) as ArrayRef),
            ("model", "1", Arc::new(StringArray::from(model))),
            ("joint", "1", Arc::new(StringArray::from(joint))),
            ("q_rms", "rad", Arc::new(Float64Array::from(q))),
            ("substeps", "1", Arc::new(UInt32Array::from(substeps))),
        ],
    )
}

/// Rollouts as one table, a row per record, model, window and joint:
/// `table`, `model` (`estimate` or `robot_file`), `window`, `start_s`,
/// `joint`, `q_rms` (rad) and `qd_rms` (rad/s), units in each field's
/// metadata. A model that could not be simulated has no rows.
pub fn rollout_table(rolled: &[RolledOut]) -> Result<arrow::record_batch::RecordBatch> {
    use arrow::array::{ArrayRef, Float64Array, StringArray, UInt32Array};

    use std::sync::Arc;
    let (mut table, mut model, mut window, mut start, mut joint, mut q, mut qd) =
        (vec![], vec![], vec![], vec![], vec![], vec![], vec![]);
    for r in rolled {
        for (name, out) in [("estimate", Some(&r.estimate)), ("robot_file", r.prior.as_ref())] {
            let Some(Ok(out)) = out else { continue };
            for (k, w) in out.windows.iter().enumerate() {
                for (j, name_j) in r.joints.iter().enumerate() {
                    table.push(r.table.display().to_string());
                    model.push(name);
                    window.push(k as u32);
                    start.push(r.time[w.start]);
                    joint.push(name_j.clone());
                    q.push(w.q_rms[j]);
                    qd.push(w.qd_rms[j]);
                }
            }
        }
    }
    units_table(
        "the rollout table",
        vec![
            ("table", "1", Arc::new(StringArray::from(table)) as ArrayRef),
            ("model", "1", Arc::new(StringArray::from(model))),
            ("window", "1", Arc::new(UInt32Array::from(window))),
            ("start_s", "s", Arc::new(Float64Array::from(start))),
            ("joint", "1", Arc::new(StringArray::from(joint))),
            ("q_rms", "rad", Arc::new(Float64Array::from(q))),
            ("qd_rms", "rad/s", Arc::new(Float64Array::from(qd))),
        ],
    )
}

/// A table of `columns` (name, unit, values), each unit in its field's
/// metadata; `what` names it in an error.
pub fn units_table(
    what: &str,
    columns: Vec<(&str, &str, arrow::array::ArrayRef)>,
) -> Result<arrow::record_batch::RecordBatch> {
    use arrow::datatypes::{Field, Schema};
    let fields: Vec<Field> = columns
        .iter()
        .map(|(name, unit, values)| {
            Field::new(*name, values.data_type().clone(), false).with_metadata(
                [(robotid_schemas::metadata::UNIT.to_string(), unit.to_string())]
                    .into_iter()
                    .collect::<std::collections::HashMap<_, _>>(),
            )
        })
        .collect();
    let arrays = columns.into_iter().map(|(_, _, a)| a).collect();
    arrow::record_batch::RecordBatch::try_new(std::sync::Arc::new(Schema::new(fields)), arrays).map_err(|e| {
        Error::Output {
            what: what.into(),
            msg: e.to_string(),
        }
    })
}
