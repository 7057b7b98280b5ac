"""Independent inverse dynamics with Pinocchio: reads a URDF and a JSON file
of states {"q": [[...]], "v": [[...]], "a": [[...]]}, prints the joint torques
(pin.rnea, gravity (0, 0, -9.81)) and the joint names as JSON."""
import json
import sys

import numpy as np
import pinocchio as pin


def main(urdf, states):
    model = pin.buildModelFromUrdf(urdf)
    data = model.createData()
    with open(states) as f:
        s = json.load(f)
    taus = []
    for q, v, a in zip(s["q"], s["v"], s["a"]):
        taus.append(pin.rnea(model, data, np.array(q), np.array(v), np.array(a)).tolist())
    print(json.dumps({"names": [n for n in model.names][1:], "nq": model.nq, "tau": taus}))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
