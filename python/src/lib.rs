//! `robotid._robotid`: the native half of the Python package, thin over
//! the `Pipeline` API. Tables cross as Arrow through the C data interface
//! (no copy); the GIL is released while Rust works. `robotid/__init__.py`
//! is the documented face.

use std::path::{Path, PathBuf};

use arrow::array::RecordBatch;
use arrow::pyarrow::{FromPyArrow, IntoPyArrow, Table, ToPyArrow};
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList};
use robotid::{Built, Pipeline as Plan};
use robotid_stages::stage::read::Log;

pyo3::create_exception!(
    _robotid,
    RobotidError,
    PyException,
    "A robotid error. `file`, `channel`, `sample` and `stage` say where, when known (else None)."
);

/// Where an error sits, as the CLI names it.
#[derive(Default)]
struct Place {
    file: Option<String>,
    channel: Option<String>,
    sample: Option<usize>,
    stage: Option<String>,
}

fn place_of_stage_error(e: &robotid_stages::Error, place: &mut Place) {
    use robotid_stages::Error as E;
    match e {
        E::Stage {
            stage,
            source_name,
            cause,
        } => {
            place.stage = Some(stage.to_string());
            place.file.get_or_insert_with(|| source_name.clone());
            place_of_stage_error(cause, place);
        }
        E::Data {
            source_name,
            channel,
            sample,
            ..
        } => {
            place.file = Some(source_name.clone());
            place.channel = Some(channel.clone());
            place.sample = *sample;
        }
        E::Robot { path, .. }
        | E::Config { path, .. }
        | E::Io { path, .. }
        | E::Format { path, .. }
        | E::Decode { path, .. } => {
            place.file = Some(path.display().to_string());
        }
        _ => {}
    }
}

/// `e` as a Python exception.
fn py_error(e: robotid::Error) -> PyErr {
    let mut place = Place::default();
    match &e {
        robotid::Error::Stage(s) => place_of_stage_error(s, &mut place),
        robotid::Error::Io { path, .. } => place.file = Some(path.display().to_string()),
        robotid::Error::Problems(p) => place.file = p.0.first().map(|x| x.file.display().to_string()),
        _ => {}
    }
    let err = RobotidError::new_err(e.to_string());
    Python::attach(|py| {
        let value = err.value(py);
        // Setting attributes on a fresh exception cannot fail.
        let _ = value.setattr("file", place.file);
        let _ = value.setattr("channel", place.channel);
        let _ = value.setattr("sample", place.sample);
        let _ = value.setattr("stage", place.stage);
    });
    err
}

/// A recording given as a path, or as bytes read where they are (named
/// `<bytes NAME>` in errors; `name`'s extension says the format, guessed
/// from the bytes when it has none).
enum Recording {
    Path(PathBuf),
    Bytes {
        name: PathBuf,
        stem: String,
        format: String,
        bytes: bytes::Bytes,
    },
}

impl Recording {
    fn new(obj: &Bound<'_, PyAny>, name: Option<&str>) -> PyResult<Recording> {
        if let Ok(b) = obj.cast::<PyBytes>() {
            let data = b.as_bytes();
            let guessed = if data.starts_with(b"\x89MCAP") {
                "mcap"
            } else if data.starts_with(b"PAR1") {
                "parquet"
            } else {
                "csv"
            };
            let given = name.map(Path::new);
            let format = given
                .and_then(|n| n.extension())
                .map_or(guessed.to_string(), |e| e.to_string_lossy().into_owned());
            let stem = given
                .and_then(|n| n.file_stem())
                .map_or("recording".to_string(), |s| s.to_string_lossy().into_owned());
            return Ok(Recording::Bytes {
                name: PathBuf::from(format!("<bytes {stem}>")),
                stem,
                format,
                bytes: bytes::Bytes::copy_from_slice(data),
            });
        }
        let path: PathBuf = obj.extract()?;
        Ok(Recording::Path(path))
    }

    fn log(&self) -> Log<'_> {
        match self {
            Recording::Path(p) => Log::File(p),
            Recording::Bytes {
                name, format, bytes, ..
            } => Log::Bytes { name, format, bytes },
        }
    }

    fn name(&self, given: Option<&str>) -> String {
        match self {
            Recording::Bytes { stem, .. } => stem.clone(),
            Recording::Path(p) => given
                .map(|n| {
                    Path::new(n)
                        .file_stem()
                        .map_or(n.to_string(), |s| s.to_string_lossy().into_owned())
                })
                .unwrap_or_else(|| {
                    p.file_stem()
                        .map(|s| s.to_string_lossy().into_owned())
                        .unwrap_or_default()
                }),
        }
    }
}

/// One batch or a list of batches (pyarrow RecordBatch or Table).
fn batches(obj: &Bound<'_, PyAny>) -> PyResult<Vec<RecordBatch>> {
    let one = |o: &Bound<'_, PyAny>| -> PyResult<Vec<RecordBatch>> {
        if let Ok(b) = RecordBatch::from_pyarrow_bound(o) {
            return Ok(vec![b]);
        }
        Ok(Table::from_pyarrow_bound(o)?.into_inner().0)
    };
    if let Ok(list) = obj.cast::<PyList>() {
        let mut out = Vec::new();
        for item in list.iter() {
            out.extend(one(&item)?);
        }
        return Ok(out);
    }
    one(obj)
}

fn table<'py>(py: Python<'py>, batch: RecordBatch) -> PyResult<Bound<'py, PyAny>> {
    let schema = batch.schema();
    Table::try_new(vec![batch], schema)
        .map_err(|e| RobotidError::new_err(e.to_string()))?
        .into_pyarrow(py)
}

/// A pipeline, built: robot loaded, recordings found, stages ready.
#[pyclass(module = "robotid._robotid", frozen)]
struct Pipeline {
    built: Built,
}

#[pymethods]
impl Pipeline {
    /// A pipeline from its TOML text; relative paths in it resolve against
    /// `base_dir`.
    #[staticmethod]
    fn from_toml(py: Python<'_>, text: &str, base_dir: PathBuf) -> PyResult<Pipeline> {
        let file = base_dir.join("pipeline.toml");
        let text = text.to_string();
        py.detach(move || {
            let built = Plan::from_toml(&text, file).and_then(|p| p.build()).map_err(py_error)?;
            Ok(Pipeline { built })
        })
    }

    /// A pipeline from its file.
    #[staticmethod]
    fn from_path(py: Python<'_>, path: PathBuf) -> PyResult<Pipeline> {
        py.detach(move || {
            let built = Plan::from_path(path).and_then(|p| p.build()).map_err(py_error)?;
            Ok(Pipeline { built })
        })
    }

    /// The recordings the pipeline's `[source]` names.
    #[getter]
    fn recordings(&self) -> Vec<PathBuf> {
        self.built.logs.clone()
    }

    /// SHA-256 of the pipeline text (in every table's metadata).
    #[getter]
    fn config_sha256(&self) -> String {
        self.built.plan.hash.clone()
    }

    /// The pipeline file's path.
    #[getter]
    fn file(&self) -> PathBuf {
        self.built.plan.file.clone()
    }

    /// Every table the pipeline writes for one recording, by kind.
    #[pyo3(signature = (recording, name=None))]
    fn run_recording<'py>(
        &self,
        py: Python<'py>,
        recording: &Bound<'py, PyAny>,
        name: Option<&str>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let rec = Recording::new(recording, name)?;
        let name = rec.name(name);
        let tables = py
            .detach(|| {
                let mut chain = self.built.run_log_for_tables(rec.log(), &name, |_| {})?;
                self.built.take_tables(&mut chain)
            })
            .map_err(|e| py_error(robotid::Error::Stage(e)))?;
        let out = PyDict::new(py);
        for (kind, batch) in tables {
            out.set_item(kind.name(), table(py, batch)?)?;
        }
        Ok(out)
    }

    /// One recording's row of sufficient statistics (needs an `estimate`
    /// stage).
    #[pyo3(signature = (recording, name=None))]
    fn summarize<'py>(
        &self,
        py: Python<'py>,
        recording: &Bound<'py, PyAny>,
        name: Option<&str>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let rec = Recording::new(recording, name)?;
        let name = rec.name(name);
        let batch = py.detach(|| self.built.summarize(rec.log(), &name)).map_err(py_error)?;
        batch.to_pyarrow(py)
    }

    /// Solves summaries made by this pipeline (merged in the order given):
    /// the `parameters` table.
    fn solve<'py>(&self, py: Python<'py>, summaries: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        let input = batches(summaries)?;
        let est = py.detach(|| self.built.solve(&input)).map_err(py_error)?;
        table(py, est.table)
    }

    fn __repr__(&self) -> String {
        format!(
            "Pipeline({:?}, {} recording(s), config {})",
            self.built.plan.file.display().to_string(),
            self.built.logs.len(),
            &self.built.plan.hash[..12.min(self.built.plan.hash.len())]
        )
    }
}

/// `e` of identify as a Python exception.
fn py_identify_error(e: robotid_identify::Error) -> PyErr {
    match e {
        robotid_identify::Error::Robotid(e) => py_error(*e),
        robotid_identify::Error::Stage(e) => py_error(robotid::Error::Stage(e)),
        e => {
            let err = RobotidError::new_err(e.to_string());
            Python::attach(|py| {
                let value = err.value(py);
                for key in ["file", "channel", "sample", "stage"] {
                    let _ = value.setattr(key, py.None());
                }
            });
            err
        }
    }
}

/// Per joint, a residue over its noise floor (None: no floor).
type JointRatios = Vec<(String, Option<f64>)>;

/// What `identify` found and wrote (`robotid identify`'s output folder,
/// typed): `identified` False with `refused` saying why when the fit is
/// refused (the folder then holds the estimate and report marked so).
#[pyclass(frozen, get_all, module = "robotid")]
struct Identification {
    /// The output folder.
    out: PathBuf,
    identified: bool,
    refused: Option<String>,
    /// The verdict, as the parameters table's metadata says it.
    verdict: String,
    /// The relative error that decided, and where it was measured.
    relative_error: f64,
    measured: String,
    /// Per recording: role, name, log, periodic, findings, pipeline.
    recordings: Py<PyList>,
    /// `parameters.parquet` (least squares) as written.
    parameters: Py<PyAny>,
    /// `parameters_physical.parquet` when the physical fit was made.
    physical: Option<Py<PyAny>>,
    /// The exports written (URDF, MJCF, sidecar).
    exports: Vec<PathBuf>,
    /// `payload.parquet` when a payload was identified (mass, centre of
    /// mass, inertia at it, the drives' gains; values, std, intervals).
    payload: Option<Py<PyAny>>,
    /// The payload's model on the held-out loaded records: its relative
    /// error and each joint's residue over its floor (None: no floor).
    payload_validation: Option<(f64, JointRatios)>,
    /// With a `controller`: the closed-loop runs on the validation
    /// records, as `robotid.closed_loop` returns them (recording, model,
    /// joint, position RMS error).
    closed_loop: Option<Py<PyAny>>,
    /// The rollouts on each validation record (else the identification
    /// records) in robotid's windows: per record, model (`estimate`,
    /// `physical`, `robot_file`, and `mujoco` with `mujoco`: the export in
    /// MuJoCo) and joint, the position and velocity RMS error.
    rollouts: Option<Py<PyAny>>,
    /// What `robotid identify` prints as `warning:` (a closed loop or a
    /// MuJoCo run that could not be made among them), the same words.
    warnings: Vec<String>,
}

#[pymethods]
impl Identification {
    fn __repr__(&self) -> String {
        format!(
            "Identification({:?}, {})",
            self.out.display().to_string(),
            self.refused
                .as_ref()
                .map_or("identified".to_string(), |_| "refused".to_string())
        )
    }
}

/// A parquet table the identification wrote, as pyarrow.
fn written<'py>(py: Python<'py>, path: &Path) -> PyResult<Py<PyAny>> {
    let batch = robotid_stages::formats::parquet::read_parquet(path).map_err(|e| py_error(robotid::Error::Stage(e)))?;
    Ok(table(py, batch)?.unbind())
}

/// As the command line: with a payload, `recordings` carry it and the
/// robot is identified from `unloaded`.
#[allow(clippy::type_complexity)]
fn roles(
    (recordings, unloaded): (Vec<PathBuf>, Vec<PathBuf>),
    payload_on: Option<String>,
    known_mass: Option<f64>,
    bound: Option<([f64; 3], [f64; 3])>,
    validate: Vec<PathBuf>,
) -> PyResult<(Vec<PathBuf>, Option<robotid_identify::PayloadRequest>)> {
    let Some(link) = payload_on else {
        return Ok((recordings, None));
    };
    if unloaded.is_empty() {
        return Err(pyo3::exceptions::PyValueError::new_err(
            "payload_on: give the recordings without the payload as `unloaded`",
        ));
    }
    let p = robotid_identify::PayloadRequest {
        loaded: recordings,
        link,
        known_mass,
        bound,
        validate,
    };
    Ok((unloaded, Some(p)))
}

/// Each recording's role, name, log, design findings and pipeline, as
/// Python dictionaries.
fn recordings_listed(py: Python<'_>, id: &robotid_identify::Identification) -> PyResult<Py<PyList>> {
    let listed = PyList::empty(py);
    for r in &id.recordings {
        let d = PyDict::new(py);
        d.set_item("role", r.role.name())?;
        d.set_item("name", &r.name)?;
        d.set_item("log", &r.log)?;
        d.set_item("periodic", r.design.periodic().is_some())?;
        let found = PyDict::new(py);
        for (k, v) in &r.design.findings {
            found.set_item(k.key(), v)?;
        }
        d.set_item("findings", found)?;
        d.set_item("pipeline", &r.design.text)?;
        listed.append(d)?;
    }
    Ok(listed.unbind())
}

/// From recordings and a robot file to a validated model, as `robotid
/// identify` (the same files, byte for byte).
#[pyfunction]
#[pyo3(signature = (recordings, robot, validate=Vec::new(), out=None, tolerance=100.0 * robotid::verdict::DEFAULT_TOLERANCE, strict=false, accept_inadequate=false, torque_per_amp=Vec::new(), threads=None, mjcf=None, payload_on=None, unloaded=Vec::new(), known_payload_mass=None, payload_ellipsoid=None, validate_loaded=Vec::new(), controller=None, mujoco=false, read=None))]
#[allow(clippy::too_many_arguments)]
fn identify(
    py: Python<'_>,
    recordings: Vec<PathBuf>,
    robot: PathBuf,
    validate: Vec<PathBuf>,
    out: Option<PathBuf>,
    tolerance: f64,
    strict: bool,
    accept_inadequate: bool,
    torque_per_amp: Vec<f64>,
    threads: Option<usize>,
    mjcf: Option<PathBuf>,
    payload_on: Option<String>,
    unloaded: Vec<PathBuf>,
    known_payload_mass: Option<f64>,
    payload_ellipsoid: Option<([f64; 3], [f64; 3])>,
    validate_loaded: Vec<PathBuf>,
    controller: Option<PathBuf>,
    mujoco: bool,
    read: Option<PathBuf>,
) -> PyResult<Identification> {
    use robotid_identify::Request;
    let (recordings, payload) = roles(
        (recordings, unloaded),
        payload_on,
        known_payload_mass,
        payload_ellipsoid,
        validate_loaded,
    )?;
    let request = Request {
        validate,
        out,
        torque_per_amp,
        // A percent, as the command line's `--tolerance`.
        policy: robotid::verdict::Policy {
            tolerance: tolerance / 100.0,
            strict,
        },
        accept_inadequate,
        threads,
        mjcf,
        payload,
        controller,
        read: read
            .as_deref()
            .map(robotid_stages::stage::read::ReadConfig::from_file)
            .transpose()
            .map_err(|e| py_error(robotid::Error::Stage(e)))?,
        // MuJoCo run by this interpreter, which has it when the caller does.
        mujoco: match mujoco {
            true => Some(py.import("sys")?.getattr("executable")?.extract::<PathBuf>()?),
            false => None,
        },
        ..Request::new(recordings, robot)
    };
    let id = py
        .detach(|| robotid_identify::identify_quietly(&request))
        .map_err(py_identify_error)?;
    identification(py, id, accept_inadequate)
}

/// What Python returns of an identification: its verdict, the tables it
/// wrote as pyarrow, its exports, rollouts and warnings.
fn identification(
    py: Python<'_>,
    id: robotid_identify::Identification,
    accept_inadequate: bool,
) -> PyResult<Identification> {
    use robotid_identify::Physical;
    let listed = recordings_listed(py, &id)?;
    let (physical, exports) = match &id.physical {
        Physical::Fitted { export, .. } => (
            Some(written(py, &id.path("parameters_physical.parquet"))?),
            export.files.iter().map(|f| id.path(f)).collect(),
        ),
        _ => (None, Vec::new()),
    };
    // A payload the records leave undetermined refuses as the command
    // line's exit code 3 does, unless accepted.
    let payload_refused = id
        .payload
        .as_deref()
        .filter(|_| !accept_inadequate)
        .and_then(|fit| robotid_identify::payload_refused(fit, &id.path("payload.parquet")));
    Ok(Identification {
        identified: !id.is_refused() && payload_refused.is_none(),
        refused: id.refused.clone().or(payload_refused),
        verdict: id.verdict.said(),
        relative_error: id.verdict.relative.0,
        measured: id.verdict.relative.1.said().to_string(),
        recordings: listed,
        parameters: written(py, &id.path("parameters.parquet"))?,
        physical,
        exports,
        payload_validation: id
            .payload_validation
            .as_ref()
            .map(|v| (v.relative_error, v.joints.clone())),
        payload: match id.payload {
            Some(_) => Some(written(py, &id.path("payload.parquet"))?),
            None => None,
        },
        closed_loop: match &id.closed_loop {
            Some(Ok(runs)) => {
                Some(table(py, robotid::validation::closed_loop_table(runs).map_err(py_error)?)?.unbind())
            }
            Some(Err(_)) | None => None,
        },
        rollouts: rollouts(py, &id)?,
        warnings: id.warnings(),
        out: id.out,
    })
}

/// identify's rollouts as a pyarrow table (`report::rollout_summary`;
/// a record where MuJoCo could not run is among the warnings).
fn rollouts(py: Python<'_>, id: &robotid_identify::Identification) -> PyResult<Option<Py<PyAny>>> {
    let Some(Ok(rolled)) = &id.rollouts else {
        return Ok(None);
    };
    let batch = robotid_report::report::rollout_summary(
        rolled,
        id.physical_rollouts.as_ref().and_then(|p| p.as_deref().ok()),
        id.mujoco.as_deref(),
    )
    .map_err(py_error)?;
    Ok(Some(table(py, batch)?.unbind()))
}

/// The payload on `payload_on` from `loaded` (records with it) against a
/// robot already identified (its `parameters` table, whose regressor
/// model the loaded records are run with, its covariance carried), as
/// `robotid identify LOADED… --payload-on LINK --parameters P`: the same
/// `payload.parquet` written into `out`, returned as a pyarrow table. A
/// payload the records leave undetermined at its size raises
/// `RobotidError` naming the values (the table written all the same)
/// unless `accept_inadequate`.
#[pyfunction]
#[pyo3(signature = (loaded, robot, parameters, payload_on, out, payload_ellipsoid=None, accept_inadequate=false))]
#[allow(clippy::too_many_arguments)]
fn payload<'py>(
    py: Python<'py>,
    loaded: Vec<PathBuf>,
    robot: PathBuf,
    parameters: PathBuf,
    payload_on: String,
    out: PathBuf,
    payload_ellipsoid: Option<([f64; 3], [f64; 3])>,
    accept_inadequate: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let request = robotid_identify::PayloadRequest {
        loaded,
        link: payload_on,
        known_mass: None,
        bound: payload_ellipsoid,
        validate: Vec::new(),
    };
    let fit = py
        .detach(|| robotid_identify::payload_against_parameters(&request, &robot, &parameters, &out, &robotid::Quiet))
        .map_err(py_identify_error)?;
    let table = out.join("payload.parquet");
    if let Some(why) = robotid_identify::payload_refused(&fit, &table).filter(|_| !accept_inadequate) {
        return Err(RobotidError::new_err(why));
    }
    Ok(written(py, &out.join("payload.parquet"))?.into_bound(py))
}

/// The parameters table `parameters` of `robot` rolled out on the
/// kinematics table beside each regressor table of `regressors`, as
/// `robotid validate --rollout`: per record, model (`estimate`,
/// `robot_file`), window and joint, the simulated angle's and velocity's
/// RMS error against the measured (rad, rad/s), as a pyarrow table.
#[pyfunction]
#[pyo3(signature = (parameters, robot, regressors, window_s=None))]
fn rollout<'py>(
    py: Python<'py>,
    parameters: PathBuf,
    robot: PathBuf,
    regressors: Vec<PathBuf>,
    window_s: Option<f64>,
) -> PyResult<Bound<'py, PyAny>> {
    let batch = py
        .detach(|| {
            let robot = robotid_stages::dynamics::Robot::read(&robot)?;
            let rolled = robotid::validation::rollouts(Path::new(""), &parameters, &robot, &regressors, window_s)?;
            robotid::validation::rollout_table(&rolled)
        })
        .map_err(py_error)?;
    table(py, batch)
}

/// The parameters table `parameters` of `robot` simulated in closed loop
/// on each raw recording of `recordings` under the controller declared in
/// `controller` (a TOML file with a `[controller]` table of per-joint kp,
/// kd, ki), tracking the recorded reference, as `robotid validate
/// --closed-loop`: per recording, model (`estimate`, `robot_file`) and
/// joint, the simulated angle's RMS error against the measured (rad), as a
/// pyarrow table.
#[pyfunction]
fn closed_loop<'py>(
    py: Python<'py>,
    parameters: PathBuf,
    robot: PathBuf,
    recordings: Vec<PathBuf>,
    controller: PathBuf,
) -> PyResult<Bound<'py, PyAny>> {
    let batch = py
        .detach(|| {
            let robot = robotid_stages::dynamics::Robot::read(&robot)?;
            let runs = robotid::validation::closed_loop_rollouts(&parameters, &robot, &recordings, &controller)?;
            robotid::validation::closed_loop_table(&runs)
        })
        .map_err(py_error)?;
    table(py, batch)
}

/// Parameter sets drawn from a physically consistent estimate's
/// distribution for domain randomization, as `robotid sample`: written
/// into `out` (`samples.parquet`, `randomization.json` and `.yaml`, and a
/// model per draw for each of `formats`, "urdf" and "mjcf", the user's
/// own `mjcf` patched when given); the samples table (one row per draw and
/// quantity) returned as a pyarrow table.
#[pyfunction]
#[pyo3(signature = (parameters, robot, draws, out, seed=0, formats=Vec::new(), mjcf=None))]
#[allow(clippy::too_many_arguments)]
fn sample<'py>(
    py: Python<'py>,
    parameters: PathBuf,
    robot: PathBuf,
    draws: usize,
    out: PathBuf,
    seed: u64,
    formats: Vec<String>,
    mjcf: Option<PathBuf>,
) -> PyResult<Bound<'py, PyAny>> {
    use robotid_report::export::Format;
    let formats = formats
        .iter()
        .map(|f| match f.as_str() {
            "urdf" => Ok(Format::Urdf),
            "mjcf" => Ok(Format::Mjcf),
            other => Err(RobotidError::new_err(format!(
                "formats: `{other}` is neither \"urdf\" nor \"mjcf\""
            ))),
        })
        .collect::<PyResult<Vec<_>>>()?;
    let request = robotid_report::sample::Sample {
        robot,
        parameters,
        draws,
        seed,
        formats,
        out: out.clone(),
        mjcf,
    };
    py.detach(|| robotid_report::sample::sample(&request))
        .map_err(|e| RobotidError::new_err(e.to_string()))?;
    Ok(written(py, &out.join("samples.parquet"))?.into_bound(py))
}

/// Summaries merged, in order, into one row.
#[pyfunction]
fn merge<'py>(py: Python<'py>, summaries: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    let input = batches(summaries)?;
    let merged = py.detach(|| robotid::summaries::merge(&input)).map_err(py_error)?;
    merged.to_pyarrow(py)
}

#[pymodule]
fn _robotid(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Pipeline>()?;
    m.add_function(wrap_pyfunction!(merge, m)?)?;
    m.add_function(wrap_pyfunction!(identify, m)?)?;
    m.add_function(wrap_pyfunction!(payload, m)?)?;
    m.add_function(wrap_pyfunction!(rollout, m)?)?;
    m.add_function(wrap_pyfunction!(sample, m)?)?;
    m.add_function(wrap_pyfunction!(closed_loop, m)?)?;
    m.add_class::<Identification>()?;
    m.add("RobotidError", m.py().get_type::<RobotidError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
