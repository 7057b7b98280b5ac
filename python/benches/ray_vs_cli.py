"""Identification of a fleet on a local Ray cluster against `robotid run`
over the same recordings, on this machine, in one run.

    CARGO_TARGET_DIR=... python python/benches/ray_vs_cli.py [RECORDINGS_PER_ROBOT] [PERIODS]

PERIODS lengthens each recording (the examples have 4): Ray's fixed cost
per execution weighs less on real-sized recordings.

Both sides use the same build profile (the `robotid` binary of
$CARGO_TARGET_DIR/<profile>, the installed extension); set ROBOTID_BIN to
pick the binary. Prints wall times, their ratio and recordings per second.
"""

import pathlib
import sys
import tempfile
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))

import ray  # noqa: E402

import robotid.ray  # noqa: E402
from conftest import make_fleet, robotid as cli  # noqa: E402


def best_of(n, f):
    times = []
    for _ in range(n):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    return min(times)


def main():
    per_robot = int(sys.argv[1]) if len(sys.argv) > 1 else 12
    periods = int(sys.argv[2]) if len(sys.argv) > 2 else 0
    with tempfile.TemporaryDirectory() as tmp:
        root = pathlib.Path(tmp)
        fleet = make_fleet(root, per_robot, periods)
        n = len(fleet["recordings"])

        def run_cli():
            for robot, pipeline in fleet["pipelines"].items():
                cli("run", pipeline, "--out", root / "out" / robot)

        t = time.perf_counter()
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
        init = time.perf_counter() - t

        def run_ray():
            robotid.ray.identify(fleet["recordings"], fleet["pipelines"], summaries_per_task=max(1, n // 8))

        first = best_of(1, run_ray)
        warm_ray = best_of(3, run_ray)
        warm_cli = best_of(3, run_cli)
        ray.shutdown()
    print(f"{n} recordings of 2 robots ({periods or 4} periods each), 2 cores")
    print(f"robotid run (both pipelines):   {warm_cli:.2f} s, {n / warm_cli:.1f} recordings/s")
    print(f"robotid.ray.identify, warm:     {warm_ray:.2f} s, {n / warm_ray:.1f} recordings/s")
    print(f"robotid.ray.identify, first:    {first:.2f} s (workers start); ray.init {init:.2f} s")
    print(f"ratio Ray / CLI (warm):         {warm_ray / warm_cli:.2f}")


if __name__ == "__main__":
    main()
