//! The workflow behind [`identify`], one step per function.

use std::path::{Path, PathBuf};

use robotid::identify::{absolute, design_with, Design, Found};
use robotid::validation::Validated;
use robotid::verdict::{channel_gains, Measured, Refusal, Verdict};
use robotid::{Observer, RunOptions};
use robotid_report::export::{Export, Format};
use robotid_schemas::TableKind;
use robotid_stages::estimation::payload::{
    identify_payload, NominalGains, PayloadFit, PayloadOptions, Robot as PayloadRobot,
};
use robotid_stages::estimation::{Covariance, Ellipsoid, Estimate, Estimator, System};
use robotid_stages::stage::estimate::{EstimateConfig, Outcome, Part};
use robotid_stages::stage::read::mcap_has_reference;

use crate::script::Script;
use crate::{
    Error, Identification, PayloadRequest, PayloadValidation, Physical, Ran, Recording, Request, Result, Role,
};

/// A payload's declared values checked before any work: a positive
/// finite mass, a finite centre and positive finite semi-axes.
fn payload_values(p: &PayloadRequest) -> Result<()> {
    if let Some(m) = p.known_mass.filter(|m| !(m.is_finite() && *m > 0.0)) {
        return Err(Error::Request(format!(
            "the known payload mass {m} kg: give a positive number of kilograms"
        )));
    }
    if let Some((centre, axes)) = &p.bound {
        if centre.iter().chain(axes).any(|v| !v.is_finite()) || axes.iter().any(|a| *a <= 0.0) {
            return Err(Error::Request(format!(
                "the payload's ellipsoid: centre {centre:?} m, semi-axes {axes:?} m: give a finite centre and positive, finite semi-axes"
            )));
        }
    }
    Ok(())
}

/// Identifies the robot of `request` (see the crate's documentation),
/// `observer` told of each pipeline's steps and of the physical fit. A
/// refused fit is an [`Identification`] whose `refused` says why, its
/// files written and marked; errors are for what could not be judged.
pub fn identify(request: &Request, observer: &dyn Observer) -> Result<Identification> {
    request.payload.as_ref().map(payload_values).transpose()?;
    let paths = Paths::of(request)?;
    // The robot file as the payload's table and exports see it, its link
    // checked before anything runs.
    let payload_model = match &request.payload {
        Some(p) => {
            let model = robotid_stages::dynamics::load_robot(&paths.robot)?;
            payload_frame(&model, &p.link)?;
            Some(model)
        }
        None => None,
    };
    // Everything is written into a staging folder and appears at once when
    // identify ends, refused or not (robotid::output): a kill or a failure
    // leaves the folder as it was. One identify or run at a time holds it.
    let staging = robotid::output::prepare(&absolute_path(&paths.out)?, None, &paths.all)?;
    if holds_anything(&paths.out) {
        return Err(Error::Request(format!(
            "{}: the output folder is not empty; give another, or remove it",
            paths.out.display()
        )));
    }
    let (recordings, locked) = design_all(request, &paths)?;
    // Every output is written into the staging folder and named relative
    // to it: the files that name each other (the report, the exports, the
    // estimate's provenance) hold paths that stay right when the folder
    // appears as `out`, and when it is moved.
    let staged = staging.staged_out();
    let mut script = Script::new(&paths.robot);
    let runs = run_pipelines(request, (staged, &paths.out), &recordings, &mut script, observer)?;
    let tables: Vec<PathBuf> = recordings.iter().map(regressor_table).collect();
    let (id_tables, rest) = tables.split_at(paths.identifying);
    let (val_tables, loaded_tables) = rest.split_at(paths.held.len());
    let mut recordings = recordings;
    let mut judged = estimate(request, (staged, &paths), &recordings, id_tables, val_tables)?;
    if own_delays(request, (staged, &paths), &mut recordings, val_tables, observer)? {
        // The verdict reads the validation rows: judged again on the rows
        // with their own delay.
        judged = estimate(request, (staged, &paths), &recordings, id_tables, val_tables)?;
    }
    script.estimate(id_tables, None);
    let validation = match val_tables {
        [] => None,
        tables => Some(Box::new(validate(staged, "parameters.parquet", tables, &paths.held)?)),
    };
    script.validate("parameters.parquet", val_tables);
    let (fit_tables, held_loaded) = loaded_tables.split_at(request.payload.as_ref().map_or(0, |p| p.loaded.len()));
    let payload = match &request.payload {
        Some(p) => Some(Box::new(payload_from_tables(
            p,
            &paths.robot,
            staged,
            id_tables,
            fit_tables,
        )?)),
        None => None,
    };
    let payload_validation = match &payload {
        Some(fit) if !held_loaded.is_empty() => payload_validated(fit, staged, held_loaded)?,
        _ => None,
    };
    if let (Some(p), Some(fit), Some(model)) = (&request.payload, &payload, &payload_model) {
        write_payload(p, fit, payload_validation.as_ref(), model, staged)?;
    }
    let physical = physical_or_why(
        request,
        &mut judged,
        &recordings,
        (staged, &paths),
        (id_tables, val_tables),
        &mut script,
        observer,
    )?;
    let fitted = matches!(physical, Physical::Fitted { .. });
    if let (Some(p), Some(fit), Some(model), true) = (&request.payload, &payload, &payload_model, fitted) {
        payload_export(&p.link, fit, model, staged)?;
    }
    let raw_tables: Vec<PathBuf> = recordings
        .iter()
        .filter(|r| r.role == Role::Validation)
        .map(|r| recording_table(r, TableKind::RawSamples))
        .collect();
    let page = robotid_report::report::Page {
        parameters: "parameters.parquet".into(),
        excitation: id_tables.to_vec(),
        validation: val_tables.to_vec(),
        physical: fitted.then(|| "parameters_physical.parquet".into()),
        robot: Some(paths.robot.clone()),
        rollout: true,
        payload: payload.as_ref().map(|_| "payload.parquet".into()),
        closed_loop: paths.controller.clone().map(|c| (c, raw_tables.clone())),
        mujoco: request
            .mujoco
            .clone()
            .filter(|_| fitted)
            .map(|python| ("identified.xml".into(), python)),
        out: "report.html".into(),
        within: staged.to_path_buf(),
    };
    // Every simulation is run here, held on the identification; the page
    // only draws them.
    let simulated = robotid::simulation::simulate(&page.asked());
    robotid_report::report::render(&page, &simulated)?;
    // Each run named where its table will be, not where it was read.
    let closed_loop = simulated.closed_loop.map(|runs| {
        runs.map(|mut runs| {
            for r in &mut runs {
                if let Ok(rel) = r.recording.strip_prefix(staged) {
                    r.recording = paths.out.join(rel);
                }
            }
            runs
        })
    });
    script.report(
        (id_tables, val_tables),
        fitted,
        request.mujoco.is_some(),
        payload.is_some(),
        paths.controller.as_deref().map(|c| (c, raw_tables.as_slice())),
    );
    std::fs::write(staged.join("identify.sh"), script.text()).map_err(io(&paths.out.join("identify.sh")))?;
    staging.commit()?;
    Ok(Identification {
        out: paths.out,
        recordings,
        locked,
        runs,
        estimate: Box::new(judged.outcome),
        verdict: judged.verdict,
        refused: judged.refused,
        unjudged: judged.unjudged,
        validation,
        physical,
        rollouts: simulated.rolled,
        closed_loop,
        mujoco: simulated.mujoco,
        physical_rollouts: simulated.physical,
        payload,
        payload_validation,
    })
}

/// The robot and payload identified, predicting the held-out loaded
/// records' torques (None with a known mass: the gains' model predicts
/// efforts, not these columns).
fn payload_validated(fit: &PayloadFit, staged: &Path, held: &[PathBuf]) -> Result<Option<PayloadValidation>> {
    let sys = robotid::tables::load_system(staged, held)?;
    if sys.names != fit.estimate.names {
        return Ok(None);
    }
    let predicted = &sys.a * &fit.estimate.values;
    let stats = robotid::validation::residues(&sys, &predicted);
    Ok(Some(PayloadValidation {
        relative_error: robotid::validation::relative_error(&stats),
        joints: stats
            .iter()
            .map(|r| (r.joint.clone(), r.noise_floor.filter(|f| *f > 0.0).map(|f| r.msr / f)))
            .collect(),
    }))
}

/// The payload identified, written as `payload.parquet`, its held-out
/// validation said in the metadata (`robotid.payload.validation`).
fn write_payload(
    request: &PayloadRequest,
    fit: &PayloadFit,
    validation: Option<&PayloadValidation>,
    model: &robotid_stages::dynamics::Model,
    staged: &Path,
) -> Result<()> {
    let mut table = robotid_stages::estimation::payload::payload_table(fit, &request.link, model)?;
    if let Some(v) = validation {
        let mut md = table.schema().metadata().clone();
        md.insert(
            robotid_schemas::metadata::PAYLOAD_VALIDATION.to_string(),
            format!("on the held-out loaded records: {}", v.said()),
        );
        let schema = std::sync::Arc::new(table.schema().as_ref().clone().with_metadata(md));
        table = table
            .with_schema(schema)
            .map_err(|e| robotid_stages::Error::numerical("the payload table", e.to_string()))?;
    }
    robotid_stages::formats::parquet::write_parquet(&staged.join("payload.parquet"), &table)?;
    Ok(())
}

/// The payload of `request` from its loaded recordings against the robot's
/// parameters given as a table (`parameters`, of an earlier identify of
/// `robot`), into `out` (`payload.parquet` and the loaded records'
/// pipelines and tables), appearing at once. The loaded records'
/// pipelines are designed from them (filter, delay, periods) with the
/// table's regressor model and the payload's columns; the table's
/// covariance is carried into the payload's.
pub fn payload_against_parameters(
    request: &PayloadRequest,
    robot: &Path,
    parameters: &Path,
    out: &Path,
    observer: &dyn Observer,
) -> Result<PayloadFit> {
    let robot = absolute(robot)?;
    let loaded = request
        .loaded
        .iter()
        .map(|p| absolute(p))
        .collect::<robotid::Result<Vec<_>>>()?;
    if loaded.is_empty() {
        return Err(Error::Request("--payload-on: no recording with the payload".into()));
    }
    payload_values(request)?;
    let model = robotid_stages::dynamics::load_robot(&robot)?;
    payload_frame(&model, &request.link)?;
    let table = robotid_stages::formats::parquet::read_parquet(parameters)?;
    let given = robotid_stages::estimation::parameters_from_table(&table)?;
    let mut regressor = robotid_stages::stage::regressor::RegressorConfig::of_metadata(&given.metadata)?;
    regressor.payload = true;
    let staging = robotid::output::prepare(&absolute_path(out)?, None, &loaded)?;
    if holds_anything(out) {
        return Err(Error::Request(format!(
            "{}: the output folder is not empty; give another, or remove it",
            out.display()
        )));
    }
    let names = robotid::run::recording_names(&loaded);
    let mut recordings: Vec<Recording> = Vec::new();
    for (log, name) in loaded.iter().zip(names) {
        // The robot file lacks the payload: the first record's torques
        // are not held against its own.
        let mut design = match recordings.first() {
            Some(r) => design_with(log, &robot, Some(&r.design), None, None)?,
            None => robotid::identify::design_loaded(log, &robot)?,
        };
        // The table's model, this record's band.
        let band = design.regressor.band_limit_hz;
        design.regressor = robotid_stages::stage::regressor::RegressorConfig {
            band_limit_hz: band,
            ..regressor.clone()
        };
        for stage in design.plan.stages.iter_mut() {
            if let robotid::plan::StageConfig::Regressor(c) = stage {
                *c = design.regressor.clone();
            }
        }
        design.text = robotid::identify::file_text(&design.plan)?;
        recordings.push(Recording {
            role: Role::Loaded,
            name,
            log: log.clone(),
            design,
        });
    }
    let staged = staging.staged_out().to_path_buf();
    let runner = Request::new(Vec::new(), robot.clone());
    run_pipelines(&runner, (&staged, out), &recordings, &mut Script::new(&robot), observer)?;
    let tables: Vec<PathBuf> = recordings.iter().map(regressor_table).collect();
    let system = robotid::tables::load_system(&staged, &tables)?;
    let known = robotid_stages::estimation::Known {
        names: given.names.clone(),
        values: given.values.clone(),
        covariance: given.covariance.clone(),
    };
    let gains = nominal_gains(&model, &system);
    let fit = bounded_payload(request, &model, |bound| {
        identify_payload(
            &system,
            PayloadRobot::Known(&known),
            &PayloadOptions {
                known_mass: None,
                bound,
                gains: gains.as_ref(),
            },
        )
    })?;
    let table = robotid_stages::estimation::payload::payload_table(&fit, &request.link, &model)?;
    robotid_stages::formats::parquet::write_parquet(&staged.join("payload.parquet"), &table)?;
    staging.commit()?;
    Ok(fit)
}

/// The declared bound (in the payload link's frame) in the last moving
/// link's: its centre moved there, its semi-axes permuted where the
/// frames' axes map onto each other (flanges turned by multiples of 90°),
/// else the sphere holding it.
fn bound_in_last_link(
    bound: Option<([f64; 3], [f64; 3])>,
    (rot, pos): (&nalgebra::Matrix3<f64>, &nalgebra::Vector3<f64>),
) -> Option<Ellipsoid> {
    bound.map(|(c, a)| {
        let a = nalgebra::Vector3::from(a);
        let aligned = rot.iter().all(|v| v.abs() < 1e-9 || (v.abs() - 1.0).abs() < 1e-9);
        Ellipsoid {
            centre: rot * nalgebra::Vector3::from(c) + pos,
            semi_axes: if aligned {
                (rot * a).abs()
            } else {
                nalgebra::Vector3::repeat(a.max())
            },
        }
    })
}

/// A recording's regressor table, relative to the staging folder.
fn regressor_table(r: &Recording) -> PathBuf {
    recording_table(r, TableKind::Regressor)
}

/// A recording's table of `kind`, relative to the staging folder: its
/// pipeline runs one log, which it names by the log's stem.
fn recording_table(r: &Recording, kind: TableKind) -> PathBuf {
    let own = robotid::run::recording_names(std::slice::from_ref(&r.log));
    Path::new(&r.name)
        .join(&own[0])
        .join(format!("{}.parquet", kind.name()))
}

/// The identified URDF and MJCF with the payload on
/// (`identified_payload.urdf`, `.xml`), or why not
/// (`identified_payload.txt`).
fn payload_export(link: &str, fit: &PayloadFit, model: &robotid_stages::dynamics::Model, staged: &Path) -> Result<()> {
    use robotid_stages::estimation::payload::{mjcf_with_payload, urdf_with_payload};
    let last = model.joints.last().map(|j| j.name.clone()).unwrap_or_default();
    let (rot, pos) = payload_frame(model, link)?;
    let mut why = Vec::new();
    let read = |name: &str| std::fs::read_to_string(staged.join(name)).ok();
    let made = [
        (
            "urdf",
            "URDF",
            read("identified.urdf").map(|t| urdf_with_payload(&t, (link, &last), (&rot, &pos), fit)),
        ),
        (
            "xml",
            "MJCF",
            read("identified.xml").map(|t| mjcf_with_payload(&t, model, (&rot, &pos), fit)),
        ),
    ];
    for (ext, format, text) in made {
        let path = staged.join(format!("identified_payload.{ext}"));
        match text {
            Some(Ok(text)) => std::fs::write(&path, text).map_err(io(&path))?,
            Some(Err(w)) => why.push(format!("no {format} with the payload: {w}\n")),
            None => {}
        }
    }
    if !why.is_empty() {
        let path = staged.join("identified_payload.txt");
        std::fs::write(&path, why.concat()).map_err(io(&path))?;
    }
    Ok(())
}

/// Where `link` is in the last moving link's frame: that link (named by
/// its joint or its own name) or one welded to it.
pub(crate) fn payload_frame(
    model: &robotid_stages::dynamics::Model,
    link: &str,
) -> Result<(nalgebra::Matrix3<f64>, nalgebra::Vector3<f64>)> {
    let last = model.joints.last().map(|j| j.name.clone()).unwrap_or_default();
    if link == last {
        return Ok((nalgebra::Matrix3::identity(), nalgebra::Vector3::zeros()));
    }
    match model.end_frames.iter().find(|(n, _, _)| n == link) {
        Some((_, r, p)) => Ok((*r, *p)),
        None => {
            let mut held: Vec<String> = model.end_frames.iter().map(|f| f.0.clone()).collect();
            held.push(last);
            Err(Error::Request(format!(
                "--payload-on {link}: not a link the last moving joint carries; one of {}",
                held.join(", ")
            )))
        }
    }
}

/// The payload of `request` from the `regressor` tables (paths under
/// `within`) of records of `robot` without it (`unloaded`) and with it
/// (`loaded`, made with the payload's columns): identified
/// (`estimation::payload`) and given about the requested link.
pub fn payload_from_tables(
    request: &PayloadRequest,
    robot: &Path,
    within: &Path,
    unloaded: &[PathBuf],
    loaded: &[PathBuf],
) -> Result<PayloadFit> {
    let model = robotid_stages::dynamics::load_robot(robot)?;
    let unloaded = robotid::tables::load_system(within, unloaded)?;
    let loaded = robotid::tables::load_system(within, loaded)?;
    let gains = nominal_gains(&model, &loaded);
    bounded_payload(request, &model, |bound| {
        identify_payload(
            &loaded,
            PayloadRobot::Unloaded(&unloaded),
            &PayloadOptions {
                known_mass: request.known_mass,
                bound,
                gains: gains.as_ref(),
            },
        )
    })
}

/// Where the records' torques are currents through the robot file's (or
/// the `[read]` table's) gains: each joint's gain's relative standard
/// deviation, the robot file's `torque_constant_rel_std` or the default,
/// and which.
fn nominal_gains(
    model: &robotid_stages::dynamics::Model,
    sys: &robotid_stages::estimation::System,
) -> Option<NominalGains> {
    let through = sys.metadata.get(robotid_schemas::metadata::EFFORT_GAINS)?;
    let names = model.joint_names();
    let declared: Vec<Option<f64>> = sys
        .joints
        .iter()
        .map(|j| {
            names
                .iter()
                .position(|n| n == j)
                .and_then(|i| model.drives[i].gain_rel_std)
        })
        .collect();
    let default = robotid_stages::dynamics::DEFAULT_GAIN_REL_STD;
    let rel_std: Vec<f64> = declared.iter().map(|d| d.unwrap_or(default)).collect();
    let whose = if declared.iter().all(Option::is_some) {
        "as the robot file declares (torque_constant_rel_std)".to_string()
    } else {
        format!(
            "{}the default {:.0} % where the robot file declares no `torque_constant_rel_std`",
            if declared.iter().any(Option::is_some) {
                "as the robot file declares, and "
            } else {
                ""
            },
            100.0 * default
        )
    };
    let each: Vec<String> = sys
        .joints
        .iter()
        .zip(&rel_std)
        .map(|(j, s)| format!("{j} {:.1} %", 100.0 * s))
        .collect();
    Some(NominalGains {
        said: format!(
            "the torques are {through}, each gain uncertain by {} ({whose})",
            each.join(", ")
        ),
        rel_std,
    })
}

/// The payload `fit` gives (with its bound in the last moving link's
/// frame), about the requested link, bounded by the declared ellipsoid,
/// else by the robot file's shapes of that link (a tool's geometry) when
/// they hold the least-squares centre of mass: where the bound came from
/// said, or why the shapes were not taken.
fn bounded_payload(
    request: &PayloadRequest,
    model: &robotid_stages::dynamics::Model,
    fit: impl Fn(Option<Ellipsoid>) -> robotid_stages::Result<PayloadFit>,
) -> Result<PayloadFit> {
    let (rot, pos) = payload_frame(model, &request.link)?;
    let frame = (&rot, &pos);
    if let Some(declared) = request.bound {
        let mut f = fit(bound_in_last_link(Some(declared), frame))?.in_frame(&rot, &pos);
        f.bound_said = Some("the declared ellipsoid (--payload-ellipsoid)".into());
        return Ok(f);
    }
    let at = model.end_frames.iter().position(|f| f.0 == request.link);
    let shapes = at.and_then(|k| model.end_extents.get(k).copied().flatten());
    let free = fit(None)?.in_frame(&rot, &pos);
    let Some(extent) = shapes else {
        return Ok(free);
    };
    let e = Ellipsoid::around(&extent);
    let box_said = format!(
        "the robot file's shapes of `{}` (a box {:.3} × {:.3} × {:.3} m about ({:.3}, {:.3}, {:.3}) m, in the ellipsoid through its corners)",
        request.link,
        extent.max.x - extent.min.x,
        extent.max.y - extent.min.y,
        extent.max.z - extent.min.z,
        e.centre.x,
        e.centre.y,
        e.centre.z
    );
    match free.body.filter(|b| e.holds(&b.com)) {
        Some(_) => {
            let c = e.centre.into();
            let a = e.semi_axes.into();
            let mut f = fit(bound_in_last_link(Some((c, a)), frame))?.in_frame(&rot, &pos);
            f.bound_said = Some(box_said);
            Ok(f)
        }
        None => Ok(PayloadFit {
            bound_said: Some(format!(
                "none: {box_said} do not hold the least-squares centre of mass{}, so they are not the payload's; declare its size with --payload-ellipsoid",
                free.body
                    .map(|b| format!(" ({:.3}, {:.3}, {:.3}) m", b.com.x, b.com.y, b.com.z))
                    .unwrap_or_default()
            )),
            ..free
        }),
    }
}

/// The physical fit, or why there is none, and the verdict on what is
/// exported. Refused (and not written anyway: marked INADEQUATE.txt) for a
/// measured cause before any fit; a held-out relative error over the
/// tolerance is judged on the estimate exported, the physically consistent
/// one where it is validated (its bounded bodies extrapolate to a record
/// the least squares' free directions do not: the real KUKA LWR4+'s file 3
/// at 5.7 % against 9.4 %), and the least squares' table marked again.
fn physical_or_why(
    request: &Request,
    judged: &mut Judged,
    recordings: &[Recording],
    (staged, paths): (&Path, &Paths),
    tables: (&[PathBuf], &[PathBuf]),
    script: &mut Script,
    observer: &dyn Observer,
) -> Result<Physical> {
    let refuse = |judged: &Judged| -> Result<Option<Physical>> {
        match judged.refused.as_deref().filter(|_| !request.accept_inadequate) {
            Some(refused) => {
                std::fs::write(staged.join("INADEQUATE.txt"), format!("{refused}\n"))
                    .map_err(io(&paths.out.join("INADEQUATE.txt")))?;
                Ok(Some(Physical::Refused))
            }
            None => Ok(None),
        }
    };
    let by_tolerance = matches!(
        judged.verdict.refused,
        None | Some(Refusal::OverTolerance {
            measured: Measured::Validation,
            ..
        })
    );
    let joint_wise = recordings.iter().any(|r| r.design.joint_wise.is_some());
    if !by_tolerance || joint_wise {
        if let Some(refused) = refuse(judged)? {
            return Ok(refused);
        }
    }
    if joint_wise {
        // The model for simulators needs every link a real body; the
        // decoupled model of joint-wise records has none to fit.
        return Ok(Physical::JointWise);
    }
    let fitted = physical_fit(&judged.parts, (staged, paths), tables, observer)?;
    if let Fit::Fitted {
        validation: Some(v), ..
    } = &fitted
    {
        let held_out = (
            robotid::validation::relative_error(&v.stats),
            Measured::ValidationPhysical,
        );
        judged.rejudge(held_out, recordings, &staged.join("parameters.parquet"))?;
    }
    if let Some(refused) = refuse(judged)? {
        std::fs::remove_file(staged.join(PHYSICAL)).map_err(io(&paths.out.join(PHYSICAL)))?;
        return Ok(refused);
    }
    match fitted {
        Fit::Failed(why) => Ok(Physical::Failed(why)),
        Fit::Fitted {
            outcome,
            fallback,
            validation,
        } => {
            let export = robotid_report::export::export(&Export {
                robot: paths.robot.clone(),
                parameters: PHYSICAL.into(),
                formats: vec![Format::Urdf, Format::Mjcf, Format::Sidecar],
                out: "identified".into(),
                prior_weight: None,
                force: false,
                within: staged.to_path_buf(),
                mjcf: paths.mjcf.clone(),
            })?;
            let (id_tables, val_tables) = tables;
            script.estimate(id_tables, Some(if fallback.is_some() { "residual" } else { "robust" }));
            script.validate(PHYSICAL, val_tables);
            script.export(paths.mjcf.as_deref());
            Ok(Physical::Fitted {
                outcome,
                fallback,
                validation,
                export,
            })
        }
    }
}

/// The request's files made absolute and checked.
struct Paths {
    robot: PathBuf,
    /// The user's MJCF, to patch.
    mjcf: Option<PathBuf>,
    /// The validation records' controller, read.
    controller: Option<PathBuf>,
    /// The identification recordings, then the validation ones.
    all: Vec<PathBuf>,
    identifying: usize,
    held: Vec<PathBuf>,
    names: Vec<String>,
    out: PathBuf,
}

impl Paths {
    fn of(request: &Request) -> Result<Paths> {
        let absolutes = |ps: &[PathBuf]| ps.iter().map(|p| absolute(p)).collect::<robotid::Result<Vec<_>>>();
        let robot = absolute(&request.robot)?;
        let mjcf = request.mjcf.as_deref().map(absolute).transpose()?;
        if let Some(m) = mjcf.as_deref().filter(|m| !m.is_file()) {
            return Err(Error::Request(format!("--mjcf {}: no such file", m.display())));
        }
        let mut all = absolutes(&request.recordings)?;
        let held = absolutes(&request.validate)?;
        let controller = request.controller.as_deref().map(absolute).transpose()?;
        if let Some(c) = &controller {
            if held.is_empty() {
                return Err(Error::Request(format!(
                    "--controller {}: no --validate recording to run it on",
                    c.display()
                )));
            }
            let dof = robotid_stages::dynamics::load_robot(&robot)?.dof();
            robotid::validation::read_controller(c, dof)?;
        }
        let identifying = all.len();
        all.extend(held.iter().cloned());
        if let Some(p) = &request.payload {
            if p.loaded.is_empty() {
                return Err(Error::Request("--payload-on: no recording with the payload".into()));
            }
            all.extend(absolutes(&p.loaded)?);
            all.extend(absolutes(&p.validate)?);
        }
        if identifying == 0 {
            return Err(Error::Request("no recording to identify from".into()));
        }
        let names = robotid::run::recording_names(&all);
        let out = request
            .out
            .clone()
            .unwrap_or_else(|| PathBuf::from("out/identify").join(&names[0]));
        if out.exists() && !out.is_dir() {
            return Err(Error::Request(format!(
                "{}: the output folder is a file; give a folder",
                out.display()
            )));
        }
        if all.iter().any(|p| absolute(&out).is_ok_and(|o| p.starts_with(o))) {
            return Err(Error::Request(format!(
                "{}: the output folder holds the recordings",
                out.display()
            )));
        }
        // The same data under two names would count twice: the intervals
        // shrink by √2, and a validation on its own excitation proves nothing.
        if let Some((first, again)) = robotid::tables::same_bytes(&all)? {
            return Err(Error::Request(format!(
                "{} and {} hold the same bytes: one recording given twice (its rows would count twice and the intervals shrink by √2, or it would validate itself)",
                first.display(),
                again.display()
            )));
        }
        Ok(Paths {
            robot,
            mjcf,
            controller,
            all,
            identifying,
            held,
            names,
            out,
        })
    }
}

/// The drives' gains of the request, one per joint.
fn gains(request: &Request, robot: &Path) -> Result<Option<Vec<f64>>> {
    let joints = robotid_stages::dynamics::load_robot(robot)?.joint_names().len();
    let gains = match request.torque_per_amp[..] {
        [] => return Ok(None),
        [k] => vec![k; joints],
        ref k if k.len() == joints => k.to_vec(),
        ref k => {
            return Err(Error::Request(format!(
                "the drives' gains (torque per amp): {} values for {joints} joints: give one per joint, or one for all",
                k.len()
            )))
        }
    };
    match gains.iter().find(|k| !(k.is_finite() && **k != 0.0)) {
        Some(k) => Err(Error::Request(format!(
            "the drives' gains (torque per amp): {k} N·m/A is not a drive's gain"
        ))),
        None => Ok(Some(gains)),
    }
}

/// Every recording's pipeline designed; all take the first one's
/// regressor stage, so that their tables share one parameter set.
fn design_all(request: &Request, paths: &Paths) -> Result<(Vec<Recording>, Option<String>)> {
    let gains = gains(request, &paths.robot)?;
    let mut designs: Vec<Design> = Vec::new();
    for log in &paths.all {
        // Its errors name the recording.
        let d = design_with(
            log,
            &paths.robot,
            designs.first(),
            request.read.as_ref(),
            gains.as_deref(),
        )?;
        designs.push(d);
    }
    // The loaded records' regressor carries the payload's columns.
    for d in designs.iter_mut().skip(paths.identifying + paths.held.len()) {
        d.regressor.payload = true;
        for stage in d.plan.stages.iter_mut() {
            if let robotid::plan::StageConfig::Regressor(c) = stage {
                c.payload = true;
            }
        }
        d.text = robotid::identify::file_text(&d.plan)?;
    }
    // Under a declared controller, the validation records' raw samples
    // (their references with them) are kept for the closed loop.
    if paths.controller.is_some() {
        for (d, log) in designs
            .iter_mut()
            .zip(&paths.all)
            .skip(paths.identifying)
            .take(paths.held.len())
        {
            if !d.plan.tables.contains(&TableKind::RawSamples) {
                d.plan.tables.push(TableKind::RawSamples);
            }
            // An MCAP log's reference topic is read only when asked for
            // (a text log's `ref_` columns are found with the others).
            if d.plan.read.reference.is_none() && mcap_has_reference(log) {
                d.plan.read.reference = Some(robotid_stages::stage::read::Channel {
                    column: None,
                    topic: None,
                    field: None,
                    unit: None,
                });
            }
            d.text = robotid::identify::file_text(&d.plan)?;
        }
    }
    let locked = lock_unrecorded(&mut designs, paths.identifying)?;
    let recordings = designs
        .into_iter()
        .enumerate()
        .map(|(i, design)| Recording {
            role: if i < paths.identifying {
                Role::Excitation
            } else if i < paths.identifying + paths.held.len() {
                Role::Validation
            } else {
                Role::Loaded
            },
            name: paths.names[i].clone(),
            log: paths.all[i].clone(),
            design,
        })
        .collect();
    Ok((recordings, locked))
}

/// Joint-wise records that move only some joints give no parameter of the
/// others: those joints are locked where the records held them (said), so
/// that the estimate is of the joints that moved. Validation records (after
/// the first `identifying`) are locked alike: one parameter set.
fn lock_unrecorded(designs: &mut [Design], identifying: usize) -> Result<Option<String>> {
    let Some(all) = designs[..identifying]
        .iter()
        .map(|d| d.joint_wise.as_ref())
        .collect::<Option<Vec<_>>>()
    else {
        return Ok(None);
    };
    let moved: Vec<&str> = all.iter().map(|(m, _)| m.as_str()).collect();
    let Some((_, held)) = all.first() else { return Ok(None) };
    let locked: Vec<(String, f64)> = held
        .iter()
        .filter(|(j, _)| !moved.contains(&j.as_str()))
        .cloned()
        .collect();
    if locked.is_empty() {
        return Ok(None);
    }
    let said = locked
        .iter()
        .map(|(j, q)| format!("{j} at {q:.4} rad"))
        .collect::<Vec<_>>()
        .join(", ");
    for d in designs.iter_mut() {
        d.plan.lock.extend(locked.iter().cloned());
        d.findings.push((Found::Locked, said.clone()));
        let all = match d.plan.inferred.get(Found::Locked.key()) {
            Some(before) => format!("{before}; {said}"),
            None => said.clone(),
        };
        d.plan.inferred.insert(Found::Locked.key().into(), all);
        d.text = robotid::identify::file_text(&d.plan)?;
    }
    Ok(Some(said))
}

/// Each recording's pipeline written to `pipelines/` and run into its
/// folder (inside the staging folder); `out` is where they will appear.
fn run_pipelines(
    request: &Request,
    (staged, out): (&Path, &Path),
    recordings: &[Recording],
    script: &mut Script,
    observer: &dyn Observer,
) -> Result<Vec<Ran>> {
    std::fs::create_dir_all(staged.join("pipelines")).map_err(io(out))?;
    let mut runs = Vec::new();
    for r in recordings {
        // Written staged, read as the file it will be: what the tables and
        // the manifest say of it names its final place.
        let rel = Path::new("pipelines").join(format!("{}.toml", r.name));
        std::fs::write(staged.join(&rel), &r.design.text).map_err(io(&out.join(&rel)))?;
        let built = robotid::Pipeline::from_toml(&r.design.text, out.join(&rel))?.build()?;
        let warnings: Vec<String> = built.model.iter().flat_map(|m| m.warnings.clone()).collect();
        let locked = built.model.as_ref().filter(|m| !m.locked.is_empty()).map(|m| {
            let l: Vec<String> = m.locked.iter().map(|(j, x)| format!("{j} at {x}")).collect();
            format!("robot `{}`: {} moving joints; locked {}", m.name, m.dof(), l.join(", "))
        });
        let report = built.run_with(
            &RunOptions {
                out: staged.join(&r.name),
                threads: request.threads,
                plot: None,
            },
            observer,
        )?;
        let failed: Vec<(String, String)> = report
            .recordings
            .iter()
            .filter_map(|x| Some((x.name.clone(), x.outcome.as_ref().err()?.to_string())))
            .collect();
        if !failed.is_empty() {
            return Err(Error::Failed { failed });
        }
        script.run(&r.name);
        runs.push(Ran {
            warnings,
            locked,
            report,
        });
    }
    Ok(runs)
}

/// Validation records that do not repeat take the identification
/// recording's effort delay; a logger may have another for them (the
/// foreign `ur5_lab`'s validation record is not late at all). Their own:
/// the time shift of the measured torque against the estimate's
/// prediction (`robotid::validation::time_shift`), undone in up to three
/// Gauss–Newton steps while it is over a tenth of a sample, kept where it
/// lowers the residue (one parameter of the chain: it takes up only the
/// part of a model error that looks like a shift). Whether any changed.
fn own_delays(
    request: &Request,
    (staged, paths): (&Path, &Paths),
    recordings: &mut [Recording],
    val_tables: &[PathBuf],
    observer: &dyn Observer,
) -> Result<bool> {
    let mut changed = false;
    for (r, table) in recordings[paths.identifying..].iter_mut().zip(val_tables) {
        if r.design.periodic().is_some() {
            continue;
        }
        let before = r.design.clone();
        let log = std::slice::from_ref(&r.log);
        let (first_shift, first_ratio, fs) = match shift_and_ratio(staged, table, log)? {
            (Some(s), ratio, Some(fs)) if (s * fs).abs() > 0.25 => (s, ratio, fs),
            _ => continue,
        };
        let (mut shift, mut ratio) = (first_shift, first_ratio);
        let inherited = before.delay_s.unwrap_or(0.0);
        let mut delay = inherited;
        for _ in 0..3 {
            delay -= shift;
            let said = format!(
                "{:.3} samples ({:.3} ms) late, this record's own (the identification recording's {:.3} samples left its torque {:.2} samples ahead of the estimate's prediction, {:.2}× its floor), undone",
                delay * fs,
                delay * 1e3,
                inherited * fs,
                first_shift * fs,
                first_ratio
            );
            r.design.with_delay(delay, fs, said)?;
            rerun(request, (staged, &paths.out), r, observer)?;
            let (s, now, _) = shift_and_ratio(staged, table, std::slice::from_ref(&r.log))?;
            ratio = ratio.min(now);
            match s {
                Some(s) if (s * fs).abs() > 0.1 => shift = s,
                _ => break,
            }
        }
        if ratio < first_ratio {
            changed = true;
        } else {
            r.design = before;
            rerun(request, (staged, &paths.out), r, observer)?;
        }
    }
    Ok(changed)
}

/// The time shift of a validation table's measured torque against the
/// estimate's prediction (s), and its pooled mean squared residue over the
/// floor (infinite without one), and its sample rate.
fn shift_and_ratio(staged: &Path, table: &Path, log: &[PathBuf]) -> Result<(Option<f64>, f64, Option<f64>)> {
    let v = validate(staged, "parameters.parquet", &[table.to_path_buf()], log)?;
    let shift = robotid::validation::time_shift(&v.sys, &v.predicted);
    let floor: f64 = v
        .stats
        .iter()
        .map(|s| s.rows as f64 * s.noise_floor.unwrap_or(0.0))
        .sum();
    let msr: f64 = v.stats.iter().map(|s| s.rows as f64 * s.msr).sum();
    // The rate of its rows' samples (a filtered record's are uniform).
    let (t, k, n) = (&v.sys.time, &v.sys.sample, v.sys.rows());
    let fs = (n > 1 && t[n - 1] > t[0]).then(|| (k[n - 1] - k[0]) as f64 / (t[n - 1] - t[0]));
    Ok((shift, if floor > 0.0 { msr / floor } else { f64::INFINITY }, fs))
}

/// One recording's pipeline run again into its folder (its design changed).
fn rerun(request: &Request, (staged, out): (&Path, &Path), r: &Recording, observer: &dyn Observer) -> Result<()> {
    let folder = staged.join(&r.name);
    std::fs::remove_dir_all(&folder).map_err(io(&out.join(&r.name)))?;
    run_pipelines(
        request,
        (staged, out),
        std::slice::from_ref(r),
        &mut Script::new(Path::new("")),
        observer,
    )?;
    Ok(())
}

/// The least-squares estimate, judged.
struct Judged {
    /// The tables' rows reduced once: the estimate and its physical fit
    /// share them.
    parts: Vec<Part>,
    outcome: Outcome,
    judge: Judge,
    verdict: Verdict,
    refused: Option<String>,
    unjudged: Vec<String>,
}

/// What the verdict reads: the identification's rows (its residue by
/// speed) and the validation's (the held-out relative error), else the
/// held-out periods' relative error.
struct Judge {
    policy: robotid::verdict::Policy,
    id_rows: System,
    val_rows: Option<System>,
    periods_relative: Option<f64>,
    /// Else a block held out in time (fewer than two steady periods).
    split_relative: Option<f64>,
    /// Every identification record has steady periods that repeat: its
    /// noise floor comes from their spread.
    repeated: bool,
    /// The effort channels' gains, fitted once: on the validation rows
    /// where they tell them (a record compared sample by sample; the
    /// identification's may be its excited lines alone, as many equations
    /// as a few parameters more than the model's, which a scale is lost
    /// in), else on the identification's.
    channels: Option<robotid::verdict::ChannelGains>,
}

impl Judge {
    fn verdict(&self, est: &Estimate) -> Verdict {
        let held_out = match &self.val_rows {
            Some(v) if v.names == est.names => {
                let stats = robotid::validation::residues(v, &(&v.a * &est.values));
                Some((robotid::validation::relative_error(&stats), Measured::Validation))
            }
            _ => self
                .periods_relative
                .map(|r| (r, Measured::HeldOutPeriods))
                .or(self.split_relative.map(|r| (r, Measured::HeldOutTime))),
        };
        self.judged(est, held_out)
    }

    /// The verdict on `est` with the relative error `held_out`.
    fn judged(&self, est: &Estimate, held_out: Option<(f64, Measured)>) -> Verdict {
        robotid::verdict::judge(self.policy, est, &self.id_rows, held_out, self.channels.clone())
    }

    /// Why `verdict` refuses, with what identify found on the way.
    fn refused(&self, verdict: &Verdict, recordings: &[Recording]) -> Option<String> {
        verdict.refused.as_ref().map(|why| {
            let why = format!("{why}. What identify found:{}", causes(&recordings[0].design));
            // A floor from one period's non-excited lines (nothing repeats
            // to take it from) may hold real content or miss noise: said
            // with the refusal. (Not refusing there exported a start-up
            // transient's fit as a model.)
            if self.repeated || verdict.over_floor().is_empty() {
                why
            } else {
                format!("{why}\n(the noise floor comes from the non-excited lines of a single steady period, not from the spread of several: the start of the record may not be steady; record two whole periods or more)")
            }
        })
    }
}

/// The verdict's marks on an estimate's table.
fn marks(verdict: &Verdict) -> Vec<(String, String)> {
    let mut md = vec![(robotid_schemas::metadata::VERDICT.to_string(), verdict.said())];
    if let Some(why) = &verdict.refused {
        md.push((robotid_schemas::metadata::INADEQUATE.to_string(), why.to_string()));
    }
    md
}

impl Judged {
    /// Judged again with the relative error `held_out` (of the estimate
    /// exported), the least squares' table at `table` marked again.
    fn rejudge(&mut self, held_out: (f64, Measured), recordings: &[Recording], table: &Path) -> Result<()> {
        self.verdict = self.judge.judged(&self.outcome.estimate, Some(held_out));
        self.refused = self.judge.refused(&self.verdict, recordings);
        let marks = marks(&self.verdict);
        robotid::tables::write_marked(&self.outcome, table, Some(&|_: &Outcome| marks.clone()))?;
        Ok(())
    }
}

/// The estimate (`parameters.parquet`, marked with its verdict), and why
/// it is refused.
fn estimate(
    request: &Request,
    (staged, paths): (&Path, &Paths),
    recordings: &[Recording],
    id_tables: &[PathBuf],
    val_tables: &[PathBuf],
) -> Result<Judged> {
    let identifying = &recordings[..paths.identifying];
    let id_rows = robotid::tables::load_system(staged, id_tables)?;
    let val_rows = (!val_tables.is_empty())
        .then(|| robotid::tables::load_system(staged, val_tables))
        .transpose()?;
    let channels = val_rows
        .as_ref()
        .and_then(|v| channel_gains(v, Measured::Validation))
        .or_else(|| channel_gains(&id_rows, Measured::InSample));
    let judge = Judge {
        policy: request.policy,
        id_rows,
        val_rows,
        channels,
        // Held-out periods of every identification recording, pooled by
        // their worst; none where one has fewer than two steady periods.
        periods_relative: identifying
            .iter()
            .map(|r| r.design.periodic().and_then(|p| p.held_out_relative))
            .collect::<Option<Vec<f64>>>()
            .map(|r| r.into_iter().fold(0.0, f64::max)),
        split_relative: identifying
            .iter()
            .map(|r| r.design.held_out_split)
            .collect::<Option<Vec<f64>>>()
            .map(|r| r.into_iter().fold(0.0, f64::max)),
        repeated: identifying
            .iter()
            .all(|r| r.design.periodic().is_some_and(|p| p.repeated)),
    };
    let locks = match id_tables.first() {
        Some(t) => robotid::tables::table_locks(&staged.join(t))?,
        None => Default::default(),
    };
    let reducer = robotid::tables::reducer(
        &estimate_config(Covariance::Robust, false),
        Some((&paths.robot, &locks)),
    )?;
    let parts = robotid::tables::parts(&reducer, staged, id_tables)?;
    let outcome = robotid::tables::solve(&reducer, &parts)?;
    let verdict = judge.verdict(&outcome.estimate);
    let marks = marks(&verdict);
    robotid::tables::write_marked(
        &outcome,
        &staged.join("parameters.parquet"),
        Some(&|_: &Outcome| marks.clone()),
    )?;
    let refused = judge.refused(&verdict, recordings);
    // Not periodic: no floor to judge the fit against, which is said.
    let unjudged = outcome
        .estimate
        .adequacy
        .iter()
        .filter(|a| a.noise_floor.is_none())
        .map(|a| format!("{} {:.3e} (N·m)²", a.joint, a.msr))
        .collect();
    Ok(Judged {
        parts,
        outcome,
        judge,
        verdict,
        refused,
        unjudged,
    })
}

/// What identify measured on the way, said with a refusal.
fn causes(design: &Design) -> String {
    design
        .findings
        .iter()
        .filter(|(k, _)| {
            matches!(
                k,
                Found::InverseFilter
                    | Found::EffortDelay
                    | Found::Differentiate
                    | Found::CoulombTransition
                    | Found::Friction
                    | Found::HeldOut
            )
        })
        .map(|(k, v)| format!("\n  {}: {v}", k.key()))
        .collect()
}

/// identify's estimates: least squares, 95 % intervals, the robot file's
/// a-priori sizes; `covariance` robust (auto's where the model is right,
/// robust to the model error real robots have where it dominates).
fn estimate_config(covariance: Covariance, physical: bool) -> EstimateConfig {
    EstimateConfig {
        method: Estimator::Ols,
        confidence: 0.95,
        covariance,
        known: None,
        physical,
        prior_weight: None,
        ..Default::default()
    }
}

/// `parameters` validated on the held-out `tables` (of `held`).
fn validate(staged: &Path, parameters: &str, tables: &[PathBuf], held: &[PathBuf]) -> Result<Validated> {
    robotid::validation::validate(staged, Path::new(parameters), tables).map_err(|source| Error::Validation {
        files: held
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", "),
        source: Box::new(source),
    })
}

/// The physically consistent estimate's table.
const PHYSICAL: &str = "parameters_physical.parquet";

/// The physically consistent estimate, validated, or why there is none.
enum Fit {
    Failed(String),
    Fitted {
        outcome: Box<Outcome>,
        fallback: Option<String>,
        validation: Option<Box<Validated>>,
    },
}

/// The physically consistent estimate (`parameters_physical.parquet`),
/// validated on the held-out tables.
fn physical_fit(
    parts: &[Part],
    (staged, paths): (&Path, &Paths),
    (id_tables, val_tables): (&[PathBuf], &[PathBuf]),
    observer: &dyn Observer,
) -> Result<Fit> {
    let fit = |covariance| -> Result<Outcome> {
        let locks = match id_tables.first() {
            Some(t) => robotid::tables::table_locks(&staged.join(t))?,
            None => Default::default(),
        };
        let reducer = robotid::tables::reducer(&estimate_config(covariance, true), Some((&paths.robot, &locks)))?;
        observer.busy(Some(
            "physical fit: the prior weight on held-out periods, then the bootstrap's semidefinite programs",
        ));
        let outcome = robotid::tables::reduce(&reducer, parts, &staged.join(PHYSICAL), None);
        observer.busy(None);
        Ok(outcome?)
    };
    // The spread across few periods can leave the covariance singular
    // (arm3, 4 periods, 25 parameters): then the residual's is used.
    let (outcome, fallback) = match fit(Covariance::Robust) {
        Ok(o) => (o, None),
        Err(first) => match fit(Covariance::Residual) {
            Ok(o) => (o, Some(chain(&first))),
            Err(e) => return Ok(Fit::Failed(chain(&e))),
        },
    };
    // The model simulators get is the physical one: validated too.
    let validation = match val_tables {
        [] => None,
        tables => Some(Box::new(validate(staged, PHYSICAL, tables, &paths.held)?)),
    };
    Ok(Fit::Fitted {
        outcome: Box::new(outcome),
        fallback,
        validation,
    })
}

/// `p` made absolute against the working folder (it need not exist).
fn absolute_path(p: &Path) -> Result<PathBuf> {
    std::path::absolute(p).map_err(io(p))
}

/// Whether `out` holds anything of the user's (robotid's own hidden
/// bookkeeping aside): identify writes only into an empty folder.
fn holds_anything(out: &Path) -> bool {
    std::fs::read_dir(out)
        .map(|d| {
            d.flatten()
                .any(|e| !e.file_name().to_string_lossy().starts_with(".robotid"))
        })
        .unwrap_or(true)
}

fn io(path: &Path) -> impl Fn(std::io::Error) -> Error + '_ {
    move |source| Error::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// An error with its causes, as one line.
fn chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        s.push_str(&format!(": {c}"));
        cause = c.source();
    }
    s
}
