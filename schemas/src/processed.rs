//! The tables the preprocessing stages emit, in columnar form
//! (`[joint][sample]`), with their Arrow conversions.

use std::collections::BTreeMap;

use arrow::array::RecordBatch;

use crate::columns::{f64_column, per_joint_columns, BatchBuilder};
use crate::{SchemaError, TableKind};

/// One period averaged over the recorded periods (`period_mean`).
#[derive(Debug, Clone, PartialEq)]
pub struct PeriodMean {
    pub joints: Vec<String>,
    /// Time within the period, s, starting at 0.
    pub time: Vec<f64>,
    pub q: Vec<Vec<f64>>,
    /// Standard deviation across periods (NaN with a single period).
    pub q_spread: Vec<Vec<f64>>,
    pub torque: Vec<Vec<f64>>,
    pub torque_spread: Vec<Vec<f64>>,
    pub metadata: BTreeMap<String, String>,
}

impl PeriodMean {
    pub fn to_record_batch(&self) -> Result<RecordBatch, SchemaError> {
        BatchBuilder::new()
            .i64("sample", (0..self.time.len() as i64).collect())
            .f64("time", &self.time)
            .per_joint("q", &self.joints, &self.q)
            .per_joint("q_spread", &self.joints, &self.q_spread)
            .per_joint("torque", &self.joints, &self.torque)
            .per_joint("torque_spread", &self.joints, &self.torque_spread)
            .build(TableKind::PeriodMean, &self.joints, &self.metadata)
    }

    pub fn from_record_batch(batch: &RecordBatch) -> Result<PeriodMean, SchemaError> {
        let joints = TableKind::PeriodMean.validate(&batch.schema())?;
        Ok(PeriodMean {
            time: f64_column(batch, "time")?,
            q: per_joint_columns(batch, "q", &joints)?,
            q_spread: per_joint_columns(batch, "q_spread", &joints)?,
            torque: per_joint_columns(batch, "torque", &joints)?,
            torque_spread: per_joint_columns(batch, "torque_spread", &joints)?,
            metadata: batch.schema().metadata().clone().into(),
            joints,
        })
    }
}

/// Noise variance of the averaged signals, per sample (`noise`).
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseTable {
    pub joints: Vec<String>,
    pub var_q: Vec<Vec<f64>>,
    pub var_torque: Vec<Vec<f64>>,
    pub metadata: BTreeMap<String, String>,
}

impl NoiseTable {
    pub fn to_record_batch(&self) -> Result<RecordBatch, SchemaError> {
        let n = self.var_q.first().map_or(0, Vec::len);
        BatchBuilder::new()
            .i64("sample", (0..n as i64).collect())
            .per_joint("var_q", &self.joints, &self.var_q)
            .per_joint("var_torque", &self.joints, &self.var_torque)
            .build(TableKind::Noise, &self.joints, &self.metadata)
    }

    pub fn from_record_batch(batch: &RecordBatch) -> Result<NoiseTable, SchemaError> {
        let joints = TableKind::Noise.validate(&batch.schema())?;
        Ok(NoiseTable {
            var_q: per_joint_columns(batch, "var_q", &joints)?,
            var_torque: per_joint_columns(batch, "var_torque", &joints)?,
            metadata: batch.schema().metadata().clone().into(),
            joints,
        })
    }
}

/// Positions, velocities, accelerations and torques (`kinematics`).
#[derive(Debug, Clone, PartialEq)]
pub struct Kinematics {
    pub joints: Vec<String>,
    pub time: Vec<f64>,
    pub q: Vec<Vec<f64>>,
    pub qd: Vec<Vec<f64>>,
    pub qdd: Vec<Vec<f64>>,
    pub torque: Option<Vec<Vec<f64>>>,
    pub metadata: BTreeMap<String, String>,
}

impl Kinematics {
    pub fn to_record_batch(&self) -> Result<RecordBatch, SchemaError> {
        let mut b = BatchBuilder::new()
            .f64("time", &self.time)
            .per_joint("q", &self.joints, &self.q)
            .per_joint("qd", &self.joints, &self.qd)
            .per_joint("qdd", &self.joints, &self.qdd);
        if let Some(t) = &self.torque {
            b = b.per_joint("torque", &self.joints, t);
        }
        b.build(TableKind::Kinematics, &self.joints, &self.metadata)
    }

    pub fn from_record_batch(batch: &RecordBatch) -> Result<Kinematics, SchemaError> {
        let schema = batch.schema();
        let joints = TableKind::Kinematics.validate(&schema)?;
        let has_torque = schema.index_of(&format!("torque_{}", joints[0])).is_ok();
        Ok(Kinematics {
            time: f64_column(batch, "time")?,
            q: per_joint_columns(batch, "q", &joints)?,
            qd: per_joint_columns(batch, "qd", &joints)?,
            qdd: per_joint_columns(batch, "qdd", &joints)?,
            torque: if has_torque {
                Some(per_joint_columns(batch, "torque", &joints)?)
            } else {
                None
            },
            metadata: schema.metadata().clone().into(),
            joints,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables_round_trip() {
        let joints = vec!["a".to_string(), "b".to_string()];
        let v = vec![vec![1.0, 2.0], vec![3.0, f64::NAN]];
        let md = BTreeMap::from([("robotid.period_s".to_string(), "10".to_string())]);
        let pm = PeriodMean {
            joints: joints.clone(),
            time: vec![0.0, 0.5],
            q: v.clone(),
            q_spread: v.clone(),
            torque: v.clone(),
            torque_spread: v.clone(),
            metadata: md.clone(),
        };
        let back = PeriodMean::from_record_batch(&pm.to_record_batch().unwrap()).unwrap();
        assert_eq!(back.q[0], pm.q[0]);
        assert!(back.q[1][1].is_nan());
        assert_eq!(back.metadata["robotid.period_s"], "10");
        let k = Kinematics {
            joints: joints.clone(),
            time: vec![0.0, 0.5],
            q: v.clone(),
            qd: v.clone(),
            qdd: v.clone(),
            torque: None,
            metadata: md,
        };
        let back = Kinematics::from_record_batch(&k.to_record_batch().unwrap()).unwrap();
        assert_eq!(back.torque, None);
        assert_eq!(back.qd[0], vec![1.0, 2.0]);
    }
}
