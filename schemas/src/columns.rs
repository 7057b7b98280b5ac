//! Building and reading per-joint Float64 tables by column name, so that
//! every table's column order comes from its kind's schema.

use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;

use arrow::array::{Array, ArrayRef, Float64Array, Int64Array, RecordBatch};

use crate::{SchemaError, TableKind};

/// Columns by name, assembled into a batch in the kind's schema order.
#[derive(Default)]
pub struct BatchBuilder {
    columns: HashMap<String, ArrayRef>,
    with: Vec<&'static str>,
}

impl BatchBuilder {
    pub fn new() -> BatchBuilder {
        BatchBuilder::default()
    }

    pub fn f64(mut self, name: impl Into<String>, values: &[f64]) -> Self {
        self.columns
            .insert(name.into(), Arc::new(Float64Array::from(values.to_vec())));
        self
    }

    pub fn i64(mut self, name: impl Into<String>, values: Vec<i64>) -> Self {
        self.columns.insert(name.into(), Arc::new(Int64Array::from(values)));
        self
    }

    /// One Int64 column per joint, named `{prefix}_{joint}`.
    pub fn per_joint_i64(mut self, prefix: &'static str, joints: &[String], values: &[Vec<i64>]) -> Self {
        for (j, v) in joints.iter().zip(values) {
            self = self.i64(format!("{prefix}_{j}"), v.clone());
        }
        self.with.push(prefix);
        self
    }

    /// One Float64 column per joint, named `{prefix}_{joint}`; `prefix` is
    /// included even if optional in the kind.
    pub fn per_joint(mut self, prefix: &'static str, joints: &[String], values: &[Vec<f64>]) -> Self {
        for (j, v) in joints.iter().zip(values) {
            self = self.f64(format!("{prefix}_{j}"), v);
        }
        self.with.push(prefix);
        self
    }

    pub fn build(
        mut self,
        kind: TableKind,
        joints: &[String],
        metadata: &BTreeMap<String, String>,
    ) -> Result<RecordBatch, SchemaError> {
        let schema = kind.schema(joints, &self.with, metadata);
        let mut arrays = Vec::with_capacity(schema.fields().len());
        for f in schema.fields() {
            let a = self
                .columns
                .remove(f.name())
                .ok_or_else(|| SchemaError::MissingColumn {
                    column: f.name().clone(),
                    why: format!("not given when building a `{kind}` table"),
                })?;
            arrays.push(a);
        }
        Ok(RecordBatch::try_new(Arc::new(schema), arrays)?)
    }
}

/// A column by name as the Arrow array type `A` (named `expected` in errors).
fn typed_column<'a, A: Array + 'static>(
    batch: &'a RecordBatch,
    name: &str,
    expected: &str,
) -> Result<&'a A, SchemaError> {
    let i = batch.schema().index_of(name).map_err(|_| SchemaError::MissingColumn {
        column: name.into(),
        why: "not in the table".into(),
    })?;
    batch
        .column(i)
        .as_any()
        .downcast_ref::<A>()
        .ok_or_else(|| SchemaError::WrongType {
            column: name.into(),
            expected: expected.into(),
            found: batch.column(i).data_type().to_string(),
        })
}

/// A non-null Float64 column by name.
pub fn f64_column(batch: &RecordBatch, name: &str) -> Result<Vec<f64>, SchemaError> {
    let a: &Float64Array = typed_column(batch, name, "Float64")?;
    if a.null_count() > 0 {
        return Err(SchemaError::WrongType {
            column: name.into(),
            expected: "Float64 without nulls".into(),
            found: format!("{} nulls", a.null_count()),
        });
    }
    Ok(a.values().to_vec())
}

/// A non-null Int64 column by name.
pub fn i64_column(batch: &RecordBatch, name: &str) -> Result<Vec<i64>, SchemaError> {
    let a: &Int64Array = typed_column(batch, name, "Int64")?;
    Ok(a.values().to_vec())
}

/// `{prefix}_{joint}` for every joint.
pub fn per_joint_columns(batch: &RecordBatch, prefix: &str, joints: &[String]) -> Result<Vec<Vec<f64>>, SchemaError> {
    joints
        .iter()
        .map(|j| f64_column(batch, &format!("{prefix}_{j}")))
        .collect()
}
