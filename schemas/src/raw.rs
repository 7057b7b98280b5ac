use std::collections::BTreeMap;
use std::sync::Arc;

use arrow::array::{Array, ArrayRef, Float64Array, Int64Array, RecordBatch};

use crate::{SchemaError, TableKind};

/// Which effort channel a recording carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TorqueChannel {
    /// Motor current in A, as sampled after the analog anti-alias filter.
    Current,
    /// Joint torque in N·m.
    Torque,
}

impl TorqueChannel {
    pub fn prefix(self) -> &'static str {
        match self {
            TorqueChannel::Current => "current",
            TorqueChannel::Torque => "torque",
        }
    }
}

/// A `raw_samples` table in columnar form: one `Vec` per channel, indexed
/// `[joint][sample]`. Units are SI as in the table kind (s, rad, A or N·m).
#[derive(Debug, Clone, PartialEq)]
pub struct RawSamples {
    pub joints: Vec<String>,
    pub time: Vec<f64>,
    pub q: Vec<Vec<f64>>,
    pub effort_kind: TorqueChannel,
    pub effort: Vec<Vec<f64>>,
    pub reference: Option<Vec<Vec<f64>>>,
    pub counts: Option<Vec<Vec<i64>>>,
    /// Schema-level provenance (sample rate, source hash, ...).
    pub metadata: BTreeMap<String, String>,
}

impl RawSamples {
    pub fn len(&self) -> usize {
        self.time.len()
    }

    pub fn is_empty(&self) -> bool {
        self.time.is_empty()
    }

    /// Checks that every channel has one column per joint and one value per sample.
    pub fn check_shape(&self) -> Result<(), SchemaError> {
        let n = self.time.len();
        let mut groups: Vec<(&str, Vec<usize>)> = vec![
            ("q", self.q.iter().map(Vec::len).collect()),
            (self.effort_kind.prefix(), self.effort.iter().map(Vec::len).collect()),
        ];
        if let Some(r) = &self.reference {
            groups.push(("ref", r.iter().map(Vec::len).collect()));
        }
        if let Some(c) = &self.counts {
            groups.push(("counts", c.iter().map(Vec::len).collect()));
        }
        for (prefix, lens) in groups {
            if lens.len() != self.joints.len() {
                return Err(SchemaError::MissingColumn {
                    column: format!("{prefix}_*"),
                    why: format!("{} joints but {} `{prefix}` columns", self.joints.len(), lens.len()),
                });
            }
            for (j, len) in lens.iter().enumerate() {
                if *len != n {
                    return Err(SchemaError::WrongLength {
                        column: format!("{prefix}_{}", self.joints[j]),
                        expected: n,
                        found: *len,
                    });
                }
            }
        }
        Ok(())
    }

    /// The Arrow record batch of this table, schema and metadata included.
    pub fn to_record_batch(&self) -> Result<RecordBatch, SchemaError> {
        self.check_shape()?;
        let mut with = vec![self.effort_kind.prefix()];
        if self.reference.is_some() {
            with.push("ref");
        }
        if self.counts.is_some() {
            with.push("counts");
        }
        let schema = TableKind::RawSamples.schema(&self.joints, &with, &self.metadata);
        let f64s = |cols: &Vec<Vec<f64>>| -> Vec<ArrayRef> {
            cols.iter()
                .map(|c| Arc::new(Float64Array::from(c.clone())) as ArrayRef)
                .collect()
        };
        let mut columns: Vec<ArrayRef> = vec![Arc::new(Float64Array::from(self.time.clone()))];
        columns.extend(f64s(&self.q));
        // Column order follows the kind's spec order: current before torque.
        columns.extend(f64s(&self.effort));
        if let Some(r) = &self.reference {
            columns.extend(f64s(r));
        }
        if let Some(c) = &self.counts {
            columns.extend(c.iter().map(|c| Arc::new(Int64Array::from(c.clone())) as ArrayRef));
        }
        Ok(RecordBatch::try_new(Arc::new(schema), columns)?)
    }

    /// Reads a `raw_samples` record batch, checking it against the kind.
    pub fn from_record_batch(batch: &RecordBatch) -> Result<RawSamples, SchemaError> {
        let schema = batch.schema();
        let joints = TableKind::RawSamples.check(&schema)?;
        let f64col = |name: &str| -> Result<Option<Vec<f64>>, SchemaError> {
            match schema.index_of(name) {
                Ok(i) => {
                    let a = batch.column(i).as_any().downcast_ref::<Float64Array>().ok_or_else(|| {
                        SchemaError::WrongType {
                            column: name.into(),
                            expected: "Float64".into(),
                            found: batch.column(i).data_type().to_string(),
                        }
                    })?;
                    if a.null_count() > 0 {
                        return Err(SchemaError::WrongType {
                            column: name.into(),
                            expected: "Float64 without nulls".into(),
                            found: format!("{} nulls", a.null_count()),
                        });
                    }
                    Ok(Some(a.values().to_vec()))
                }
                Err(_) => Ok(None),
            }
        };
        let per_joint = |prefix: &str| -> Result<Option<Vec<Vec<f64>>>, SchemaError> {
            let cols: Vec<Option<Vec<f64>>> = joints
                .iter()
                .map(|j| f64col(&format!("{prefix}_{j}")))
                .collect::<Result<_, _>>()?;
            Ok(cols.into_iter().collect())
        };
        let time = f64col("time")?.expect("checked by the kind");
        let q = per_joint("q")?.expect("checked by the kind");
        let (effort_kind, effort) = match per_joint("current")? {
            Some(c) => (crate::TorqueChannel::Current, c),
            None => (
                crate::TorqueChannel::Torque,
                per_joint("torque")?.ok_or_else(|| SchemaError::MissingColumn {
                    column: format!("torque_{}", joints[0]),
                    why: "no current and no torque columns".into(),
                })?,
            ),
        };
        let reference = per_joint("ref")?;
        let counts =
            if schema.index_of(&format!("counts_{}", joints[0])).is_ok() {
                let mut all = Vec::new();
                for j in &joints {
                    let name = format!("counts_{j}");
                    let i = schema.index_of(&name).map_err(|_| SchemaError::MissingColumn {
                        column: name.clone(),
                        why: "counts are given for some joints only".into(),
                    })?;
                    let a = batch.column(i).as_any().downcast_ref::<Int64Array>().ok_or_else(|| {
                        SchemaError::WrongType {
                            column: name.clone(),
                            expected: "Int64".into(),
                            found: batch.column(i).data_type().to_string(),
                        }
                    })?;
                    all.push(a.values().to_vec());
                }
                Some(all)
            } else {
                None
            };
        let raw = RawSamples {
            joints,
            time,
            q,
            effort_kind,
            effort,
            reference,
            counts,
            metadata: schema.metadata().clone().into(),
        };
        raw.check_shape()?;
        Ok(raw)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn record_batch_round_trip() {
        let raw = RawSamples {
            joints: vec!["a".into(), "b".into()],
            time: vec![0.0, 0.1, 0.2],
            q: vec![vec![1.0, 2.0, 3.0], vec![4.0, 5.0, 6.0]],
            effort_kind: TorqueChannel::Current,
            effort: vec![vec![0.1, 0.2, 0.3], vec![0.4, 0.5, 0.6]],
            reference: Some(vec![vec![1.0; 3], vec![2.0; 3]]),
            counts: Some(vec![vec![1, 2, 3], vec![4, 5, 6]]),
            metadata: BTreeMap::from([("robotid.sample_rate_hz".to_string(), "10".to_string())]),
        };
        let batch = raw.to_record_batch().unwrap();
        assert_eq!(batch.num_columns(), 1 + 2 * 4);
        let back = RawSamples::from_record_batch(&batch).unwrap();
        assert_eq!(back.q, raw.q);
        assert_eq!(back.counts, raw.counts);
        assert_eq!(back.metadata["robotid.sample_rate_hz"], "10");
    }

    #[test]
    fn ragged_columns_are_named() {
        let raw = RawSamples {
            joints: vec!["a".into()],
            time: vec![0.0, 0.1],
            q: vec![vec![1.0]],
            effort_kind: TorqueChannel::Torque,
            effort: vec![vec![0.0, 0.0]],
            reference: None,
            counts: None,
            metadata: BTreeMap::new(),
        };
        assert_eq!(
            raw.to_record_batch().unwrap_err(),
            SchemaError::WrongLength {
                column: "q_a".into(),
                expected: 2,
                found: 1
            }
        );
    }
}
