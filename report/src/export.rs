//! Exports for simulators: physically consistent standard parameters
//! closest to the a-priori model that reproduce the identified base
//! parameters, written as URDF, MJCF and a sidecar with everything neither
//! can hold. Everything is made before anything is written.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow::array::{Array, ArrayRef, BooleanArray, Float64Array, RecordBatch, StringArray};
use arrow::datatypes::{DataType, Field, Schema};
use robotid_schemas::metadata;
use robotid_stages::dynamics::{
    parameter_names, parameter_unit, standard_parameters, with_standard_parameters, Model, Robot,
};
use robotid_stages::estimation::{physically_consistent, LinkBound};
use robotid_stages::export::{to_mjcf, to_urdf, MjcfPatch, Patched, UrdfPatch};
use robotid_stages::formats::parquet::{read_parquet, write_parquet};
use robotid_stages::formats::{sha256_hex, write_atomic};

/// What to write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// `<stem>.urdf`: the robot file's own URDF with each moving link's
    /// `<inertial>` and each joint's `<dynamics damping friction>`
    /// replaced, every other byte kept (a robot file in robotid's TOML: a
    /// URDF made from the model).
    Urdf,
    /// `<stem>.xml`: the user's MJCF ([`Export::mjcf`]) with each moving
    /// body's `<inertial>` and each joint's `armature`, `damping` and
    /// `frictionloss` written, every other byte kept; without one, MJCF made
    /// from the model (bodies, inertials, the robot file's shapes as geoms).
    Mjcf,
    /// `<stem>.sidecar.json` and `<stem>.sidecar.parquet`: every value with
    /// unit, standard deviation and interval, the covariance, what the
    /// formats cannot hold, the provenance.
    Sidecar,
}

/// An export asked for.
#[derive(Clone, Debug)]
pub struct Export {
    /// The robot file the parameters were identified for: its inertials
    /// are the a-priori model the exported standard parameters stay close
    /// to. Read by the caller (identify has read it already).
    pub robot: Arc<Robot>,
    /// The identified parameters (physically consistent).
    pub parameters: PathBuf,
    pub formats: Vec<Format>,
    /// Output path without extension (or with the one format's).
    pub out: PathBuf,
    /// The pull towards the a-priori inertials; by default the estimate's.
    pub prior_weight: Option<f64>,
    /// Write bodies outside their bounds all the same (said in the sidecar).
    pub force: bool,
    /// The folder `parameters` is read and `out` written in, both named as
    /// given (`""`: the working folder).
    pub within: PathBuf,
    /// The user's own MJCF of the robot, patched for [`Format::Mjcf`].
    pub mjcf: Option<PathBuf>,
}

/// What an export did.
#[derive(Debug)]
pub struct Exported {
    /// Where the consistent standard parameters came from.
    pub how: String,
    /// Bodies far from the robot file's (written all the same).
    pub warnings: Vec<String>,
    pub files: Vec<PathBuf>,
}

/// Why nothing was exported.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    #[error("--prior-weight: the prior weight must be a positive number, not {0}")]
    PriorWeight(f64),
    #[error("export needs the chain model's base parameters (the decoupled model has no standard parameters)")]
    Decoupled,
    #[error("{} is not a physically consistent estimate: a least-squares estimate can hold links with negative mass or inertia, which no simulator accepts. Estimate with `physical = true` in the pipeline's `estimate` stage, or `robotid estimate REGRESSOR… --robot {} --physical`, and export that", parameters.display(), robot.display())]
    NotPhysical { parameters: PathBuf, robot: PathBuf },
    #[error("the link of `{joint}` has mass {mass} in the consistent fit: no simulator moves a massless body; give the robot file a mass for it")]
    Massless { joint: String, mass: f64 },
    #[error("{}: the identified bodies are not physical: {problem}; no model is written", parameters.display())]
    Impossible { parameters: PathBuf, problem: String },
    #[error("{}: bodies no robot has, so no model is written: {}. These parameters were fitted without the bounds (an older robotid, or another tool), or the robot file is not theirs; estimate again with `physical = true`, or give --force to write them anyway", parameters.display(), links.join("; "))]
    OutOfBounds { parameters: PathBuf, links: Vec<String> },
    #[error("{}: the parameters table has no column `{column}`", parameters.display())]
    Column { parameters: PathBuf, column: String },
    #[error("{0} draw(s) mapped to bodies: at least 2 are needed for a spread")]
    Draws(usize),
    #[error("{draws} draws: over the ceiling of {ceiling}{with_files} (each is a bounded fit{files_cost}); nothing was drawn: draw fewer, or run several seeds into separate folders")]
    DrawsCeiling {
        draws: u64,
        ceiling: usize,
        with_files: &'static str,
        files_cost: String,
    },
    #[error("{}: the identified dynamics cannot be written into it: {problem}", robot.display())]
    Patch {
        robot: PathBuf,
        problem: Box<robotid_stages::export::PatchError>,
    },
    #[error("--mjcf {}: the identified dynamics cannot be written into it: {problem}", mjcf.display())]
    MjcfPatch {
        mjcf: PathBuf,
        problem: Box<robotid_stages::export::PatchError>,
    },
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(transparent)]
    Library(#[from] robotid::Error),
    #[error(transparent)]
    Stage(#[from] robotid_stages::Error),
    #[error("the sidecar: {0}")]
    Json(#[from] serde_json::Error),
    #[error("the sidecar table: {0}")]
    Arrow(#[from] arrow::error::ArrowError),
}

pub type Result<T, E = ExportError> = std::result::Result<T, E>;

/// Every file made, written (each atomically).
fn write_outputs(within: &Path, files: &[(PathBuf, Output)]) -> Result<()> {
    for (path, out) in files {
        let path = &within.join(path);
        match out {
            Output::Text(text) => write_atomic(path, |w| {
                use std::io::Write;
                w.write_all(text.as_bytes())
                    .map_err(|e| robotid_stages::Error::io(path, e))
            })?,
            Output::Table(batch) => write_parquet(path, batch)?,
        }
    }
    Ok(())
}

/// Bodies a simulator takes: every link with mass, finite, of a robot's
/// size, inertias that satisfy the triangle inequality (a table holding
/// ixx = 1e30 wrote a URDF that broke it).
fn simulable(identified: &Model, parameters: &Path) -> Result<()> {
    if let Some((l, j)) = identified
        .links
        .iter()
        .zip(&identified.joints)
        .find(|(l, _)| !(l.mass > 0.0))
    {
        return Err(ExportError::Massless {
            joint: j.name.clone(),
            mass: l.mass,
        });
    }
    if let Err(p) = identified.validate() {
        return Err(ExportError::Impossible {
            parameters: parameters.to_path_buf(),
            problem: p.to_string(),
        });
    }
    Ok(())
}

/// The estimate's own consistent model (`stored`), unless another prior
/// weight is asked for (or the table predates it being stored): then
/// fitted again.
pub(crate) fn consistent(
    params: &robotid_stages::estimation::Parameters,
    base: &robotid_stages::dynamics::BaseRegressor,
    map: &nalgebra::DMatrix<f64>,
    names: &[String],
    prior_weight: Option<f64>,
) -> Result<Consistent> {
    let stored: Option<Vec<f64>> = params
        .metadata
        .get(metadata::PHYSICAL_STANDARD)
        .and_then(|s| serde_json::from_str(s).ok())
        .filter(|v: &Vec<f64>| v.len() == names.len());
    Ok(match (stored, prior_weight) {
        (Some(standard), None) => Consistent {
            standard,
            how: params.metadata[metadata::PHYSICAL].clone(),
            said: format!(
                "the estimate's physically consistent standard parameters ({})",
                metadata::PHYSICAL_STANDARD
            ),
        },
        (_, weight) => {
            let prior = standard_parameters(&base.model, base.terms);
            let weight = weight.or_else(|| {
                params
                    .metadata
                    .get(metadata::PHYSICAL_PRIOR_WEIGHT)
                    .and_then(|w| w.parse::<f64>().ok())
            });
            let bounds = robotid_stages::estimation::link_bounds(&base.model, &prior);
            let fit = physically_consistent(names, &prior, map, &params.values, &params.covariance, &bounds, weight)?;
            let how = format!(
                "fitted again: χ² = {:.3} against the estimate's covariance ({} base parameters), prior weight {:e}{}, smallest pseudo-inertia eigenvalues {:?}",
                fit.chi2,
                params.names.len(),
                fit.prior_weight,
                fit.chosen.as_ref().map(|c| format!(" ({c})")).unwrap_or_default(),
                fit.min_eigen
            );
            Consistent {
                standard: fit.standard,
                said: format!("physically consistent standard parameters {how}"),
                how,
            }
        }
    })
}

/// None of the files `args` would write is one it reads (the robot file,
/// the parameters, the user's MJCF).
fn refuse_inputs_as_outputs(args: &Export, stem: &Path) -> Result<()> {
    let writes: Vec<PathBuf> = dedup(&args.formats)
        .iter()
        .flat_map(|f| match f {
            Format::Urdf => &["urdf"][..],
            Format::Mjcf => &["xml"][..],
            Format::Sidecar => &["sidecar.json", "sidecar.parquet"][..],
        })
        .map(|ext| args.within.join(with_ext(stem, ext)))
        .collect();
    let reads: Vec<PathBuf> = [args.robot.path().to_path_buf(), args.within.join(&args.parameters)]
        .into_iter()
        .chain(args.mjcf.clone())
        .collect();
    robotid_stages::formats::refuse_inputs(writes.iter().map(PathBuf::as_path), reads.iter().map(PathBuf::as_path))?;
    Ok(())
}

/// Physically consistent standard parameters closest to the a-priori model
/// that reproduce the identified base parameters, written as URDF, MJCF
/// and a sidecar with everything neither can hold.
pub fn export(args: &Export) -> Result<Exported> {
    if let Some(w) = args.prior_weight.filter(|w| !(*w > 0.0 && w.is_finite())) {
        return Err(ExportError::PriorWeight(w));
    }
    let stem = stem(&args.out, &args.formats);
    refuse_inputs_as_outputs(args, &stem)?;
    let (params, base) = physical_table(&args.robot, &args.within.join(&args.parameters), &args.parameters)?;
    let map = base.map().ok_or(ExportError::Decoupled)?;
    let names = parameter_names(&base.model, base.terms);
    let fit = consistent(&params, &base, map, &names, args.prior_weight)?;
    let identified = with_standard_parameters(&base.model, base.terms, &fit.standard);
    simulable(&identified, &args.parameters)?;
    let prior = standard_parameters(&base.model, base.terms);
    let bounds = robotid_stages::estimation::link_bounds(&base.model, &prior);
    let outside = outside_bounds(&identified, &bounds);
    if !outside.is_empty() && !args.force {
        return Err(ExportError::OutOfBounds {
            parameters: args.parameters.clone(),
            links: outside,
        });
    }
    let mut warnings = estimate_warnings(&params.metadata);
    warnings.extend(far_from_the_robot_file(
        &base.model,
        &identified,
        &bounds,
        &params.metadata,
    ));
    warnings.extend(outside.iter().map(|o| format!("written with --force: {o}")));
    let note = format!(
        "identified by robotid {} from {} (a-priori model {}); physically consistent",
        env!("CARGO_PKG_VERSION"),
        args.parameters.display(),
        args.robot.path().display(),
    );
    let (urdf, patched) = urdf_of(args, &identified, &note, &mut warnings)?;
    let (mjcf, mjcf_patched) = match args.formats.contains(&Format::Mjcf) {
        true => mjcf_of(args, &identified, &note, &mut warnings)?,
        false => (String::new(), None),
    };
    // Everything is made before anything is written.
    let mut files: Vec<(PathBuf, Output)> = Vec::new();
    for f in dedup(&args.formats) {
        match f {
            Format::Urdf => files.push((with_ext(&stem, "urdf"), Output::Text(urdf.clone()))),
            Format::Mjcf => files.push((with_ext(&stem, "xml"), Output::Text(mjcf.clone()))),
            Format::Sidecar => {
                let batch = read_parquet(&args.within.join(&args.parameters))?;
                let table = Table::of(&batch, &params.names, &args.parameters)?;
                let side = Sidecar {
                    args,
                    params: &params,
                    table: &table,
                    fit: &fit,
                    names: &names,
                    model: &identified,
                    terms: base.terms,
                    map,
                    warnings: &warnings,
                    bounds: &bounds,
                    patched: patched.as_deref(),
                    mjcf_patched: mjcf_patched.as_deref(),
                };
                files.push((with_ext(&stem, "sidecar.json"), Output::Text(side.json()?)));
                files.push((with_ext(&stem, "sidecar.parquet"), Output::Table(side.parquet()?)));
            }
        }
    }
    write_outputs(&args.within, &files)?;
    Ok(Exported {
        how: fit.said,
        warnings,
        files: files.into_iter().map(|(p, _)| p).collect(),
    })
}

/// The URDF export: the robot file's own, patched, where it is a URDF (the
/// links lumped or carried, and meshes named relative to it, said in
/// `warnings` where they need the user), else one made from the model.
fn urdf_of(
    args: &Export,
    identified: &Model,
    note: &str,
    warnings: &mut Vec<String>,
) -> Result<(String, Option<Vec<Patched>>)> {
    let Some(user) = user_urdf(&args.robot, identified)? else {
        return Ok((to_urdf(identified, note), None));
    };
    let short = format!(
        "identified by robotid {} from {}, physically consistent (the sidecar has its provenance)",
        env!("CARGO_PKG_VERSION"),
        args.parameters.display()
    );
    let (text, links) = user
        .apply(identified, &short)
        .map_err(|p| patch_error(args.robot.path(), p))?;
    warnings.extend(relative_meshes(&text));
    warnings.extend(links.iter().filter_map(|p| p.said.clone()));
    Ok((text, Some(links)))
}

/// The MJCF export: the user's own (`--mjcf`), patched, with what it
/// overrides and where its kinematics differ said in `warnings`; else one
/// made from the model.
fn mjcf_of(
    args: &Export,
    identified: &Model,
    note: &str,
    warnings: &mut Vec<String>,
) -> Result<(String, Option<Vec<Patched>>)> {
    let Some(user) = user_mjcf(args.mjcf.as_deref(), identified)? else {
        return Ok((to_mjcf(identified, note), None));
    };
    let short = format!(
        "identified by robotid {} from {}, physically consistent (the sidecar has its provenance)",
        env!("CARGO_PKG_VERSION"),
        args.parameters.display()
    );
    let mjcf = args.mjcf.as_deref().unwrap_or(Path::new(""));
    let (text, bodies) = user.apply(identified, &short).map_err(|p| mjcf_error(mjcf, p))?;
    warnings.extend(user.said.iter().cloned());
    warnings.extend(relative_assets(&text));
    warnings.extend(bodies.iter().filter_map(|p| p.said.clone()));
    Ok((text, Some(bodies)))
}

/// The user's MJCF read for patching with models like `model` (None:
/// none given).
pub(crate) fn user_mjcf(mjcf: Option<&Path>, model: &Model) -> Result<Option<MjcfPatch>> {
    let Some(path) = mjcf else { return Ok(None) };
    let text = std::fs::read_to_string(path).map_err(|source| ExportError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(Some(MjcfPatch::new(text, model).map_err(|p| mjcf_error(path, p))?))
}

pub(crate) fn mjcf_error(mjcf: &Path, problem: robotid_stages::export::PatchError) -> ExportError {
    ExportError::MjcfPatch {
        mjcf: mjcf.to_path_buf(),
        problem: Box::new(problem),
    }
}

/// Asset files an MJCF names relative to its folder (or its `meshdir`):
/// they resolve from the folder of the file MuJoCo loads.
fn relative_assets(mjcf: &str) -> Option<String> {
    let doc = roxmltree::Document::parse(mjcf).ok()?;
    let root = doc.root_element();
    let absolute_dir = |k: &str| {
        root.children()
            .filter(|n| n.has_tag_name("compiler"))
            .filter_map(|n| n.attribute(k).or_else(|| n.attribute("assetdir")))
            .any(|d| Path::new(d).is_absolute())
    };
    let mut relative: Vec<&str> = doc
        .descendants()
        .filter(|n| ["mesh", "texture", "hfield", "skin"].iter().any(|t| n.has_tag_name(*t)))
        .filter(|n| {
            !absolute_dir(if n.has_tag_name("texture") {
                "texturedir"
            } else {
                "meshdir"
            })
        })
        .filter_map(|n| n.attribute("file"))
        .filter(|f| !Path::new(f).is_absolute())
        .collect();
    relative.dedup();
    (!relative.is_empty()).then(|| {
        format!(
            "the MJCF names {} asset file(s) relative to its folder ({}{}): they resolve from the folder of the file MuJoCo loads, so keep the exported MJCF beside the one given or give it the assets",
            relative.len(),
            relative[..relative.len().min(3)].join(", "),
            if relative.len() > 3 { ", …" } else { "" }
        )
    })
}

/// The robot file's own URDF read for patching with models of it like
/// `model` (None: the robot file is not a URDF).
pub(crate) fn user_urdf(robot: &Robot, model: &Model) -> Result<Option<UrdfPatch>> {
    let path = robot.path();
    if !path.extension().is_some_and(|e| e.eq_ignore_ascii_case("urdf")) {
        return Ok(None);
    }
    Ok(Some(
        UrdfPatch::new(robot.text().to_string(), path, model).map_err(|problem| patch_error(path, problem))?,
    ))
}

pub(crate) fn patch_error(robot: &Path, problem: robotid_stages::export::PatchError) -> ExportError {
    ExportError::Patch {
        robot: robot.to_path_buf(),
        problem: Box::new(problem),
    }
}

/// Mesh files a URDF names by a path relative to its own folder: they
/// resolve beside the robot file, not beside the export.
fn relative_meshes(urdf: &str) -> Option<String> {
    let doc = roxmltree::Document::parse(urdf).ok()?;
    let mut relative: Vec<&str> = doc
        .descendants()
        .filter(|n| n.has_tag_name("mesh"))
        .filter_map(|n| n.attribute("filename"))
        .filter(|f| !f.contains("://") && !Path::new(f).is_absolute())
        .collect();
    relative.dedup();
    (!relative.is_empty()).then(|| {
        format!(
            "the URDF names {} mesh file(s) relative to its folder ({}{}): they resolve from the robot file's folder, so keep the exported URDF there or give it the meshes",
            relative.len(),
            relative[..relative.len().min(3)].join(", "),
            if relative.len() > 3 { ", …" } else { "" }
        )
    })
}

/// The parameters table at `path` (named `shown`) with the robot it was
/// identified for; refused unless it is a physically consistent estimate
/// of the chain model.
pub(crate) fn physical_table(
    robot: &Robot,
    path: &Path,
    shown: &Path,
) -> Result<(
    robotid_stages::estimation::Parameters,
    Arc<robotid_stages::dynamics::BaseRegressor>,
)> {
    let (params, _, base) = robotid::tables::identified_with(robot, path)?;
    if base.map().is_none() {
        return Err(ExportError::Decoupled);
    }
    if !params.metadata.contains_key(metadata::PHYSICAL) {
        return Err(ExportError::NotPhysical {
            parameters: shown.to_path_buf(),
            robot: robot.path().to_path_buf(),
        });
    }
    Ok((params, base))
}

/// Physically consistent standard parameters and how they were obtained.
pub(crate) struct Consistent {
    pub(crate) standard: Vec<f64>,
    how: String,
    /// What the export says of it.
    said: String,
}

/// Links whose exported mass or centre of mass is outside its bounds
/// (beyond the solver's tolerance), with the numbers.
fn outside_bounds(exported: &Model, bounds: &[LinkBound]) -> Vec<String> {
    (0..exported.dof())
        .filter_map(|i| outside_bound(exported, i, &bounds[i]))
        .collect()
}

/// Whether the link of joint `i` is outside its bound `b`, said.
pub(crate) fn outside_bound(exported: &Model, i: usize, b: &LinkBound) -> Option<String> {
    let (link, j) = (&exported.links[i], &exported.joints[i]);
    let tol = 1e-6;
    let m = link.mass;
    if !(m >= b.mass.0 * (1.0 - tol) && m <= b.mass.1 * (1.0 + tol)) {
        return Some(format!(
            "the link of `{}` weighs {m:.4} kg, outside {:.4}–{:.4} kg ({}× either way of the robot file's)",
            j.name,
            b.mass.0,
            b.mass.1,
            robotid_stages::estimation::MASS_FACTOR
        ));
    }
    let e = b.ellipsoid?;
    let c = link.com;
    let d = (c - e.centre).component_div(&e.semi_axes).norm();
    (d > 1.0 + tol).then(|| {
                format!(
                    "the link of `{}` has its centre of mass at ({:.3}, {:.3}, {:.3}) m, {d:.2}× the way out of the ellipsoid of its shapes (centre ({:.3}, {:.3}, {:.3}) m, semi-axes ({:.3}, {:.3}, {:.3}) m)",
                    j.name, c.x, c.y, c.z, e.centre.x, e.centre.y, e.centre.z, e.semi_axes.x, e.semi_axes.y, e.semi_axes.z
                )
            })
}

/// What the estimate's own checks said of the table, carried into the
/// export: a model exported from a fit that disagreed with its data (a
/// residue over the noise floor, parameters no body can have, identify's
/// refusal overridden) is said again where it is used.
fn estimate_warnings(md: &std::collections::BTreeMap<String, String>) -> Vec<String> {
    let mut out = Vec::new();
    if let Some(v) = md.get(metadata::INADEQUATE) {
        out.push(format!("identify judged this estimate inadequate: {v}"));
    }
    let adequacy: Vec<serde_json::Value> = md
        .get(metadata::ADEQUACY)
        .and_then(|a| serde_json::from_str(a).ok())
        .unwrap_or_default();
    let over: Vec<String> = adequacy
        .iter()
        .filter_map(|a| Some((a.get("joint")?.as_str()?, a.get("ratio")?.as_f64()?)))
        .filter(|(_, r)| *r > robotid_stages::estimation::ADEQUATE_RATIO)
        .map(|(j, r)| format!("{j} {r:.1}×"))
        .collect();
    if !over.is_empty() {
        out.push(format!(
            "the estimate's residue is over {}× the noise floor on {} (model error, or a channel that disagrees with the data: swapped, scaled or late); the exported model carries it",
            robotid_stages::estimation::ADEQUATE_RATIO,
            over.join(", ")
        ));
    }
    for (key, what) in [
        (metadata::IMPOSSIBLE, "parameters no body can have"),
        (
            metadata::UNIDENTIFIED,
            "parameters not identified at their physical size",
        ),
    ] {
        if let Some(v) = md.get(key) {
            out.push(format!("the estimate has {what}: {v}"));
        }
    }
    out
}

/// Links whose exported mass is over 3× from the robot file's (either
/// way): a base parameter groups it with others and the data cannot tell
/// them apart, or they push it to its bound. The joint torques along
/// motions like the recorded ones stay right; a simulation's masses, and
/// so its contacts and Cartesian forces, may not.
fn far_from_the_robot_file(
    prior: &Model,
    exported: &Model,
    bounds: &[LinkBound],
    md: &std::collections::BTreeMap<String, String>,
) -> Vec<String> {
    let weight = md.get(metadata::PHYSICAL_PRIOR_WEIGHT).map_or("?", String::as_str);
    prior
        .links
        .iter()
        .zip(&exported.links)
        .zip(&prior.joints)
        .zip(bounds)
        .filter(|(((a, b), _), _)| a.mass > 0.0 && !(b.mass / a.mass <= 3.0 && b.mass / a.mass >= 1.0 / 3.0))
        .map(|(((a, b), j), bound)| {
            let at_bound = (b.mass - bound.mass.0).abs() <= 1e-6 * bound.mass.0 || (b.mass - bound.mass.1).abs() <= 1e-6 * bound.mass.1;
            if at_bound {
                format!(
                    "the link of `{}` weighs {:.4} kg in the export against {:.4} kg in the robot file: held at its bound ({}× either way), the data would move it further (fit prior weight {weight}). Torques along motions like the recorded ones are right; check the robot file's mass for this link, or the model (a payload, a cable, friction that is not viscous + Coulomb)",
                    j.name, b.mass, a.mass, robotid_stages::estimation::MASS_FACTOR
                )
            } else {
                format!(
                    "the link of `{}` weighs {:.4} kg in the export against {:.4} kg in the robot file: the data do not tell its mass from the parameters it is grouped with, and the fit's prior weight ({weight}) left it free. Torques along motions like the recorded ones are right; the body may not be. Estimate with a larger `prior_weight` (or `robotid export --prior-weight`) to keep it near the robot file",
                    j.name, b.mass, a.mass
                )
            }
        })
        .collect()
}

enum Output {
    Text(String),
    Table(RecordBatch),
}

fn dedup(formats: &[Format]) -> Vec<Format> {
    let mut out = Vec::new();
    for f in formats {
        if !out.contains(f) {
            out.push(*f);
        }
    }
    out
}

/// `-o` without the extension its one format would add.
fn stem(out: &Path, formats: &[Format]) -> PathBuf {
    let one = dedup(formats);
    let ext = out.extension().and_then(|e| e.to_str()).unwrap_or("");
    let strip = matches!(
        (one.as_slice(), ext),
        ([Format::Urdf], "urdf") | ([Format::Mjcf], "xml") | ([Format::Sidecar], "json" | "parquet")
    );
    if !strip {
        return out.to_path_buf();
    }
    let s = out.with_extension("");
    match s.extension().and_then(|e| e.to_str()) {
        Some("sidecar") => s.with_extension(""),
        _ => s,
    }
}

fn with_ext(stem: &Path, ext: &str) -> PathBuf {
    let mut s = stem.as_os_str().to_owned();
    s.push(".");
    s.push(ext);
    PathBuf::from(s)
}

/// The parameters table's intervals and expressions, by base parameter.
struct Table {
    ci_low: Vec<f64>,
    ci_high: Vec<f64>,
    expressions: Vec<String>,
}

impl Table {
    /// The columns of `parameters`' table; the first missing one is named.
    fn of(batch: &RecordBatch, names: &[String], parameters: &Path) -> Result<Table> {
        let f = |c: &str| -> Result<Vec<f64>> {
            let a = batch
                .column_by_name(c)
                .and_then(|a| a.as_any().downcast_ref::<Float64Array>())
                .ok_or_else(|| ExportError::Column {
                    parameters: parameters.to_path_buf(),
                    column: c.to_string(),
                })?;
            Ok(a.values().to_vec())
        };
        let expressions = match robotid_stages::estimation::expressions_of(batch) {
            e if e.is_empty() => names.to_vec(),
            e => e,
        };
        Ok(Table {
            ci_low: f("ci_low")?,
            ci_high: f("ci_high")?,
            expressions,
        })
    }
}

struct Sidecar<'a> {
    args: &'a Export,
    params: &'a robotid_stages::estimation::Parameters,
    table: &'a Table,
    fit: &'a Consistent,
    /// Standard parameter names, in the fit's order.
    names: &'a [String],
    model: &'a Model,
    terms: robotid_stages::dynamics::RegressorTerms,
    /// θ_base = map·θ_standard.
    map: &'a nalgebra::DMatrix<f64>,
    warnings: &'a [String],
    bounds: &'a [LinkBound],
    /// The robot file's own URDF patched: which link holds each body.
    patched: Option<&'a [Patched]>,
    /// The user's MJCF patched: which body holds each.
    mjcf_patched: Option<&'a [Patched]>,
}

/// Where a standard parameter goes: (URDF holds it, MJCF holds it). The
/// symmetric friction pair goes into both (`friction`/`frictionloss`,
/// `damping`); asymmetric coefficients only as their means; Stribeck's
/// static excess, offsets, springs and the URDF's rotor inertia (and a
/// coupled motor's friction, which the MJCF's tendon holds) nowhere
/// (the sidecar and the robotid comments carry them).
fn representable(name: &str) -> (bool, bool) {
    use robotid_stages::dynamics::ParameterKind as K;
    match K::of(name) {
        K::Inertia | K::FirstMoment | K::Mass => (true, true),
        K::Viscous { one_sided } | K::Coulomb { one_sided } => (!one_sided, !one_sided),
        // A coupled motor's own friction: the MJCF's tendon holds it.
        K::RotorInertia | K::MotorViscous | K::MotorCoulomb => (false, true),
        K::Static { .. } | K::JointInertia | K::Gravity | K::Offset | K::Spring | K::Unknown => (false, false),
    }
}

impl Sidecar<'_> {
    /// Whether URDF and MJCF hold base parameter `i`: every standard
    /// parameter it combines is held.
    fn base_representable(&self, i: usize) -> (bool, bool) {
        // The regrouping's round-off aside (|K_ij| ~ 1e-17 of the row).
        let row = self.map.row(i).amax();
        (0..self.names.len())
            .filter(|&j| self.map[(i, j)].abs() > 1e-9 * row)
            .map(|j| representable(&self.names[j]))
            .fold((true, true), |(u, m), (a, b)| (u && a, m && b))
    }

    fn provenance(&self) -> Result<serde_json::Map<String, serde_json::Value>> {
        let bytes = |p: &Path| {
            std::fs::read(p).map_err(|source| ExportError::Io {
                path: p.to_path_buf(),
                source,
            })
        };
        let mut m = serde_json::Map::new();
        m.insert("robotid_version".into(), env!("CARGO_PKG_VERSION").into());
        m.insert(
            "parameters_file".into(),
            self.args.parameters.display().to_string().into(),
        );
        m.insert(
            "parameters_sha256".into(),
            sha256_hex(&bytes(&self.args.within.join(&self.args.parameters))?).into(),
        );
        m.insert("robot_file".into(), self.args.robot.path().display().to_string().into());
        m.insert("robot_sha256".into(), self.args.robot.sha256().into());
        // The estimate's own provenance: recordings, pipeline and config
        // hashes, method, adequacy, what the physical fit cost.
        for (k, v) in &self.params.metadata {
            if k.starts_with("robotid.") && k.as_str() != metadata::CONTENT_CRC32 {
                m.insert(k.clone(), v.clone().into());
            }
        }
        Ok(m)
    }

    /// A joint's friction and rotor inertia as the formats take them, and
    /// what each cannot hold.
    fn joint_json(&self, i: usize) -> serde_json::Value {
        use serde_json::json;
        let j = &self.model.joints[i];
        let f = &self.model.friction[i];
        let ia = self.model.drives[i].reflected_inertia();
        let mut lost_both = Vec::new();
        if f.viscous_pos != f.viscous_neg || f.coulomb_pos != f.coulomb_neg {
            lost_both.push("asymmetric friction (the formats take the means of the two signs)");
        }
        if f.transition > 0.0 {
            lost_both.push("the Coulomb transition tanh(q̇/v): URDF and MuJoCo switch at q̇ = 0");
        }
        let s = &f.stribeck;
        if s.velocity > 0.0 && (s.excess_pos != 0.0 || s.excess_neg != 0.0) {
            lost_both.push(
                "Stribeck's static excess fading with speed: the formats hold Coulomb's friction alone (MuJoCo's frictionloss is constant in speed)",
            );
        }
        if self.terms.offset {
            lost_both.push("the torque offset");
        }
        let mut not_in_urdf = lost_both.clone();
        if self.terms.rotor {
            not_in_urdf.push("the rotor inertia (MJCF: armature)");
        }
        // A coupled motor's rotor is its tendon's armature (`transmission`).
        if self.model.couplings.iter().any(|c| c.motor == i) {
            not_in_urdf.push("the coupled motor (MJCF: a fixed tendon; see `transmission`)");
        }
        json!({
            "name": j.name,
            "viscous_pos": f.viscous_pos, "viscous_neg": f.viscous_neg,
            "coulomb_pos": f.coulomb_pos, "coulomb_neg": f.coulomb_neg,
            "coulomb_transition_rad_s": f.transition, "offset": f.offset,
            "stribeck": {"excess_pos": s.excess_pos, "excess_neg": s.excess_neg, "velocity_rad_s": s.velocity, "exponent": s.exponent},
            "reflected_rotor_inertia": ia,
            "urdf": {"damping": 0.5 * (f.viscous_pos + f.viscous_neg), "friction": 0.5 * (f.coulomb_pos + f.coulomb_neg)},
            "mjcf": {"armature": self.model.own_armature(i), "damping": 0.5 * (f.viscous_pos + f.viscous_neg), "frictionloss": 0.5 * (f.coulomb_pos + f.coulomb_neg)},
            "not_in_urdf": not_in_urdf,
            "not_in_mjcf": lost_both,
        })
    }

    /// The transmission where a motor turns with other joints than its
    /// own (None otherwise, so uncoupled sidecars stay as they were): R
    /// (motor angles θ = R·q + offsets), and each coupled motor with its
    /// identified rotor and friction as the MJCF's fixed tendon holds them.
    /// URDF has no element for a motor: a `<mimic>` ties joint angles,
    /// which a coupled motor does not.
    fn transmission_json(&self) -> Option<serde_json::Value> {
        use serde_json::json;
        let m = self.model;
        if m.couplings.is_empty() {
            return None;
        }
        let r = m.transmission();
        let name = |j: usize| m.joints[j].name.clone();
        Some(json!({
            "joints": (0..m.dof()).map(name).collect::<Vec<_>>(),
            "matrix": (0..r.nrows()).map(|i| r.row(i).iter().copied().collect::<Vec<f64>>()).collect::<Vec<_>>(),
            "motor_offset_rad": m.drives.iter().map(|d| d.motor_offset).collect::<Vec<_>>(),
            "coupled_motors": m.couplings.iter().map(|c| json!({
                "motor_of": name(c.motor),
                "gear_ratio": m.drives[c.motor].gear_ratio,
                "turns": c.with.iter().map(|&(j, t)| (name(j), json!(t))).collect::<serde_json::Map<_, _>>(),
                "rotor_inertia": m.drives[c.motor].rotor_inertia,
                "motor_viscous": c.viscous,
                "motor_coulomb": c.coulomb,
                "mjcf": {"tendon": format!("motor_{}", name(c.motor)), "armature": m.drives[c.motor].rotor_inertia, "damping": c.viscous, "frictionloss": c.coulomb},
            })).collect::<Vec<_>>(),
            "not_in_urdf": "the coupling: URDF has no motor element, and a <mimic> ties joint angles, which a coupled motor does not (the robotid comments state it)",
        }))
    }

    fn json(&self) -> Result<String> {
        use serde_json::json;
        let p = self.params;
        let base: Vec<_> = (0..p.names.len())
            .map(|i| {
                let (urdf, mjcf) = self.base_representable(i);
                json!({
                    "name": p.names[i], "unit": p.units[i], "value": p.values[i], "std": p.std[i],
                    "ci_low": self.table.ci_low[i], "ci_high": self.table.ci_high[i],
                    "expression": self.table.expressions[i], "in_urdf": urdf, "in_mjcf": mjcf,
                })
            })
            .collect();
        let standard: Vec<_> = self
            .names
            .iter()
            .zip(&self.fit.standard)
            .map(|(n, v)| {
                let (urdf, mjcf) = representable(n);
                json!({"name": n, "unit": parameter_unit(n), "value": v, "in_urdf": urdf, "in_mjcf": mjcf})
            })
            .collect();
        let joints: Vec<_> = (0..self.model.joints.len()).map(|i| self.joint_json(i)).collect();
        let cov: Vec<Vec<f64>> = (0..p.names.len())
            .map(|r| (0..p.names.len()).map(|c| p.covariance[(r, c)]).collect())
            .collect();
        let confidence = p.metadata.get(metadata::ESTIMATE_CONFIDENCE).cloned();
        let mut doc = json!({
            "robot": self.model.name,
            "provenance": self.provenance()?,
            "confidence": confidence,
            "physical_fit": self.fit.how,
            "base_parameters": base,
            "base_covariance": {"names": p.names, "unit": "the product of the two parameters' units", "matrix": cov},
            "standard_parameters": standard,
            "joints": joints,
            "bounds": self.bounds.iter().zip(&self.model.joints).map(|(b, j)| json!({
                "link_of": j.name,
                "mass_min_kg": b.mass.0,
                "mass_max_kg": if b.mass.1.is_finite() { json!(b.mass.1) } else { json!(null) },
                "ellipsoid": b.ellipsoid.map(|e| json!({
                    "centre_m": [e.centre.x, e.centre.y, e.centre.z],
                    "semi_axes_m": [e.semi_axes.x, e.semi_axes.y, e.semi_axes.z],
                })),
                "how": b.said,
            })).collect::<Vec<_>>(),
            "warnings": self.warnings,
            "urdf_patched": self.patched.map(|p| p.iter().map(|p| json!({
                "joint": p.joint, "link": p.link, "lumped_links": p.lumped,
                "carried_links": p.carried, "said": p.said,
            })).collect::<Vec<_>>()),
            "mjcf_patched": self.mjcf_patched.map(|p| json!({
                "file": self.args.mjcf.as_ref().map(|m| m.display().to_string()),
                "bodies": p.iter().map(|p| json!({
                    "joint": p.joint, "body": p.link, "welded_bodies": p.lumped,
                    "carried_bodies": p.carried, "said": p.said,
                })).collect::<Vec<_>>(),
            })),
        });
        if let Some(t) = self.transmission_json() {
            doc["transmission"] = t;
        }
        Ok(serde_json::to_string_pretty(&doc)? + "\n")
    }

    /// One row per value: the base parameters (with standard deviation,
    /// interval and covariance columns), then the standard ones (the
    /// deviation and interval where a standard parameter is a base one).
    fn parquet(&self) -> Result<RecordBatch> {
        let p = self.params;
        let nb = p.names.len();
        let rows = nb + self.names.len();
        let base_of = |n: &str| p.names.iter().position(|b| b == n);
        let mut name = Vec::with_capacity(rows);
        let mut kind = Vec::with_capacity(rows);
        let mut unit = Vec::with_capacity(rows);
        let mut value = Vec::with_capacity(rows);
        let (mut std, mut lo, mut hi) = (Vec::new(), Vec::new(), Vec::new());
        let (mut urdf, mut mjcf, mut base_row) = (Vec::new(), Vec::new(), Vec::new());
        for i in 0..nb {
            name.push(p.names[i].clone());
            kind.push("base".to_string());
            unit.push(p.units[i].clone());
            value.push(p.values[i]);
            std.push(Some(p.std[i]));
            lo.push(Some(self.table.ci_low[i]));
            hi.push(Some(self.table.ci_high[i]));
            let (u, m) = self.base_representable(i);
            urdf.push(u);
            mjcf.push(m);
            base_row.push(Some(i));
        }
        for (n, v) in self.names.iter().zip(&self.fit.standard) {
            let b = base_of(n);
            name.push(n.clone());
            kind.push("standard".to_string());
            unit.push(parameter_unit(n).to_string());
            value.push(*v);
            std.push(b.map(|i| p.std[i]));
            lo.push(b.map(|i| self.table.ci_low[i]));
            hi.push(b.map(|i| self.table.ci_high[i]));
            let (u, m) = representable(n);
            urdf.push(u);
            mjcf.push(m);
            base_row.push(None);
        }
        let (fields, columns) = sidecar_columns(p, [name, kind, unit], [value], [std, lo, hi], [urdf, mjcf], &base_row);
        let mut md: std::collections::HashMap<String, String> = self
            .provenance()?
            .into_iter()
            .map(|(k, v)| (k, v.as_str().map(str::to_string).unwrap_or_else(|| v.to_string())))
            .collect();
        md.insert(metadata::TABLE.into(), "export_sidecar".into());
        let schema = Schema::new(fields).with_metadata(md);
        Ok(RecordBatch::try_new(Arc::new(schema), columns)?)
    }
}

/// The sidecar table's fields (units in their metadata) and columns: the
/// strings (name, kind, unit), the value, its deviation and interval, where
/// the formats hold it, and the base parameters' covariance by `base_row`.
fn sidecar_columns(
    p: &robotid_stages::estimation::Parameters,
    [name, kind, unit]: [Vec<String>; 3],
    [value]: [Vec<f64>; 1],
    [std, lo, hi]: [Vec<Option<f64>>; 3],
    [urdf, mjcf]: [Vec<bool>; 2],
    base_row: &[Option<usize>],
) -> (Vec<Field>, Vec<ArrayRef>) {
    let unit_field = |n: &str, u: &str| {
        Field::new(n, DataType::Float64, true).with_metadata(std::collections::HashMap::from([(
            metadata::UNIT.to_string(),
            u.to_string(),
        )]))
    };
    let mut fields = vec![
        Field::new("name", DataType::Utf8, false),
        Field::new("kind", DataType::Utf8, false),
        Field::new("unit", DataType::Utf8, false),
        Field::new("value", DataType::Float64, false).with_metadata(std::collections::HashMap::from([(
            metadata::UNIT.to_string(),
            "see `unit`".to_string(),
        )])),
        unit_field("std", "see `unit`"),
        unit_field("ci_low", "see `unit`"),
        unit_field("ci_high", "see `unit`"),
        Field::new("in_urdf", DataType::Boolean, false),
        Field::new("in_mjcf", DataType::Boolean, false),
    ];
    let mut columns: Vec<ArrayRef> = vec![
        Arc::new(StringArray::from(name)),
        Arc::new(StringArray::from(kind)),
        Arc::new(StringArray::from(unit)),
        Arc::new(Float64Array::from(value)),
        Arc::new(Float64Array::from(std)),
        Arc::new(Float64Array::from(lo)),
        Arc::new(Float64Array::from(hi)),
        Arc::new(BooleanArray::from(urdf)),
        Arc::new(BooleanArray::from(mjcf)),
    ];
    for (c, cn) in p.names.iter().enumerate() {
        fields.push(unit_field(
            &format!("cov_{cn}"),
            &format!("units of `unit` × {}", p.units[c]),
        ));
        columns.push(Arc::new(Float64Array::from(
            base_row
                .iter()
                .map(|r| r.map(|r| p.covariance[(r, c)]))
                .collect::<Vec<_>>(),
        )));
    }
    (fields, columns)
}
