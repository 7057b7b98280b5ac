"""Independent inverse dynamics with Pinocchio: reads a URDF, a JSON file of
states {"q": [[...]], "v": [[...]], "a": [[...]]} and optionally a JSON
object of locked joints {name: position}; prints the joint torques
(pin.rnea, gravity (0, 0, -9.81)), the joint names and their damping and
friction as Pinocchio loaded them from <dynamics>, as JSON. Locked
joints are removed by pin.buildReducedModel at those positions (the other
joints of the reference configuration at 0)."""
import json
import sys

import numpy as np
import pinocchio as pin


def main(urdf, states, locks=None):
    model = pin.buildModelFromUrdf(urdf)
    if locks:
        locked = json.loads(locks)
        q0 = pin.neutral(model)
        ids = []
        for name, x in locked.items():
            jid = model.getJointId(name)
            q0[model.joints[jid].idx_q] = x
            ids.append(jid)
        model = pin.buildReducedModel(model, ids, q0)
    data = model.createData()
    with open(states) as f:
        s = json.load(f)
    taus = []
    for q, v, a in zip(s["q"], s["v"], s["a"]):
        taus.append(pin.rnea(model, data, np.array(q), np.array(v), np.array(a)).tolist())
    # The URDF's <dynamics> as Pinocchio loaded them.
    dyn = {"damping": model.damping.tolist(), "friction": model.friction.tolist()}
    print(json.dumps({"names": [n for n in model.names][1:], "nq": model.nq, "tau": taus, **dyn}))


if __name__ == "__main__":
    main(*sys.argv[1:])
