//! The base regressor of one robot and regressor model: which columns of
//! the full torque regressor (`torque_regressor.rs`) or of Bona's decoupled
//! model (`decoupled.rs`) are kept, their names and the expressions that
//! regroup the standard parameters into them. Built once per run, then
//! evaluated at any number of states (tables, predictions, ML Jacobians,
//! excitation design).

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

use nalgebra::DMatrix;
use rayon::prelude::*;
use robotid_schemas::Kinematics;
use serde::{Deserialize, Serialize};

use super::{
    base_parameters, decoupled_names, decoupled_regressor, regressor, Batched, Data, FrictionTerms, Model,
    RegressorTerms, Spring, Stribeck, LANES,
};
use super::{rnea::rigid_torque, torque_regressor::joint_columns, torque_regressor::MOTOR_COLUMNS};
use crate::{Error, Result};

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

impl ModelKind {
    pub fn name(self) -> &'static str {
        match self {
            ModelKind::Chain => "chain",
            ModelKind::Decoupled => "decoupled",
        }
    }
}

/// The terms of an identification model: which model, which joint terms.
/// The `regressor` stage's and the excitation file's `regressor` settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RegressorModel {
    pub model: ModelKind,
    pub friction: FrictionTerms,
    /// Rotor inertia seen at each joint (Ia) (default: when the robot file
    /// declares its drives; a URDF alone does not).
    pub rotor: Option<bool>,
    /// A constant torque offset per joint (Off).
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
    /// Ten more columns, after the base ones: the standard columns of the
    /// last moving link, for a payload it carries (`XX_payload` …
    /// `M_payload`, about that link's frame). They are not regrouped: a
    /// payload changes that link's ten parameters, and records with and
    /// without it tell the change apart (`estimation::payload`).
    pub payload: bool,
    /// With `friction = "stribeck"` or `"stribeck_asymmetric"`: each
    /// joint's Stribeck fade, by joint name. A joint not named has no
    /// static excess (its column is zero, and the base leaves it out).
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub stribeck: BTreeMap<String, StribeckShape>,
}

/// How a joint's static friction fades with speed: exp(−(|q̇|/vs)^δ).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StribeckShape {
    /// vs, rad/s (> 0).
    pub velocity_rad_s: f64,
    /// δ (> 0; 2 is Gaussian).
    pub exponent: f64,
}

/// The chain model with symmetric friction (Swevers' and Bona's), rotor
/// inertia where the robot file declares drives, sign(q̇) Coulomb unless
/// the robot file says otherwise.
impl Default for RegressorModel {
    fn default() -> Self {
        RegressorModel {
            model: ModelKind::Chain,
            friction: FrictionTerms::Symmetric,
            rotor: None,
            offset: false,
            coulomb_transition_rad_s: None,
            spring: None,
            payload: false,
            stribeck: BTreeMap::new(),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpringConfig {
    /// The joint carrying the spring.
    pub joint: String,
    /// Harmonics of its Fourier series in the joint angle (≥ 1).
    pub harmonics: u32,
}

impl RegressorModel {
    pub fn terms(&self, model: &Model) -> Result<RegressorTerms> {
        let spring = match &self.spring {
            Some(sc) => {
                let joint = model.joints.iter().position(|j| j.name == sc.joint).ok_or_else(|| {
                    Error::mismatch(
                        "spring: joint",
                        format!("one of {}", model.joint_names().join(", ")),
                        &sc.joint,
                    )
                })?;
                if sc.harmonics == 0 {
                    return Err(Error::setting("spring.harmonics", "≥ 1", 0));
                }
                Some(Spring {
                    joint,
                    harmonics: sc.harmonics,
                })
            }
            None => None,
        };
        Ok(RegressorTerms {
            rotor: self.rotor.unwrap_or(model.drives_declared),
            friction: self.friction,
            offset: self.offset,
            spring,
        })
    }
}

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
    /// The chain's kernel for whole tables, four samples per pass.
    batched: Option<Batched>,
}

/// The payload's columns (`RegressorModel::payload`), in the order of a
/// link's ten standard parameters.
pub const PAYLOAD_COLUMNS: [&str; 10] = [
    "XX_payload",
    "XY_payload",
    "XZ_payload",
    "YY_payload",
    "YZ_payload",
    "ZZ_payload",
    "MX_payload",
    "MY_payload",
    "MZ_payload",
    "M_payload",
];

/// Preallocated buffers for [`BaseRegressor::rows`].
#[derive(Clone)]
pub struct Workspace {
    data: Data,
    phi: DMatrix<f64>,
}

/// How many built base regressors [`BaseRegressor::shared`] keeps: an
/// identification asks for a handful (one per Coulomb candidate).
const SHARED_KEPT: usize = 16;

type Built = (Model, RegressorModel, Arc<BaseRegressor>);

static SHARED: Mutex<Vec<Built>> = Mutex::new(Vec::new());

impl BaseRegressor {
    /// The base regressor of `model` under `spec`, built once and shared:
    /// a build is a QR of the regressor at random states (its outcome is
    /// the same every time: seeded), and planning, linting, the regressor
    /// stage, the estimate and identify's candidates ask for the same one
    /// many times. The last [`SHARED_KEPT`] are kept.
    pub fn shared(model: &Model, spec: &RegressorModel) -> Result<Arc<BaseRegressor>> {
        let found = |kept: &Vec<Built>| {
            kept.iter()
                .find(|(m, s, _)| m == model && s == spec)
                .map(|(_, _, b)| b.clone())
        };
        if let Some(b) = found(&SHARED.lock().unwrap_or_else(|e| e.into_inner())) {
            return Ok(b);
        }
        // Built outside the lock: two threads may both build the same one
        // (the same result), but none waits on another's build.
        let built = Arc::new(BaseRegressor::new(model, spec)?);
        let mut kept = SHARED.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(b) = found(&kept) {
            return Ok(b);
        }
        if kept.len() == SHARED_KEPT {
            kept.remove(0);
        }
        kept.push((model.clone(), spec.clone(), built.clone()));
        Ok(built)
    }

    /// Regroups the standard parameters of `model` under `spec` (a
    /// restricted-pivot QR on sampled states, `base_parameters.rs`).
    pub fn new(model: &Model, spec: &RegressorModel) -> Result<BaseRegressor> {
        let model = with_friction_shapes(model, spec)?;
        let terms = spec.terms(&model)?;
        let n = model.dof();
        // Columns: (standard-column index into the full regressor, name, expression).
        let (full_count, columns, map) = match spec.model {
            ModelKind::Chain => {
                let bp = base_parameters(&model, terms, 40 + 6 * terms.count(&model) / n, 7);
                let cols = bp
                    .base
                    .iter()
                    .enumerate()
                    .map(|(i, &c)| (c, bp.names[c].clone(), bp.expression(i)))
                    .collect();
                (terms.count(&model), cols, Some(bp.map))
            }
            ModelKind::Decoupled => {
                if terms.rotor || terms.spring.is_some() {
                    return Err(Error::setting(
                        "model = \"decoupled\"",
                        "used with rotor = false and no spring (its M·q̈ holds the rotor)",
                        format!("rotor = {}, spring = {}", terms.rotor, terms.spring.is_some()),
                    ));
                }
                let names = decoupled_names(&model, terms.friction, terms.offset);
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
        let mut columns: Vec<(usize, String, String)> = columns;
        if spec.payload {
            if spec.model != ModelKind::Chain {
                return Err(Error::setting(
                    "payload",
                    "used with model = \"chain\" (the decoupled model has no links)",
                    "model = \"decoupled\"",
                ));
            }
            let last = 10 * (n - 1);
            for (c, name) in PAYLOAD_COLUMNS.iter().enumerate() {
                columns.push((
                    last + c,
                    (*name).to_string(),
                    format!("payload {name} about the last link's frame"),
                ));
            }
        }
        let batched = (spec.model == ModelKind::Chain).then(|| Batched::new(&model));
        Ok(BaseRegressor {
            batched,
            model,
            kind: spec.model,
            terms,
            full_count,
            columns,
            map,
        })
    }

    /// The base parameters of a model's own standard parameters (its
    /// inertials, rotors, friction): the truth a simulation of `model`
    /// identifies. None for the decoupled model.
    /// With payload columns, the payload's values are zero: the robot
    /// alone carries none.
    pub fn base_values(&self, model: &Model) -> Option<nalgebra::DVector<f64>> {
        let map = self.map.as_ref()?;
        let std = crate::dynamics::standard_parameters(model, self.terms);
        let robot = map * nalgebra::DVector::from_vec(std);
        Some(robot.resize_vertically(self.columns.len(), 0.0))
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

    /// The joint and the index among its friction columns (as
    /// `friction_values` orders them) of base column `c` when it is a
    /// friction term: a function of that joint's velocity alone, in that
    /// joint's row alone. None for every other column.
    pub fn friction_term(&self, c: usize) -> Option<(usize, usize)> {
        let n = self.model.dof();
        let full = self.columns[c].0;
        let (first, per, before) = match self.kind {
            ModelKind::Chain => (10 * n, self.terms.per_joint(), self.terms.rotor as usize),
            ModelKind::Decoupled => (
                0,
                super::decoupled::per_joint(self.terms.friction, self.terms.offset),
                3,
            ),
        };
        let at = full.checked_sub(first)?;
        let (joint, k) = (at / per.max(1), (at % per.max(1)).checked_sub(before)?);
        (joint < n && k < self.terms.friction.width()).then_some((joint, k))
    }

    /// Whether base column `c` is a Coulomb friction term (sign or tanh of
    /// the joint's velocity).
    pub fn is_coulomb(&self, c: usize) -> bool {
        self.friction_term(c)
            .is_some_and(|(_, k)| self.terms.friction.is_coulomb(k))
    }

    /// Every friction term of `joint` at joint velocity `qd`, as the
    /// regressor makes them (indexed as [`BaseRegressor::friction_term`]'s
    /// second number): one tanh for all.
    pub fn friction_values(&self, joint: usize, qd: f64) -> [f64; super::torque_regressor::FRICTION_COLUMNS] {
        super::torque_regressor::friction_values(self.terms.friction, &self.model.friction[joint], qd).0
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
            ModelKind::Decoupled => decoupled_regressor(
                &self.model,
                q,
                qd,
                qdd,
                self.terms.friction,
                self.terms.offset,
                &mut ws.phi,
            ),
        }
        for j in 0..n {
            for (bi, (col, _, _)) in self.columns.iter().enumerate() {
                out[j * nb + bi] = ws.phi[(j, *col)];
            }
        }
    }

    /// θ over the full regressor's columns with the base θ's torques
    /// (Φ·θ_full = Y·θ): a base column is a column of Φ, and the payload's
    /// add to the last link's. None for the decoupled model.
    pub fn full_values(&self, theta: &[f64]) -> Option<Vec<f64>> {
        (self.kind == ModelKind::Chain).then(|| {
            let mut full = vec![0.0; self.full_count];
            for ((c, _, _), v) in self.columns.iter().zip(theta) {
                full[*c] += v;
            }
            full
        })
    }

    /// Φ(q, q̇, q̈)·θ_full into `out` (n torques) for a chain and
    /// [`BaseRegressor::full_values`]: the links by Newton–Euler, O(n)
    /// against [`BaseRegressor::rows`]' O(n²), and each joint's own columns
    /// as the regressor makes them. Equal to Y·θ to round-off. No
    /// allocation.
    pub fn torque(&self, ws: &mut Workspace, (q, qd, qdd): (&[f64], &[f64], &[f64]), full: &[f64], out: &mut [f64]) {
        let n = self.model.dof();
        assert_eq!(self.kind, ModelKind::Chain, "torque: a chain's full parameters");
        rigid_torque(&self.model, &mut ws.data, (q, qd, qdd), &full[..10 * n], out);
        // Each joint's columns are its own row's, the spring's its joint's.
        joint_columns(&self.model, (q, qd, qdd), self.terms, &mut ws.phi);
        let per = self.terms.per_joint();
        for (j, t) in out.iter_mut().enumerate() {
            for c in 10 * n + per * j..10 * n + per * (j + 1) {
                *t += ws.phi[(j, c)] * full[c];
            }
        }
        let motors = self.terms.motors_at(n);
        if let Some(sp) = self.terms.spring {
            for c in n * (10 + per)..motors {
                out[sp.joint] += ws.phi[(sp.joint, c)] * full[c];
            }
        }
        // A coupled motor's columns reach the other joints it turns with:
        // its friction's every row, its rotor's rows past its own.
        for (i, c) in self.model.couplings.iter().enumerate() {
            let rotor = self.terms.rotor.then_some(10 * n + per * c.motor);
            let friction = motors + MOTOR_COLUMNS * i..motors + MOTOR_COLUMNS * (i + 1);
            for row in std::iter::once(c.motor).chain(c.with.iter().map(|w| w.0)) {
                for col in friction.clone().chain(rotor.filter(|_| row != c.motor)) {
                    out[row] += ws.phi[(row, col)] * full[col];
                }
            }
        }
    }

    /// The stacked rows of a whole kinematics table (samples × n rows,
    /// sample-major), samples in parallel chunks with their own workspace:
    /// no allocation per sample, and the result does not depend on the
    /// thread count. Written straight into the column-major matrix: each
    /// chunk owns its rows' piece of every column.
    pub fn matrix(&self, kin: &Kinematics) -> DMatrix<f64> {
        self.matrix_of(&kin.q, &kin.qd, &kin.qdd, 0..kin.time.len())
    }

    /// The stacked rows of the samples `range` of the motion (q, q̇, q̈ per
    /// joint): rows `range.start·n ..` of [`BaseRegressor::matrix`], equal
    /// to them bit for bit (each sample is computed alone), for callers
    /// that take the matrix in blocks rather than whole.
    pub fn matrix_of(
        &self,
        q: &[Vec<f64>],
        qd: &[Vec<f64>],
        qdd: &[Vec<f64>],
        range: std::ops::Range<usize>,
    ) -> DMatrix<f64> {
        let n = self.model.dof();
        let nb = self.columns.len();
        let first = range.start;
        let samples = range.len();
        let rows = samples * n;
        const CHUNK: usize = 256; // samples, a multiple of LANES
        let mut a = DMatrix::zeros(rows, nb);
        let mut pieces: Vec<Vec<&mut [f64]>> = (0..samples.div_ceil(CHUNK)).map(|_| Vec::with_capacity(nb)).collect();
        if rows > 0 {
            for column in a.as_mut_slice().chunks_mut(rows) {
                for (c, piece) in column.chunks_mut(CHUNK * n).enumerate() {
                    pieces[c].push(piece);
                }
            }
        }
        pieces
            .into_par_iter()
            .enumerate()
            .for_each(|(c, mut out)| match &self.batched {
                Some(batched) => {
                    let mut ws = batched.workspace(self.terms);
                    let (mut lq, mut lqd, mut lqdd) =
                        (vec![[0.0; LANES]; n], vec![[0.0; LANES]; n], vec![[0.0; LANES]; n]);
                    let len = out.first().map_or(0, |p| p.len() / n);
                    for k0 in (0..len).step_by(LANES) {
                        let lanes = LANES.min(len - k0);
                        // A short last pass repeats its last sample in the spare lanes.
                        for l in 0..LANES {
                            let k = first + c * CHUNK + k0 + l.min(lanes - 1);
                            for j in 0..n {
                                (lq[j][l], lqd[j][l], lqdd[j][l]) = (q[j][k], qd[j][k], qdd[j][k]);
                            }
                        }
                        batched.regressor(&mut ws, &lq, &lqd, &lqdd, self.terms);
                        for (bi, (col, _, _)) in self.columns.iter().enumerate() {
                            for j in 0..n {
                                let v = ws.phi(j, *col);
                                for (l, x) in v.iter().take(lanes).enumerate() {
                                    out[bi][(k0 + l) * n + j] = *x;
                                }
                            }
                        }
                    }
                }
                None => {
                    let mut ws = self.workspace();
                    let (mut sq, mut sqd, mut sqdd) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
                    let mut row = vec![0.0; n * nb];
                    let len = out.first().map_or(0, |p| p.len() / n);
                    for local in 0..len {
                        let k = first + c * CHUNK + local;
                        for j in 0..n {
                            sq[j] = q[j][k];
                            sqd[j] = qd[j][k];
                            sqdd[j] = qdd[j][k];
                        }
                        self.rows(&mut ws, &sq, &sqd, &sqdd, &mut row);
                        for j in 0..n {
                            for (bi, piece) in out.iter_mut().enumerate() {
                                piece[local * n + j] = row[j * nb + bi];
                            }
                        }
                    }
                }
            });
        a
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

/// `model` with the configuration's friction shapes: its Coulomb
/// transition, and its Stribeck fades in place of the robot file's (a
/// joint the configuration does not name has none, where it names any).
fn with_friction_shapes(model: &Model, spec: &RegressorModel) -> Result<Model> {
    let mut model = model.clone();
    if let Some(v) = spec.coulomb_transition_rad_s {
        if !(v >= 0.0) {
            return Err(Error::setting("coulomb_transition_rad_s", "≥ 0 rad/s", v));
        }
        model.friction.iter_mut().for_each(|f| f.transition = v);
    }
    if !spec.stribeck.is_empty() {
        for (name, s) in &spec.stribeck {
            if !model.joints.iter().any(|j| j.name == *name) {
                return Err(Error::mismatch(
                    "stribeck: joint",
                    format!("one of {}", model.joint_names().join(", ")),
                    name,
                ));
            }
            if !(s.velocity_rad_s > 0.0 && s.velocity_rad_s.is_finite() && s.exponent > 0.0 && s.exponent <= 10.0) {
                return Err(Error::setting(
                    "stribeck",
                    "velocity_rad_s > 0 and exponent in (0, 10]",
                    format!("{name}: {} rad/s, δ {}", s.velocity_rad_s, s.exponent),
                ));
            }
        }
        // The configuration's shapes replace the robot file's (which
        // stand where it names none): a joint not named has none.
        for (j, f) in model.friction.iter_mut().enumerate() {
            f.stribeck = match spec.stribeck.get(&model.joints[j].name) {
                Some(s) => Stribeck {
                    velocity: s.velocity_rad_s,
                    exponent: s.exponent,
                    ..f.stribeck
                },
                None => Stribeck::default(),
            };
        }
    }
    Ok(model)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every fade on identify's Stribeck grid keeps each joint's static
    /// excess as a base parameter: the base set is found on random states
    /// whose speeds (±2 rad/s) seldom fall inside a slow fade.
    #[test]
    fn every_stribeck_fade_keeps_its_column() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/robots/ur5.toml");
        let model = crate::dynamics::load_robot(&path).unwrap();
        for vs in [0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5] {
            for d in [0.5, 1.0, 2.0] {
                let spec = RegressorModel {
                    friction: FrictionTerms::Stribeck,
                    stribeck: model
                        .joints
                        .iter()
                        .map(|j| {
                            (
                                j.name.clone(),
                                StribeckShape {
                                    velocity_rad_s: vs,
                                    exponent: d,
                                },
                            )
                        })
                        .collect(),
                    ..RegressorModel::default()
                };
                let b = BaseRegressor::new(&model, &spec).unwrap();
                let fs = b.names().iter().filter(|n| n.starts_with("Fs_")).count();
                assert_eq!(fs, model.dof(), "vs {vs}, δ {d}: {:?}", b.names());
            }
        }
    }

    /// The whole-table matrix (batched, four samples per pass, straight into
    /// columns) equals the per-sample rows, on a length that fills neither a
    /// pass nor a chunk, for the chain and the decoupled model.
    /// The shared build is the one `new` makes, handed out again for the
    /// same robot and settings, and another for other settings.
    #[test]
    fn shared_builds_are_the_same_build() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/robots/ur5.toml");
        let model = crate::dynamics::load_robot(&path).unwrap();
        let spec = RegressorModel::default();
        let a = BaseRegressor::shared(&model, &spec).unwrap();
        let b = BaseRegressor::shared(&model, &spec).unwrap();
        assert!(Arc::ptr_eq(&a, &b));
        let fresh = BaseRegressor::new(&model, &spec).unwrap();
        assert_eq!(a.names(), fresh.names());
        assert_eq!(a.map(), fresh.map());
        let other = RegressorModel {
            coulomb_transition_rad_s: Some(0.02),
            ..spec.clone()
        };
        let c = BaseRegressor::shared(&model, &other).unwrap();
        assert!(!Arc::ptr_eq(&a, &c));
        assert_eq!(c.model.friction[0].transition, 0.02);
        let mut heavier = model.clone();
        heavier.links[1].mass *= 2.0;
        assert!(!Arc::ptr_eq(&a, &BaseRegressor::shared(&heavier, &spec).unwrap()));
    }

    #[test]
    fn matrix_equals_the_rows_of_each_sample() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/robots/ur5.toml");
        let model = crate::dynamics::load_robot(&path).unwrap();
        let n = model.dof();
        let samples = 2 * 256 + 7;
        let wave = |j: usize, d: usize| -> Vec<f64> {
            (0..samples)
                .map(|k| ((1 + j + d) as f64 * 0.013 * k as f64 + d as f64).sin() * (1 + d) as f64)
                .collect()
        };
        let kin = Kinematics {
            joints: model.joint_names(),
            time: (0..samples).map(|k| k as f64 * 0.01).collect(),
            q: (0..n).map(|j| wave(j, 0)).collect(),
            qd: (0..n).map(|j| wave(j, 1)).collect(),
            qdd: (0..n).map(|j| wave(j, 2)).collect(),
            torque: None,
            metadata: Default::default(),
        };
        let specs = [
            RegressorModel {
                friction: FrictionTerms::Asymmetric,
                offset: true,
                ..Default::default()
            },
            RegressorModel {
                model: ModelKind::Decoupled,
                rotor: Some(false),
                ..Default::default()
            },
        ];
        for spec in specs {
            let base = BaseRegressor::new(&model, &spec).unwrap();
            let a = base.matrix(&kin);
            let nb = base.parameters();
            assert_eq!(a.shape(), (samples * n, nb));
            let mut ws = base.workspace();
            let mut rows = vec![0.0; n * nb];
            for k in 0..samples {
                let at = |x: &Vec<Vec<f64>>| x.iter().map(|c| c[k]).collect::<Vec<_>>();
                base.rows(&mut ws, &at(&kin.q), &at(&kin.qd), &at(&kin.qdd), &mut rows);
                for j in 0..n {
                    for c in 0..nb {
                        let (got, want) = (a[(k * n + j, c)], rows[j * nb + c]);
                        assert!(
                            (got - want).abs() <= 1e-12 * want.abs().max(1.0),
                            "{:?} sample {k} row {j} col {c}: {got} vs {want}",
                            spec.model
                        );
                    }
                }
            }
        }
    }

    /// Newton–Euler on the full parameters gives the base rows' torques,
    /// for values no body has (θ drawn at random, the payload's added to
    /// the last link's) and every kind of joint column.
    #[test]
    fn torque_of_the_full_values_is_the_rows_times_theta() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/robots/ur5.toml");
        let model = crate::dynamics::load_robot(&path).unwrap();
        let n = model.dof();
        let spring = SpringConfig {
            joint: model.joints[1].name.clone(),
            harmonics: 2,
        };
        let stribeck = model
            .joints
            .iter()
            .map(|j| {
                let shape = StribeckShape {
                    velocity_rad_s: 0.1,
                    exponent: 1.5,
                };
                (j.name.clone(), shape)
            })
            .collect();
        let specs = [
            RegressorModel::default(),
            RegressorModel {
                friction: FrictionTerms::StribeckAsymmetric,
                rotor: Some(true),
                offset: true,
                coulomb_transition_rad_s: Some(0.02),
                spring: Some(spring),
                payload: true,
                stribeck,
                ..Default::default()
            },
        ];
        let mut seed = 7u64;
        let mut draw = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        for spec in specs {
            let base = BaseRegressor::new(&model, &spec).unwrap();
            let nb = base.parameters();
            let theta: Vec<f64> = (0..nb).map(|_| draw()).collect();
            let full = base.full_values(&theta).unwrap();
            let mut ws = base.workspace();
            let (mut rows, mut got) = (vec![0.0; n * nb], vec![0.0; n]);
            for _ in 0..50 {
                let state: Vec<Vec<f64>> = (0..3)
                    .map(|d| (0..n).map(|_| (1 + d) as f64 * draw()).collect())
                    .collect();
                let (q, qd, qdd) = (&state[0][..], &state[1][..], &state[2][..]);
                base.rows(&mut ws, q, qd, qdd, &mut rows);
                base.torque(&mut ws, (q, qd, qdd), &full, &mut got);
                for j in 0..n {
                    let want: f64 = rows[j * nb..(j + 1) * nb].iter().zip(&theta).map(|(y, v)| y * v).sum();
                    let scale: f64 = rows[j * nb..(j + 1) * nb]
                        .iter()
                        .zip(&theta)
                        .map(|(y, v)| (y * v).abs())
                        .sum();
                    assert!(
                        (got[j] - want).abs() <= 1e-12 * scale.max(1.0),
                        "payload {} joint {j}: {} vs {want}",
                        spec.payload,
                        got[j]
                    );
                }
            }
        }
        let decoupled = RegressorModel {
            model: ModelKind::Decoupled,
            rotor: Some(false),
            ..Default::default()
        };
        let base = BaseRegressor::new(&model, &decoupled).unwrap();
        assert!(base.full_values(&vec![0.0; base.parameters()]).is_none());
    }
}
