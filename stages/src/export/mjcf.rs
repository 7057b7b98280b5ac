//! [`Model`] → MJCF (MuJoCo's XML): one body per joint, nested as the
//! chain is, each at its joint's origin (`pos`, `quat`) with a hinge about
//! the joint's axis, so MuJoCo's q = 0 is robotid's. Locked joints are
//! already welded into the model (their links lumped into the moving link
//! that carries them). Each body's inertial is its link's, on the principal
//! axes of its inertia about the centre of mass (`quat`, `diaginertia`).
//! Per joint: `armature` = the rotor inertia reflected through the gear
//! (gear² · I_rotor), `damping` = viscous friction, `frictionloss` =
//! Coulomb friction (MuJoCo's dry friction is symmetric: the mean of the
//! two signs), its constraint's time constant `solreffriction` at
//! [`FRICTION_TIMECONST_S`]. What MJCF cannot hold — asymmetric friction, the Coulomb
//! transition, offsets — goes into a `robotid:` comment beside each joint
//! and into the export's sidecar. The robot file's shapes (URDF collision
//! shapes, else visual ones) are each body's `<geom>`s, meshes as assets
//! at their STL files' absolute paths, so that the model is seen and
//! collides; the explicit inertials, not the geoms, give the mass. A
//! coupled motor (docs/robot-file.md, Transmissions) is a fixed tendon over
//! the joints it turns with, carrying its rotor and its friction.

use std::fmt::Write;

use nalgebra::{Matrix3, Rotation3, SymmetricEigen, UnitQuaternion, Vector3};

use crate::dynamics::model::{Geometry, Model, Shape};

/// The time constant of each joint's friction-loss constraint, s: twice
/// MuJoCo's default timestep, the shortest it keeps stable. At MuJoCo's
/// own default (0.02 s) the constraint is soft enough that a moving joint
/// feels less than its Coulomb friction: rolled out by MuJoCo on the
/// foreign Panda's validation record, the exported model missed the
/// measured angles by up to 2.7× the true parameters' error in robotid's
/// rollout, and by 0.88–1.03× at 0.004 s.
pub const FRICTION_TIMECONST_S: f64 = 0.004;

/// Numbers in their shortest exact form, with an exponent when tiny or huge.
fn v3(v: &Vector3<f64>) -> String {
    format!("{:?} {:?} {:?}", v.x, v.y, v.z)
}

/// MuJoCo's quaternion order: w x y z.
fn quat(r: &Matrix3<f64>) -> String {
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*r));
    format!("{:?} {:?} {:?} {:?}", q.w, q.i, q.j, q.k)
}

/// The principal moments of a symmetric inertia and the rotation whose
/// columns are its principal axes (right-handed).
pub fn principal_axes(inertia: &Matrix3<f64>) -> (Vector3<f64>, Matrix3<f64>) {
    let eig = SymmetricEigen::new((inertia + inertia.transpose()) * 0.5);
    let mut axes = eig.eigenvectors;
    if axes.determinant() < 0.0 {
        axes.set_column(2, &(-axes.column(2)));
    }
    (eig.eigenvalues, axes)
}

/// The mesh files a model's shapes name, each once per scale, as MJCF
/// assets.
struct Meshes(Vec<(std::path::PathBuf, Vector3<f64>)>);

impl Meshes {
    fn of(model: &Model) -> Meshes {
        let mut files = Vec::new();
        for shape in model.base_shapes.iter().chain(model.shapes.iter().flatten()) {
            if let Geometry::Mesh {
                file: Some(f), scale, ..
            } = &shape.geometry
            {
                if !files.contains(&(f.clone(), *scale)) {
                    files.push((f.clone(), *scale));
                }
            }
        }
        Meshes(files)
    }

    /// The `<asset>` block (empty without meshes).
    fn assets(&self) -> String {
        if self.0.is_empty() {
            return String::new();
        }
        let mut s = String::from("  <asset>\n");
        for (k, (f, scale)) in self.0.iter().enumerate() {
            let scale = match *scale == Vector3::new(1.0, 1.0, 1.0) {
                true => String::new(),
                false => format!(" scale=\"{}\"", v3(scale)),
            };
            let _ = writeln!(
                s,
                "    <mesh name=\"mesh{k}\" file=\"{}\"{scale}/>",
                xml_attr(&f.display().to_string())
            );
        }
        s.push_str("  </asset>\n");
        s
    }

    /// A `<geom>` per shape, each line led by `pad`; a mesh MuJoCo cannot
    /// read (not found, or not an STL) said in a comment instead.
    fn geoms(&self, shapes: &[Shape], pad: &str) -> String {
        let mut s = String::new();
        for shape in shapes {
            let at = format!("pos=\"{}\" quat=\"{}\"", v3(&shape.position), quat(&shape.rotation));
            let geom = match &shape.geometry {
                Geometry::Box(h) => format!("type=\"box\" size=\"{}\"", v3(h)),
                Geometry::Cylinder { radius, half_length } => {
                    format!("type=\"cylinder\" size=\"{radius:?} {half_length:?}\"")
                }
                Geometry::Capsule { radius, half_length } => {
                    format!("type=\"capsule\" size=\"{radius:?} {half_length:?}\"")
                }
                Geometry::Sphere(r) => format!("type=\"sphere\" size=\"{r:?}\""),
                Geometry::Mesh {
                    file: Some(f), scale, ..
                } => {
                    let k = self
                        .0
                        .iter()
                        .position(|x| x.0 == *f && x.1 == *scale)
                        .unwrap_or_default();
                    format!("type=\"mesh\" mesh=\"mesh{k}\"")
                }
                Geometry::Mesh { name, .. } => {
                    let _ = writeln!(
                        s,
                        "{pad}<!-- robotid: mesh {} not drawn (not found as an STL file, which MuJoCo reads) -->",
                        crate::dynamics::xml::comment(name)
                    );
                    continue;
                }
            };
            let _ = writeln!(s, "{pad}<geom {geom} {at}/>");
        }
        s
    }
}

/// `text` escaped for a double-quoted XML attribute.
fn xml_attr(text: &str) -> String {
    text.replace('&', "&amp;").replace('"', "&quot;").replace('<', "&lt;")
}

/// The MJCF text of `model`; `note` goes into a comment at the top.
pub fn to_mjcf(model: &Model, note: &str) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "<!-- {} -->", crate::dynamics::xml::comment(note));
    let _ = writeln!(s, "<mujoco model=\"{}\">", model.name);
    let _ = writeln!(s, "  <compiler angle=\"radian\" autolimits=\"true\"/>");
    let _ = writeln!(s, "  <option gravity=\"{}\"/>", v3(&model.gravity));
    let meshes = Meshes::of(model);
    s.push_str(&meshes.assets());
    let _ = writeln!(s, "  <worldbody>");
    s.push_str(&meshes.geoms(&model.base_shapes, "    "));
    let n = model.dof();
    for (i, j) in model.joints.iter().enumerate() {
        let pad = "  ".repeat(i + 2);
        let f = &model.friction[i];
        let l = &model.links[i];
        let (moments, axes) = principal_axes(&l.inertia_com);
        let _ = writeln!(
            s,
            "{pad}<body name=\"{}_link\" pos=\"{}\" quat=\"{}\">",
            j.name,
            v3(&j.origin_xyz),
            quat(&j.origin_rot)
        );
        let _ = writeln!(
            s,
            "{pad}  <inertial pos=\"{}\" quat=\"{}\" mass=\"{:?}\" diaginertia=\"{}\"/>",
            v3(&l.com),
            quat(&axes),
            l.mass,
            v3(&moments)
        );
        let _ = writeln!(
            s,
            "{pad}  <!-- robotid: viscous_pos = {}, viscous_neg = {}, coulomb_pos = {}, coulomb_neg = {} (damping and frictionloss are their means), coulomb_transition = {}, offset = {}{}{} -->",
            f.viscous_pos, f.viscous_neg, f.coulomb_pos, f.coulomb_neg, f.transition, f.offset, f.stribeck_said(), model.motor_said(i)
        );
        let range = match model.limits[i].position {
            Some((lo, hi)) => format!(" range=\"{lo:?} {hi:?}\""),
            None => String::new(),
        };
        let _ = writeln!(
            s,
            "{pad}  <joint name=\"{}\" type=\"hinge\" axis=\"{}\"{range} armature=\"{:?}\" damping=\"{:?}\" frictionloss=\"{:?}\" solreffriction=\"{FRICTION_TIMECONST_S:?} 1\"/>",
            j.name,
            v3(&j.axis),
            model.own_armature(i),
            0.5 * (f.viscous_pos + f.viscous_neg),
            0.5 * (f.coulomb_pos + f.coulomb_neg)
        );
        s.push_str(&meshes.geoms(model.shapes.get(i).map_or(&[], Vec::as_slice), &format!("{pad}  ")));
    }
    for i in (0..n).rev() {
        let _ = writeln!(s, "{}</body>", "  ".repeat(i + 2));
    }
    let _ = writeln!(s, "  </worldbody>");
    s.push_str(&coupled_tendons(model, &|j| model.joints[j].name.clone()));
    let _ = writeln!(s, "</mujoco>");
    s
}

/// Each coupled motor as a fixed tendon whose length is the motor's angle
/// θ = r·q (r its row of the transmission): its `armature` J adds J·rᵀ·r
/// to the mass matrix, its `damping` the motor's viscous friction and its
/// `frictionloss` its Coulomb friction, each through rᵀ, as Rᵀ does. The
/// MJCF's name of model joint j is `joint(j)`.
pub(super) fn coupled_tendons(model: &Model, joint: &dyn Fn(usize) -> String) -> String {
    if model.couplings.is_empty() {
        return String::new();
    }
    let mut s = String::from("  <tendon>\n");
    for c in &model.couplings {
        let d = &model.drives[c.motor];
        let _ = writeln!(
            s,
            "    <fixed name=\"motor_{}\" armature=\"{:?}\" damping=\"{:?}\" frictionloss=\"{:?}\">",
            joint(c.motor),
            d.rotor_inertia,
            c.viscous,
            c.coulomb
        );
        let row = std::iter::once((c.motor, d.gear_ratio)).chain(c.with.iter().copied());
        for (j, coef) in row {
            let _ = writeln!(s, "      <joint joint=\"{}\" coef=\"{coef:?}\"/>", joint(j));
        }
        let _ = writeln!(s, "    </fixed>");
    }
    s.push_str("  </tendon>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The principal axes rebuild the inertia, and are a rotation.
    #[test]
    fn principal_axes_rebuild_the_inertia() {
        let i = Matrix3::new(0.30, 0.02, -0.05, 0.02, 0.25, 0.01, -0.05, 0.01, 0.12);
        let (m, r) = principal_axes(&i);
        let back = r * Matrix3::from_diagonal(&m) * r.transpose();
        assert!((back - i).amax() < 1e-15, "{back} vs {i}");
        assert!((r.determinant() - 1.0).abs() < 1e-14);
    }
}
