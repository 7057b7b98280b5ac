//! The `regressor` table (whole or a row group at a time) and its R factor.

use std::collections::BTreeMap;
use std::sync::Arc;

use arrow::array::{ArrayRef, Float64Array, Int64Array, RecordBatch, StringArray};
use arrow::datatypes::{DataType, Field, Schema, SchemaRef};
use nalgebra::DMatrix;
use robotid_schemas::{metadata, Kinematics, NoiseTable, TableKind};

use super::{regressor_rows, RegressorConfig, RegressorRows};
use crate::dynamics::Model;
use crate::estimation::{columns_of, RowBlocks, System, BLOCK_SAMPLES, PARAMETER_COLUMN, PERIOD_TORQUE};
use crate::signal::Spectra;
use crate::stage::Periods;
use crate::{Error, Result};
/// The base regressor of `kin` for `model` as a `regressor` table (the
/// stage without a pipeline, for tests and tools).
pub fn regressor_table(
    kin: &Kinematics,
    noise: Option<&NoiseTable>,
    periods: Option<&Periods>,
    model: &Model,
    cfg: &RegressorConfig,
    recording: &str,
) -> Result<RecordBatch> {
    let base = cfg.base_regressor(model)?;
    let spectra = Spectra::new();
    let band = match cfg.band_limit_hz {
        Some(b) => Some((
            b,
            kin.metadata
                .get(metadata::PERIOD_S)
                .and_then(|v| v.parse::<f64>().ok())
                .filter(|_| kin.metadata.get(metadata::DIFFERENTIATION).map(String::as_str) != Some("filtered"))
                .ok_or_else(|| Error::missing("one averaged period", "band_limit_hz applies to periodic kinematics"))?,
        )),
        None => None,
    };
    regressor_rows(kin, noise, periods, &base, cfg, band, &spectra, recording, false)?.into_record_batch()
}

impl RegressorRows {
    /// The `regressor` table's schema metadata: the kinematics' provenance,
    /// the condition number, the robot and the regressor configuration.
    pub fn table_metadata(&self) -> Result<BTreeMap<String, String>> {
        let sys = &self.system;
        let mut md = self.metadata.clone();
        md.insert(metadata::CONDITION_NUMBER.into(), self.condition.to_string());
        md.insert(metadata::BASE_PARAMETERS.into(), sys.parameters().to_string());
        md.insert(metadata::ROBOT.into(), self.robot.clone());
        if !self.locked.is_empty() {
            let locked: BTreeMap<&str, f64> = self.locked.iter().map(|(j, x)| (j.as_str(), *x)).collect();
            md.insert(
                metadata::LOCKED.into(),
                serde_json::to_string(&locked).map_err(|e| Error::numerical("serde_json", e.to_string()))?,
            );
        }
        if let Some(p) = &self.projection {
            md.insert(metadata::PROJECTION.into(), p.clone());
        }
        if let Some(e) = sys.equations {
            md.insert(metadata::PROJECTION_EQUATIONS.into(), e.to_string());
        }
        md.insert(
            metadata::REGRESSOR_CONFIG.into(),
            serde_json::to_string(&self.config).map_err(|e| Error::numerical("serde_json", e.to_string()))?,
        );
        md.insert(metadata::MODEL.into(), self.config.model.name().into());
        Ok(TableKind::Regressor.metadata(&sys.joints, &md))
    }

    /// A's rows: the system's matrix, or the maker's.
    pub fn source(&self) -> &dyn RowBlocks {
        match &self.maker {
            Some(m) => m,
            None => &self.system.a,
        }
    }

    /// The system with A whole (made, when its rows are made on demand).
    pub fn whole(&self) -> System {
        let mut sys = self.system.clone();
        if let Some(m) = &self.maker {
            sys.a = m.block(0, sys.rows());
        }
        sys
    }

    /// Makes A whole in the system, when its rows are made on demand.
    pub fn make_whole(&mut self) {
        if let Some(m) = self.maker.take() {
            self.system.a = m.block(0, self.system.rows());
        }
    }

    /// The `regressor` table: recording, sample, joint, time, torque,
    /// torque_var, one column per base parameter, then `torque_p0`, … for
    /// each period when there are at least two. A copy; see
    /// [`RegressorRows::into_record_batch`].
    pub fn to_record_batch(&self) -> Result<RecordBatch> {
        self.clone().into_record_batch()
    }

    /// The `regressor` table, its parameter and period columns slices of
    /// the system's own column-major storage, moved, not copied (they are
    /// most of the table, which is as large as the recording).
    pub fn into_record_batch(mut self) -> Result<RecordBatch> {
        self.make_whole();
        let schema = Arc::new(self.table_schema()?);
        let periods = self.system.periods.first_mut().and_then(Option::take);
        let a = std::mem::replace(&mut self.system.a, DMatrix::zeros(0, 0));
        let rows = self.system.rows();
        self.batch(&schema, 0, rows, a, periods)
    }

    /// Rows per row group of the table written in groups: whole samples,
    /// [`BLOCK_SAMPLES`] of them, more when that would make over 64 groups
    /// (each group's metadata is a few kB).
    pub fn group_rows(&self) -> usize {
        let n = self.system.joints.len().max(1);
        let samples = self.system.rows().div_ceil(n);
        BLOCK_SAMPLES.max(samples.div_ceil(64)) * n
    }

    /// The `regressor` table a row group at a time ([`RegressorRows::group_rows`]):
    /// its schema, and the groups, each made when asked, A's rows for it
    /// from [`RegressorRows::source`], so that A is never whole.
    pub fn into_groups(self) -> Result<(SchemaRef, impl Iterator<Item = Result<RecordBatch>>)> {
        let schema = Arc::new(self.table_schema()?);
        let (m, group) = (self.system.rows(), self.group_rows());
        let out = schema.clone();
        let groups = (0..m).step_by(group).map(move |start| {
            let k = group.min(m - start);
            let a = self.source().block(start, k);
            let periods = self
                .system
                .periods
                .first()
                .and_then(Option::as_ref)
                .map(|p| p.rows(start, k).into_owned());
            self.batch(&schema, start, k, a, periods)
        });
        Ok((out, groups))
    }

    /// The table's schema: the kinds' columns, then one per base parameter
    /// (unit, expression) and one per period.
    fn table_schema(&self) -> Result<Schema> {
        let md = self.table_metadata()?;
        let sys = &self.system;
        let base_schema = TableKind::Regressor.schema(&sys.joints, &[], &md);
        let mut fields: Vec<Field> = base_schema.fields().iter().map(|f| f.as_ref().clone()).collect();
        for (i, name) in sys.names.iter().enumerate() {
            fields.push(
                Field::new(name, DataType::Float64, false).with_metadata(BTreeMap::from([
                    (metadata::UNIT.to_string(), sys.units[i].clone()),
                    (metadata::QUANTITY.to_string(), PARAMETER_COLUMN.to_string()),
                    (metadata::EXPRESSION.to_string(), sys.expressions[i].clone()),
                ])),
            );
        }
        let periods = sys.periods.first().and_then(Option::as_ref).map_or(0, |p| p.ncols());
        for pi in 0..periods {
            fields.push(
                Field::new(format!("torque_p{pi}"), DataType::Float64, false).with_metadata(BTreeMap::from([
                    (metadata::UNIT.to_string(), "N*m".to_string()),
                    (metadata::QUANTITY.to_string(), PERIOD_TORQUE.to_string()),
                    (metadata::PERIOD.to_string(), pi.to_string()),
                ])),
            );
        }
        let schema = Schema::new(fields).with_metadata(base_schema.metadata().clone());
        TableKind::Regressor.validate(&schema)?;
        Ok(schema)
    }

    /// The table's rows `start .. start + k`, with A's and the periods'
    /// rows for them (moved into the table).
    fn batch(
        &self,
        schema: &SchemaRef,
        start: usize,
        k: usize,
        a: DMatrix<f64>,
        periods: Option<DMatrix<f64>>,
    ) -> Result<RecordBatch> {
        let sys = &self.system;
        let range = start..start + k;
        let recording = sys.recordings.first().map(String::as_str).unwrap_or("");
        let mut columns: Vec<ArrayRef> = vec![
            Arc::new(StringArray::from(vec![recording; k])),
            Arc::new(Int64Array::from(sys.sample[range.clone()].to_vec())),
            Arc::new(StringArray::from_iter_values(
                sys.joint[range.clone()].iter().map(|&j| sys.joints[j].as_str()),
            )),
            Arc::new(Float64Array::from_iter_values(
                sys.sample[range.clone()].iter().map(|&s| self.time[s as usize]),
            )),
            Arc::new(Float64Array::from_iter_values(sys.b.rows(start, k).iter().copied())),
            Arc::new(Float64Array::from_iter_values(sys.var.rows(start, k).iter().copied())),
        ];
        columns.extend(column_arrays(a));
        if let Some(p) = periods {
            columns.extend(column_arrays(p));
        }
        Ok(RecordBatch::try_new(schema.clone(), columns)
            .map_err(|e| robotid_schemas::SchemaError::Arrow(e.to_string()))?)
    }
}

/// The columns of `m` as Arrow arrays over its own storage: one buffer,
/// each column a slice of it (column-major, so contiguous).
fn column_arrays(m: DMatrix<f64>) -> Vec<ArrayRef> {
    let rows = m.nrows();
    let cols = m.ncols();
    let buffer = arrow::buffer::Buffer::from_vec(Vec::from(m.data));
    (0..cols)
        .map(|c| {
            let values = arrow::buffer::ScalarBuffer::<f64>::new(buffer.clone(), c * rows, rows);
            Arc::new(Float64Array::new(values, None)) as ArrayRef
        })
        .collect()
}

/// Reduces a `regressor` table to its R factor (`r_factor` table): one row
/// per parameter with that row of R and of Qᵀb, folded in blocks of rows so
/// the full system is never held twice. Its least-squares solution and
/// residual are those of the table; factors of several recordings merge
/// (`dynamics::RFactor::merge`).
pub fn r_factor_table(regressor: &RecordBatch) -> Result<RecordBatch> {
    use crate::dynamics::RFactor;
    let schema = regressor.schema();
    TableKind::Regressor.validate(&schema)?;
    let param_idx = columns_of(&schema, PARAMETER_COLUMN);
    let params: Vec<Field> = param_idx.iter().map(|&i| schema.field(i).clone()).collect();
    let p = params.len();
    let f64s = |i: usize| -> Result<&Float64Array> {
        regressor
            .column(i)
            .as_any()
            .downcast_ref::<Float64Array>()
            .ok_or_else(|| {
                Error::mismatch(
                    format!("regressor table: column `{}`", schema.field(i).name()),
                    "Float64",
                    regressor.column(i).data_type(),
                )
            })
    };
    let torque = schema
        .index_of("torque")
        .map_err(|_| Error::missing("column `torque`", "the regressor table has none"))?;
    let b = f64s(torque)?;
    let cols: Vec<&Float64Array> = param_idx.iter().map(|&i| f64s(i)).collect::<Result<_, _>>()?;
    let rows = regressor.num_rows();
    let mut acc = RFactor::new(p);
    const BLOCK: usize = 4096;
    for start in (0..rows).step_by(BLOCK) {
        let k = BLOCK.min(rows - start);
        let a = DMatrix::from_fn(k, p, |i, j| cols[j].value(start + i));
        let bb = nalgebra::DVector::from_fn(k, |i, _| b.value(start + i));
        acc.add_rows(&a, &bb);
    }
    let mut md: BTreeMap<String, String> = schema.metadata().clone().into();
    md.insert(metadata::RSS.into(), acc.rss.to_string());
    md.insert(metadata::ROWS.into(), acc.rows.to_string());
    let base = TableKind::RFactor.schema(&[], &[], &md);
    let mut fields: Vec<Field> = base.fields().iter().map(|f| f.as_ref().clone()).collect();
    fields.extend(params);
    let mut columns: Vec<ArrayRef> = vec![
        Arc::new(Int64Array::from((0..p as i64).collect::<Vec<_>>())),
        Arc::new(Float64Array::from(acc.z.iter().copied().collect::<Vec<f64>>())),
    ];
    for j in 0..p {
        columns.push(Arc::new(Float64Array::from(
            (0..p).map(|i| acc.r[(i, j)]).collect::<Vec<f64>>(),
        )));
    }
    let out = RecordBatch::try_new(
        Arc::new(Schema::new(fields).with_metadata(base.metadata().clone())),
        columns,
    )
    .map_err(|e| robotid_schemas::SchemaError::Arrow(e.to_string()))?;
    TableKind::RFactor.validate(&out.schema())?;
    Ok(out)
}
