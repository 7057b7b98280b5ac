//! `identify.sh`: what identify ran, as the commands that do it step by
//! step, for the user to pin and edit.

use std::path::{Path, PathBuf};

/// The script, one command per step, its paths relative to the output
/// folder.
pub struct Script {
    text: String,
    robot: String,
}

impl Script {
    pub fn new(robot: &Path) -> Script {
        Script {
            text: String::from(
                "#!/usr/bin/env bash\n# What `robotid identify` ran, as commands to pin and edit (from this folder).\nset -euo pipefail\ncd \"$(dirname \"$0\")\"\n",
            ),
            robot: robot.display().to_string(),
        }
    }

    fn line(&mut self, line: String) {
        self.text.push_str(&line);
        self.text.push('\n');
    }

    pub fn run(&mut self, name: &str) {
        self.line(format!("robotid run pipelines/{name}.toml --out {name}"));
    }

    pub fn estimate(&mut self, tables: &[PathBuf], physical: Option<&str>) {
        let (flag, covariance, out) = match physical {
            None => ("", "robust", "parameters.parquet"),
            Some(c) => (" --physical", c, "parameters_physical.parquet"),
        };
        self.line(format!(
            "robotid estimate {} --robot {}{flag} --covariance {covariance} -o {out}",
            joined(tables),
            self.robot
        ));
    }

    pub fn validate(&mut self, parameters: &str, tables: &[PathBuf]) {
        if !tables.is_empty() {
            self.line(format!("robotid validate -p {parameters} {}", joined(tables)));
        }
    }

    pub fn export(&mut self, mjcf: Option<&Path>) {
        let mjcf = mjcf.map(|m| format!(" --mjcf {}", m.display())).unwrap_or_default();
        self.line(format!(
            "robotid export --robot {} -p parameters_physical.parquet --format urdf,mjcf,sidecar{mjcf} -o identified",
            self.robot
        ));
    }

    /// The report as identify wrote it: rollouts always (the robot is
    /// known), the physical estimate beside when `physical`, the export in
    /// MuJoCo with `mujoco`, the payload with `payload`, the closed loop
    /// under a controller on raw tables.
    pub fn report(
        &mut self,
        (excitation, validation): (&[PathBuf], &[PathBuf]),
        physical: bool,
        mujoco: bool,
        payload: bool,
        closed_loop: Option<(&Path, &[PathBuf])>,
    ) {
        let validation = if validation.is_empty() {
            String::new()
        } else {
            format!(" --validation {}", joined(validation))
        };
        let physical = match (physical, mujoco) {
            (false, _) => String::new(),
            (true, false) => " --physical parameters_physical.parquet".to_string(),
            (true, true) => " --physical parameters_physical.parquet --mujoco identified.xml".to_string(),
        };
        let payload = if payload { " --payload payload.parquet" } else { "" };
        let closed_loop = closed_loop.map_or(String::new(), |(c, raw)| {
            format!(" --controller {} --closed-loop {}", c.display(), joined(raw))
        });
        self.line(format!(
            "robotid report -p parameters.parquet --excitation {}{validation} --robot {} --rollout{physical}{payload}{closed_loop} -o report.html",
            joined(excitation),
            self.robot
        ));
    }

    pub fn text(&self) -> &str {
        &self.text
    }
}

/// Tables as the script names them.
fn joined(tables: &[PathBuf]) -> String {
    tables
        .iter()
        .map(|t| t.display().to_string())
        .collect::<Vec<_>>()
        .join(" ")
}
