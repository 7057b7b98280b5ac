//! [`Model`] → URDF: a base link, then one revolute joint and link per
//! joint, each link's inertial at its centre of mass. URDF knows gravity
//! only as −z: a model whose gravity points elsewhere (the KUKA axis's
//! −x) gets a fixed `world` joint that turns it there. What URDF cannot
//! hold — asymmetric friction, Coulomb transition, offsets, rotor inertia —
//! is written as a `robotid:` comment beside each joint; `<dynamics>`
//! carries the symmetric mean of viscous and Coulomb friction.

use std::fmt::Write;

use nalgebra::{Rotation3, Vector3};

use crate::dynamics::model::{Inertial, Model};

fn v3(v: &Vector3<f64>) -> String {
    format!("{} {} {}", v.x, v.y, v.z)
}

fn rpy(m: &nalgebra::Matrix3<f64>) -> String {
    let (r, p, y) = Rotation3::from_matrix_unchecked(*m).euler_angles();
    format!("{r} {p} {y}")
}

/// What URDF cannot hold of joint `i`'s friction and drive, as a
/// `robotid:` comment.
pub(super) fn friction_comment(model: &Model, i: usize) -> String {
    let (f, d) = (&model.friction[i], &model.drives[i]);
    format!(
        "<!-- robotid: viscous_pos = {}, viscous_neg = {}, coulomb_pos = {}, coulomb_neg = {} (<dynamics> carries the means of the two signs), offset = {}, coulomb_transition = {}{}, rotor_inertia = {} (motor side), gear_ratio = {}, reflected rotor inertia = {}{} (URDF has no place for it) -->",
        f.viscous_pos,
        f.viscous_neg,
        f.coulomb_pos,
        f.coulomb_neg,
        f.offset,
        f.transition,
        f.stribeck_said(),
        d.rotor_inertia,
        d.gear_ratio,
        d.reflected_inertia(),
        model.motor_said(i)
    )
}

/// A link's `<inertial>` element, its inner lines indented by `indent`
/// plus two spaces and its close by `indent`; `comment` first inside it.
pub(super) fn inertial(l: &Inertial, indent: &str, comment: Option<&str>) -> String {
    let ic = (l.inertia_com + l.inertia_com.transpose()) * 0.5;
    let comment = comment.map(|c| format!("\n{indent}  <!-- {} -->", crate::dynamics::xml::comment(c)));
    format!(
        "<inertial>{}\n{indent}  <origin xyz=\"{}\" rpy=\"0 0 0\"/>\n{indent}  <mass value=\"{}\"/>\n{indent}  <inertia ixx=\"{}\" ixy=\"{}\" ixz=\"{}\" iyy=\"{}\" iyz=\"{}\" izz=\"{}\"/>\n{indent}</inertial>",
        comment.unwrap_or_default(),
        v3(&l.com),
        l.mass,
        ic[(0, 0)],
        ic[(0, 1)],
        ic[(0, 2)],
        ic[(1, 1)],
        ic[(1, 2)],
        ic[(2, 2)]
    )
}

/// `<dynamics>` of joint `i`: the means of the two signs' friction.
pub(super) fn dynamics(model: &Model, i: usize) -> String {
    let f = &model.friction[i];
    format!(
        "<dynamics damping=\"{}\" friction=\"{}\"/>",
        0.5 * (f.viscous_pos + f.viscous_neg),
        0.5 * (f.coulomb_pos + f.coulomb_neg)
    )
}

/// The URDF text of `model`; `note` goes into a comment at the top.
pub fn to_urdf(model: &Model, note: &str) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "<?xml version=\"1.0\"?>");
    let _ = writeln!(s, "<!-- {} -->", crate::dynamics::xml::comment(note));
    let _ = writeln!(s, "<robot name=\"{}\">", model.name);
    let g = model.gravity;
    let mut parent = "base_link".to_string();
    if g.norm() > 0.0 && (g.normalize() - Vector3::new(0.0, 0.0, -1.0)).norm() > 1e-12 {
        // R·g = −|g|·z: the base turned so that gravity is URDF's −z.
        let r = Rotation3::rotation_between(&g, &Vector3::new(0.0, 0.0, -1.0))
            .unwrap_or_else(|| Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI));
        let _ = writeln!(s, "  <link name=\"world\"/>");
        let _ = writeln!(
            s,
            "  <joint name=\"world_to_base\" type=\"fixed\">\n    <parent link=\"world\"/>\n    <child link=\"base_link\"/>\n    <origin xyz=\"0 0 0\" rpy=\"{}\"/>\n  </joint>",
            rpy(r.matrix())
        );
    }
    let _ = writeln!(s, "  <link name=\"base_link\"/>");
    for (i, j) in model.joints.iter().enumerate() {
        let child = format!("{}_link", j.name);
        let lim = &model.limits[i];
        let (lo, hi) = lim.position.unwrap_or((-std::f64::consts::PI, std::f64::consts::PI));
        let _ = writeln!(s, "  {}", friction_comment(model, i));
        let _ = writeln!(
            s,
            "  <joint name=\"{}\" type=\"revolute\">\n    <parent link=\"{parent}\"/>\n    <child link=\"{child}\"/>\n    <origin xyz=\"{}\" rpy=\"{}\"/>\n    <axis xyz=\"{}\"/>\n    <limit lower=\"{lo}\" upper=\"{hi}\" effort=\"{}\" velocity=\"{}\"/>\n    {}\n  </joint>",
            j.name,
            v3(&j.origin_xyz),
            rpy(&j.origin_rot),
            v3(&j.axis),
            lim.torque.unwrap_or(0.0),
            lim.velocity.unwrap_or(0.0),
            dynamics(model, i),
        );
        let _ = writeln!(
            s,
            "  <link name=\"{child}\">\n    {}\n  </link>",
            inertial(&model.links[i], "    ", None)
        );
        parent = child;
    }
    let _ = writeln!(s, "</robot>");
    s
}
