"""Identification on a local Ray cluster equals `robotid run`."""

import os

import pyarrow.parquet as pq
import pytest

from conftest import PER_ROBOT, robotid as cli
from test_package import largest_relative_difference

# Skipped where Ray is not installed, but not under CI, which installs it:
# there a missing Ray fails rather than passing vacuously.
if os.environ.get("CI"):
    import ray
else:
    ray = pytest.importorskip("ray")
import robotid.ray  # noqa: E402


@pytest.fixture(scope="module")
def local_ray():
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    yield
    ray.shutdown()


def test_ray_identify_equals_the_command_line_for_two_robots(fleet, local_ray, tmp_path):
    recordings = fleet["recordings"]
    assert len(recordings) == 2 * PER_ROBOT
    expected = {}
    for robot, pipeline in fleet["pipelines"].items():
        cli("run", pipeline, "--out", tmp_path / robot)
        expected[robot] = pq.read_table(tmp_path / robot / "parameters.parquet")
    # Two partitionings: one recording per task, and five.
    for per_task in [1, 5]:
        found = robotid.ray.identify(recordings[::-1], fleet["pipelines"], summaries_per_task=per_task)
        assert sorted(found) == ["arm3", "ur5"]
        for robot, table in found.items():
            d = largest_relative_difference(table, expected[robot])
            print(f"{robot}, {per_task} per task: largest relative difference {d:.1e}")
            assert d < 1e-10, (robot, d)


def test_a_recording_without_a_pipeline_is_refused(fleet):
    with pytest.raises(robotid.RobotidError, match="has no pipeline"):
        robotid.ray.identify(fleet["recordings"][:1], {"ur5": fleet["pipelines"]["ur5"]})


def test_a_missing_recording_is_a_robotid_error(fleet, local_ray, tmp_path):
    missing = str(tmp_path / "robot=ur5" / "gone.mcap")
    with pytest.raises(robotid.RobotidError) as e:
        robotid.ray.identify([missing], fleet["pipelines"])
    assert type(e.value) is robotid.RobotidError and e.value.file == missing, repr(e.value)


def test_identify_robots_runs_identify_per_robot_as_the_command_line(examples, local_ray, tmp_path):
    """Two robots of a fleet identified in two Ray tasks: each folder holds
    the command line's files byte for byte (same paths: they are written
    into the tables), and a refused one is a result."""
    from test_identify import files

    rec = examples / "recordings"
    axis3 = {
        "recordings": [rec / "kuka_axis3" / "kuka_axis3.mcap"],
        "robot": examples / "robots" / "kuka_axis3.toml",
        "validate": [rec / "kuka_axis3_validation" / "kuka_axis3_validation.mcap"],
    }
    strict = dict(axis3, tolerance=1e-4)
    out = tmp_path / "fleet"
    expected = {}
    for name, extra in [("axis3", []), ("axis3_strict", ["--tolerance", "0.0001"])]:
        args = [*axis3["recordings"], "--robot", axis3["robot"], "--validate", *axis3["validate"]]
        done = cli("identify", *args, "--out", out / name, *extra, check=False)
        assert done.returncode == (0 if not extra else 3), done.stderr
        expected[name] = files(out / name)
    import shutil

    shutil.rmtree(out)
    results = robotid.ray.identify_robots({"axis3": axis3, "axis3_strict": strict}, out)
    assert sorted(results) == ["axis3", "axis3_strict"]
    for name in results:
        assert files(out / name) == expected[name], name
    assert results["axis3"]["identified"] and results["axis3"]["physical"] is not None
    assert not results["axis3_strict"]["identified"]
    assert "over the tolerance" in results["axis3_strict"]["refused"]
