//! Dataset-level regression: a run's tables against pinned golden tables,
//! column by column. A value passes when |run − golden| ≤ abs + rel·|golden|;
//! the report lists the worst column first, as the ratio of the largest
//! difference to what was allowed.

use std::path::{Path, PathBuf};

use arrow::array::{Array, Float64Array, Int64Array, StringArray};
use robotid_stages::formats::parquet::read_parquet;
use serde::Deserialize;

/// Tolerances: defaults, then the first matching per-column rule.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tolerances {
    #[serde(default = "default_rel")]
    pub rel: f64,
    #[serde(default = "default_abs")]
    pub abs: f64,
    /// Rules by column-name pattern (`*` matches any run of characters).
    #[serde(default)]
    pub column: Vec<ColumnTolerance>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ColumnTolerance {
    pub pattern: String,
    pub rel: f64,
    pub abs: f64,
}

fn default_rel() -> f64 {
    1e-9
}
fn default_abs() -> f64 {
    1e-12
}

impl Default for Tolerances {
    fn default() -> Self {
        Tolerances {
            rel: default_rel(),
            abs: default_abs(),
            column: Vec::new(),
        }
    }
}

fn matches(pattern: &str, name: &str) -> bool {
    let parts: Vec<&str> = pattern.split('*').collect();
    if parts.len() == 1 {
        return pattern == name;
    }
    let mut rest = name;
    for (i, p) in parts.iter().enumerate() {
        if i == 0 {
            let Some(r) = rest.strip_prefix(p) else { return false };
            rest = r;
        } else if i == parts.len() - 1 {
            return rest.ends_with(p);
        } else {
            match rest.find(p) {
                Some(k) => rest = &rest[k + p.len()..],
                None => return false,
            }
        }
    }
    true
}

impl Tolerances {
    pub fn for_column(&self, name: &str) -> (f64, f64) {
        self.column
            .iter()
            .find(|c| matches(&c.pattern, name))
            .map_or((self.rel, self.abs), |c| (c.rel, c.abs))
    }
}

/// One compared column.
#[derive(Debug, Clone)]
pub struct ColumnReport {
    pub file: PathBuf,
    pub column: String,
    /// Largest |run − golden| / allowed; > 1 fails.
    pub ratio: f64,
    pub worst_diff: f64,
    pub worst_row: usize,
}

#[derive(Debug, Clone, Default)]
pub struct Comparison {
    pub columns: Vec<ColumnReport>,
    /// Structural differences: missing files, columns, row counts.
    pub problems: Vec<String>,
}

impl Comparison {
    pub fn passed(&self) -> bool {
        self.problems.is_empty() && self.columns.iter().all(|c| c.ratio <= 1.0)
    }
}

fn parquet_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        if let Ok(entries) = std::fs::read_dir(&d) {
            for e in entries.flatten() {
                let p = e.path();
                if p.is_dir() {
                    stack.push(p);
                } else if p.extension().is_some_and(|x| x == "parquet") {
                    out.push(p);
                }
            }
        }
    }
    out.sort();
    out
}

/// Compares every table under `golden` with the same path under `run`.
pub fn compare(run: &Path, golden: &Path, tol: &Tolerances) -> Comparison {
    let mut report = Comparison::default();
    let files = parquet_files(golden);
    if files.is_empty() {
        report.problems.push(format!("{}: no golden tables", golden.display()));
    }
    for g in files {
        let rel = g.strip_prefix(golden).expect("below golden").to_path_buf();
        let r = run.join(&rel);
        let (gb, rb) = match (read_parquet(&g), read_parquet(&r)) {
            (Ok(a), Ok(b)) => (a, b),
            (Err(e), _) | (_, Err(e)) => {
                report.problems.push(e.to_string());
                continue;
            }
        };
        if gb.num_rows() != rb.num_rows() {
            report.problems.push(format!(
                "{}: {} rows, golden has {}",
                rel.display(),
                rb.num_rows(),
                gb.num_rows()
            ));
            continue;
        }
        let gs = gb.schema();
        for (i, field) in gs.fields().iter().enumerate() {
            let name = field.name();
            let Ok(j) = rb.schema().index_of(name) else {
                report
                    .problems
                    .push(format!("{}: column `{name}` is missing", rel.display()));
                continue;
            };
            let (ga, ra) = (gb.column(i), rb.column(j));
            let as_f64 = |a: &dyn Array| -> Option<Vec<f64>> {
                if let Some(f) = a.as_any().downcast_ref::<Float64Array>() {
                    Some(f.iter().map(|v| v.unwrap_or(f64::NAN)).collect())
                } else {
                    a.as_any()
                        .downcast_ref::<Int64Array>()
                        .map(|i| i.iter().map(|v| v.map_or(f64::NAN, |x| x as f64)).collect())
                }
            };
            match (as_f64(ga.as_ref()), as_f64(ra.as_ref())) {
                (Some(g), Some(r)) => {
                    let (rel_tol, abs_tol) = tol.for_column(name);
                    let mut worst = ColumnReport {
                        file: rel.clone(),
                        column: name.clone(),
                        ratio: 0.0,
                        worst_diff: 0.0,
                        worst_row: 0,
                    };
                    for (k, (a, b)) in r.iter().zip(&g).enumerate() {
                        let both_nan = a.is_nan() && b.is_nan();
                        let diff = if both_nan { 0.0 } else { (a - b).abs() };
                        let allowed = abs_tol + rel_tol * b.abs();
                        let ratio = if diff.is_nan() { f64::INFINITY } else { diff / allowed };
                        if ratio > worst.ratio {
                            worst.ratio = ratio;
                            worst.worst_diff = diff;
                            worst.worst_row = k;
                        }
                    }
                    report.columns.push(worst);
                }
                _ => {
                    let same = match (
                        ga.as_any().downcast_ref::<StringArray>(),
                        ra.as_any().downcast_ref::<StringArray>(),
                    ) {
                        (Some(a), Some(b)) => a == b,
                        _ => false,
                    };
                    if !same {
                        report
                            .problems
                            .push(format!("{}: column `{name}` differs", rel.display()));
                    }
                }
            }
        }
    }
    report.columns.sort_by(|a, b| b.ratio.total_cmp(&a.ratio));
    report
}

#[cfg(test)]
mod tests {
    #[test]
    fn patterns() {
        assert!(super::matches("qdd_*", "qdd_j1"));
        assert!(super::matches("*_j1", "qdd_j1"));
        assert!(super::matches("q*_j*", "qdd_j1"));
        assert!(!super::matches("qd_*", "qdd_j1"));
        assert!(super::matches("time", "time"));
    }
}
