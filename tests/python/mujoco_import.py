"""MuJoCo's own URDF import, saved as MJCF: reads a URDF whose meshes are
named `package://PKG/...`, resolves PKG to the folder of that name above
the URDF, keeps the collision meshes (STL, which MuJoCo reads; the visual
DAE files it does not are discarded) and writes what `mj_saveLastXML`
writes. Prints the model's joint and body counts as JSON."""
import json
import os
import re
import sys
import tempfile

import mujoco


def main(urdf, out):
    text = open(urdf).read()
    meshes = re.findall(r'<collision>.*?filename="([^"]+)"', text, flags=re.S)
    dirs = set()
    for m in meshes:
        pkg, rest = m[len("package://"):].split("/", 1)
        root = os.path.dirname(os.path.abspath(urdf))
        while os.path.basename(root) != pkg:
            root = os.path.dirname(root)
        dirs.add(os.path.dirname(os.path.join(root, rest)))
    (meshdir,) = dirs
    mujoco_tag = f'<mujoco><compiler meshdir="{meshdir}" strippath="true" discardvisual="true"/></mujoco>'
    text = re.sub(r"(<robot[^>]*>)", r"\1" + mujoco_tag, text, count=1)
    with tempfile.NamedTemporaryFile("w", suffix=".urdf", delete=False) as f:
        f.write(text)
    try:
        model = mujoco.MjModel.from_xml_path(f.name)
        mujoco.mj_saveLastXML(out, model)
    finally:
        os.unlink(f.name)
    print(json.dumps({"joints": model.njnt, "bodies": model.nbody, "geoms": model.ngeom}))


if __name__ == "__main__":
    main(*sys.argv[1:])
