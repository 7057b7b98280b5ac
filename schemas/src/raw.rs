use std::collections::BTreeMap;

use arrow::array::RecordBatch;

use crate::columns::{f64_column, i64_column, per_joint_columns, BatchBuilder};
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
        let mut b = BatchBuilder::new()
            .f64("time", &self.time)
            .per_joint("q", &self.joints, &self.q)
            .per_joint(self.effort_kind.prefix(), &self.joints, &self.effort);
        if let Some(r) = &self.reference {
            b = b.per_joint("ref", &self.joints, r);
        }
        if let Some(c) = &self.counts {
            b = b.per_joint_i64("counts", &self.joints, c);
        }
        b.build(TableKind::RawSamples, &self.joints, &self.metadata)
    }

    /// Reads a `raw_samples` record batch, checking it against the kind.
    pub fn from_record_batch(batch: &RecordBatch) -> Result<RawSamples, SchemaError> {
        let schema = batch.schema();
        let joints = TableKind::RawSamples.validate(&schema)?;
        let has = |prefix: &str| schema.index_of(&format!("{prefix}_{}", joints[0])).is_ok();
        let (effort_kind, effort) = if has("current") {
            (TorqueChannel::Current, per_joint_columns(batch, "current", &joints)?)
        } else {
            (TorqueChannel::Torque, per_joint_columns(batch, "torque", &joints)?)
        };
        let reference = if has("ref") {
            Some(per_joint_columns(batch, "ref", &joints)?)
        } else {
            None
        };
        let counts = if has("counts") {
            Some(
                joints
                    .iter()
                    .map(|j| i64_column(batch, &format!("counts_{j}")))
                    .collect::<Result<Vec<_>, _>>()?,
            )
        } else {
            None
        };
        let raw = RawSamples {
            time: f64_column(batch, "time")?,
            q: per_joint_columns(batch, "q", &joints)?,
            joints,
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
