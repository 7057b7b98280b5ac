"""Identification on Ray Data: recordings are summarized in parallel
(`Pipeline.summarize`), the summaries of each group merged by an
aggregation whose combine step is `robotid.merge`, and each group solved
(`robotid.solve`). The parameters equal `robotid run`'s on the same
recordings to round-off, for any partitioning.

    import ray, robotid.ray
    ray.init()                                   # or ray.init(address="auto")
    params = robotid.ray.identify(
        ["fleet/robot=arm3/r01.parquet", "fleet/robot=ur5/r01.parquet", ...],
        {"arm3": "pipelines/arm3.toml", "ur5": "pipelines/ur5.toml"},
    )                                            # {"arm3": pyarrow.Table, "ur5": ...}

Or `robotid identify` for each robot of a fleet, one Ray task each:

    results = robotid.ray.identify_robots(
        {"arm_a": {"recordings": ["a/excitation.mcap"], "robot": "a/robot.urdf",
                   "validate": ["a/validation.mcap"]},
         "arm_b": {"recordings": ["b/excitation.mcap"], "robot": "b/robot.urdf"}},
        out="out/fleet",
    )                                            # {"arm_a": {"identified": True, ...}, ...}

Workers read the recordings and pipeline files by path: on a cluster the
paths must be visible to every node (a shared file system).
"""

from __future__ import annotations

import functools
import os
import re
from typing import Dict, Iterable, Mapping, Optional, Union

import pyarrow as pa

from . import Pipeline, RobotidError, merge, solve
from . import identify as _identify

PathLike = Union[str, "os.PathLike[str]"]


@functools.lru_cache(maxsize=16)
def _pipeline(path: str) -> Pipeline:
    """One built pipeline per worker process and file."""
    return Pipeline.from_path(path)


def _ipc(batch: pa.RecordBatch) -> bytes:
    sink = pa.BufferOutputStream()
    with pa.ipc.new_stream(sink, batch.schema) as w:
        w.write_batch(batch)
    return sink.getvalue().to_pybytes()


def _from_ipc(data: bytes) -> pa.RecordBatch:
    return pa.ipc.open_stream(data).read_next_batch()


def group_of(path: PathLike, key: str = "robot") -> Optional[str]:
    """The value of a hive-style folder `key=value` in `path`, if any."""
    m = re.search(rf"(?:^|[/\\]){re.escape(key)}=([^/\\]+)", os.fspath(path))
    return m.group(1) if m else None


def _summarize(batch: pa.Table, group_by: str) -> pa.Table:
    rows = []
    for key, path, pipeline in zip(
        batch[group_by].to_pylist(), batch["path"].to_pylist(), batch["pipeline"].to_pylist()
    ):
        s = _pipeline(pipeline).summarize(path)
        t = pa.Table.from_batches([s])
        rows.append(t.append_column(group_by, pa.array([key], pa.string())))
    return pa.concat_tables(rows)


def _robotid_error_in(e: BaseException) -> Optional[RobotidError]:
    """The RobotidError in `e`'s chain of causes (Ray's task errors keep
    theirs in `cause`), if any."""
    seen = set()
    while e is not None and id(e) not in seen:
        seen.add(id(e))
        if type(e) is RobotidError:
            return e
        e = getattr(e, "cause", None) or e.__cause__
    return None


def _merge_summaries():
    from ray.data.aggregate import AggregateFnV2
    from ray.data.block import BlockAccessor

    class MergeSummaries(AggregateFnV2):
        """Summaries merged by `robotid.merge`; the accumulator is the
        merged one-row summary as Arrow IPC bytes (b"" before any)."""

        def __init__(self):
            # The `summary` column alone merges (it holds what made it).
            super().__init__("summary", zero_factory=lambda: b"", on="summary", ignore_nulls=False)

        def aggregate_block(self, block) -> bytes:
            table = BlockAccessor.for_block(block).to_arrow().select(["summary"])
            return _ipc(merge(table.to_batches()))

        def combine(self, current: bytes, new: bytes) -> bytes:
            if not current:
                return new
            if not new:
                return current
            return _ipc(merge([_from_ipc(current), _from_ipc(new)]))

        def finalize(self, accumulator: bytes) -> bytes:
            return accumulator

    return MergeSummaries()


def identify(
    recordings: Iterable[PathLike],
    pipelines: Union[PathLike, Mapping[str, PathLike]],
    group_by: str = "robot",
    *,
    summaries_per_task: int = 1,
) -> Dict[str, pa.Table]:
    """The `parameters` table of each group of recordings.

    A recording's group is the value of its `group_by=value` folder
    (hive-style), else the only pipeline's. `pipelines` maps each group to
    its pipeline file, or is one pipeline file for every recording."""
    import ray.data
    import ray.data.context

    if isinstance(pipelines, Mapping):
        files = {k: os.path.abspath(os.fspath(v)) for k, v in pipelines.items()}
    else:
        files = None
        single = os.path.abspath(os.fspath(pipelines))
    items = []
    for r in recordings:
        path = os.path.abspath(os.fspath(r))
        key = group_of(path, group_by)
        if files is None:
            key = key if key is not None else "all"
            pipeline = single
        else:
            if key is None and len(files) == 1:
                key = next(iter(files))
            if key not in files:
                raise RobotidError(
                    f"{path}: group {key!r} has no pipeline (given for: {', '.join(sorted(files))}); "
                    f"put the recording under a `{group_by}=<name>` folder"
                )
            pipeline = files[key]
        items.append({group_by: key, "path": path, "pipeline": pipeline})
    if not items:
        raise RobotidError("no recordings given")
    # One shuffle partition per group (a group's summaries are a few small
    # rows), and the sort-based shuffle: the default hash shuffle starts
    # aggregator actors, seconds on a small cluster for kilobytes of data.
    # A dataset takes the context current when it is made.
    groups = len({it[group_by] for it in items})
    ctx = ray.data.DataContext.get_current()
    strategy, original = ctx.shuffle_strategy, ctx.raise_original_map_exception
    ctx.shuffle_strategy = ray.data.context.ShuffleStrategy.SORT_SHUFFLE_PULL_BASED
    # A worker's RobotidError kept as the task error's cause (not wrapped
    # in a UserCodeException, whose cause is lost on the way).
    ctx.raise_original_map_exception = True
    try:
        ds = ray.data.from_items(items, override_num_blocks=-(-len(items) // summaries_per_task))
        summaries = ds.map_batches(
            _summarize, fn_kwargs={"group_by": group_by}, batch_format="pyarrow", batch_size=None
        )
        merged = summaries.groupby(group_by, num_partitions=groups).aggregate(_merge_summaries()).take_all()
    except Exception as e:
        # A worker's RobotidError (a missing or bad recording) reaches the
        # driver wrapped in Ray's task errors: raised as itself, with its
        # file, channel, sample and stage.
        raise _robotid_error_in(e) or e
    finally:
        ctx.shuffle_strategy, ctx.raise_original_map_exception = strategy, original
    pipeline_of = {it[group_by]: it["pipeline"] for it in items}
    out = {}
    for row in merged:
        key = row[group_by]
        out[key] = solve(_from_ipc(row["summary"]), _pipeline(pipeline_of[key]))
    return dict(sorted(out.items()))


def _identify_one(name: str, request: dict, out: str) -> dict:
    """One robot identified in a Ray task: what `robotid.identify` returns,
    as plain values (pyarrow tables travel as they are)."""
    r = _identify(out=os.path.join(out, name), **request)
    return {
        "out": os.fspath(r.out),
        "identified": r.identified,
        "refused": r.refused,
        "verdict": r.verdict,
        "relative_error": r.relative_error,
        "measured": r.measured,
        "parameters": r.parameters,
        "physical": r.physical,
        "exports": [os.fspath(e) for e in r.exports],
    }


def identify_robots(robots: Mapping[str, Mapping], out: PathLike) -> Dict[str, dict]:
    """`robotid identify` for each robot, one Ray task each, into
    `out/<name>`: `robots` maps a name to the keyword arguments of
    `robotid.identify` (`recordings` and `robot`, and optionally
    `validate`, `tolerance`, `strict`, `accept_inadequate`,
    `torque_per_amp`, `mjcf`). Each folder holds what `robotid identify` writes;
    the result per robot is what `robotid.identify` returns, as a dict.
    A refused fit is a result (`identified` False); an error is raised as
    the worker's `RobotidError`."""
    import ray

    out = os.path.abspath(os.fspath(out))
    task = ray.remote(_identify_one)
    names = sorted(robots)
    refs = []
    for name in names:
        request = {k: v for k, v in robots[name].items()}
        request["recordings"] = [os.path.abspath(os.fspath(p)) for p in request["recordings"]]
        request["robot"] = os.path.abspath(os.fspath(request["robot"]))
        if request.get("mjcf") is not None:
            request["mjcf"] = os.path.abspath(os.fspath(request["mjcf"]))
        if "validate" in request:
            request["validate"] = [os.path.abspath(os.fspath(p)) for p in request["validate"]]
        refs.append(task.remote(name, request, out))
    try:
        return dict(zip(names, ray.get(refs)))
    except Exception as e:
        raise _robotid_error_in(e) or e
