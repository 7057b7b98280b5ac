//! The exported MJCF rolled out by MuJoCo itself, beside robotid's own
//! rollout: the same windows from the measured state, driven by the
//! measured torque, so that "validated" means validated in the simulator
//! the export is for (its `frictionloss` constraint holding a joint at
//! rest, its integrator). MuJoCo is a Python package: a Python that has it
//! runs `scripts/mujoco_rollout.py`, carried in the binary.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// The rollout script, as `scripts/mujoco_rollout.py` is.
const SCRIPT: &str = include_str!("../../scripts/mujoco_rollout.py");

/// One record rolled out by MuJoCo: per joint, the position and velocity
/// RMS error against the measured (rad, rad/s).
#[derive(Debug, Clone, PartialEq)]
pub struct MujocoRollout {
    pub joints: Vec<String>,
    pub q_rms: Vec<f64>,
    pub qd_rms: Vec<f64>,
}

/// Why MuJoCo's rollout did not come back: each names the Python run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MujocoError {
    /// The Python could not be started or waited on.
    #[error("{}: {message}", python.display())]
    Start { python: PathBuf, message: String },
    /// The script failed: its last line on stderr (no `mujoco` package,
    /// a model MuJoCo does not load).
    #[error("{} (MuJoCo's rollout): {said}", python.display())]
    Failed { python: PathBuf, said: String },
    /// It printed something other than its figures.
    #[error("{} (MuJoCo's rollout): not its JSON: {message}", python.display())]
    NotJson { python: PathBuf, message: String },
    #[error("{} (MuJoCo's rollout): no per-joint figures", python.display())]
    NoFigures { python: PathBuf },
}

/// `mjcf` rolled out by MuJoCo on the kinematics table `kinematics` in
/// windows of `window_s`, run by `python`; Err says why not (no such
/// Python, no `mujoco` package in it, a model MuJoCo does not load).
pub fn rollout(python: &Path, mjcf: &Path, kinematics: &Path, window_s: f64) -> Result<MujocoRollout, MujocoError> {
    let start = |e: std::io::Error| MujocoError::Start {
        python: python.to_path_buf(),
        message: e.to_string(),
    };
    let mut child = Command::new(python)
        .arg("-")
        .arg(mjcf)
        .arg(kinematics)
        .args(["--window-s", &window_s.to_string()])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(start)?;
    // A failed write shows as the script's failure below.
    let _ = child.stdin.take().map(|mut s| s.write_all(SCRIPT.as_bytes()));
    let out = child.wait_with_output().map_err(start)?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        let last = err.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("no message");
        return Err(MujocoError::Failed {
            python: python.to_path_buf(),
            said: last.to_string(),
        });
    }
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).map_err(|e| MujocoError::NotJson {
        python: python.to_path_buf(),
        message: e.to_string(),
    })?;
    let numbers = |k: &str| -> Option<Vec<f64>> { v[k].as_array()?.iter().map(|x| x.as_f64()).collect() };
    let joints: Option<Vec<String>> = v["joints"]
        .as_array()
        .and_then(|a| a.iter().map(|x| x.as_str().map(String::from)).collect());
    match (joints, numbers("q_rms"), numbers("qd_rms")) {
        (Some(joints), Some(q_rms), Some(qd_rms)) if q_rms.len() == joints.len() && qd_rms.len() == joints.len() => {
            Ok(MujocoRollout { joints, q_rms, qd_rms })
        }
        _ => Err(MujocoError::NoFigures {
            python: python.to_path_buf(),
        }),
    }
}

/// The Python to run MuJoCo with when none is named: `ROBOTID_PYTHON`,
/// else `python3`.
pub fn default_python() -> std::path::PathBuf {
    std::env::var_os("ROBOTID_PYTHON")
        .filter(|p| !p.is_empty())
        .map_or_else(|| "python3".into(), Into::into)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_python_that_is_not_there_is_named() {
        let why = rollout(
            Path::new("/no/such/python"),
            Path::new("m.xml"),
            Path::new("k.parquet"),
            0.05,
        )
        .unwrap_err();
        assert!(
            matches!(&why, MujocoError::Start { python, .. } if python == Path::new("/no/such/python")),
            "{why}"
        );
        assert!(why.to_string().starts_with("/no/such/python: "), "{why}");
    }
}
