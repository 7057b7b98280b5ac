//! URDF → [`Model`]: follows the chain of moving joints from the root link,
//! composing fixed joints into the next joint's origin and lumping the
//! inertia of rigidly attached links into the moving link that carries them.
//!
//! Joints of any kind load. A locked joint is a fixed one at its locked
//! position (as Pinocchio's `buildReducedModel`): revolute and continuous
//! joints rotate about their axis by it, prismatic ones translate along it.
//! Prismatic and mimic joints, and every joint a [`Locks`] does not keep,
//! are locked (a mimic joint at its leader's position times its multiplier
//! plus its offset); the model says which, and where.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use nalgebra::{Matrix3, Unit, Vector3};
use urdf_rs::JointType;

use super::model::{rpy_rotation, Drive, Extent, Friction, Geometry, Inertial, Joint, Limits, Model, Shape};
use crate::{Error, Result};

/// A rigid transform (rotation, translation).
type Frame = (Matrix3<f64>, Vector3<f64>);

fn compose(a: &Frame, b: &Frame) -> Frame {
    (a.0 * b.0, a.0 * b.1 + a.1)
}

fn pose(p: &urdf_rs::Pose) -> Frame {
    (rpy_rotation(p.rpy.0), Vector3::from(p.xyz.0))
}

/// Which joints of a description move: the others are locked.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Locks {
    /// The joints that move (a recording's joints); None: every revolute
    /// and continuous joint that no other joint mimics.
    pub keep: Option<Vec<String>>,
    /// Positions of locked joints, rad or m (default 0, or the nearest
    /// limit when 0 lies outside the joint's range).
    pub positions: BTreeMap<String, f64>,
}

pub fn load_urdf(path: &Path) -> Result<Model> {
    load_urdf_with(path, &Locks::default())
}

pub fn load_urdf_with(path: &Path, locks: &Locks) -> Result<Model> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    parse_urdf_with(&text, path, locks)
}

pub fn parse_urdf(text: &str, path: &Path) -> Result<Model> {
    parse_urdf_with(text, path, &Locks::default())
}

/// The transform a joint adds at position `x` (rad or m).
fn motion(j: &urdf_rs::Joint, x: f64) -> Frame {
    let axis = Vector3::from(j.axis.xyz.0);
    let axis = if axis.norm() > 0.0 {
        axis.normalize()
    } else {
        Vector3::z()
    };
    match j.joint_type {
        JointType::Prismatic => (Matrix3::identity(), axis * x),
        JointType::Revolute | JointType::Continuous => (
            super::model::axis_rotation(&Unit::new_unchecked(axis), x),
            Vector3::zeros(),
        ),
        _ => (Matrix3::identity(), Vector3::zeros()),
    }
}

/// Which joints are locked, and at which position.
fn locked_positions(robot: &urdf_rs::Robot, locks: &Locks, path: &Path) -> Result<BTreeMap<String, f64>> {
    let err = |msg: String| Error::Robot {
        path: path.to_path_buf(),
        msg,
    };
    let names: Vec<&str> = robot.joints.iter().map(|j| j.name.as_str()).collect();
    for n in locks.positions.keys().chain(locks.keep.iter().flatten()) {
        if !names.contains(&n.as_str()) {
            return Err(err(format!(
                "joint `{n}` is not in the URDF ({} joints: {})",
                names.len(),
                names.join(", ")
            )));
        }
    }
    let mut out = BTreeMap::new();
    let default_at = |j: &urdf_rs::Joint| {
        let (lo, hi) = (j.limit.lower, j.limit.upper);
        if hi > lo && !(lo..=hi).contains(&0.0) {
            if 0.0 < lo {
                lo
            } else {
                hi
            }
        } else {
            0.0
        }
    };
    for j in &robot.joints {
        if j.joint_type == JointType::Fixed || j.mimic.is_some() {
            continue;
        }
        let kept = match &locks.keep {
            Some(k) => k.contains(&j.name),
            None => matches!(j.joint_type, JointType::Revolute | JointType::Continuous),
        };
        if let Some(&x) = locks.positions.get(&j.name) {
            if kept && locks.keep.is_some() {
                return Err(err(format!("joint `{}` is both kept (recorded) and locked", j.name)));
            }
            out.insert(j.name.clone(), x);
        } else if !kept {
            out.insert(j.name.clone(), default_at(j));
        }
    }
    for j in robot.joints.iter().filter(|j| j.mimic.is_some()) {
        let m = j.mimic.as_ref().expect("filtered");
        let leader = out.get(&m.joint).copied().ok_or_else(|| {
            err(format!(
                "joint `{}` mimics `{}`, which moves: coupled joints are not a serial chain robotid can identify; lock `{}`",
                j.name, m.joint, m.joint
            ))
        })?;
        let x = locks
            .positions
            .get(&j.name)
            .copied()
            .unwrap_or(m.multiplier.unwrap_or(1.0) * leader + m.offset.unwrap_or(0.0));
        out.insert(j.name.clone(), x);
    }
    Ok(out)
}

/// The root link of a URDF's joints, refused unless they make a tree:
/// every link named defined, one root, each link the child of one joint
/// at most, every link reached from the root (a joint cycle hung the walk).
fn tree_root<'a>(
    robot: &'a urdf_rs::Robot,
    links: &HashMap<&str, &urdf_rs::Link>,
    children: &HashMap<&'a str, Vec<&'a urdf_rs::Joint>>,
    path: &Path,
) -> Result<&'a str> {
    let err = |msg: String| Error::Robot {
        path: path.to_path_buf(),
        msg,
    };
    if let Some((j, link)) = robot
        .joints
        .iter()
        .flat_map(|j| [(j, &j.parent.link), (j, &j.child.link)])
        .find(|(_, l)| !links.contains_key(l.as_str()))
    {
        return Err(err(format!(
            "joint `{}` names link `{link}`, which the URDF does not define",
            j.name
        )));
    }
    let roots: Vec<&str> = robot
        .links
        .iter()
        .map(|l| l.name.as_str())
        .filter(|l| !robot.joints.iter().any(|j| j.child.link == *l))
        .collect();
    let [root] = roots[..] else {
        return Err(err(format!(
            "expected one root link, found {}: {}",
            roots.len(),
            roots.join(", ")
        )));
    };
    let mut parent_of: HashMap<&str, &str> = HashMap::new();
    for j in &robot.joints {
        if j.parent.link == j.child.link {
            return Err(err(format!(
                "joint `{}` is its own parent: link `{}` on both sides",
                j.name, j.child.link
            )));
        }
        if let Some(other) = parent_of.insert(j.child.link.as_str(), j.name.as_str()) {
            return Err(err(format!(
                "link `{}` is the child of joints `{other}` and `{}`: a URDF is a tree (closed chains are not supported)",
                j.child.link, j.name
            )));
        }
    }
    let mut reached = vec![root];
    let mut at = 0;
    while let Some(&l) = reached.get(at) {
        reached.extend(children.get(l).into_iter().flatten().map(|j| j.child.link.as_str()));
        at += 1;
    }
    if let Some(away) = robot.links.iter().find(|l| !reached.contains(&l.name.as_str())) {
        return Err(err(format!(
            "link `{}` is not connected to the root link `{root}`: its joints form a cycle",
            away.name
        )));
    }
    Ok(root)
}

/// Whether a link's subtree holds a moving joint.
fn moving_below<'a>(
    link: &'a str,
    children: &HashMap<&'a str, Vec<&'a urdf_rs::Joint>>,
    moves: &dyn Fn(&urdf_rs::Joint) -> bool,
) -> bool {
    children.get(link).is_some_and(|js| {
        js.iter()
            .any(|j| moves(j) || moving_below(&j.child.link, children, moves))
    })
}

/// A revolute joint `j` at `origin` (in the last moving link's frame) and
/// its link, still without mass (the walk merges the URDF's links into
/// it), with the URDF's damping, friction and limits. Any other moving
/// joint is refused.
fn push_revolute(model: &mut Model, j: &urdf_rs::Joint, origin: Frame, path: &Path) -> Result<()> {
    let err = |msg: String| Error::Robot {
        path: path.to_path_buf(),
        msg,
    };
    if !matches!(j.joint_type, JointType::Revolute | JointType::Continuous) {
        return Err(err(format!(
            "joint `{}`: a moving {:?} joint is not supported (revolute chains): lock it (`[lock] {} = position`) or leave it out of the recorded joints",
            j.name, j.joint_type, j.name
        )));
    }
    let axis = Vector3::from(j.axis.xyz.0);
    if !(axis.norm() > 0.0) {
        return Err(err(format!("joint `{}`: zero axis", j.name)));
    }
    model.joints.push(Joint {
        name: j.name.clone(),
        origin_rot: origin.0,
        origin_xyz: origin.1,
        axis: Unit::new_normalize(axis),
    });
    model.links.push(Inertial {
        mass: 0.0,
        com: Vector3::zeros(),
        inertia_com: Matrix3::zeros(),
    });
    model.drives.push(Drive::default());
    let (viscous, coulomb) = j.dynamics.as_ref().map_or((0.0, 0.0), |d| (d.damping, d.friction));
    model.friction.push(Friction::symmetric(viscous, coulomb));
    let lim = &j.limit;
    model.limits.push(Limits {
        position: (j.joint_type == JointType::Revolute && lim.upper > lim.lower).then_some((lim.lower, lim.upper)),
        velocity: (lim.velocity > 0.0).then_some(lim.velocity),
        acceleration: None,
        torque: (lim.effort > 0.0).then_some(lim.effort),
    });
    Ok(())
}

/// A URDF link's inertial in the frame `frame` places it in; its shapes
/// and their box merged `into` the moving link's it joins.
fn link_inertial(
    l: &urdf_rs::Link,
    frame: &Frame,
    path: &Path,
    into: &std::cell::RefCell<(Option<Extent>, Vec<Shape>)>,
) -> Inertial {
    let shapes = link_shapes(l, frame, path);
    let mut x = into.borrow_mut();
    if let Some(e) = shapes_extent(&shapes) {
        x.0 = Some(x.0.map_or(e, |x| x.union(&e)));
    }
    x.1.extend(shapes);
    let (r, p) = compose(frame, &pose(&l.inertial.origin));
    let i = &l.inertial.inertia;
    let local = Matrix3::new(i.ixx, i.ixy, i.ixz, i.ixy, i.iyy, i.iyz, i.ixz, i.iyz, i.izz);
    Inertial {
        mass: l.inertial.mass.value,
        com: p,
        inertia_com: r * local * r.transpose(),
    }
}

/// The shapes and box `found` for the current moving link (if any) are
/// its: into `model`, `found` emptied for the next.
fn close_link(model: &mut Model, found: &std::cell::RefCell<(Option<Extent>, Vec<Shape>)>) {
    if !model.links.is_empty() {
        let (extent, shapes) = std::mem::take(&mut *found.borrow_mut());
        model.extents.push(extent);
        model.shapes.push(shapes);
    }
}

/// Each link's child joints.
fn children_of(robot: &urdf_rs::Robot) -> HashMap<&str, Vec<&urdf_rs::Joint>> {
    let mut children: HashMap<&str, Vec<&urdf_rs::Joint>> = HashMap::new();
    for j in &robot.joints {
        children.entry(j.parent.link.as_str()).or_default().push(j);
    }
    children
}

/// The tool point, in the last moving link's frame: a single chain of
/// fixed links followed past the last moving joint (a flange, `ee_link`)
/// from `link` at `frame`.
fn tool_point<'a>(
    mut link: &'a str,
    mut frame: Frame,
    children: &HashMap<&'a str, Vec<&'a urdf_rs::Joint>>,
    rigid: &dyn Fn(&urdf_rs::Joint) -> Frame,
) -> Vector3<f64> {
    while let Some([j]) = children.get(link).map(Vec::as_slice) {
        (frame, link) = (compose(&frame, &rigid(j)), &j.child.link);
    }
    frame.1
}

/// The box each link welded to the last moving one fills in its own frame
/// (None where it has no shapes).
fn end_extents(
    robot: &urdf_rs::Robot,
    end_frames: &[(String, Matrix3<f64>, Vector3<f64>)],
    path: &Path,
) -> Vec<Option<Extent>> {
    let identity = (Matrix3::identity(), Vector3::zeros());
    end_frames
        .iter()
        .map(|(name, _, _)| {
            let l = robot.links.iter().find(|l| &l.name == name)?;
            shapes_extent(&link_shapes(l, &identity, path))
        })
        .collect()
}

pub fn parse_urdf_with(text: &str, path: &Path, locks: &Locks) -> Result<Model> {
    let err = |msg: String| Error::Robot {
        path: path.to_path_buf(),
        msg,
    };
    let (text, warnings) = drop_duplicate_origins(text).map_err(|e| err(e.to_string()))?;
    let robot = urdf_rs::read_from_string(&text).map_err(|e| err(format!("invalid URDF: {e}")))?;
    let links: HashMap<&str, &urdf_rs::Link> = robot.links.iter().map(|l| (l.name.as_str(), l)).collect();
    let children = children_of(&robot);
    let root = tree_root(&robot, &links, &children, path)?;
    let locked = locked_positions(&robot, locks, path)?;
    // A joint moves unless it is fixed or locked.
    let moves = |j: &urdf_rs::Joint| j.joint_type != JointType::Fixed && !locked.contains_key(&j.name);
    // The transform of a joint that does not move: its origin, and its
    // motion at the locked position.
    let at = |j: &urdf_rs::Joint| locked.get(&j.name).copied().unwrap_or(0.0);
    let rigid = |j: &urdf_rs::Joint| compose(&pose(&j.origin), &motion(j, at(j)));
    // The shapes of the URDF links merged into the current moving link,
    // and the box they fill in its frame (meshes: their STL's vertices,
    // when found).
    let found = std::cell::RefCell::new((None::<Extent>, Vec::new()));
    let inertial_of = |name: &str, frame: &Frame| link_inertial(links[name], frame, path, &found);
    let mut model = Model::empty(&robot.name, Vector3::new(0.0, 0.0, -9.81));
    // `frame`: the current URDF link's frame in the current moving link's
    // frame (or the base frame before the first moving joint).
    let mut frame: Frame = (Matrix3::identity(), Vector3::zeros());
    let mut link = root;
    loop {
        match model.links.last_mut() {
            Some(last) => *last = last.merge(&inertial_of(link, &frame)),
            None => model.base_shapes.extend(link_shapes(links[link], &frame, path)),
        }
        // One child leads to the next moving joint; the others are rigid parts.
        let kids = children.get(link).map(Vec::as_slice).unwrap_or_default();
        let (ahead, rigid_kids): (Vec<&urdf_rs::Joint>, Vec<&urdf_rs::Joint>) = kids
            .iter()
            .copied()
            .partition(|j| moving_below(&j.child.link, &children, &moves) || moves(j));
        if let Some(last) = model.links.last_mut() {
            for j in rigid_kids {
                lump_fixed(
                    &j.child.link,
                    compose(&frame, &rigid(j)),
                    &children,
                    &rigid,
                    &inertial_of,
                    last,
                );
            }
        }
        if ahead.len() > 1 {
            return Err(err(format!(
                "link `{link}` branches into several moving chains; robotid handles serial chains"
            )));
        }
        let Some(j) = ahead.first().copied() else { break };
        let origin = compose(&frame, &pose(&j.origin));
        if !moves(j) {
            (frame, link) = (compose(&frame, &rigid(j)), &j.child.link);
            continue;
        }
        close_link(&mut model, &found);
        push_revolute(&mut model, j, origin, path)?;
        frame = (Matrix3::identity(), Vector3::zeros());
        link = &j.child.link;
    }
    close_link(&mut model, &found);
    model.end_effector = tool_point(link, frame, &children, &rigid);
    welded(link, frame, &children, &rigid, &mut model.end_frames);
    model.end_extents = end_extents(&robot, &model.end_frames, path);
    model.warnings = warnings;
    model.locked = locked.into_iter().collect();
    if model.joints.is_empty() {
        return Err(err("no revolute joint found".into()));
    }
    Ok(model)
}

/// A URDF link's collision shapes (else its visual ones), placed by
/// `frame` (meshes resolved to their STL files where found).
fn link_shapes(link: &urdf_rs::Link, frame: &Frame, urdf: &Path) -> Vec<Shape> {
    let shapes: Vec<(&urdf_rs::Pose, &urdf_rs::Geometry)> = if link.collision.is_empty() {
        link.visual.iter().map(|v| (&v.origin, &v.geometry)).collect()
    } else {
        link.collision.iter().map(|c| (&c.origin, &c.geometry)).collect()
    };
    shapes
        .into_iter()
        .map(|(origin, geometry)| {
            let (rotation, position) = compose(frame, &pose(origin));
            let geometry = match geometry {
                urdf_rs::Geometry::Box { size } => Geometry::Box(Vector3::new(size[0], size[1], size[2]) * 0.5),
                urdf_rs::Geometry::Cylinder { radius, length } => Geometry::Cylinder {
                    radius: *radius,
                    half_length: 0.5 * length,
                },
                urdf_rs::Geometry::Capsule { radius, length } => Geometry::Capsule {
                    radius: *radius,
                    half_length: 0.5 * length,
                },
                urdf_rs::Geometry::Sphere { radius } => Geometry::Sphere(*radius),
                urdf_rs::Geometry::Mesh { filename, scale } => Geometry::Mesh {
                    name: filename.clone(),
                    file: super::stl::resolve(filename, urdf),
                    scale: scale.map_or(Vector3::new(1.0, 1.0, 1.0), |s| Vector3::new(s[0], s[1], s[2])),
                },
            };
            Shape {
                geometry,
                rotation,
                position,
            }
        })
        .collect()
}

/// The box `shapes` fill; None without shapes, or with a mesh whose file
/// is not found or not an STL.
fn shapes_extent(shapes: &[Shape]) -> Option<Extent> {
    let mut out: Option<Extent> = None;
    for shape in shapes {
        let h = |v: Vector3<f64>| Extent { min: -v, max: v };
        let local = match &shape.geometry {
            Geometry::Box(half) => h(*half),
            Geometry::Cylinder { radius, half_length } => h(Vector3::new(*radius, *radius, *half_length)),
            Geometry::Capsule { radius, half_length } => h(Vector3::new(*radius, *radius, half_length + radius)),
            Geometry::Sphere(r) => h(Vector3::new(*r, *r, *r)),
            Geometry::Mesh { file, scale, .. } => {
                let e = super::stl::extent(file.as_ref()?).ok()?;
                Extent::of_points([e.min.component_mul(scale), e.max.component_mul(scale)])?
            }
        };
        let e = Extent::of_points(local.corners().map(|c| shape.rotation * c + shape.position))?;
        if !(e.min.iter().chain(e.max.iter()).all(|v| v.is_finite())) {
            return None;
        }
        out = Some(out.map_or(e, |o| o.union(&e)));
    }
    out
}

/// `link` at `frame` and every link rigidly held by it, with their frames.
fn welded<'a>(
    link: &'a str,
    frame: Frame,
    children: &HashMap<&'a str, Vec<&'a urdf_rs::Joint>>,
    rigid: &dyn Fn(&urdf_rs::Joint) -> Frame,
    out: &mut Vec<(String, Matrix3<f64>, Vector3<f64>)>,
) {
    out.push((link.to_string(), frame.0, frame.1));
    for j in children.get(link).cloned().unwrap_or_default() {
        welded(&j.child.link, compose(&frame, &rigid(j)), children, rigid, out);
    }
}

fn lump_fixed<'a>(
    link: &'a str,
    frame: Frame,
    children: &HashMap<&'a str, Vec<&'a urdf_rs::Joint>>,
    rigid: &dyn Fn(&urdf_rs::Joint) -> Frame,
    inertial_of: &dyn Fn(&str, &Frame) -> Inertial,
    into: &mut Inertial,
) {
    *into = into.merge(&inertial_of(link, &frame));
    for j in children.get(link).cloned().unwrap_or_default() {
        lump_fixed(
            &j.child.link,
            compose(&frame, &rigid(j)),
            children,
            rigid,
            inertial_of,
            into,
        );
    }
}

/// Some xacro-generated URDFs carry two `<origin>` elements in one joint;
/// ROS's parser (urdfdom) takes the first. Do the same: cut the later ones
/// out of the text and say so.
fn drop_duplicate_origins(text: &str) -> Result<(String, Vec<String>), super::xml::XmlError> {
    let doc = super::xml::parse(text)?;
    let mut cuts = Vec::new();
    let mut warnings = Vec::new();
    for joint in doc.descendants().filter(|n| n.has_tag_name("joint")) {
        let origins: Vec<_> = joint.children().filter(|n| n.has_tag_name("origin")).collect();
        for extra in origins.iter().skip(1) {
            cuts.push(extra.range());
            let line = doc.text_pos_at(extra.range().start).row;
            warnings.push(format!(
                "joint `{}` has more than one <origin>; the first is used and the one at line {line} ignored, as ROS does",
                joint.attribute("name").unwrap_or("?")
            ));
        }
    }
    let mut out = text.to_string();
    cuts.sort_by_key(|r| std::cmp::Reverse(r.start));
    for r in cuts {
        out.replace_range(r, "");
    }
    Ok((out, warnings))
}
