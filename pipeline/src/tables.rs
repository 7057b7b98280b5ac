//! Estimates from the tables runs wrote: regressor tables folded into the
//! estimate's parts and reduced, stacked for validation, a parameters table
//! matched with its robot. What `robotid estimate`, `validate`, `report`,
//! `predict`, `export` and `identify` share.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use robotid_stages::dynamics::{BaseRegressor, Locks, Model, Robot};
use robotid_stages::estimation::{parameters_from_table, Parameters, System};
use robotid_stages::formats::parquet::{read_parquet, write_parquet};
use robotid_stages::stage::estimate::{EstimateConfig, Outcome, Part, Reducer};
use robotid_stages::stage::regressor::RegressorConfig;

use robotid_schemas::metadata;

use crate::error::{Error, Result};

/// The first two of `paths` that hold the same bytes (by the SHA-256 the
/// reader records, streamed; a ROS 2 bag folder by its files), if any:
/// one file given twice under two names. Only files of one size can hold
/// the same bytes: a file whose size no other shares is not opened.
pub fn same_bytes(paths: &[PathBuf]) -> Result<Option<(&Path, &Path)>> {
    // A folder's size is not its content's: None, always hashed.
    let size = |p: &Path| std::fs::metadata(p).ok().filter(|m| m.is_file()).map(|m| m.len());
    let sizes: Vec<Option<u64>> = paths.iter().map(|p| size(p)).collect();
    let alike = |i: usize| sizes[i].is_none() || sizes.iter().enumerate().any(|(k, s)| k != i && *s == sizes[i]);
    let mut seen: Vec<(String, &Path)> = Vec::new();
    for (i, p) in paths.iter().enumerate() {
        if !alike(i) {
            continue;
        }
        let hash = robotid_stages::stage::read::hash_recording(p)?;
        if let Some((_, first)) = seen.iter().find(|(h, _)| *h == hash) {
            return Ok(Some((first, p)));
        }
        seen.push((hash, p));
    }
    Ok(None)
}

/// The map step of a pipeline's `estimate` stage over regressor tables:
/// each folded into its summary. Parts do not depend on the covariance or
/// the physical fit: one read serves an estimate and its physical fit. A
/// table given twice is refused (its rows would count twice). The tables
/// are read `within` a folder and named as given (relative paths stay
/// right when the folder moves; `Path::new("")`: the working folder).
pub fn parts(reducer: &Reducer, within: &Path, regressors: &[PathBuf]) -> Result<Vec<Part>> {
    let read: Vec<PathBuf> = regressors.iter().map(|p| within.join(p)).collect();
    if let Some((first, again)) = same_bytes(&read)? {
        return Err(Error::SameRecording {
            first: first.to_path_buf(),
            again: again.to_path_buf(),
        });
    }
    regressors
        .iter()
        .zip(&read)
        .map(|(name, p)| {
            let sys = System::from_tables(&[(name.display().to_string(), read_parquet(p)?)])?;
            Ok(reducer.part_of(sys)?)
        })
        .collect()
}

/// Metadata to add to an estimate's table, made from its outcome.
pub type Marks<'a> = &'a dyn Fn(&Outcome) -> Vec<(String, String)>;

/// The parts merged and solved; the table written to `out` with `marks`
/// added to its metadata.
pub fn reduce(reducer: &Reducer, parts: &[Part], out: &Path, marks: Option<Marks>) -> Result<Outcome> {
    let outcome = solve(reducer, parts)?;
    write_marked(&outcome, out, marks)?;
    Ok(outcome)
}

/// The parts merged and solved.
pub fn solve(reducer: &Reducer, parts: &[Part]) -> Result<Outcome> {
    Ok(reducer.reduce(parts, &Default::default())?)
}

/// `outcome`'s table written to `out` with `marks` added to its metadata
/// (again, where a table's verdict changed).
pub fn write_marked(outcome: &Outcome, out: &Path, marks: Option<Marks>) -> Result<()> {
    let table = match marks.map(|m| m(outcome)).filter(|m| !m.is_empty()) {
        None => outcome.table.clone(),
        Some(m) => {
            let mut md = outcome.table.schema().metadata().clone();
            md.extend(m);
            let schema = std::sync::Arc::new(outcome.table.schema().as_ref().clone().with_metadata(md));
            outcome
                .table
                .clone()
                .with_schema(schema)
                .map_err(robotid_schemas::SchemaError::from)
                .map_err(robotid_stages::Error::from)?
        }
    };
    write_parquet(out, &table)?;
    Ok(())
}

/// Regressor tables stacked into one system, read `within` a folder and
/// each named by its path as given.
pub fn load_system(within: &Path, paths: &[PathBuf]) -> Result<System> {
    let mut tables = Vec::new();
    for p in paths {
        tables.push((p.display().to_string(), read_parquet(&within.join(p))?));
    }
    Ok(System::from_tables(&tables)?)
}

/// The parameters table at `path`.
pub fn read_parameters(path: &Path) -> Result<Parameters> {
    parameters_from_table(&read_parquet(path)?).map_err(|source| Error::Table {
        path: path.to_path_buf(),
        source,
    })
}

/// The reduce step of `cfg`, its a-priori model the robot file's when
/// given, read (the physical fit's prior; the sizes that flag parameters
/// the data cannot tell).
pub fn reducer(cfg: &EstimateConfig, robot: Option<(&Robot, &Locks)>) -> Result<Reducer> {
    if let Some(p) = cfg.settings_problems().into_iter().next() {
        return Err(Error::Settings {
            key: p.key,
            message: p.message,
        });
    }
    let model = match robot {
        Some((r, locks)) => Some(r.model(locks)?),
        None => None,
    };
    Ok(cfg.reducer(&robotid_stages::stage::Context {
        base_dir: PathBuf::from("."),
        model,
        ..Default::default()
    })?)
}

/// The locks a table's robot was loaded with (`robotid.locked`): its
/// readers load it alike, or a gripper the log did not hold would be back.
pub fn locks_of(md: &BTreeMap<String, String>) -> robotid_stages::Result<Locks> {
    let positions = match md.get(metadata::LOCKED) {
        Some(text) => serde_json::from_str(text)
            .map_err(|e| robotid_stages::Error::setting(metadata::LOCKED, "joints and their positions", e))?,
        None => BTreeMap::new(),
    };
    Ok(Locks { keep: None, positions })
}

/// The locks of the robot a regressor table was made with.
pub fn table_locks(path: &Path) -> Result<Locks> {
    let md = robotid_stages::formats::parquet::read_schema_metadata(path)?;
    locks_of(&md).map_err(|source| Error::Table {
        path: path.to_path_buf(),
        source,
    })
}

/// A parameters table with the robot it was identified for and the base
/// regressor rebuilt from the regressor configuration it carries; refused
/// when the robot does not give the table's base parameters.
pub fn identified(robot: &Path, parameters: &Path) -> Result<(Parameters, Model, std::sync::Arc<BaseRegressor>)> {
    identified_with(&Robot::read(robot)?, parameters)
}

/// [`identified`] with the robot file read.
pub fn identified_with(robot: &Robot, parameters: &Path) -> Result<(Parameters, Model, std::sync::Arc<BaseRegressor>)> {
    let in_table = |source| Error::Table {
        path: parameters.to_path_buf(),
        source,
    };
    let params = read_parameters(parameters)?;
    let cfg = RegressorConfig::of_metadata(&params.metadata).map_err(in_table)?;
    let model = robot
        .model(&locks_of(&params.metadata).map_err(in_table)?)?
        .as_ref()
        .clone();
    let base = cfg.base_regressor(&model)?;
    if base.names() != params.names {
        return Err(Error::NotTheRobot {
            robot: model.name.clone(),
            parameters: parameters.to_path_buf(),
            expected: base.names(),
            found: params.names.clone(),
        });
    }
    Ok((params, model, base))
}
