use robotid_schemas::TableKind;

#[derive(clap::Args)]
pub struct Args {
    /// Table kind: raw_samples, kinematics, period_mean, noise, regressor, r_factor, parameters, payload.
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
    println!("\nArrow schema for joints {}:", args.joints.join(", "));
    for f in schema.fields() {
        // Sorted: a field's metadata is a hash map.
        let md: std::collections::BTreeMap<_, _> = f.metadata().iter().collect();
        let md: Vec<String> = md.iter().map(|(k, v)| format!("{k}={v}")).collect();
        let null = if f.is_nullable() { "nullable" } else { "not null" };
        println!("  {:<22} {:<8} {null:<9} {}", f.name(), f.data_type(), md.join(" "));
    }
    println!("schema metadata:");
    let md: std::collections::BTreeMap<_, _> = schema.metadata().iter().collect();
    for (k, v) in md {
        println!("  {k} = {v}");
    }
    Ok(())
}
