//! The user's own URDF with identified dynamics: each moving link's
//! `<inertial>` and each moving joint's `<dynamics>` replaced, every other
//! byte kept (names, visuals, collisions, meshes, `<transmission>`,
//! `<ros2_control>`, `<gazebo>`, comments, attribute order).
//!
//! A body the model lumps is written on the moving joint's child link.
//! Links on fixed joints below it have their own inertials taken out, so
//! that nothing counts twice. Links on joints the model locked (a gripper
//! the log does not hold) still move in a simulator and need their
//! bodies: they keep the robot file's, and the child link gets the
//! identified body less theirs (at the locked position) where that is a
//! body; where it is not, they are taken out too, said. Comments say where
//! each inertial went.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::ops::Range;
use std::path::Path;

use super::error::PatchError;
use super::urdf::{dynamics, friction_comment, inertial};
use crate::dynamics::model::{Inertial, Model};
use crate::dynamics::urdf::{parse_urdf_with, Locks};
use crate::dynamics::xml::indent;

/// What patching did to one link, for the sidecar and the command's
/// report.
#[derive(Debug, Clone, PartialEq)]
pub struct Patched {
    /// The URDF link that carries the identified body of `joint`.
    pub link: String,
    pub joint: String,
    /// Links whose inertials the body holds, their own taken out.
    pub lumped: Vec<String>,
    /// Links on locked joints that keep the robot file's inertials, taken
    /// out of the body written on `link`.
    pub carried: Vec<String>,
    /// Why links on locked joints lost their inertials (the identified
    /// body less theirs is no body).
    pub said: Option<String>,
}

/// A link hung below a moving one by joints that do not move.
struct Hung<'a> {
    link: &'a str,
    /// Below a locked (not fixed) joint: it moves in a simulator.
    carried: bool,
}

/// `text` (the URDF at `path` that `model` was loaded from) with
/// `model`'s bodies and friction written into it; `note` goes into a
/// comment inside each replaced `<inertial>`. Refused when a joint of the
/// model is not in the text (another robot file).
pub fn patch_urdf(text: &str, path: &Path, model: &Model, note: &str) -> Result<(String, Vec<Patched>), PatchError> {
    UrdfPatch::new(text.to_string(), path, model)?.apply(model, note)
}

/// A robot file's URDF read for patching, once for any number of models
/// of it (the same joints and locks, other bodies and friction): the
/// carried links' share of each body is the robot file's, found by loading
/// it twice.
pub struct UrdfPatch {
    text: String,
    /// Each body's share that links on locked joints hold (None: none).
    shares: Vec<Option<Inertial>>,
}

/// A URDF's links and joints by name, and the links hung below each of
/// the model's moving joints' child links.
struct Tree<'a, 'i> {
    links: HashMap<&'a str, roxmltree::Node<'a, 'i>>,
    joints: HashMap<&'a str, roxmltree::Node<'a, 'i>>,
    hung: Vec<(&'a str, Vec<Hung<'a>>)>,
}

impl<'a, 'i> Tree<'a, 'i> {
    fn of(doc: &'a roxmltree::Document<'i>, model: &Model) -> Result<Tree<'a, 'i>, PatchError> {
        let robot = doc.root_element();
        let named = |tag: &'static str| -> HashMap<&'a str, roxmltree::Node<'a, 'i>> {
            robot
                .children()
                .filter(|n| n.has_tag_name(tag))
                .filter_map(|n| Some((n.attribute("name")?, n)))
                .collect()
        };
        let (links, joints) = (named("link"), named("joint"));
        let moving: HashSet<&str> = model.joints.iter().map(|j| j.name.as_str()).collect();
        // Each link's joints to its children that do not move (and whether
        // the joint is locked rather than fixed): what is lumped.
        let mut rigid: BTreeMap<&str, Vec<(&str, bool)>> = BTreeMap::new();
        // In the file's order, not the map's: what is said and written
        // names the lumped links alike on every run.
        let mut in_order: Vec<(&&str, &roxmltree::Node)> = joints.iter().collect();
        in_order.sort_by_key(|(_, j)| j.range().start);
        for (name, j) in in_order {
            if let (false, Some(p), Some(c)) = (moving.contains(name), end(*j, "parent"), end(*j, "child")) {
                rigid
                    .entry(p)
                    .or_default()
                    .push((c, j.attribute("type") != Some("fixed")));
            }
        }
        let mut hung = Vec::new();
        for mj in &model.joints {
            let joint = joints.get(mj.name.as_str()).ok_or_else(|| PatchError::MissingJoint {
                format: "URDF",
                joint: mj.name.clone(),
                joints: Vec::new(),
            })?;
            let link = end(*joint, "child").ok_or_else(|| PatchError::NoChild { joint: mj.name.clone() })?;
            if !links.contains_key(link) {
                return Err(PatchError::MissingLink {
                    link: link.to_string(),
                    joint: mj.name.clone(),
                });
            }
            hung.push((link, below(link, false, &rigid)));
        }
        Ok(Tree { links, joints, hung })
    }

    /// Link `l`'s `<inertial>` element.
    fn inertial_of(&self, l: &str) -> Option<roxmltree::Node<'a, 'i>> {
        self.links.get(l)?.children().find(|c| c.has_tag_name("inertial"))
    }
}

impl UrdfPatch {
    pub fn new(text: String, path: &Path, model: &Model) -> Result<UrdfPatch, PatchError> {
        let doc = crate::dynamics::xml::parse(&text)?;
        let tree = Tree::of(&doc, model)?;
        // The carried links' share of each body, at their locked positions:
        // the robot file's bodies with and without their inertials.
        let carried: Vec<Range<usize>> = tree
            .hung
            .iter()
            .flat_map(|(_, h)| h.iter().filter(|h| h.carried).filter_map(|h| tree.inertial_of(h.link)))
            .map(|n| n.range())
            .collect();
        let shares = match carried.is_empty() {
            true => vec![None; model.joints.len()],
            false => carried_shares(&text, path, model, &carried)?,
        };
        Ok(UrdfPatch { text, shares })
    }

    /// The URDF with `model`'s bodies and friction written into it, and
    /// what was done to each link.
    pub fn apply(&self, model: &Model, note: &str) -> Result<(String, Vec<Patched>), PatchError> {
        let text = self.text.as_str();
        let doc = crate::dynamics::xml::parse(text)?;
        let tree = Tree::of(&doc, model)?;
        let mut edits: Vec<(Range<usize>, String)> = Vec::new();
        let mut patched = Vec::new();
        for (i, ((link_name, hung), share)) in tree.hung.iter().zip(&self.shares).enumerate() {
            let p = body_edits(
                text,
                &tree,
                (link_name, hung),
                (&model.links[i], share.as_ref()),
                note,
                &mut edits,
            );
            let joint = tree.joints[model.joints[i].name.as_str()];
            let element = format!(
                "{}\n{}{}",
                friction_comment(model, i),
                indent(text, &joint, "  "),
                dynamics(model, i)
            );
            edits.push(match joint.children().find(|c| c.has_tag_name("dynamics")) {
                Some(d) => (d.range(), element),
                None => insert_before_close(text, &joint, &element),
            });
            patched.push(Patched {
                joint: model.joints[i].name.clone(),
                ..p
            });
        }
        Ok((apply(text, edits), patched))
    }
}

/// The edits that write `body` on `link` and take the lumped links'
/// inertials out; the links lumped and carried, and what is said (the
/// joint's name left to the caller).
fn body_edits(
    text: &str,
    tree: &Tree,
    (link_name, hung): (&str, &[Hung]),
    (body, share): (&Inertial, Option<&Inertial>),
    note: &str,
    edits: &mut Vec<(Range<usize>, String)>,
) -> Patched {
    let rest = share.map(|s| body.without(s));
    let keep_carried = matches!(rest, Some(Some(_)));
    let (lumped, carried): (Vec<&Hung>, Vec<&Hung>) = hung.iter().partition(|h| !(h.carried && keep_carried));
    let lumped: Vec<String> = lumped.iter().map(|h| h.link.to_string()).collect();
    let carried: Vec<String> = carried.iter().map(|h| h.link.to_string()).collect();
    let said = matches!(rest, Some(None)).then(|| {
        format!(
            "the identified body of {link_name} less the robot file's bodies of {} (on locked joints) is no body: their inertials are in it, and they have none of their own",
            hung.iter().filter(|h| h.carried).map(|h| h.link).collect::<Vec<_>>().join(", ")
        )
    });
    let mut comment = note.to_string();
    if !lumped.is_empty() {
        comment += &format!(
            "; this body holds the links {} (their inertials moved here)",
            lumped.join(", ")
        );
    }
    if !carried.is_empty() {
        comment += &format!(
            "; the links {} on locked joints keep their own, taken out of it",
            carried.join(", ")
        );
    }
    let written = rest.flatten().unwrap_or(*body);
    let link = &tree.links[link_name];
    edits.push(replace_inertial(
        text,
        link,
        &inertial(&written, &indent(text, link, "  "), Some(&comment)),
    ));
    for l in &lumped {
        if let Some(own) = tree.inertial_of(l) {
            let why = format!(
                "<!-- robotid: this link's inertial is in the identified body of {} -->",
                crate::dynamics::xml::comment(link_name)
            );
            edits.push((own.range(), why));
        }
    }
    Patched {
        link: link_name.to_string(),
        joint: String::new(),
        lumped,
        carried,
        said,
    }
}

/// `text` with each range replaced.
pub(super) fn apply(text: &str, mut edits: Vec<(Range<usize>, String)>) -> String {
    edits.sort_by_key(|(r, _)| r.start);
    let mut out = String::with_capacity(text.len() + 4096);
    let mut at = 0;
    for (r, with) in edits {
        out.push_str(&text[at..r.start]);
        out.push_str(&with);
        at = r.end;
    }
    out.push_str(&text[at..]);
    out
}

/// Each body's share that the links whose `<inertial>` elements are at
/// `carried` hold, as the model's loader lumps them (None: none).
fn carried_shares(
    text: &str,
    path: &Path,
    model: &Model,
    carried: &[Range<usize>],
) -> Result<Vec<Option<Inertial>>, PatchError> {
    let locks = Locks {
        keep: Some(model.joints.iter().map(|j| j.name.clone()).collect()),
        positions: model.locked.iter().cloned().collect(),
    };
    let bare = apply(text, carried.iter().map(|r| (r.clone(), String::new())).collect());
    let load = |t: &str| parse_urdf_with(t, path, &locks).map_err(|e| PatchError::Load(Box::new(e)));
    let (with, without) = (load(text)?, load(&bare)?);
    Ok(with.links.iter().zip(&without.links).map(|(a, b)| a.minus(b)).collect())
}

/// The link at a joint's `side` ("parent" or "child").
fn end<'a>(joint: roxmltree::Node<'a, '_>, side: &str) -> Option<&'a str> {
    joint.children().find(|c| c.has_tag_name(side))?.attribute("link")
}

/// The links hung from `link` by joints that do not move, depth first;
/// `carried` once a locked joint is on the way.
fn below<'a>(link: &str, carried: bool, rigid: &BTreeMap<&'a str, Vec<(&'a str, bool)>>) -> Vec<Hung<'a>> {
    let mut out = Vec::new();
    for &(c, locked) in rigid.get(link).into_iter().flatten() {
        out.push(Hung {
            link: c,
            carried: carried || locked,
        });
        out.extend(below(c, carried || locked, rigid));
    }
    out
}

/// The edit that puts `inertial` in `link`: in place of its own, else as
/// its first child (a self-closed `<link name=".."/>` opened for it).
fn replace_inertial(text: &str, link: &roxmltree::Node, inertial: &str) -> (Range<usize>, String) {
    if let Some(own) = link.children().find(|c| c.has_tag_name("inertial")) {
        return (own.range(), inertial.to_string());
    }
    let r = link.range();
    if let Some(open) = text[r.clone()].strip_suffix("/>") {
        let (own, open) = (indent(text, link, ""), open.trim_end());
        let inner = indent(text, link, "  ");
        return (r, format!("{open}>\n{inner}{inertial}\n{own}</link>"));
    }
    insert_before_close(text, link, inertial)
}

/// The edit that puts `element` last in `parent` (before its closing
/// tag), on a line of its own at its siblings' indentation.
fn insert_before_close(text: &str, parent: &roxmltree::Node, element: &str) -> (Range<usize>, String) {
    let r = parent.range();
    let close = text[..r.end].rfind("</").unwrap_or(r.end);
    // Keep the whitespace that leads to the closing tag after the insert.
    let lead = text[..close].trim_end_matches([' ', '\t']).len();
    let inner = indent(text, parent, "  ");
    (lead..lead, format!("{inner}{element}\n"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dynamics::{parse_urdf, parse_urdf_with, Locks};
    use nalgebra::{Matrix3, Vector3};
    use std::path::Path;

    /// A user's URDF: comments, shapes, a self-closed link, a joint with
    /// and one without `<dynamics>`, a flange on a fixed joint, and the
    /// elements robotid does not read.
    const URDF: &str = r#"<?xml version="1.0"?>
<!-- my arm, by hand -->
<robot name="arm">
  <link name="base_link">
    <visual><geometry><box size="0.2 0.2 0.1"/></geometry></visual>
    <inertial><origin xyz="0 0 0.05"/><mass value="4"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
  </link>
  <joint name="shoulder" type="revolute">
    <parent link="base_link"/>
    <child link="upper"/>
    <origin xyz="0 0 0.1" rpy="0 0 0"/>
    <axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="50" velocity="2"/>
    <dynamics friction="0.3" damping="0.1"/>
  </joint>
  <link name="upper">
    <visual><geometry><mesh filename="package://arm/upper.dae"/></geometry></visual>
    <collision><geometry><cylinder radius="0.05" length="0.4"/></geometry></collision>
    <inertial>
      <origin xyz="0 0 0.2" rpy="0 0 0"/>
      <mass value="2"/>
      <inertia ixx="0.03" ixy="0" ixz="0" iyy="0.03" iyz="0" izz="0.004"/>
    </inertial>
  </link>
  <joint name="elbow" type="revolute">
    <parent link="upper"/>
    <child link="fore"/>
    <origin xyz="0 0 0.4" rpy="1.5707963 0 0"/>
    <axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="30" velocity="2"/>
  </joint>
  <link name="fore"/>
  <joint name="flange_joint" type="fixed">
    <parent link="fore"/>
    <child link="flange"/>
    <origin xyz="0.3 0 0"/>
  </joint>
  <link name="flange">
    <inertial><origin xyz="0.01 0 0"/><mass value="0.5"/><inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial>
  </link>
  <transmission name="t1"><type>transmission_interface/SimpleTransmission</type></transmission>
  <gazebo reference="upper"><material>Gazebo/Orange</material></gazebo>
</robot>
"#;

    /// The text with every `<tag …>…</tag>` or `<tag …/>` of `tags` and
    /// every robotid comment cut out, blank lines dropped.
    fn without(text: &str, tags: &[&str]) -> Vec<String> {
        let mut s = text.to_string();
        // Comments first: robotid's name `<dynamics>` in their text.
        for open in ["<!-- robotid".to_string()]
            .into_iter()
            .chain(tags.iter().map(|t| format!("<{t}")))
        {
            while let Some(a) = s.find(&open) {
                let start_tag = s[a..].find('>').unwrap() + 1;
                let b = if open.starts_with("<!--") {
                    a + s[a..].find("-->").unwrap() + 3
                } else if s[a..a + start_tag].ends_with("/>") {
                    a + start_tag
                } else {
                    let close = format!("</{}>", &open[1..]);
                    a + s[a..].find(&close).unwrap() + close.len()
                };
                s.replace_range(a..b, "");
            }
        }
        s.lines().filter(|l| !l.trim().is_empty()).map(str::to_string).collect()
    }

    #[test]
    fn the_users_urdf_keeps_every_byte_but_the_bodies_and_friction() {
        let mut model = parse_urdf(URDF, Path::new("arm.urdf")).unwrap();
        // Identified: other bodies and friction than the file's.
        for (k, l) in model.links.iter_mut().enumerate() {
            l.mass *= 1.3 + k as f64;
            l.com += Vector3::new(0.01, -0.02, 0.03);
            l.inertia_com += Matrix3::new(0.002, 0.0005, 0.0, 0.0005, 0.003, -0.0002, 0.0, -0.0002, 0.001);
        }
        model.friction[0].viscous_pos = 0.7;
        model.friction[1].coulomb_neg = 1.1;
        let (text, patched) = patch_urdf(URDF, Path::new("arm.urdf"), &model, "identified by robotid").unwrap();
        // Read back, the bodies and friction are the identified ones: the
        // flange is in the forearm's body once, not twice.
        let back = parse_urdf(&text, Path::new("arm.urdf")).unwrap();
        for (a, b) in back.links.iter().zip(&model.links) {
            assert!((a.mass - b.mass).abs() < 1e-12 && (a.com - b.com).norm() < 1e-12);
            assert!((a.inertia_com - b.inertia_com).norm() < 1e-12, "{a:?} {b:?}");
        }
        for (a, b) in back.friction.iter().zip(&model.friction) {
            assert!((a.viscous_pos - 0.5 * (b.viscous_pos + b.viscous_neg)).abs() < 1e-12);
            assert!((a.coulomb_pos - 0.5 * (b.coulomb_pos + b.coulomb_neg)).abs() < 1e-12);
        }
        assert_eq!(patched[1].lumped, vec!["flange".to_string()]);
        assert!(text.contains("<!-- robotid: this link's inertial is in the identified body of fore -->"));
        // Everything else as the user wrote it, line for line; the
        // self-closed link opened for its body.
        let (was, is) = (
            without(URDF, &["inertial", "dynamics"]),
            without(&text, &["inertial", "dynamics"]),
        );
        let is: Vec<String> = is
            .join("\n")
            .replace("<link name=\"fore\">\n  </link>", "<link name=\"fore\"/>")
            .lines()
            .map(str::to_string)
            .collect();
        assert_eq!(was, is);
        // The base's inertial is the user's.
        assert!(text.contains("<inertial><origin xyz=\"0 0 0.05\"/><mass value=\"4\"/>"));
    }

    /// The arm with a revolute gripper on the flange and a camera fixed
    /// to it, the gripper locked (the log does not hold it).
    fn with_gripper() -> String {
        let gripper = r#"  <joint name="grip" type="revolute">
    <parent link="flange"/>
    <child link="gripper"/>
    <origin xyz="0.05 0 0" rpy="0 0.3 0"/>
    <axis xyz="1 0 0"/>
    <limit lower="-1" upper="1" effort="5" velocity="1"/>
  </joint>
  <link name="gripper">
    <inertial><origin xyz="0.02 0.01 0"/><mass value="0.8"/><inertia ixx="0.002" ixy="0" ixz="0" iyy="0.003" iyz="0" izz="0.002"/></inertial>
  </link>
  <joint name="camera_mount" type="fixed">
    <parent link="gripper"/>
    <child link="camera"/>
    <origin xyz="0 0.04 0"/>
  </joint>
  <link name="camera">
    <inertial><origin xyz="0 0 0.01"/><mass value="0.1"/><inertia ixx="0.0001" ixy="0" ixz="0" iyy="0.0001" iyz="0" izz="0.0001"/></inertial>
  </link>
"#;
        URDF.replace("  <transmission", &format!("{gripper}  <transmission"))
    }

    #[test]
    fn a_locked_gripper_keeps_its_body_and_the_arm_link_gets_the_rest() {
        let text = with_gripper();
        let path = Path::new("arm.urdf");
        let locks = Locks {
            keep: Some(vec!["shoulder".into(), "elbow".into()]),
            positions: [("grip".to_string(), 0.4)].into(),
        };
        let prior = parse_urdf_with(&text, path, &locks).unwrap();
        let identified = |scale: f64| {
            let mut m = prior.clone();
            m.links[1].mass *= scale;
            m.links[1].com += Vector3::new(0.003, 0.0, -0.002);
            m
        };
        // 10 % heavier than the robot file says: the forearm gets the
        // rest, the gripper and its camera keep their own inertials (and
        // move with the gripper in a simulator).
        let model = identified(1.1);
        let (patched, said) = patch_urdf(&text, path, &model, "identified").unwrap();
        assert_eq!(said[1].lumped, vec!["flange".to_string()]);
        assert_eq!(said[1].carried, vec!["gripper".to_string(), "camera".to_string()]);
        assert!(said[1].said.is_none());
        assert!(patched.contains(r#"<inertial><origin xyz="0.02 0.01 0"/><mass value="0.8"/>"#));
        // Loaded as the identification loaded it (gripper locked at 0.4
        // rad), the body is the identified one.
        let back = parse_urdf_with(&patched, path, &locks).unwrap();
        let (a, b) = (&back.links[1], &model.links[1]);
        assert!(
            (a.mass - b.mass).abs() < 1e-12 && (a.com - b.com).norm() < 1e-12,
            "{a:?} {b:?}"
        );
        assert!((a.inertia_com - b.inertia_com).norm() < 1e-12, "{a:?} {b:?}");
        // Lighter than the gripper: no forearm body is left once the
        // gripper's is taken out; the gripper's inertials go into the body,
        // said.
        let model = identified(0.3);
        let (patched, said) = patch_urdf(&text, path, &model, "identified").unwrap();
        assert!(said[1].carried.is_empty() && said[1].said.as_deref().unwrap().contains("is no body"));
        let back = parse_urdf_with(&patched, path, &locks).unwrap();
        assert!((back.links[1].mass - model.links[1].mass).abs() < 1e-12);
    }

    /// Two tools fixed side by side on the flange: they are named in the
    /// file's order on every run (a map's order differed between runs of
    /// the real Panda's identify, fingers swapped in the URDF comment).
    #[test]
    fn lumped_links_are_named_in_the_files_order() {
        let tools = r#"  <joint name="zeta_mount" type="fixed">
    <parent link="flange"/>
    <child link="zeta"/>
  </joint>
  <link name="zeta"/>
  <joint name="alpha_mount" type="fixed">
    <parent link="flange"/>
    <child link="alpha"/>
  </joint>
  <link name="alpha"/>
"#;
        let text = URDF.replace("  <transmission", &format!("{tools}  <transmission"));
        let model = parse_urdf(&text, Path::new("arm.urdf")).unwrap();
        for _ in 0..16 {
            let (_, said) = patch_urdf(&text, Path::new("arm.urdf"), &model, "").unwrap();
            assert_eq!(said[1].lumped, ["flange", "zeta", "alpha"]);
        }
    }

    #[test]
    fn a_model_of_another_robot_is_refused() {
        let mut model = parse_urdf(URDF, Path::new("arm.urdf")).unwrap();
        model.joints[1].name = "wrist".into();
        let e = patch_urdf(URDF, Path::new("arm.urdf"), &model, "").unwrap_err();
        assert!(
            matches!(&e, PatchError::MissingJoint { joint, .. } if joint == "wrist"),
            "{e}"
        );
        assert!(
            e.to_string().contains("joint `wrist` of the model is not in the URDF"),
            "{e}"
        );
    }
}
