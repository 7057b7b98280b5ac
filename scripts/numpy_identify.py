"""The 130 s UR5 identification as a plain numpy/scipy/Pinocchio script, for
scripts/bench-numpy.sh: the yardstick of "identification ≥ 10× faster than
a script" (issue "speed in practice"). It does what the pipeline
fixtures/bench/ur5_130s_identify.toml does, the way a lab script would:

  read /joint_states from the MCAP (mcap-ros2-support), keep the last
  `periods` whole periods, divide the torque's DFT lines by the analog
  Chebyshev I anti-alias filter up to the bandwidth (zero above), average
  the periods, noise variance from their spread, positions fitted by a
  Fourier series at the excited harmonics and differentiated exactly,
  Pinocchio's joint torque regressor plus rotor inertia and symmetric
  friction (sign), base columns by pivoted QR, ordinary least squares;
  the period mean, noise, kinematics and regressor tables written as
  Parquet (pyarrow, zstd).

Prints the time of its imports, of reading and of the rest, and the
per-joint residual RMS, which must match robotid's.

usage: numpy_identify.py MCAP URDF ROBOT_TOML OUT_DIR
"""
import time

START = time.perf_counter()

import json  # noqa: E402
import os  # noqa: E402
import sys  # noqa: E402
import tomllib  # noqa: E402

import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402
import pyarrow as pa  # noqa: E402
import pyarrow.parquet as pq  # noqa: E402
import scipy.linalg  # noqa: E402
import scipy.signal  # noqa: E402
from mcap_ros2.reader import read_ros2_messages  # noqa: E402

PERIOD_S = 10.0
RATE_HZ = 500.0
PERIODS = 12
HARMONICS = [1, 2, 3, 4, 5]
BANDWIDTH_HZ = 40.0
FILTER = dict(order=6, ripple_db=1.0, cutoff_hz=100.0)


def read(path):
    t, q, tau = [], [], []
    for m in read_ros2_messages(path, topics=["/joint_states"]):
        msg = m.ros_msg
        t.append(msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec)
        q.append(msg.position)
        tau.append(msg.effort)
    return np.array(t), np.array(q), np.array(tau)


def inverse_filter(x, n):
    """Divides each period-aligned column's DFT by H(j2πf) up to the band."""
    b, a = scipy.signal.cheby1(FILTER["order"], FILTER["ripple_db"], 2 * np.pi * FILTER["cutoff_hz"], analog=True)
    f = np.fft.rfftfreq(len(x), 1.0 / RATE_HZ)
    _, h = scipy.signal.freqs(b, a, worN=2 * np.pi * f)
    spec = np.fft.rfft(x, axis=0)
    keep = f <= BANDWIDTH_HZ
    spec[keep] /= h[keep, None]
    spec[~keep] = 0.0
    return np.fft.irfft(spec, n=len(x), axis=0)


def fourier_fit(q, n):
    """Least-squares fit at the harmonics (and the mean); q, q̇, q̈ exactly."""
    w = 2 * np.pi / PERIOD_S
    t = np.arange(n) / RATE_HZ
    cols = [np.ones(n)]
    for h in HARMONICS:
        cols += [np.cos(h * w * t), np.sin(h * w * t)]
    basis = np.stack(cols, axis=1)
    coef, *_ = np.linalg.lstsq(basis, q, rcond=None)
    qf, qd, qdd = np.tile(coef[0], (n, 1)), np.zeros_like(q), np.zeros_like(q)
    for i, h in enumerate(HARMONICS):
        c, s = coef[1 + 2 * i], coef[2 + 2 * i]
        hw = h * w
        cos, sin = np.cos(hw * t)[:, None], np.sin(hw * t)[:, None]
        qf += c * cos + s * sin
        qd += hw * (-c * sin + s * cos)
        qdd += -hw * hw * (c * cos + s * sin)
    return qf, qd, qdd


def regressor(model, q, qd, qdd):
    """Rows (sample, joint) × [10 inertials per link, rotor, Fv, Fc]."""
    data = model.createData()
    n, dof = q.shape
    cols = 10 * dof + 3 * dof
    out = np.zeros((n * dof, cols))
    eye = np.eye(dof)
    for k in range(n):
        rows = slice(k * dof, (k + 1) * dof)
        out[rows, : 10 * dof] = pin.computeJointTorqueRegressor(model, data, q[k], qd[k], qdd[k])
        out[rows, 10 * dof : 11 * dof] = eye * qdd[k]
        out[rows, 11 * dof : 12 * dof] = eye * qd[k]
        out[rows, 12 * dof :] = eye * np.sign(qd[k])
    return out


def table(path, columns, md):
    arrays = {k: pa.array(v) for k, v in columns.items()}
    pq.write_table(pa.table(arrays).replace_schema_metadata(md), path, compression="zstd")


def main(mcap, urdf, robot_toml, out):
    os.makedirs(out, exist_ok=True)
    with open(robot_toml, "rb") as f:
        joints = [j["name"] for j in tomllib.load(f)["joint"]]
    imported = time.perf_counter()
    t, q, tau = read(mcap)
    read_done = time.perf_counter()
    n = int(round(PERIOD_S * RATE_HZ))
    q, tau = q[-PERIODS * n :], tau[-PERIODS * n :]
    tau = inverse_filter(tau, n)
    qp, taup = q.reshape(PERIODS, n, -1), tau.reshape(PERIODS, n, -1)
    q_mean, tau_mean = qp.mean(axis=0), taup.mean(axis=0)
    var_q, var_tau = qp.var(axis=0, ddof=1) / PERIODS, taup.var(axis=0, ddof=1) / PERIODS
    qf, qd, qdd = fourier_fit(q_mean, n)

    model = pin.buildModelFromUrdf(urdf)
    assert [model.names[i] for i in range(1, model.njoints)] == joints, "joint order"
    a = regressor(model, qf, qd, qdd)
    b = tau_mean.reshape(-1)
    # Base columns: pivoted QR of the regressor at random states.
    rng = np.random.default_rng(0)
    dof = len(joints)
    probe = regressor(model, *(rng.uniform(-3, 3, (200, dof)) for _ in range(3)))
    _, r, piv = scipy.linalg.qr(probe, mode="economic", pivoting=True)
    rank = int(np.sum(np.abs(np.diag(r)) > 1e-8 * abs(r[0, 0])))
    base = np.sort(piv[:rank])
    ab = a[:, base]
    theta, *_ = np.linalg.lstsq(ab, b, rcond=None)
    residual = (b - ab @ theta).reshape(n, dof)
    rms = np.sqrt((residual**2).mean(axis=0))

    time_s = np.arange(n) / RATE_HZ
    md = {b"period_s": str(PERIOD_S).encode()}
    table(f"{out}/period_mean.parquet", {"time": time_s, **{f"q_{j}": q_mean[:, i] for i, j in enumerate(joints)},
                                         **{f"torque_{j}": tau_mean[:, i] for i, j in enumerate(joints)}}, md)
    table(f"{out}/noise.parquet", {**{f"var_q_{j}": var_q[:, i] for i, j in enumerate(joints)},
                                   **{f"var_torque_{j}": var_tau[:, i] for i, j in enumerate(joints)}}, md)
    table(f"{out}/kinematics.parquet", {"time": time_s, **{f"{c}_{j}": x[:, i] for c, x in
                                        (("q", qf), ("qd", qd), ("qdd", qdd)) for i, j in enumerate(joints)}}, md)
    table(f"{out}/regressor.parquet", {"torque": b, **{f"c{c}": ab[:, i] for i, c in enumerate(base)},
                                       **{f"torque_p{p}": taup[p].reshape(-1) for p in range(PERIODS)}}, md)
    table(f"{out}/parameters.parquet", {"index": base, "value": theta}, md)
    end = time.perf_counter()
    steps = {"imports_s": imported - START, "read_s": read_done - imported, "rest_s": end - read_done}
    print(json.dumps({**steps, "base_parameters": rank, "residual_rms": dict(zip(joints, rms.tolist()))}))


if __name__ == "__main__":
    main(*sys.argv[1:])
