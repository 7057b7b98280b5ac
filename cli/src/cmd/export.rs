use std::path::PathBuf;

use robotid_report::export::{export, Export};

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// `<stem>.urdf`: the robot file's own URDF with each moving link's
    /// `<inertial>` and each joint's `<dynamics damping friction>` replaced
    /// (a robot file in robotid's TOML: a URDF made from the model).
    Urdf,
    /// `<stem>.xml`: the MJCF given with --mjcf, its bodies' inertials and
    /// its joints' armature, damping and frictionloss written, every other
    /// byte kept; without one, MJCF made from the robot file (bodies,
    /// inertials, its shapes as geoms).
    Mjcf,
    /// `<stem>.sidecar.json` and `<stem>.sidecar.parquet`: every value with
    /// unit, standard deviation and interval, the covariance, what the
    /// formats cannot hold, the provenance.
    Sidecar,
}

#[derive(clap::Args)]
pub struct Args {
    /// The robot file the parameters were identified for: its inertials
    /// are the a-priori model the exported standard parameters stay close to.
    #[arg(long)]
    pub robot: PathBuf,
    /// Identified parameters (`parameters.parquet`, chain model, from an
    /// estimate with `physical = true`).
    #[arg(long, short)]
    pub parameters: PathBuf,
    /// What to write (comma-separated or repeated).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "urdf")]
    pub format: Vec<Format>,
    /// Output path without extension: `identified` gives identified.urdf,
    /// identified.xml, identified.sidecar.json and identified.sidecar.parquet.
    /// The extension of the one format written is accepted (`-o model.urdf`).
    #[arg(long, short, default_value = "identified")]
    pub out: PathBuf,
    /// Weight of the pull of the inertial parameters towards the a-priori
    /// model, relative to the data (χ² units per squared deviation of one
    /// a-priori scale); by default the estimate's own.
    #[arg(long)]
    pub prior_weight: Option<f64>,
    /// Write bodies outside their bounds (a mass over 5× from the robot
    /// file's either way, a centre of mass outside its link's shapes) all
    /// the same; the sidecar says which.
    #[arg(long)]
    pub force: bool,
    /// The user's own MJCF of the robot (e.g. MuJoCo Menagerie's, or
    /// MuJoCo's import of the URDF saved as MJCF): the MJCF export is it
    /// with the identified dynamics written in. Its joints are found by the
    /// robot file's names, and its kinematics must be the robot file's.
    #[arg(long)]
    pub mjcf: Option<PathBuf>,
}

impl From<Format> for robotid_report::export::Format {
    fn from(f: Format) -> Self {
        match f {
            Format::Urdf => Self::Urdf,
            Format::Mjcf => Self::Mjcf,
            Format::Sidecar => Self::Sidecar,
        }
    }
}

/// Physically consistent standard parameters closest to the a-priori model
/// that reproduce the identified base parameters, written as URDF, MJCF
/// and a sidecar with everything neither can hold.
pub fn run(args: Args) -> anyhow::Result<()> {
    let done = export(&Export {
        robot: std::sync::Arc::new(robotid_stages::dynamics::Robot::read(&args.robot)?),
        parameters: args.parameters,
        formats: args.format.into_iter().map(Into::into).collect(),
        out: args.out,
        prior_weight: args.prior_weight,
        force: args.force,
        within: PathBuf::new(),
        mjcf: args.mjcf,
    })?;
    println!("{}", done.how);
    for w in &done.warnings {
        eprintln!("warning: {w}");
    }
    for f in &done.files {
        println!("{}", f.display());
    }
    Ok(())
}
