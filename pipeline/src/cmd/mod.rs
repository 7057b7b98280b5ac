pub mod check;
pub mod estimate;
pub mod excite;
pub mod export;
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
use robotid_stages::dynamics::{load_robot, Model};
use robotid_stages::estimate::{parameters_from_table, Parameters};
use robotid_stages::formats::parquet::read_parquet;
use robotid_stages::regressor::{BaseRegressor, RegressorConfig, CONFIG_KEY};

/// A parameters table with the robot it was identified for and the base
/// regressor rebuilt from the regressor configuration it carries; refused
/// when the robot does not give the table's base parameters.
pub fn identified(robot: &Path, parameters: &Path) -> anyhow::Result<(Parameters, Model, BaseRegressor)> {
    let params = parameters_from_table(&read_parquet(parameters).map_err(anyhow::Error::msg)?)
        .map_err(|e| anyhow::anyhow!("{}: {e}", parameters.display()))?;
    let text = params.metadata.get(CONFIG_KEY).with_context(|| {
        format!(
            "{}: no regressor configuration in its metadata (`{CONFIG_KEY}`)",
            parameters.display()
        )
    })?;
    let cfg: RegressorConfig =
        serde_json::from_str(text).with_context(|| format!("{}: `{CONFIG_KEY}`", parameters.display()))?;
    let model = load_robot(robot).map_err(anyhow::Error::msg)?;
    let base = BaseRegressor::new(&model, &cfg).map_err(anyhow::Error::msg)?;
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
