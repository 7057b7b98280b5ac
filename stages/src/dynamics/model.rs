//! The immutable robot description: a serial chain of revolute joints, each
//! carrying one rigid link, plus per-joint drive (gear, torque constant,
//! encoder, rotor) and friction data. Built once from a robot file
//! (`robot_file.rs`) or a URDF (`urdf.rs`); algorithms take `&Model` and a
//! preallocated [`super::Data`].

use crate::Problem;
use nalgebra::{Matrix3, Unit, Vector3};

/// Names and units of [`Inertial::listed`]: what a simulator's body
/// holds (the payload table, the domain-randomisation samples).
pub const LISTED: [(&str, &str); 10] = [
    ("mass", "kg"),
    ("com_x", "m"),
    ("com_y", "m"),
    ("com_z", "m"),
    ("ixx", "kg*m^2"),
    ("ixy", "kg*m^2"),
    ("ixz", "kg*m^2"),
    ("iyy", "kg*m^2"),
    ("iyz", "kg*m^2"),
    ("izz", "kg*m^2"),
];

/// Rigid-body inertia of one link, in the link frame (the frame of the joint
/// that moves it, after the joint rotation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Inertial {
    /// kg
    pub mass: f64,
    /// Centre of mass in the link frame, m.
    pub com: Vector3<f64>,
    /// Inertia tensor about the centre of mass, link-frame axes, kg·m².
    pub inertia_com: Matrix3<f64>,
}

impl Inertial {
    /// The body of ten standard parameters [XX XY XZ YY YZ ZZ MX MY MZ M]
    /// (inertia about the frame's origin); None without mass.
    pub fn of_standard(t: &[f64]) -> Option<Inertial> {
        let mass = t[9];
        if !(mass > 0.0) {
            return None;
        }
        let com = Vector3::new(t[6], t[7], t[8]) / mass;
        let origin = Matrix3::new(t[0], t[1], t[2], t[1], t[3], t[4], t[2], t[4], t[5]);
        let inertia_com = origin - (Matrix3::identity() * com.dot(&com) - com * com.transpose()) * mass;
        Some(Inertial { mass, com, inertia_com })
    }

    /// [mass, com x y z, Ixx Ixy Ixz Iyy Iyz Izz at the centre of mass]
    /// ([`LISTED`]), the inertia's off-diagonal the mean of its two.
    pub fn listed(&self) -> [f64; 10] {
        let c = self.com;
        let [xx, xy, xz, yy, yz, zz] = super::upper(&((self.inertia_com + self.inertia_com.transpose()) * 0.5));
        [self.mass, c.x, c.y, c.z, xx, xy, xz, yy, yz, zz]
    }

    /// Its ten standard parameters [XX XY XZ YY YZ ZZ MX MY MZ M].
    pub fn standard(&self) -> [f64; 10] {
        super::inertial_parameters(&self.inertia_origin(), &self.first_moment(), self.mass)
    }

    /// First moment of mass h = m·c, kg·m.
    pub fn first_moment(&self) -> Vector3<f64> {
        self.com * self.mass
    }

    /// Inertia about the link-frame origin (parallel-axis theorem), kg·m².
    pub fn inertia_origin(&self) -> Matrix3<f64> {
        let c = self.com;
        self.inertia_com + (Matrix3::identity() * c.dot(&c) - c * c.transpose()) * self.mass
    }

    /// The body left when `part` (given in this link's frame) is taken
    /// out; None when what is left is no body (mass ≤ 0, or an inertia
    /// about its centre of mass that is not positive definite or breaks
    /// the triangle inequality of its principal moments).
    pub fn without(&self, part: &Inertial) -> Option<Inertial> {
        let rest = self.minus(part)?;
        let p = rest.inertia_com.symmetric_eigenvalues();
        let scale = p.amax().max(f64::MIN_POSITIVE);
        let body = p.iter().all(|&e| e > 1e-9 * scale)
            && (0..3).all(|k| p[k] <= p[(k + 1) % 3] + p[(k + 2) % 3] + 1e-9 * scale);
        body.then_some(rest)
    }

    /// Mass, first moment and inertia about the origin less `part`'s,
    /// whatever is left (None: no mass left).
    pub fn minus(&self, part: &Inertial) -> Option<Inertial> {
        let mass = self.mass - part.mass;
        if !(mass > 0.0) {
            return None;
        }
        let com = (self.first_moment() - part.first_moment()) / mass;
        let origin = self.inertia_origin() - part.inertia_origin();
        let inertia_com = origin - (Matrix3::identity() * com.dot(&com) - com * com.transpose()) * mass;
        Some(Inertial { mass, com, inertia_com })
    }

    /// Adds a rigid body given in this link's frame (used to lump fixed
    /// children, e.g. a URDF tool flange, into the moving link).
    pub fn merge(&self, other: &Inertial) -> Inertial {
        let m = self.mass + other.mass;
        if m == 0.0 {
            return *self;
        }
        let com = (self.com * self.mass + other.com * other.mass) / m;
        let shift = |i: &Inertial| {
            let d = i.com - com;
            i.inertia_com + (Matrix3::identity() * d.dot(&d) - d * d.transpose()) * i.mass
        };
        Inertial {
            mass: m,
            com,
            inertia_com: shift(self) + shift(other),
        }
    }
}

/// Joint friction, joint side (Bona eq. 2): for q̇ > 0 the torque is
/// `viscous_pos·q̇ + coulomb_pos`, for q̇ < 0 `viscous_neg·q̇ − coulomb_neg`,
/// zero at rest; `offset` is added always. Coulomb values are magnitudes (≥ 0).
/// With `transition` > 0 the Coulomb term is smooth: it follows
/// tanh(q̇ / transition) instead of sign(q̇) (simulation, prediction near
/// zero velocity). With a Stribeck fade (`stribeck.velocity` > 0) the
/// static friction exceeds Coulomb's at rest and fades with speed:
/// Fs·exp(−(|q̇|/vs)^δ) more, in the Coulomb term's direction.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Friction {
    /// N·m·s/rad
    pub viscous_pos: f64,
    /// N·m·s/rad
    pub viscous_neg: f64,
    /// N·m
    pub coulomb_pos: f64,
    /// N·m
    pub coulomb_neg: f64,
    /// N·m
    pub offset: f64,
    /// Coulomb transition velocity, rad/s (0: exact sign).
    pub transition: f64,
    /// Static friction's excess over Coulomb's and how it fades.
    pub stribeck: Stribeck,
}

/// Stribeck's static friction: at rest the friction reaches Fc + Fs (per
/// direction), and the excess Fs fades with speed as exp(−(|q̇|/vs)^δ)
/// (Armstrong-Hélouvry's model; δ = 2 is Gaussian, δ = 1 exponential).
/// `velocity` 0: no excess, the joint's friction is Coulomb's and viscous.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Stribeck {
    /// The excess over Coulomb at rest, each direction, N·m (≥ 0).
    pub excess_pos: f64,
    pub excess_neg: f64,
    /// The speed it fades over, vs, rad/s.
    pub velocity: f64,
    /// The fade's exponent δ.
    pub exponent: f64,
}

impl Stribeck {
    /// The fade's shape alone, (vs, δ), with no excess yet.
    pub fn shape(velocity: f64, exponent: f64) -> Stribeck {
        Stribeck {
            velocity,
            exponent,
            ..Stribeck::default()
        }
    }

    /// exp(−(|q̇|/vs)^δ): 1 at rest, → 0 with speed; 0 without a fade.
    #[inline]
    pub fn fade(&self, qd: f64) -> f64 {
        match self.velocity > 0.0 {
            true => (-(qd.abs() / self.velocity).powf(self.exponent)).exp(),
            false => 0.0,
        }
    }
}

impl Friction {
    pub fn symmetric(viscous: f64, coulomb: f64) -> Friction {
        Friction {
            viscous_pos: viscous,
            viscous_neg: viscous,
            coulomb_pos: coulomb,
            coulomb_neg: coulomb,
            offset: 0.0,
            transition: 0.0,
            stribeck: Stribeck::default(),
        }
    }

    /// Friction torque at joint velocity `qd` (rad/s), N·m.
    #[inline]
    pub fn torque(&self, qd: f64) -> f64 {
        if self.transition > 0.0 {
            let s = (qd / self.transition).tanh();
            let (viscous, coulomb) = if qd >= 0.0 {
                (self.viscous_pos, self.coulomb_pos)
            } else {
                (self.viscous_neg, self.coulomb_neg)
            };
            let excess = if qd >= 0.0 {
                self.stribeck.excess_pos
            } else {
                self.stribeck.excess_neg
            };
            return self.offset + viscous * qd + (coulomb + excess * self.stribeck.fade(qd)) * s;
        }
        let fade = self.stribeck.fade(qd);
        self.offset
            + if qd > 0.0 {
                self.viscous_pos * qd + self.coulomb_pos + self.stribeck.excess_pos * fade
            } else if qd < 0.0 {
                self.viscous_neg * qd - self.coulomb_neg - self.stribeck.excess_neg * fade
            } else {
                0.0
            }
    }

    /// Stribeck's excess as the exports' `robotid:` comments carry it (no
    /// format has a place for it); empty without one.
    pub fn stribeck_said(&self) -> String {
        let s = &self.stribeck;
        match s.velocity > 0.0 && (s.excess_pos != 0.0 || s.excess_neg != 0.0) {
            true => format!(
                ", stribeck_excess_pos = {}, stribeck_excess_neg = {}, stribeck_velocity = {}, stribeck_exponent = {} (static friction over Coulomb's at rest, fading as exp(-(|qd|/velocity)^exponent); the format has no place for it)",
                s.excess_pos, s.excess_neg, s.velocity, s.exponent
            ),
            false => String::new(),
        }
    }

    pub fn is_zero(&self) -> bool {
        *self == Friction::default()
    }
}

/// The actuator of one joint: what turns motor current and encoder counts
/// into joint torque and angle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Drive {
    /// Motor turns per joint turn (|·| ≥ 1 for a reducer; negative where
    /// the motor turns the other way).
    pub gear_ratio: f64,
    /// Motor torque per ampere, N·m/A (motor side).
    pub torque_constant: f64,
    /// Encoder counts per motor revolution.
    pub encoder_counts_per_rev: f64,
    /// Rotor inertia, motor side, kg·m²; reflected to the joint as `J·gear²`.
    pub rotor_inertia: f64,
    /// The relative standard deviation of the joint torque per ampere
    /// (torque constant × gear ratio) as declared; None: not declared, and
    /// a current read through it carries [`DEFAULT_GAIN_REL_STD`].
    pub gain_rel_std: Option<f64>,
    /// The motor's angle at joint angle 0 (its encoder's calibration), rad
    /// motor side: a motor-side position θ reads as the joint's through
    /// θ − offset.
    pub motor_offset: f64,
}

/// A nominal drive gain's relative standard deviation where the robot
/// file declares none: motor data sheets give torque constants within
/// ±10 % (a uniform ±10 % has a 5.8 % std; 10 % also covers the gear's
/// efficiency, which no data sheet gives per unit).
pub const DEFAULT_GAIN_REL_STD: f64 = 0.10;

impl Default for Drive {
    fn default() -> Self {
        Drive {
            gear_ratio: 1.0,
            torque_constant: 1.0,
            encoder_counts_per_rev: 1_048_576.0,
            rotor_inertia: 0.0,
            gain_rel_std: None,
            motor_offset: 0.0,
        }
    }
}

impl Drive {
    /// Joint torque per ampere of motor current, N·m/A.
    pub fn joint_torque_per_amp(&self) -> f64 {
        self.torque_constant * self.gear_ratio
    }

    /// Joint angle of one encoder count, rad.
    pub fn radians_per_count(&self) -> f64 {
        2.0 * std::f64::consts::PI / (self.encoder_counts_per_rev * self.gear_ratio)
    }

    /// Rotor inertia seen at the joint, kg·m².
    pub fn reflected_inertia(&self) -> f64 {
        self.rotor_inertia * self.gear_ratio * self.gear_ratio
    }
}

/// Motion limits of one joint (used by the simulator's report and the
/// excitation design). `None` means unlimited.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Limits {
    /// rad
    pub position: Option<(f64, f64)>,
    /// rad/s (symmetric)
    pub velocity: Option<f64>,
    /// rad/s² (symmetric)
    pub acceleration: Option<f64>,
    /// N·m (symmetric)
    pub torque: Option<f64>,
}

/// A revolute joint: its frame relative to the parent link frame at q = 0
/// (rotation `origin_rot`, translation `origin_xyz`), then a rotation by q
/// about `axis` (expressed in the joint frame).
#[derive(Debug, Clone, PartialEq)]
pub struct Joint {
    pub name: String,
    pub origin_rot: Matrix3<f64>,
    pub origin_xyz: Vector3<f64>,
    pub axis: Unit<Vector3<f64>>,
}

/// A serial chain of revolute joints. Index i is joint i, the link it moves,
/// its drive, friction and limits.
#[derive(Debug, Clone, PartialEq)]
pub struct Model {
    pub name: String,
    /// Gravity vector in the base frame, m/s².
    pub gravity: Vector3<f64>,
    pub joints: Vec<Joint>,
    pub links: Vec<Inertial>,
    pub drives: Vec<Drive>,
    pub friction: Vec<Friction>,
    pub limits: Vec<Limits>,
    /// A point on the last link (its frame), m: the end effector for
    /// Cartesian constraints and plots.
    pub end_effector: Vector3<f64>,
    /// What loading the description tolerated (shown to the user).
    pub warnings: Vec<String>,
    /// Joints of the description locked out of the model, with their
    /// position (rad or m).
    pub locked: Vec<(String, f64)>,
    /// Whether the description says anything of the drives (gear, torque
    /// constant, encoder, rotor inertia): without that, rotor inertia is
    /// not part of the default identification model.
    pub drives_declared: bool,
    /// Per link, the box its shapes fill in its frame (URDF collision
    /// shapes, else visual ones), when the description has them: where
    /// its mass can be (the physical fit's bounds).
    pub extents: Vec<Option<Extent>>,
    /// Per link, its shapes in its frame (URDF collision shapes, else
    /// visual ones), for the exports' geometry; empty where the
    /// description has none.
    pub shapes: Vec<Vec<Shape>>,
    /// The base's shapes (the links before the first moving joint), in the
    /// base frame.
    pub base_shapes: Vec<Shape>,
    /// The description's links held rigidly by the last moving link (it
    /// too, first), each with its frame in that link's: (name, rotation,
    /// position). Where a payload can be declared.
    pub end_frames: Vec<(String, Matrix3<f64>, Vector3<f64>)>,
    /// Each end frame's link's own shapes, the box they fill in its own
    /// frame (None: it has none): a tool's geometry, where the description
    /// carries one.
    pub end_extents: Vec<Option<Extent>>,
    /// Motors that turn with more than their own joint (a coupled wrist),
    /// base first; every other motor turns with its joint alone, by its
    /// drive's gear ratio.
    pub couplings: Vec<Coupling>,
}

/// A motor that also turns with other joints: its angle is
/// θ = gear_ratio·q_motor + Σ turns·q_joint, so the transmission matrix R
/// (motor angles θ = R·q) has `turns` off its diagonal in this motor's row.
/// It acts on each joint it turns with: joint torques τ = Rᵀ·τ_motor, its
/// rotor inertia enters the mass matrix as Rᵀ·J·R.
#[derive(Debug, Clone, PartialEq)]
pub struct Coupling {
    /// The motor's own joint (its drive is that joint's).
    pub motor: usize,
    /// The other joints it turns with: (joint, motor turns per joint turn).
    pub with: Vec<(usize, f64)>,
    /// The motor's viscous friction, motor side, N·m·s/rad.
    pub viscous: f64,
    /// The motor's Coulomb friction, motor side, N·m (a magnitude).
    pub coulomb: f64,
}

/// A shape of a link, placed in its frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Shape {
    pub geometry: Geometry,
    pub rotation: Matrix3<f64>,
    pub position: Vector3<f64>,
}

/// What a shape is, m.
#[derive(Debug, Clone, PartialEq)]
pub enum Geometry {
    /// Half the box's sides.
    Box(Vector3<f64>),
    /// About the shape's z axis.
    Cylinder {
        radius: f64,
        half_length: f64,
    },
    Capsule {
        radius: f64,
        half_length: f64,
    },
    Sphere(f64),
    /// A mesh as the description names it, and the STL file it resolved to
    /// (None: not found, or not an STL).
    Mesh {
        name: String,
        file: Option<std::path::PathBuf>,
        scale: Vector3<f64>,
    },
}

/// An axis-aligned box in a link's frame, m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extent {
    pub min: Vector3<f64>,
    pub max: Vector3<f64>,
}

impl Extent {
    /// The smallest box holding `points` (None for none).
    pub fn of_points(points: impl IntoIterator<Item = Vector3<f64>>) -> Option<Extent> {
        points.into_iter().fold(None, |e: Option<Extent>, p| {
            Some(match e {
                None => Extent { min: p, max: p },
                Some(e) => Extent {
                    min: e.min.inf(&p),
                    max: e.max.sup(&p),
                },
            })
        })
    }

    /// The box holding both.
    pub fn union(&self, other: &Extent) -> Extent {
        Extent {
            min: self.min.inf(&other.min),
            max: self.max.sup(&other.max),
        }
    }

    /// Its eight corners.
    pub fn corners(&self) -> impl Iterator<Item = Vector3<f64>> + '_ {
        (0..8).map(move |k| {
            Vector3::new(
                if k & 1 == 0 { self.min.x } else { self.max.x },
                if k & 2 == 0 { self.min.y } else { self.max.y },
                if k & 4 == 0 { self.min.z } else { self.max.z },
            )
        })
    }
}

/// The largest values a body of a robot arm may have in a description:
/// far beyond any arm, far below where products of them overflow (a
/// 1e300 kg link made the SVD of the regressor panic, a NaN origin hung
/// the base-parameter search).
const MAX_MASS_KG: f64 = 1e6;
const MAX_LENGTH_M: f64 = 1e3;
const MAX_INERTIA: f64 = 1e9;
/// The most moving joints a model may have: arms have 6 or 7, humanoids a
/// few dozen; a 200-joint chain kept `lint` busy for over 300 s.
pub const MAX_JOINTS: usize = 64;

impl Model {
    /// Every number of the description finite and of a size a robot can
    /// have: masses up to 1e6 kg, lengths (origins, centres of mass, the
    /// end effector) within 1e3 m, inertias within 1e9 kg·m², drives and
    /// friction finite. The first value that is not, by joint and key.
    fn check_sizes(&self) -> Result<(), Problem> {
        let within = |v: f64, max: f64| v.is_finite() && v.abs() <= max;
        let bad = |key: &str, what: String, v: f64, range: &str| {
            Err(Problem::new(key, format!("{what} = {v:?} is not a robot's ({range})")))
        };
        for v in self.gravity.iter().chain(self.end_effector.iter()) {
            if !within(*v, MAX_LENGTH_M) {
                return bad("gravity", "gravity or end effector".into(), *v, "finite");
            }
        }
        for (i, (j, l)) in self.joints.iter().zip(&self.links).enumerate() {
            let ctx = format!("joint {} (`{}`)", i + 1, j.name);
            for v in j.origin_xyz.iter() {
                if !within(*v, MAX_LENGTH_M) {
                    return bad("origin", format!("{ctx}: origin"), *v, "finite, within 1e3 m");
                }
            }
            for v in j.origin_rot.iter().chain(j.axis.iter()) {
                if !v.is_finite() {
                    return bad("origin", format!("{ctx}: origin rotation or axis"), *v, "finite");
                }
            }
            if !(l.mass <= MAX_MASS_KG) {
                return bad("mass", format!("{ctx}: its link's mass"), l.mass, "0 to 1e6 kg");
            }
            for v in l.com.iter() {
                if !within(*v, MAX_LENGTH_M) {
                    return bad("com", format!("{ctx}: its link's centre of mass"), *v, "within 1e3 m");
                }
            }
            for v in l.inertia_com.iter() {
                if !within(*v, MAX_INERTIA) {
                    return bad("inertia", format!("{ctx}: its link's inertia"), *v, "within 1e9 kg·m²");
                }
            }
            let (d, f) = (&self.drives[i], &self.friction[i]);
            for (key, v) in [
                ("gear_ratio", d.gear_ratio),
                ("torque_constant", d.torque_constant),
                ("encoder_counts_per_rev", d.encoder_counts_per_rev),
                ("rotor_inertia", d.rotor_inertia),
                ("motor_offset", d.motor_offset),
                ("viscous", f.viscous_pos),
                ("viscous", f.viscous_neg),
                ("coulomb", f.coulomb_pos),
                ("coulomb", f.coulomb_neg),
                ("offset", f.offset),
                ("coulomb_transition", f.transition),
                ("stribeck_excess", f.stribeck.excess_pos),
                ("stribeck_excess", f.stribeck.excess_neg),
                ("stribeck_velocity", f.stribeck.velocity),
                ("stribeck_exponent", f.stribeck.exponent),
            ] {
                if !v.is_finite() {
                    return bad(key, format!("{ctx}: {key}"), v, "finite");
                }
            }
        }
        Ok(())
    }

    /// A model with no joints yet, for loaders to fill.
    pub fn empty(name: &str, gravity: Vector3<f64>) -> Model {
        Model {
            name: name.to_string(),
            gravity,
            joints: Vec::new(),
            links: Vec::new(),
            drives: Vec::new(),
            friction: Vec::new(),
            limits: Vec::new(),
            end_effector: Vector3::zeros(),
            warnings: Vec::new(),
            locked: Vec::new(),
            drives_declared: false,
            extents: Vec::new(),
            shapes: Vec::new(),
            base_shapes: Vec::new(),
            end_frames: Vec::new(),
            end_extents: Vec::new(),
            couplings: Vec::new(),
        }
    }

    /// Link `l`'s extent, when its description has shapes.
    pub fn extent(&self, l: usize) -> Option<Extent> {
        self.extents.get(l).copied().flatten()
    }

    /// The transmission matrix R: motor angles θ = R·q + offsets. Diagonal
    /// (the gear ratios) but for coupled motors' rows.
    pub fn transmission(&self) -> nalgebra::DMatrix<f64> {
        let n = self.dof();
        let mut r = nalgebra::DMatrix::from_diagonal(&nalgebra::DVector::from_iterator(
            n,
            self.drives.iter().map(|d| d.gear_ratio),
        ));
        for c in &self.couplings {
            for &(j, turns) in &c.with {
                r[(c.motor, j)] += turns;
            }
        }
        r
    }

    /// What a description without transmissions cannot hold of joint `i`'s
    /// motor, for the exports' `robotid:` comments: its offset and its
    /// coupling with friction ("" for a motor that turns with its joint
    /// alone from 0, so such comments stay as they were).
    pub fn motor_said(&self, i: usize) -> String {
        let mut said = String::new();
        if self.drives[i].motor_offset != 0.0 {
            said += &format!(", motor_offset = {} (motor side)", self.drives[i].motor_offset);
        }
        if let Some(c) = self.couplings.iter().find(|c| c.motor == i) {
            let with: Vec<String> = c
                .with
                .iter()
                .map(|&(j, t)| format!("{} = {t}", self.joints[j].name))
                .collect();
            said += &format!(
                ", coupling = {{ {} }} with motor_viscous = {}, motor_coulomb = {} (the motor turns with those joints too)",
                with.join(", "),
                c.viscous,
                c.coulomb
            );
        }
        said
    }

    /// What coupled motors add to joint torques `tau` beyond each joint's
    /// own terms (which hold J·gear²·q̈ of every rotor and the joints'
    /// friction): the rotor inertia's cross terms of Rᵀ·J·R·q̈ (`rotor`) and
    /// the motor's friction at its speed r·q̇ through Rᵀ (`friction`). Nothing
    /// without couplings.
    pub fn add_coupled_torque(&self, qd: &[f64], qdd: &[f64], (rotor, friction): (bool, bool), tau: &mut [f64]) {
        for c in &self.couplings {
            let m = c.motor;
            let (g, j_m) = (self.drives[m].gear_ratio, self.drives[m].rotor_inertia);
            let cross_qdd: f64 = c.with.iter().map(|&(k, t)| t * qdd[k]).sum();
            // The motor torque on the motor's own joint's row (less J·g²·q̈),
            // and the one every coupled joint sees through its turns.
            let (mut own, mut motor) = (0.0, 0.0);
            if rotor {
                own += j_m * g * cross_qdd;
                motor += j_m * (g * qdd[m] + cross_qdd);
            }
            if friction {
                let f = self.coupled_friction(c, qd);
                own += g * f;
                motor += f;
            }
            tau[m] += own;
            for &(k, t) in &c.with {
                tau[k] += t * motor;
            }
        }
    }

    /// A coupled motor's friction torque (motor side) at its speed θ̇ =
    /// g·q̇_motor + Σ turns·q̇: its Coulomb turn-over is its own joint's
    /// (`transition`, sign(θ̇) at 0) at the motor's speed, v·|g|, so that
    /// a model smoothed for the simulator or chosen by identify turns the
    /// coupled motor over alike.
    pub fn coupled_friction(&self, c: &Coupling, qd: &[f64]) -> f64 {
        let g = self.drives[c.motor].gear_ratio;
        let speed = g * qd[c.motor] + c.with.iter().map(|&(k, t)| t * qd[k]).sum::<f64>();
        c.viscous * speed + c.coulomb * self.motor_sign(c, speed)
    }

    /// sign(θ̇) of coupled motor `c`, or tanh(θ̇/(v·|gear|)) where its joint
    /// turns over smoothly at v.
    pub fn motor_sign(&self, c: &Coupling, speed: f64) -> f64 {
        let v = self.friction[c.motor].transition * self.drives[c.motor].gear_ratio.abs();
        match v > 0.0 {
            true => (speed / v).tanh(),
            false => speed.signum() * (speed != 0.0) as i32 as f64,
        }
    }

    /// The rotor inertia a simulator puts on joint `i` itself (MJCF
    /// `armature`): its reflected rotor, or 0 where its motor is coupled,
    /// whose rotor the motor's fixed tendon carries.
    pub fn own_armature(&self, i: usize) -> f64 {
        match self.couplings.iter().any(|c| c.motor == i) {
            true => 0.0,
            false => self.drives[i].reflected_inertia(),
        }
    }

    /// The coupled motors' friction through Rᵀ taken from joint torques
    /// `tau`: forward dynamics takes it, as each joint's own friction, from
    /// the torque that is left to accelerate the bodies.
    pub fn take_coupled_friction(&self, qd: &[f64], tau: &mut [f64]) {
        for c in &self.couplings {
            let g = self.drives[c.motor].gear_ratio;
            let f = self.coupled_friction(c, qd);
            tau[c.motor] -= g * f;
            for &(k, t) in &c.with {
                tau[k] -= t * f;
            }
        }
    }

    /// Number of joints (degrees of freedom).
    pub fn dof(&self) -> usize {
        self.joints.len()
    }

    pub fn joint_names(&self) -> Vec<String> {
        self.joints.iter().map(|j| j.name.clone()).collect()
    }

    /// Links whose inertia about the centre of mass no body has (a
    /// negative principal moment, or moments that break the triangle
    /// inequality: a typo in a widely copied URDF) taken as the nearest
    /// body's, each said in `warnings` with both sets of moments. The
    /// nearest in the mass's second moments Σ = ½tr(I)·1 − I, which a body
    /// has positive semidefinite: Σ's negative eigenvalues set to 0, the
    /// principal axes kept (I = tr(Σ)·1 − Σ). The link then serves as the
    /// physical fit's prior and the simulator's body; the data decide its
    /// identified values.
    pub fn make_bodies_physical(&mut self) {
        for (link, joint) in self.links.iter_mut().zip(&self.joints) {
            let ic = link.inertia_com;
            let scale = ic.abs().max();
            if !scale.is_finite() || (ic - ic.transpose()).abs().max() > 1e-12 * (1.0 + scale) {
                continue; // not symmetric or not finite: validate() refuses it
            }
            let eig = ic.symmetric_eigen();
            let tol = 1e-12 * (1.0 + scale);
            let p = eig.eigenvalues;
            let trace = p.sum();
            let second = p.map(|a| 0.5 * trace - a);
            if second.iter().all(|s| *s >= -tol) {
                continue;
            }
            let kept = second.map(|s| s.max(0.0));
            let moments = kept.map(|s| kept.sum() - s);
            let axes = eig.eigenvectors;
            link.inertia_com = axes * Matrix3::from_diagonal(&moments) * axes.transpose();
            let list = |v: &Vector3<f64>| {
                let mut v: Vec<f64> = v.iter().copied().collect();
                v.sort_by(f64::total_cmp);
                v.iter().map(|x| format!("{x:.6e}")).collect::<Vec<_>>().join(", ")
            };
            self.warnings.push(format!(
                "the link of `{}`: principal moments {} kg·m² about its centre of mass are no body's ({}); taken as the nearest body's, {} kg·m², for the physical fit's prior and simulation (the data decide the identified values)",
                joint.name,
                list(&p),
                if p.iter().any(|a| *a < -tol) {
                    "a negative moment"
                } else {
                    "one exceeds the sum of the other two: the triangle inequality"
                },
                list(&moments)
            ));
        }
    }

    /// Checks the physical sanity of the description: positive masses
    /// (zero allowed), symmetric positive semidefinite inertias satisfying
    /// the triangle inequalities, positive drive constants.
    pub fn validate(&self) -> Result<(), Problem> {
        let n = self.dof();
        if n == 0 {
            return Err(Problem::new("joint", "the robot has no moving joint"));
        }
        if n > MAX_JOINTS {
            return Err(Problem::new(
                "joint",
                format!("{n} moving joints: robotid identifies arms of up to {MAX_JOINTS} (the base-parameter search grows as the cube of the joints); lock the others"),
            ));
        }
        for (what, len) in [
            ("links", self.links.len()),
            ("drives", self.drives.len()),
            ("friction", self.friction.len()),
            ("limits", self.limits.len()),
        ] {
            if len != n {
                return Err(Problem::new("joint", format!("{n} joints but {len} {what}")));
            }
        }
        self.check_sizes()?;
        for (i, (j, l)) in self.joints.iter().zip(&self.links).enumerate() {
            let ctx = format!("joint {} (`{}`)", i + 1, j.name);
            check_body(&ctx, l)?;
            check_drive(&ctx, &self.drives[i])?;
            check_friction(&ctx, &self.friction[i])?;
        }
        self.check_couplings()
    }

    /// Each coupled motor names joints of the chain other than its own,
    /// once each; its friction is finite (Coulomb a magnitude); and R is
    /// invertible, so motor-side channels determine the joints.
    fn check_couplings(&self) -> Result<(), Problem> {
        let n = self.dof();
        let mut seen = vec![false; n];
        for c in &self.couplings {
            if c.motor >= n {
                return Err(Problem::new(
                    "coupling",
                    format!("a coupled motor of joint {} of {n}", c.motor + 1),
                ));
            }
            let name = &self.joints[c.motor].name;
            if std::mem::replace(&mut seen[c.motor], true) {
                return Err(Problem::new(
                    "coupling",
                    format!("joint `{name}`: its motor is coupled twice"),
                ));
            }
            for (k, &(j, t)) in c.with.iter().enumerate() {
                if j >= n || j == c.motor || c.with[..k].iter().any(|w| w.0 == j) || !(t.is_finite() && t != 0.0) {
                    return Err(Problem::new(
                        "coupling",
                        format!("joint `{name}`: each coupled joint is another joint of the chain, once, with finite non-zero turns"),
                    ));
                }
            }
            if !(c.viscous.is_finite() && c.coulomb.is_finite() && c.coulomb >= 0.0) {
                return Err(Problem::new(
                    "coupling",
                    format!("joint `{name}`: motor friction must be finite, Coulomb's ≥ 0"),
                ));
            }
        }
        if !self.couplings.is_empty() {
            let r = self.transmission();
            let scale = r.abs().max();
            let smallest = r.clone().svd(false, false).singular_values.min();
            if !(smallest > 1e-9 * scale) {
                return Err(Problem::new(
                    "coupling",
                    format!("the transmission matrix is singular (smallest singular value {smallest:.3e} against {scale:.3e}): motor angles would not determine the joints'"),
                ));
            }
        }
        Ok(())
    }
}

/// A link's body is physical: mass ≥ 0, inertia about its centre of mass
/// symmetric, positive semidefinite and within the triangle inequality.
fn check_body(ctx: &str, l: &Inertial) -> Result<(), Problem> {
    if !(l.mass >= 0.0) || !l.mass.is_finite() {
        return Err(Problem::new(
            "mass",
            format!("{ctx}: link mass must be ≥ 0, found {}", l.mass),
        ));
    }
    let ic = l.inertia_com;
    if (ic - ic.transpose()).abs().max() > 1e-12 * (1.0 + ic.abs().max()) {
        return Err(Problem::new(
            "inertia",
            format!("{ctx}: inertia tensor is not symmetric"),
        ));
    }
    let eig = ic.symmetric_eigenvalues();
    let tol = 1e-12 * (1.0 + ic.abs().max());
    if eig.iter().any(|e| *e < -tol) {
        return Err(Problem::new(
            "mass",
            format!("{ctx}: inertia about the centre of mass has a negative principal moment"),
        ));
    }
    let (a, b, c) = (eig[0], eig[1], eig[2]);
    if a + b < c - tol || a + c < b - tol || b + c < a - tol {
        return Err(Problem::new(
            "inertia",
            format!("{ctx}: principal moments {a}, {b}, {c} violate the triangle inequality"),
        ));
    }
    Ok(())
}

/// A drive's constants are positive (its gains' uncertainty in [0, 1)).
fn check_drive(ctx: &str, d: &Drive) -> Result<(), Problem> {
    if !(d.gear_ratio != 0.0 && d.torque_constant > 0.0 && d.encoder_counts_per_rev > 0.0) {
        return Err(Problem::new(
            "drive",
            format!("{ctx}: torque constant and encoder counts must be > 0, the gear ratio non-zero (negative: the motor turns the other way)"),
        ));
    }
    if d.rotor_inertia < 0.0 {
        return Err(Problem::new("inertia", format!("{ctx}: rotor inertia must be ≥ 0")));
    }
    if let Some(g) = d.gain_rel_std.filter(|g| !(*g >= 0.0 && *g < 1.0)) {
        return Err(Problem::new(
            "torque_constant_rel_std",
            format!("{ctx}: a relative standard deviation in [0, 1), found {g}"),
        ));
    }
    Ok(())
}

/// Coulomb friction is a magnitude, and a Stribeck fade has a shape.
fn check_friction(ctx: &str, f: &Friction) -> Result<(), Problem> {
    if f.coulomb_pos < 0.0 || f.coulomb_neg < 0.0 {
        return Err(Problem::new(
            "coulomb",
            format!("{ctx}: Coulomb friction is a magnitude and must be ≥ 0"),
        ));
    }
    let s = &f.stribeck;
    if s.velocity < 0.0 || (s.velocity > 0.0 && !(s.exponent > 0.0)) {
        return Err(Problem::new(
            "stribeck",
            format!("{ctx}: a Stribeck fade needs a velocity ≥ 0 and, with one, an exponent > 0"),
        ));
    }
    Ok(())
}

/// Rotation matrix about a unit axis by angle `q` (Rodrigues), without
/// allocation.
#[inline]
pub fn axis_rotation(axis: &Unit<Vector3<f64>>, q: f64) -> Matrix3<f64> {
    let (s, c) = q.sin_cos();
    let k = axis.into_inner();
    let kx = Matrix3::new(0.0, -k.z, k.y, k.z, 0.0, -k.x, -k.y, k.x, 0.0);
    Matrix3::identity() + kx * s + kx * kx * (1.0 - c)
}

/// Rotation from roll-pitch-yaw (URDF convention: R = Rz(yaw)·Ry(pitch)·Rx(roll)).
pub fn rpy_rotation(rpy: [f64; 3]) -> Matrix3<f64> {
    let x = Unit::new_unchecked(Vector3::x());
    let y = Unit::new_unchecked(Vector3::y());
    let z = Unit::new_unchecked(Vector3::z());
    axis_rotation(&z, rpy[2]) * axis_rotation(&y, rpy[1]) * axis_rotation(&x, rpy[0])
}
