"""robotid from Python: dynamic identification of robot arms.

A pipeline file (docs/pipeline-file.md) says how recordings become
regressor rows and an estimate. From Python:

    import robotid
    p = robotid.Pipeline.from_path("fixtures/pipelines/kuka_axis3.toml")
    tables = p.run_recording(p.recordings[0])        # {"kinematics": pyarrow.Table, ...}
    parts = [p.summarize(r) for r in p.recordings]   # one row each
    parameters = robotid.solve(robotid.merge(parts), p)

Or from recordings and a robot file alone, as `robotid identify` (the same
files in `out`, the verdict and tables returned):

    result = robotid.identify(["excitation.mcap"], "robot.urdf", validate=["validation.mcap"], out="out/id")
    result.identified, result.refused, result.parameters  # pyarrow.Table

A payload against a robot identified before (its parameters table):

    table = robotid.payload(["loaded.mcap"], "robot.urdf", "out/id/parameters.parquet", "tool0", "out/payload")

A model judged by simulation error (its forward dynamics driven by the
measured torque, from the measured state, every `window_s` restarted):

    errors = robotid.rollout("out/id/parameters.parquet", "robot.urdf",
                             ["out/id/validation/validation/regressor.parquet"])

and in closed loop, under the controller a recording declares, tracking
its recorded reference (`robotid.closed_loop`).

`summarize` is the map and `merge` the reduce of identification: summaries
merge in any grouping, on any machine, and solve to the parameters
`robotid run` estimates from the same recordings (robotid.ray runs it on a
Ray cluster). Errors are `RobotidError`, with `file`, `channel`, `sample`
and `stage` saying where.
"""

from __future__ import annotations

from typing import Sequence, Union

import pyarrow as pa

from ._robotid import (
    Identification,
    Pipeline,
    RobotidError,
    __version__,
    closed_loop,
    identify,
    merge,
    payload,
    rollout,
    sample,
)

# Pickled by this name (a Ray worker's error reaches the driver so), it
# comes back as this very class, its file, channel, sample and stage kept.
RobotidError.__module__ = "robotid"

Summaries = Union[pa.RecordBatch, pa.Table, Sequence[pa.RecordBatch]]


def solve(summaries: Summaries, pipeline: Pipeline) -> pa.Table:
    """The `parameters` table from summaries made by `pipeline` (merged in
    the order given): values, standard deviations, intervals and the
    covariance, as `robotid run` writes them."""
    if isinstance(summaries, tuple):
        summaries = list(summaries)
    return pipeline.solve(summaries)


__all__ = ["Identification", "Pipeline", "RobotidError", "closed_loop", "identify", "merge", "payload", "rollout", "sample", "solve", "__version__"]
