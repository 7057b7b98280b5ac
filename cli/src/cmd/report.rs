use std::path::PathBuf;

use robotid_report::report::{render, Page};
#[derive(clap::Args)]
pub struct Args {
    /// Identified parameters (`parameters.parquet`).
    #[arg(long, short)]
    pub parameters: PathBuf,
    /// Regressor tables of the excitation data (the estimate's own).
    #[arg(long, num_args = 1..)]
    pub excitation: Vec<PathBuf>,
    /// Regressor tables of validation recordings.
    #[arg(long, num_args = 1..)]
    pub validation: Vec<PathBuf>,
    /// A physically consistent estimate of the same parameters
    /// (`estimate --physical`): its relative errors beside the reported
    /// one's, and, with `--robot`, its bodies against the robot file's.
    #[arg(long)]
    pub physical: Option<PathBuf>,
    /// The robot file the parameters were identified for (for
    /// `--physical`'s bodies and for `--rollout`).
    #[arg(long)]
    pub robot: Option<PathBuf>,
    /// Add rollouts: the estimate's forward dynamics driven by the measured
    /// torque, restarted from the measured state every window (chosen from
    /// each record's noise, said), on the validation records (else the
    /// excitation's), beside the robot file's.
    #[arg(long, requires = "robot")]
    pub rollout: bool,
    /// Raw tables with the recorded references (`q_<joint>` and
    /// `ref_<joint>`, as `robotid simulate` writes) to simulate in closed
    /// loop under `--controller`, the estimate beside the robot file.
    #[arg(long, num_args = 1.., requires_all = ["robot", "controller"])]
    pub closed_loop: Vec<PathBuf>,
    /// The recordings' controller: a TOML file with a `[controller]` table
    /// (kp, kd, ki per joint), as `robotid simulate`'s truth file declares.
    #[arg(long)]
    pub controller: Option<PathBuf>,
    /// An identified payload (`payload.parquet`, from `identify
    /// --payload-on`): its body, intervals and drive gains shown.
    #[arg(long)]
    pub payload: Option<PathBuf>,
    /// With --rollout: this MJCF (the physical estimate's export,
    /// `identified.xml`) rolled out by MuJoCo itself in the same windows,
    /// by a Python with the `mujoco` package ($ROBOTID_PYTHON, else
    /// python3).
    #[arg(long, requires = "rollout")]
    pub mujoco: Option<PathBuf>,
    /// Output HTML page (self-contained: pictures inline).
    #[arg(long, short, default_value = "report.html")]
    pub out: PathBuf,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let inputs: Vec<&std::path::Path> = [&args.parameters]
        .into_iter()
        .chain(&args.excitation)
        .chain(&args.validation)
        .chain(&args.physical)
        .chain(&args.robot)
        .chain(&args.closed_loop)
        .chain(&args.controller)
        .chain(&args.payload)
        .chain(&args.mujoco)
        .map(PathBuf::as_path)
        .collect();
    robotid_stages::formats::refuse_inputs([args.out.as_path()], inputs)?;
    let page = Page {
        parameters: args.parameters,
        excitation: args.excitation,
        validation: args.validation,
        physical: args.physical,
        robot: match &args.robot {
            Some(r) => Some(std::sync::Arc::new(robotid_stages::dynamics::Robot::read(r)?)),
            None => None,
        },
        rollout: args.rollout,
        payload: args.payload,
        closed_loop: args.controller.map(|c| (c, args.closed_loop)),
        mujoco: args.mujoco.map(|m| (m, robotid::mujoco::default_python())),
        out: args.out.clone(),
        within: PathBuf::new(),
    };
    // Read and checked before anything is simulated for it.
    let read = page.read()?;
    render(&page, &read, &robotid::simulation::simulate(&page.asked()))?;
    println!("report in {}", args.out.display());
    Ok(())
}
