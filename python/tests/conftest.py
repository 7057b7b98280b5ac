"""Shared fixtures: the repository, the robotid binary, and a small fleet
of simulated recordings of two robots (made once per test session)."""

import os
import pathlib
import re
import shutil
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
FIXTURES = ROOT / "fixtures"
PER_ROBOT = 12


def robotid_bin() -> str:
    if "ROBOTID_BIN" in os.environ:
        return os.environ["ROBOTID_BIN"]
    target = os.environ.get("CARGO_TARGET_DIR", str(ROOT / "target"))
    return os.path.join(target, "debug", "robotid")


def robotid(*args, check=True):
    return subprocess.run([robotid_bin(), *map(str, args)], capture_output=True, text=True, check=check)


PIPELINE_TAIL = """
[[stage]]
kind = "regressor"
friction = "symmetric"

[[stage]]
kind = "estimate"
method = "ols"

[output]
tables = ["kinematics"]
"""


def _pipeline(robot: str, fleet: pathlib.Path) -> pathlib.Path:
    """The fixture pipeline of `robot`, reading the fleet's recordings, with
    a regressor and an estimate."""
    text = (FIXTURES / "pipelines" / f"{robot}.toml").read_text()
    text = text.split("[output]")[0]
    text = re.sub(r'robot = "[^"]*"', f'robot = "{FIXTURES / "robots" / (robot + ".toml")}"', text, count=1)
    text = re.sub(r'(\[source\]\s*\npath = )"[^"]*"', rf'\1"robot={robot}/{robot}_[0-9][0-9].parquet"', text)
    path = fleet / f"{robot}.toml"
    path.write_text(text + PIPELINE_TAIL)
    return path


def make_fleet(root: pathlib.Path, per_robot: int, periods: int = 0) -> dict:
    """`per_robot` arm3 and UR5 recordings (own seeds) under `root` in
    hive-style folders, and a pipeline per robot:
    {"root", "recordings": [...], "pipelines": {robot: path}}. `periods`
    (when given) replaces the example simulations' 4 periods."""
    recordings = []
    for robot in ["arm3", "ur5"]:
        sim = (FIXTURES / "sims" / f"{robot}.toml").read_text()
        sim = re.sub(r'robot = "[^"]*"', f'robot = "{FIXTURES / "robots" / (robot + ".toml")}"', sim, count=1)
        for i in range(per_robot):
            name = f"{robot}_{i:02d}"
            text = re.sub(r"^seed = \d+", f"seed = {1000 + i}", sim, flags=re.M)
            if periods:
                text = re.sub(r"^periods = \d+", f"periods = {periods}", text, flags=re.M)
            text = re.sub(r'^name = "[^"]*"', f'name = "{name}"\nformats = ["parquet"]', text, flags=re.M)
            cfg = root / "sims" / f"{name}.toml"
            cfg.parent.mkdir(exist_ok=True)
            cfg.write_text(text)
            robotid("simulate", cfg, "--out", root / f"robot={robot}")
            recordings.append(root / f"robot={robot}" / f"{name}.parquet")
    pipelines = {r: _pipeline(r, root) for r in ["arm3", "ur5"]}
    return {"root": root, "recordings": recordings, "pipelines": pipelines}


@pytest.fixture(scope="session")
def fleet(tmp_path_factory):
    """12 arm3 and 12 UR5 recordings (own seeds), hive-style folders, and a
    pipeline per robot."""
    return make_fleet(tmp_path_factory.mktemp("fleet"), PER_ROBOT)


@pytest.fixture(scope="session")
def examples(tmp_path_factory):
    """A copy of fixtures/ (robots, pipelines, sims) with the example
    recordings the tests use simulated into recordings/ (they are not
    committed): the folder, whose pipelines/ run as they are."""
    root = tmp_path_factory.mktemp("examples")
    for sub in ["robots", "pipelines", "sims"]:
        shutil.copytree(FIXTURES / sub, root / sub)
    for sim in ["kuka_axis3", "kuka_axis3_validation", "arm3"]:
        robotid("simulate", root / "sims" / f"{sim}.toml", "--out", root / "recordings" / sim)
    return root
