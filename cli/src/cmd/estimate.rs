use std::path::PathBuf;

use anyhow::bail;
use robotid::tables::{parts, reduce, Marks};
use robotid_stages::dynamics::Robot;
use robotid_stages::estimation::{expressions_of, Covariance, Estimate, Estimator};
use robotid_stages::stage::estimate::{EstimateConfig, Outcome, Reducer};

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
    /// Covariance: auto (spectrum for tables of one averaged period, periods
    /// when the tables carry them), spectrum, periods, residual, or robust
    /// (auto's, or where model error dominates a joint the sandwich robust
    /// to a residue correlated in time: what identify uses).
    #[arg(long, default_value = "auto")]
    pub covariance: String,
    /// A parameters table whose parameters are taken as known (friction
    /// from `robotid sweeps`): compensated before estimating the rest.
    #[arg(long)]
    pub known: Option<PathBuf>,
    /// The nearest physically consistent estimate (every link a real body,
    /// friction ≥ 0), as the `estimate` stage's `physical = true`: what
    /// `robotid export` needs. Needs `--robot`.
    #[arg(long, requires = "robot")]
    pub physical: bool,
    /// The robot file the tables were made for (the physical fit's
    /// a-priori model).
    #[arg(long)]
    pub robot: Option<PathBuf>,
    /// With `--physical`: the weight of the pull towards the robot file's
    /// inertials (chosen by held-out periods when not given; with fewer than two, by held-out blocks in time where `--covariance robust` keeps the rows; else Mallows' C_p).
    #[arg(long, requires = "physical")]
    pub prior_weight: Option<f64>,
    /// Output parameters table.
    #[arg(long, short, default_value = "parameters.parquet")]
    pub out: PathBuf,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let inputs: Vec<&std::path::Path> = args
        .regressors
        .iter()
        .chain(&args.known)
        .chain(&args.robot)
        .map(PathBuf::as_path)
        .collect();
    robotid_stages::formats::refuse_inputs([args.out.as_path()], inputs)?;
    let out = if args.physical {
        crate::progress::spinning("physical fit: semidefinite programs", || estimate(&args, None))?
    } else {
        estimate(&args, None)?
    };
    print_outcome(&args, &out);
    Ok(())
}

/// What `run` prints of an estimate: the known, the table, the findings,
/// and of a physical fit its prior weight (how it was chosen) and the
/// links it held at a bound.
pub fn print_outcome(args: &Args, out: &Outcome) {
    if let Some(k) = &args.known {
        println!("known ({}): {}", k.display(), out.known.join(", "));
    }
    print!("{}", outcome_text(out, args.confidence, &args.out));
}

/// An estimate's outcome as text, its table at `table`.
pub fn outcome_text(out: &Outcome, confidence: f64, table: &std::path::Path) -> String {
    let mut s = summary(&out.estimate, confidence, &expressions_of(&out.table)) + &findings(out);
    if let Some(fit) = &out.physical {
        s.push_str(&format!(
            "physically consistent: prior weight {:e}{}\n",
            fit.prior_weight,
            fit.chosen.as_ref().map(|c| format!(" {c}")).unwrap_or_default()
        ));
        for (l, b) in fit.bounds.iter().enumerate() {
            let m = fit.standard[10 * l + 9];
            if (m - b.mass.0).abs() <= 1e-6 * b.mass.0 || (m - b.mass.1).abs() <= 1e-6 * b.mass.1 {
                s.push_str(&format!(
                    "  link {} (from the base): {m:.4} kg, held at its mass bound {:.4}–{:.4} kg (5× either way of the robot file's); the data would move it further\n",
                    l + 1,
                    b.mass.0,
                    b.mass.1
                ));
            }
        }
    }
    s + &format!("parameters in {}\n", table.display())
}

/// The estimate of `args`, its table written to `args.out` with
/// `marks` added to the table's metadata.
pub fn estimate(args: &Args, marks: Option<Marks>) -> anyhow::Result<Outcome> {
    let reducer = reducer(args)?;
    let parts = parts(&reducer, std::path::Path::new(""), &args.regressors)?;
    Ok(reduce(&reducer, &parts, &args.out, marks)?)
}

/// The reduce step that `args` ask for.
pub fn reducer(args: &Args) -> anyhow::Result<Reducer> {
    let method = match args.method.as_str() {
        "ols" => Estimator::Ols,
        "wls" => Estimator::Wls,
        "ml" => anyhow::bail!(
            "--method ml needs the positions' noise and the robot: run it as a pipeline's `estimate` stage"
        ),
        m => anyhow::bail!("--method: unknown estimator `{m}` (ols, wls)"),
    };
    let covariance = match args.covariance.as_str() {
        "auto" => Covariance::Auto,
        "periods" => Covariance::Periods,
        "spectrum" => Covariance::Spectrum,
        "residual" => Covariance::Residual,
        "robust" => Covariance::Robust,
        c => anyhow::bail!("--covariance: `{c}` is not auto, spectrum, periods, residual or robust"),
    };
    let cfg = EstimateConfig {
        method,
        confidence: args.confidence,
        covariance,
        known: args.known.clone(),
        physical: args.physical,
        prior_weight: args.prior_weight,
        ..Default::default()
    };
    if let Some(p) = cfg.settings_problems().first() {
        bail!("--{}: {}", p.key, p.message);
    }
    // The robot as the tables were made with it (a gripper the log did not hold, locked).
    let robot = match (&args.robot, args.regressors.first()) {
        (Some(r), Some(t)) => Some((Robot::read(r)?, robotid::tables::table_locks(t)?)),
        (Some(r), None) => Some((Robot::read(r)?, Default::default())),
        (None, _) => None,
    };
    Ok(robotid::tables::reducer(&cfg, robot.as_ref().map(|(r, l)| (r, l)))?)
}

/// What the reduce found beside the estimate: parameters not identified
/// at their physical size, and the essential set.
pub fn findings(out: &Outcome) -> String {
    let mut s = String::new();
    for u in &out.unidentified {
        s.push_str(&format!(
            "warning: {} = {:.4e} ± {:.2e} is not identified: its standard deviation exceeds its a-priori size {:.2e} (robot file); the data carry too little of it to tell it from zero at its physical size\n",
            u.name, u.value, u.std, u.scale
        ));
    }
    if let Some(e) = out.essential.as_ref().filter(|e| !e.dropped.is_empty()) {
        s.push_str(&format!(
            "essential parameters (Pham & Gautier): {} of {}; dropped, least informative first: {} (residual sum of squares ×{:.4} without them)\n",
            e.kept.len(),
            e.kept.len() + e.dropped.len(),
            e.dropped
                .iter()
                .map(|(n, r)| format!("{n} ({:.0} %)", 100.0 * r))
                .collect::<Vec<_>>()
                .join(", "),
            e.rss_ratio
        ));
    }
    s
}

/// The adequacy verdicts as text: per joint, the residue against the noise
/// floor of the torque fitted, and what the intervals did about it.
pub fn adequacy(est: &Estimate) -> String {
    if est.adequacy.is_empty() {
        return String::new();
    }
    let mut s = format!(
        "model adequacy (mean squared residue of the fit against the noise floor of the fitted torque):\n{:<12} {:>8} {:>12} {:>12} {:>8}  verdict\n",
        "joint", "rows", "residue", "noise floor", "ratio"
    );
    for a in &est.adequacy {
        s.push_str(&format!(
            "{:<12} {:>8} {:>12.4e} {:>12} {:>8}  {}\n",
            a.joint,
            a.rows,
            a.msr,
            a.noise_floor.map_or("-".into(), |f| format!("{f:.4e}")),
            a.ratio().map_or("-".into(), |r| format!("{r:.2}")),
            a.verdict().name()
        ));
    }
    let bad: Vec<&str> = est.inadequate().iter().map(|a| a.joint.as_str()).collect();
    if est.widened {
        s.push_str(&format!(
            "intervals widened: model error dominates on {} (over {}× the floor); the periods' spread sees only the noise, so the excess residual variance is added to it\n",
            bad.join(", "),
            robotid_stages::estimation::ADEQUATE_RATIO
        ));
    } else if !bad.is_empty() && est.covariance_from == robotid_stages::estimation::Covariance::Robust {
        s.push_str(&format!(
            "model error dominates on {}: the intervals are robust to it (a sandwich over the residue's correlation in time, {} degrees of freedom), not the noise's\n",
            bad.join(", "),
            est.dof
        ));
    } else if !bad.is_empty() && est.covariance_from == robotid_stages::estimation::Covariance::Bootstrap {
        s.push_str(&format!(
            "model error dominates on {}: the physical fit's intervals come from a parametric bootstrap of the base estimate's covariance\n",
            bad.join(", ")
        ));
    } else if !bad.is_empty() {
        s.push_str(&format!(
            "model error dominates on {}: the intervals come from the residual, which holds it as if it were white noise\n",
            bad.join(", ")
        ));
    }
    s
}

/// The parameter table as text: value, std, relative std and interval
/// (the table's: `expressions` are its column, empty where each parameter
/// is its own).
pub fn summary(est: &Estimate, level: f64, expressions: &[String]) -> String {
    summary_at(est, level, Some(level), expressions)
}

/// The same, with the intervals' label: `None` where the fit is
/// inadequate and the intervals are at no known level.
pub fn summary_at(est: &Estimate, level: f64, label: Option<f64>, expressions: &[String]) -> String {
    let std = est.std();
    let (low, high) = robotid_stages::estimation::intervals(est, level, expressions);
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
    s.push_str(&adequacy(est));
    s.push_str(&format!(
        "{:<14} {:>14} {:>12} {:>8} {:>30}  unit\n",
        "parameter",
        "value",
        "std",
        "std %",
        label.map_or("interval (level unknown)".to_string(), |l| format!(
            "{:.1} % interval",
            100.0 * l
        ))
    ));
    for i in 0..est.values.len() {
        s.push_str(&format!(
            "{:<14} {:>14.6} {:>12.3e} {:>8} [{:>13.6}, {:>13.6}]  {}\n",
            est.names[i],
            est.values[i],
            std[i],
            relative(100.0 * std[i] / est.values[i].abs()),
            low[i],
            high[i],
            est.units[i]
        ));
    }
    s
}

/// A relative std in the table's column: to 3 decimals, or in powers of
/// ten where the value is near 0 (a friction at its bound, 3.5e7 % rather
/// than 35417295.459).
fn relative(percent: f64) -> String {
    match percent < 1e4 {
        true => format!("{percent:.3}"),
        false => format!("{percent:.1e}"),
    }
}
