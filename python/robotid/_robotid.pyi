"""Type stubs of the native module (python/src/lib.rs)."""

from os import PathLike
from typing import Dict, List, Optional, Sequence, Tuple, Union

import pyarrow as pa

__version__: str

Recording = Union[str, PathLike, bytes]
Summaries = Union[pa.RecordBatch, pa.Table, Sequence[pa.RecordBatch]]

class RobotidError(Exception):
    """A robotid error; where it sits, when known."""

    file: Optional[str]
    channel: Optional[str]
    sample: Optional[int]
    stage: Optional[str]

class Pipeline:
    """A built pipeline: robot loaded, recordings found, stages ready."""

    @staticmethod
    def from_toml(text: str, base_dir: Union[str, PathLike]) -> Pipeline:
        """A pipeline from its TOML text; relative paths resolve against `base_dir`."""
    @staticmethod
    def from_path(path: Union[str, PathLike]) -> Pipeline:
        """A pipeline from its file."""
    @property
    def recordings(self) -> List[str]:
        """The recordings the pipeline's `[source]` names."""
    @property
    def config_sha256(self) -> str:
        """SHA-256 of the pipeline text (in every table's metadata)."""
    @property
    def file(self) -> str:
        """The pipeline file's path."""
    def run_recording(self, recording: Recording, name: Optional[str] = None) -> Dict[str, pa.Table]:
        """Every table the pipeline writes for one recording, by kind.
        Bytes are a recording's file content; `name`'s extension (else the
        content) says its format."""
    def summarize(self, recording: Recording, name: Optional[str] = None) -> pa.RecordBatch:
        """One recording's row of sufficient statistics (needs an `estimate` stage)."""
    def solve(self, summaries: Summaries) -> pa.Table:
        """The `parameters` table from summaries this pipeline made."""

def merge(summaries: Summaries) -> pa.RecordBatch:
    """Summaries merged, in order, into one row."""

class Identification:
    """What `identify` found and wrote (its output folder, typed)."""

    out: str
    identified: bool
    refused: Optional[str]
    verdict: str
    relative_error: float
    measured: str
    recordings: List[Dict[str, object]]
    parameters: pa.Table
    physical: Optional[pa.Table]
    exports: List[str]
    payload: Optional[pa.Table]
    payload_validation: Optional[Tuple[float, List[Tuple[str, Optional[float]]]]]
    closed_loop: Optional[pa.Table]
    warnings: List[str]
    rollouts: Optional[pa.Table]

def identify(
    recordings: Sequence[Union[str, PathLike]],
    robot: Union[str, PathLike],
    validate: Sequence[Union[str, PathLike]] = (),
    out: Optional[Union[str, PathLike]] = None,
    tolerance: float = 5.0,
    strict: bool = False,
    accept_inadequate: bool = False,
    torque_per_amp: Sequence[float] = (),
    threads: Optional[int] = None,
    mjcf: Optional[Union[str, PathLike]] = None,
    payload_on: Optional[str] = None,
    unloaded: Sequence[Union[str, PathLike]] = (),
    known_payload_mass: Optional[float] = None,
    payload_ellipsoid: Optional[Tuple[Tuple[float, float, float], Tuple[float, float, float]]] = None,
    validate_loaded: Sequence[Union[str, PathLike]] = (),
    controller: Optional[Union[str, PathLike]] = None,
    mujoco: bool = False,
    read: Optional[Union[str, PathLike]] = None,
) -> Identification:
    """From recordings and a robot file to a validated model, as `robotid
    identify`: the same files in `out`, byte for byte. `tolerance` is a
    percent of the measured torque, as `--tolerance`; `read`, a TOML file
    whose `[read]` table says where the channels are, as `--read`. A
    refused fit is a
    result (`identified` False, `refused` the cause), not an error. With
    `mjcf` (the user's own MJCF of the robot), `identified.xml` is it with
    the identified dynamics written in. With `payload_on` (a link), the
    `recordings` carry a payload, the robot is identified from `unloaded`,
    and `payload` is the payload's table (in that link's frame; with
    `known_payload_mass`, the drives' gains too; `payload_ellipsoid`:
    centre and semi-axes, m, the bounded estimate's region;
    `validate_loaded`: held-out loaded records, whose prediction is
    `payload_validation`). With `controller` (a TOML file's
    `[controller]` table, the `validate` records' PID), `closed_loop` is
    the estimate's and the robot file's closed-loop runs on them (None
    with a warning when they cannot be run, e.g. without reference
    channels). `rollouts`: the models
    rolled out on each validation record in robotid's windows (table,
    model: estimate, physical, robot_file, and with `mujoco` the exported
    MJCF run by this interpreter's MuJoCo; joint, q_rms in rad, qd_rms in
    rad/s), as the report shows them. `warnings`: what the command line
    prints as `warning:`, the same words."""

def payload(
    loaded: Sequence[Union[str, PathLike]],
    robot: Union[str, PathLike],
    parameters: Union[str, PathLike],
    payload_on: str,
    out: Union[str, PathLike],
    payload_ellipsoid: Optional[Tuple[Tuple[float, float, float], Tuple[float, float, float]]] = None,
    accept_inadequate: bool = False,
) -> pa.Table:
    """The payload on the link `payload_on` from `loaded` (records with
    it) against a robot already identified (its `parameters` table, whose
    covariance is carried), as `robotid identify LOADED… --payload-on LINK
    --parameters P`: `payload.parquet` written into `out` (an empty or new
    folder) and returned. Values the records leave undetermined at the
    payload's size raise RobotidError naming them (the table written all
    the same) unless `accept_inadequate`."""

def rollout(
    parameters: Union[str, PathLike],
    robot: Union[str, PathLike],
    regressors: Sequence[Union[str, PathLike]],
    window_s: Optional[float] = None,
) -> pa.Table:
    """The parameters rolled out on the kinematics table beside each
    regressor table, as `robotid validate --rollout`: per record, model
    (`estimate`, `robot_file`), window and joint, the simulated angle's and
    velocity's RMS error against the measured (rad, rad/s). The window is
    `window_s`, else chosen from each record's noise (the longest at which
    it moves an exact model by at most 1 % of each joint's motion)."""

def closed_loop(
    parameters: Union[str, PathLike],
    robot: Union[str, PathLike],
    recordings: Sequence[Union[str, PathLike]],
    controller: Union[str, PathLike],
) -> pa.Table:
    """The parameters simulated in closed loop on each raw recording (its
    positions and recorded reference) under the controller declared in
    `controller` (a `[controller]` table of per-joint kp, kd, ki), as
    `robotid validate --closed-loop`: per recording, model (`estimate`,
    `robot_file`) and joint, the simulated angle's RMS error against the
    measured (rad)."""

def sample(
    parameters: Union[str, PathLike],
    robot: Union[str, PathLike],
    draws: int,
    out: Union[str, PathLike],
    seed: int = 0,
    formats: Sequence[str] = (),
    mjcf: Optional[Union[str, PathLike]] = None,
) -> pa.Table:
    """Parameter sets drawn from a physically consistent estimate's
    distribution for domain randomization, as `robotid sample`: written into
    `out` (`samples.parquet`, `randomization.json` and `.yaml`, a model per
    draw for each of `formats`, "urdf" and "mjcf", the user's own `mjcf`
    patched when given); the samples table (draw, joint, quantity, unit,
    value) returned."""
