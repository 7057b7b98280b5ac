//! Writes a simulation's files into a folder: the recording in the chosen
//! formats, `truth.parquet` and `truth.toml`. Each file is written
//! atomically.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use robotid_schemas::metadata;

use super::config::OutputFormat;
use super::run::Simulation;
use crate::dynamics::Model;
use crate::formats::{
    csv::write_raw_csv, mcap::write_recording_mcap, parquet::write_parquet, sha256_hex, write_atomic,
};
use crate::{Error, Result};

/// Provenance of a simulated recording: the simulation file's name and
/// hash, and the robot file's.
pub fn provenance(config_path: &Path, config_text: &str, robot_path: &Path) -> Result<BTreeMap<String, String>> {
    let robot_bytes = std::fs::read(robot_path).map_err(|e| Error::io(robot_path, e))?;
    let name = |p: &Path| {
        p.file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default()
    };
    let hash = sha256_hex(config_text.as_bytes());
    Ok(BTreeMap::from([
        (metadata::SOURCE_FILE.to_string(), name(config_path)),
        (metadata::SOURCE_SHA256.to_string(), hash.clone()),
        (metadata::CONFIG_SHA256.to_string(), hash),
        (metadata::ROBOT_FILE.to_string(), name(robot_path)),
        (metadata::ROBOT_SHA256.to_string(), sha256_hex(&robot_bytes)),
    ]))
}

#[derive(Debug, Clone, Default)]
pub struct WrittenFiles {
    pub files: Vec<PathBuf>,
}

pub fn write_simulation(
    dir: &Path,
    name: &str,
    formats: &[OutputFormat],
    sim: &Simulation,
    model: &Model,
) -> Result<WrittenFiles> {
    if let Some(why) = super::config::plain_name_problem(name) {
        return Err(Error::Config {
            path: dir.join(name),
            msg: format!("the recording name `{name}` {why}"),
        });
    }
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let mut out = WrittenFiles::default();
    for f in formats {
        let path = match f {
            OutputFormat::Mcap => {
                let p = dir.join(format!("{name}.mcap"));
                let k: Vec<f64> = model.drives.iter().map(|d| d.joint_torque_per_amp()).collect();
                write_recording_mcap(&p, &sim.raw, &k)?;
                p
            }
            OutputFormat::Csv => {
                let p = dir.join(format!("{name}.csv"));
                write_raw_csv(&p, &sim.raw)?;
                p
            }
            OutputFormat::Parquet => {
                let p = dir.join(format!("{name}.parquet"));
                write_parquet(&p, &sim.raw.to_record_batch()?)?;
                p
            }
        };
        out.files.push(path);
    }
    let truth_pq = dir.join(format!("{name}.truth.parquet"));
    write_parquet(&truth_pq, &sim.truth.to_record_batch(&sim.raw.metadata)?)?;
    out.files.push(truth_pq);
    let truth_toml = dir.join(format!("{name}.truth.toml"));
    let text = toml::to_string(&sim.ground_truth).map_err(|e| Error::Decode {
        path: "truth.toml".into(),
        source: Box::new(e),
    })?;
    write_atomic(&truth_toml, |w| {
        use std::io::Write;
        w.write_all(b"# Ground truth of a robotid simulation: every value that made the recording.\n")
            .and_then(|_| w.write_all(text.as_bytes()))
            .map_err(|e| Error::io(&truth_toml, e))
    })?;
    out.files.push(truth_toml);
    Ok(out)
}
