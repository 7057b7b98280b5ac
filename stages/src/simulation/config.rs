//! The simulation file (`robotid simulate SIM.toml`); format documented in
//! `docs/simulation-file.md`.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::signal::FilterSpec;
use crate::trajectory::Trajectory;
use crate::Problem;
use crate::{Error, Result};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimConfig {
    /// Robot file (TOML or URDF), relative to the simulation file.
    pub robot: PathBuf,
    /// Seed of every random choice (start phase, noise, jitter, drops).
    #[serde(default)]
    pub seed: u64,
    pub trajectory: Trajectory,
    pub timing: Timing,
    #[serde(default)]
    pub controller: ControllerConfig,
    #[serde(default)]
    pub measurement: Measurement,
    #[serde(default)]
    pub disturbance: Disturbance,
    #[serde(default)]
    pub plant: PlantConfig,
    #[serde(default)]
    pub output: OutputConfig,
}

/// How the simulated robot differs from its description.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlantConfig {
    /// Coulomb transition velocity, rad/s, for joints whose robot file sets
    /// none: exact sign(q̇) friction chatters at the integration rate
    /// whenever the controller holds a joint still; tanh(q̇/v) with v ≳
    /// C·h/J does not. 0 keeps the exact sign.
    #[serde(default = "default_transition")]
    pub coulomb_transition_rad_s: f64,
}

fn default_transition() -> f64 {
    0.01
}

impl Default for PlantConfig {
    fn default() -> Self {
        PlantConfig {
            coulomb_transition_rad_s: default_transition(),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Timing {
    /// Rate of the log, Hz.
    pub log_rate_hz: f64,
    /// RK4 steps per log sample.
    #[serde(default = "default_steps")]
    pub steps_per_sample: u32,
    /// Start-up: the reference fades in from rest over this time, s.
    #[serde(default)]
    pub transient_s: f64,
    /// Periods logged after the transient (periodic trajectories).
    pub periods: Option<u32>,
    /// Phase of the periodic reference at the end of the fade-in, s into the
    /// period; absent: drawn at random from the seed.
    pub start_phase_s: Option<f64>,
    /// Standard deviation of the sampling-time jitter, s (0: none).
    #[serde(default)]
    pub jitter_std_s: f64,
    /// Probability that a sample is dropped from the log.
    #[serde(default)]
    pub drop_probability: f64,
}

fn default_steps() -> u32 {
    8
}

/// Joint position controller. `pid` gains default from a closed-loop
/// bandwidth and the mass matrix at the start position:
/// kp = M_ii·ω², kd = 2ζω·M_ii, ki = kp·ω_i.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum ControllerConfig {
    Pid {
        #[serde(default = "default_bandwidth")]
        bandwidth_hz: f64,
        #[serde(default = "default_damping")]
        damping: f64,
        #[serde(default = "default_integral")]
        integral_hz: f64,
        /// Explicit gains (N·m/rad, N·m·s/rad, N·m/(rad·s)) override the defaults.
        kp: Option<PerJoint>,
        kd: Option<PerJoint>,
        ki: Option<PerJoint>,
    },
    /// No control: the robot moves freely (with gravity and friction).
    Off,
}

fn default_bandwidth() -> f64 {
    5.0
}
fn default_damping() -> f64 {
    0.8
}
fn default_integral() -> f64 {
    0.5
}

impl Default for ControllerConfig {
    fn default() -> Self {
        ControllerConfig::Pid {
            bandwidth_hz: default_bandwidth(),
            damping: default_damping(),
            integral_hz: default_integral(),
            kp: None,
            kd: None,
            ki: None,
        }
    }
}

/// The measurement chain.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Measurement {
    /// Analog anti-alias filter on the motor current; absent: none.
    pub filter: Option<FilterSpec>,
    /// White Gaussian noise on the sampled current, A.
    #[serde(default)]
    pub current_noise_std_a: PerJoint,
    /// White Gaussian noise on the position before quantisation, rad.
    #[serde(default)]
    pub position_noise_std_rad: PerJoint,
    /// Quantise positions to whole encoder counts.
    #[serde(default = "yes")]
    pub quantise: bool,
}

fn yes() -> bool {
    true
}

impl Default for Measurement {
    fn default() -> Self {
        Measurement {
            filter: None,
            current_noise_std_a: PerJoint::default(),
            position_noise_std_rad: PerJoint::default(),
            quantise: true,
        }
    }
}

/// Process noise: a white torque disturbance acting on the joints, held
/// over each log-sample interval. It enters the loop, so the commanded
/// torque correlates with it (the closed-loop identification problem).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Disturbance {
    #[serde(default)]
    pub torque_std_nm: PerJoint,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OutputFormat {
    Mcap,
    Csv,
    Parquet,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputConfig {
    #[serde(default = "all_formats")]
    pub formats: Vec<OutputFormat>,
    /// Base name of the recording files.
    #[serde(default = "default_name")]
    pub name: String,
}

fn all_formats() -> Vec<OutputFormat> {
    vec![OutputFormat::Mcap, OutputFormat::Csv, OutputFormat::Parquet]
}
fn default_name() -> String {
    "recording".into()
}

impl Default for OutputConfig {
    fn default() -> Self {
        OutputConfig {
            formats: all_formats(),
            name: default_name(),
        }
    }
}

/// A value for every joint, or one list with a value per joint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum PerJoint {
    All(f64),
    Each(Vec<f64>),
}

impl Default for PerJoint {
    fn default() -> Self {
        PerJoint::All(0.0)
    }
}

impl PerJoint {
    pub fn resolve(&self, n: usize, key: &str) -> Result<Vec<f64>> {
        match self {
            PerJoint::All(v) => Ok(vec![*v; n]),
            PerJoint::Each(v) if v.len() == n => Ok(v.clone()),
            PerJoint::Each(v) => Err(Error::mismatch(
                format!("`{key}`: values"),
                format!("{n} (one per joint)"),
                v.len(),
            )),
        }
    }
}

/// The most samples one simulation may log (about 5 GB of f64 channels for
/// a 6-joint arm).
pub const MAX_SAMPLES: f64 = 5e7;

/// Why `name` cannot name files inside the output folder, if it cannot:
/// it comes from a file the user may not have written, and a separator,
/// `..` or an absolute path would write outside that folder.
pub fn plain_name_problem(name: &str) -> Option<&'static str> {
    if name.is_empty() || name == "." || name == ".." {
        Some("must be a file name (it is empty, `.` or `..`)")
    } else if name.contains(['/', '\\', '\0']) {
        Some("must be a plain file name, without a path separator: the recordings go into the output folder")
    } else if name.len() > 200 {
        Some("is longer than 200 bytes")
    } else {
        None
    }
}

impl SimConfig {
    /// Reads and checks a simulation file; the robot path is made absolute
    /// against the file's folder.
    pub fn load(path: &Path) -> Result<(SimConfig, String)> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        Ok((SimConfig::parse(&text, path)?, text))
    }

    /// Parses simulation-file text; `path` names it in errors and anchors
    /// the robot path.
    pub fn parse(text: &str, path: &Path) -> Result<SimConfig> {
        let err = |msg: String| Error::Config {
            path: path.to_path_buf(),
            msg,
        };
        let mut table: toml::Table = toml::from_str(text).map_err(|e| err(crate::error::toml_message(text, &e)))?;
        // `trajectory_file = "…"` instead of a [trajectory] table: the
        // [trajectory] of another file, e.g. `robotid excite`'s output.
        // Without it, deserialise the text itself (errors keep their line).
        if !table.contains_key("trajectory_file") {
            let mut cfg: SimConfig = toml::from_str(text).map_err(|e| err(crate::error::toml_message(text, &e)))?;
            cfg.robot = path.parent().unwrap_or(Path::new(".")).join(&cfg.robot);
            cfg.validate().map_err(|e| err(e.to_string()))?;
            return Ok(cfg);
        }
        if let Some(file) = table.remove("trajectory_file") {
            let rel = file
                .as_str()
                .ok_or_else(|| err("trajectory_file must be a path".into()))?;
            if table.contains_key("trajectory") {
                return Err(err("give either [trajectory] or trajectory_file, not both".into()));
            }
            let t = crate::trajectory::load_trajectory(&path.parent().unwrap_or(Path::new(".")).join(rel))?;
            table.insert(
                "trajectory".into(),
                toml::Value::try_from(t).map_err(|e| err(format!("trajectory_file: {e}")))?,
            );
        }
        let mut cfg: SimConfig = toml::Value::Table(table)
            .try_into()
            .map_err(|e: toml::de::Error| err(e.message().to_string()))?;
        cfg.robot = path.parent().unwrap_or(Path::new(".")).join(&cfg.robot);
        cfg.validate().map_err(|e| Error::Config {
            path: path.to_path_buf(),
            msg: e.to_string(),
        })?;
        Ok(cfg)
    }

    /// Structural problems that need no robot, each with its key.
    pub fn problems(&self) -> Vec<Problem> {
        let mut errs = Vec::new();
        if let Err(e) = self.trajectory.validate() {
            errs.push(e.under("trajectory"));
        }
        let t = &self.timing;
        if !(t.log_rate_hz > 0.0 && t.log_rate_hz.is_finite()) {
            errs.push(Problem::new(
                "timing.log_rate_hz",
                format!("must be > 0, found {}", t.log_rate_hz),
            ));
        }
        if t.steps_per_sample == 0 {
            errs.push(Problem::new("timing.steps_per_sample", "must be ≥ 1"));
        }
        if !(t.transient_s >= 0.0 && t.transient_s.is_finite()) {
            errs.push(Problem::new(
                "timing.transient_s",
                format!("must be ≥ 0 and finite, not {}", t.transient_s),
            ));
        }
        // The samples the run would make, bounded before anything is allocated.
        let logged = match (&self.trajectory, t.periods) {
            (Trajectory::Fourier(f), Some(p)) => p as f64 / f.base_frequency_hz,
            (Trajectory::Waypoints(w), _) => w.duration(),
            (Trajectory::Sweeps(s), _) => s.duration(),
            _ => 0.0,
        };
        let samples = (t.transient_s + logged) * t.log_rate_hz;
        if samples > MAX_SAMPLES {
            errs.push(Problem::new(
                "timing",
                format!(
                    "{:.3e} samples ({:.1} s at {} Hz) is more than {MAX_SAMPLES:.0e}: a shorter record, or fewer periods",
                    samples,
                    t.transient_s + logged,
                    t.log_rate_hz
                ),
            ));
        }
        match (&self.trajectory, t.periods) {
            (Trajectory::Fourier(_), None) | (Trajectory::Fourier(_), Some(0)) => errs.push(Problem::new(
                "timing.periods",
                "(≥ 1) is required for a periodic trajectory",
            )),
            (Trajectory::Waypoints(_) | Trajectory::Sweeps(_), Some(_)) => {
                errs.push(Problem::new("timing.periods", "applies to periodic trajectories only"))
            }
            _ => {}
        }
        if !(t.jitter_std_s >= 0.0 && t.jitter_std_s.is_finite() && (0.0..1.0).contains(&t.drop_probability)) {
            errs.push(Problem::new(
                "timing.jitter_std_s",
                "must be ≥ 0 and drop_probability in [0, 1)",
            ));
        }
        if let Some(f) = &self.measurement.filter {
            if let Err(e) = f.validate() {
                errs.push(e.under("measurement.filter"));
            }
        }
        if !(self.plant.coulomb_transition_rad_s >= 0.0) {
            errs.push(Problem::new("plant.coulomb_transition_rad_s", "must be ≥ 0"));
        }
        if self.output.formats.is_empty() {
            errs.push(Problem::new("output.formats", "is empty"));
        }
        if let Some(why) = plain_name_problem(&self.output.name) {
            errs.push(Problem::new("output.name", why));
        }
        errs
    }

    /// Refuses a file with structural problems, naming each.
    pub fn validate(&self) -> Result<()> {
        let problems = self.problems();
        if problems.is_empty() {
            Ok(())
        } else {
            Err(Error::Problems {
                what: "simulation file".into(),
                problems,
            })
        }
    }
}
