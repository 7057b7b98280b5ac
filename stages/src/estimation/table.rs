//! The `parameters` table: one row per parameter (name, unit, value, std,
//! relative std, Student-t interval, expression), then one `cov_<name>`
//! column per parameter holding the covariance matrix. The schema metadata
//! says how the estimate was made (method, level, degrees of freedom,
//! residual variance, condition number, recordings) and carries the
//! regressor's provenance (robot, model, regressor configuration), so that
//! `robotid predict` can rebuild the regressor the values belong to.

use crate::{Error, Result};
use std::collections::BTreeMap;
use std::sync::Arc;

use arrow::array::{Array, ArrayRef, Float64Array, RecordBatch, StringArray};
use arrow::datatypes::{DataType, Field, Schema};
use nalgebra::{DMatrix, DVector};
use robotid_schemas::{metadata, TableKind};

use super::Estimate;

/// Schema key: confidence level of `ci_low`/`ci_high`.
pub use robotid_schemas::metadata::ESTIMATE_CONFIDENCE as CONFIDENCE;
/// Schema key: Student-t degrees of freedom.
pub use robotid_schemas::metadata::ESTIMATE_DOF as DOF;
/// Schema key: estimator (`ols`, `wls`, `ml`).
pub use robotid_schemas::metadata::ESTIMATE_METHOD as METHOD;

/// A `parameters` table read back.
#[derive(Debug, Clone)]
pub struct Parameters {
    pub names: Vec<String>,
    pub units: Vec<String>,
    /// Each base parameter's expression in the standard ones (the
    /// optional `expression` column; empty when the table has none).
    pub expressions: Vec<String>,
    pub values: DVector<f64>,
    pub std: DVector<f64>,
    pub covariance: DMatrix<f64>,
    pub metadata: BTreeMap<String, String>,
}

/// The table of an estimate; `extra` (provenance) goes into the schema
/// metadata, `expressions` into the optional column.
pub fn parameters_table(
    est: &Estimate,
    level: f64,
    expressions: &[String],
    extra: &BTreeMap<String, String>,
) -> Result<RecordBatch> {
    let p = est.values.len();
    let std = est.std();
    let (low, high) = intervals(est, level, expressions);
    let mut md = extra.clone();
    md.insert(METHOD.into(), est.method.name().into());
    md.insert(CONFIDENCE.into(), level.to_string());
    md.insert(DOF.into(), est.dof.to_string());
    md.insert(metadata::ESTIMATE_COVARIANCE.into(), est.covariance_from.name().into());
    md.insert(metadata::ESTIMATE_ROWS.into(), est.rows.to_string());
    md.insert(
        metadata::ESTIMATE_RESIDUAL_VARIANCE.into(),
        est.residual_variance.to_string(),
    );
    md.insert(metadata::ESTIMATE_ITERATIONS.into(), est.iterations.to_string());
    md.insert(metadata::CONDITION_NUMBER.into(), est.condition.to_string());
    let base = TableKind::Parameters.schema(&[], &["expression"], &md);
    let mut fields: Vec<Field> = base.fields().iter().map(|f| f.as_ref().clone()).collect();
    let values: Vec<f64> = est.values.iter().copied().collect();
    let mut columns: Vec<ArrayRef> = vec![
        Arc::new(StringArray::from(est.names.clone())),
        Arc::new(StringArray::from(est.units.clone())),
        Arc::new(Float64Array::from(values.clone())),
        Arc::new(Float64Array::from(std.iter().copied().collect::<Vec<_>>())),
        Arc::new(Float64Array::from(
            (0..p).map(|i| 100.0 * std[i] / values[i].abs()).collect::<Vec<_>>(),
        )),
        Arc::new(Float64Array::from(low)),
        Arc::new(Float64Array::from(high)),
        Arc::new(StringArray::from(
            (0..p)
                .map(|i| expressions.get(i).cloned().unwrap_or_else(|| est.names[i].clone()))
                .collect::<Vec<_>>(),
        )),
    ];
    for (j, name) in est.names.iter().enumerate() {
        fields.push(
            Field::new(format!("cov_{name}"), DataType::Float64, false).with_metadata(BTreeMap::from([
                (metadata::UNIT.to_string(), "1".to_string()),
                (metadata::QUANTITY.to_string(), "covariance".to_string()),
                ("parameter".to_string(), name.clone()),
            ])),
        );
        columns.push(Arc::new(Float64Array::from(
            (0..p).map(|i| est.covariance[(i, j)]).collect::<Vec<_>>(),
        )));
    }
    let schema = Schema::new(fields).with_metadata(base.metadata().clone());
    let batch = RecordBatch::try_new(Arc::new(schema), columns)
        .map_err(|e| robotid_schemas::SchemaError::Arrow(e.to_string()))?;
    TableKind::Parameters.validate(&batch.schema())?;
    Ok(batch)
}

/// Each parameter's Student-t interval at `level`, (lows, highs). The
/// physically consistent fit's values keep to its bounds, and so does the
/// truth: where a rotor inertia or a friction coefficient is a base
/// parameter on its own (its expression is its name), its interval is cut
/// at 0. A symmetric interval about a value held at 0 (the real LWR4+'s
/// `Fv_lwr_1_joint`, 0 ± 0.43) would claim negative friction possible;
/// the cut one holds the truth whenever the whole one does. Least
/// squares' intervals are those of an unconstrained estimator, kept whole
/// (a negative value's interval is how it is seen to be impossible).
pub fn intervals(est: &Estimate, level: f64, expressions: &[String]) -> (Vec<f64>, Vec<f64>) {
    let half = est.half_width(level);
    let constrained = est.covariance_from == super::Covariance::Bootstrap;
    (0..est.values.len())
        .map(|i| {
            let (v, n) = (est.values[i], &est.names[i]);
            let alone = expressions.get(i).is_none_or(|e| e == n);
            let floor = match constrained && alone && crate::dynamics::ParameterKind::of(n).non_negative() {
                true => 0.0,
                false => f64::NEG_INFINITY,
            };
            ((v - half[i]).max(floor), v + half[i])
        })
        .unzip()
}

/// A parameters table's `expression` column (empty when it has none).
pub fn expressions_of(batch: &RecordBatch) -> Vec<String> {
    batch
        .column_by_name("expression")
        .and_then(|c| c.as_any().downcast_ref::<StringArray>())
        .map(|c| (0..c.len()).map(|i| c.value(i).to_string()).collect())
        .unwrap_or_default()
}

/// Reads a `parameters` table back.
pub fn parameters_from_table(batch: &RecordBatch) -> Result<Parameters> {
    let schema = batch.schema();
    TableKind::Parameters.validate(&schema)?;
    let missing = |name: &str| Error::mismatch(format!("parameters table: column `{name}`"), "present", "missing");
    let s = |name: &str| -> Result<Vec<String>> {
        let c = batch
            .column_by_name(name)
            .and_then(|c| c.as_any().downcast_ref::<StringArray>())
            .ok_or_else(|| missing(name))?;
        Ok((0..c.len()).map(|i| c.value(i).to_string()).collect())
    };
    let f = |name: &str| -> Result<DVector<f64>> {
        let c = batch
            .column_by_name(name)
            .and_then(|c| c.as_any().downcast_ref::<Float64Array>())
            .ok_or_else(|| missing(name))?;
        Ok(DVector::from_fn(c.len(), |i, _| c.value(i)))
    };
    let names = s("name")?;
    let values = f("value")?;
    // An estimate is finite: a table that says otherwise was not written
    // by an estimate (an edited one without its CRC), and would make every
    // prediction NaN.
    if let Some(i) = (0..values.len()).find(|&i| !values[i].is_finite()) {
        return Err(Error::NotFinite {
            what: "the parameters table's `value`".into(),
            value: values[i],
            at: format!("parameter `{}` (row {i})", names[i]),
        });
    }
    let p = names.len();
    let mut covariance = DMatrix::zeros(p, p);
    for (j, name) in names.iter().enumerate() {
        let c = f(&format!("cov_{name}"))?;
        covariance.set_column(j, &c);
    }
    Ok(Parameters {
        units: s("unit")?,
        expressions: expressions_of(batch),
        values,
        std: f("std")?,
        names,
        covariance,
        metadata: schema.metadata().clone().into_iter().collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimation::{Covariance, Estimator};

    fn estimate(from: Covariance) -> Estimate {
        let names: Vec<String> = ["Fv_j1", "Fc_j1", "MX_j1", "Fv_j2"].map(String::from).to_vec();
        Estimate {
            units: vec!["1".into(); names.len()],
            names,
            method: Estimator::Ols,
            values: DVector::from_vec(vec![0.0, 0.5, 0.0, 0.0]),
            covariance: DMatrix::from_diagonal(&DVector::from_vec(vec![0.04, 0.01, 0.04, 0.04])),
            dof: usize::MAX / 2,
            residual_variance: 1.0,
            condition: 1.0,
            rows: 100,
            iterations: 1,
            covariance_from: from,
            adequacy: vec![],
            widened: false,
        }
    }

    /// The physical fit's friction held at 0 gets [0, 1.96·std]; a
    /// friction far from its bound, an inertial parameter (which may be
    /// negative), a friction regrouped with others, and least squares'
    /// intervals keep the symmetric ones.
    #[test]
    fn a_bound_cuts_the_physical_intervals_only() {
        let z = 1.959_964;
        let expressions = ["Fv_j1", "Fc_j1", "MX_j1", "Fv_j2 + Fv_j3"].map(String::from);
        let (lo, hi) = intervals(&estimate(Covariance::Bootstrap), 0.95, &expressions);
        let close = |a: f64, b: f64| (a - b).abs() < 1e-5;
        assert!(lo[0] == 0.0 && close(hi[0], 0.2 * z), "{lo:?} {hi:?}");
        assert!(close(lo[1], 0.5 - 0.1 * z) && close(hi[1], 0.5 + 0.1 * z));
        assert!(close(lo[2], -0.2 * z) && close(lo[3], -0.2 * z), "{lo:?}");
        let (lo, _) = intervals(&estimate(Covariance::Periods), 0.95, &expressions);
        assert!(close(lo[0], -0.2 * z), "{lo:?}");
    }
}
