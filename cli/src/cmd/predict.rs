use std::path::PathBuf;

use anyhow::bail;
use robotid_schemas::metadata;
use robotid_schemas::Kinematics;
use robotid_stages::formats::parquet::{read_parquet, write_parquet};

#[derive(clap::Args)]
pub struct Args {
    /// The robot file the parameters were identified for.
    #[arg(long)]
    pub robot: PathBuf,
    /// Identified parameters (`parameters.parquet`).
    #[arg(long, short)]
    pub parameters: PathBuf,
    /// A `kinematics` table: q, q̇, q̈ per joint and sample.
    pub kinematics: PathBuf,
    /// Output: the kinematics table with the predicted torques.
    #[arg(long, short, default_value = "predicted.parquet")]
    pub out: PathBuf,
}

/// τ = Φ_base(q, q̇, q̈)·θ̂, the base regressor rebuilt from the robot and
/// the regressor configuration the parameters carry.
pub fn run(args: Args) -> anyhow::Result<()> {
    robotid_stages::formats::refuse_inputs(
        [args.out.as_path()],
        [args.robot.as_path(), &args.parameters, &args.kinematics],
    )?;
    let (params, model, base) = robotid::tables::identified(&args.robot, &args.parameters)?;
    let batch = read_parquet(&args.kinematics)?;
    let mut kin =
        Kinematics::from_record_batch(&batch).map_err(|e| anyhow::anyhow!("{}: {e}", args.kinematics.display()))?;
    if kin.joints != model.joint_names() {
        bail!(
            "{}: joints {:?} are not the robot's {:?}",
            args.kinematics.display(),
            kin.joints,
            model.joint_names()
        );
    }
    // A NaN in the motion would come out as a NaN torque, written as if
    // predicted: refused where it is.
    for (channel, values) in [("q", &kin.q), ("qd", &kin.qd), ("qdd", &kin.qdd)] {
        for (j, series) in values.iter().enumerate() {
            if let Some(k) = series.iter().position(|x| !x.is_finite()) {
                bail!(
                    "{}: column `{channel}_{}`, sample {k}: {} is not a number; nothing predicted",
                    args.kinematics.display(),
                    kin.joints[j],
                    series[k]
                );
            }
        }
    }
    let n = model.dof();
    let tau = base.matrix(&kin) * &params.values;
    let samples = kin.time.len();
    kin.torque = Some((0..n).map(|j| (0..samples).map(|k| tau[k * n + j]).collect()).collect());
    kin.metadata.insert(metadata::TORQUE.into(), "predicted".into());
    kin.metadata
        .insert(metadata::PARAMETERS_FILE.into(), args.parameters.display().to_string());
    write_parquet(&args.out, &kin.to_record_batch()?)?;
    println!("{} samples × {n} joints predicted into {}", samples, args.out.display());
    Ok(())
}
