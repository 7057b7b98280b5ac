//! What the simulator knows and a lab never does: noise-free signals at the
//! sample instants (`truth.parquet`) and every parameter that made the
//! recording (`truth.toml`).

use std::collections::BTreeMap;
use std::sync::Arc;

use arrow::array::{ArrayRef, Float64Array, RecordBatch};
use arrow::datatypes::{Field, Schema};
use robotid_schemas::{metadata, SchemaError, TableKind, Unit};
use serde::Serialize;

use crate::dynamics::Model;
use crate::signal::{AnalogFilter, FilterSpec};
use crate::trajectory::Trajectory;

/// Noise-free signals at the logged sample instants, `[joint][sample]`.
#[derive(Debug, Clone, PartialEq)]
pub struct TruthSamples {
    pub joints: Vec<String>,
    pub time: Vec<f64>,
    pub q: Vec<Vec<f64>>,
    pub qd: Vec<Vec<f64>>,
    pub qdd: Vec<Vec<f64>>,
    /// Commanded (= motor) joint torque, N·m: what the current measures.
    pub torque: Vec<Vec<f64>>,
    /// Torque disturbance that acted besides it, N·m.
    pub disturbance: Vec<Vec<f64>>,
    /// Motor current after the analog filter, before noise, A.
    pub current_clean: Vec<Vec<f64>>,
}

impl TruthSamples {
    /// A `kinematics` table (time, q, qd, qdd, torque) with two extra
    /// per-joint columns: `disturbance_<joint>` (N·m) and
    /// `current_clean_<joint>` (A).
    pub fn to_record_batch(&self, extra: &BTreeMap<String, String>) -> Result<RecordBatch, SchemaError> {
        let kind = TableKind::Kinematics;
        let base = kind.schema(&self.joints, &["torque"], extra);
        let mut fields: Vec<Field> = base.fields().iter().map(|f| f.as_ref().clone()).collect();
        let extra_field = |prefix: &str, quantity: &str, unit: Unit, joint: &str| {
            Field::new(format!("{prefix}_{joint}"), arrow::datatypes::DataType::Float64, false).with_metadata(
                BTreeMap::from([
                    (metadata::UNIT.to_string(), unit.symbol().to_string()),
                    (metadata::QUANTITY.to_string(), quantity.to_string()),
                    (metadata::JOINT.to_string(), joint.to_string()),
                ]),
            )
        };
        for j in &self.joints {
            fields.push(extra_field("disturbance", "torque_disturbance", Unit::NewtonMetre, j));
        }
        for j in &self.joints {
            fields.push(extra_field(
                "current_clean",
                "motor_current_noise_free",
                Unit::Ampere,
                j,
            ));
        }
        let schema = Schema::new(fields).with_metadata(base.metadata().clone());
        let col = |v: &Vec<f64>| Arc::new(Float64Array::from(v.clone())) as ArrayRef;
        let mut columns = vec![col(&self.time)];
        for group in [
            &self.q,
            &self.qd,
            &self.qdd,
            &self.torque,
            &self.disturbance,
            &self.current_clean,
        ] {
            columns.extend(group.iter().map(col));
        }
        let batch = RecordBatch::try_new(Arc::new(schema), columns)?;
        kind.validate(&batch.schema())?;
        Ok(batch)
    }
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct JointTruth {
    pub name: String,
    /// kg
    pub mass: f64,
    /// m, link frame
    pub com: [f64; 3],
    /// kg·m: m·com
    pub first_moment: [f64; 3],
    /// kg·m² about the COM: ixx, iyy, izz, ixy, ixz, iyz
    pub inertia_com: [f64; 6],
    /// kg·m² about the link-frame origin: ixx, iyy, izz, ixy, ixz, iyz
    pub inertia_origin: [f64; 6],
    pub gear_ratio: f64,
    pub torque_constant: f64,
    pub encoder_counts_per_rev: f64,
    pub rotor_inertia: f64,
    /// rotor·gear², kg·m²
    pub reflected_inertia: f64,
    pub viscous_pos: f64,
    pub viscous_neg: f64,
    pub coulomb_pos: f64,
    pub coulomb_neg: f64,
    pub offset: f64,
    /// Coulomb transition velocity of the simulated plant, rad/s (0: sign)
    pub coulomb_transition_rad_s: f64,
    /// std of the Gaussian noise added before quantisation, rad
    pub position_noise_std_rad: f64,
    /// one encoder count at the joint, rad (0: not quantised)
    pub position_quantum_rad: f64,
    /// std of the noise on the sampled current, A
    pub current_noise_std_a: f64,
    /// the same, as joint torque, N·m
    pub torque_noise_std_nm: f64,
    /// std of the process torque disturbance, N·m
    pub disturbance_std_nm: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FilterTruth {
    pub spec: FilterSpec,
    /// rad/s
    pub poles_re: Vec<f64>,
    pub poles_im: Vec<f64>,
    pub gain: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GainsTruth {
    pub kp: Vec<f64>,
    pub kd: Vec<f64>,
    pub ki: Vec<f64>,
}

/// Everything that made a simulated recording (`truth.toml`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GroundTruth {
    pub robot: String,
    pub seed: u64,
    pub log_rate_hz: f64,
    pub steps_per_sample: u32,
    pub period_s: Option<f64>,
    pub harmonics: Option<Vec<u32>>,
    /// Length of the reference fade-in from rest, s.
    pub transient_s: f64,
    /// Phase of the periodic reference when the fade-in ends, s.
    pub start_phase_s: f64,
    /// Samples in the log (after drops).
    pub samples: usize,
    pub dropped_samples: usize,
    pub jitter_std_s: f64,
    pub filter: Option<FilterTruth>,
    pub controller: Option<GainsTruth>,
    pub trajectory: Trajectory,
    #[serde(rename = "joint")]
    pub joints: Vec<JointTruth>,
}

pub(crate) fn joint_truths(
    model: &Model,
    pos_std: &[f64],
    quantise: bool,
    cur_std: &[f64],
    dist_std: &[f64],
) -> Vec<JointTruth> {
    let sym = |m: nalgebra::Matrix3<f64>| [m[(0, 0)], m[(1, 1)], m[(2, 2)], m[(0, 1)], m[(0, 2)], m[(1, 2)]];
    (0..model.dof())
        .map(|i| {
            let l = &model.links[i];
            let d = &model.drives[i];
            let f = &model.friction[i];
            JointTruth {
                name: model.joints[i].name.clone(),
                mass: l.mass,
                com: l.com.into(),
                first_moment: l.first_moment().into(),
                inertia_com: sym(l.inertia_com),
                inertia_origin: sym(l.inertia_origin()),
                gear_ratio: d.gear_ratio,
                torque_constant: d.torque_constant,
                encoder_counts_per_rev: d.encoder_counts_per_rev,
                rotor_inertia: d.rotor_inertia,
                reflected_inertia: d.reflected_inertia(),
                viscous_pos: f.viscous_pos,
                viscous_neg: f.viscous_neg,
                coulomb_pos: f.coulomb_pos,
                coulomb_neg: f.coulomb_neg,
                offset: f.offset,
                coulomb_transition_rad_s: f.transition,
                position_noise_std_rad: pos_std[i],
                position_quantum_rad: if quantise { d.radians_per_count() } else { 0.0 },
                current_noise_std_a: cur_std[i],
                torque_noise_std_nm: cur_std[i] * d.joint_torque_per_amp(),
                disturbance_std_nm: dist_std[i],
            }
        })
        .collect()
}

pub(crate) fn filter_truth(f: &AnalogFilter) -> FilterTruth {
    FilterTruth {
        spec: f.spec,
        poles_re: f.poles.iter().map(|p| p.re).collect(),
        poles_im: f.poles.iter().map(|p| p.im).collect(),
        gain: f.gain,
    }
}
