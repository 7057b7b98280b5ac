//! Why a user's URDF or MJCF cannot take the identified bodies: typed, so
//! that each front end words it and a program can tell the cases apart.

use crate::dynamics::xml::XmlError;

/// Why a user's robot file (URDF or MJCF) cannot be patched with a model's
/// bodies.
#[derive(Debug, thiserror::Error)]
pub enum PatchError {
    /// Not read: malformed, over a limit, a value that is not a number.
    #[error(transparent)]
    Xml(#[from] XmlError),
    /// A joint of the model the file does not have (`joints`: the file's
    /// own, where it names them).
    #[error("joint `{joint}` of the model is not in the {format}{}", listed(.joints))]
    MissingJoint {
        format: &'static str,
        joint: String,
        joints: Vec<String>,
    },
    /// A URDF joint without a child link.
    #[error("joint `{joint}` has no child link")]
    NoChild { joint: String },
    /// A URDF joint's child link missing.
    #[error("link `{link}` (child of `{joint}`) is not in the URDF")]
    MissingLink { link: String, joint: String },
    /// An MJCF joint of another kind than the robot file's hinge.
    #[error("joint `{joint}` is a {kind} joint in the MJCF, a hinge in the robot file")]
    JointKind { joint: String, kind: String },
    /// An MJCF body holding more than one of the model's joints.
    #[error("body `{body}` holds joint `{joint}` and {others} other(s): robotid writes one identified body per joint")]
    SharedBody { body: String, joint: String, others: usize },
    /// The file's kinematics are not the robot file's.
    #[error("its kinematics are not the robot file's: joint `{joint}`'s axis is {angle_rad:.2e} rad and {distance_m:.2e} m from the robot file's, with the robot file's base at {base} (another robot, or another zero pose)")]
    Kinematics {
        joint: String,
        angle_rad: f64,
        distance_m: f64,
        base: String,
    },
    /// The model has no joint to patch.
    #[error("the model has no joint")]
    NoJoint,
    /// The identified body less what it carries on locked joints has no
    /// mass left, or no inertia a body can have.
    #[error("the identified body of `{body}` less the bodies it carries on locked joints ({carried}) is no body: give them lighter <inertial>s, or lock them in the robot file too")]
    NothingLeft { body: String, carried: String },
    /// A body on a locked joint without an `<inertial>` (MuJoCo takes its
    /// mass from its geoms, which robotid does not compute).
    #[error("body `{body}` moves on a joint the model holds locked and has no <inertial>: MuJoCo would take its mass from its geoms, which robotid does not compute; give it an <inertial> so that robotid can take it out of the identified body of `{of}`")]
    NoInertial { body: String, of: String },
    /// A body to add whose name the file has already.
    #[error("it has a body `{0}` already")]
    BodyExists(String),
    /// The robot file, loaded to find the carried links' share, refused.
    #[error("{0}")]
    Load(Box<crate::Error>),
}

fn listed(joints: &[String]) -> String {
    match joints.is_empty() {
        true => String::new(),
        false => format!(" (its joints: {})", joints.join(", ")),
    }
}
