//! Reference trajectories: the periodic finite Fourier series of Swevers
//! eq. 5 (excitation) and rest-to-rest quintic moves through waypoints
//! (non-periodic validation). Both serialise to the `[trajectory]` table
//! of simulation and excitation files.

mod fourier;
mod sweeps;
mod waypoints;

pub use fourier::FourierSeries;
pub use sweeps::Sweeps;
pub use waypoints::{Durations, Waypoints};

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Trajectory {
    Fourier(FourierSeries),
    Waypoints(Waypoints),
    /// Dedicated gravity and friction experiments (Bona §3.2).
    Sweeps(Sweeps),
}

impl Trajectory {
    /// Number of joints the trajectory drives.
    pub fn dof(&self) -> usize {
        match self {
            Trajectory::Fourier(f) => f.q0.len(),
            Trajectory::Waypoints(w) => w.points.first().map_or(0, Vec::len),
            Trajectory::Sweeps(s) => s.hold.len(),
        }
    }

    /// Period in s for periodic trajectories.
    pub fn period(&self) -> Option<f64> {
        match self {
            Trajectory::Fourier(f) => Some(f.period()),
            Trajectory::Waypoints(_) | Trajectory::Sweeps(_) => None,
        }
    }

    /// Positions (rad), velocities (rad/s), accelerations (rad/s²) at `t` s.
    pub fn eval(&self, t: f64, q: &mut [f64], qd: &mut [f64], qdd: &mut [f64]) {
        match self {
            Trajectory::Fourier(f) => f.eval(t, q, qd, qdd),
            Trajectory::Waypoints(w) => w.eval(t, q, qd, qdd),
            Trajectory::Sweeps(s) => s.eval(t, q, qd, qdd),
        }
    }

    /// The position at which the trajectory is at rest before it starts
    /// (the Fourier offsets q0, or the first waypoint).
    pub fn rest_position(&self) -> Vec<f64> {
        match self {
            Trajectory::Fourier(f) => f.q0.clone(),
            Trajectory::Waypoints(w) => w.points[0].clone(),
            Trajectory::Sweeps(s) => {
                let mut q = s.hold.clone();
                q[s.joint] = s.range[0];
                q
            }
        }
    }

    pub fn validate(&self) -> Result<(), crate::Problem> {
        match self {
            Trajectory::Fourier(f) => f.validate(),
            Trajectory::Waypoints(w) => w.validate(),
            Trajectory::Sweeps(s) => s.validate(),
        }
    }
}

/// The `[trajectory]` table of a TOML file (a simulation or excitation file).
pub fn load_trajectory(path: &std::path::Path) -> crate::Result<Trajectory> {
    let err = |msg: String| crate::Error::Config {
        path: path.to_path_buf(),
        msg,
    };
    let text = std::fs::read_to_string(path).map_err(|e| crate::Error::io(path, e))?;
    let table: toml::Table = toml::from_str(&text).map_err(|e| err(crate::error::toml_message(&text, &e)))?;
    let t = table
        .get("trajectory")
        .cloned()
        .ok_or_else(|| err("no [trajectory] table".into()))?;
    let t: Trajectory = t
        .try_into()
        .map_err(|e: toml::de::Error| err(format!("[trajectory]: {}", e.message())))?;
    t.validate().map_err(|e| err(format!("[trajectory] {e}")))?;
    Ok(t)
}
