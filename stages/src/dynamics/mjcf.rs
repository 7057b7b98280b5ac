//! An MJCF (MuJoCo's XML) read as MuJoCo's compiler reads its kinematics:
//! each body's pose (`pos` and one of `quat`, `axisangle`, `euler`,
//! `xyaxes`, `zaxis`, through `<frame>`s), its joints with their
//! `<default>` classes applied, its explicit `<inertial>`, and the byte
//! ranges where a patch writes. Angles follow `<compiler angle>` (degrees
//! unless it says radian) and `eulerseq`. What robotid cannot follow
//! (`<include>`, `<attach>`, `<replicate>`, a compiler that takes inertia
//! from geoms) is refused, named.

use std::collections::HashMap;
use std::ops::Range;

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

use super::model::{axis_rotation, Inertial};
use super::xml::XmlError;

/// A rigid transform: rotate by `r`, then move by `p`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Pose {
    pub r: Matrix3<f64>,
    pub p: Vector3<f64>,
}

impl Pose {
    pub fn identity() -> Pose {
        Pose {
            r: Matrix3::identity(),
            p: Vector3::zeros(),
        }
    }

    pub fn at(p: Vector3<f64>) -> Pose {
        Pose {
            r: Matrix3::identity(),
            p,
        }
    }

    /// `self` then `b` (b given in self's frame).
    pub fn then(&self, b: &Pose) -> Pose {
        Pose {
            r: self.r * b.r,
            p: self.p + self.r * b.p,
        }
    }

    pub fn inverse(&self) -> Pose {
        let rt = self.r.transpose();
        Pose {
            r: rt,
            p: -(rt * self.p),
        }
    }

    pub fn point(&self, v: &Vector3<f64>) -> Vector3<f64> {
        self.p + self.r * v
    }

    /// A body given in the frame this pose is of, in the outer frame.
    pub fn inertial(&self, i: &Inertial) -> Inertial {
        Inertial {
            mass: i.mass,
            com: self.point(&i.com),
            inertia_com: self.r * i.inertia_com * self.r.transpose(),
        }
    }
}

/// An MJCF joint as MuJoCo reads it, its class's defaults applied.
#[derive(Debug, Clone)]
pub(crate) struct MjJoint {
    pub name: String,
    /// hinge, slide, ball or free.
    pub kind: String,
    /// In its body's frame, m.
    pub pos: Vector3<f64>,
    /// Unit, in its body's frame.
    pub axis: Vector3<f64>,
    /// The position at which the body is where the XML puts it (rad or m).
    pub reference: f64,
    /// The byte range of the element.
    pub range: Range<usize>,
    /// Where its start tag's attributes end (before `/>` or `>`).
    pub attributes_end: usize,
    /// `armature`, `damping`, `frictionloss` as written on the element:
    /// each value's byte range.
    pub own: [Option<Range<usize>>; 3],
    /// The class each of those three comes from when the element does not
    /// set it and a class does.
    pub inherited: [Option<String>; 3],
}

/// The joint attributes a patch writes, in [`MjJoint::own`]'s order.
pub(crate) const DYNAMICS: [&str; 3] = ["armature", "damping", "frictionloss"];

/// A body of the MJCF.
#[derive(Debug, Clone)]
pub(crate) struct MjBody {
    pub name: String,
    pub parent: Option<usize>,
    /// In its parent body's frame (its frames composed).
    pub local: Pose,
    /// In the world, where the XML puts it (every joint at its reference).
    pub world: Pose,
    pub joints: Vec<MjJoint>,
    /// Its `<inertial>`: the element's byte range and the body it gives,
    /// in the body's frame.
    pub inertial: Option<(Range<usize>, Inertial)>,
    /// Just after its start tag: where a first child goes.
    pub open_end: usize,
    /// The indentation of its children.
    pub indent: String,
}

/// An MJCF's bodies (worldbody's children and theirs, depth first).
pub(crate) struct Mjcf {
    pub bodies: Vec<MjBody>,
}

struct Compiler {
    degrees: bool,
    eulerseq: Vec<u8>,
}

/// The `<default>` classes: each one's parent and its `<joint>` defaults.
struct Defaults<'a> {
    classes: HashMap<&'a str, (Option<&'a str>, HashMap<&'a str, &'a str>)>,
}

impl<'a> Defaults<'a> {
    fn of(root: roxmltree::Node<'a, '_>) -> Defaults<'a> {
        let mut classes = HashMap::new();
        fn walk<'a>(
            d: roxmltree::Node<'a, '_>,
            parent: Option<&'a str>,
            out: &mut HashMap<&'a str, (Option<&'a str>, HashMap<&'a str, &'a str>)>,
        ) {
            let name = d.attribute("class").unwrap_or("main");
            let joint = d
                .children()
                .filter(|c| c.has_tag_name("joint"))
                .flat_map(|j| j.attributes().map(|a| (a.name(), a.value())))
                .collect();
            out.insert(name, (parent, joint));
            for c in d.children().filter(|c| c.has_tag_name("default")) {
                walk(c, Some(name), out);
            }
        }
        for d in root.children().filter(|c| c.has_tag_name("default")) {
            walk(d, None, &mut classes);
        }
        Defaults { classes }
    }

    /// A joint attribute from class `class` or the classes it inherits
    /// from, with the class that set it.
    fn joint(&self, class: &'a str, key: &str) -> Option<(&'a str, &'a str)> {
        let mut at = Some(class);
        while let Some(c) = at {
            let (parent, attrs) = self.classes.get(c)?;
            if let Some(v) = attrs.get(key) {
                return Some((v, c));
            }
            at = *parent;
        }
        None
    }
}

/// `text`, attribute `attribute` of `element`, as numbers.
/// Why a file that includes others is not read.
const ONE_FILE: &str = "robotid reads one MJCF file as written; give it the file MuJoCo saves (mj_saveLastXML)";

fn numbers(text: &str, element: &str, attribute: &str) -> Result<Vec<f64>, XmlError> {
    text.split_whitespace()
        .map(|t| {
            t.parse::<f64>()
                .map_err(|_| XmlError::value(element, attribute, text, "is not a list of numbers"))
        })
        .collect()
}

fn vector(text: &str, element: &str, attribute: &str) -> Result<Vector3<f64>, XmlError> {
    match numbers(text, element, attribute)?[..] {
        [x, y, z] => Ok(Vector3::new(x, y, z)),
        _ => Err(XmlError::value(element, attribute, text, "is not 3 numbers")),
    }
}

/// `v` (read from `text`) made unit length, or refused where it is zero.
fn unit(v: Vector3<f64>, (text, element, attribute): (&str, &str, &str)) -> Result<Vector3<f64>, XmlError> {
    let n = v.norm();
    match n > 1e-12 && n.is_finite() {
        true => Ok(v / n),
        false => Err(XmlError::value(element, attribute, text, "is a zero vector")),
    }
}

impl Compiler {
    fn of(root: roxmltree::Node) -> Result<Compiler, XmlError> {
        let mut c = Compiler {
            degrees: true,
            eulerseq: b"xyz".to_vec(),
        };
        for n in root.children().filter(|n| n.has_tag_name("compiler")) {
            if let Some(a) = n.attribute("angle") {
                c.degrees = a != "radian";
            }
            if let Some(s) = n.attribute("eulerseq") {
                if s.len() != 3 || !s.bytes().all(|b| b"xyzXYZ".contains(&b)) {
                    return Err(XmlError::value(
                        "<compiler>",
                        "eulerseq",
                        s,
                        "is not a sequence of 3 axes",
                    ));
                }
                c.eulerseq = s.as_bytes().to_vec();
            }
            if n.attribute("inertiafromgeom") == Some("true") {
                return Err(XmlError::element(
                    "<compiler inertiafromgeom=\"true\">",
                    "MuJoCo takes every body's inertia from its geoms and ignores <inertial>, so identified bodies cannot be written into it",
                ));
            }
        }
        Ok(c)
    }

    fn angle(&self, a: f64) -> f64 {
        match self.degrees {
            true => a.to_radians(),
            false => a,
        }
    }

    /// The rotation an element's orientation attributes give (identity
    /// without one), as MuJoCo's compiler makes it.
    fn orientation(&self, n: roxmltree::Node, what: &str) -> Result<Matrix3<f64>, XmlError> {
        let given: Vec<&str> = ["quat", "axisangle", "euler", "xyaxes", "zaxis"]
            .into_iter()
            .filter(|k| n.attribute(*k).is_some())
            .collect();
        let (key, text) = match given[..] {
            [] => return Ok(Matrix3::identity()),
            [k] => (k, n.attribute(k).unwrap_or_default()),
            _ => {
                return Err(XmlError::element(
                    what,
                    format!("more than one orientation ({})", given.join(", ")),
                ))
            }
        };
        let v = numbers(text, what, key)?;
        let count = |k: usize| match v.len() == k {
            true => Ok(()),
            false => Err(XmlError::value(what, key, text, format!("is not {k} numbers"))),
        };
        let read_from = (text, what, key);
        Ok(match key {
            "quat" => {
                count(4)?;
                let q = nalgebra::Quaternion::new(v[0], v[1], v[2], v[3]);
                if !(q.norm() > 1e-12) {
                    return Err(XmlError::value(what, key, text, "is a zero quaternion"));
                }
                UnitQuaternion::from_quaternion(q).to_rotation_matrix().into_inner()
            }
            "axisangle" => {
                count(4)?;
                let axis = nalgebra::Unit::new_unchecked(unit(Vector3::new(v[0], v[1], v[2]), read_from)?);
                axis_rotation(&axis, self.angle(v[3]))
            }
            "euler" => {
                count(3)?;
                // Lower case: about the moving axes (post-multiplied);
                // upper case: about the fixed ones (pre-multiplied).
                let mut r = Matrix3::identity();
                for (k, &c) in self.eulerseq.iter().enumerate() {
                    let axis = match c.to_ascii_lowercase() {
                        b'x' => Vector3::x_axis(),
                        b'y' => Vector3::y_axis(),
                        _ => Vector3::z_axis(),
                    };
                    let step = axis_rotation(&axis, self.angle(v[k]));
                    r = match c.is_ascii_lowercase() {
                        true => r * step,
                        false => step * r,
                    };
                }
                r
            }
            "xyaxes" => {
                count(6)?;
                let x = unit(Vector3::new(v[0], v[1], v[2]), read_from)?;
                let y = Vector3::new(v[3], v[4], v[5]);
                let y = unit(y - x * x.dot(&y), read_from)?;
                Matrix3::from_columns(&[x, y, x.cross(&y)])
            }
            _ => {
                count(3)?;
                let z = unit(Vector3::new(v[0], v[1], v[2]), read_from)?;
                UnitQuaternion::rotation_between(&Vector3::z(), &z)
                    .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI))
                    .to_rotation_matrix()
                    .into_inner()
            }
        })
    }

    /// An element's `pos` and orientation.
    fn pose(&self, n: roxmltree::Node, what: &str) -> Result<Pose, XmlError> {
        let p = match n.attribute("pos") {
            Some(t) => vector(t, what, "pos")?,
            None => Vector3::zeros(),
        };
        Ok(Pose {
            r: self.orientation(n, what)?,
            p,
        })
    }
}

/// Where an element's start tag ends: its attributes' end (before `/>`
/// or `>`), and just after it.
fn start_tag(text: &str, n: &roxmltree::Node) -> (usize, usize) {
    let r = n.range();
    let mut quote = None;
    for (k, c) in text[r.clone()].char_indices() {
        match (quote, c) {
            (Some(q), c) if c == q => quote = None,
            (Some(_), _) => {}
            (None, '"' | '\'') => quote = Some(c),
            (None, '>') => {
                let end = r.start + k;
                let attrs = if text[..end].ends_with('/') { end - 1 } else { end };
                return (attrs, end + 1);
            }
            _ => {}
        }
    }
    (r.end, r.end)
}

/// Walks the body tree as MuJoCo composes it.
struct Reader<'a> {
    text: &'a str,
    compiler: Compiler,
    defaults: Defaults<'a>,
    bodies: Vec<MjBody>,
}

impl<'a> Reader<'a> {
    /// The contents of a body (or the world) below `n`, through frames
    /// (`at`: the frame's pose in the body), into body `owner`.
    fn contents(
        &mut self,
        n: roxmltree::Node<'a, '_>,
        owner: Option<usize>,
        at: Pose,
        class: &'a str,
    ) -> Result<(), XmlError> {
        for c in n.children().filter(|c| c.is_element()) {
            match c.tag_name().name() {
                "frame" => {
                    let pose = at.then(&self.compiler.pose(c, "<frame>")?);
                    self.contents(c, owner, pose, c.attribute("childclass").unwrap_or(class))?;
                }
                "body" => self.body(c, owner, at, class)?,
                "joint" | "freejoint" => {
                    let Some(b) = owner else {
                        return Err(XmlError::element(
                            "<worldbody>",
                            "holds a <joint> itself: a joint moves a <body>",
                        ));
                    };
                    let j = self.joint(c, at, class)?;
                    self.bodies[b].joints.push(j);
                }
                "inertial" => {
                    if let Some(b) = owner {
                        let i = self.inertial(c, &at, &self.bodies[b].name)?;
                        self.bodies[b].inertial = Some((c.range(), i));
                    }
                }
                "include" | "attach" | "replicate" => {
                    return Err(XmlError::element(
                        format!("<{}> at byte {}", c.tag_name().name(), c.range().start),
                        ONE_FILE,
                    ))
                }
                _ => {}
            }
        }
        Ok(())
    }

    fn body(
        &mut self,
        c: roxmltree::Node<'a, '_>,
        parent: Option<usize>,
        at: Pose,
        class: &'a str,
    ) -> Result<(), XmlError> {
        let name = c.attribute("name").unwrap_or("").to_string();
        let local = at.then(&self.compiler.pose(c, &format!("<body name=\"{name}\">"))?);
        let world = parent.map_or(Pose::identity(), |p| self.bodies[p].world).then(&local);
        let (_, open_end) = start_tag(self.text, &c);
        self.bodies.push(MjBody {
            name,
            parent,
            local,
            world,
            joints: Vec::new(),
            inertial: None,
            open_end,
            indent: super::xml::indent(self.text, &c, "  "),
        });
        let id = self.bodies.len() - 1;
        self.contents(
            c,
            Some(id),
            Pose::identity(),
            c.attribute("childclass").unwrap_or(class),
        )
    }

    fn joint(&self, c: roxmltree::Node<'a, '_>, at: Pose, class: &'a str) -> Result<MjJoint, XmlError> {
        let name = c.attribute("name").unwrap_or("").to_string();
        let what = format!("<joint name=\"{name}\">");
        let class = c.attribute("class").unwrap_or(class);
        let get = |key: &str| {
            c.attribute(key)
                .or_else(|| self.defaults.joint(class, key).map(|(v, _)| v))
        };
        let kind = match c.tag_name().name() {
            "freejoint" => "free".to_string(),
            _ => get("type").unwrap_or("hinge").to_string(),
        };
        let pos = at.point(&get("pos").map_or(Ok(Vector3::zeros()), |t| vector(t, &what, "pos"))?);
        let axis_text = get("axis").unwrap_or("0 0 1");
        let axis = at.r * unit(vector(axis_text, &what, "axis")?, (axis_text, &what, "axis"))?;
        let reference = get("ref").map_or(Ok(0.0), |t| {
            t.trim()
                .parse::<f64>()
                .map_err(|_| XmlError::value(&what, "ref", t, "is not a number"))
        })?;
        let reference = match kind.as_str() {
            "hinge" => self.compiler.angle(reference),
            _ => reference,
        };
        let own = DYNAMICS.map(|k| c.attributes().find(|a| a.name() == k).map(|a| a.range_value()));
        let inherited = DYNAMICS.map(|k| match c.attribute(k) {
            Some(_) => None,
            None => self.defaults.joint(class, k).map(|(_, from)| from.to_string()),
        });
        let (attributes_end, _) = start_tag(self.text, &c);
        Ok(MjJoint {
            name,
            kind,
            pos,
            axis,
            reference,
            range: c.range(),
            attributes_end,
            own,
            inherited,
        })
    }

    /// An `<inertial>`'s body in the frame of the body that holds it.
    fn inertial(&self, c: roxmltree::Node, at: &Pose, body: &str) -> Result<Inertial, XmlError> {
        let what = format!("the <inertial> of body `{body}`");
        let pose = at.then(&self.compiler.pose(c, &what)?);
        let mass = match c.attribute("mass") {
            Some(m) => m
                .trim()
                .parse::<f64>()
                .map_err(|_| XmlError::value(&what, "mass", m, "is not a number"))?,
            None => return Err(XmlError::element(what, "no mass")),
        };
        let inertia = match (c.attribute("diaginertia"), c.attribute("fullinertia")) {
            (Some(d), None) => Matrix3::from_diagonal(&vector(d, &what, "diaginertia")?),
            (None, Some(f)) => match numbers(f, &what, "fullinertia")?[..] {
                [xx, yy, zz, xy, xz, yz] => Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz),
                _ => return Err(XmlError::value(&what, "fullinertia", f, "is not 6 numbers")),
            },
            _ => return Err(XmlError::element(what, "give diaginertia or fullinertia")),
        };
        Ok(pose.inertial(&Inertial {
            mass,
            com: Vector3::zeros(),
            inertia_com: inertia,
        }))
    }
}

impl Mjcf {
    /// The MJCF `text` read.
    pub fn read(text: &str) -> Result<Mjcf, XmlError> {
        let doc = super::xml::parse(text)?;
        let root = doc.root_element();
        if !root.has_tag_name("mujoco") {
            return Err(XmlError::Root {
                format: "MJCF",
                found: root.tag_name().name().to_string(),
            });
        }
        let mut reader = Reader {
            text,
            compiler: Compiler::of(root)?,
            defaults: Defaults::of(root),
            bodies: Vec::new(),
        };
        for w in root.children().filter(|c| c.has_tag_name("worldbody")) {
            reader.contents(w, None, Pose::identity(), "main")?;
        }
        if let Some(i) = root.descendants().find(|n| n.has_tag_name("include")) {
            return Err(XmlError::element(
                format!("<include> at byte {}", i.range().start),
                ONE_FILE,
            ));
        }
        Ok(Mjcf { bodies: reader.bodies })
    }

    /// The joint named `name`: its body and index there.
    pub fn joint(&self, name: &str) -> Option<(usize, usize)> {
        self.bodies
            .iter()
            .enumerate()
            .find_map(|(b, body)| body.joints.iter().position(|j| j.name == name).map(|k| (b, k)))
    }

    /// The bodies whose parent is `b`.
    pub fn children(&self, b: usize) -> impl Iterator<Item = usize> + '_ {
        (0..self.bodies.len()).filter(move |&c| self.bodies[c].parent == Some(b))
    }
}

/// The motion a joint adds at `x` from its reference (a hinge turns
/// about its axis through its position, a slide moves along it).
pub(crate) fn joint_motion(j: &MjJoint, x: f64) -> Pose {
    let d = x - j.reference;
    match j.kind.as_str() {
        "hinge" => {
            let r = axis_rotation(&nalgebra::Unit::new_unchecked(j.axis), d);
            Pose {
                r,
                p: j.pos - r * j.pos,
            }
        }
        "slide" => Pose::at(j.axis * d),
        _ => Pose::identity(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each orientation form gives the rotation MuJoCo documents; angles in
    /// degrees by default.
    #[test]
    fn orientations_as_mujoco_reads_them() {
        let xml = r#"<mujoco>
  <default><joint axis="0 1 0" damping="2"/><default class="wrist"><joint armature="0.1"/></default></default>
  <worldbody>
    <body name="a" euler="0 0 90"><joint name="ja"/>
      <body name="b" pos="1 0 0" axisangle="1 0 0 90" childclass="wrist"><joint name="jb" damping="3"/>
        <frame pos="0 0 1" quat="0 0 0 1">
          <body name="c" xyaxes="0 1 0 -1 0 0"><joint name="jc" axis="1 0 0" ref="30"/>
            <inertial pos="0.1 0 0" mass="2" diaginertia="1 2 3"/>
          </body>
        </frame>
      </body>
    </body>
  </worldbody>
</mujoco>"#;
        let m = Mjcf::read(xml).unwrap();
        let rz90 = Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
        assert!((m.bodies[0].world.r - rz90).amax() < 1e-15);
        let rx90 = Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0);
        assert!((m.bodies[1].local.r - rx90).amax() < 1e-15);
        assert!((m.bodies[1].world.p - Vector3::new(0.0, 1.0, 0.0)).norm() < 1e-15);
        // The frame turns 180° about z, then c's xyaxes turn 90° about z.
        let rz180 = Matrix3::new(-1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0);
        assert!((m.bodies[2].local.r - rz180 * rz90).amax() < 1e-15);
        assert!((m.bodies[2].local.p - Vector3::new(0.0, 0.0, 1.0)).norm() < 1e-15);
        // Defaults: the main class's axis and damping, the wrist class's
        // armature below b; own values win.
        let (ja, jb, jc) = (&m.bodies[0].joints[0], &m.bodies[1].joints[0], &m.bodies[2].joints[0]);
        assert_eq!(ja.axis, Vector3::y());
        assert_eq!(ja.inherited, [None, Some("main".into()), None]);
        assert!(jb.own[1].is_some());
        assert_eq!(jb.inherited, [Some("wrist".into()), None, None]);
        assert_eq!(jc.axis, Vector3::x());
        assert!((jc.reference - 30f64.to_radians()).abs() < 1e-15);
        let (_, i) = m.bodies[2].inertial.as_ref().unwrap();
        assert_eq!((i.mass, i.com), (2.0, Vector3::new(0.1, 0.0, 0.0)));
    }

    #[test]
    fn what_robotid_cannot_follow_is_named() {
        for (xml, says) in [
            (r#"<mujoco><include file="arm.xml"/></mujoco>"#, "<include>"),
            (
                r#"<mujoco><compiler inertiafromgeom="true"/><worldbody/></mujoco>"#,
                "inertiafromgeom",
            ),
            (
                r#"<mujoco><worldbody><body quat="1 0 0 0" euler="0 0 1"/></worldbody></mujoco>"#,
                "more than one orientation",
            ),
            (r#"<robot name="x"/>"#, "not an MJCF"),
        ] {
            let e = Mjcf::read(xml).err().unwrap().to_string();
            assert!(e.contains(says), "{e}");
        }
    }
}
