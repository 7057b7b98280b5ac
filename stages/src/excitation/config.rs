//! The excitation file (docs/excitation-file.md).

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::Layout;
use crate::dynamics::Model;
use crate::dynamics::RegressorModel;
use crate::Problem;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExciteConfig {
    /// The robot file, relative to the excitation file.
    pub robot: PathBuf,
    pub base_frequency_hz: f64,
    /// Harmonic numbers of the series (omit some to keep energy out of a band).
    pub harmonics: Vec<u32>,
    /// Per joint, the subset of `harmonics` it uses (default: all).
    pub joint_harmonics: Option<Vec<Vec<u32>>>,
    /// Samples per second at which every constraint is enforced and checked.
    pub sample_rate_hz: f64,
    /// Samples per period used in the criterion (default: all, at most 200).
    pub criterion_samples: Option<usize>,
    #[serde(default)]
    pub criterion: CriterionKind,
    /// The identification model whose base regressor is conditioned.
    #[serde(default)]
    pub regressor: RegressorModel,
    /// Limits (default: the robot file's).
    #[serde(default)]
    pub limits: LimitsConfig,
    #[serde(default)]
    pub cartesian: Vec<Cartesian>,
    #[serde(default = "default_starts")]
    pub starts: usize,
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// SLSQP evaluations per phase and start.
    #[serde(default = "default_iterations")]
    pub max_iterations: usize,
}

fn default_starts() -> usize {
    8
}
fn default_seed() -> u64 {
    1
}
fn default_iterations() -> usize {
    300
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CriterionKind {
    /// Condition number of the column-normalised base regressor (Swevers eq. 6).
    #[default]
    Condition,
    /// Condition number with the columns scaled by the a-priori base
    /// parameters instead (Gautier): balances the torque contributions.
    Gautier,
    /// −log det of the information matrix with the columns scaled by the
    /// a-priori base parameters (D-optimality: the volume of the
    /// confidence ellipsoid, in units of the parameters' own sizes).
    LogDet,
}

/// Per-joint limit overrides (lists, one entry per joint).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LimitsConfig {
    pub position: Option<Vec<[f64; 2]>>,
    pub velocity: Option<Vec<f64>>,
    pub acceleration: Option<Vec<f64>>,
}

/// Whether a box keeps the point inside or out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Keep {
    Inside,
    Outside,
}

/// Constraints on a point of the arm from forward kinematics: `link` is a
/// joint index (its frame origin), absent for the end effector.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Cartesian {
    /// min ≤ z ≤ max (either may be absent).
    Height {
        link: Option<usize>,
        min: Option<f64>,
        max: Option<f64>,
    },
    /// Stay out of a vertical cylinder of `radius` around (x, y) = `center`,
    /// up to the height `below` if given (Swevers: the arm touches its base
    /// if r < 0.7 m and z < 1.8 m).
    Cylinder {
        link: Option<usize>,
        radius: f64,
        #[serde(default)]
        center: [f64; 2],
        below: Option<f64>,
    },
    Box {
        link: Option<usize>,
        min: [f64; 3],
        max: [f64; 3],
        keep: Keep,
    },
}

impl Cartesian {
    pub fn link(&self) -> Option<usize> {
        match self {
            Cartesian::Height { link, .. } | Cartesian::Cylinder { link, .. } | Cartesian::Box { link, .. } => *link,
        }
    }

    pub fn name(&self) -> String {
        let at = self.link().map_or("end effector".to_string(), |l| format!("link {l}"));
        let bound = |b: &Option<f64>, none: &str| b.map_or(none.to_string(), |v| v.to_string());
        let point = |p: &[f64]| format!("({})", p.iter().map(f64::to_string).collect::<Vec<_>>().join(", "));
        match self {
            Cartesian::Height { min, max, .. } => {
                format!("{at} height in [{}, {}] m", bound(min, "-inf"), bound(max, "inf"))
            }
            Cartesian::Cylinder {
                radius, center, below, ..
            } => match below {
                Some(h) => format!(
                    "{at} outside the cylinder r = {radius} m at {} below z = {h} m",
                    point(center)
                ),
                None => format!("{at} outside the cylinder r = {radius} m at {}", point(center)),
            },
            Cartesian::Box { min, max, keep, .. } => {
                format!("{at} {keep:?} box {}..{}", point(min), point(max)).to_lowercase()
            }
        }
    }
}

impl ExciteConfig {
    /// Samples per period at the constraint rate.
    pub fn samples(&self) -> usize {
        (self.sample_rate_hz / self.base_frequency_hz).round() as usize
    }

    /// Every problem at once.
    pub fn problems(&self, model: &Model) -> Vec<Problem> {
        let mut e = Vec::new();
        let n = model.dof();
        if !(self.base_frequency_hz > 0.0) {
            e.push(Problem::new("base_frequency_hz", "base_frequency_hz must be > 0"));
        }
        if !(self.sample_rate_hz > 0.0) {
            e.push(Problem::new("sample_rate_hz", "sample_rate_hz must be > 0"));
        }
        if self.harmonics.is_empty() || self.harmonics.windows(2).any(|w| w[1] <= w[0]) || self.harmonics[0] == 0 {
            e.push(Problem::new(
                "harmonics",
                "harmonics must be distinct positive integers in increasing order",
            ));
        }
        if let Some(&top) = self.harmonics.last() {
            if top as f64 * self.base_frequency_hz * 2.0 >= self.sample_rate_hz {
                e.push(Problem::new(
                    "harmonics",
                    format!(
                        "harmonic {top} ({} Hz) is above the Nyquist frequency of sample_rate_hz",
                        top as f64 * self.base_frequency_hz
                    ),
                ));
            }
        }
        if let Some(jh) = &self.joint_harmonics {
            if jh.len() != n {
                e.push(Problem::new(
                    "joint_harmonics",
                    format!("joint_harmonics lists {} joints, the robot has {n}", jh.len()),
                ));
            }
            for (j, h) in jh.iter().enumerate() {
                if let Some(x) = h.iter().find(|x| !self.harmonics.contains(x)) {
                    e.push(Problem::new(
                        "joint_harmonics",
                        format!("joint_harmonics[{j}]: {x} is not in harmonics"),
                    ));
                }
            }
        }
        if self.starts == 0 {
            e.push(Problem::new("starts", "starts must be ≥ 1"));
        }
        if (self.samples() as f64) < 4.0 * *self.harmonics.last().unwrap_or(&1) as f64 {
            e.push(Problem::new(
                "sample_rate_hz",
                "sample_rate_hz gives too few samples per period for the harmonics",
            ));
        }
        e.extend(self.limit_problems(model));
        e
    }

    /// The problems of the limits (per joint, each known) and of the
    /// Cartesian constraints.
    fn limit_problems(&self, model: &Model) -> Vec<Problem> {
        let mut e = Vec::new();
        let n = model.dof();
        for (what, len) in [
            ("position", self.limits.position.as_ref().map(Vec::len)),
            ("velocity", self.limits.velocity.as_ref().map(Vec::len)),
            ("acceleration", self.limits.acceleration.as_ref().map(Vec::len)),
        ] {
            if let Some(l) = len {
                if l != n {
                    e.push(Problem::new(
                        "limits",
                        format!("limits.{what} lists {l} joints, the robot has {n}"),
                    ));
                }
            }
        }
        for j in 0..n {
            let (p, v, a) = self.limit(model, j);
            if p.is_none() || v.is_none() || a.is_none() {
                e.push(Problem::new(
                    "limits",
                    format!(
                        "joint `{}`: position, velocity and acceleration limits are needed (robot file or [limits])",
                        model.joints[j].name
                    ),
                ));
            }
        }
        for c in &self.cartesian {
            if let Some(l) = c.link() {
                if l >= n {
                    e.push(Problem::new(
                        "cartesian",
                        format!("cartesian `{}`: link {l} is not a joint index (0..{n})", c.name()),
                    ));
                }
            }
            if let Cartesian::Box { min, max, .. } = c {
                if (0..3).any(|k| max[k] <= min[k]) {
                    e.push(Problem::new(
                        "cartesian",
                        format!("cartesian `{}`: max must exceed min", c.name()),
                    ));
                }
            }
        }
        e
    }

    /// Refuses a file with problems, naming each.
    pub fn validate(&self, model: &Model) -> crate::Result<()> {
        let problems = self.problems(model);
        if problems.is_empty() {
            Ok(())
        } else {
            Err(crate::Error::Problems {
                what: "excitation file".into(),
                problems,
            })
        }
    }

    /// (position range, velocity, acceleration) limits of joint `j`.
    pub fn limit(&self, model: &Model, j: usize) -> (Option<(f64, f64)>, Option<f64>, Option<f64>) {
        let m = &model.limits[j];
        (
            self.limits.position.as_ref().map(|p| (p[j][0], p[j][1])).or(m.position),
            self.limits.velocity.as_ref().map(|v| v[j]).or(m.velocity),
            self.limits.acceleration.as_ref().map(|v| v[j]).or(m.acceleration),
        )
    }

    pub fn layout(&self, model: &Model) -> Layout {
        let n = model.dof();
        Layout {
            base_frequency_hz: self.base_frequency_hz,
            harmonics: self.harmonics.clone(),
            active: (0..n)
                .map(|j| {
                    self.harmonics
                        .iter()
                        .map(|h| self.joint_harmonics.as_ref().is_none_or(|jh| jh[j].contains(h)))
                        .collect()
                })
                .collect(),
        }
    }
}
