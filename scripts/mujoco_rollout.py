"""A model rolled out by MuJoCo itself, as `robotid validate --rollout`
rolls out robotid's: the MJCF (e.g. identify's `identified.xml`) driven by
a kinematics table's measured torque (`torque_<joint>`, linear between
samples), restarted from the measured state (`q_`, `qd_<joint>`) every
window, the simulated angles against the measured. MuJoCo's own friction:
`frictionloss` as its constraint (with --no-frictionloss, constraints
off). Prints per joint the position and velocity RMS error as JSON.

    python scripts/mujoco_rollout.py identified.xml validation/validation/kinematics.parquet --window-s 0.05
"""
import argparse
import json

import mujoco
import numpy as np
import pyarrow.parquet as pq


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("mjcf")
    p.add_argument("kinematics")
    p.add_argument("--window-s", type=float, default=0.05)
    p.add_argument("--substeps", type=int, default=8, help="MuJoCo steps per sample")
    p.add_argument("--no-frictionloss", action="store_true")
    a = p.parse_args()
    model = mujoco.MjModel.from_xml_path(a.mjcf)
    if a.no_frictionloss:
        model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONSTRAINT
    else:
        # Joint limits and contacts (its geoms touch) are not what is
        # judged: only the dynamics and the friction loss.
        model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_LIMIT | mujoco.mjtDisableBit.mjDSBL_CONTACT
    data = mujoco.MjData(model)
    t = pq.read_table(a.kinematics)
    names = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(model.njnt)]
    joints = [c[len("q_"):] for c in t.schema.names if c.startswith("q_")]
    qadr = [model.jnt_qposadr[names.index(j)] for j in joints]
    dadr = [model.jnt_dofadr[names.index(j)] for j in joints]
    col = lambda k: np.column_stack([t.column(f"{k}_{j}").to_numpy() for j in joints])
    time, q, qd, tau = t.column("time").to_numpy(), col("q"), col("qd"), col("torque")
    step = (time[-1] - time[0]) / (len(time) - 1)
    window = max(2, round(a.window_s / step))
    model.opt.timestep = step / a.substeps
    # Every joint the table does not hold stays at its reference.
    sim = np.empty_like(q)
    simd = np.empty_like(qd)
    for s in range(len(time)):
        if s % window == 0:
            mujoco.mj_resetData(model, data)
            data.qpos[qadr] = q[s]
            data.qvel[dadr] = qd[s]
            mujoco.mj_forward(model, data)
        else:
            for k in range(a.substeps):
                f = (k + 0.5) / a.substeps
                data.qfrc_applied[dadr] = tau[s - 1] + f * (tau[s] - tau[s - 1])
                mujoco.mj_step(model, data)
        sim[s] = data.qpos[qadr]
        simd[s] = data.qvel[dadr]
    moved = np.arange(len(time)) % window != 0
    rms = lambda e: np.sqrt((e[moved] ** 2).mean(axis=0)).tolist()
    print(json.dumps({"joints": joints, "window": window, "q_rms": rms(sim - q), "qd_rms": rms(simd - qd)}))


if __name__ == "__main__":
    main()
