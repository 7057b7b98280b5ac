pub mod dataset;
pub mod estimate;
pub mod excite;
pub mod export;
pub mod identify;
pub mod lint;
pub mod model;
pub mod predict;
pub mod report;
pub mod run;
pub mod schema;
pub mod simulate;
pub mod sweeps;
pub mod validate;

use std::path::Path;

use anyhow::{bail, Context};
use robotid_stages::dynamics::BaseRegressor;
use robotid_stages::dynamics::{load_robot, Model};
use robotid_stages::estimation::{parameters_from_table, Parameters};
use robotid_stages::formats::parquet::read_parquet;
use robotid_stages::stage::regressor::RegressorConfig;

/// The first two of `paths` that hold the same bytes (by the SHA-256 the
/// reader records, streamed; a ROS 2 bag folder by its files), if any:
/// one file given twice under two names.
pub fn same_bytes(paths: &[std::path::PathBuf]) -> anyhow::Result<Option<(&Path, &Path)>> {
    let mut seen: Vec<(String, &Path)> = Vec::new();
    for p in paths {
        let hash = robotid_stages::stage::read::hash_recording(p)?;
        if let Some((_, first)) = seen.iter().find(|(h, _)| *h == hash) {
            return Ok(Some((first, p)));
        }
        seen.push((hash, p));
    }
    Ok(None)
}

/// A parameters table with the robot it was identified for and the base
/// regressor rebuilt from the regressor configuration it carries; refused
/// when the robot does not give the table's base parameters.
pub fn identified(robot: &Path, parameters: &Path) -> anyhow::Result<(Parameters, Model, BaseRegressor)> {
    let params = parameters_from_table(&read_parquet(parameters)?).with_context(|| parameters.display().to_string())?;
    let cfg = RegressorConfig::of_metadata(&params.metadata).with_context(|| parameters.display().to_string())?;
    let model = load_robot(robot)?;
    let base = cfg.base_regressor(&model)?;
    if base.names() != params.names {
        bail!(
            "robot `{}` with the parameters' regressor configuration has base parameters {:?}, not the table's {:?}: is it the robot they were identified for?",
            model.name,
            base.names(),
            params.names
        );
    }
    Ok((params, model, base))
}
