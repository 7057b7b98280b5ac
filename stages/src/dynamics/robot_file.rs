//! The robot file: a TOML description of a serial chain, either complete
//! (joint origins and link inertials listed here) or pointing at a URDF for
//! kinematics and inertials and adding drive and friction data by joint name.
//! The format is documented in `docs/robot-file.md`.

use super::urdf::Locks;
use crate::Problem;
use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Unit, Vector3};
use serde::Deserialize;

use super::model::{rpy_rotation, Drive, Friction, Inertial, Joint, Limits, Model};
use crate::{Error, Result};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RobotFile {
    name: String,
    /// Gravity in the base frame, m/s².
    #[serde(default = "default_gravity")]
    gravity: [f64; 3],
    /// URDF giving kinematics and inertials, relative to this file.
    urdf: Option<PathBuf>,
    /// Point on the last link, m.
    end_effector: Option<[f64; 3]>,
    /// Free text: where the numbers come from and under which licence.
    #[allow(dead_code)]
    source: Option<String>,
    #[serde(default, rename = "joint")]
    joints: Vec<JointEntry>,
}

fn default_gravity() -> [f64; 3] {
    [0.0, 0.0, -9.81]
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct JointEntry {
    name: String,
    origin: Option<Origin>,
    dh: Option<ModifiedDh>,
    axis: Option<[f64; 3]>,
    mass: Option<f64>,
    com: Option<[f64; 3]>,
    inertia: Option<InertiaEntry>,
    gear_ratio: Option<f64>,
    torque_constant: Option<f64>,
    torque_constant_rel_std: Option<f64>,
    encoder_counts_per_rev: Option<f64>,
    rotor_inertia: Option<f64>,
    /// The motor's angle at joint angle 0, rad motor side.
    motor_offset: Option<f64>,
    /// Other joints this joint's motor turns with: name → motor turns per
    /// joint turn (a coupled wrist).
    coupling: Option<std::collections::BTreeMap<String, f64>>,
    /// A coupled motor's own friction, motor side.
    motor_viscous: Option<f64>,
    motor_coulomb: Option<f64>,
    viscous: Option<f64>,
    viscous_pos: Option<f64>,
    viscous_neg: Option<f64>,
    coulomb: Option<f64>,
    coulomb_pos: Option<f64>,
    coulomb_neg: Option<f64>,
    offset: Option<f64>,
    coulomb_transition: Option<f64>,
    limits: Option<LimitsEntry>,
    /// The box the link's body fills in its frame, m: where the physical
    /// fit may put its mass (a URDF's shapes give it otherwise).
    extent: Option<ExtentEntry>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ExtentEntry {
    min: [f64; 3],
    max: [f64; 3],
}

/// A joint entry's `extent`, checked.
fn extent_of(e: &JointEntry) -> Result<Option<super::model::Extent>, Problem> {
    let Some(x) = &e.extent else { return Ok(None) };
    if (0..3).any(|k| !(x.min[k].is_finite() && x.max[k].is_finite() && x.min[k] < x.max[k])) {
        return Err(Problem::new(
            "extent",
            format!(
                "min {:?} must lie below max {:?} on every axis (finite, m)",
                x.min, x.max
            ),
        ));
    }
    Ok(Some(super::model::Extent {
        min: Vector3::from(x.min),
        max: Vector3::from(x.max),
    }))
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Origin {
    #[serde(default)]
    xyz: [f64; 3],
    #[serde(default)]
    rpy: [f64; 3],
}

/// Modified (Craig) Denavit–Hartenberg: T = Rx(alpha)·Tx(a)·Rz(theta + q)·Tz(d).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ModifiedDh {
    a: f64,
    alpha: f64,
    d: f64,
    #[serde(default)]
    theta: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct InertiaEntry {
    ixx: f64,
    iyy: f64,
    izz: f64,
    #[serde(default)]
    ixy: f64,
    #[serde(default)]
    ixz: f64,
    #[serde(default)]
    iyz: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct LimitsEntry {
    position: Option<[f64; 2]>,
    velocity: Option<f64>,
    acceleration: Option<f64>,
    torque: Option<f64>,
}

/// Loads a robot from a `.toml` robot file or directly from a `.urdf`.
pub fn load_robot(path: &Path) -> Result<Model> {
    load_robot_with(path, &Locks::default())
}

/// Loads a robot with some joints of its URDF locked (see [`Locks`]).
pub fn load_robot_with(path: &Path, locks: &Locks) -> Result<Model> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    model_of(&text, path, locks)
}

/// A robot file read once: its digest (what tables name as their robot's
/// provenance) and its model for each set of locked joints, made on first
/// use. A run hands one along instead of the path, so that its design,
/// probes, pipelines and tables read the file once between them.
pub struct Robot {
    path: PathBuf,
    text: String,
    sha256: String,
    models: std::sync::Mutex<Vec<(Locks, std::sync::Arc<Model>)>>,
}

impl std::fmt::Debug for Robot {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Robot")
            .field("path", &self.path)
            .field("sha256", &self.sha256)
            .finish_non_exhaustive()
    }
}

impl Robot {
    /// Reads the robot file at `path` (a `.toml` robot file or a `.urdf`);
    /// its model is made by [`Robot::model`].
    pub fn read(path: &Path) -> Result<Robot> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        let sha256 = crate::formats::sha256_hex(&bytes);
        // The error `read_to_string` gives.
        let text = String::from_utf8(bytes).map_err(|_| {
            let e = std::io::Error::new(std::io::ErrorKind::InvalidData, "stream did not contain valid UTF-8");
            Error::io(path, e)
        })?;
        Ok(Robot {
            path: path.to_path_buf(),
            text,
            sha256,
            models: Default::default(),
        })
    }

    /// The file's path, as given to [`Robot::read`].
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The file's text.
    pub fn text(&self) -> &str {
        &self.text
    }

    /// SHA-256 of the file's bytes, lowercase hex.
    pub fn sha256(&self) -> &str {
        &self.sha256
    }

    /// The model with `locks`, made once per set of locks.
    pub fn model(&self, locks: &Locks) -> Result<std::sync::Arc<Model>> {
        let mut models = self.models.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, m)) = models.iter().find(|(l, _)| l == locks) {
            return Ok(m.clone());
        }
        let m = std::sync::Arc::new(model_of(&self.text, &self.path, locks)?);
        models.push((locks.clone(), m.clone()));
        Ok(m)
    }
}

/// The model of a robot file's text (`path` tells a URDF by its
/// extension, names the file in errors and anchors relative paths).
fn model_of(text: &str, path: &Path, locks: &Locks) -> Result<Model> {
    let is_urdf = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("urdf"));
    let mut model = if is_urdf {
        super::urdf::parse_urdf_with(text, path, locks)?
    } else {
        parse_robot_file_with(text, path, locks)?
    };
    model.make_bodies_physical();
    model.validate().map_err(|p| Error::Robot {
        path: path.to_path_buf(),
        msg: p.to_string(),
    })?;
    Ok(model)
}

/// Parses robot-file text; `path` names the file in errors and anchors a
/// relative `urdf` path.
pub fn parse_robot_file(text: &str, path: &Path) -> Result<Model> {
    parse_robot_file_with(text, path, &Locks::default())
}

fn parse_robot_file_with(text: &str, path: &Path, locks: &Locks) -> Result<Model> {
    let err = |msg: String| Error::Robot {
        path: path.to_path_buf(),
        msg,
    };
    let file: RobotFile = toml::from_str(text).map_err(|e| err(crate::error::toml_message(text, &e)))?;
    let gravity = Vector3::from(file.gravity);
    let mut model = match &file.urdf {
        Some(urdf) => with_urdf(&file, urdf, path, locks)?,
        None => from_entries(&file, gravity, path)?,
    };
    model.gravity = gravity;
    if let Some(ee) = file.end_effector {
        model.end_effector = Vector3::from(ee);
    }
    model.drives_declared = file.joints.iter().any(declares_drive);
    model.couplings = couplings(&file.joints, &model).map_err(|p| err(p.to_string()))?;
    let mut names: Vec<&str> = model.joints.iter().map(|j| j.name.as_str()).collect();
    names.sort_unstable();
    if let Some(w) = names.windows(2).find(|w| w[0] == w[1]) {
        return Err(err(format!("joint name `{}` is used twice", w[0])));
    }
    Ok(model)
}

/// The model of a robot file that names a URDF: the URDF's bodies, with
/// the file's drives, friction, limits and shapes per joint.
fn with_urdf(file: &RobotFile, urdf: &Path, path: &Path, locks: &Locks) -> Result<Model> {
    let err = |msg: String| Error::Robot {
        path: path.to_path_buf(),
        msg,
    };
    let full = path.parent().unwrap_or(Path::new(".")).join(urdf);
    let mut m = super::urdf::load_urdf_with(&full, locks)?;
    for entry in &file.joints {
        let i = m.joints.iter().position(|j| j.name == entry.name).ok_or_else(|| {
            err(format!(
                "joint `{}` is not a moving joint of {}",
                entry.name,
                full.display()
            ))
        })?;
        for (key, given) in [
            ("origin", entry.origin.is_some()),
            ("dh", entry.dh.is_some()),
            ("axis", entry.axis.is_some()),
            ("mass", entry.mass.is_some()),
            ("com", entry.com.is_some()),
            ("inertia", entry.inertia.is_some()),
        ] {
            if given {
                return Err(err(format!(
                    "joint `{}`: `{key}` comes from the URDF and cannot be set here",
                    entry.name
                )));
            }
        }
        apply_actuation(entry, &mut m.drives[i], &mut m.friction[i], &mut m.limits[i])
            .map_err(|p| err(format!("joint `{}`: {p}", entry.name)))?;
        if let Some(e) = extent_of(entry).map_err(|p| err(format!("joint `{}`: {p}", entry.name)))? {
            m.extents.resize(m.links.len(), None);
            m.extents[i] = Some(e);
        }
    }
    m.name = file.name.clone();
    Ok(m)
}

/// The model of a robot file that gives every joint and body itself.
fn from_entries(file: &RobotFile, gravity: Vector3<f64>, path: &Path) -> Result<Model> {
    let err = |msg: String| Error::Robot {
        path: path.to_path_buf(),
        msg,
    };
    if file.joints.is_empty() {
        return Err(err("no [[joint]] entries and no `urdf`".into()));
    }
    let mut m = Model::empty(&file.name, gravity);
    for entry in &file.joints {
        let ctx = |msg: String| err(format!("joint `{}`: {msg}", entry.name));
        let (origin_rot, origin_xyz) = match (&entry.origin, &entry.dh) {
            (Some(o), None) => (rpy_rotation(o.rpy), Vector3::from(o.xyz)),
            (None, Some(dh)) => {
                let x = Unit::new_unchecked(Vector3::x());
                let z = Unit::new_unchecked(Vector3::z());
                let rx = super::model::axis_rotation(&x, dh.alpha);
                (
                    rx * super::model::axis_rotation(&z, dh.theta),
                    Vector3::new(dh.a, 0.0, 0.0) + rx * Vector3::new(0.0, 0.0, dh.d),
                )
            }
            (None, None) => (Matrix3::identity(), Vector3::zeros()),
            (Some(_), Some(_)) => return Err(ctx("give either `origin` or `dh`, not both".into())),
        };
        let axis = match (entry.axis, entry.dh.is_some()) {
            (Some(_), true) => return Err(ctx("with `dh` the axis is z; remove `axis`".into())),
            (Some(a), false) => a,
            (None, _) => [0.0, 0.0, 1.0],
        };
        let axis = Vector3::from(axis);
        if !(axis.norm() > 0.0) {
            return Err(ctx("`axis` must be a non-zero vector".into()));
        }
        let mass = entry.mass.ok_or_else(|| ctx("`mass` is required".into()))?;
        let com = Vector3::from(entry.com.unwrap_or([0.0; 3]));
        let inertia = entry
            .inertia
            .as_ref()
            .ok_or_else(|| ctx("`inertia` is required".into()))?;
        let inertia_com = Matrix3::new(
            inertia.ixx,
            inertia.ixy,
            inertia.ixz,
            inertia.ixy,
            inertia.iyy,
            inertia.iyz,
            inertia.ixz,
            inertia.iyz,
            inertia.izz,
        );
        m.joints.push(Joint {
            name: entry.name.clone(),
            origin_rot,
            origin_xyz,
            axis: Unit::new_normalize(axis),
        });
        m.links.push(Inertial { mass, com, inertia_com });
        m.extents.push(extent_of(entry).map_err(|p| ctx(p.to_string()))?);
        let (mut d, mut f, mut l) = (Drive::default(), Friction::default(), Limits::default());
        apply_actuation(entry, &mut d, &mut f, &mut l).map_err(|p| ctx(p.to_string()))?;
        m.drives.push(d);
        m.friction.push(f);
        m.limits.push(l);
    }
    Ok(m)
}

/// Whether a joint entry declares anything of its drive.
fn declares_drive(e: &JointEntry) -> bool {
    e.gear_ratio.is_some()
        || e.torque_constant.is_some()
        || e.encoder_counts_per_rev.is_some()
        || e.rotor_inertia.is_some()
        || e.coupling.is_some()
}

/// The coupled motors of the entries, by the model's joint numbers (the
/// model checks the rest: [`Model::validate`]).
fn couplings(entries: &[JointEntry], model: &Model) -> Result<Vec<super::Coupling>, Problem> {
    let index = |name: &str| model.joints.iter().position(|j| j.name == name);
    let mut out = Vec::new();
    for e in entries {
        let Some(with) = &e.coupling else {
            if e.motor_viscous.is_some() || e.motor_coulomb.is_some() {
                return Err(Problem::new(
                    "motor_viscous",
                    format!("joint `{}`: `motor_viscous` and `motor_coulomb` are a coupled motor's; an uncoupled motor's friction is the joint's (`viscous` = motor's × gear², `coulomb` = motor's × gear)", e.name),
                ));
            }
            continue;
        };
        let mut pairs = Vec::with_capacity(with.len());
        for (name, turns) in with {
            let j = index(name).ok_or_else(|| {
                Problem::new(
                    "coupling",
                    format!(
                        "joint `{}`: `coupling` names `{name}`, not a moving joint of the robot",
                        e.name
                    ),
                )
            })?;
            pairs.push((j, *turns));
        }
        out.push(super::Coupling {
            motor: index(&e.name).expect("every entry is a joint of the model"),
            with: pairs,
            viscous: e.motor_viscous.unwrap_or(0.0),
            coulomb: e.motor_coulomb.unwrap_or(0.0),
        });
    }
    out.sort_by_key(|c| c.motor);
    Ok(out)
}

/// Drive, friction and limit keys of a joint entry, over the given defaults.
fn apply_actuation(e: &JointEntry, d: &mut Drive, f: &mut Friction, l: &mut Limits) -> Result<(), Problem> {
    if let Some(v) = e.gear_ratio {
        d.gear_ratio = v;
    }
    if let Some(v) = e.torque_constant {
        d.torque_constant = v;
    }
    if let Some(v) = e.torque_constant_rel_std {
        d.gain_rel_std = Some(v);
    }
    if let Some(v) = e.encoder_counts_per_rev {
        d.encoder_counts_per_rev = v;
    }
    if let Some(v) = e.rotor_inertia {
        d.rotor_inertia = v;
    }
    if let Some(v) = e.motor_offset {
        d.motor_offset = v;
    }
    let pick = |both: Option<f64>, one: Option<f64>, name: &str, current: f64| -> Result<f64, Problem> {
        match (both, one) {
            (Some(_), Some(_)) => Err(Problem::new(
                name,
                format!("give `{name}` or its `_pos`/`_neg` forms, not both"),
            )),
            (Some(v), None) | (None, Some(v)) => Ok(v),
            (None, None) => Ok(current),
        }
    };
    f.viscous_pos = pick(e.viscous, e.viscous_pos, "viscous", f.viscous_pos)?;
    f.viscous_neg = pick(e.viscous, e.viscous_neg, "viscous", f.viscous_neg)?;
    f.coulomb_pos = pick(e.coulomb, e.coulomb_pos, "coulomb", f.coulomb_pos)?;
    f.coulomb_neg = pick(e.coulomb, e.coulomb_neg, "coulomb", f.coulomb_neg)?;
    if let Some(v) = e.offset {
        f.offset = v;
    }
    if let Some(v) = e.coulomb_transition {
        if !(v >= 0.0) {
            return Err(Problem::new("coulomb_transition", "coulomb_transition must be ≥ 0"));
        }
        f.transition = v;
    }
    if let Some(lim) = &e.limits {
        if let Some([lo, hi]) = lim.position {
            if lo >= hi {
                return Err(Problem::new(
                    "limits.position",
                    format!("position limits [{lo}, {hi}] are empty"),
                ));
            }
            l.position = Some((lo, hi));
        }
        l.velocity = lim.velocity.or(l.velocity);
        l.acceleration = lim.acceleration.or(l.acceleration);
        l.torque = lim.torque.or(l.torque);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A robot read once gives the model a load from its path gives, for
    /// each set of locks, the same one when asked again, and the digest of
    /// its bytes.
    #[test]
    fn a_robot_read_once_gives_what_loading_gives() {
        let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/robots");
        for (file, keep) in [("ur5.toml", None), ("arm_gripper.urdf", Some(2))] {
            let path = fixtures.join(file);
            let robot = Robot::read(&path).unwrap();
            let all = Locks::default();
            assert_eq!(
                *robot.model(&all).unwrap(),
                load_robot_with(&path, &all).unwrap(),
                "{file}"
            );
            assert!(std::sync::Arc::ptr_eq(
                &robot.model(&all).unwrap(),
                &robot.model(&all).unwrap()
            ));
            if let Some(k) = keep {
                let joints = robot.model(&all).unwrap().joint_names();
                let locks = Locks {
                    keep: Some(joints[..k].to_vec()),
                    positions: Default::default(),
                };
                let locked = robot.model(&locks).unwrap();
                assert_eq!(*locked, load_robot_with(&path, &locks).unwrap(), "{file}");
                assert_eq!(locked.dof(), k, "{file}");
                assert!(!locked.locked.is_empty(), "{file}");
            }
            let bytes = std::fs::read(&path).unwrap();
            assert_eq!(robot.sha256(), crate::formats::sha256_hex(&bytes));
            assert_eq!(robot.text().as_bytes(), &bytes[..]);
        }
        let missing = Robot::read(&fixtures.join("no_such_robot.urdf")).unwrap_err();
        assert!(missing.to_string().contains("no_such_robot.urdf"), "{missing}");
    }
}
