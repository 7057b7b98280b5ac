//! `identify` as one library call: from recordings and a robot file to a
//! validated model — the pipelines designed from the data
//! ([`design`]), run, the estimate judged against the noise
//! floor and held-out data (the refusal policy, [`robotid::verdict`]), its
//! physically consistent fit, the report and the exports — returned typed
//! as an [`Identification`] for the command line to print, for Python and
//! for Ray. Everything is written into a staging folder that appears as
//! the output folder at once when identify ends, refused or not.

pub mod design;
mod judge;
mod payload;
mod recordings;
mod script;
mod warnings;
mod work;

use std::path::{Path, PathBuf};

use crate::design::Design;
use robotid::validation::Validated;
use robotid::verdict::{Policy, Verdict};
use robotid::RunReport;
use robotid_report::export::Exported;
use robotid_stages::stage::estimate::Outcome;
use robotid_stages::stage::read::ReadConfig;

pub use payload::{payload_against_parameters, payload_from_tables};
pub use warnings::ROLLOUT_WORSE;
pub use work::identify;

/// What to identify, and how strictly.
#[derive(Clone, Debug)]
pub struct Request {
    /// Recordings of the excitation, periodic or not; the parameters are
    /// estimated from all of them.
    pub recordings: Vec<PathBuf>,
    /// The robot file (TOML or URDF).
    pub robot: PathBuf,
    /// Held-out recordings to validate the identified model on.
    pub validate: Vec<PathBuf>,
    /// The output folder (default `out/identify/<first recording's name>`):
    /// it must not exist or be empty.
    pub out: Option<PathBuf>,
    /// Where the channels are, for every recording (a pipeline file's
    /// `[read]` table); None: found in the logs.
    pub read: Option<ReadConfig>,
    /// The drives' joint torque per ampere, N·m/A: one per joint, one for
    /// all, or none (the robot file's drives, or torque channels).
    pub torque_per_amp: Vec<f64>,
    /// The refusal policy: the held-out relative error tolerated, and
    /// whether any joint over 3× its noise floor is refused.
    pub policy: Policy,
    /// Write the physical fit and the exports even when the fit is refused.
    pub accept_inadequate: bool,
    /// Worker threads of the pipeline runs (default: one per core); the
    /// outputs do not depend on it.
    pub threads: Option<usize>,
    /// The user's own MJCF of the robot: the MJCF export is it, patched
    /// (else MJCF made from the robot file).
    pub mjcf: Option<PathBuf>,
    /// Records of the robot carrying a payload: the payload identified
    /// against the robot identified from `recordings`.
    pub payload: Option<PayloadRequest>,
    /// The controller the `validate` recordings ran under (a TOML file's
    /// `[controller]` table, kp, kd, ki per joint): the estimate and the
    /// robot file's parameters simulated under it in closed loop, tracking
    /// each record's reference (its `ref_<joint>` channels), in the report.
    pub controller: Option<PathBuf>,
    /// A Python with the `mujoco` package: the exported MJCF rolled out
    /// by MuJoCo itself beside robotid's rollouts, in the report
    /// ([`robotid::mujoco`]).
    pub mujoco: Option<PathBuf>,
}

/// The payload to identify (`estimation::payload`).
#[derive(Clone, Debug)]
pub struct PayloadRequest {
    /// Recordings of the robot with the payload on.
    pub loaded: Vec<PathBuf>,
    /// The link holding it: the last moving link or one welded to it
    /// (a flange, `tool0`); the payload is given in its frame.
    pub link: String,
    /// Its mass, kg, when known: the drives' gains are identified (the
    /// efforts as read times a scale per joint).
    pub known_mass: Option<f64>,
    /// Where its mass can be, in the link's frame: an ellipsoid's centre
    /// and semi-axes, m (the bounded estimate keeps inside it).
    pub bound: Option<([f64; 3], [f64; 3])>,
    /// Held-out recordings with the payload: the robot and payload
    /// identified predict their torques (not with a known mass).
    pub validate: Vec<PathBuf>,
}

/// The payload's model on held-out loaded records: the relative error of
/// the predicted torque, and per joint the mean squared residue over the
/// record's noise floor (None: no floor).
#[derive(Clone, Debug)]
pub struct PayloadValidation {
    pub relative_error: f64,
    pub joints: Vec<(String, Option<f64>)>,
}

impl PayloadValidation {
    /// The relative error and each joint's residue over its floor, said.
    pub fn said(&self) -> String {
        let joints: Vec<String> = self
            .joints
            .iter()
            .map(|(j, r)| match r {
                Some(r) => format!("{j} {r:.2}×"),
                None => format!("{j} (no floor)"),
            })
            .collect();
        format!(
            "relative error {:.2} %; residue over the noise floor: {}",
            100.0 * self.relative_error,
            joints.join(", ")
        )
    }
}

impl Request {
    /// The request of `recordings` of `robot` with every default: no
    /// validation recordings, the default policy.
    pub fn new(recordings: Vec<PathBuf>, robot: PathBuf) -> Request {
        Request {
            recordings,
            robot,
            validate: Vec::new(),
            out: None,
            read: None,
            torque_per_amp: Vec::new(),
            policy: Policy {
                tolerance: robotid::verdict::DEFAULT_TOLERANCE,
                strict: false,
            },
            accept_inadequate: false,
            threads: None,
            mjcf: None,
            payload: None,
            controller: None,
            mujoco: None,
        }
    }
}

/// What a recording is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    Excitation,
    Validation,
    /// The robot with a payload.
    Loaded,
}

impl Role {
    pub fn name(self) -> &'static str {
        match self {
            Role::Excitation => "excitation",
            Role::Validation => "validation",
            Role::Loaded => "loaded",
        }
    }
}

/// One recording and the pipeline designed for it.
#[derive(Debug)]
pub struct Recording {
    pub role: Role,
    /// Its name in the output folder (the file's stem, made unique).
    pub name: String,
    pub log: PathBuf,
    pub design: Design,
}

/// One recording's pipeline run: what the robot file said on the way
/// and the run's report.
pub struct Ran {
    /// The robot file's warnings.
    pub warnings: Vec<String>,
    /// The joints the robot file's model locks, said.
    pub locked: Option<String>,
    pub report: RunReport,
}

/// The physically consistent estimate (what the exports need), or why
/// there is none.
pub enum Physical {
    /// Refused, and not written anyway.
    Refused,
    /// Joint-wise records give the decoupled model, not the links' bodies.
    JointWise,
    /// The fit failed: why.
    Failed(String),
    Fitted {
        outcome: Box<Outcome>,
        /// The fit with the estimate's covariance failed (why): made with
        /// the residual's.
        fallback: Option<String>,
        /// Its validation on the held-out recordings.
        validation: Option<Box<Validated>>,
        export: Exported,
    },
}

/// What `identify` found and wrote.
pub struct Identification {
    /// The output folder, as the request named it.
    pub out: PathBuf,
    pub recordings: Vec<Recording>,
    /// Joints no joint-wise record moves, locked where they were held.
    pub locked: Option<String>,
    pub runs: Vec<Ran>,
    /// The least-squares estimate (`parameters.parquet`).
    pub estimate: Box<Outcome>,
    pub verdict: Verdict,
    /// Why the fit is refused, with what identify found on the way; None:
    /// identified.
    pub refused: Option<String>,
    /// Joints with no noise floor to judge the fit against (records that
    /// do not repeat): the residue said, unjudged.
    pub unjudged: Vec<String>,
    /// The estimate validated on the held-out recordings.
    pub validation: Option<Box<Validated>>,
    pub physical: Physical,
    /// The report's rollouts (multiple shooting, every
    /// `ROLLOUT_WINDOW_S`): on each validation record (else each
    /// identification one), the estimate's and the robot file's position
    /// and velocity errors; Err: why there are none, as the report says.
    pub rollouts: robotid::simulation::Rolled,
    /// The closed-loop runs on the validation records under the declared
    /// controller, when one is; Err: why there are none, as the report
    /// says.
    pub closed_loop: robotid::simulation::ClosedLooped,
    /// The physically consistent estimate rolled out on each record of
    /// `rollouts`, in its windows.
    pub physical_rollouts: robotid::simulation::PhysicalRolled,
    /// The exported MJCF rolled out by MuJoCo on each record of
    /// `rollouts`, with `Request::mujoco`.
    pub mujoco: robotid::simulation::InMujoco,
    /// The payload identified (`payload.parquet`), when asked for.
    pub payload: Option<Box<robotid_stages::estimation::payload::PayloadFit>>,
    /// The payload's model on its held-out records.
    pub payload_validation: Option<PayloadValidation>,
}

impl Identification {
    /// The files it wrote, under [`Identification::out`].
    pub fn path(&self, file: impl AsRef<Path>) -> PathBuf {
        self.out.join(file)
    }

    /// Refused and not written anyway: the command line's exit code 3.
    pub fn is_refused(&self) -> bool {
        self.refused.is_some() && matches!(self.physical, Physical::Refused)
    }
}

/// Drive gains (the torque over the effort as read, relative to the robot
/// file's constants) plausible for a robot whose file is right: outside
/// them the robot's identified masses would be as far off the file's.
pub const GAINS_PLAUSIBLE: (f64, f64) = (1.0 / 1.5, 1.5);

/// Why the payload `fit` (written to `table`) is not identified: drive
/// gains a known mass implies that contradict the robot file, or values
/// its records leave undetermined at its size, named (the command line
/// exits 3 with it unless told to accept it); None when it stands.
pub fn payload_refused(fit: &robotid_stages::estimation::payload::PayloadFit, table: &Path) -> Option<String> {
    let implausible: Vec<String> = fit
        .gains
        .iter()
        .filter(|g| !(GAINS_PLAUSIBLE.0..=GAINS_PLAUSIBLE.1).contains(&g.scale))
        .map(|g| format!("{} {:.3}×", g.joint, g.scale))
        .collect();
    if !implausible.is_empty() {
        return Some(format!(
            "the drives' gains the known payload mass implies contradict the robot file: {} (outside {:.2}–{:.2}×, which would make the robot's own masses as far from the robot file's); the known mass, the payload's link or the torque constants are wrong. {} holds every value all the same; to take it: accept inadequate (--accept-inadequate)",
            implausible.join(", "),
            GAINS_PLAUSIBLE.0,
            GAINS_PLAUSIBLE.1,
            table.display()
        ));
    }
    (!fit.undetermined.is_empty()).then(|| {
        format!(
            "the payload is not identified: the records do not determine {} at its size (move the wrist more, or longer). {} holds every value with its interval all the same; to take it: accept inadequate (--accept-inadequate)",
            robotid_stages::estimation::payload::said_undetermined(&fit.undetermined),
            table.display()
        )
    })
}

/// Why identify did not run to a verdict.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Robotid(Box<robotid::Error>),
    #[error(transparent)]
    Stage(#[from] robotid_stages::Error),
    #[error(transparent)]
    Export(#[from] robotid_report::export::ExportError),
    /// identify refused a recording, or found no pipeline for it: why,
    /// with the numbers.
    #[error("{}: {message}", log.display())]
    Design { log: PathBuf, message: String },
    /// A step of designing a recording's pipeline failed: which, and the
    /// cause.
    #[error("{}: {step}", log.display())]
    DesignStep {
        log: PathBuf,
        step: String,
        #[source]
        source: Box<Error>,
    },
    /// A designed plan could not be written as a pipeline file.
    #[error("writing a pipeline file: {0}")]
    Write(#[from] toml::ser::Error),
    /// A request identify cannot take: what, and why.
    #[error("{0}")]
    Request(String),
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Recordings whose pipeline failed: nothing was written.
    #[error("{} recording(s) failed; nothing was written:{}", failed.len(), failed.iter().map(|(n, e)| format!("\n  {n}: {e}")).collect::<String>())]
    Failed { failed: Vec<(String, String)> },
    /// The held-out recordings could not validate the estimate.
    #[error("validating on {files}")]
    Validation {
        files: String,
        #[source]
        source: Box<robotid::Error>,
    },
}

impl From<robotid::Error> for Error {
    fn from(e: robotid::Error) -> Self {
        Error::Robotid(Box::new(e))
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

/// `identify` with nothing shown: [`identify`] told to
/// [`robotid::Quiet`].
pub fn identify_quietly(request: &Request) -> Result<Identification> {
    identify(request, &robotid::Quiet)
}
