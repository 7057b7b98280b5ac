//! The user's own MJCF with identified dynamics: each moving body's
//! `<inertial>` and each moving joint's `armature`, `damping` and
//! `frictionloss` written, every other byte kept (names, geoms, meshes,
//! actuators, sensors, `<default>` classes, comments, attribute order).
//!
//! The MJCF need not share the robot file's frames: each model joint's
//! body is found by name, and the robot file's kinematics are laid over
//! the MJCF's (its base at the MJCF's world, or at the body holding the
//! first joint, whichever fits) so that each identified body is written
//! in its body's own frame, and every joint axis is checked on the way:
//! an MJCF of another robot, or with another zero pose, is refused with
//! the distance. A joint that takes `damping` (etc.) from a `<default>`
//! class gets the identified value on itself, over the class's, said; the
//! class stays as written for the joints robotid did not identify.
//!
//! Bodies welded to a moving one (no joint) are in its identified body:
//! theirs is written as zero, said. Bodies on joints the model locked (a
//! gripper) keep their own, and the moving body gets the identified body
//! less theirs at the locked position.

use std::collections::HashSet;
use std::ops::Range;

use nalgebra::Vector3;

use super::error::PatchError;
use super::urdf_patch::Patched;
use crate::dynamics::mjcf::{joint_motion, Mjcf, Pose, DYNAMICS};
use crate::dynamics::model::{axis_rotation, Inertial, Joint, Model};

/// Kinematics farther than this from the robot file's (rad or m) are
/// another robot's, or another zero pose.
const SAME_ROBOT: f64 = 1e-3;

/// Where one of the model's bodies goes in the MJCF.
struct Placed {
    body: usize,
    joint: usize,
    /// The model's link frame in the body's frame.
    link_in_body: Pose,
    lumped: Vec<usize>,
    carried: Vec<usize>,
    /// The carried bodies together, in the body's frame.
    share: Option<Inertial>,
}

/// The robot file's kinematics laid over the MJCF's with its base at
/// `base` (in the MJCF's world).
struct Overlay {
    base: Pose,
    link_in_body: Vec<Pose>,
    /// The largest angle between a joint's axes, rad, and distance
    /// between its axis lines, m, with the joint.
    worst: (f64, f64, usize),
}

/// A user's MJCF read for patching, once for any number of models of the
/// robot file it holds (the same joints and locks, other bodies and
/// friction).
pub struct MjcfPatch {
    text: String,
    mjcf: Mjcf,
    placed: Vec<Placed>,
    /// The robot file's base frame in the MJCF's world.
    base: Pose,
    /// What the MJCF's kinematics are to the robot file's, when not equal.
    pub said: Vec<String>,
}

impl MjcfPatch {
    /// `text` (an MJCF) read for patching with models like `model`.
    pub fn new(text: String, model: &Model) -> Result<MjcfPatch, PatchError> {
        let mjcf = Mjcf::read(&text)?;
        let at = model_joints(&mjcf, model)?;
        let (overlay, said) = best_overlay(&mjcf, model, &at)?;
        let moving: HashSet<usize> = at.iter().map(|&(b, _)| b).collect();
        let mut placed = Vec::new();
        for (i, &(body, joint)) in at.iter().enumerate() {
            let (lumped, carried) = parts(&mjcf, body, &moving, model);
            let share = carried_share(&mjcf, body, &carried)?;
            placed.push(Placed {
                body,
                joint,
                link_in_body: overlay.link_in_body[i],
                lumped,
                carried: carried.into_iter().map(|(c, _)| c).collect(),
                share,
            });
        }
        Ok(MjcfPatch {
            text,
            mjcf,
            placed,
            base: overlay.base,
            said,
        })
    }

    /// The MJCF with `model`'s bodies and friction written into it, and
    /// what was done to each body; `note` goes into a comment beside each.
    pub fn apply(&self, model: &Model, note: &str) -> Result<(String, Vec<Patched>), PatchError> {
        let text = self.text.as_str();
        let mut edits: Vec<(Range<usize>, String)> = Vec::new();
        let mut patched = Vec::new();
        for (i, p) in self.placed.iter().enumerate() {
            let body = &self.mjcf.bodies[p.body];
            let identified = p.link_in_body.inertial(&model.links[i]);
            let written = match &p.share {
                None => identified,
                Some(s) => identified.without(s).ok_or_else(|| PatchError::NothingLeft {
                    body: body.name.clone(),
                    carried: self.names(&p.carried),
                })?,
            };
            let mut comment = note.to_string();
            if !p.lumped.is_empty() {
                comment += &format!("; it holds the bodies {} (written as zero)", self.names(&p.lumped));
            }
            if !p.carried.is_empty() {
                comment += &format!(
                    "; the bodies {} on locked joints keep their own, taken out of it",
                    self.names(&p.carried)
                );
            }
            let element = format!(
                "<!-- robotid: {} -->\n{}{}",
                crate::dynamics::xml::comment(&comment),
                body.indent,
                inertial(&written)
            );
            edits.push(place_inertial(body, element));
            for &l in &p.lumped {
                let welded = &self.mjcf.bodies[l];
                let element = format!(
                    "<!-- robotid: this body's mass is in the identified body of `{}` -->\n{}<inertial pos=\"0 0 0\" mass=\"0\" diaginertia=\"0 0 0\"/>",
                    crate::dynamics::xml::comment(&body.name),
                    welded.indent
                );
                edits.push(place_inertial(welded, element));
            }
            let over = self.joint_edits(model, i, &mut edits);
            patched.push(Patched {
                link: body.name.clone(),
                joint: model.joints[i].name.clone(),
                lumped: p.lumped.iter().map(|&b| self.mjcf.bodies[b].name.clone()).collect(),
                carried: p.carried.iter().map(|&b| self.mjcf.bodies[b].name.clone()).collect(),
                said: over,
            });
        }
        // Coupled motors: tendons before the document's end.
        if let (false, Some(end)) = (model.couplings.is_empty(), text.rfind("</mujoco>")) {
            let name = |j: usize| {
                let p = &self.placed[j];
                self.mjcf.bodies[p.body].joints[p.joint].name.clone()
            };
            edits.push((end..end, super::mjcf::coupled_tendons(model, &name)));
        }
        Ok((super::urdf_patch::apply(text, edits), patched))
    }

    /// The edits that write joint `i`'s armature, damping and frictionloss
    /// (and a comment with what MJCF cannot hold); what they override of a
    /// class, said.
    fn joint_edits(&self, model: &Model, i: usize, edits: &mut Vec<(Range<usize>, String)>) -> Option<String> {
        let p = &self.placed[i];
        let j = &self.mjcf.bodies[p.body].joints[p.joint];
        let f = &model.friction[i];
        let values = [
            model.own_armature(i),
            0.5 * (f.viscous_pos + f.viscous_neg),
            0.5 * (f.coulomb_pos + f.coulomb_neg),
        ];
        for (k, v) in values.iter().enumerate() {
            edits.push(match &j.own[k] {
                Some(r) => (r.clone(), format!("{v:?}")),
                None => (
                    j.attributes_end..j.attributes_end,
                    format!(" {}=\"{v:?}\"", DYNAMICS[k]),
                ),
            });
        }
        let indent = line_indent(&self.text, j.range.start);
        edits.push((
            j.range.start..j.range.start,
            format!(
                "<!-- robotid: viscous_pos = {}, viscous_neg = {}, coulomb_pos = {}, coulomb_neg = {} (damping and frictionloss are their means), coulomb_transition = {}, offset = {}{}{} -->\n{indent}",
                f.viscous_pos, f.viscous_neg, f.coulomb_pos, f.coulomb_neg, f.transition, f.offset, f.stribeck_said(), model.motor_said(i)
            ),
        ));
        let over: Vec<String> = (0..3)
            .filter_map(|k| {
                j.inherited[k]
                    .as_ref()
                    .map(|c| format!("{} (class `{c}`)", DYNAMICS[k]))
            })
            .collect();
        (!over.is_empty()).then(|| {
            format!(
                "joint `{}`: {} written on the joint, over its class's",
                j.name,
                over.join(", ")
            )
        })
    }

    /// The MJCF with `carried` (given in `model`'s last moving link's
    /// frame) as a body of its own, `name`, welded to the last moving
    /// joint's body (a body without a joint moves with its parent); every
    /// other byte kept. `note` goes into a comment beside it.
    pub fn with_body(&self, name: &str, carried: &Inertial, note: &str) -> Result<String, PatchError> {
        if self.mjcf.bodies.iter().any(|b| b.name == name) {
            return Err(PatchError::BodyExists(name.to_string()));
        }
        let p = self.placed.last().ok_or(PatchError::NoJoint)?;
        let parent = &self.mjcf.bodies[p.body];
        let pad = &parent.indent;
        let element = format!(
            "\n{pad}<!-- robotid: {} -->\n{pad}<body name=\"{name}\">\n{pad}  {}\n{pad}</body>",
            crate::dynamics::xml::comment(note),
            inertial(&p.link_in_body.inertial(carried))
        );
        Ok(super::urdf_patch::apply(
            &self.text,
            vec![(parent.open_end..parent.open_end, element)],
        ))
    }

    fn names(&self, bodies: &[usize]) -> String {
        bodies
            .iter()
            .map(|&b| format!("`{}`", self.mjcf.bodies[b].name))
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// `model` as MuJoCo simulates the patched MJCF: the MJCF's own
    /// kinematics (its joint axes and positions, its q), the bodies
    /// written into it, gravity in its world. For checks: its shapes and
    /// limits are not carried over.
    pub fn on_its_kinematics(&self, model: &Model) -> Model {
        let mut out = model.clone();
        out.gravity = self.base.r * model.gravity;
        out.shapes.iter_mut().for_each(Vec::clear);
        out.extents.iter_mut().for_each(|e| *e = None);
        out.base_shapes.clear();
        let mut parent = Pose::identity();
        for (i, p) in self.placed.iter().enumerate() {
            let body = &self.mjcf.bodies[p.body];
            let j = &body.joints[p.joint];
            let axis = nalgebra::Unit::new_normalize(j.axis);
            // The link frame: the body's, moved to the joint's position;
            // the XML puts it where q = ref.
            let at_ref = body.world.then(&Pose::at(j.pos));
            let origin = parent.inverse().then(&at_ref).then(&Pose {
                r: axis_rotation(&axis, -j.reference),
                p: Vector3::zeros(),
            });
            out.joints[i] = Joint {
                name: model.joints[i].name.clone(),
                origin_rot: origin.r,
                origin_xyz: origin.p,
                axis,
            };
            out.links[i] = Pose::at(-j.pos).then(&p.link_in_body).inertial(&model.links[i]);
            parent = at_ref;
        }
        out
    }
}

/// Each of the model's joints in the MJCF: its body and its index there;
/// refused where one is missing, not a hinge, or shares its body.
fn model_joints(mjcf: &Mjcf, model: &Model) -> Result<Vec<(usize, usize)>, PatchError> {
    let mut at = Vec::new();
    for j in &model.joints {
        let (b, k) = mjcf.joint(&j.name).ok_or_else(|| PatchError::MissingJoint {
            format: "MJCF",
            joint: j.name.clone(),
            joints: mjcf
                .bodies
                .iter()
                .flat_map(|b| &b.joints)
                .map(|j| j.name.clone())
                .collect(),
        })?;
        let body = &mjcf.bodies[b];
        if body.joints[k].kind != "hinge" {
            return Err(PatchError::JointKind {
                joint: j.name.clone(),
                kind: body.joints[k].kind.clone(),
            });
        }
        if body.joints.len() > 1 {
            return Err(PatchError::SharedBody {
                body: body.name.clone(),
                joint: j.name.clone(),
                others: body.joints.len() - 1,
            });
        }
        at.push((b, k));
    }
    Ok(at)
}

/// The robot file's kinematics laid over the MJCF's with its base at the
/// MJCF's world or at the body holding the first joint, whichever fits;
/// refused past [`SAME_ROBOT`], a difference above 1e-9 said.
fn best_overlay(mjcf: &Mjcf, model: &Model, at: &[(usize, usize)]) -> Result<(Overlay, Vec<String>), PatchError> {
    let mut bases = vec![(Pose::identity(), "its world frame".to_string())];
    if let Some(p) = at.first().and_then(|&(b, _)| mjcf.bodies[b].parent) {
        bases.push((mjcf.bodies[p].world, format!("its body `{}`", mjcf.bodies[p].name)));
    }
    let (overlay, base_said) = bases
        .iter()
        .map(|(w, said)| (overlay(mjcf, model, at, *w), said))
        .min_by(|a, b| {
            let worst = |o: &Overlay| o.worst.0.max(o.worst.1);
            worst(&a.0).total_cmp(&worst(&b.0))
        })
        .ok_or(PatchError::NoJoint)?;
    let (angle, distance, j) = overlay.worst;
    if angle.max(distance) > SAME_ROBOT {
        return Err(PatchError::Kinematics {
            joint: model.joints[j].name.clone(),
            angle_rad: angle,
            distance_m: distance,
            base: base_said.clone(),
        });
    }
    let mut said = Vec::new();
    if angle.max(distance) > 1e-9 {
        said.push(format!(
            "the MJCF's joint axes are up to {angle:.1e} rad and {distance:.1e} m from the robot file's (its numbers rounded): the identified bodies are written in its frames, and it moves as its own kinematics say"
        ));
    }
    Ok((overlay, said))
}

/// The bodies `carried` (each with its pose in `body`'s frame) together,
/// in `body`'s frame; refused where one has no `<inertial>`.
fn carried_share(mjcf: &Mjcf, body: usize, carried: &[(usize, Pose)]) -> Result<Option<Inertial>, PatchError> {
    let mut share: Option<Inertial> = None;
    for (c, pose) in carried {
        let Some((_, own)) = &mjcf.bodies[*c].inertial else {
            return Err(PatchError::NoInertial {
                body: mjcf.bodies[*c].name.clone(),
                of: mjcf.bodies[body].name.clone(),
            });
        };
        let own = pose.inertial(own);
        share = Some(share.map_or(own, |s| s.merge(&own)));
    }
    Ok(share)
}

/// The robot file's kinematics over the MJCF's with its base at `base`:
/// each link frame in its body's frame, and the worst axis mismatch.
fn overlay(mjcf: &Mjcf, model: &Model, at: &[(usize, usize)], base: Pose) -> Overlay {
    let mut parent = base;
    let mut link_in_body = Vec::new();
    let mut worst = (0.0f64, 0.0f64, 0);
    for (i, j) in model.joints.iter().enumerate() {
        let (b, k) = at[i];
        let (body, mj) = (&mjcf.bodies[b], &mjcf.bodies[b].joints[k]);
        let before = parent.then(&Pose {
            r: j.origin_rot,
            p: j.origin_xyz,
        });
        let dir = before.r * j.axis.into_inner();
        // The MJCF's axis may point the other way: its q is then −q.
        let sign = if dir.dot(&(body.world.r * mj.axis)) < 0.0 {
            -1.0
        } else {
            1.0
        };
        let theirs = body.world.r * mj.axis * sign;
        let angle = dir.cross(&theirs).norm().atan2(dir.dot(&theirs));
        let distance = (body.world.point(&mj.pos) - before.p).cross(&dir).norm();
        if angle.max(distance) > worst.0.max(worst.1) {
            worst = (angle, distance, i);
        }
        // The body is where the XML puts it at q = ref.
        let link = before.then(&Pose {
            r: axis_rotation(&j.axis, sign * mj.reference),
            p: Vector3::zeros(),
        });
        link_in_body.push(body.world.inverse().then(&link));
        parent = link;
    }
    Overlay {
        base,
        link_in_body,
        worst,
    }
}

/// The bodies below moving body `b` that are not below another moving
/// one: welded to it (no joint on the way), and carried on joints the
/// model locked, each with its pose in `b`'s frame at the locked position.
fn parts(mjcf: &Mjcf, b: usize, moving: &HashSet<usize>, model: &Model) -> (Vec<usize>, Vec<(usize, Pose)>) {
    let (mut lumped, mut carried) = (Vec::new(), Vec::new());
    let mut stack: Vec<(usize, Pose, bool)> = mjcf.children(b).map(|c| (c, mjcf.bodies[c].local, false)).collect();
    stack.reverse();
    while let Some((c, pose, on_joint)) = stack.pop() {
        if moving.contains(&c) {
            continue;
        }
        let body = &mjcf.bodies[c];
        let on_joint = on_joint || !body.joints.is_empty();
        let mut pose = pose;
        for j in &body.joints {
            let x = model
                .locked
                .iter()
                .find(|(n, _)| *n == j.name)
                .map_or(j.reference, |(_, x)| *x);
            pose = pose.then(&joint_motion(j, x));
        }
        match on_joint {
            true => carried.push((c, pose)),
            false => lumped.push(c),
        }
        let below: Vec<_> = mjcf
            .children(c)
            .map(|g| (g, pose.then(&mjcf.bodies[g].local), on_joint))
            .collect();
        stack.extend(below.into_iter().rev());
    }
    (lumped, carried)
}

/// An `<inertial>` at the centre of mass with the full inertia there, in
/// the body's axes (MuJoCo finds the principal axes itself).
fn inertial(i: &Inertial) -> String {
    let c = (i.inertia_com + i.inertia_com.transpose()) * 0.5;
    format!(
        "<inertial pos=\"{:?} {:?} {:?}\" mass=\"{:?}\" fullinertia=\"{:?} {:?} {:?} {:?} {:?} {:?}\"/>",
        i.com.x,
        i.com.y,
        i.com.z,
        i.mass,
        c[(0, 0)],
        c[(1, 1)],
        c[(2, 2)],
        c[(0, 1)],
        c[(0, 2)],
        c[(1, 2)]
    )
}

/// The edit that puts `element` in place of `body`'s `<inertial>`, else
/// as its first child.
fn place_inertial(body: &crate::dynamics::mjcf::MjBody, element: String) -> (Range<usize>, String) {
    match &body.inertial {
        Some((r, _)) => (r.clone(), element),
        None => (body.open_end..body.open_end, format!("\n{}{element}", body.indent)),
    }
}

/// The indentation of the line `at` is on (empty when text precedes it).
fn line_indent(text: &str, at: usize) -> String {
    let start = text[..at].rfind('\n').map_or(0, |n| n + 1);
    let lead = &text[start..at];
    match lead.chars().all(|c| c == ' ' || c == '\t') {
        true => lead.to_string(),
        false => String::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dynamics::{parse_urdf_with, rnea, Data, Locks};
    use nalgebra::Matrix3;
    use std::path::Path;

    /// A two-joint arm with a flange on a fixed joint and a gripper on a
    /// revolute one that the log does not hold.
    const URDF: &str = include_str!("../../../fixtures/robots/arm_gripper.urdf");

    /// The same arm as a user writes it in MJCF, in other frames: the
    /// upper arm's body turned 90° about z, the forearm's body off its
    /// joint's axis (the joint at `pos`) and through a `<frame>`, the
    /// flange a welded body, classes giving the joints' dynamics, angles in
    /// degrees.
    const MJCF: &str = include_str!("../../../fixtures/robots/arm_gripper.xml");

    fn identified() -> Model {
        let locks = Locks {
            keep: Some(vec!["shoulder".into(), "elbow".into()]),
            positions: [("grip".to_string(), 0.4)].into(),
        };
        let mut m = parse_urdf_with(URDF, Path::new("arm.urdf"), &locks).unwrap();
        for (k, l) in m.links.iter_mut().enumerate() {
            l.mass *= 1.2 + 0.1 * k as f64;
            l.com += Vector3::new(0.01, -0.02, 0.005);
            l.inertia_com += Matrix3::new(0.002, 0.0004, 0.0, 0.0004, 0.003, -0.0002, 0.0, -0.0002, 0.001);
        }
        m.friction[1].viscous_pos = 0.7;
        m.friction[1].coulomb_neg = 1.1;
        m.drives[0].rotor_inertia = 1e-4;
        m.drives[0].gear_ratio = 100.0;
        m
    }

    /// The model's torques equal those of the patched MJCF's bodies on the
    /// MJCF's own kinematics: each identified body is in its body's frame.
    #[test]
    fn each_body_is_written_in_its_own_frame() {
        let model = identified();
        let patch = MjcfPatch::new(MJCF.to_string(), &model).unwrap();
        assert!(patch.said.is_empty(), "{:?}", patch.said);
        let theirs = patch.on_its_kinematics(&model);
        let (mut a, mut b) = (Data::new(&model), Data::new(&theirs));
        for (q, v, acc) in [
            ([0.3, -0.7], [1.0, -0.5], [2.0, 3.0]),
            ([-1.1, 1.4], [-0.4, 2.0], [-1.0, 0.5]),
        ] {
            let want = rnea(&model, &mut a, &q, &v, &acc).clone();
            let got = rnea(&theirs, &mut b, &q, &v, &acc);
            assert!((&want - got).amax() < 1e-12, "{want} vs {got}");
        }
        // Read back, the forearm's body with the gripper's and camera's at
        // the locked 0.4 rad is the identified one.
        let (text, patched) = patch.apply(&model, "identified").unwrap();
        let back = Mjcf::read(&text).unwrap();
        let fore = back.bodies.iter().position(|b| b.name == "fore").unwrap();
        let mut total = back.bodies[fore].inertial.as_ref().unwrap().1;
        let grip = &back.bodies[fore + 2];
        let at = back.bodies[fore + 1]
            .local
            .then(&grip.local)
            .then(&joint_motion(&grip.joints[0], 0.4));
        total = total.merge(&at.inertial(&grip.inertial.as_ref().unwrap().1));
        let cam = at
            .then(&back.bodies[fore + 3].local)
            .inertial(&back.bodies[fore + 3].inertial.as_ref().unwrap().1);
        total = total.merge(&cam);
        let want = patch.placed[1].link_in_body.inertial(&model.links[1]);
        assert!((total.mass - want.mass).abs() < 1e-12 && (total.com - want.com).norm() < 1e-12);
        assert!((total.inertia_com - want.inertia_com).amax() < 1e-12);
        assert_eq!(back.bodies[fore + 1].inertial.as_ref().unwrap().1.mass, 0.0);
        assert_eq!(
            (patched[1].lumped.clone(), patched[1].carried.len()),
            (vec!["flange".to_string()], 2)
        );
        // The joints carry the model's friction and armature; the elbow's
        // class gave it armature and frictionloss, now its own.
        let elbow = &back.bodies[fore].joints[0];
        let value =
            |j: &crate::dynamics::mjcf::MjJoint, k: usize| text[j.own[k].clone().unwrap()].parse::<f64>().unwrap();
        assert_eq!([value(elbow, 0), value(elbow, 1), value(elbow, 2)], [0.0, 0.35, 0.55]);
        let shoulder = &back.bodies[0].joints[0];
        assert_eq!(value(shoulder, 0), model.drives[0].reflected_inertia());
        assert!(patched[1].said.as_deref().unwrap().contains("armature (class `wrist`)"));
    }

    /// A body carried by the last link (a payload), given in the model's
    /// link frame, is welded to the forearm's body (turned and off its
    /// joint's axis in this MJCF) where the model has it; nothing else
    /// changes.
    #[test]
    fn a_carried_body_is_welded_where_the_model_has_it() {
        let model = identified();
        let patch = MjcfPatch::new(MJCF.to_string(), &model).unwrap();
        let carried = Inertial {
            mass: 1.7,
            com: Vector3::new(0.12, -0.03, 0.05),
            inertia_com: Matrix3::new(0.004, 0.0005, -0.0002, 0.0005, 0.006, 0.0003, -0.0002, 0.0003, 0.005),
        };
        let text = patch.with_body("payload", &carried, "a payload").unwrap();
        let back = Mjcf::read(&text).unwrap();
        let fore = back.bodies.iter().position(|b| b.name == "fore").unwrap();
        let p = back.bodies.iter().find(|b| b.name == "payload").unwrap();
        assert_eq!(p.parent, Some(fore));
        assert!(p.joints.is_empty());
        let in_fore = p.local.inertial(&p.inertial.as_ref().unwrap().1);
        let in_link = patch.placed[1].link_in_body.inverse().inertial(&in_fore);
        assert!((in_link.mass - carried.mass).abs() < 1e-15);
        assert!(
            (in_link.com - carried.com).norm() < 1e-15,
            "{} vs {}",
            in_link.com,
            carried.com
        );
        assert!((in_link.inertia_com - carried.inertia_com).amax() < 1e-15);
        let start = text.find("<!-- robotid: a payload").unwrap();
        let end = text[start..].find("</body>").unwrap() + start + "</body>".len();
        let line = text[..start].rfind('\n').unwrap();
        assert_eq!(format!("{}{}", &text[..line], &text[end..]), MJCF);
        let e = MjcfPatch::new(text, &model)
            .unwrap()
            .with_body("payload", &carried, "again")
            .unwrap_err();
        assert!(matches!(&e, PatchError::BodyExists(n) if n == "payload"), "{e}");
        assert!(e.to_string().contains("a body `payload` already"), "{e}");
    }

    #[test]
    fn another_robots_mjcf_is_refused() {
        let model = identified();
        let moved = MJCF.replace("pos=\"-0.1 0 0\"", "pos=\"-0.05 0 0\"");
        let e = MjcfPatch::new(moved, &model).err().unwrap();
        assert!(
            matches!(&e, PatchError::Kinematics { joint, distance_m, .. } if joint == "elbow" && (distance_m - 0.05).abs() < 1e-9),
            "{e}"
        );
        assert!(
            e.to_string().contains("joint `elbow`'s axis") && e.to_string().contains("5.00e-2 m"),
            "{e}"
        );
        let e = MjcfPatch::new(MJCF.replace("\"elbow\"", "\"wrist\""), &model)
            .err()
            .unwrap();
        assert!(
            matches!(&e, PatchError::MissingJoint { joint, joints, .. } if joint == "elbow" && joints == &["shoulder", "wrist", "grip"]),
            "{e}"
        );
        assert!(
            e.to_string()
                .contains("joint `elbow` of the model is not in the MJCF (its joints: shoulder, wrist, grip)"),
            "{e}"
        );
    }
}
