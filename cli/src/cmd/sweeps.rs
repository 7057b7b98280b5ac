use std::path::PathBuf;

use robotid_schemas::metadata;
use robotid_schemas::Kinematics;
use robotid_stages::dynamics::FrictionTerms;
use robotid_stages::estimation::dedicated::{gravity_friction, SweepConfig};
use robotid_stages::estimation::parameters_table;
use robotid_stages::formats::parquet::{read_parquet, write_parquet};

#[derive(clap::Args)]
pub struct Args {
    /// The `kinematics` table of a sweeps recording (one joint moving at
    /// constant velocities, e.g. a `filtered` differentiation).
    pub kinematics: PathBuf,
    /// The moving joint.
    #[arg(long)]
    pub joint: String,
    /// Friction parameter names to produce: symmetric or asymmetric.
    #[arg(long, default_value = "asymmetric")]
    pub friction: String,
    /// Samples with |q̈| above this are left out (rad/s²).
    #[arg(long, default_value_t = 0.5)]
    pub max_acceleration: f64,
    /// Samples slower than this are left out (rad/s).
    #[arg(long, default_value_t = 0.02)]
    pub min_speed: f64,
    /// Confidence level of the intervals.
    #[arg(long, default_value_t = 0.95)]
    pub confidence: f64,
    #[arg(long, short, default_value = "gravity_friction.parquet")]
    pub out: PathBuf,
}

/// Gravity (k, q_off) and friction (β_v±, β_c±) of one joint from
/// constant-velocity sweeps (Bona §3.2), as a parameters table that
/// `robotid estimate --known` (or the `estimate` stage's `known`) can
/// compensate.
pub fn run(args: Args) -> anyhow::Result<()> {
    let friction = match args.friction.as_str() {
        "symmetric" => FrictionTerms::Symmetric,
        "asymmetric" => FrictionTerms::Asymmetric,
        f => anyhow::bail!("--friction: `{f}` is not symmetric or asymmetric"),
    };
    let batch = read_parquet(&args.kinematics)?;
    let kin =
        Kinematics::from_record_batch(&batch).map_err(|e| anyhow::anyhow!("{}: {e}", args.kinematics.display()))?;
    let cfg = SweepConfig {
        joint: args.joint.clone(),
        max_acceleration_rad_s2: args.max_acceleration,
        min_speed_rad_s: args.min_speed,
        friction,
    };
    let gf = gravity_friction(&kin, &cfg).map_err(|e| anyhow::anyhow!("{}: {e}", args.kinematics.display()))?;
    println!("speed levels (rad/s → friction torque N·m ± std):");
    for (v, f, s) in &gf.levels {
        println!("  {v:+8.4} → {f:+10.4} ± {s:.4}");
    }
    println!(
        "gravity: k = {:.4} N·m, q_off = {:.5} rad (Bona eq. 23)",
        gf.k, gf.q_off
    );
    print!("{}", super::estimate::summary(&gf.estimate, args.confidence, &[]));
    let mut md = kin.metadata.clone();
    md.insert(metadata::DEDICATED.into(), "sweeps".into());
    let table = parameters_table(&gf.estimate, args.confidence, &gf.estimate.names, &md)?;
    write_parquet(&args.out, &table)?;
    println!("parameters in {}", args.out.display());
    Ok(())
}
