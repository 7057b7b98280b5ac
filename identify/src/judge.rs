//! identify's estimate judged: least squares, its verdict, the
//! physically consistent fit and what is refused.

use std::path::{Path, PathBuf};

use crate::design::{Design, Found};
use robotid::validation::Validated;
use robotid::verdict::{channel_gains, Measured, Refusal, Verdict};
use robotid::Observer;
use robotid_report::export::{Export, Format};
use robotid_stages::estimation::{Covariance, Estimate, Estimator, System};
use robotid_stages::stage::estimate::{EstimateConfig, Outcome, Part};

use crate::recordings::Paths;
use crate::script::Script;
use crate::work::{chain, io};
use crate::{Error, Physical, Recording, Request, Result};

/// The physical fit, or why there is none, and the verdict on what is
/// exported. Refused (and not written anyway: marked INADEQUATE.txt) for a
/// measured cause before any fit; a held-out relative error over the
/// tolerance is judged on the estimate exported, the physically consistent
/// one where it is validated (its bounded bodies extrapolate to a record
/// the least squares' free directions do not: the real KUKA LWR4+'s file 3
/// at 5.7 % against 9.4 %), and the least squares' table marked again.
pub(crate) fn physical_or_why(
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
    exported(fitted, (staged, paths), tables, script)
}

/// The physical fit exported for simulators (URDF, MJCF, sidecar), and its
/// commands added to the script.
fn exported(
    fitted: Fit,
    (staged, paths): (&Path, &Paths),
    (id_tables, val_tables): (&[PathBuf], &[PathBuf]),
    script: &mut Script,
) -> Result<Physical> {
    match fitted {
        Fit::Failed(why) => Ok(Physical::Failed(why)),
        Fit::Fitted {
            outcome,
            fallback,
            validation,
        } => {
            let export = robotid_report::export::export(&Export {
                robot: paths.robot_file.clone(),
                parameters: PHYSICAL.into(),
                formats: vec![Format::Urdf, Format::Mjcf, Format::Sidecar],
                out: "identified".into(),
                prior_weight: None,
                force: false,
                within: staged.to_path_buf(),
                mjcf: paths.mjcf.clone(),
            })?;
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

/// The least-squares estimate, judged.
pub(crate) struct Judged {
    /// The tables' rows reduced once: the estimate and its physical fit
    /// share them.
    pub(crate) parts: Vec<Part>,
    pub(crate) outcome: Outcome,
    pub(crate) judge: Judge,
    pub(crate) verdict: Verdict,
    pub(crate) refused: Option<String>,
    pub(crate) unjudged: Vec<String>,
}

/// What the verdict reads: the identification's rows (its residue by
/// speed) and the validation's (the held-out relative error), else the
/// held-out periods' relative error.
pub(crate) struct Judge {
    pub(crate) policy: robotid::verdict::Policy,
    pub(crate) id_rows: System,
    pub(crate) val_rows: Option<System>,
    pub(crate) periods_relative: Option<f64>,
    /// Else a block held out in time (fewer than two steady periods).
    pub(crate) split_relative: Option<f64>,
    /// Every identification record has steady periods that repeat: its
    /// noise floor comes from their spread.
    pub(crate) repeated: bool,
    /// The effort channels' gains, fitted once: on the validation rows
    /// where they tell them (a record compared sample by sample; the
    /// identification's may be its excited lines alone, as many equations
    /// as a few parameters more than the model's, which a scale is lost
    /// in), else on the identification's.
    pub(crate) channels: Option<robotid::verdict::ChannelGains>,
}

impl Judge {
    pub(crate) fn verdict(&self, est: &Estimate) -> Verdict {
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
    pub(crate) fn judged(&self, est: &Estimate, held_out: Option<(f64, Measured)>) -> Verdict {
        robotid::verdict::judge(self.policy, est, &self.id_rows, held_out, self.channels.clone())
    }

    /// Why `verdict` refuses, with what identify found on the way.
    pub(crate) fn refused(&self, verdict: &Verdict, recordings: &[Recording]) -> Option<String> {
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
    pub(crate) fn rejudge(&mut self, held_out: (f64, Measured), recordings: &[Recording], table: &Path) -> Result<()> {
        self.verdict = self.judge.judged(&self.outcome.estimate, Some(held_out));
        self.refused = self.judge.refused(&self.verdict, recordings);
        let marks = marks(&self.verdict);
        robotid::tables::write_marked(&self.outcome, table, Some(&|_: &Outcome| marks.clone()))?;
        Ok(())
    }
}

/// The estimate (`parameters.parquet`, marked with its verdict), and why
/// it is refused.
pub(crate) fn estimate(
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
        Some((&paths.robot_file, &locks)),
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
pub(crate) fn validate(staged: &Path, parameters: &str, tables: &[PathBuf], held: &[PathBuf]) -> Result<Validated> {
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
pub(crate) enum Fit {
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
        let reducer = robotid::tables::reducer(&estimate_config(covariance, true), Some((&paths.robot_file, &locks)))?;
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
