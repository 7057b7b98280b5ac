"""Independent inverse dynamics with MuJoCo: loads an MJCF model, reads a
JSON file of states {"q": [[...]], "v": [[...]], "a": [[...]]} and prints
mj_inverse's joint forces (qfrc_inverse) and the joint names as JSON.
Constraints are disabled: joint limits, and frictionloss, which MuJoCo
applies as a constraint force rather than Fc·sign(q̇); damping and armature
stay in (passive force and mass matrix)."""
import json
import sys

import mujoco
import numpy as np


def main(mjcf, states):
    model = mujoco.MjModel.from_xml_path(mjcf)
    model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONSTRAINT
    data = mujoco.MjData(model)
    with open(states) as f:
        s = json.load(f)
    taus = []
    for q, v, a in zip(s["q"], s["v"], s["a"]):
        data.qpos[:] = np.array(q)
        data.qvel[:] = np.array(v)
        data.qacc[:] = np.array(a)
        mujoco.mj_inverse(model, data)
        taus.append(data.qfrc_inverse.tolist())
    names = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(model.njnt)]
    print(json.dumps({"names": names, "tau": taus}))


if __name__ == "__main__":
    main(*sys.argv[1:])
