"""Independent inverse dynamics with MuJoCo: loads an MJCF model, reads a
JSON file of states {"q": [[...]], "v": [[...]], "a": [[...]]} and prints
mj_inverse's joint forces (qfrc_inverse), the joint names and their
armature, damping and frictionloss as MuJoCo loaded them, as JSON.
Constraints are disabled: joint limits, and frictionloss, which MuJoCo
applies as a constraint force rather than Fc·sign(q̇); damping and armature
stay in (passive force and mass matrix).

With "names" in the states, the states are those joints' (by name) and
the forces printed are theirs; every other joint is held still at the
position an optional JSON object {name: position} gives it (else its
reference), as a locked joint is."""
import json
import sys

import mujoco
import numpy as np


def main(mjcf, states, locks="{}"):
    model = mujoco.MjModel.from_xml_path(mjcf)
    model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONSTRAINT
    data = mujoco.MjData(model)
    with open(states) as f:
        s = json.load(f)
    all_names = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(model.njnt)]
    names = s.get("names", all_names)
    ids = [all_names.index(n) for n in names]
    qadr = [model.jnt_qposadr[j] for j in ids]
    dadr = [model.jnt_dofadr[j] for j in ids]
    q0 = model.qpos0.copy()
    for name, x in json.loads(locks).items():
        q0[model.jnt_qposadr[all_names.index(name)]] = x
    taus = []
    for q, v, a in zip(s["q"], s["v"], s["a"]):
        data.qpos[:] = q0
        data.qvel[:] = 0.0
        data.qacc[:] = 0.0
        data.qpos[qadr] = q
        data.qvel[dadr] = v
        data.qacc[dadr] = a
        mujoco.mj_inverse(model, data)
        taus.append(data.qfrc_inverse[dadr].tolist())
    # The joints' dynamics as MuJoCo loaded them.
    dof = {k: [float(getattr(model, "dof_" + k)[d]) for d in dadr] for k in ("armature", "damping", "frictionloss")}
    print(json.dumps({"names": names, "tau": taus, **dof}))


if __name__ == "__main__":
    main(*sys.argv[1:])
