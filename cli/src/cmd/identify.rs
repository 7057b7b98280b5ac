use std::path::PathBuf;

use robotid_identify::design::Found;
use robotid_identify::{Identification, PayloadRequest, Physical, Request};

#[derive(clap::Args)]
pub struct Args {
    /// Recordings of the excitation (text, Parquet or MCAP logs), periodic
    /// or not; the parameters are estimated from all of them.
    #[arg(required = true)]
    pub recordings: Vec<PathBuf>,
    /// The robot file (TOML or URDF).
    #[arg(long)]
    pub robot: PathBuf,
    /// Held-out recordings to validate the identified model on.
    #[arg(long, num_args = 1..)]
    pub validate: Vec<PathBuf>,
    /// Output folder (default: out/identify/<first recording's name>); must
    /// not exist or be empty.
    #[arg(long, short)]
    pub out: Option<PathBuf>,
    /// Print the pipeline file of the first recording (also written into
    /// the output folder, with every other one).
    #[arg(long)]
    pub print_pipeline: bool,
    /// Write the estimate, its physical fit and the exports even when the
    /// fit is refused (the tables are marked `robotid.identify.inadequate`);
    /// without it a refused fit gives the estimate and the report marked
    /// so, no export, and exit code 3.
    #[arg(long)]
    pub accept_inadequate: bool,
    /// The held-out relative error refused above, % of the measured torque
    /// (measured on the --validate recordings, else on held-out periods,
    /// else in sample). Under it a fit whose residue is above the noise
    /// floor is identified with its model error said per joint; a friction
    /// the model lacks, measured, is refused whatever the tolerance.
    #[arg(long, default_value_t = 100.0 * robotid::verdict::DEFAULT_TOLERANCE, value_name = "PERCENT")]
    pub tolerance: f64,
    /// Refuse any fit whose residue is over 3× the noise floor on a joint,
    /// or whose floors are over twice its residue on every joint (floors
    /// holding more than noise judge nothing): for simulated and regression
    /// data, whose model is exact.
    #[arg(long)]
    pub strict: bool,
    /// Where the channels are, for every recording: a TOML file with a
    /// `[read]` table as in a pipeline file (columns by name or number,
    /// units, `header`, `separator`, `torque_per_amp`; docs/pipeline-file.md).
    #[arg(long)]
    pub read: Option<PathBuf>,
    /// The drives' joint torque per ampere, N·m/A (one per joint, or one
    /// for all), for logs whose effort channels are motor currents and a
    /// robot file that declares no drives.
    #[arg(long, value_delimiter = ',', num_args = 1.., allow_negative_numbers = true)]
    pub torque_per_amp: Vec<f64>,
    /// The user's own MJCF of the robot: `identified.xml` is it with the
    /// identified dynamics written in (as `robotid export --mjcf`), else
    /// MJCF made from the robot file.
    #[arg(long)]
    pub mjcf: Option<PathBuf>,
    /// The controller the `--validate` recordings ran under: a TOML file
    /// with a `[controller]` table (kp, kd, ki per joint; `robotid
    /// simulate`'s truth file declares its own). The estimate and the
    /// robot file's parameters are simulated under it in closed loop,
    /// tracking each record's reference (`ref_<joint>`), and compared
    /// with the measured angles (printed, and in the report).
    #[arg(long, requires = "validate")]
    pub controller: Option<PathBuf>,
    /// Roll the exported MJCF (`identified.xml`, the physical estimate)
    /// out in MuJoCo itself too, in the windows of robotid's rollouts, and
    /// report both (printed, and in the report): a Python with the
    /// `mujoco` package runs it ($ROBOTID_PYTHON, else python3).
    #[arg(long)]
    pub mujoco: bool,
    /// The recordings carry a payload held by this link (the last moving
    /// link, or one welded to it: a flange, `tool0`): its mass, centre of
    /// mass and inertia are identified against the robot identified from
    /// the `--unloaded` recordings, given in that link's frame, and written
    /// to `payload.parquet`.
    #[arg(long, value_name = "LINK")]
    pub payload_on: Option<String>,
    /// With `--payload-on`: recordings of the robot without the payload.
    #[arg(long, num_args = 1.., requires = "payload_on", conflicts_with = "parameters")]
    pub unloaded: Vec<PathBuf>,
    /// With `--payload-on` and `--unloaded`: held-out recordings with the
    /// payload, whose torques the robot and payload identified predict.
    #[arg(long, num_args = 1.., requires = "unloaded")]
    pub validate_loaded: Vec<PathBuf>,
    /// With `--payload-on`, instead of `--unloaded`: the robot's parameters
    /// table (an earlier identify's `parameters.parquet`), its covariance
    /// carried into the payload's. Only the payload is written.
    #[arg(long, value_name = "PARAMETERS", requires = "payload_on")]
    pub parameters: Option<PathBuf>,
    /// With `--payload-on`: the payload's mass, kg, known: the drives'
    /// gains are identified too (each joint's torque over its effort as
    /// read).
    #[arg(long, value_name = "KG", requires = "payload_on", conflicts_with = "parameters")]
    pub known_payload_mass: Option<f64>,
    /// With `--payload-on`: where the payload's mass can be, an ellipsoid
    /// in the link's frame: centre x,y,z and semi-axes a,b,c, m. The
    /// physically consistent estimate keeps inside it.
    #[arg(
        long,
        value_delimiter = ',',
        value_name = "X,Y,Z,A,B,C",
        requires = "payload_on",
        allow_negative_numbers = true
    )]
    pub payload_ellipsoid: Vec<f64>,
}

/// The exit code of an identification refused as inadequate.
pub const INADEQUATE_EXIT: u8 = 3;

/// identify's refusal of an inadequate fit (exit code [`INADEQUATE_EXIT`]).
#[derive(Debug)]
pub struct Inadequate(pub String);

impl std::fmt::Display for Inadequate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Inadequate {}

pub fn run(mut args: Args) -> anyhow::Result<()> {
    // With a payload the recordings named are the loaded ones; the robot
    // is identified from the unloaded.
    let (recordings, payload) = match args.payload_on {
        Some(link) => {
            let payload = payload_request(
                link,
                std::mem::take(&mut args.recordings),
                &args.payload_ellipsoid,
                args.known_payload_mass,
                std::mem::take(&mut args.validate_loaded),
            )?;
            if let Some(given) = &args.parameters {
                return payload_only(
                    &payload,
                    &args.robot,
                    given,
                    (args.out.as_deref(), args.accept_inadequate),
                );
            }
            if args.unloaded.is_empty() {
                anyhow::bail!("--payload-on: give the records without the payload (--unloaded) or the robot's parameters (--parameters)");
            }
            (args.unloaded, Some(payload))
        }
        None => (args.recordings, None),
    };
    let request = Request {
        out: args.out,
        read: args
            .read
            .as_deref()
            .map(robotid_stages::stage::read::ReadConfig::from_file)
            .transpose()?,
        torque_per_amp: args.torque_per_amp,
        policy: robotid::verdict::Policy {
            tolerance: args.tolerance / 100.0,
            strict: args.strict,
        },
        accept_inadequate: args.accept_inadequate,
        validate: args.validate,
        mjcf: args.mjcf,
        controller: args.controller,
        mujoco: args.mujoco.then(robotid::mujoco::default_python),
        payload,
        ..Request::new(recordings, args.robot)
    };
    let id = robotid_identify::identify(&request, &crate::progress::Bars::new(false, |_| {}))?;
    print_designs(&id, args.print_pipeline);
    print_estimate(&id);
    for w in id.warnings() {
        eprintln!("warning: {w}");
    }
    let out = id.out.display();
    if let Some(why) = id.refused.as_ref().filter(|_| id.is_refused()) {
        return Err(Inadequate(format!(
            "{}: not identified: {why}\nThe estimate and the report are in {out} marked inadequate (INADEQUATE.txt), with no physical fit and no export; its intervals are not 95 % intervals. To write everything anyway: --accept-inadequate",
            id.recordings[0].log.display(),
        ))
        .into());
    }
    if let Some(why) = &id.refused {
        println!("refused, written anyway (--accept-inadequate): {why}");
    }
    print_physical(&id);
    print_rollouts(&id);
    if args.mujoco && id.mujoco.is_none() {
        eprintln!("note: nothing rolled out in MuJoCo: no MJCF was exported (no physically consistent estimate) or no record was rolled out");
    }
    if let Some(Ok(runs)) = &id.closed_loop {
        print!("\n{}", super::validate::closed_loop_said(runs));
    }
    print_payload(&id);
    println!("report in {}", id.path("report.html").display());
    println!("\nidentified: {out} (pipelines in {out}/pipelines, commands in {out}/identify.sh)");
    match &id.payload {
        Some(fit) if !args.accept_inadequate => payload_determined(fit, &id.path("payload.parquet")),
        _ => Ok(()),
    }
}

/// The payload's request: the recordings named are the loaded ones, and
/// its ellipsoid six numbers or none.
fn payload_request(
    link: String,
    loaded: Vec<std::path::PathBuf>,
    e: &[f64],
    known_mass: Option<f64>,
    validate: Vec<std::path::PathBuf>,
) -> anyhow::Result<PayloadRequest> {
    if !(e.is_empty() || e.len() == 6) {
        anyhow::bail!(
            "--payload-ellipsoid: {} values; give six, the centre x,y,z and the semi-axes a,b,c (m)",
            e.len()
        );
    }
    Ok(PayloadRequest {
        loaded,
        link,
        known_mass,
        bound: (e.len() == 6).then(|| ([e[0], e[1], e[2]], [e[3], e[4], e[5]])),
        validate,
    })
}

/// Refused (exit 3) when the records leave some of the payload's values
/// undetermined at its size: named, the table written all the same.
fn payload_determined(
    fit: &robotid_stages::estimation::payload::PayloadFit,
    table: &std::path::Path,
) -> anyhow::Result<()> {
    match robotid_identify::payload_refused(fit, table) {
        Some(why) => Err(Inadequate(why).into()),
        None => Ok(()),
    }
}

/// The payload against the robot's parameters given: only it identified.
fn payload_only(
    payload: &PayloadRequest,
    robot: &std::path::Path,
    given: &std::path::Path,
    (out, accept_inadequate): (Option<&std::path::Path>, bool),
) -> anyhow::Result<()> {
    let out = out.map(PathBuf::from).unwrap_or_else(|| {
        let stem = payload.loaded[0]
            .file_stem()
            .unwrap_or_default()
            .to_string_lossy()
            .into_owned();
        PathBuf::from("out/payload").join(stem)
    });
    let fit = robotid_identify::payload_against_parameters(
        payload,
        robot,
        given,
        &out,
        &crate::progress::Bars::new(false, |_| {}),
    )?;
    print_payload_fit(&fit);
    println!("payload in {}", out.join("payload.parquet").display());
    match accept_inadequate {
        true => Ok(()),
        false => payload_determined(&fit, &out.join("payload.parquet")),
    }
}

/// What identify found in each recording, the pipelines run, and what the
/// robot file said on the way.
fn print_designs(id: &Identification, print_pipeline: bool) {
    for r in &id.recordings {
        let periodic = if r.design.periodic().is_some() {
            "periodic"
        } else {
            "not periodic"
        };
        println!("{} {} ({periodic}):", r.role.name(), r.name);
        for (k, v) in &r.design.findings {
            if *k == Found::Locked && Some(v) == id.locked.as_ref() {
                continue;
            }
            println!("  {}: {v}", k.key());
        }
    }
    if let Some(said) = &id.locked {
        println!("  locked: {said}: no joint-wise record moves them (each gets its own record to be identified)");
    }
    if print_pipeline {
        let first = &id.recordings[0];
        println!(
            "\n# {}/pipelines/{}.toml\n{}",
            id.out.display(),
            first.name,
            first.design.text
        );
    }
    for (ran, r) in id.runs.iter().zip(&id.recordings) {
        if let Some(l) = &ran.locked {
            println!("{l}");
        }
        let recordings = &ran.report.recordings;
        super::run::print_recordings(recordings, false);
        println!(
            "{0} of {0} recording(s) done in {1:.2} s; output folder {2}",
            recordings.len(),
            ran.report.seconds,
            id.path(&r.name).display()
        );
    }
}

/// The least-squares estimate, its verdict and its validation.
fn print_estimate(id: &Identification) {
    let level = if id.refused.is_some() { None } else { Some(0.95) };
    print!(
        "{}",
        super::estimate::summary_at(
            &id.estimate.estimate,
            0.95,
            level,
            &robotid_stages::estimation::expressions_of(&id.estimate.table)
        )
    );
    print!("{}", super::estimate::findings(&id.estimate));
    println!("verdict: {}", id.verdict.said());
    println!("parameters in {}", id.path("parameters.parquet").display());
    if let Some(v) = &id.validation {
        print!("\n{}", super::validate::said(v, "parameters.parquet".as_ref()));
    }
}

/// The payload, with its intervals and the drives' gains.
fn print_payload(id: &Identification) {
    let Some(fit) = &id.payload else { return };
    print_payload_fit(fit);
    if let Some(v) = &id.payload_validation {
        println!("  on the held-out loaded records: {}", v.said());
    }
    println!("payload in {}", id.path("payload.parquet").display());
    for f in ["identified_payload.urdf", "identified_payload.xml"] {
        if id.path(f).is_file() {
            println!("{}", id.path(f).display());
        }
    }
    if let Ok(why) = std::fs::read_to_string(id.path("identified_payload.txt")) {
        print!("{why}");
    }
}

fn print_payload_fit(fit: &robotid_stages::estimation::payload::PayloadFit) {
    let Some(body) = &fit.body else { return };
    let t = robotid_stages::estimation::student_t_quantile(0.975, fit.estimate.dof);
    println!("\npayload ({} degrees of freedom, 95 % intervals):", fit.estimate.dof);
    let listed = body.listed();
    let bounded = fit.bounded.as_ref().map(|b| b.body.listed());
    for (k, (name, unit)) in robotid_stages::dynamics::LISTED.iter().enumerate() {
        let b = bounded.map(|b| format!("   bounded {:+.5}", b[k])).unwrap_or_default();
        if k == 0 && !fit.gains.is_empty() {
            println!("  {name:<7} {:+.5} {unit} (known)", listed[k]);
            continue;
        }
        println!("  {name:<7} {:+.5} ± {:.5} {unit}{b}", listed[k], t * fit.body_std[k]);
    }
    for g in &fit.gains {
        let b = g.bounded.map(|b| format!("   bounded {b:.5}")).unwrap_or_default();
        println!("  gain {:<24} {:.5} ± {:.5}{b}", g.joint, g.scale, t * g.std);
    }
    if let Some(said) = &fit.bound_said {
        println!("  bound: {said}");
    }
    if let Some(g) = &fit.gains_share {
        println!("  gains: {}", g.said());
    }
    if !fit.undetermined.is_empty() {
        println!(
            "  undetermined at the payload's size (the records do not tell them from any body of that mass and size; move the wrist more, or longer): {}",
            robotid_stages::estimation::payload::said_undetermined(&fit.undetermined)
        );
    }
}

/// The rollouts, per record: each joint's position RMS error (mrad) of
/// the estimate, the physically consistent estimate, the robot file and
/// the export in MuJoCo, as far as each was run (the warnings are
/// [`Identification::warnings`]).
fn print_rollouts(id: &Identification) {
    let Some(Ok(rolled)) = &id.rollouts else {
        return;
    };
    for (k, r) in rolled.iter().enumerate() {
        let stopped = |x: &robotid::simulation::Rollout| x.as_ref().ok().map(|x| x.q_rms.clone());
        let mut columns: Vec<(&str, Option<Vec<f64>>)> = vec![
            ("estimate", stopped(&r.estimate)),
            (
                "physical",
                id.physical_rollouts
                    .as_ref()
                    .and_then(|p| p.as_ref().ok()?.get(k))
                    .and_then(stopped),
            ),
            ("robot file", r.prior.as_ref().and_then(stopped)),
        ];
        if let Some(Ok(m)) = id.mujoco.as_ref().and_then(|m| m.get(k)) {
            let q = r.joints.iter();
            let q = q.map(|j| m.joints.iter().position(|x| x == j).map_or(f64::NAN, |i| m.q_rms[i]));
            columns.push(("MuJoCo", Some(q.collect())));
        }
        println!(
            "\nrollout on {} (windows of {:.3} s), position RMS error, mrad (\"-\": not simulated; the report says why):",
            r.table.display(),
            r.window_s
        );
        let width = r.joints.iter().map(String::len).max().unwrap_or(5).max(5);
        print!("{:width$}", "joint");
        for (name, _) in &columns {
            print!(" {name:>10}");
        }
        println!();
        for (j, joint) in r.joints.iter().enumerate() {
            print!("{joint:width$}");
            for (_, values) in &columns {
                match values {
                    Some(v) => print!(" {:>10.4}", 1e3 * v[j]),
                    None => print!(" {:>10}", "-"),
                }
            }
            println!();
        }
    }
}

/// The physically consistent estimate, its validation and the exports.
fn print_physical(id: &Identification) {
    match &id.physical {
        Physical::Refused | Physical::Failed(_) => {}
        Physical::JointWise => println!("no physical fit and no export for simulators: joint-wise records give the decoupled model (each joint's inertia, gravity and friction), not the links' bodies"),
        Physical::Fitted {
            outcome,
            validation,
            export,
            ..
        } => {
            let table = id.path("parameters_physical.parquet");
            print!("{}", super::estimate::outcome_text(outcome, 0.95, &table));
            if let Some(v) = validation {
                print!("\nthe physically consistent estimate:\n{}", super::validate::said(v, &table));
            }
            println!("{}", export.how);
            for f in &export.files {
                println!("{}", id.path(f).display());
            }
        }
    }
}
