//! The stacked system of one or more `regressor` tables, checked before any
//! estimator runs: every error names the parameter (column), recording,
//! sample and joint it is about.

use std::collections::BTreeMap;

use arrow::array::{Array, Float64Array, Int64Array, RecordBatch, StringArray};
use arrow::datatypes::Schema;
use nalgebra::{DMatrix, DVector};
use robotid_schemas::{metadata, TableKind};

use super::Weights;
use crate::{Error, Result};

/// Field quantity of the parameter columns.
pub const PARAMETER_COLUMN: &str = "regressor_column";
/// Field quantity of the per-period torque columns.
pub const PERIOD_TORQUE: &str = "period_torque";

/// Indices of the columns of a `regressor` table whose field quantity is `quantity`.
pub fn columns_of(schema: &Schema, quantity: &str) -> Vec<usize> {
    schema
        .fields()
        .iter()
        .enumerate()
        .filter(|(_, f)| f.metadata().get(metadata::QUANTITY).map(String::as_str) == Some(quantity))
        .map(|(i, _)| i)
        .collect()
}

/// Where the rows of A come from: a system's own matrix, or a maker that
/// computes them block by block, so that A is never whole (it is the
/// largest thing a run holds: a 130 s recording's A is larger than the
/// recording). Readers take [`block_rows`] rows at a time, so that sums
/// over the rows do not depend on where A came from.
pub trait RowBlocks: Sync {
    /// Rows `start .. start + k` of A (k × parameters), a fresh matrix;
    /// `start` and `k` are whole samples of every joint, but at the end.
    fn block(&self, start: usize, k: usize) -> DMatrix<f64>;
}

impl RowBlocks for DMatrix<f64> {
    fn block(&self, start: usize, k: usize) -> DMatrix<f64> {
        self.rows(start, k).into_owned()
    }
}

/// Samples per block of rows (times the joints: rows). A 6-joint,
/// 52-parameter block is 1.3 MB.
pub const BLOCK_SAMPLES: usize = 512;

/// Rows per block for a system of `joints` joints: whole samples.
pub fn block_rows(joints: usize) -> usize {
    BLOCK_SAMPLES * joints.max(1)
}

/// A·θ = b with the bookkeeping to name rows.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct System {
    pub names: Vec<String>,
    pub units: Vec<String>,
    /// Full expression of each base parameter (regrouped standard ones).
    pub expressions: Vec<String>,
    pub a: DMatrix<f64>,
    pub b: DVector<f64>,
    /// Torque noise variance per row (NaN when no noise stage ran).
    pub var: DVector<f64>,
    /// Per row: recording index, sample, joint index.
    pub recording: Vec<usize>,
    pub sample: Vec<i64>,
    pub joint: Vec<usize>,
    /// Per row: the sample's time, s (for pictures).
    pub time: Vec<f64>,
    pub recordings: Vec<String>,
    pub joints: Vec<String>,
    /// Per recording: its first row and, when the table carries them, the
    /// torque of each period (rows × periods) — the periods' spread gives
    /// the covariance.
    pub offsets: Vec<usize>,
    pub periods: Vec<Option<DMatrix<f64>>>,
    /// Columns of the parameters taken as known, and their covariance.
    pub known: Option<(DMatrix<f64>, DMatrix<f64>)>,
    /// Independent equations, when fewer than the rows (tables projected by
    /// the Projection Method).
    pub equations: Option<usize>,
    /// Schema metadata of the first table (provenance, regressor config).
    pub metadata: BTreeMap<String, String>,
}

fn f64_col<'a>(label: &str, batch: &'a RecordBatch, name: &str) -> Result<&'a Float64Array> {
    batch
        .column_by_name(name)
        .and_then(|c| c.as_any().downcast_ref::<Float64Array>())
        .ok_or_else(|| Error::mismatch(format!("{label}: column `{name}`"), "a Float64 column", "none"))
}

fn str_col<'a>(label: &str, batch: &'a RecordBatch, name: &str) -> Result<&'a StringArray> {
    batch
        .column_by_name(name)
        .and_then(|c| c.as_any().downcast_ref::<StringArray>())
        .ok_or_else(|| Error::mismatch(format!("{label}: column `{name}`"), "a Utf8 column", "none"))
}

/// The index of `name` in `names`, appended when new.
fn index_of(names: &mut Vec<String>, name: &str) -> usize {
    match names.iter().position(|x| x == name) {
        Some(k) => k,
        None => {
            names.push(name.to_string());
            names.len() - 1
        }
    }
}

/// A regressor table's per-period torques, one column per period (None
/// with fewer than two).
fn period_torques(label: &str, t: &RecordBatch) -> Result<Option<DMatrix<f64>>> {
    let pcols = columns_of(&t.schema(), PERIOD_TORQUE);
    Ok(if pcols.len() >= 2 {
        let mut m = DMatrix::zeros(t.num_rows(), pcols.len());
        for (k, &c) in pcols.iter().enumerate() {
            let col = t.column(c).as_any().downcast_ref::<Float64Array>().ok_or_else(|| {
                Error::mismatch(format!("{label}: period torque column {c}"), "Float64", "another type")
            })?;
            for i in 0..t.num_rows() {
                m[(i, k)] = col.value(i);
            }
        }
        Some(m)
    } else {
        None
    })
}

/// Refused unless `t` is a regressor table with the parameter columns
/// `names`, in order.
fn same_parameters(label: &str, t: &RecordBatch, names: &[String]) -> Result<()> {
    let s = t.schema();
    TableKind::Regressor.validate(&s).map_err(|e| Error::Decode {
        path: label.into(),
        source: Box::new(e),
    })?;
    let theirs: Vec<&String> = columns_of(&s, PARAMETER_COLUMN)
        .into_iter()
        .map(|i| s.field(i).name())
        .collect();
    if theirs.len() != names.len() || theirs.iter().zip(names).any(|(a, b)| *a != b) {
        return Err(Error::mismatch(
            format!("{label}: parameters (the recordings were not made with one regressor configuration)"),
            format!("{} (the first table's)", names.join(", ")),
            theirs.iter().map(|n| n.as_str()).collect::<Vec<_>>().join(", "),
        ));
    }
    Ok(())
}

impl System {
    /// Table `t` (recording `r`, `label`) into rows `at..` of A, b and
    /// their row labels.
    fn stack_table(&mut self, r: usize, at: usize, label: &str, t: &RecordBatch) -> Result<()> {
        let b = f64_col(label, t, "torque")?;
        let var = f64_col(label, t, "torque_var")?;
        let joint = str_col(label, t, "joint")?;
        let time = f64_col(label, t, "time")?;
        let sample = t
            .column_by_name("sample")
            .and_then(|c| c.as_any().downcast_ref::<Int64Array>())
            .ok_or_else(|| Error::mismatch(format!("{label}: column `sample`"), "an Int64 column", "none"))?;
        for (j, name) in self.names.clone().iter().enumerate() {
            let c = f64_col(label, t, name)?;
            for i in 0..t.num_rows() {
                self.a[(at + i, j)] = c.value(i);
            }
        }
        for i in 0..t.num_rows() {
            self.b[at + i] = b.value(i);
            self.var[at + i] = if var.is_null(i) { f64::NAN } else { var.value(i) };
            self.recording.push(r);
            self.sample.push(sample.value(i));
            self.time.push(time.value(i));
            let ji = index_of(&mut self.joints, joint.value(i));
            self.joint.push(ji);
        }
        Ok(())
    }

    /// Stacks `regressor` tables (one per recording) with the same
    /// parameter columns.
    pub fn from_tables(tables: &[(String, RecordBatch)]) -> Result<System> {
        let first = &tables
            .first()
            .ok_or_else(|| Error::missing("a regressor table", "give at least one to estimate from"))?
            .1;
        let schema = first.schema();
        let params: Vec<_> = columns_of(&schema, PARAMETER_COLUMN)
            .into_iter()
            .map(|i| schema.field(i).clone())
            .collect();
        if params.is_empty() {
            return Err(Error::missing("parameter columns", "the regressor table has none"));
        }
        let names: Vec<String> = params.iter().map(|f| f.name().clone()).collect();
        let md = |f: &arrow::datatypes::Field, k: &str| f.metadata().get(k).cloned().unwrap_or_default();
        let units = params.iter().map(|f| md(f, metadata::UNIT)).collect();
        let expressions = params.iter().map(|f| md(f, "expression")).collect();
        let rows: usize = tables.iter().map(|(_, t)| t.num_rows()).sum();
        let p = names.len();
        let mut sys = System {
            names,
            units,
            expressions,
            a: DMatrix::zeros(rows, p),
            b: DVector::zeros(rows),
            var: DVector::zeros(rows),
            recording: Vec::with_capacity(rows),
            sample: Vec::with_capacity(rows),
            joint: Vec::with_capacity(rows),
            time: Vec::with_capacity(rows),
            recordings: Vec::new(),
            joints: Vec::new(),
            offsets: Vec::new(),
            periods: Vec::new(),
            known: None,
            equations: None,
            metadata: schema.metadata().clone().into_iter().collect(),
        };
        // A table that names its joints fixes their order (rows left out
        // at its start would otherwise reorder them).
        if let Some(j) = schema.metadata().get(metadata::JOINTS) {
            sys.joints = j.split(',').map(str::to_string).collect();
        }
        let mut at = 0;
        for (r, (label, t)) in tables.iter().enumerate() {
            same_parameters(label, t, &sys.names)?;
            sys.recordings.push(label.clone());
            sys.offsets.push(at);
            sys.periods.push(period_torques(label, t)?);
            sys.stack_table(r, at, label, t)?;
            at += t.num_rows();
        }
        // Projected tables (closed-loop Projection Method) hold fewer
        // independent equations than rows.
        sys.equations = tables
            .iter()
            .map(|(_, t)| {
                t.schema()
                    .metadata()
                    .get(metadata::PROJECTION_EQUATIONS)
                    .and_then(|v| v.parse::<usize>().ok())
            })
            .sum();
        sys.metadata.remove(metadata::PROJECTION_EQUATIONS);
        Ok(sys)
    }

    /// Several systems stacked (recordings one after another).
    pub fn stack(parts: &[&System]) -> Result<System> {
        let first = parts
            .first()
            .ok_or_else(|| Error::missing("a regressor system", "give at least one to estimate from"))?;
        let p = first.parameters();
        let rows: usize = parts.iter().map(|s| s.rows()).sum();
        let mut out = System {
            a: DMatrix::zeros(rows, p),
            b: DVector::zeros(rows),
            var: DVector::zeros(rows),
            recording: Vec::with_capacity(rows),
            sample: Vec::with_capacity(rows),
            joint: Vec::with_capacity(rows),
            time: Vec::with_capacity(rows),
            recordings: Vec::new(),
            offsets: Vec::new(),
            periods: Vec::new(),
            known: None,
            equations: None,
            ..(*first).clone()
        };
        let mut at = 0;
        for s in parts {
            if s.names != first.names {
                return Err(Error::mismatch(
                    format!("{}: parameters", s.recordings.join(", ")),
                    first.names.join(", "),
                    s.names.join(", "),
                ));
            }
            out.a.view_mut((at, 0), (s.rows(), p)).copy_from(&s.a);
            out.b.rows_mut(at, s.rows()).copy_from(&s.b);
            out.var.rows_mut(at, s.rows()).copy_from(&s.var);
            let r0 = out.recordings.len();
            out.recording.extend(s.recording.iter().map(|r| r + r0));
            out.sample.extend(&s.sample);
            out.time.extend(&s.time);
            for &j in &s.joint {
                let ji = index_of(&mut out.joints, &s.joints[j]);
                out.joint.push(ji);
            }
            out.recordings.extend(s.recordings.iter().cloned());
            out.offsets.extend(s.offsets.iter().map(|o| o + at));
            out.periods.extend(s.periods.iter().cloned());
            out.known = match (out.known.take(), &s.known) {
                (None, Some(k)) if at == 0 => Some(k.clone()),
                (Some((ak, ck)), Some((bk, _))) => {
                    let mut m = DMatrix::zeros(ak.nrows() + bk.nrows(), ak.ncols());
                    m.view_mut((0, 0), (ak.nrows(), ak.ncols())).copy_from(&ak);
                    m.view_mut((ak.nrows(), 0), (bk.nrows(), bk.ncols())).copy_from(bk);
                    Some((m, ck))
                }
                (k, _) => k,
            };
            at += s.rows();
        }
        out.equations = parts.iter().map(|s| s.equations).sum();
        Ok(out)
    }

    /// A system from matrices: rows in groups of `joints.len()` (one
    /// sample: one row per joint), one recording.
    pub fn from_matrices(
        names: Vec<String>,
        units: Vec<String>,
        joints: Vec<String>,
        a: DMatrix<f64>,
        b: DVector<f64>,
        var: DVector<f64>,
    ) -> System {
        let m = b.len();
        let n = joints.len().max(1);
        System {
            expressions: names.clone(),
            names,
            units,
            a,
            b,
            var,
            recording: vec![0; m],
            sample: (0..m).map(|i| (i / n) as i64).collect(),
            joint: (0..m).map(|i| i % n).collect(),
            time: (0..m).map(|i| (i / n) as f64).collect(),
            recordings: vec!["(matrices)".into()],
            joints,
            offsets: vec![0],
            periods: vec![None],
            known: None,
            equations: None,
            metadata: BTreeMap::new(),
        }
    }

    /// Keeps only the rows of joint `joint` (index into `joints`); returns
    /// the rows kept.
    pub fn keep_joint(&mut self, joint: usize) -> Vec<usize> {
        let rows: Vec<usize> = (0..self.rows()).filter(|&i| self.joint[i] == joint).collect();
        self.keep_rows(&rows);
        rows
    }

    /// Keeps only `rows` (ascending), of one recording.
    pub fn keep_rows(&mut self, rows: &[usize]) {
        self.a = self.a.select_rows(rows.iter());
        self.b = self.b.select_rows(rows.iter());
        self.var = self.var.select_rows(rows.iter());
        self.recording = rows.iter().map(|&i| self.recording[i]).collect();
        self.sample = rows.iter().map(|&i| self.sample[i]).collect();
        self.time = rows.iter().map(|&i| self.time[i]).collect();
        self.joint = rows.iter().map(|&i| self.joint[i]).collect();
        self.offsets = vec![0];
    }

    /// Moves known parameters to the right-hand side (b − A_k·θ_k) and drops
    /// their columns: friction from dedicated experiments, compensated
    /// before the inertial estimation (Bona §3.4). Their covariance is kept
    /// and propagated into the estimate's. Returns the names fixed; names
    /// the system does not have are ignored.
    pub fn fix(&mut self, known: &Known) -> Result<Vec<String>> {
        let mut fixed = Vec::new();
        let mut cols = Vec::new();
        let mut idx = Vec::new();
        for (ki, name) in known.names.iter().enumerate() {
            let value = known.values[ki];
            if !value.is_finite() {
                return Err(Error::NotFinite {
                    what: "the known parameters".into(),
                    value,
                    at: format!("`{name}`"),
                });
            }
            let Some(c) = self.names.iter().position(|n| n == name) else {
                continue;
            };
            let col = self.a.column(c).clone_owned();
            self.b -= &col * value;
            for (r, p) in self.periods.iter_mut().enumerate() {
                if let Some(p) = p {
                    let start = self.offsets[r];
                    for row in 0..p.nrows() {
                        let d = col[start + row] * value;
                        for k in 0..p.ncols() {
                            p[(row, k)] -= d;
                        }
                    }
                }
            }
            self.a = std::mem::replace(&mut self.a, DMatrix::zeros(0, 0)).remove_column(c);
            self.names.remove(c);
            self.units.remove(c);
            self.expressions.remove(c);
            fixed.push(name.clone());
            cols.push(col);
            idx.push(ki);
        }
        if !cols.is_empty() {
            let cov = DMatrix::from_fn(idx.len(), idx.len(), |i, j| known.covariance[(idx[i], idx[j])]);
            self.known = Some((DMatrix::from_columns(&cols), cov));
        }
        self.metadata.insert(metadata::KNOWN.into(), fixed.join(","));
        Ok(fixed)
    }

    /// One joint `j` of one recording `r`, its rows the samples of `a` and
    /// `b` taken every `dt` s, its columns `names` (no units, no
    /// expressions, no noise): a system made by hand, as tests and
    /// callers outside the pipeline make one.
    pub fn one_joint(names: Vec<String>, a: DMatrix<f64>, b: DVector<f64>, dt: f64) -> System {
        let (n, p) = (b.len(), a.ncols());
        System {
            names,
            units: vec![String::new(); p],
            expressions: vec![String::new(); p],
            a,
            b,
            var: DVector::from_element(n, f64::NAN),
            recording: vec![0; n],
            sample: (0..n as i64).collect(),
            joint: vec![0; n],
            time: (0..n).map(|i| i as f64 * dt).collect(),
            recordings: vec!["r".into()],
            joints: vec!["j".into()],
            offsets: vec![0],
            periods: vec![None],
            known: None,
            equations: None,
            metadata: Default::default(),
        }
    }

    /// Independent equations: the rows, or fewer for projected tables.
    pub fn equations(&self) -> usize {
        self.equations.unwrap_or(self.rows())
    }

    pub fn rows(&self) -> usize {
        self.b.len()
    }

    pub fn parameters(&self) -> usize {
        self.names.len()
    }

    /// Names a row: recording, sample and joint.
    pub fn row_label(&self, i: usize) -> String {
        format!(
            "{}, sample {}, joint `{}`",
            self.recordings
                .get(self.recording[i])
                .map(String::as_str)
                .unwrap_or("?"),
            self.sample[i],
            self.joints.get(self.joint[i]).map(String::as_str).unwrap_or("?")
        )
    }

    /// What no estimator can work with: non-finite values, too few rows,
    /// a parameter with an all-zero column.
    pub fn validate(&self) -> Result<()> {
        self.validate_values()?;
        let (m, p) = (self.rows(), self.parameters());
        if m <= p {
            return Err(Error::TooFewRows { rows: m, parameters: p });
        }
        let scale = (0..p).map(|j| self.a.column(j).amax()).fold(0.0, f64::max);
        for j in 0..p {
            if self.a.column(j).amax() <= 1e-14 * scale {
                return Err(Error::NotExcited {
                    parameter: self.names[j].clone(),
                    rows: m,
                });
            }
        }
        Ok(())
    }

    /// Every value finite; an error names the parameter, recording, sample and joint.
    pub fn validate_values(&self) -> Result<()> {
        self.validate_block(0, &self.a)?;
        self.validate_torque()
    }

    /// Every value of the rows `start ..` of A in `a` finite.
    pub fn validate_block(&self, start: usize, a: &DMatrix<f64>) -> Result<()> {
        for j in 0..a.ncols() {
            if let Some(i) = (0..a.nrows()).find(|&i| !a[(i, j)].is_finite()) {
                return Err(Error::NotFinite {
                    what: format!("the regressor column of parameter `{}`", self.names[j]),
                    value: a[(i, j)],
                    at: format!("row {} ({})", start + i, self.row_label(start + i)),
                });
            }
        }
        Ok(())
    }

    /// Every torque finite.
    pub fn validate_torque(&self) -> Result<()> {
        let m = self.rows();
        if let Some(i) = (0..m).find(|&i| !self.b[i].is_finite()) {
            return Err(Error::NotFinite {
                what: "the torque".into(),
                value: self.b[i],
                at: format!("row {i} ({})", self.row_label(i)),
            });
        }
        Ok(())
    }
}

/// Parameters taken as known, with their covariance.
#[derive(Debug, Clone)]
pub struct Known {
    pub names: Vec<String>,
    pub values: DVector<f64>,
    pub covariance: DMatrix<f64>,
}

/// Row weights 1/σ² from the noise stage's torque variances, per sample or
/// pooled per (recording, joint).
pub fn row_weights(sys: &System, how: Weights) -> Result<DVector<f64>> {
    let m = sys.rows();
    if let Some(i) = (0..m).find(|&i| !(sys.var[i] > 0.0) || !sys.var[i].is_finite()) {
        return Err(Error::missing(
            "the torque noise variance",
            format!(
                "weighted estimation needs it, but `torque_var` is {} at row {i} ({}): add a `noise` stage before `regressor`",
                sys.var[i],
                sys.row_label(i)
            ),
        ));
    }
    Ok(match how {
        Weights::PerSample => sys.var.map(|v| 1.0 / v),
        Weights::PerJoint => {
            let mut sum: BTreeMap<(usize, usize), (f64, usize)> = BTreeMap::new();
            for i in 0..m {
                let e = sum.entry((sys.recording[i], sys.joint[i])).or_insert((0.0, 0));
                e.0 += sys.var[i];
                e.1 += 1;
            }
            DVector::from_fn(m, |i, _| {
                let (s, n) = sum[&(sys.recording[i], sys.joint[i])];
                n as f64 / s
            })
        }
    })
}
