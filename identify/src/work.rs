//! The workflow behind [`identify`], one step per function.

use std::path::{Path, PathBuf};

use robotid::Observer;
use robotid_schemas::TableKind;

use crate::judge::{estimate, physical_or_why, validate};
use crate::payload::{
    payload_export, payload_frame, payload_of_tables, payload_validated, payload_values, write_payload,
};
use crate::recordings::{design_all, own_delays, run_pipelines, Paths};
use crate::script::Script;
use crate::{Error, Identification, Physical, Recording, Request, Result, Role};

/// The payload of `request`, fitted on the loaded records' tables against
/// the robot the identification tables give, validated on the held-out
/// loaded ones, and written (with the robot file's `model`).
#[allow(clippy::type_complexity)]
fn payload_part(
    request: &Request,
    staged: &Path,
    (id_tables, loaded_tables): (&[PathBuf], &[PathBuf]),
    model: Option<&robotid_stages::dynamics::Model>,
) -> Result<(
    Option<Box<robotid_stages::estimation::payload::PayloadFit>>,
    Option<crate::PayloadValidation>,
)> {
    let (Some(p), Some(model)) = (&request.payload, model) else {
        return Ok((None, None));
    };
    let (fit_tables, held_loaded) = loaded_tables.split_at(p.loaded.len());
    let fit = Box::new(payload_of_tables(p, model, staged, id_tables, fit_tables)?);
    let validation = match held_loaded.is_empty() {
        true => None,
        false => payload_validated(&fit, staged, held_loaded)?,
    };
    write_payload(p, &fit, validation.as_ref(), model, staged)?;
    Ok((Some(fit), validation))
}

/// The report's page of an identification: its tables, the physical
/// estimate where fitted, the payload, the closed loop under the user's
/// controller on the validation records' raw samples, and MuJoCo.
fn report_page(
    request: &Request,
    (staged, paths): (&Path, &Paths),
    (id_tables, val_tables, raw_tables): (&[PathBuf], &[PathBuf], &[PathBuf]),
    fitted: bool,
    payload: bool,
) -> robotid_report::report::Page {
    robotid_report::report::Page {
        parameters: "parameters.parquet".into(),
        excitation: id_tables.to_vec(),
        validation: val_tables.to_vec(),
        physical: fitted.then(|| "parameters_physical.parquet".into()),
        robot: Some(paths.robot_file.clone()),
        rollout: true,
        payload: payload.then(|| "payload.parquet".into()),
        closed_loop: paths.controller.clone().map(|c| (c, raw_tables.to_vec())),
        mujoco: request
            .mujoco
            .clone()
            .filter(|_| fitted)
            .map(|python| ("identified.xml".into(), python)),
        out: "report.html".into(),
        within: staged.to_path_buf(),
    }
}

/// Identifies the robot of `request` (see the crate's documentation),
/// `observer` told of each pipeline's steps and of the physical fit. A
/// refused fit is an [`Identification`] whose `refused` says why, its
/// files written and marked; errors are for what could not be judged.
pub fn identify(request: &Request, observer: &dyn Observer) -> Result<Identification> {
    request.payload.as_ref().map(payload_values).transpose()?;
    let paths = Paths::of(request)?;
    let payload_model = payload_model(request, &paths)?;
    let staging = staging_for(&paths)?;
    let (recordings, locked) = design_all(request, &paths)?;
    // Every output is written into the staging folder and named relative
    // to it: the files that name each other (the report, the exports, the
    // estimate's provenance) hold paths that stay right when the folder
    // appears as `out`, and when it is moved.
    let staged = staging.staged_out();
    let mut script = Script::new(paths.robot_file.path());
    let runs = run_pipelines(
        (request, &paths.robot_file),
        (staged, &paths.out),
        &recordings,
        &mut script,
        observer,
    )?;
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
    let (payload, payload_validation) =
        payload_part(request, staged, (id_tables, loaded_tables), payload_model.as_deref())?;
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
    let simulated = simulated_and_drawn(
        request,
        (staged, &paths),
        &recordings,
        (id_tables, val_tables),
        (fitted, payload.is_some()),
        &mut script,
    )?;
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
        closed_loop: simulated.closed_loop,
        mujoco: simulated.mujoco,
        physical_rollouts: simulated.physical,
        payload,
        payload_validation,
    })
}

/// Everything is written into a staging folder and appears at once when
/// identify ends, refused or not (robotid::output): a kill or a failure
/// leaves the folder as it was. One identify or run at a time holds it.
fn staging_for(paths: &Paths) -> Result<robotid::output::Staging> {
    let staging = robotid::output::prepare(&absolute_path(&paths.out)?, None, &paths.all)?;
    if holds_anything(&paths.out) {
        return Err(Error::Request(format!(
            "{}: the output folder is not empty; give another, or remove it",
            paths.out.display()
        )));
    }
    Ok(staging)
}

/// The robot file as the payload's table and exports see it, its link
/// checked before anything runs (None: no payload asked for).
fn payload_model(request: &Request, paths: &Paths) -> Result<Option<std::sync::Arc<robotid_stages::dynamics::Model>>> {
    let Some(p) = &request.payload else {
        return Ok(None);
    };
    let model = paths.robot_file.model(&Default::default())?;
    payload_frame(&model, &p.link)?;
    Ok(Some(model))
}

/// Every simulation the report shows, run here and held on the
/// identification (the page only draws them), each run and failure named
/// where its files will be, not where they were read; the page drawn and
/// the script told.
fn simulated_and_drawn(
    request: &Request,
    (staged, paths): (&Path, &Paths),
    recordings: &[Recording],
    (id_tables, val_tables): (&[PathBuf], &[PathBuf]),
    (fitted, payload): (bool, bool),
    script: &mut Script,
) -> Result<robotid::simulation::Simulated> {
    let raw_tables: Vec<PathBuf> = recordings
        .iter()
        .filter(|r| r.role == Role::Validation)
        .map(|r| recording_table(r, TableKind::RawSamples))
        .collect();
    let page = report_page(
        request,
        (staged, paths),
        (id_tables, val_tables, &raw_tables),
        fitted,
        payload,
    );
    let read = page.read()?;
    let simulated = robotid::simulation::simulate(&page.asked()).relocated(staged, &paths.out);
    robotid_report::report::render(&page, &read, &simulated)?;
    script.report(
        (id_tables, val_tables),
        fitted,
        request.mujoco.is_some(),
        payload,
        paths.controller.as_deref().map(|c| (c, raw_tables.as_slice())),
    );
    Ok(simulated)
}

/// A recording's regressor table, relative to the staging folder.
pub(crate) fn regressor_table(r: &Recording) -> PathBuf {
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

/// `p` made absolute against the working folder (it need not exist).
pub(crate) fn absolute_path(p: &Path) -> Result<PathBuf> {
    std::path::absolute(p).map_err(io(p))
}

/// Whether `out` holds anything of the user's (robotid's own hidden
/// bookkeeping aside): identify writes only into an empty folder.
pub(crate) fn holds_anything(out: &Path) -> bool {
    std::fs::read_dir(out)
        .map(|d| {
            d.flatten()
                .any(|e| !e.file_name().to_string_lossy().starts_with(".robotid"))
        })
        .unwrap_or(true)
}

pub(crate) fn io(path: &Path) -> impl Fn(std::io::Error) -> Error + '_ {
    move |source| Error::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// An error with its causes, as one line.
pub(crate) fn chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        s.push_str(&format!(": {c}"));
        cause = c.source();
    }
    s
}
