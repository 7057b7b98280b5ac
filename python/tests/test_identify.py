"""`robotid.identify` against `robotid identify`: the same library call, so
the same files byte for byte, and the same verdict."""

import pathlib
import shutil
import sysconfig

import pyarrow.parquet as pq
import pytest

import robotid
from conftest import robotid as cli

SHARED = pathlib.Path(__file__).resolve().parents[3] / "shared"


def files(root: pathlib.Path) -> dict:
    """Every file under `root` (robotid's hidden bookkeeping aside) by its
    path relative to it."""
    return {
        p.relative_to(root): p.read_bytes()
        for p in sorted(root.rglob("*"))
        if p.is_file() and not any(part.startswith(".robotid") for part in p.relative_to(root).parts)
    }


def identify_both(tmp_path, recordings, robot, validate, exit_code=0):
    """identify from the command line and from Python into the same
    folder (paths are written into the tables): both folders' files and
    the Python result."""
    out = tmp_path / "out"
    args = [*recordings, "--robot", robot, "--out", out]
    if validate:
        args += ["--validate", *validate]
    done = cli("identify", *args, check=False)
    assert done.returncode == exit_code, done.stderr
    by_cli = files(out)
    shutil.rmtree(out)
    result = robotid.identify(recordings, robot, validate=validate, out=out)
    # The same warnings, as values.
    warned = [line for line in done.stderr.splitlines() if line.startswith("warning: ")]
    assert warned == [f"warning: {w}" for w in result.warnings], (warned, result.warnings)
    return by_cli, files(out), result


def test_a_read_file_from_python_as_from_the_command_line(examples, tmp_path):
    """`read=` is `--read`: a log whose columns robotid cannot place by
    name (`stamp`, `angle1`…, `amps1`…), placed by a `[read]` table;
    the same files byte for byte."""
    text = (examples / "recordings" / "arm3" / "arm3.csv").read_text()
    header, body = text.split("\n", 1)
    names = {"time": "stamp"}
    for j in "123":
        names |= {f"q_j{j}": f"angle{j}", f"current_j{j}": f"amps{j}", f"ref_j{j}": f"goal{j}", f"counts_j{j}": f"ticks{j}"}
    log = tmp_path / "arm3.csv"
    log.write_text(",".join(names.get(c, c) for c in header.split(",")) + "\n" + body)
    read = tmp_path / "read.toml"
    read.write_text(
        '[read]\ntime = { column = "stamp", unit = "s" }\n'
        'position = { column = "angle{index}", unit = "rad" }\n'
        'effort = { column = "amps{index}", unit = "A" }\n'
    )
    robot = examples / "robots" / "arm3.toml"
    out = tmp_path / "out"
    cli("identify", log, "--robot", robot, "--read", read, "--out", out)
    by_cli = files(out)
    shutil.rmtree(out)
    result = robotid.identify([log], robot, out=out, read=read)
    assert result.identified
    assert files(out) == by_cli
    # A controller that cannot be run on the record (its references are
    # named `goal{index}`, which `[read]` does not place) is a warning, as
    # the command line's, not an error after the files are written.
    controller = examples / "recordings" / "arm3" / "arm3.truth.toml"
    held = tmp_path / "held.csv"
    held.write_text("\n".join(log.read_text().splitlines()[:-1]) + "\n")
    looped_out = tmp_path / "looped"
    done = cli("identify", log, "--robot", robot, "--read", read, "--validate", held, "--controller", controller,
               "--out", looped_out)
    warned = [line for line in done.stderr.splitlines() if line.startswith("warning: ")]
    by_cli = files(looped_out)
    shutil.rmtree(looped_out)
    looped = robotid.identify([log], robot, validate=[held], out=looped_out, read=read, controller=controller)
    assert looped.closed_loop is None
    assert files(looped_out) == by_cli
    # Said where the file is, not where identify staged it.
    why = [w for w in looped.warnings if w.startswith("not run in closed loop: ")]
    assert why and why[0].startswith(f"not run in closed loop: {looped_out / 'held'}"), looped.warnings
    assert warned == [f"warning: {w}" for w in looped.warnings], (warned, looped.warnings)
    with pytest.raises(robotid.RobotidError, match="no `\\[read\\]` table"):
        robotid.identify([log], robot, out=tmp_path / "x", read=robot)


def test_identify_from_python_writes_the_command_lines_files(examples, tmp_path):
    rec = examples / "recordings"
    by_cli, by_python, result = identify_both(
        tmp_path,
        [rec / "kuka_axis3" / "kuka_axis3.mcap"],
        examples / "robots" / "kuka_axis3.toml",
        [rec / "kuka_axis3_validation" / "kuka_axis3_validation.mcap"],
    )
    assert sorted(by_cli) == sorted(by_python)
    for f in ["parameters.parquet", "parameters_physical.parquet", "report.html", "identify.sh", "identified.urdf"]:
        assert pathlib.Path(f) in by_cli, f
    different = [str(p) for p in by_cli if by_cli[p] != by_python[p]]
    assert different == []
    assert result.identified and result.refused is None
    assert [r["role"] for r in result.recordings] == ["excitation", "validation"]
    assert result.recordings[0]["periodic"]
    assert result.recordings[0]["pipeline"] == (tmp_path / "out" / "pipelines" / "kuka_axis3.toml").read_text()
    # The tables given are the files written.
    assert result.parameters.equals(pq.read_table(tmp_path / "out" / "parameters.parquet"))
    assert result.physical is not None
    assert sorted(p.suffix for p in map(pathlib.Path, result.exports)) == [".json", ".parquet", ".urdf", ".xml"]
    assert 0 < result.relative_error < 0.05, result.relative_error
    # The verdict judges what is exported: the physically consistent
    # estimate, validated.
    assert result.measured == "on the validation recordings by the physically consistent estimate (the one exported)"
    # Rolled out from Python on the validation record: a row per model,
    # window and joint, in units; the identified model as close to the
    # measured angle as the robot file (the simulation's truth; 1.109×
    # pooled, cli/tests/suite/identify.rs).
    out = tmp_path / "out"
    errors = robotid.rollout(
        out / "parameters.parquet",
        examples / "robots" / "kuka_axis3.toml",
        [out / "kuka_axis3_validation" / "kuka_axis3_validation" / "regressor.parquet"],
        window_s=0.5,
    )
    assert errors.schema.field("q_rms").metadata == {b"unit": b"rad"}
    rows = errors.to_pylist()
    by = {m: [r["q_rms"] for r in rows if r["model"] == m] for m in ("estimate", "robot_file")}
    assert len(by["estimate"]) == len(by["robot_file"]) > 10
    # Pooled over the windows (equal lengths but the last): √mean(rms²).
    pooled = {m: (sum(x * x for x in v) / len(v)) ** 0.5 for m, v in by.items()}
    assert pooled["estimate"] <= 1.15 * pooled["robot_file"], pooled
    # In closed loop under the simulator's declared PID (its truth file),
    # tracking the recorded reference: within 1.3× of the truth (1.245×,
    # cli/tests/suite/identify.rs).
    validation = examples / "recordings" / "kuka_axis3_validation"
    looped = robotid.closed_loop(
        out / "parameters.parquet",
        examples / "robots" / "kuka_axis3.toml",
        [validation / "kuka_axis3_validation.parquet"],
        validation / "kuka_axis3_validation.truth.toml",
    ).to_pylist()
    by = {r["model"]: r["q_rms"] for r in looped}
    assert by["estimate"] <= 1.3 * by["robot_file"], by
    # The same from identify itself, the controller declared: its
    # validation record's raw samples (read from the MCAP, references with
    # them) run in closed loop, the same figures. With `mujoco`, the
    # exported MJCF rolled out by this interpreter's MuJoCo in the windows
    # robotid chose: within 1.5× of robotid's own rollout of the estimate
    # there (the export carries the physical fit, friction as MuJoCo's
    # frictionloss; measured 1.08×), and in the report.
    again = robotid.identify(
        [examples / "recordings" / "kuka_axis3" / "kuka_axis3.mcap"],
        examples / "robots" / "kuka_axis3.toml",
        validate=[validation / "kuka_axis3_validation.mcap"],
        controller=validation / "kuka_axis3_validation.truth.toml",
        mujoco=True,
        out=tmp_path / "with_controller",
    )
    from_identify = {r["model"]: r["q_rms"] for r in again.closed_loop.to_pylist()}
    assert from_identify == pytest.approx(by, rel=1e-9), (from_identify, by)
    assert result.closed_loop is None
    assert {r["model"] for r in result.rollouts.to_pylist()} == {"estimate", "physical", "robot_file"}
    assert again.rollouts.schema.field("q_rms").metadata == {b"unit": b"rad"}
    in_mujoco = [r for r in again.rollouts.to_pylist() if r["model"] == "mujoco"]
    assert [r["joint"] for r in in_mujoco] == ["a3"], in_mujoco
    ours = robotid.rollout(
        tmp_path / "with_controller" / "parameters.parquet",
        examples / "robots" / "kuka_axis3.toml",
        [tmp_path / "with_controller" / "kuka_axis3_validation" / "kuka_axis3_validation" / "regressor.parquet"],
    ).to_pylist()
    windows = [r["q_rms"] for r in ours if r["model"] == "estimate"]
    pooled = (sum(x * x for x in windows) / len(windows)) ** 0.5
    assert pooled / 1.5 <= in_mujoco[0]["q_rms"] <= 1.5 * pooled, (in_mujoco, pooled)
    assert "in MuJoCo (the export)" in (tmp_path / "with_controller" / "report.html").read_text()
    # Domain randomization from Python: the command line's files, byte for
    # byte; each drawn MJCF loads in MuJoCo with the drawn masses.
    physical = out / "parameters_physical.parquet"
    robot = examples / "robots" / "kuka_axis3.toml"
    drawn = robotid.sample(physical, robot, 20, tmp_path / "py_samples", seed=3, formats=["mjcf"])
    cli("sample", "20", "--robot", robot, "-p", physical, "--seed", "3", "--format", "mjcf", "-o", tmp_path / "cli_samples")
    assert files(tmp_path / "py_samples") == files(tmp_path / "cli_samples")
    assert drawn.num_rows == 20 * 13 and set(drawn.column("quantity").to_pylist()) >= {"mass", "damping", "armature"}
    import mujoco

    masses = [r["value"] for r in drawn.to_pylist() if r["quantity"] == "mass"]
    for k in (0, 19):
        model = mujoco.MjModel.from_xml_path(str(tmp_path / "py_samples" / f"draw_{k:05d}.xml"))
        assert abs(model.body_mass[-1] - masses[k]) <= 1e-9 * masses[k], (model.body_mass, masses[k])


def example_robot(path: str) -> pathlib.Path:
    """A URDF of the `example-robot-data` package (scripts/test.sh installs it)."""
    urdf = pathlib.Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix/share/example-robot-data/robots" / path
    if not urdf.is_file():
        pytest.skip(f"{urdf}: example-robot-data is not installed (scripts/test.sh installs it)")
    return urdf


# Records robotid did not make: three of an independent simulator (the
# foreign corpus, truth beside them) and the real LWR4+ (issue 62).
NOT_OURS = {
    "ur5": ("foreign/ur5", "excitation.mcap", ["validation.mcap"], "ur_description/urdf/ur5_robot.urdf"),
    "ur5_lab": ("foreign/ur5_lab", "excitation.mcap", ["validation.mcap"], "ur_description/urdf/ur5_robot.urdf"),
    "panda": ("foreign/panda", "excitation.csv", ["validation.csv"], "panda_description/urdf/panda.urdf"),
    "kuka_lwr4": ("realdata/kuka_lwr4", "measurements_1.csv", ["measurements_2.csv", "measurements_3.csv"], None),
}


@pytest.mark.parametrize("name", sorted(NOT_OURS))
def test_records_robotid_did_not_make_give_the_command_lines_bytes(name, tmp_path):
    """On records robotid did not make (a lab's shape, a late effort
    channel, CSV and MCAP, a real arm), Python writes the command line's
    files byte for byte, with the same warnings and the same verdict."""
    folder, excitation, validation, urdf = NOT_OURS[name]
    case = SHARED / folder
    if not case.exists():
        pytest.skip(f"{case} is absent (../shared sits beside the repository)")
    robot = example_robot(urdf) if urdf else case / "kuka_lwr4.urdf"
    by_cli, by_python, result = identify_both(
        tmp_path, [case / excitation], robot, [case / v for v in validation]
    )
    assert sorted(by_cli) == sorted(by_python)
    assert [str(p) for p in by_cli if by_cli[p] != by_python[p]] == []
    assert pathlib.Path("parameters.parquet") in by_cli and pathlib.Path("report.html") in by_cli
    assert result.identified and result.refused is None, result.refused


def test_a_refused_identification_is_a_result_with_the_cause(tmp_path):
    """A foreign recording (made without robotid) under a tolerance no
    model meets: refused by both (exit 3 from the command line), the same
    files either way, and the cause in the result."""
    case = SHARED / "foreign" / "ur5"
    if not case.exists():
        pytest.skip(f"{case} is absent (the foreign recordings sit beside the repository)")
    urdf = example_robot("ur_description/urdf/ur5_robot.urdf")
    out = tmp_path / "out"
    done = cli("identify", case / "excitation.mcap", "--robot", urdf, "--out", out, "--tolerance", "0.01", check=False)
    assert done.returncode == 3, done.stderr
    by_cli = files(out)
    shutil.rmtree(out)
    result = robotid.identify([case / "excitation.mcap"], urdf, out=out, tolerance=0.01)
    assert files(out) == by_cli
    assert not result.identified
    assert "over the tolerance 0.0 %" in result.refused, result.refused
    assert (out / "INADEQUATE.txt").read_text() == result.refused + "\n"
    assert result.physical is None and result.exports == []


PAYLOAD_LINK = """
  <link name="payload">
    <inertial><origin xyz="0.04 -0.03 0.06" rpy="0 0 0"/><mass value="3.0"/>
      <inertia ixx="0.0052" ixy="0" ixz="0" iyy="0.0061" iyz="0" izz="0.0041"/></inertial>
  </link>
  <joint name="payload_joint" type="fixed">
    <parent link="ee_link"/><child link="payload"/><origin xyz="0 0 0" rpy="0 0 0"/>
  </joint>
"""

PAYLOAD_SIM = """robot = "{robot}"
seed = {seed}
[trajectory]
kind = "fourier"
base_frequency_hz = 0.1
q0 = [0.0, -1.2, 1.0, -1.4, -1.57, 0.0]
a = [[0.40, -0.20, 0.10, 0.08, -0.05], [0.30, 0.20, -0.10, 0.06, 0.04], [-0.35, 0.20, 0.12, -0.08, 0.05], [0.50, -0.25, 0.15, 0.10, -0.06], [0.45, 0.20, -0.15, 0.08, 0.05], [-0.50, 0.30, 0.10, -0.10, 0.06]]
b = [[0.20, 0.25, -0.10, 0.05, 0.04], [-0.25, 0.10, 0.10, -0.05, 0.03], [0.30, -0.10, 0.12, 0.05, -0.04], [-0.30, 0.20, 0.10, -0.08, 0.05], [0.30, -0.25, 0.10, 0.06, -0.05], [0.40, 0.20, -0.15, 0.08, 0.05]]
[timing]
log_rate_hz = 250.0
steps_per_sample = 4
transient_s = 4.0
periods = 3
[controller]
kind = "pid"
bandwidth_hz = 6.0
[measurement]
current_noise_std_a = 0.05
position_noise_std_rad = 1.0e-5
[output]
name = "{name}"
formats = ["csv"]
"""


def test_a_payload_from_python(examples, tmp_path):
    """The UR5 URDF alone and the same with a 3 kg payload on `ee_link`
    (a fixed link the simulator's URDF reading lumps into the wrist),
    simulated by `robotid simulate`: `robotid.identify(payload_on=…)`
    gives its mass within 2 % and its centre of mass within 5 mm, in the
    table the command line writes, byte for byte."""
    urdf = examples / "robots" / "ur5.urdf"
    text = urdf.read_text()
    loaded_urdf = examples / "robots" / "ur5_payload.urdf"
    loaded_urdf.write_text(text.replace("</robot>", PAYLOAD_LINK + "</robot>"))
    logs = {}
    for name, robot, seed in [("unloaded", urdf, 11), ("loaded", loaded_urdf, 12), ("held", loaded_urdf, 13)]:
        sim = tmp_path / f"{name}.toml"
        sim.write_text(PAYLOAD_SIM.format(robot=robot, seed=seed, name=name))
        cli("simulate", sim, "--out", tmp_path / "rec")
        logs[name] = tmp_path / "rec" / f"{name}.csv"
    out = tmp_path / "out"
    args = [logs["loaded"], "--robot", urdf, "--payload-on", "ee_link", "--unloaded", logs["unloaded"]]
    # The payload's size declared (a 10 cm ellipsoid about its centre):
    # the bounded estimate is what the exports carry.
    args += ["--payload-ellipsoid", "0.04,-0.03,0.06,0.1,0.1,0.1"]
    cli("identify", *args, "--validate-loaded", logs["held"], "--accept-inadequate", "--out", out)
    by_cli = (out / "payload.parquet").read_bytes()
    shutil.rmtree(out)
    result = robotid.identify(
        [logs["loaded"]],
        urdf,
        payload_on="ee_link",
        unloaded=[logs["unloaded"]],
        validate_loaded=[logs["held"]],
        payload_ellipsoid=((0.04, -0.03, 0.06), (0.1, 0.1, 0.1)),
        accept_inadequate=True,
        out=out,
    )
    assert (out / "payload.parquet").read_bytes() == by_cli
    rows = {r["name"]: r for r in result.payload.to_pylist()}
    assert abs(rows["mass"]["value"] - 3.0) / 3.0 < 0.02, rows["mass"]
    com = [rows[f"com_{a}"]["value"] for a in "xyz"]
    assert sum((c - t) ** 2 for c, t in zip(com, [0.04, -0.03, 0.06])) ** 0.5 < 5e-3, com
    assert result.payload.schema.metadata[b"robotid.payload.link"] == b"ee_link"
    # A held-out loaded record: predicted to within 1 % of its torque.
    relative, joints = result.payload_validation
    assert relative < 0.01 and len(joints) == 6, result.payload_validation
    said = result.payload.schema.metadata[b"robotid.payload.validation"].decode()
    assert said.startswith("on the held-out loaded records: relative error"), said
    # The MJCF export with the payload, as MuJoCo loads it: its torques
    # less the same export's without the payload are the payload's alone
    # (dynamics are linear in the bodies; the joints' damping is the same
    # in both), and equal Pinocchio's for the identified payload fixed to
    # ee_link in the URDF.
    import mujoco
    import numpy as np
    import pinocchio

    body = {r["name"]: r["bounded"] for r in result.payload.to_pylist()}
    link = PAYLOAD_LINK.replace("0.04 -0.03 0.06", "{com_x!r} {com_y!r} {com_z!r}").replace(
        '<mass value="3.0"/>', '<mass value="{mass!r}"/>'
    )
    link = link.replace(
        'ixx="0.0052" ixy="0" ixz="0" iyy="0.0061" iyz="0" izz="0.0041"',
        'ixx="{ixx!r}" ixy="{ixy!r}" ixz="{ixz!r}" iyy="{iyy!r}" iyz="{iyz!r}" izz="{izz!r}"',
    ).format(**body)
    pin = [pinocchio.buildModelFromXML(t) for t in (text.replace("</robot>", link + "</robot>"), text)]
    mj = [mujoco.MjModel.from_xml_path(str(out / f)) for f in ("identified_payload.xml", "identified.xml")]
    for m in mj:
        m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONSTRAINT
    assert mj[0].nbody == mj[1].nbody + 1 and mj[0].nv == 6
    rng = np.random.default_rng(5)
    for _ in range(3):
        q, v, a = (rng.uniform(-1.5, 1.5, 6) for _ in range(3))
        by_pin = [pinocchio.rnea(m, m.createData(), q, v, a).copy() for m in pin]
        by_mj = []
        for m in mj:
            d = mujoco.MjData(m)
            d.qpos[:], d.qvel[:], d.qacc[:] = q, v, a
            mujoco.mj_inverse(m, d)
            by_mj.append(d.qfrc_inverse.copy())
        want, got = by_pin[0] - by_pin[1], by_mj[0] - by_mj[1]
        assert np.abs(got - want).max() < 1e-9 * np.abs(want).max() + 1e-12, (got, want)
    # Against the robot identified above (its parameters table): the
    # payload alone, the command line's table byte for byte, its mass as
    # close and its intervals no narrower.
    given = tmp_path / "given.parquet"
    shutil.copy(out / "parameters.parquet", given)
    cli("identify", logs["loaded"], "--robot", urdf, "--payload-on", "ee_link", "--parameters", given, "--out", tmp_path / "p_cli")
    alone = robotid.payload([logs["loaded"]], urdf, given, "ee_link", tmp_path / "p_py")
    assert (tmp_path / "p_py" / "payload.parquet").read_bytes() == (tmp_path / "p_cli" / "payload.parquet").read_bytes()
    again = {r["name"]: r for r in alone.to_pylist()}
    assert abs(again["mass"]["value"] - 3.0) / 3.0 < 0.02, again["mass"]
    assert again["mass"]["std"] >= 0.99 * rows["mass"]["std"], (again["mass"], rows["mass"])
    with pytest.raises(robotid.RobotidError, match="not a link the last moving joint carries"):
        robotid.payload([logs["loaded"]], urdf, given, "no_such_link", tmp_path / "p_bad")
    assert not (tmp_path / "p_bad").exists()
