use robotid_schemas::TableKind;

#[derive(clap::Args)]
pub struct Args {
    /// Table kind: raw_samples, kinematics, period_mean, noise, regressor, parameters.
    pub kind: String,
    /// Joint names to lay out per-joint columns for.
    #[arg(long, value_delimiter = ',', default_value = "j1,j2")]
    pub joints: Vec<String>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let kind: TableKind = args.kind.parse()?;
    println!("table `{}`, version {}", kind.name(), kind.version());
    for spec in kind.columns() {
        let name = if spec.per_joint {
            format!("{}_<joint>", spec.prefix)
        } else {
            spec.prefix.to_string()
        };
        println!(
            "  {name:<22} {:<8} {:<9} {:<10} {}",
            format!("{:?}", spec.dtype),
            spec.unit.symbol(),
            format!("{:?}", spec.presence).to_lowercase(),
            spec.doc
        );
    }
    let all: Vec<&str> = kind.columns().iter().map(|c| c.prefix).collect();
    let schema = kind.schema(&args.joints, &all, &Default::default());
    println!("\nArrow schema for joints {:?}:\n{schema:#?}", args.joints);
    Ok(())
}
