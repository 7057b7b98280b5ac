//! The `regressor` stage: differentiated periods → the stacked linear system
//! A·θ = b (Swevers eq. 2–3, Bona eq. 9) as a `regressor` table: one row per
//! (sample, joint), one column per base parameter (named after its leading
//! standard parameter; its unit and full expression in the field metadata),
//! the measured torque, its noise variance, time and recording id. The
//! schema metadata holds the condition number of the column-normalised A.

use std::collections::BTreeMap;
use std::sync::Arc;

use arrow::array::{ArrayRef, Float64Array, Int64Array, RecordBatch, StringArray};
use arrow::datatypes::{DataType, Field, Schema};
use nalgebra::DMatrix;
use rayon::prelude::*;
use robotid_schemas::{metadata, Kinematics, NoiseTable, SchemaError, TableKind};
use serde::{Deserialize, Serialize};

use crate::dynamics::{
    base_parameters, decoupled_names, decoupled_regressor, parameter_unit, regressor, Data, FrictionTerms, Model,
    RegressorTerms, Spring,
};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FrictionModel {
    None,
    Symmetric,
    Asymmetric,
}

/// Which dynamic model the regressor describes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ModelKind {
    /// The full serial chain of the robot file (base parameters).
    #[default]
    Chain,
    /// Bona §3.1: joints moved one at a time, M·q̈ + k·sin(q + q_off) + friction.
    Decoupled,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RegressorConfig {
    pub model: ModelKind,
    pub friction: FrictionModel,
    pub rotor: bool,
    pub offset: bool,
    /// Coulomb transition velocity of the estimation model, rad/s: tanh(q̇/v)
    /// instead of sign(q̇) (default: the robot file's). A model whose
    /// friction is sharper than the robot's biases viscous and Coulomb
    /// estimates (measured on the simulated KUKA axis: +32 % and −6 % with
    /// sign(q̇) against a plant with v = 0.01 rad/s).
    pub coulomb_transition_rad_s: Option<f64>,
    /// Swevers eq. 9: gravity-spring terms on one joint as a Fourier series
    /// in its angle.
    pub spring: Option<SpringConfig>,
    /// Band-limit every regressor column, over the period, to the band the
    /// torque was inverse-filtered to (lines above are zeroed), so that both
    /// sides of A·θ = b see the same band: the Coulomb columns' sharp edges
    /// have energy above it that the torque lost. On the simulated KUKA axis
    /// the effect is small (the estimates move by under 0.05 σ); the
    /// derivative band matters more there. Periodic kinematics only.
    pub band_limit_hz: Option<f64>,
    /// Closed-loop data: the Projection Method (`projection.rs`) with a
    /// non-causal FIR of taps −m1..m2 from the references to the command;
    /// torque and columns are projected on the references' span.
    pub projection: Option<crate::projection::ProjectionConfig>,
}

/// The chain model with rotor inertia and symmetric friction (Swevers' and
/// Bona's), sign(q̇) Coulomb unless the robot file says otherwise.
impl Default for RegressorConfig {
    fn default() -> Self {
        RegressorConfig {
            model: ModelKind::Chain,
            friction: FrictionModel::Symmetric,
            rotor: true,
            offset: false,
            coulomb_transition_rad_s: None,
            spring: None,
            band_limit_hz: None,
            projection: None,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpringConfig {
    pub joint: String,
    pub harmonics: u32,
}

impl RegressorConfig {
    pub fn terms(&self, model: &Model) -> Result<RegressorTerms, String> {
        let spring = match &self.spring {
            Some(sc) => {
                let joint = model
                    .joints
                    .iter()
                    .position(|j| j.name == sc.joint)
                    .ok_or_else(|| format!("spring: `{}` is not a joint of `{}`", sc.joint, model.name))?;
                if sc.harmonics == 0 {
                    return Err("spring: harmonics must be ≥ 1".into());
                }
                Some(Spring {
                    joint,
                    harmonics: sc.harmonics,
                })
            }
            None => None,
        };
        Ok(RegressorTerms {
            rotor: self.rotor,
            friction: match self.friction {
                FrictionModel::None => FrictionTerms::None,
                FrictionModel::Symmetric => FrictionTerms::Symmetric,
                FrictionModel::Asymmetric => FrictionTerms::Asymmetric,
            },
            offset: self.offset,
            spring,
        })
    }
}

/// Schema key: the regressor configuration (JSON) a table was made with.
pub const CONFIG_KEY: &str = "robotid.regressor_config";

/// The base regressor of one model and configuration: which columns of the
/// full regressor are kept, their names and expressions. Built once, then
/// evaluated at any number of states (tables, predictions, ML Jacobians).
#[derive(Debug, Clone)]
pub struct BaseRegressor {
    /// The model with the configuration's Coulomb transition applied.
    pub model: Model,
    pub kind: ModelKind,
    pub terms: RegressorTerms,
    full_count: usize,
    /// (column of the full regressor, name, expression)
    columns: Vec<(usize, String, String)>,
    /// θ_base = map·θ_standard (chain models).
    map: Option<DMatrix<f64>>,
}

/// Preallocated buffers for [`BaseRegressor::rows`].
pub struct Workspace {
    data: Data,
    phi: DMatrix<f64>,
}

impl BaseRegressor {
    pub fn new(model: &Model, cfg: &RegressorConfig) -> Result<BaseRegressor, String> {
        let mut model = model.clone();
        if let Some(v) = cfg.coulomb_transition_rad_s {
            if !(v >= 0.0) {
                return Err("coulomb_transition_rad_s must be ≥ 0".into());
            }
            model.friction.iter_mut().for_each(|f| f.transition = v);
        }
        let terms = cfg.terms(&model)?;
        let n = model.dof();
        // Columns: (standard-column index into the full regressor, name, expression).
        let (full_count, columns, map) = match cfg.model {
            ModelKind::Chain => {
                let bp = base_parameters(&model, terms, 40 + 6 * terms.count(n) / n, 7);
                let cols = bp
                    .base
                    .iter()
                    .enumerate()
                    .map(|(i, &c)| (c, bp.names[c].clone(), bp.expression(i)))
                    .collect();
                (terms.count(n), cols, Some(bp.map))
            }
            ModelKind::Decoupled => {
                if terms.rotor || terms.offset || terms.spring.is_some() {
                    return Err(
                        "the decoupled model takes no rotor, offset or spring terms (its M·q̈ holds the rotor)".into(),
                    );
                }
                let names = decoupled_names(&model, terms.friction);
                (
                    names.len(),
                    names
                        .into_iter()
                        .enumerate()
                        .map(|(c, name)| (c, name.clone(), name))
                        .collect(),
                    None,
                )
            }
        };
        Ok(BaseRegressor {
            model,
            kind: cfg.model,
            terms,
            full_count,
            columns,
            map,
        })
    }

    /// The base parameters of a model's own standard parameters (its
    /// inertials, rotors, friction): the truth a simulation of `model`
    /// identifies. None for the decoupled model.
    pub fn base_values(&self, model: &Model) -> Option<nalgebra::DVector<f64>> {
        let map = self.map.as_ref()?;
        let std = crate::dynamics::standard_parameters(model, self.terms);
        Some(map * nalgebra::DVector::from_vec(std))
    }

    /// θ_base = map·θ_standard (chain models).
    pub fn map(&self) -> Option<&DMatrix<f64>> {
        self.map.as_ref()
    }

    pub fn names(&self) -> Vec<String> {
        self.columns.iter().map(|c| c.1.clone()).collect()
    }

    pub fn expressions(&self) -> Vec<String> {
        self.columns.iter().map(|c| c.2.clone()).collect()
    }

    pub fn parameters(&self) -> usize {
        self.columns.len()
    }

    pub fn workspace(&self) -> Workspace {
        Workspace {
            data: Data::new(&self.model),
            phi: DMatrix::zeros(self.model.dof(), self.full_count),
        }
    }

    /// The n rows of the base regressor at one state, row-major into `out`
    /// (n × parameters). No allocation.
    pub fn rows(&self, ws: &mut Workspace, q: &[f64], qd: &[f64], qdd: &[f64], out: &mut [f64]) {
        let n = self.model.dof();
        let nb = self.columns.len();
        match self.kind {
            ModelKind::Chain => regressor(&self.model, &mut ws.data, q, qd, qdd, self.terms, &mut ws.phi),
            ModelKind::Decoupled => decoupled_regressor(&self.model, q, qd, qdd, self.terms.friction, &mut ws.phi),
        }
        for j in 0..n {
            for (bi, (col, _, _)) in self.columns.iter().enumerate() {
                out[j * nb + bi] = ws.phi[(j, *col)];
            }
        }
    }

    /// The stacked rows of a whole kinematics table (samples × n rows,
    /// sample-major), samples in parallel chunks with their own workspace:
    /// no allocation per sample, and the result does not depend on the
    /// thread count.
    pub fn matrix(&self, kin: &Kinematics) -> DMatrix<f64> {
        let n = self.model.dof();
        let nb = self.columns.len();
        let samples = kin.time.len();
        let mut buf = vec![0.0; samples * n * nb];
        const CHUNK: usize = 256;
        buf.par_chunks_mut(CHUNK * n * nb).enumerate().for_each(|(c, out)| {
            let mut ws = self.workspace();
            let (mut q, mut qd, mut qdd) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
            for (local, rows_out) in out.chunks_mut(n * nb).enumerate() {
                let k = c * CHUNK + local;
                for j in 0..n {
                    q[j] = kin.q[j][k];
                    qd[j] = kin.qd[j][k];
                    qdd[j] = kin.qdd[j][k];
                }
                self.rows(&mut ws, &q, &qd, &qdd, rows_out);
            }
        });
        DMatrix::from_row_slice(samples * n, nb, &buf)
    }

    /// ∂A/∂x for every sample of `kin` and each of its 3n inputs (q, q̇, q̈
    /// of every joint, in that order), by central differences with steps
    /// scaled to each input's spread: the Jacobians maximum likelihood
    /// needs (`estimate::InputNoise`), samples × 3n × n × parameters.
    pub fn input_jacobians(&self, kin: &Kinematics) -> Vec<f64> {
        let n = self.model.dof();
        let nb = self.columns.len();
        let block = 3 * n * n * nb;
        let samples = kin.time.len();
        let rms = |v: &Vec<f64>| (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
        let steps: Vec<f64> = (0..3 * n)
            .map(|l| {
                let col = match l / n {
                    0 => &kin.q[l % n],
                    1 => &kin.qd[l % n],
                    _ => &kin.qdd[l % n],
                };
                1e-5 * rms(col).max(1e-3)
            })
            .collect();
        let mut out = vec![0.0; samples * block];
        out.par_chunks_mut(block).enumerate().for_each(|(k, jac)| {
            let mut ws = self.workspace();
            let mut x = vec![0.0; 3 * n];
            for j in 0..n {
                x[j] = kin.q[j][k];
                x[n + j] = kin.qd[j][k];
                x[2 * n + j] = kin.qdd[j][k];
            }
            let (mut plus, mut minus) = (vec![0.0; n * nb], vec![0.0; n * nb]);
            for l in 0..3 * n {
                let h = steps[l];
                let x0 = x[l];
                x[l] = x0 + h;
                self.rows(&mut ws, &x[..n], &x[n..2 * n], &x[2 * n..], &mut plus);
                x[l] = x0 - h;
                self.rows(&mut ws, &x[..n], &x[n..2 * n], &x[2 * n..], &mut minus);
                x[l] = x0;
                let dst = &mut jac[l * n * nb..(l + 1) * n * nb];
                for i in 0..n * nb {
                    dst[i] = (plus[i] - minus[i]) / (2.0 * h);
                }
            }
        });
        out
    }
}

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

/// The base regressor of `kin` for `model` as a `regressor` table. With
/// the aligned `periods` the torque of every period follows the parameter
/// columns (`torque_p0`, `torque_p1`, …): the estimator's covariance then
/// comes from the spread across periods, which holds whatever the noise's
/// colour (Swevers §4.1.2).
pub fn regressor_table(
    kin: &Kinematics,
    noise: Option<&NoiseTable>,
    periods: Option<&crate::align::Periods>,
    model: &Model,
    cfg: &RegressorConfig,
    recording: &str,
) -> Result<RecordBatch, String> {
    let base = BaseRegressor::new(model, cfg)?;
    let model = &base.model;
    let names = model.joint_names();
    if names != kin.joints {
        return Err(format!(
            "the table's joints {:?} are not the robot's {:?}",
            kin.joints, names
        ));
    }
    let torque = kin.torque.as_ref().ok_or("the kinematics table has no torques")?;
    let n = model.dof();
    let samples = kin.time.len();
    let rows = samples * n;
    let columns_of = &base.columns;
    let kind = cfg.model;
    let mut a = base.matrix(kin);
    if let Some(band) = cfg.band_limit_hz {
        band_limit(&mut a, n, kin, band)?;
    }
    let mut b_torque: Vec<Vec<f64>> = torque.clone();
    let mut projection_md = Vec::new();
    if let Some(pc) = &cfg.projection {
        let p = periods
            .filter(|p| p.samples_per_period == samples)
            .ok_or("projection needs the aligned periods of this table (an `align` stage, no resampling after it)")?;
        let proj = crate::projection::sensitivity(p, pc)?;
        let equations = n * proj.rank();
        if equations <= a.ncols() {
            return Err(format!(
                "projection: the references span {} dimensions per joint ({} equations for {} parameters); excite more harmonics or use a smaller model",
                proj.rank(),
                equations,
                a.ncols()
            ));
        }
        let mut series = vec![0.0; samples];
        for j in 0..n {
            b_torque[j] = proj.apply(&torque[j]);
            for c in 0..a.ncols() {
                for k in 0..samples {
                    series[k] = a[(k * n + j, c)];
                }
                let back = proj.apply(&series);
                for k in 0..samples {
                    a[(k * n + j, c)] = back[k];
                }
            }
        }
        projection_md.push((
            "robotid.projection".to_string(),
            format!(
                "m1 = {}, m2 = {}, rank {} per joint, explained {:?}, corr(û, u − û) {:?}",
                proj.m1,
                proj.m2,
                proj.rank(),
                proj.explained,
                proj.correlation
            ),
        ));
        projection_md.push(("robotid.projection.equations".to_string(), equations.to_string()));
    }
    let torque = &b_torque;
    let (mut sample, mut joint, mut time, mut b, mut var) = (
        Vec::with_capacity(rows),
        Vec::with_capacity(rows),
        Vec::with_capacity(rows),
        Vec::with_capacity(rows),
        Vec::with_capacity(rows),
    );
    for k in 0..samples {
        for j in 0..n {
            sample.push(k as i64);
            joint.push(names[j].clone());
            time.push(kin.time[k]);
            b.push(torque[j][k]);
            var.push(
                noise
                    .and_then(|t| t.var_torque.get(j).and_then(|v| v.get(k)).copied())
                    .unwrap_or(f64::NAN),
            );
        }
    }
    // Condition number of the column-normalised A (Swevers' criterion).
    let mut scaled = a.clone();
    for mut c in scaled.column_iter_mut() {
        let norm = c.norm();
        if norm > 0.0 {
            c /= norm;
        }
    }
    let sv = scaled.singular_values();
    let cond = if sv.min() > 0.0 {
        sv.max() / sv.min()
    } else {
        f64::INFINITY
    };
    let mut md: BTreeMap<String, String> = kin.metadata.clone();
    md.insert("robotid.condition_number".into(), cond.to_string());
    md.insert("robotid.base_parameters".into(), base.parameters().to_string());
    md.insert("robotid.robot".into(), model.name.clone());
    md.extend(projection_md);
    md.insert(
        CONFIG_KEY.into(),
        serde_json::to_string(cfg).map_err(|e| e.to_string())?,
    );
    md.insert(
        "robotid.model".into(),
        match kind {
            ModelKind::Chain => "chain",
            ModelKind::Decoupled => "decoupled",
        }
        .into(),
    );
    let base_schema = TableKind::Regressor.schema(&names, &[], &md);
    let mut fields: Vec<Field> = base_schema.fields().iter().map(|f| f.as_ref().clone()).collect();
    let mut columns: Vec<ArrayRef> = vec![
        Arc::new(StringArray::from(vec![recording; rows])),
        Arc::new(Int64Array::from(sample)),
        Arc::new(StringArray::from(joint)),
        Arc::new(Float64Array::from(time)),
        Arc::new(Float64Array::from(b)),
        Arc::new(Float64Array::from(var)),
    ];
    for (i, (_, name, expression)) in columns_of.iter().enumerate() {
        fields.push(
            Field::new(name, DataType::Float64, false).with_metadata(BTreeMap::from([
                (metadata::UNIT.to_string(), parameter_unit(name).to_string()),
                (metadata::QUANTITY.to_string(), PARAMETER_COLUMN.to_string()),
                ("expression".to_string(), expression.clone()),
            ])),
        );
        columns.push(Arc::new(Float64Array::from(
            a.column(i).iter().copied().collect::<Vec<f64>>(),
        )));
    }
    if let Some(p) = periods.filter(|p| p.periods >= 2 && p.samples_per_period == samples) {
        for pi in 0..p.periods {
            fields.push(
                Field::new(format!("torque_p{pi}"), DataType::Float64, false).with_metadata(BTreeMap::from([
                    (metadata::UNIT.to_string(), "N*m".to_string()),
                    (metadata::QUANTITY.to_string(), PERIOD_TORQUE.to_string()),
                    ("period".to_string(), pi.to_string()),
                ])),
            );
            let at = pi * samples;
            columns.push(Arc::new(Float64Array::from_iter_values(
                (0..samples).flat_map(|k| (0..n).map(move |j| p.torque[j][at + k])),
            )));
        }
    }
    let schema = Schema::new(fields).with_metadata(base_schema.metadata().clone());
    let batch = RecordBatch::try_new(Arc::new(schema), columns).map_err(|e| e.to_string())?;
    TableKind::Regressor
        .check(&batch.schema())
        .map_err(|e: SchemaError| e.to_string())?;
    Ok(batch)
}

/// Zeroes, per joint and column, the DFT lines of A above `band` Hz over
/// the table's period.
fn band_limit(a: &mut DMatrix<f64>, n: usize, kin: &Kinematics, band: f64) -> Result<(), String> {
    if !(band > 0.0) {
        return Err("band_limit_hz must be > 0".into());
    }
    let period = kin
        .metadata
        .get(metadata::PERIOD_S)
        .and_then(|v| v.parse::<f64>().ok())
        .filter(|_| kin.metadata.get("robotid.differentiation").map(String::as_str) != Some("filtered"))
        .ok_or("band_limit_hz needs one averaged period (the kinematics is not periodic)")?;
    let samples = kin.time.len();
    let spectra = crate::signal::Spectra::new();
    let cols = a.ncols();
    let mut series = vec![0.0; samples];
    for j in 0..n {
        for c in 0..cols {
            for k in 0..samples {
                series[k] = a[(k * n + j, c)];
            }
            let mut spec = spectra.forward(&series);
            for (line, x) in spec.iter_mut().enumerate() {
                if line as f64 / period > band {
                    *x = rustfft::num_complex::Complex64::new(0.0, 0.0);
                }
            }
            let back = spectra.inverse(&spec, samples);
            for k in 0..samples {
                a[(k * n + j, c)] = back[k];
            }
        }
    }
    Ok(())
}

/// Reduces a `regressor` table to its R factor (`r_factor` table): one row
/// per parameter with that row of R and of Qᵀb, folded in blocks of rows so
/// the full system is never held twice. Its least-squares solution and
/// residual are those of the table; factors of several recordings merge
/// (`dynamics::RFactor::merge`).
pub fn r_factor_table(regressor: &RecordBatch) -> Result<RecordBatch, String> {
    use crate::dynamics::RFactor;
    let schema = regressor.schema();
    TableKind::Regressor.check(&schema).map_err(|e| e.to_string())?;
    let param_idx = columns_of(&schema, PARAMETER_COLUMN);
    let params: Vec<Field> = param_idx.iter().map(|&i| schema.field(i).clone()).collect();
    let p = params.len();
    let f64s = |i: usize| -> Result<&Float64Array, String> {
        regressor
            .column(i)
            .as_any()
            .downcast_ref::<Float64Array>()
            .ok_or_else(|| format!("column {i} is not Float64"))
    };
    let b = f64s(schema.index_of("torque").map_err(|e| e.to_string())?)?;
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
    md.insert("robotid.rss".into(), acc.rss.to_string());
    md.insert("robotid.rows".into(), acc.rows.to_string());
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
    .map_err(|e| e.to_string())?;
    TableKind::RFactor.check(&out.schema()).map_err(|e| e.to_string())?;
    Ok(out)
}
