use std::path::PathBuf;

use robotid_report::sample::{sample, Sample};

use super::export::Format;

#[derive(clap::Args)]
pub struct Args {
    /// How many parameter sets to draw.
    pub draws: usize,
    /// The robot file the parameters were identified for.
    #[arg(long)]
    pub robot: PathBuf,
    /// A physically consistent parameters table (`parameters_physical.parquet`
    /// of identify, or an estimate with `--physical`): its covariance is
    /// drawn from.
    #[arg(long, short)]
    pub parameters: PathBuf,
    /// Besides `samples.parquet` and `randomization.json`/`.yaml`: one
    /// model per draw (`draw_00000.urdf`, the robot file's own patched
    /// where it is a URDF; `.xml`, MJCF).
    #[arg(long, value_enum, value_delimiter = ',')]
    pub format: Vec<Format>,
    /// The draws' seed: the same seed, the same draws (at any thread count).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Output folder (made; an existing one must be empty of robotid's
    /// outputs).
    #[arg(long, short, default_value = "samples")]
    pub out: PathBuf,
    /// The user's own MJCF of the robot: each draw's `.xml` is it with the
    /// draw's dynamics written in (as `robotid export --mjcf`).
    #[arg(long)]
    pub mjcf: Option<PathBuf>,
}

/// Parameter sets drawn from the identification's distribution for domain
/// randomization, each mapped to physically consistent bodies.
pub fn run(args: Args) -> anyhow::Result<()> {
    let done = sample(&Sample {
        robot: args.robot,
        parameters: args.parameters,
        draws: args.draws,
        seed: args.seed,
        formats: args.format.into_iter().map(Into::into).collect(),
        out: args.out.clone(),
        mjcf: args.mjcf,
    })?;
    println!(
        "{:<34} {:>10} {:>12} {:>12} {:>12}  unit",
        "quantity", "value", "mean", "std", "std %"
    );
    for p in &done.parameters {
        let share = match p.value.abs() > 1e-9 {
            true => format!("{:.2}", 100.0 * p.std / p.value.abs()),
            false => "-".into(),
        };
        println!(
            "{:<34} {:>10.5} {:>12.5} {:>12.3e} {share:>12}  {}",
            p.name, p.value, p.mean, p.std, p.unit
        );
    }
    let p = done.base.first().map_or(0, |b| b.len());
    println!(
        "drawn: {} base parameters, their standard deviations {:.3}–{:.3}× the covariance's",
        p, done.drawn_std_ratio.0, done.drawn_std_ratio.1
    );
    let by: Vec<String> = done
        .projected_by_joint
        .iter()
        .filter(|(_, n)| *n > 0)
        .map(|(j, n)| format!("{j} {n}"))
        .collect();
    println!(
        "projected by the bounded fit: {} of {} draws (outside their bounds, per joint's body or friction: {})",
        done.projected,
        done.base.len(),
        if by.is_empty() {
            "none".to_string()
        } else {
            by.join(", ")
        }
    );
    println!("{}", robotid_report::sample::moved_said(done.moved, p));
    if done.failed > 0 {
        eprintln!(
            "warning: {} draw(s) the bounded fit could not map were left out ({})",
            done.failed,
            done.failed_why.as_deref().unwrap_or_default()
        );
    }
    println!("{} file(s) in {}", done.files.len(), args.out.display());
    Ok(())
}
