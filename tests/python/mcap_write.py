"""Writes an MCAP log with the `mcap-ros2-support` writer (chunked, zstd,
CDR-encoded sensor_msgs/msg/JointState on /joint_states), as a ROS 2 arm
logs one: argv[1] the file, argv[2] the excitation period in s. Joints
j1..j3 sweep a two-harmonic periodic motion at 250 Hz for four periods,
in a scrambled name order; effort is half the position. No robotid
metadata: the reader has nothing but the messages."""
import math
import sys

from mcap_ros2.writer import Writer

SCHEMA = """std_msgs/Header header
string[] name
float64[] position
float64[] velocity
float64[] effort
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"""


def position(i, t, period):
    return 0.4 * math.sin(2 * math.pi * t / period + i) + 0.1 * math.sin(6 * math.pi * t / period)


def main(path, period):
    period = float(period)
    with open(path, "wb") as f:
        w = Writer(f)
        schema = w.register_msgdef("sensor_msgs/msg/JointState", SCHEMA)
        order = [2, 0, 1]
        for k in range(int(4 * period * 250)):
            t = k / 250.0
            ns = 1_700_000_000_000_000_000 + round(t * 1e9)
            q = [position(i, t, period) for i in order]
            msg = {
                "header": {"stamp": {"sec": ns // 10**9, "nanosec": ns % 10**9}, "frame_id": ""},
                "name": [f"j{i + 1}" for i in order],
                "position": q,
                "velocity": [],
                "effort": [0.5 * x for x in q],
            }
            w.write_message(topic="/joint_states", schema=schema, message=msg, log_time=ns, publish_time=ns)
        w.finish()


if __name__ == "__main__":
    main(*sys.argv[1:])
