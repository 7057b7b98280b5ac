//! The inverse-dynamics regressor Φ(q, q̇, q̈) with τ = Φ·θ (Swevers eq. 2,
//! Bona eq. 9), by the Newton–Euler recursion written in its regressor form.
//!
//! Per link, the 10 standard inertial parameters about the link-frame
//! origin, in this order: XX, XY, XZ, YY, YZ, ZZ (inertia), MX, MY, MZ
//! (first moments m·c), M (mass). Per joint, optionally: Ia (rotor inertia
//! seen at the joint), friction (Fv, Fc; or Fv+, Fv−, Fc+, Fc− as Bona eq.
//! 2), Off (torque offset). The link's own wrench about its origin is linear
//! in its parameters:
//!   f = M·a + (S(ω̇) + S(ω)²)·h,
//!   n = K(ω̇)·ι + S(ω)·K(ω)·ι − S(a)·h,
//! with h the first moments, ι the inertia components, K(v)·ι = I·v, and a
//! the link origin's acceleration with gravity; joint j's torque sums the
//! wrenches of links i ≥ j carried back to frame j, projected on its axis.

use nalgebra::{DMatrix, Matrix3, SMatrix, Vector3};

use super::rnea::kinematics;
use super::{Data, Model};

/// Which joint terms the regressor carries besides the link inertials.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RegressorTerms {
    pub rotor: bool,
    pub friction: FrictionTerms,
    pub offset: bool,
    /// Swevers eq. 9: a gravity-compensation spring (plus gravity) on one
    /// joint as a finite Fourier series in its angle, Σ_l A_l cos(l·q) + B_l sin(l·q).
    pub spring: Option<Spring>,
}

/// Which joint carries the spring terms and how many harmonics they have.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Spring {
    pub joint: usize,
    pub harmonics: u32,
}

/// The friction columns of each joint.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FrictionTerms {
    None,
    /// Fv·q̇ + Fc·sign(q̇).
    Symmetric,
    /// Bona eq. 2: separate coefficients for each sign of q̇.
    Asymmetric,
    /// Symmetric, and Stribeck's static excess Fs·exp(−(|q̇|/vs)^δ)·sign(q̇)
    /// with each joint's own fade (`Friction::stribeck`; a joint without
    /// one has a zero column, which the base parameters leave out).
    Stribeck,
    /// Asymmetric, and the static excess for each sign of q̇.
    StribeckAsymmetric,
}

impl FrictionTerms {
    /// Columns per joint.
    pub fn width(self) -> usize {
        match self {
            FrictionTerms::None => 0,
            FrictionTerms::Symmetric => 2,
            FrictionTerms::Asymmetric => 4,
            FrictionTerms::Stribeck => 3,
            FrictionTerms::StribeckAsymmetric => 6,
        }
    }

    /// The same model with Stribeck's excess (`true`) or without.
    pub fn with_stribeck(self, stribeck: bool) -> FrictionTerms {
        match (self, stribeck) {
            (FrictionTerms::Symmetric | FrictionTerms::Stribeck, true) => FrictionTerms::Stribeck,
            (FrictionTerms::Asymmetric | FrictionTerms::StribeckAsymmetric, true) => FrictionTerms::StribeckAsymmetric,
            (FrictionTerms::Stribeck, false) => FrictionTerms::Symmetric,
            (FrictionTerms::StribeckAsymmetric, false) => FrictionTerms::Asymmetric,
            (other, _) => other,
        }
    }

    /// Whether Stribeck's excess is among the columns.
    pub fn has_stribeck(self) -> bool {
        matches!(self, FrictionTerms::Stribeck | FrictionTerms::StribeckAsymmetric)
    }

    /// Whether viscous and Coulomb friction differ by direction.
    pub fn is_asymmetric(self) -> bool {
        matches!(self, FrictionTerms::Asymmetric | FrictionTerms::StribeckAsymmetric)
    }

    /// Whether column `index` of a joint's friction (as [`friction_values`]
    /// orders them) is a Stribeck fade's: the one column whose function
    /// depends on the joint's fade.
    pub fn is_fade(self, index: usize) -> bool {
        match self {
            FrictionTerms::Stribeck => index == 2,
            FrictionTerms::StribeckAsymmetric => index >= 4,
            _ => false,
        }
    }

    /// Whether column `index` of a joint's friction (as [`friction_values`]
    /// orders them) is Coulomb's: sign or tanh of q̇, one-sided or not.
    pub fn is_coulomb(self, index: usize) -> bool {
        match self {
            FrictionTerms::None => false,
            FrictionTerms::Symmetric => index == 1,
            FrictionTerms::Asymmetric => index >= 2,
            FrictionTerms::Stribeck => index >= 1,
            FrictionTerms::StribeckAsymmetric => index >= 2,
        }
    }

    /// Whether column `index` is smooth in q̇: only the symmetric viscous
    /// one (linear); the others have a kink or a jump at q̇ = 0.
    pub fn is_smooth(self, index: usize) -> bool {
        matches!(self, FrictionTerms::Symmetric | FrictionTerms::Stribeck) && index == 0
    }
}

impl RegressorTerms {
    /// Rotor inertia and symmetric friction: Swevers' and Bona's models.
    pub const DEFAULT: RegressorTerms = RegressorTerms {
        rotor: true,
        friction: FrictionTerms::Symmetric,
        offset: false,
        spring: None,
    };

    pub(crate) fn per_joint(&self) -> usize {
        self.rotor as usize + self.friction.width() + self.offset as usize
    }

    /// Number of parameters of `model`'s regressor: each joint's, the
    /// spring's, and each coupled motor's friction ([`MOTOR_COLUMNS`]).
    pub fn count(&self, model: &Model) -> usize {
        self.motors_at(model.dof()) + MOTOR_COLUMNS * model.couplings.len()
    }

    /// The first coupled motor's friction column, for `n` joints: past the
    /// joints' and the spring's.
    pub(crate) fn motors_at(&self, n: usize) -> usize {
        n * (10 + self.per_joint()) + self.spring.map_or(0, |s| 2 * s.harmonics as usize)
    }
}

/// Columns per coupled motor: its viscous and Coulomb friction (motor
/// side; its rotor is its joint's `Ia`, whose column carries the coupling).
pub const MOTOR_COLUMNS: usize = 2;

/// Parameter name prefixes (before `_<joint>`).
const INERTIAL: [&str; 10] = ["XX", "XY", "XZ", "YY", "YZ", "ZZ", "MX", "MY", "MZ", "M"];

/// Parameter names (`ZZ_<joint>`, `Fv_<joint>`, …), in column order.
pub fn parameter_names(model: &Model, terms: RegressorTerms) -> Vec<String> {
    let mut names = Vec::with_capacity(terms.count(model));
    for j in &model.joints {
        names.extend(INERTIAL.iter().map(|p| format!("{p}_{}", j.name)));
    }
    for j in &model.joints {
        let n = &j.name;
        if terms.rotor {
            names.push(format!("Ia_{n}"));
        }
        names.extend(friction_names(terms.friction, n));
        if terms.offset {
            names.push(format!("Off_{n}"));
        }
    }
    if let Some(sp) = terms.spring {
        let n = &model.joints[sp.joint].name;
        for l in 1..=sp.harmonics {
            names.extend([format!("SpA{l}_{n}"), format!("SpB{l}_{n}")]);
        }
    }
    for c in &model.couplings {
        let n = &model.joints[c.motor].name;
        names.extend([format!("Fvm_{n}"), format!("Fcm_{n}")]);
    }
    names
}

/// What a standard parameter is: [`parameter_names`] writes the kind as
/// the name's prefix (`ZZ_<joint>`), and this is the one place that reads
/// it back (tables carry names only).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParameterKind {
    /// A link's second moment about its origin (XX … ZZ), kg·m².
    Inertia,
    /// A link's first moment (MX, MY, MZ), kg·m.
    FirstMoment,
    /// A link's mass, kg.
    Mass,
    /// A drive's rotor inertia seen at the joint, kg·m².
    RotorInertia,
    /// The decoupled model's inertia about a joint (`Mi`), kg·m².
    JointInertia,
    /// The decoupled model's gravity coefficients (`Gs`, `Gc`), N·m.
    Gravity,
    /// Viscous friction, N·m·s/rad: both directions, or one (Bona's
    /// asymmetric friction, `Fv+`/`Fv-`).
    Viscous { one_sided: bool },
    /// Coulomb friction, N·m: both directions, or one (`Fc+`/`Fc-`).
    Coulomb { one_sided: bool },
    /// Stribeck's static excess over Coulomb at rest, N·m (`Fs`, or
    /// `Fs+`/`Fs-`), fading with speed by the joint's own shape.
    Static { one_sided: bool },
    /// A coupled motor's viscous friction at its own speed, motor side,
    /// N·m·s/rad (`Fvm`).
    MotorViscous,
    /// A coupled motor's Coulomb friction, motor side, N·m (`Fcm`).
    MotorCoulomb,
    /// A constant torque offset, N·m.
    Offset,
    /// A spring's Fourier coefficient, N·m.
    Spring,
    /// A name robotid does not make (a table from elsewhere).
    Unknown,
}

impl ParameterKind {
    /// The kind of a standard parameter named by [`parameter_names`].
    pub fn of(name: &str) -> ParameterKind {
        match name.split('_').next().unwrap_or("") {
            "XX" | "XY" | "XZ" | "YY" | "YZ" | "ZZ" => ParameterKind::Inertia,
            "MX" | "MY" | "MZ" => ParameterKind::FirstMoment,
            "M" => ParameterKind::Mass,
            "Ia" => ParameterKind::RotorInertia,
            "Mi" => ParameterKind::JointInertia,
            "Gs" | "Gc" => ParameterKind::Gravity,
            "Fv" => ParameterKind::Viscous { one_sided: false },
            "Fv+" | "Fv-" => ParameterKind::Viscous { one_sided: true },
            "Fc" => ParameterKind::Coulomb { one_sided: false },
            "Fc+" | "Fc-" => ParameterKind::Coulomb { one_sided: true },
            "Fs" => ParameterKind::Static { one_sided: false },
            "Fs+" | "Fs-" => ParameterKind::Static { one_sided: true },
            "Fvm" => ParameterKind::MotorViscous,
            "Fcm" => ParameterKind::MotorCoulomb,
            "Off" => ParameterKind::Offset,
            p if p.starts_with("SpA") || p.starts_with("SpB") => ParameterKind::Spring,
            _ => ParameterKind::Unknown,
        }
    }

    /// One of a link's ten inertial parameters.
    pub fn is_inertial(self) -> bool {
        matches!(
            self,
            ParameterKind::Inertia | ParameterKind::FirstMoment | ParameterKind::Mass
        )
    }

    /// Friction, either kind.
    pub fn is_friction(self) -> bool {
        matches!(
            self,
            ParameterKind::Viscous { .. } | ParameterKind::Coulomb { .. } | ParameterKind::Static { .. }
        )
    }

    /// A magnitude no physical drive has below zero.
    pub fn non_negative(self) -> bool {
        matches!(
            self,
            ParameterKind::RotorInertia
                | ParameterKind::JointInertia
                | ParameterKind::Viscous { .. }
                | ParameterKind::Coulomb { .. }
                | ParameterKind::Static { .. }
                | ParameterKind::MotorViscous
                | ParameterKind::MotorCoulomb
        )
    }

    pub fn unit(self) -> &'static str {
        match self {
            ParameterKind::Inertia | ParameterKind::RotorInertia | ParameterKind::JointInertia => "kg*m^2",
            ParameterKind::FirstMoment => "kg*m",
            ParameterKind::Mass => "kg",
            ParameterKind::Viscous { .. } | ParameterKind::MotorViscous => "N*m*s/rad",
            ParameterKind::Coulomb { .. }
            | ParameterKind::MotorCoulomb
            | ParameterKind::Static { .. }
            | ParameterKind::Gravity
            | ParameterKind::Offset
            | ParameterKind::Spring
            | ParameterKind::Unknown => "N*m",
        }
    }
}

/// The unit of a parameter.
pub fn parameter_unit(name: &str) -> &'static str {
    ParameterKind::of(name).unit()
}

/// A link's 10 standard parameters [XX XY XZ YY YZ ZZ MX MY MZ M] from its
/// inertia about the link origin, first moment and mass.
pub fn inertial_parameters(i: &Matrix3<f64>, h: &Vector3<f64>, mass: f64) -> [f64; 10] {
    let [xx, xy, xz, yy, yz, zz] = upper(i);
    [xx, xy, xz, yy, yz, zz, h.x, h.y, h.z, mass]
}

/// An inertia's six values [xx xy xz yy yz zz] (its upper triangle).
pub fn upper(i: &Matrix3<f64>) -> [f64; 6] {
    [i[(0, 0)], i[(0, 1)], i[(0, 2)], i[(1, 1)], i[(1, 2)], i[(2, 2)]]
}

/// The model's own parameter values in [`parameter_names`] order. With
/// symmetric terms, asymmetric friction is averaged.
pub fn standard_parameters(model: &Model, terms: RegressorTerms) -> Vec<f64> {
    let mut theta = Vec::with_capacity(terms.count(model));
    for l in &model.links {
        theta.extend(l.standard());
    }
    for (d, f) in model.drives.iter().zip(&model.friction) {
        if terms.rotor {
            theta.push(d.reflected_inertia());
        }
        match terms.friction {
            FrictionTerms::None => {}
            FrictionTerms::Symmetric => theta.extend([
                0.5 * (f.viscous_pos + f.viscous_neg),
                0.5 * (f.coulomb_pos + f.coulomb_neg),
            ]),
            FrictionTerms::Asymmetric => theta.extend([f.viscous_pos, f.viscous_neg, f.coulomb_pos, f.coulomb_neg]),
            FrictionTerms::Stribeck => theta.extend([
                0.5 * (f.viscous_pos + f.viscous_neg),
                0.5 * (f.coulomb_pos + f.coulomb_neg),
                0.5 * (f.stribeck.excess_pos + f.stribeck.excess_neg),
            ]),
            FrictionTerms::StribeckAsymmetric => theta.extend([
                f.viscous_pos,
                f.viscous_neg,
                f.coulomb_pos,
                f.coulomb_neg,
                f.stribeck.excess_pos,
                f.stribeck.excess_neg,
            ]),
        }
        if terms.offset {
            theta.push(f.offset);
        }
    }
    // The model has no spring: its Fourier coefficients are zero.
    if let Some(sp) = terms.spring {
        theta.extend(std::iter::repeat_n(0.0, 2 * sp.harmonics as usize));
    }
    for c in &model.couplings {
        theta.extend([c.viscous, c.coulomb]);
    }
    theta
}

/// The inverse of [`standard_parameters`]: a copy of `model` with its
/// inertials, reflected rotor inertias (the rotor inertia is set so that
/// rotor·gear² matches), friction and offsets taken from `theta`. Spring
/// coefficients have no place in the model and are ignored.
pub fn with_standard_parameters(model: &Model, terms: RegressorTerms, theta: &[f64]) -> Model {
    assert_eq!(theta.len(), terms.count(model), "standard parameter count");
    let mut m = model.clone();
    for (k, l) in m.links.iter_mut().enumerate() {
        let t = &theta[10 * k..10 * k + 10];
        let io = Matrix3::new(t[0], t[1], t[2], t[1], t[3], t[4], t[2], t[4], t[5]);
        let h = Vector3::new(t[6], t[7], t[8]);
        let mass = t[9];
        let com = if mass > 0.0 { h / mass } else { Vector3::zeros() };
        l.mass = mass;
        l.com = com;
        l.inertia_com = io - (Matrix3::identity() * com.dot(&com) - com * com.transpose()) * mass;
    }
    let mut at = 10 * m.dof();
    for j in 0..m.dof() {
        if terms.rotor {
            let g2 = m.drives[j].gear_ratio * m.drives[j].gear_ratio;
            if g2 > 0.0 {
                m.drives[j].rotor_inertia = theta[at] / g2;
            }
            at += 1;
        }
        let f = &mut m.friction[j];
        match terms.friction {
            FrictionTerms::None => {}
            FrictionTerms::Symmetric => {
                (f.viscous_pos, f.viscous_neg) = (theta[at], theta[at]);
                (f.coulomb_pos, f.coulomb_neg) = (theta[at + 1], theta[at + 1]);
                at += 2;
            }
            FrictionTerms::Asymmetric => {
                (f.viscous_pos, f.viscous_neg) = (theta[at], theta[at + 1]);
                (f.coulomb_pos, f.coulomb_neg) = (theta[at + 2], theta[at + 3]);
                at += 4;
            }
            FrictionTerms::Stribeck => {
                (f.viscous_pos, f.viscous_neg) = (theta[at], theta[at]);
                (f.coulomb_pos, f.coulomb_neg) = (theta[at + 1], theta[at + 1]);
                (f.stribeck.excess_pos, f.stribeck.excess_neg) = (theta[at + 2], theta[at + 2]);
                at += 3;
            }
            FrictionTerms::StribeckAsymmetric => {
                (f.viscous_pos, f.viscous_neg) = (theta[at], theta[at + 1]);
                (f.coulomb_pos, f.coulomb_neg) = (theta[at + 2], theta[at + 3]);
                (f.stribeck.excess_pos, f.stribeck.excess_neg) = (theta[at + 4], theta[at + 5]);
                at += 6;
            }
        }
        if terms.offset {
            f.offset = theta[at];
            at += 1;
        }
    }
    let at = terms.motors_at(m.dof());
    for (k, c) in m.couplings.iter_mut().enumerate() {
        (c.viscous, c.coulomb) = (theta[at + MOTOR_COLUMNS * k], theta[at + MOTOR_COLUMNS * k + 1]);
    }
    m
}

fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// K(v) with I·v = K(v)·[XX, XY, XZ, YY, YZ, ZZ].
fn k_of(v: &Vector3<f64>) -> SMatrix<f64, 3, 6> {
    SMatrix::<f64, 3, 6>::new(
        v.x, v.y, v.z, 0.0, 0.0, 0.0, 0.0, v.x, 0.0, v.y, v.z, 0.0, 0.0, 0.0, v.x, 0.0, v.y, v.z,
    )
}

/// Fills `out` (n × terms.count(model)) with Φ(q, q̇, q̈). `transition` of each
/// joint's friction shapes the Coulomb column as in the model (sign or tanh).
pub fn regressor(
    model: &Model,
    data: &mut Data,
    q: &[f64],
    qd: &[f64],
    qdd: &[f64],
    terms: RegressorTerms,
    out: &mut DMatrix<f64>,
) {
    let n = model.dof();
    assert_eq!(
        out.shape(),
        (n, terms.count(model)),
        "regressor: output matrix has the wrong shape"
    );
    kinematics(model, data, q, qd, qdd, true);
    out.fill(0.0);
    for i in 0..n {
        let (w, dw, a) = (data.omega[i], data.domega[i], data.acc[i]);
        // Link i's own wrench regressor, frame i: force rows F, moment rows M (3 × 10 each).
        let mut f = SMatrix::<f64, 3, 10>::zeros();
        let mut m = SMatrix::<f64, 3, 10>::zeros();
        let sw = skew(&w);
        f.fixed_view_mut::<3, 3>(0, 6).copy_from(&(skew(&dw) + sw * sw));
        f.fixed_view_mut::<3, 1>(0, 9).copy_from(&a);
        m.fixed_view_mut::<3, 6>(0, 0).copy_from(&(k_of(&dw) + sw * k_of(&w)));
        m.fixed_view_mut::<3, 3>(0, 6).copy_from(&(-skew(&a)));
        // Carry it back to every joint j ≤ i.
        for j in (0..=i).rev() {
            let z = model.joints[j].axis.into_inner();
            let row = z.transpose() * m;
            for c in 0..10 {
                out[(j, 10 * i + c)] = row[c];
            }
            if j > 0 {
                let r = data.rot[j];
                let p = skew(&model.joints[j].origin_xyz);
                let rf = r * f;
                m = r * m + p * rf;
                f = rf;
            }
        }
    }
    joint_columns(model, (q, qd, qdd), terms, out);
}

/// The columns of Φ(q, q̇, q̈) past the links' 10·n: each joint's own
/// (rotor, friction, offset, spring) and the coupled motors' ([`coupled`]),
/// into `out`; the rest untouched.
pub(crate) fn joint_columns(
    model: &Model,
    (q, qd, qdd): (&[f64], &[f64], &[f64]),
    terms: RegressorTerms,
    out: &mut DMatrix<f64>,
) {
    let n = model.dof();
    let per = terms.per_joint();
    for j in 0..n {
        let mut c = 10 * n + per * j;
        if terms.rotor {
            out[(j, c)] = qdd[j];
            c += 1;
        }
        c += friction_columns(terms.friction, &model.friction[j], qd[j], out, j, c);
        if terms.offset {
            out[(j, c)] = 1.0;
        }
    }
    if let Some(sp) = terms.spring {
        let c0 = n * (10 + per);
        for l in 1..=sp.harmonics as usize {
            let (s, c) = (l as f64 * q[sp.joint]).sin_cos();
            out[(sp.joint, c0 + 2 * (l - 1))] = c;
            out[(sp.joint, c0 + 2 * (l - 1) + 1)] = s;
        }
    }
    coupled(model, (qd, qdd), terms, &mut |row, col, v| out[(row, col)] = v);
}

/// Each coupled motor's columns, as (row, column, value) to `put`: its
/// rotor's `Ia` (J·gear², the motor's own joint's column) on every joint
/// it turns with, (r·q̈)·r/gear² with r its row of the transmission
/// (Rᵀ·J·R·q̈; q̈ alone where it is not coupled), and its friction at its
/// own speed θ̇ = r·q̇: θ̇·r (`Fvm`) and sign(θ̇)·r (`Fcm`; smoothed as its
/// joint's Coulomb friction is, [`Model::motor_sign`]).
pub(crate) fn coupled(
    model: &Model,
    (qd, qdd): (&[f64], &[f64]),
    terms: RegressorTerms,
    put: &mut dyn FnMut(usize, usize, f64),
) {
    let n = model.dof();
    let first = terms.motors_at(n);
    for (i, c) in model.couplings.iter().enumerate() {
        let (m, g) = (c.motor, model.drives[c.motor].gear_ratio);
        let speed = g * qd[m] + c.with.iter().map(|&(k, t)| t * qd[k]).sum::<f64>();
        let accel = g * qdd[m] + c.with.iter().map(|&(k, t)| t * qdd[k]).sum::<f64>();
        let sign = model.motor_sign(c, speed);
        let row = std::iter::once((m, g)).chain(c.with.iter().copied());
        let (viscous, coulomb) = (first + MOTOR_COLUMNS * i, first + MOTOR_COLUMNS * i + 1);
        for (k, r) in row {
            if terms.rotor {
                put(k, 10 * n + terms.per_joint() * m, accel * r / (g * g));
            }
            put(k, viscous, speed * r);
            put(k, coulomb, sign * r);
        }
    }
}

/// Names of one joint's friction parameters.
pub fn friction_names(friction: FrictionTerms, joint: &str) -> Vec<String> {
    match friction {
        FrictionTerms::None => Vec::new(),
        FrictionTerms::Symmetric => vec![format!("Fv_{joint}"), format!("Fc_{joint}")],
        FrictionTerms::Asymmetric => {
            vec![
                format!("Fv+_{joint}"),
                format!("Fv-_{joint}"),
                format!("Fc+_{joint}"),
                format!("Fc-_{joint}"),
            ]
        }
        FrictionTerms::Stribeck => vec![format!("Fv_{joint}"), format!("Fc_{joint}"), format!("Fs_{joint}")],
        FrictionTerms::StribeckAsymmetric => {
            vec![
                format!("Fv+_{joint}"),
                format!("Fv-_{joint}"),
                format!("Fc+_{joint}"),
                format!("Fc-_{joint}"),
                format!("Fs+_{joint}"),
                format!("Fs-_{joint}"),
            ]
        }
    }
}

/// The most friction columns a joint has ([`FrictionTerms::width`]).
pub const FRICTION_COLUMNS: usize = 6;

/// One joint's friction columns for joint velocity `qd`, and how many
/// there are; the Coulomb shape (sign or tanh) and the Stribeck fade are
/// the joint's.
pub(crate) fn friction_values(
    friction: FrictionTerms,
    model: &super::Friction,
    qd: f64,
) -> ([f64; FRICTION_COLUMNS], usize) {
    let sign = if model.transition > 0.0 {
        (qd / model.transition).tanh()
    } else {
        qd.signum() * (qd != 0.0) as i32 as f64
    };
    let pos = qd >= 0.0;
    let (up, down) = (sign.max(0.0), sign.min(0.0));
    match friction {
        FrictionTerms::None => ([0.0; FRICTION_COLUMNS], 0),
        FrictionTerms::Symmetric => ([qd, sign, 0.0, 0.0, 0.0, 0.0], 2),
        FrictionTerms::Asymmetric => match pos {
            true => ([qd, 0.0, up, 0.0, 0.0, 0.0], 4),
            false => ([0.0, qd, 0.0, down, 0.0, 0.0], 4),
        },
        FrictionTerms::Stribeck => ([qd, sign, sign * model.stribeck.fade(qd), 0.0, 0.0, 0.0], 3),
        FrictionTerms::StribeckAsymmetric => {
            let fade = model.stribeck.fade(qd);
            match pos {
                true => ([qd, 0.0, up, 0.0, up * fade, 0.0], 6),
                false => ([0.0, qd, 0.0, down, 0.0, down * fade], 6),
            }
        }
    }
}

/// Writes one joint's friction columns into `out[(row, col..)]`; returns
/// their number.
pub(crate) fn friction_columns(
    friction: FrictionTerms,
    model: &super::Friction,
    qd: f64,
    out: &mut DMatrix<f64>,
    row: usize,
    col: usize,
) -> usize {
    let (values, width) = friction_values(friction, model, qd);
    for (k, v) in values.iter().take(width).enumerate() {
        out[(row, col + k)] = *v;
    }
    width
}
