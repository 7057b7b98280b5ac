//! Domain randomization from the identification's covariance: parameter
//! sets drawn from the base estimate's distribution, each mapped to
//! physically consistent bodies by the estimate's own bounded fit, written
//! as the quantities simulators take (per link: mass, centre of mass,
//! inertia; per joint: damping, frictionloss, armature), with each one's
//! identified value, spread and correlation with the others.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow::array::{ArrayRef, Float64Array, RecordBatch, StringArray, UInt32Array};
use arrow::datatypes::{DataType, Field, Schema};
use nalgebra::{DMatrix, DVector};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use robotid_schemas::metadata;
use robotid_stages::dynamics::{
    parameter_names, prior_scales, standard_parameters, with_standard_parameters, Model, Robot,
};
use robotid_stages::estimation::{link_bounds, physically_consistent};
use robotid_stages::export::{to_mjcf, to_urdf};
use robotid_stages::formats::parquet::write_parquet;
use robotid_stages::formats::sha256_hex;

use crate::export::{ExportError, Format, Result};

/// Draws asked for.
#[derive(Clone, Debug)]
pub struct Sample {
    /// The robot file the parameters were identified for.
    pub robot: PathBuf,
    /// A physically consistent parameters table (its covariance is drawn
    /// from).
    pub parameters: PathBuf,
    pub draws: usize,
    pub seed: u64,
    /// Besides the table: one model file per draw (URDF: the robot file's
    /// own patched where it is one; MJCF).
    pub formats: Vec<Format>,
    /// The output folder (made; must not hold anything).
    pub out: PathBuf,
    /// The user's own MJCF, patched per draw for [`Format::Mjcf`].
    pub mjcf: Option<PathBuf>,
}

/// One simulator parameter.
#[derive(Clone, Debug, PartialEq)]
pub struct Randomized {
    /// `<joint>.<quantity>`: the body the joint moves, or the joint's own.
    pub name: String,
    pub joint: String,
    pub quantity: &'static str,
    pub unit: &'static str,
    /// The identified value (the estimate's own bodies).
    pub value: f64,
    /// Mean and standard deviation over the draws.
    pub mean: f64,
    pub std: f64,
}

/// What [`sample`] drew and wrote.
#[derive(Debug)]
pub struct Sampled {
    pub parameters: Vec<Randomized>,
    /// Correlation over the draws, in `parameters`' order (NaN where a
    /// parameter does not vary).
    pub correlation: DMatrix<f64>,
    /// Draws the bounded fit could not map (left out), and why the first.
    pub failed: usize,
    pub failed_why: Option<String>,
    /// The draws' centre: the estimate's bodies' base parameters.
    pub centre: DVector<f64>,
    /// Each kept draw's bodies' base parameters.
    pub base: Vec<DVector<f64>>,
    /// How far the bounded fit moved the draws: the mean of each draw's χ²
    /// between its bodies' base parameters and the drawn ones, in the
    /// covariance's metric.
    pub moved: f64,
    /// Draws that were no body a robot can have as drawn, projected by the
    /// estimate's bounded fit, and how many of them each joint's body or
    /// friction was outside its bounds in.
    pub projected: usize,
    pub projected_by_joint: Vec<(String, usize)>,
    /// The drawn base parameters' standard deviations over the
    /// covariance's, before projection: smallest and largest.
    pub drawn_std_ratio: (f64, f64),
    pub files: Vec<PathBuf>,
}

/// The quantities of a joint, with their units (a link's body's:
/// [`robotid_stages::dynamics::LISTED`]).
const JOINT: [(&str, &str); 3] = [
    ("damping", "N*m*s/rad"),
    ("frictionloss", "N*m"),
    ("armature", "kg*m^2"),
];

/// The simulator's quantities of `model`, in [`quantities`]' order: each
/// body (inertia about its centre of mass, link-frame axes), then each
/// joint (damping and frictionloss the means of the two directions;
/// armature the rotor inertia reflected to the joint), then each coupled
/// motor as the MJCF's fixed tendon `motor_<joint>` holds it (its rotor,
/// motor side, as armature, and its own friction; its joint's armature is
/// then 0, as in the MJCF).
fn values(model: &Model) -> Vec<f64> {
    let mut v = Vec::with_capacity(13 * model.dof());
    for l in &model.links {
        v.extend(l.listed());
    }
    for (i, f) in model.friction.iter().enumerate() {
        v.extend([
            0.5 * (f.viscous_pos + f.viscous_neg),
            0.5 * (f.coulomb_pos + f.coulomb_neg),
            model.own_armature(i),
        ]);
    }
    for c in &model.couplings {
        v.extend([c.viscous, c.coulomb, model.drives[c.motor].rotor_inertia]);
    }
    v
}

/// (joint, quantity, unit) of each of [`values`].
fn quantities(model: &Model) -> Vec<(String, &'static str, &'static str)> {
    let of = |q: &[(&'static str, &'static str)]| {
        let q = q.to_vec();
        model
            .joints
            .iter()
            .flat_map(move |j| q.clone().into_iter().map(|(n, u)| (j.name.clone(), n, u)))
            .collect::<Vec<_>>()
    };
    let mut out = of(&robotid_stages::dynamics::LISTED);
    out.extend(of(&JOINT));
    for c in &model.couplings {
        let tendon = format!("motor_{}", model.joints[c.motor].name);
        out.extend(JOINT.iter().map(|&(n, u)| (tendon.clone(), n, u)));
    }
    out
}

/// `n` draws of N(mean, covariance), seeded: a factor of the covariance
/// (Cholesky, else the eigen-decomposition with negative eigenvalues, from
/// round-off, at zero) times standard normal vectors drawn in order.
fn draws(mean: &DVector<f64>, covariance: &DMatrix<f64>, n: usize, seed: u64) -> Vec<DVector<f64>> {
    let sym = (covariance + covariance.transpose()) * 0.5;
    let factor = match sym.clone().cholesky() {
        Some(c) => c.l(),
        None => {
            let e = sym.symmetric_eigen();
            let root = DMatrix::from_diagonal(&e.eigenvalues.map(|l| l.max(0.0).sqrt()));
            e.eigenvectors * root
        }
    };
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let z = DVector::from_fn(mean.len(), |_, _| StandardNormal.sample(&mut rng));
            mean + &factor * z
        })
        .collect()
}

/// What each draw is mapped with: the estimate's robot, bounds and
/// covariance, and its own bodies.
struct Drawing {
    params: robotid_stages::estimation::Parameters,
    base: Arc<robotid_stages::dynamics::BaseRegressor>,
    names: Vec<String>,
    prior: Vec<f64>,
    bounds: Vec<robotid_stages::estimation::LinkBound>,
    /// The covariance's (pseudo-)inverse: χ² between two base vectors.
    inverse: DMatrix<f64>,
    /// The estimate's bodies, as standard parameters, and their base
    /// parameters: the draws' centre.
    own: Vec<f64>,
    centre: DVector<f64>,
    /// The estimate's own prior weight (None: chosen again).
    weight: Option<f64>,
    /// A base-parameter step into the standard step of least a-priori
    /// size that makes it: S²Mᵀ(MS²Mᵀ)⁺, S the robot file's scales.
    lift: DMatrix<f64>,
}

/// One draw mapped to bodies: them, their base parameters, how far the
/// bounded fit moved them from the draw (χ² in the covariance's metric; 0
/// for bodies as drawn) and the joints whose bodies or friction were no
/// robot's as drawn (empty: not projected).
struct Drawn {
    model: Model,
    base: DVector<f64>,
    moved: f64,
    outside: Vec<usize>,
}

impl Drawing {
    fn of(args: &Sample, robot: &Robot) -> Result<Drawing> {
        let (params, base) = crate::export::physical_table(robot, &args.parameters, &args.parameters)?;
        let map = base.map().ok_or(ExportError::Decoupled)?;
        let names = parameter_names(&base.model, base.terms);
        let prior = standard_parameters(&base.model, base.terms);
        let bounds = link_bounds(&base.model, &prior);
        let weight = params
            .metadata
            .get(metadata::PHYSICAL_PRIOR_WEIGHT)
            .and_then(|w| w.parse().ok());
        let own = crate::export::consistent(&params, &base, map, &names, None)?.standard;
        let s2 = DMatrix::from_diagonal(&DVector::from_vec(prior_scales(&names, &prior)).map(|x| x * x));
        let gram = (map * &s2 * map.transpose())
            .pseudo_inverse(1e-12)
            .map_err(|e| ExportError::Impossible {
                parameters: args.parameters.clone(),
                problem: format!("its base map cannot be inverted: {e}"),
            })?;
        let lift = &s2 * map.transpose() * gram;
        let centre = map * DVector::from_column_slice(&own);
        let inverse = params
            .covariance
            .clone()
            .pseudo_inverse(1e-12)
            .map_err(|e| ExportError::Impossible {
                parameters: args.parameters.clone(),
                problem: format!("its covariance cannot be inverted: {e}"),
            })?;
        Ok(Drawing {
            params,
            base,
            names,
            prior,
            bounds,
            inverse,
            own,
            centre,
            weight,
            lift,
        })
    }

    fn map(&self) -> &DMatrix<f64> {
        self.base.map().expect("the chain model's")
    }

    /// Draw `d` as bodies: the estimate's own moved by the standard step of
    /// least a-priori size that makes the draw (exact, and nothing moves
    /// that the data cannot tell); where that is no body a robot can have
    /// (outside the links' bounds, or friction < 0), the estimate's bounded
    /// fit of the draw.
    fn fit(&self, d: &DVector<f64>) -> robotid_stages::Result<Drawn> {
        let map = self.map();
        let step = &self.lift * (d - &self.centre);
        let lifted: Vec<f64> = self.own.iter().zip(step.iter()).map(|(a, b)| a + b).collect();
        let model = with_standard_parameters(&self.base.model, self.base.terms, &lifted);
        let outside = self.impossible(&model);
        if outside.is_empty() {
            return Ok(Drawn {
                base: map * DVector::from_column_slice(&lifted),
                model,
                moved: 0.0,
                outside,
            });
        }
        let cov = &self.params.covariance;
        let fit = physically_consistent(&self.names, &self.prior, map, d, cov, &self.bounds, self.weight)?;
        let base = map * DVector::from_column_slice(&fit.standard);
        let moved = (&base - d).dot(&(&self.inverse * (&base - d)));
        Ok(Drawn {
            model: with_standard_parameters(&self.base.model, self.base.terms, &fit.standard),
            base,
            moved,
            outside,
        })
    }

    /// The joints whose body or friction no robot can have: outside the
    /// link's bounds (the estimate's: mass, centre of mass in the shapes'
    /// ellipsoid), an inertia that is not positive definite or breaks the
    /// triangle inequality, friction < 0.
    fn impossible(&self, model: &Model) -> Vec<usize> {
        (0..model.dof())
            .filter(|&i| {
                let p = model.links[i].inertia_com.symmetric_eigenvalues();
                let f = &model.friction[i];
                crate::export::outside_bound(model, i, &self.bounds[i]).is_some()
                    || !(p.min() > 0.0 && (0..3).all(|k| p[k] <= p[(k + 1) % 3] + p[(k + 2) % 3]))
                    || !(f.viscous_pos.min(f.viscous_neg).min(f.coulomb_pos).min(f.coulomb_neg) >= 0.0)
            })
            .collect()
    }
}

/// The most draws one `sample` makes: each is a bounded fit (about 1–3 ms
/// on a 7-joint arm, one core), and all are held to compute their spread,
/// so 100 000 take a few minutes and well under 1 GB.
pub const MAX_DRAWS: usize = 100_000;
/// The most draws written as one model file each: a URDF or MJCF is
/// 10–60 kB, so 10 000 of them are up to about 600 MB per format.
pub const MAX_FILE_DRAWS: usize = 10_000;

/// Refuses, before any work, a count of draws over the ceiling, with the
/// figure it would cost.
pub fn draws_within_ceiling(draws: u64, files: bool) -> Result<()> {
    let (ceiling, with_files) = match files {
        false => (MAX_DRAWS, ""),
        true => (MAX_FILE_DRAWS, " with a model file per draw"),
    };
    if draws > ceiling as u64 {
        let files_cost = match files {
            true => format!(
                " and a file of up to 60 kB: about {:.1} GB per format",
                draws as f64 * 60e3 / 1e9
            ),
            false => String::new(),
        };
        return Err(ExportError::DrawsCeiling {
            draws,
            ceiling,
            with_files,
            files_cost,
        });
    }
    Ok(())
}

/// Draws `args.draws` parameter sets from the estimate's distribution,
/// maps each to bodies, and writes `samples.parquet` (one row per draw
/// and quantity), `randomization.json` and `.yaml` (each quantity's value,
/// spread and correlations) and, per `args.formats`, one model per draw.
pub fn sample(args: &Sample) -> Result<Sampled> {
    if args.draws < 2 {
        return Err(ExportError::Draws(args.draws));
    }
    draws_within_ceiling(args.draws as u64, !args.formats.is_empty())?;
    // Read once: the draws' prior and the patched URDF's carried links.
    let robot = Robot::read(&args.robot)?;
    let drawing = Drawing::of(args, &robot)?;
    let identified = with_standard_parameters(&drawing.base.model, drawing.base.terms, &drawing.own);
    // Drawn around the estimate's own bodies (the exported model) with the
    // identification's covariance, in order, then fitted in parallel: the
    // same at any thread count.
    let centre = drawing.centre.clone();
    let drawn = draws(&centre, &drawing.params.covariance, args.draws, args.seed);
    let fitted: Vec<_> = drawn.par_iter().map(|d| drawing.fit(d)).collect();
    let (mut models, mut base_values, mut moved, mut failed_why) = (Vec::new(), Vec::new(), 0.0, None);
    let mut projected = 0;
    let mut by_joint = vec![0usize; drawing.base.model.dof()];
    for (k, f) in fitted.into_iter().enumerate() {
        match f {
            Ok(d) => {
                models.push((k as u32, d.model));
                base_values.push(d.base);
                moved += d.moved;
                projected += !d.outside.is_empty() as usize;
                for &j in &d.outside {
                    by_joint[j] += 1;
                }
            }
            Err(e) => {
                failed_why.get_or_insert(format!("draw {k}: {e}"));
            }
        }
    }
    if models.len() < 2 {
        return Err(ExportError::Draws(models.len()));
    }
    let failed = args.draws - models.len();
    let table: Vec<Vec<f64>> = models.iter().map(|(_, m)| values(m)).collect();
    let (parameters, correlation) = spread(&identified, &table);
    let joints = drawing.base.model.joint_names();
    let mut sampled = Sampled {
        parameters,
        correlation,
        failed,
        failed_why,
        moved: moved / models.len() as f64,
        projected,
        projected_by_joint: joints.into_iter().zip(by_joint).collect(),
        drawn_std_ratio: std_ratio(&drawn, &drawing.params.covariance),
        base: base_values,
        centre,
        files: Vec::new(),
    };
    let md = provenance(args, failed)?;
    let staging = robotid::output::prepare(&args.out, None, &[args.parameters.clone(), args.robot.clone()])?;
    let dir = staging.staged_out();
    let mut files = vec![PathBuf::from("samples.parquet")];
    write_parquet(&dir.join(&files[0]), &samples_table(&identified, &models, &table, &md)?)?;
    let doc = randomization(&identified, &sampled, &md);
    for (file, text) in [
        ("randomization.json", serde_json::to_string_pretty(&doc)? + "\n"),
        ("randomization.yaml", yaml(&doc, 0)),
    ] {
        write_text(&dir.join(file), &text)?;
        files.push(file.into());
    }
    files.extend(model_files(args, &robot, dir, &models)?);
    staging.commit()?;
    sampled.files = files;
    Ok(sampled)
}

/// The drawn base parameters' standard deviations over the covariance's,
/// smallest and largest: the draws themselves, before any projection.
fn std_ratio(drawn: &[DVector<f64>], covariance: &DMatrix<f64>) -> (f64, f64) {
    let n = drawn.len() as f64;
    (0..covariance.nrows())
        .filter(|&i| covariance[(i, i)] > 0.0)
        .map(|i| {
            let mean = drawn.iter().map(|d| d[i]).sum::<f64>() / n;
            let var = drawn.iter().map(|d| (d[i] - mean).powi(2)).sum::<f64>() / (n - 1.0);
            (var / covariance[(i, i)]).sqrt()
        })
        .fold((f64::INFINITY, 0.0), |(a, b), r| (a.min(r), b.max(r)))
}

/// What the sample's files say of where they come from.
fn provenance(args: &Sample, failed: usize) -> Result<Vec<(&'static str, String)>> {
    let bytes = std::fs::read(&args.parameters).map_err(|source| ExportError::Io {
        path: args.parameters.clone(),
        source,
    })?;
    Ok(vec![
        (metadata::SOURCE_FILE, args.parameters.display().to_string()),
        (metadata::SOURCE_SHA256, sha256_hex(&bytes)),
        (metadata::SAMPLE_SEED, args.seed.to_string()),
        (metadata::SAMPLE_DRAWS, args.draws.to_string()),
        (metadata::SAMPLE_FAILED, failed.to_string()),
    ])
}

/// What the bounded fit's χ² over the draws means.
pub fn moved_said(moved: f64, parameters: usize) -> String {
    format!(
        "the bodies' base parameters differ from the drawn ones by χ² = {moved:.3} on average ({parameters} base parameters): near 0, the draws are the identification's distribution; larger, the bounds or the pull towards the robot file narrowed it"
    )
}

fn write_text(path: &Path, text: &str) -> Result<()> {
    std::fs::write(path, text).map_err(|source| ExportError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Each quantity's value, mean and spread over `table` (rows: draws), and
/// their correlation.
fn spread(identified: &Model, table: &[Vec<f64>]) -> (Vec<Randomized>, DMatrix<f64>) {
    let n = table.len() as f64;
    let p = table[0].len();
    let mean: Vec<f64> = (0..p).map(|j| table.iter().map(|r| r[j]).sum::<f64>() / n).collect();
    let cov = DMatrix::from_fn(p, p, |a, b| {
        table.iter().map(|r| (r[a] - mean[a]) * (r[b] - mean[b])).sum::<f64>() / (n - 1.0)
    });
    // A quantity that does not vary but by the solver's round-off (1e-8
    // of the largest of its kind, e.g. the masses) moves no torque: the
    // data cannot tell it, and every draw keeps the robot file's. Its
    // spread is 0 and it has no correlation.
    let kinds = quantities(identified);
    let largest = |kind: &str| {
        (0..p)
            .filter(|&j| kinds[j].1 == kind)
            .map(|j| mean[j].abs())
            .fold(0.0f64, f64::max)
    };
    let varies: Vec<bool> = (0..p)
        .map(|j| cov[(j, j)].max(0.0).sqrt() > 1e-8 * largest(kinds[j].1).max(f64::MIN_POSITIVE))
        .collect();
    let std: Vec<f64> = (0..p)
        .map(|j| if varies[j] { cov[(j, j)].sqrt() } else { 0.0 })
        .collect();
    let varies = |j: usize| varies[j];
    let correlation = DMatrix::from_fn(p, p, |a, b| match varies(a) && varies(b) {
        true => cov[(a, b)] / (std[a] * std[b]),
        false => f64::NAN,
    });
    let own = values(identified);
    let parameters = quantities(identified)
        .into_iter()
        .enumerate()
        .map(|(j, (joint, quantity, unit))| Randomized {
            name: format!("{joint}.{quantity}"),
            joint,
            quantity,
            unit,
            value: own[j],
            mean: mean[j],
            std: std[j],
        })
        .collect();
    (parameters, correlation)
}

/// One row per draw and quantity: draw, joint, quantity, unit, value.
fn samples_table(
    identified: &Model,
    models: &[(u32, Model)],
    table: &[Vec<f64>],
    md: &[(&str, String)],
) -> Result<RecordBatch> {
    let q = quantities(identified);
    let rows = models.len() * q.len();
    let mut draw = Vec::with_capacity(rows);
    let (mut joint, mut quantity, mut unit, mut value) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for ((k, _), v) in models.iter().zip(table) {
        for ((j, n, u), x) in q.iter().zip(v) {
            draw.push(*k);
            joint.push(j.as_str());
            quantity.push(*n);
            unit.push(*u);
            value.push(*x);
        }
    }
    let field = |name: &str, t: DataType, about: &str| {
        Field::new(name, t, false).with_metadata(std::collections::HashMap::from([(
            "description".to_string(),
            about.to_string(),
        )]))
    };
    let schema = Schema::new(vec![
        field("draw", DataType::UInt32, "the draw's index (draws the bounded fit could not map are left out)"),
        field(
            "joint",
            DataType::Utf8,
            match identified.couplings.is_empty() {
                true => "the joint: its own quantity, or the body it moves",
                false => "the joint: its own quantity, or the body it moves; motor_<joint>: a coupled motor, the MJCF's fixed tendon of that name",
            },
        ),
        field("quantity", DataType::Utf8, "mass, com_x..com_z (link frame), ixx..izz (about the centre of mass, link-frame axes), damping, frictionloss, armature"),
        field("unit", DataType::Utf8, "the value's unit"),
        field("value", DataType::Float64, "the drawn value, in `unit`"),
    ])
    .with_metadata(md.iter().map(|(k, v)| (k.to_string(), v.clone())).collect::<std::collections::HashMap<_, _>>());
    let columns: Vec<ArrayRef> = vec![
        Arc::new(UInt32Array::from(draw)),
        Arc::new(StringArray::from(joint)),
        Arc::new(StringArray::from(quantity)),
        Arc::new(StringArray::from(unit)),
        Arc::new(Float64Array::from(value)),
    ];
    Ok(RecordBatch::try_new(Arc::new(schema), columns)?)
}

/// What `randomization.json` and `.yaml` hold.
fn randomization(identified: &Model, sampled: &Sampled, md: &[(&str, String)]) -> serde_json::Value {
    let (parameters, correlation) = (&sampled.parameters, &sampled.correlation);
    use serde_json::json;
    let finite = |x: f64| if x.is_finite() { json!(x) } else { json!(null) };
    let rows: Vec<Vec<serde_json::Value>> = (0..correlation.nrows())
        .map(|a| (0..correlation.ncols()).map(|b| finite(correlation[(a, b)])).collect())
        .collect();
    json!({
        "robot": identified.name,
        "provenance": md.iter().map(|(k, v)| (k.to_string(), json!(v))).collect::<serde_json::Map<_, _>>(),
        "distribution": "base parameters drawn from N(the estimate's bodies' base parameters, the estimate's covariance); each draw made bodies by the standard-parameter step of least a-priori size from the estimate's own (what the data cannot tell stays the robot file's), or, where that is no body a robot can have, by the estimate's bounded fit (projected_draws); value: the estimate's own bodies (the exported model); mean and std over the draws; std 0: the quantity moves no torque (the data cannot tell it)",
        "drawn_std_over_covariance": [sampled.drawn_std_ratio.0, sampled.drawn_std_ratio.1],
        "projected_draws": sampled.projected,
        "projected_by_joint": sampled.projected_by_joint.iter().map(|(j, n)| (j.clone(), json!(n))).collect::<serde_json::Map<_, _>>(),
        "bounded_fit_moved_chi2": sampled.moved,
        "bounded_fit_moved": moved_said(sampled.moved, sampled.centre.len()),
        "parameters": parameters.iter().map(|p| json!({
            "name": p.name, "joint": p.joint, "quantity": p.quantity, "unit": p.unit,
            "value": p.value, "mean": p.mean, "std": p.std,
        })).collect::<Vec<_>>(),
        "correlation": {"names": parameters.iter().map(|p| p.name.clone()).collect::<Vec<_>>(), "matrix": rows},
    })
}

/// `v` as block YAML (objects and lists of objects as blocks, lists of
/// scalars in flow style, strings double-quoted as JSON writes them).
fn yaml(v: &serde_json::Value, indent: usize) -> String {
    use serde_json::Value;
    let pad = " ".repeat(indent);
    let scalar = |v: &Value| match v {
        Value::Array(a) if a.iter().all(|x| !x.is_object() && !x.is_array()) => Some(v.to_string()),
        Value::Object(_) | Value::Array(_) => None,
        other => Some(other.to_string()),
    };
    match v {
        Value::Object(m) => m
            .iter()
            .map(|(k, x)| match scalar(x) {
                Some(s) => format!("{pad}{k}: {s}\n"),
                None => format!("{pad}{k}:\n{}", yaml(x, indent + 2)),
            })
            .collect(),
        Value::Array(a) => a
            .iter()
            .map(|x| match scalar(x) {
                Some(s) => format!("{pad}- {s}\n"),
                None => {
                    let inner = yaml(x, indent + 2);
                    format!("{pad}- {}", inner.trim_start())
                }
            })
            .collect(),
        other => format!("{pad}{other}\n"),
    }
}

/// One model file per draw and format (`draw_00000.urdf`, `.xml`).
fn model_files(args: &Sample, robot: &Robot, dir: &Path, models: &[(u32, Model)]) -> Result<Vec<PathBuf>> {
    // Read once: the carried links' shares are the robot file's.
    let user = match (args.formats.contains(&Format::Urdf), models.first()) {
        (true, Some((_, m))) => crate::export::user_urdf(robot, m)?,
        _ => None,
    };
    let user_mjcf = match (args.formats.contains(&Format::Mjcf), models.first()) {
        (true, Some((_, m))) => crate::export::user_mjcf(args.mjcf.as_deref(), m)?,
        _ => None,
    };
    let mut files = Vec::new();
    for (k, m) in models {
        let note = format!("robotid sample: draw {k} of {} (seed {})", args.draws, args.seed);
        for f in &args.formats {
            let (ext, text) = match f {
                Format::Urdf => match &user {
                    Some(user) => (
                        "urdf",
                        user.apply(m, &note)
                            .map_err(|p| crate::export::patch_error(&args.robot, p))?
                            .0,
                    ),
                    None => ("urdf", to_urdf(m, &note)),
                },
                Format::Mjcf => match &user_mjcf {
                    Some(user) => (
                        "xml",
                        user.apply(m, &note)
                            .map_err(|p| crate::export::mjcf_error(args.mjcf.as_deref().unwrap_or(Path::new("")), p))?
                            .0,
                    ),
                    None => ("xml", to_mjcf(m, &note)),
                },
                Format::Sidecar => continue,
            };
            let file = PathBuf::from(format!("draw_{k:05}.{ext}"));
            write_text(&dir.join(&file), &text)?;
            files.push(file);
        }
    }
    Ok(files)
}
