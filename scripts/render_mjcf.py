"""Renders an MJCF (robotid export's, with the robot file's geometry) to a
PNG with MuJoCo's offscreen renderer, at a pose, for the docs.

usage: MUJOCO_GL=egl python scripts/render_mjcf.py MODEL.xml OUT.png [q0 q1 ...]
"""
import struct
import sys
import zlib

import mujoco


def png(path, rgb):
    """An 8-bit RGB image as a PNG file (no imaging package needed)."""
    h, w, _ = rgb.shape
    raw = b"".join(b"\x00" + rgb[y].tobytes() for y in range(h))

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n")
        f.write(chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)))
        f.write(chunk(b"IDAT", zlib.compress(raw, 9)))
        f.write(chunk(b"IEND", b""))


def main(model_path, out, *q):
    spec = mujoco.MjSpec.from_file(model_path)
    # A floor, a light and a camera on the robot: the export holds only the
    # robot.
    spec.worldbody.add_light(pos=[1.0, -1.0, 3.0], dir=[-0.3, 0.3, -1.0], diffuse=[0.8, 0.8, 0.8])
    spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_PLANE, size=[2, 2, 0.01], rgba=[0.9, 0.9, 0.9, 1])
    model = spec.compile()
    data = mujoco.MjData(model)
    data.qpos[: len(q)] = [float(x) for x in q]
    mujoco.mj_forward(model, data)
    renderer = mujoco.Renderer(model, 480, 640)
    camera = mujoco.MjvCamera()
    camera.lookat[:] = [0.25, 0.15, 0.3]
    camera.distance, camera.azimuth, camera.elevation = 1.5, 150.0, -20.0
    renderer.update_scene(data, camera)
    png(out, renderer.render())


if __name__ == "__main__":
    main(*sys.argv[1:])
