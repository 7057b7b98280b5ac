//! identify's payload: the declared values checked, the payload fitted
//! against the robot (its own records, or a parameters table), bounded,
//! validated and written into the exports.

use std::path::{Path, PathBuf};

use crate::design::{absolute, design_with};
use robotid::Observer;
use robotid_stages::dynamics::Robot;
use robotid_stages::estimation::payload::{
    identify_payload, NominalGains, PayloadFit, PayloadOptions, Robot as PayloadRobot,
};
use robotid_stages::estimation::Ellipsoid;

use crate::recordings::run_pipelines;
use crate::script::Script;
use crate::work::{absolute_path, holds_anything, io, regressor_table};
use crate::{Error, PayloadRequest, PayloadValidation, Recording, Request, Result, Role};

/// A payload's declared values checked before any work: a positive
/// finite mass, a finite centre and positive finite semi-axes.
pub(crate) fn payload_values(p: &PayloadRequest) -> Result<()> {
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

/// The robot and payload identified, predicting the held-out loaded
/// records' torques (None with a known mass: the gains' model predicts
/// efforts, not these columns).
pub(crate) fn payload_validated(
    fit: &PayloadFit,
    staged: &Path,
    held: &[PathBuf],
) -> Result<Option<PayloadValidation>> {
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
pub(crate) fn write_payload(
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

/// The loaded records' designs: each found in its log (the first one's
/// periods and filter shared), with the parameters table's regressor model
/// (the payload's columns added) at the record's own band.
fn loaded_recordings(
    loaded: &[PathBuf],
    robot: &std::sync::Arc<Robot>,
    regressor: &robotid_stages::stage::regressor::RegressorConfig,
) -> Result<Vec<Recording>> {
    let names = robotid::run::recording_names(loaded);
    let mut recordings: Vec<Recording> = Vec::new();
    for (log, name) in loaded.iter().zip(names) {
        // The robot file lacks the payload: the first record's torques
        // are not held against its own.
        let mut design = match recordings.first() {
            Some(r) => design_with(log, robot, Some(&r.design), None, None)?,
            None => crate::design::design_loaded(log, robot)?,
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
        design.text = crate::design::file_text(&design.plan)?;
        recordings.push(Recording {
            role: Role::Loaded,
            name,
            log: log.clone(),
            design,
        });
    }
    Ok(recordings)
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
    let robot = std::sync::Arc::new(Robot::read(&absolute(robot)?)?);
    let loaded = request.loaded.iter().map(|p| absolute(p)).collect::<Result<Vec<_>>>()?;
    if loaded.is_empty() {
        return Err(Error::Request("--payload-on: no recording with the payload".into()));
    }
    payload_values(request)?;
    let model = robot.model(&Default::default())?;
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
    let recordings = loaded_recordings(&loaded, &robot, &regressor)?;
    let staged = staging.staged_out().to_path_buf();
    let runner = Request::new(Vec::new(), robot.path().to_path_buf());
    run_pipelines(
        (&runner, &robot),
        (&staged, out),
        &recordings,
        &mut Script::new(robot.path()),
        observer,
    )?;
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

/// The identified URDF and MJCF with the payload on
/// (`identified_payload.urdf`, `.xml`), or why not
/// (`identified_payload.txt`).
pub(crate) fn payload_export(
    link: &str,
    fit: &PayloadFit,
    model: &robotid_stages::dynamics::Model,
    staged: &Path,
) -> Result<()> {
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
    payload_of_tables(request, &model, within, unloaded, loaded)
}

/// [`payload_from_tables`] with the robot's model loaded.
pub(crate) fn payload_of_tables(
    request: &PayloadRequest,
    model: &robotid_stages::dynamics::Model,
    within: &Path,
    unloaded: &[PathBuf],
    loaded: &[PathBuf],
) -> Result<PayloadFit> {
    let unloaded = robotid::tables::load_system(within, unloaded)?;
    let loaded = robotid::tables::load_system(within, loaded)?;
    let gains = nominal_gains(model, &loaded);
    bounded_payload(request, model, |bound| {
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
