//! Run trees as a dataset: every folder holding a `run.json` (what `robotid
//! run --out` writes) below the given roots, with the hive-style `key=value`
//! folder names on its path as columns.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::error::{io, Error, Result};
use serde::Deserialize;

/// `run.json`, the run's manifest (the fields the dataset layer reads).
#[derive(Debug, Clone, Deserialize)]
pub struct Manifest {
    pub robotid_version: String,
    pub config_sha256: String,
    #[serde(default)]
    pub robot_sha256: Option<String>,
    #[serde(default)]
    pub parameters: Option<String>,
    pub recordings: Vec<RecordingEntry>,
}

#[derive(Debug, Clone, Deserialize)]
pub struct RecordingEntry {
    pub name: String,
    pub source_sha256: String,
    pub samples: u64,
    /// Table kind → path relative to the run's folder.
    pub tables: BTreeMap<String, String>,
}

/// One run tree found below a root.
#[derive(Debug, Clone)]
pub struct Run {
    pub dir: PathBuf,
    /// The run's folder relative to its root (`.` when the root is the run).
    pub name: String,
    /// `key=value` folder names between the root and the run, in path order.
    pub hive: Vec<(String, String)>,
    pub manifest: Manifest,
}

/// Every run below each root, sorted by root and then path; a root that
/// holds no run is an error (a typo should not give an empty dataset).
pub fn discover(roots: &[PathBuf]) -> Result<Vec<Run>> {
    let mut runs = Vec::new();
    for root in roots {
        if !root.is_dir() {
            return Err(Error::Invalid {
                path: root.clone(),
                msg: "not a folder".into(),
            });
        }
        let mut dirs = Vec::new();
        find_runs(root, &mut dirs)?;
        if dirs.is_empty() {
            return Err(Error::Invalid {
                path: root.clone(),
                msg: "no run below it (no run.json; write one with `robotid run --out`)".into(),
            });
        }
        dirs.sort();
        for dir in dirs {
            let rel = dir.strip_prefix(root).expect("found below the root");
            let name = if rel.as_os_str().is_empty() {
                ".".to_string()
            } else {
                rel.to_string_lossy().into_owned()
            };
            let hive = rel
                .components()
                .filter_map(|c| {
                    let s = c.as_os_str().to_str()?;
                    let (k, v) = s.split_once('=')?;
                    (!k.is_empty()).then(|| (k.to_string(), v.to_string()))
                })
                .collect();
            let path = dir.join("run.json");
            let text = std::fs::read_to_string(&path).map_err(io(&path))?;
            let manifest: Manifest = serde_json::from_str(&text).map_err(|source| Error::Json {
                path: path.clone(),
                what: "not a robotid run manifest",
                source,
            })?;
            runs.push(Run {
                dir,
                name,
                hive,
                manifest,
            });
        }
    }
    Ok(runs)
}

/// Folders with a run.json; a run's own subfolders are not searched further.
fn find_runs(dir: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
    if dir.join("run.json").is_file() {
        out.push(dir.to_path_buf());
        return Ok(());
    }
    let entries = std::fs::read_dir(dir).map_err(io(dir))?;
    for e in entries {
        let e = e.map_err(io(dir))?;
        // Hidden folders are a run's staging area or tool state.
        if e.file_type().map_err(io(&e.path()))?.is_dir() && !e.file_name().to_string_lossy().starts_with('.') {
            find_runs(&e.path(), out)?;
        }
    }
    Ok(())
}

/// Every `.parquet` file below `dir`, as sorted paths relative to it.
pub fn parquet_files(dir: &Path) -> Result<Vec<PathBuf>> {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
        for e in std::fs::read_dir(dir).map_err(io(dir))? {
            let p = e.map_err(io(dir))?.path();
            if p.file_name().is_some_and(|n| n.to_string_lossy().starts_with('.')) {
                continue;
            } else if p.is_dir() {
                walk(root, &p, out)?;
            } else if p.extension().is_some_and(|x| x == "parquet") {
                out.push(p.strip_prefix(root).expect("below the root").to_path_buf());
            }
        }
        Ok(())
    }
    if !dir.is_dir() {
        return Err(Error::Invalid {
            path: dir.to_path_buf(),
            msg: "not a folder".into(),
        });
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out)?;
    out.sort();
    Ok(out)
}
