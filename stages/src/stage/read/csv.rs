//! CSV and Parquet logs share the column mapping; CSV is streamed line by
//! line, keeping only the mapped columns.

use robotid_schemas::metadata;
use std::collections::BTreeMap;
use std::io::BufRead;
use std::path::Path;

use super::{column_name, Columns, ReadConfig};
use crate::{Error, Result};

/// Column names the mapping asks for, resolved against a header.
pub(crate) struct Mapping {
    pub time: String,
    pub position: Vec<String>,
    pub effort: Vec<String>,
    pub reference: Option<Vec<String>>,
    /// Unit implied by a defaulted effort column (`torque_…` → N·m).
    pub effort_unit: Option<&'static str>,
}

pub(crate) fn resolve(header: &[String], cfg: &ReadConfig, joints: &[String], source: &str) -> Result<Mapping> {
    let has = |n: &str| header.iter().any(|h| h == n);
    let names = |template: &str| -> Vec<String> {
        joints
            .iter()
            .enumerate()
            .map(|(j, name)| column_name(template, j, name))
            .collect()
    };
    let missing = |col: &str| Error::Data {
        source_name: source.to_string(),
        channel: col.to_string(),
        sample: None,
        msg: format!("missing column; the log has: {}", header.join(", ")),
    };
    let require = |cols: Vec<String>| -> Result<Vec<String>> {
        match cols.iter().find(|c| !has(c)) {
            Some(c) => Err(missing(c)),
            None => Ok(cols),
        }
    };
    let column_of = |ch: &Option<super::Channel>, kind: &str| -> Result<Option<String>> {
        match ch {
            Some(c) => match (&c.column, &c.topic) {
                (Some(col), _) => Ok(Some(col.clone())),
                (None, Some(_)) => Err(Error::Data {
                    source_name: source.to_string(),
                    channel: kind.to_string(),
                    sample: None,
                    msg: "`topic` applies to MCAP logs; give `column` for CSV and Parquet".into(),
                }),
                (None, None) => Ok(None),
            },
            None => Ok(None),
        }
    };
    let time = column_of(&cfg.time, "time")?.unwrap_or_else(|| "time".into());
    if !has(&time) {
        return Err(missing(&time));
    }
    let position = require(names(
        &column_of(&cfg.position, "position")?.unwrap_or_else(|| "q_{joint}".into()),
    ))?;
    let (effort, effort_unit) = match column_of(&cfg.effort, "effort")? {
        Some(t) => (require(names(&t))?, None),
        None => {
            // Currents if the log has any, else torques; the error names
            // the first missing column of the set in use.
            let current = names("current_{joint}");
            if current.iter().any(|c| has(c)) {
                (require(current)?, Some("A"))
            } else {
                (require(names("torque_{joint}"))?, Some("N*m"))
            }
        }
    };
    let reference = match column_of(&cfg.reference, "reference")? {
        Some(t) => Some(require(names(&t))?),
        None => {
            let r = names("ref_{joint}");
            r.iter().all(|c| has(c)).then_some(r)
        }
    };
    Ok(Mapping {
        time,
        position,
        effort,
        reference,
        effort_unit: if cfg.effort.is_some() { None } else { effort_unit },
    })
}

pub(crate) fn into_columns(
    m: Mapping,
    mut get: impl FnMut(&str) -> Vec<f64>,
    mut metadata: BTreeMap<String, String>,
) -> Columns {
    if let Some(u) = m.effort_unit {
        metadata.insert(metadata::READ_EFFORT_UNIT.into(), u.into());
    }
    Columns {
        time: get(&m.time),
        position: m.position.iter().map(|c| get(c)).collect(),
        effort: m.effort.iter().map(|c| get(c)).collect(),
        reference: m.reference.as_ref().map(|r| r.iter().map(|c| get(c)).collect()),
        names: [
            m.position.clone(),
            m.effort.clone(),
            m.reference.clone().unwrap_or_default(),
        ],
        metadata,
    }
}

pub(crate) fn read_csv(path: &Path, cfg: &ReadConfig, joints: &[String]) -> Result<Columns> {
    let source = path.display().to_string();
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut reader = std::io::BufReader::new(file);
    let mut line = String::new();
    let mut line_no = 0usize;
    // The next non-empty, non-comment line into `line`; false at the end.
    let mut next = |line: &mut String, line_no: &mut usize| -> Result<bool> {
        loop {
            line.clear();
            if reader.read_line(line).map_err(|e| Error::io(path, e))? == 0 {
                return Ok(false);
            }
            *line_no += 1;
            let t = line.trim_end_matches(['\n', '\r']);
            if !t.trim().is_empty() && !t.starts_with('#') {
                let len = t.len();
                line.truncate(len);
                return Ok(true);
            }
        }
    };
    if !next(&mut line, &mut line_no)? {
        return Err(Error::Format {
            path: path.to_path_buf(),
            msg: "empty file".into(),
        });
    }
    let header: Vec<String> = line
        .split(',')
        .map(|s| s.trim().trim_matches('"').to_string())
        .collect();
    let mapping = resolve(&header, cfg, joints, &source)?;
    let wanted: Vec<String> = std::iter::once(mapping.time.clone())
        .chain(mapping.position.iter().cloned())
        .chain(mapping.effort.iter().cloned())
        .chain(mapping.reference.iter().flatten().cloned())
        .collect();
    // For each header column, the slots (wanted entries) it feeds.
    let mut slots: Vec<Vec<usize>> = vec![Vec::new(); header.len()];
    for (k, w) in wanted.iter().enumerate() {
        slots[header.iter().position(|h| h == w).expect("resolved")].push(k);
    }
    let mut data: Vec<Vec<f64>> = vec![Vec::new(); wanted.len()];
    let mut sample = 0usize;
    while next(&mut line, &mut line_no)? {
        let mut fields = 0usize;
        for (i, text) in line.split(',').enumerate() {
            fields += 1;
            if i >= header.len() || slots[i].is_empty() {
                continue;
            }
            let text = text.trim();
            let v: f64 = text.parse().map_err(|_| Error::Data {
                source_name: source.clone(),
                channel: header[i].clone(),
                sample: Some(sample),
                msg: format!("`{text}` is not a number (line {line_no})"),
            })?;
            for &k in &slots[i] {
                data[k].push(v);
            }
        }
        if fields != header.len() {
            return Err(Error::Data {
                source_name: source.clone(),
                channel: "(row)".into(),
                sample: Some(sample),
                msg: format!(
                    "line {line_no} has {fields} fields, the header has {} (truncated or corrupt file?)",
                    header.len()
                ),
            });
        }
        sample += 1;
    }
    let by_name: BTreeMap<String, usize> = wanted.iter().enumerate().map(|(k, w)| (w.clone(), k)).collect();
    Ok(into_columns(
        mapping,
        |name| data[by_name[name]].clone(),
        BTreeMap::new(),
    ))
}
