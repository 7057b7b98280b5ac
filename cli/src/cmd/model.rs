use std::path::{Path, PathBuf};

use anyhow::bail;
use nalgebra::DMatrix;
use robotid_stages::dynamics::{
    base_parameters, load_robot, parameter_names, parameter_unit, regressor, standard_parameters, BaseParameters, Data,
    FrictionTerms, Model, RegressorTerms,
};
use robotid_stages::trajectory::{load_trajectory, Trajectory};

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    pub command: ModelCommand,
}

#[derive(clap::Subcommand)]
pub enum ModelCommand {
    /// Print the parameters, the base parameter set with its expressions, and
    /// the condition number of the regressor along a trajectory.
    Inspect(InspectArgs),
}

#[derive(clap::Args)]
pub struct InspectArgs {
    /// Robot file (TOML) or URDF.
    pub robot: PathBuf,
    /// Friction terms: none, symmetric, asymmetric.
    #[arg(long, default_value = "symmetric")]
    pub friction: String,
    /// Include a rotor-inertia parameter per joint.
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub rotor: bool,
    /// A file with a [trajectory] table: report the condition number of the
    /// column-normalised base regressor along one period (or its duration).
    #[arg(long)]
    pub trajectory: Option<PathBuf>,
    /// Sample rate for the condition number, Hz.
    #[arg(long, default_value_t = 100.0)]
    pub rate: f64,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        ModelCommand::Inspect(a) => inspect(a),
    }
}

fn inspect(a: InspectArgs) -> anyhow::Result<()> {
    let model = load_robot(&a.robot)?;
    let friction = match a.friction.as_str() {
        "none" => FrictionTerms::None,
        "symmetric" => FrictionTerms::Symmetric,
        "asymmetric" => FrictionTerms::Asymmetric,
        other => bail!("--friction: unknown `{other}` (none, symmetric, asymmetric)"),
    };
    let terms = RegressorTerms {
        rotor: a.rotor,
        friction,
        offset: false,
        spring: None,
    };
    let n = model.dof();
    let names = parameter_names(&model, terms);
    let theta = standard_parameters(&model, terms);
    println!(
        "robot `{}`: {n} joints ({})",
        model.name,
        model.joint_names().join(", ")
    );
    println!("\n{} standard parameters:", names.len());
    for (name, v) in names.iter().zip(&theta) {
        println!("  {name:<28} {v:>14.6e} {}", parameter_unit(name));
    }
    let bp = base_parameters(&model, terms, 40 + 6 * terms.count(&model) / n, 7);
    let values = bp.base_values(&theta);
    println!(
        "\n{} base parameters ({} unidentifiable; singular values at the rank {:.2e} | {:.2e}):",
        bp.base.len(),
        bp.unidentifiable.len(),
        bp.gap.0,
        bp.gap.1
    );
    for b in 0..bp.base.len() {
        println!("  {:>3}. {:>14.6e}  = {}", b + 1, values[b], bp.expression(b));
    }
    if !bp.unidentifiable.is_empty() {
        let u: Vec<&str> = bp.unidentifiable.iter().map(|&c| names[c].as_str()).collect();
        println!("\nunidentifiable: {}", u.join(", "));
    }
    if let Some(path) = &a.trajectory {
        trajectory_condition(&model, terms, &bp, path, a.rate)?;
    }
    Ok(())
}

/// The condition number of the column-normalised base regressor along the
/// trajectory file `path`, sampled at `rate` Hz, printed.
fn trajectory_condition(
    model: &Model,
    terms: RegressorTerms,
    bp: &BaseParameters,
    path: &Path,
    rate: f64,
) -> anyhow::Result<()> {
    let n = model.dof();
    let traj = load_trajectory(path)?;
    if traj.dof() != n {
        bail!(
            "{}: the trajectory drives {} joints, the robot has {n}",
            path.display(),
            traj.dof()
        );
    }
    let duration = match &traj {
        Trajectory::Fourier(f) => f.period(),
        Trajectory::Waypoints(w) => w.duration(),
        Trajectory::Sweeps(s) => s.duration(),
    };
    let samples = (duration * rate).round().max(1.0) as usize;
    let mut data = Data::new(model);
    let mut phi = DMatrix::zeros(n, terms.count(model));
    let mut w = DMatrix::zeros(samples * n, bp.base.len());
    let (mut q, mut qd, mut qdd) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    for s in 0..samples {
        traj.eval(s as f64 / rate, &mut q, &mut qd, &mut qdd);
        regressor(model, &mut data, &q, &qd, &qdd, terms, &mut phi);
        let base = bp.base_regressor(&phi);
        w.rows_mut(s * n, n).copy_from(&base);
    }
    for mut c in w.column_iter_mut() {
        let norm = c.norm();
        if norm > 0.0 {
            c /= norm;
        }
    }
    let sv = w.singular_values();
    let (max, min) = (sv.max(), sv.min());
    println!(
        "\ncondition number of the column-normalised base regressor along {} ({samples} samples at {} Hz): {}",
        path.display(),
        rate,
        if min > 0.0 {
            format!("{:.4e}", max / min)
        } else {
            "infinite (a base parameter is not excited)".into()
        }
    );
    Ok(())
}
