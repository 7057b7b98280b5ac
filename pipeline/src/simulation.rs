//! Every simulation an identification or a report asks for, run in one
//! place and returned as values: the estimate's and the robot file's
//! rollouts, the physically consistent estimate's in the same windows, the
//! export's in MuJoCo and the closed loop. Pages only draw what this
//! returns (`robotid-report` runs none of it).

use std::path::{Path, PathBuf};

use robotid_stages::dynamics::Robot;

use crate::validation::{ClosedLoopRun, RolledOut};

/// A rollout, or where it stopped.
pub type Rollout = std::result::Result<robotid_stages::dynamics::Rollout, robotid_stages::dynamics::Stopped>;

/// Per record, the estimate's and the robot file's rollouts (None: not
/// asked for, or no robot file; Err: why not, as the page says).
pub type Rolled = Option<crate::Result<Vec<RolledOut>>>;

/// What ran in closed loop, as [`Rolled`].
pub type ClosedLooped = Option<crate::Result<Vec<ClosedLoopRun>>>;

/// Per record, MuJoCo's rollout or why there is none.
pub type MujocoRuns = [std::result::Result<crate::mujoco::MujocoRollout, crate::mujoco::MujocoError>];

/// What was rolled out in MuJoCo, per record of [`Rolled`] (None: not
/// asked for, or nothing rolled out; Err: why not).
pub type InMujoco = Option<Vec<std::result::Result<crate::mujoco::MujocoRollout, crate::mujoco::MujocoError>>>;

/// The physically consistent estimate rolled out on each record of
/// [`Rolled`] in its windows (None: no physical estimate, or nothing
/// rolled out; Err: why not, for every record).
pub type PhysicalRolled = Option<crate::Result<Vec<Rollout>>>;

/// What was simulated.
pub struct Simulated {
    pub rolled: Rolled,
    pub closed_loop: ClosedLooped,
    pub mujoco: InMujoco,
    /// The physically consistent estimate rolled out as `rolled`'s
    /// records were.
    pub physical: PhysicalRolled,
}

impl Simulated {
    /// Nothing simulated.
    pub fn nothing() -> Simulated {
        Simulated {
            rolled: None,
            closed_loop: None,
            mujoco: None,
            physical: None,
        }
    }

    /// The same, with the files under `from` (a staging folder) named
    /// under `to` (where it is committed): in the runs and in what failed.
    pub fn relocated(self, from: &Path, to: &Path) -> Simulated {
        fn err<'a, T>(from: &'a Path, to: &'a Path) -> impl Fn(crate::Result<T>) -> crate::Result<T> + 'a {
            move |r| {
                r.map_err(|mut e| {
                    e.relocate(from, to);
                    e
                })
            }
        }
        Simulated {
            rolled: self.rolled.map(err(from, to)),
            closed_loop: self.closed_loop.map(|runs| {
                err(from, to)(runs).map(|mut runs| {
                    for r in &mut runs {
                        robotid_stages::relocate_path(&mut r.recording, from, to);
                    }
                    runs
                })
            }),
            mujoco: self.mujoco,
            physical: self.physical.map(err(from, to)),
        }
    }
}

/// What to simulate; every path under `within`.
pub struct Asked<'a> {
    pub within: &'a Path,
    /// The parameters table rolled out and run in closed loop.
    pub parameters: &'a Path,
    /// A physically consistent estimate, rolled out in the same windows.
    pub physical: Option<&'a Path>,
    /// The robot file, read (nothing is simulated without one).
    pub robot: Option<&'a Robot>,
    /// The regressor tables to roll out on (None: no rollouts), over
    /// windows chosen from each record's noise
    /// ([`crate::validation::rollouts`]).
    pub rollout_on: Option<&'a [PathBuf]>,
    /// The exported MJCF and the Python that runs MuJoCo: rolled out on
    /// every record `rollout_on` rolls out on, in the same windows.
    pub mujoco: Option<(&'a Path, &'a Path)>,
    /// The controller (a TOML file's `[controller]` table) and the raw
    /// tables holding the references it tracked.
    pub closed_loop: Option<(&'a Path, &'a [PathBuf])>,
}

/// Everything `asked` names, simulated. What cannot be simulated is said
/// in its place (an Err), not fatal to the rest.
pub fn simulate(asked: &Asked) -> Simulated {
    let within = |p: &Path| asked.within.join(p);
    let rolled = match (asked.robot, asked.rollout_on) {
        (Some(robot), Some(tables)) => Some(crate::validation::rollouts(
            asked.within,
            asked.parameters,
            robot,
            tables,
            None,
        )),
        _ => None,
    };
    let mujoco: InMujoco = match (&rolled, asked.mujoco) {
        (Some(Ok(rolled)), Some((mjcf, python))) => Some(
            rolled
                .iter()
                .map(|r| crate::mujoco::rollout(python, &within(mjcf), &within(&r.table), r.window_s))
                .collect(),
        ),
        _ => None,
    };
    // The physical estimate rolled out in the estimate's windows.
    let physical: PhysicalRolled = match (&rolled, asked.physical, asked.robot) {
        (Some(Ok(rolled)), Some(physical), Some(robot)) => {
            Some(crate::validation::rolled_alike(asked.within, physical, robot, rolled))
        }
        _ => None,
    };
    let closed_loop = match (asked.robot, asked.closed_loop) {
        (Some(robot), Some((controller, tables))) => {
            let tables: Vec<PathBuf> = tables.iter().map(|t| within(t)).collect();
            Some(crate::validation::closed_loop_rollouts(
                &within(asked.parameters),
                robot,
                &tables,
                &within(controller),
            ))
        }
        _ => None,
    };
    Simulated {
        rolled,
        closed_loop,
        mujoco,
        physical,
    }
}
