use std::path::PathBuf;

use anyhow::bail;
use robotid_stages::dynamics::{parameter_names, standard_parameters, to_urdf, with_standard_parameters};
use robotid_stages::estimation::physically_consistent;
use robotid_stages::formats::write_atomic;

#[derive(clap::Args)]
pub struct Args {
    /// The robot file the parameters were identified for: its inertials
    /// are the a-priori model the exported standard parameters stay close to.
    #[arg(long)]
    pub robot: PathBuf,
    /// Identified parameters (`parameters.parquet`, chain model).
    #[arg(long, short)]
    pub parameters: PathBuf,
    /// Output URDF.
    #[arg(long, short, default_value = "identified.urdf")]
    pub out: PathBuf,
    /// Weight of the pull of the inertial parameters towards the a-priori
    /// model, relative to the data (χ² units per squared deviation of one
    /// a-priori scale); chosen by Mallows' C_p when not given.
    #[arg(long)]
    pub prior_weight: Option<f64>,
}

/// Physically consistent standard parameters closest to the a-priori model
/// that reproduce the identified base parameters, written as a URDF.
pub fn run(args: Args) -> anyhow::Result<()> {
    let (params, _, base) = super::identified(&args.robot, &args.parameters)?;
    let Some(map) = base.map() else {
        bail!("export needs the chain model's base parameters (the decoupled model has no standard parameters)");
    };
    let names = parameter_names(&base.model, base.terms);
    let prior = standard_parameters(&base.model, base.terms);
    let fit = physically_consistent(
        &names,
        &prior,
        map,
        &params.values,
        &params.covariance,
        args.prior_weight,
    )
    .map_err(anyhow::Error::msg)?;
    println!(
        "physically consistent fit: χ² = {:.3} against the estimate's covariance ({} base parameters), prior weight {:e}{}, {} interior-point iterations",
        fit.chi2,
        params.names.len(),
        fit.prior_weight,
        if fit.chosen { " (chosen by C_p)" } else { "" },
        fit.iterations
    );
    for (l, j) in base.model.joints.iter().enumerate() {
        println!(
            "  link of `{}`: smallest pseudo-inertia eigenvalue {:.3e} (a-priori {:.3e})",
            j.name, fit.min_eigen[l], fit.min_eigen_prior[l]
        );
    }
    let mut moved: Vec<(f64, usize)> = (0..names.len())
        .map(|i| ((fit.standard[i] - prior[i]).abs(), i))
        .collect();
    moved.sort_by(|a, b| b.0.total_cmp(&a.0));
    println!("largest changes from the a-priori model:");
    for (_, i) in moved.iter().take(6) {
        println!("  {:<10} {:>14.6} → {:>14.6}", names[*i], prior[*i], fit.standard[*i]);
    }
    let identified = with_standard_parameters(&base.model, base.terms, &fit.standard);
    let note = format!(
        "identified by robotid from {} (a-priori model {}); physically consistent, χ² = {:.3}",
        args.parameters.display(),
        args.robot.display(),
        fit.chi2
    );
    let text = to_urdf(&identified, &note);
    write_atomic(&args.out, |w| {
        use std::io::Write;
        w.write_all(text.as_bytes())
            .map_err(|e| robotid_stages::Error::io(&args.out, e))
    })
    .map_err(anyhow::Error::msg)?;
    println!("URDF in {}", args.out.display());
    Ok(())
}
