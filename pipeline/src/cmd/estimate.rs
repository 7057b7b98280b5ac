use std::path::PathBuf;

use anyhow::{bail, Context};
use robotid_stages::estimate::{estimate, parameters_table, Covariance, Estimate, EstimateConfig, Method, System};
use robotid_stages::formats::parquet::{read_parquet, write_parquet};

#[derive(clap::Args)]
pub struct Args {
    /// Regressor tables (`regressor.parquet` of one or more recordings,
    /// made with the same regressor configuration).
    #[arg(required = true)]
    pub regressors: Vec<PathBuf>,
    /// Estimator: ols or wls (ml needs the kinematics: use the pipeline's
    /// `estimate` stage).
    #[arg(long, default_value = "ols")]
    pub method: String,
    /// Confidence level of the intervals.
    #[arg(long, default_value_t = 0.95)]
    pub confidence: f64,
    /// Covariance: auto (periods when the tables carry them), periods or residual.
    #[arg(long, default_value = "auto")]
    pub covariance: String,
    /// A parameters table whose parameters are taken as known (friction
    /// from `robotid sweeps`): compensated before estimating the rest.
    #[arg(long)]
    pub known: Option<PathBuf>,
    /// Output parameters table.
    #[arg(long, short, default_value = "parameters.parquet")]
    pub out: PathBuf,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let method = match args.method.as_str() {
        "ols" => Method::Ols,
        "wls" => Method::Wls,
        "ml" => anyhow::bail!(
            "--method ml needs the positions' noise and the robot: run it as a pipeline's `estimate` stage"
        ),
        m => anyhow::bail!("--method: unknown estimator `{m}` (ols, wls)"),
    };
    let covariance = match args.covariance.as_str() {
        "auto" => Covariance::Auto,
        "periods" => Covariance::Periods,
        "residual" => Covariance::Residual,
        c => anyhow::bail!("--covariance: `{c}` is not auto, periods or residual"),
    };
    let cfg = EstimateConfig {
        method,
        confidence: args.confidence,
        covariance,
        ..Default::default()
    };
    cfg.check().map_err(anyhow::Error::msg).context("--confidence")?;
    let mut sys = load_system(&args.regressors)?;
    if let Some(k) = &args.known {
        let fixed = sys
            .fix(&robotid::run::load_known(k).map_err(anyhow::Error::msg)?)
            .map_err(anyhow::Error::msg)?;
        if fixed.is_empty() {
            bail!("--known {}: none of its parameters is in the model", k.display());
        }
        println!("known ({}): {}", k.display(), fixed.join(", "));
    }
    let est = estimate(&sys, &cfg, None).map_err(anyhow::Error::msg)?;
    let mut md = sys.metadata.clone();
    md.insert("robotid.recordings".into(), sys.recordings.join(","));
    let batch = parameters_table(&est, cfg.confidence, &sys.expressions, &md).map_err(anyhow::Error::msg)?;
    write_parquet(&args.out, &batch).map_err(anyhow::Error::msg)?;
    print!("{}", summary(&est, cfg.confidence));
    println!("parameters in {}", args.out.display());
    Ok(())
}

/// Stacks regressor tables named on the command line.
pub fn load_system(paths: &[PathBuf]) -> anyhow::Result<System> {
    let mut tables = Vec::new();
    for p in paths {
        let b = read_parquet(p).map_err(anyhow::Error::msg)?;
        tables.push((p.display().to_string(), b));
    }
    System::from_tables(&tables).map_err(anyhow::Error::msg)
}

/// The parameter table as text: value, std, relative std and interval.
pub fn summary(est: &Estimate, level: f64) -> String {
    let std = est.std();
    let half = est.half_width(level);
    let mut s = format!(
        "{} on {} rows, condition number {:.3}, covariance from {} ({} degrees of freedom), residual variance {:.4e}{}\n",
        est.method.name(),
        est.rows,
        est.condition,
        est.covariance_from.name(),
        est.dof,
        est.residual_variance,
        if est.iterations > 1 {
            format!(", {} iterations", est.iterations)
        } else {
            String::new()
        }
    );
    s.push_str(&format!(
        "{:<14} {:>14} {:>12} {:>8} {:>30}  unit\n",
        "parameter",
        "value",
        "std",
        "std %",
        format!("{:.1} % interval", 100.0 * level)
    ));
    for i in 0..est.values.len() {
        s.push_str(&format!(
            "{:<14} {:>14.6} {:>12.3e} {:>8.3} [{:>13.6}, {:>13.6}]  {}\n",
            est.names[i],
            est.values[i],
            std[i],
            100.0 * std[i] / est.values[i].abs(),
            est.values[i] - half[i],
            est.values[i] + half[i],
            est.units[i]
        ));
    }
    s
}
