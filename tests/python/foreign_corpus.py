"""Recordings of a lab's arm made without robotid: Pinocchio's RNEA along a
Fourier excitation, friction, an analog anti-alias filter simulated by
scipy on a fine grid, white torque noise and encoder quantisation, logged
as a headed CSV or a headerless whitespace log, with the truth beside it.

usage: foreign_corpus.py URDF OUT_DIR CASE

CASE names what a lab brings (see CASES). Writes OUT_DIR/excitation.csv
(or .txt), OUT_DIR/truth.json (joints, friction, filter, noise). Nothing
here imports or mirrors robotid: the reference is Pinocchio and scipy."""
import json
import sys

import numpy as np
import pinocchio as pin
from scipy import signal

FS = 500.0
FINE = 8  # simulation steps per logged sample: the filter sees the torque's kinks
NOISE = 0.05  # N·m, white, after the filter
COUNTS = 2**17  # encoder counts per revolution

# Each case: the filter (scipy design arguments, or None), the friction law,
# periods at full amplitude, the ramps before and after them (s; the ramp-in
# defaults to one period), a constant torque offset, the log form, the joints
# that move (the others held by a stiff position loop: they sag under gravity
# and their encoders flicker by a count), rest at the end (s).
CASES = {
    "butter4_20": dict(filter=("butter", 4, 20.0, None), friction="sign", periods=5),
    "bessel6_40": dict(filter=("bessel", 6, 40.0, None), friction="sign", periods=5),
    "cheby1_6_25": dict(filter=("cheby1", 6, 25.0, 1.0), friction="sign", periods=5),
    "none_offset": dict(filter=None, friction="sign", periods=5, offset=0.3),
    "stribeck": dict(filter=("butter", 4, 40.0, None), friction="stribeck", periods=5),
    "headerless": dict(filter=("butter", 2, 60.0, None), friction="sign", periods=5, form="txt"),
    "ramps_1p5": dict(filter=("butter", 4, 30.0, None), friction="sign", periods=1.5, ramp_in=0.5, ramp_out=0.5),
    "ramps_2p5": dict(filter=("butter", 4, 30.0, None), friction="sign", periods=2.5, ramp_in=0.5, ramp_out=0.5),
    "jointwise": dict(filter=("butter", 4, 30.0, None), friction="sign", periods=4, moving=[1], ramp_out=1.0, rest=16.0),
    # A gripper in the robot file (robot.urdf: the URDF with a revolute
    # wrist-mounted gripper and a prismatic finger on it) that the log does
    # not hold: held at their zero while the arm moves.
    "gripper": dict(filter=("butter", 4, 30.0, None), friction="sign", periods=5, gripper=True),
    # A lab's shape: a move from a rest pose to the start (larger than the
    # excitation) and a second still, the ramp-in, the periods, a ramp-down
    # and rest; the effort logged late by a fraction of a sample or more.
    "lab_delay_0p5": dict(
        filter=("cheby1", 8, 40.0, 0.5), friction="sign", periods=5, premove=4.0, ramp_out=10.0, rest=8.0, delay=0.5
    ),
    "lab_delay_3": dict(filter=("cheby1", 6, 35.0, 1.0), friction="sign", periods=4, premove=3.0, rest=5.0, delay=3.0),
    # A joint-wise record whose other joints first move from rest to the
    # pose they are then held at.
    "jointwise_premove": dict(
        filter=("butter", 4, 30.0, None), friction="sign", periods=4, moving=[3], premove=3.0, ramp_out=1.0, rest=8.0
    ),
    # A start-up transient (a decaying 2 Hz ring of the position loop) on
    # 1.5 periods, no ramps.
    "transient_1p5": dict(filter=("butter", 4, 30.0, None), friction="sign", periods=1.5, ramp_in=0.0, transient=0.05),
    "lab_2p5": dict(
        filter=("butter", 4, 30.0, None), friction="sign", periods=2.5, premove=4.0, ramp_in=0.5, ramp_out=0.5, rest=6.0
    ),
    # The gripper case as a ROS 2 bag: JointState messages naming the arm's joints.
    "gripper_mcap": dict(filter=("butter", 4, 30.0, None), friction="sign", periods=5, gripper=True, form="mcap"),
    # Torque sensors at 1 kHz, no anti-alias filter, 1.6 periods between a
    # ramp-up and a ramp-down, the position loop's tracking error on the
    # motion, logged as headerless whitespace text.
    "sensors_1k_1p6": dict(
        filter=None, friction="sign", periods=1.6, ramp_in=3.0, ramp_out=3.0, fs=1000.0, tracking=2e-4, form="txt"
    ),
    # The same arm and excitation (3 periods of 10 s) without and with a
    # payload on tool0: a 2.5 kg body off the flange's axis. The loaded
    # record draws its noise apart.
    "payload_unloaded": dict(filter=("butter", 4, 30.0, None), friction="sign", periods=3),
    "payload_loaded": dict(
        filter=("butter", 4, 30.0, None), friction="sign", periods=3, seed_case="payload_unloaded", payload=True
    ),
    # Stribeck's static friction fading faster and exponentially, twice
    # Coulomb's at rest (added last: the other cases' seeds are their
    # places in this table).
    "stribeck_fast": dict(
        filter=("butter", 4, 30.0, None), friction="stribeck", periods=5, stribeck=(0.02, 1.0, 1.0)
    ),
    # 1 kHz, no anti-alias filter, 2.2 periods between a move from rest and
    # rest (the filter search's range ends at Nyquist: a pipeline declaring
    # a filter beyond it is one its own lint refuses).
    "unfiltered_1k_2p2": dict(
        filter=None, friction="sign", periods=2.2, premove=3.0, ramp_in=0.5, ramp_out=0.5, rest=3.0, fs=1000.0
    ),
    # No period at all: the five lines at incommensurate frequencies (the
    # fundamental times 1, √2, √5, √10, √17), 30 s between ramps; and 5 s
    # of it, from rest to rest, whose slow lines barely turn (its
    # column-normalised condition 509, the 30 s record's 25).
    "nonperiodic_30s": dict(
        filter=("butter", 4, 30.0, None), friction="sign", periods=3.0, ramp_in=1.0, ramp_out=1.0, nonperiodic=True
    ),
    "nonperiodic_5s": dict(
        filter=("butter", 4, 30.0, None), friction="sign", periods=0.5, ramp_in=0.5, ramp_out=0.5, nonperiodic=True
    ),
    # Exactly one period between ramps.
    "one_period": dict(filter=("butter", 4, 30.0, None), friction="sign", periods=1.0, ramp_in=1.0, ramp_out=1.0),
    # The 5 s record's motion at a fiftieth of its size: the joints turn
    # by a few hundredths of a radian, so few poses are seen and the
    # regressor's columns nearly repeat one another (its column-normalised
    # condition over 1e5, Kinova Gen3's real 5 s record's 1.3e6); the
    # Coulomb steps come at speeds the encoder barely resolves.
    "illcond_5s": dict(
        filter=("butter", 4, 30.0, None),
        friction="sign",
        periods=0.5,
        ramp_in=0.5,
        ramp_out=0.5,
        nonperiodic=True,
        scale=0.02,
    ),
    # An industrial wrist: motor 6 turns with joints 5 and 6, the controller
    # logs motor-side encoder counts (offset by calibration) and motor
    # currents, at 5 kHz, with no time column.
    "coupled_wrist": dict(
        filter=("butter", 4, 200.0, None), friction="sign", periods=4, f0=0.2, fs=5000.0, transmission=True
    ),
}

# The transmission of "coupled_wrist": gear ratios (motor turns per joint
# turn; joint 4's motor turns the other way), motor 6 also turning 32 times
# per turn of joint 5, motor-side encoders and torque constants.
GEARS = [32.0, 32.0, 45.0, -48.0, 45.0, 32.0]
COUPLED = (5, 4, 32.0)  # (motor, joint, turns)
MOTOR_COUNTS = 2**14
TORQUE_CONSTANT = [0.11, 0.11, 0.09, 0.07, 0.07, 0.07]
MOTOR_FRICTION = (2.0e-4, 0.01)  # the coupled motor's, motor side: N·m·s/rad, N·m
CURRENT_NOISE = 0.004  # A, white, after the filter

# The payload of "payload_loaded", in tool0's frame: kg, m, kg·m² at its
# centre of mass (a 12 × 8 × 6 cm box turned 0.3 rad about z).
PAYLOAD = dict(mass=2.5, com=[0.05, -0.03, 0.07], box=[0.12, 0.08, 0.06], yaw=0.3)

# What "gripper" adds to the URDF: a revolute gripper on tool0 and a
# prismatic finger on it, each with a body the arm carries.
GRIPPER = """
  <link name="gripper_link">
    <inertial><origin xyz="0.01 -0.02 0.07" rpy="0 0 0"/><mass value="1.2"/>
      <inertia ixx="0.004" ixy="0" ixz="0" iyy="0.003" iyz="0" izz="0.002"/></inertial>
  </link>
  <joint name="gripper_joint" type="revolute">
    <parent link="tool0"/><child link="gripper_link"/><origin xyz="0 0 0.01" rpy="0 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-3.14" upper="3.14" effort="5" velocity="2"/>
  </joint>
  <link name="finger_link">
    <inertial><origin xyz="0 0.01 0.02" rpy="0 0 0"/><mass value="0.3"/>
      <inertia ixx="0.0002" ixy="0" ixz="0" iyy="0.0002" iyz="0" izz="0.0001"/></inertial>
  </link>
  <joint name="finger_joint" type="prismatic">
    <parent link="gripper_link"/><child link="finger_link"/><origin xyz="0 0 0.12" rpy="0 0 0"/>
    <axis xyz="0 1 0"/><limit lower="0" upper="0.04" effort="20" velocity="0.1"/>
  </joint>
"""


def write_mcap(path, names, t, q, tau):
    """/joint_states as a ROS 2 arm logs it (mcap-ros2-support's writer,
    CDR JointState), stamped from an epoch in integer nanoseconds."""
    from mcap_ros2.writer import Writer

    from mcap_write import SCHEMA

    with open(path, "wb") as f:
        w = Writer(f)
        schema = w.register_msgdef("sensor_msgs/msg/JointState", SCHEMA)
        for k in range(len(t)):
            ns = 1_700_000_000_000_000_000 + int(round(t[k] * 1e9))
            msg = {
                "header": {"stamp": {"sec": ns // 10**9, "nanosec": ns % 10**9}, "frame_id": ""},
                "name": names,
                "position": q[k].tolist(),
                "velocity": [],
                "effort": tau[k].tolist(),
            }
            w.write_message(topic="/joint_states", schema=schema, message=msg, log_time=ns, publish_time=ns)
        w.finish()


def main(urdf, out, case):
    spec = CASES[case]
    if spec.get("gripper"):
        text = open(urdf).read()
        at = text.rindex("</robot>")
        # Mesh paths stay resolvable: the URDF is written where it was.
        urdf = f"{out}/robot.urdf"
        with open(urdf, "w") as f:
            f.write(text[:at] + GRIPPER + text[at:])
    full = pin.buildModelFromUrdf(urdf)
    truth_payload = None
    if spec.get("payload"):
        # Carried by the joint tool0 hangs from, placed at tool0.
        frame = full.frames[full.getFrameId("tool0")]
        m, (x, y, z), yaw = PAYLOAD["mass"], PAYLOAD["box"], PAYLOAD["yaw"]
        inertia_box = np.diag([y * y + z * z, x * x + z * z, x * x + y * y]) * m / 12
        rz = pin.utils.rotate("z", yaw)
        inertia_com = rz @ inertia_box @ rz.T
        full.appendBodyToJoint(frame.parentJoint, pin.Inertia(m, np.array(PAYLOAD["com"]), inertia_com), frame.placement)
        truth_payload = dict(link="tool0", mass=m, com=PAYLOAD["com"], inertia_com=inertia_com.tolist())
    # The gripper held at its zero: the arm carries it as one body.
    arm_ids = [i for i in range(1, full.njoints) if full.names[i] not in ("gripper_joint", "finger_joint")]
    locked = [i for i in range(1, full.njoints) if i not in arm_ids]
    model = pin.buildReducedModel(full, locked, pin.neutral(full)) if locked else full
    data = model.createData()
    nq = model.nq
    names = [model.names[i] for i in range(1, model.njoints)]
    # Seeded by the case's place: new cases go last, so the others keep theirs.
    rng = np.random.default_rng(list(CASES).index(spec.get("seed_case", case)) + 1)
    f0, harmonics = spec.get("f0", 0.1), 5
    lines = np.sqrt([1.0, 2.0, 5.0, 10.0, 17.0]) if spec.get("nonperiodic") else np.arange(1, harmonics + 1)
    w = 2 * np.pi * f0 * lines
    a = rng.uniform(-0.5, 0.5, (nq, harmonics)) / np.arange(1, harmonics + 1)
    b = rng.uniform(-0.5, 0.5, (nq, harmonics)) / np.arange(1, harmonics + 1)
    a, b = a * spec.get("scale", 1.0), b * spec.get("scale", 1.0)

    def excitation(t):
        s, c = np.sin(np.outer(t, w)), np.cos(np.outer(t, w))
        q = (s @ (a / w).T) - (c @ (b / w).T)
        q -= -(b / w).sum(axis=1)  # q(0) = 0
        qd = c @ a.T + s @ b.T
        qdd = -(s @ (a * w).T) + c @ (b * w).T
        return q, qd, qdd

    period = 1 / f0
    # Before the ramp-in: a move from the rest pose and a second still.
    premove = spec.get("premove", 0.0)
    pre = premove + 1.0 if premove > 0 else 0.0
    ramp_in = spec.get("ramp_in", period)
    ramp_out = spec.get("ramp_out", 0.0)
    rest = spec.get("rest", 0.0)
    moving = spec.get("moving", list(range(nq)))
    held = [j for j in range(nq) if j not in moving]
    a[held], b[held] = 0.0, 0.0
    total = pre + ramp_in + spec["periods"] * period + ramp_out + rest
    fs = spec.get("fs", FS)
    fine = spec.get("fine", FINE)
    t = np.arange(int(round(total * fs * fine))) / (fs * fine)
    # The excitation starts at full phase when the ramp-in ends; before it,
    # it is faded in by a smooth window, after the periods faded out.
    q, qd, qdd = excitation(t - pre - ramp_in)

    def window(x, length):  # quintic 0 -> 1 over [0, length], and its derivatives
        r = np.clip(x / length, 0, 1) if length > 0 else (x >= 0).astype(float)
        inside = (x > 0) & (x < length)
        return (
            r**3 * (10 - 15 * r + 6 * r**2),
            np.where(inside, 30 * r**2 * (1 - r) ** 2 / max(length, 1e-12), 0),
            np.where(inside, 60 * r * (1 - r) * (1 - 2 * r) / max(length, 1e-12) ** 2, 0),
        )

    up, upd, updd = window(t - pre, ramp_in)
    end = pre + ramp_in + spec["periods"] * period
    down, downd, downdd = window(end + ramp_out - t, ramp_out) if ramp_out > 0 else window(end - t + 1e-12, 0)
    downd, downdd = -downd, downdd
    g = up * down
    gd = upd * down + up * downd
    gdd = updd * down + 2 * upd * downd + up * downdd
    q, qd, qdd = (
        g[:, None] * q,
        g[:, None] * qd + gd[:, None] * q,
        g[:, None] * qdd + 2 * gd[:, None] * qd + gdd[:, None] * q,
    )
    if spec.get("tracking"):
        # The position loop's tracking error: periodic (the reference is),
        # spread over harmonics 6-60 (0.6-6 Hz) and falling with them, near
        # the encoder's count at the top.
        hs = np.arange(6, 61)
        amp = spec["tracking"] * 6.0 / hs * rng.uniform(0.5, 1.0, (nq, len(hs)))
        phase = rng.uniform(0, 2 * np.pi, (nq, len(hs)))
        x = t - pre - ramp_in
        arg = 2 * np.pi * f0 * np.multiply.outer(x, hs)[:, None, :] + phase[None]
        wh = 2 * np.pi * f0 * hs
        q = q + g[:, None] * (amp * np.sin(arg)).sum(axis=2)
        qd = qd + g[:, None] * (amp * wh * np.cos(arg)).sum(axis=2)
        qdd = qdd - g[:, None] * (amp * wh**2 * np.sin(arg)).sum(axis=2)
    if spec.get("transient"):
        # The loop rings at the start: 2 Hz, decaying in 1 s, on every joint.
        x = np.clip(t - pre, 0, None)
        ring = spec["transient"] * np.exp(-x) * np.sin(2 * np.pi * 2.0 * x)
        ringd = spec["transient"] * np.exp(-x) * (2 * np.pi * 2.0 * np.cos(2 * np.pi * 2.0 * x) - np.sin(2 * np.pi * 2.0 * x))
        ringdd = spec["transient"] * np.exp(-x) * (
            (1 - (2 * np.pi * 2.0) ** 2) * np.sin(2 * np.pi * 2.0 * x) - 2 * (2 * np.pi * 2.0) * np.cos(2 * np.pi * 2.0 * x)
        )
        q, qd, qdd = q + ring[:, None], qd + ringd[:, None], qdd + ringdd[:, None]
    if premove > 0:
        # From a rest pose 1.2 rad from the start on every joint (more than
        # the excitation's reach), to the start, in a quintic.
        rest_pose = 1.2 * np.where(np.arange(nq) % 2 == 0, 1.0, -1.0)
        w, wd, wdd = window(t, premove)
        q += (1 - w)[:, None] * rest_pose
        qd -= wd[:, None] * rest_pose
        qdd -= wdd[:, None] * rest_pose
    fv = rng.uniform(0.3, 1.5, nq)
    fc = rng.uniform(0.2, 1.8, nq)
    tau = np.empty_like(q)
    for k in range(len(t)):
        tau[k] = pin.rnea(model, data, q[k], qd[k], qdd[k])
    if spec["friction"] == "sign":
        tau += fv * qd + fc * np.sign(qd)
    else:
        # Stribeck: static friction (1 + ratio)× Coulomb, fading as
        # exp(−(|q̇|/vs)^δ); by default 1.5× over 0.05 rad/s, Gaussian.
        vs, delta, ratio = spec.get("stribeck", (0.05, 2.0, 0.5))
        tau += fv * qd + (fc + ratio * fc * np.exp(-((np.abs(qd) / vs) ** delta))) * np.sign(qd)
    tau += spec.get("offset", 0.0)
    motors = None
    if spec.get("transmission"):
        # θ = R·q: each motor's rotor inertia as Rᵀ·J·R·q̈, the coupled
        # motor's friction at its own speed through Rᵀ.
        R = np.diag(GEARS)
        R[COUPLED[0], COUPLED[1]] = COUPLED[2]
        rotor = rng.uniform(1e-5, 4e-5, nq)
        offsets = rng.uniform(-3.0, 3.0, nq)
        speed = qd @ R.T
        motor_tau = (qdd @ R.T) * rotor
        m = COUPLED[0]
        motor_tau[:, m] += MOTOR_FRICTION[0] * speed[:, m] + MOTOR_FRICTION[1] * np.sign(speed[:, m])
        tau += motor_tau @ R
        motors = dict(R=R, rotor=rotor, offsets=offsets)
    if held:
        # A stiff position loop (5000 N·m/rad) holds them: they sag by the
        # change of their gravity load as the moving joint swings.
        start = int(round(pre * fs * FINE))
        q[:, held] -= (tau[:, held] - tau[start, held]) / 5000.0
    clean_tau = tau.copy() if motors else None
    filt = None
    if spec["filter"]:
        family, order, cutoff, ripple = spec["filter"]
        wc = 2 * np.pi * cutoff
        if family == "butter":
            num, den = signal.butter(order, wc, analog=True)
        elif family == "bessel":
            num, den = signal.bessel(order, wc, analog=True, norm="mag")
        else:
            num, den = signal.cheby1(order, ripple, wc, analog=True)
        sys_ = signal.lti(num, den)
        tau = np.stack([signal.lsim(sys_, tau[:, j], t)[1] for j in range(nq)], axis=1)
        filt = dict(family=family, order=order, cutoff_hz=cutoff, ripple_db=ripple)
    late = int(round(spec.get("delay", 0.0) * fine))
    if late:
        # The effort logged late: each sample holds the torque of `delay`
        # samples before (the first held at the start's).
        tau = np.concatenate([np.repeat(tau[:1], late, axis=0), tau[:-late]])
    logged = slice(0, None, fine)
    clean = (t[logged], q[logged], qd[logged], qdd[logged], clean_tau[logged]) if motors else None
    t, q, tau = t[logged], q[logged], tau[logged]
    if spec.get("seed_case"):
        # The excitation and the arm another case's, the noise its own.
        rng = np.random.default_rng(list(CASES).index(case) + 1)
    if motors:
        # What the controller logs: motor currents i = R⁻ᵀ·τ / k with their
        # own noise, motor encoder counts of θ = R·q + offsets; no time.
        current = np.linalg.solve(motors["R"].T, tau.T).T / TORQUE_CONSTANT
        current += rng.normal(0, CURRENT_NOISE, current.shape)
        counts = np.round((q @ motors["R"].T + motors["offsets"]) / (2 * np.pi / MOTOR_COUNTS))
        header = ",".join([f"enc_{k + 1}" for k in range(nq)] + [f"cur_{k + 1}" for k in range(nq)])
        np.savetxt(f"{out}/motors.csv", np.column_stack([counts, current]), fmt="%.9g", delimiter=",", header=header, comments="")
        # The joint side the log hides, every 25th sample: exact angles and
        # their derivatives, the torque before the filter and the noise.
        every = slice(0, None, 25)
        tc, qc, qdc, qddc, tauc = (x[every] for x in clean)
        cols = [tc[:, None], qc, qdc, qddc, tauc]
        np.savetxt(f"{out}/joint_side.csv", np.column_stack(cols), fmt="%.17g", delimiter=",")
    else:
        tau = tau + rng.normal(0, NOISE, tau.shape)
        step = 2 * np.pi / COUNTS
        if held:
            # Held exactly half a count off a boundary, their encoders flicker.
            q[:, held] += step / 2 + rng.normal(0, step / 4, (len(t), len(held)))
        q = np.round(q / step) * step
        table = np.column_stack([t, q, tau])
        if spec.get("form") == "txt":
            np.savetxt(f"{out}/excitation.txt", table, fmt="%.9g", delimiter=" ")
        elif spec.get("form") == "mcap":
            write_mcap(f"{out}/excitation.mcap", names, t, q, tau)
        else:
            header = ",".join(["time_s"] + [f"{n}_pos_rad" for n in names] + [f"{n}_effort_Nm" for n in names])
            np.savetxt(f"{out}/excitation.csv", table, fmt="%.9g", delimiter=",", header=header, comments="")
    truth = dict(
        joints=names,
        fs_hz=fs,
        f0_hz=f0,
        harmonics=harmonics,
        nonperiodic=bool(spec.get("nonperiodic")),
        periods=spec["periods"],
        ramp_in_s=ramp_in,
        premove_s=premove,
        effort_delay_s=spec.get("delay", 0.0) / fs,
        ramp_out_s=ramp_out,
        rest_s=rest,
        moving=[names[j] for j in moving],
        anti_alias=filt,
        friction=spec["friction"],
        **(
            dict(zip(("stribeck_velocity_rad_s", "stribeck_exponent", "stribeck_ratio"), spec.get("stribeck", (0.05, 2.0, 0.5))))
            if spec["friction"] == "stribeck"
            else {}
        ),
        friction_viscous=fv.tolist(),
        friction_coulomb=fc.tolist(),
        offset_Nm=spec.get("offset", 0.0),
        effort_noise_std_Nm=NOISE,
        encoder_counts_per_rev=COUNTS,
        locked={full.names[i]: 0.0 for i in locked},
    )
    if truth_payload:
        truth["payload"] = truth_payload
    if motors:
        truth["effort_noise_std_Nm"] = None
        truth["current_noise_std_A"] = CURRENT_NOISE
        truth["transmission"] = dict(
            gear_ratio=GEARS,
            coupling=dict(motor=names[COUPLED[0]], joint=names[COUPLED[1]], turns=COUPLED[2]),
            motor_offset_rad=motors["offsets"].tolist(),
            torque_constant=TORQUE_CONSTANT,
            rotor_inertia=motors["rotor"].tolist(),
            motor_viscous=MOTOR_FRICTION[0],
            motor_coulomb=MOTOR_FRICTION[1],
            encoder_counts_per_rev=MOTOR_COUNTS,
        )
    if held:
        # The joint-wise (decoupled) model of each moving joint, the others
        # at rest: τ = Mi·q̈ + Gs·sin q + Gc·cos q + friction.
        decoupled = {}
        for j in moving:
            z = np.zeros(nq)
            up = z.copy()
            up[j] = np.pi / 2
            decoupled[names[j]] = dict(
                Mi=float(pin.crba(model, data, z)[j, j]),
                Gs=float(pin.rnea(model, data, up, z, z)[j]),
                Gc=float(pin.rnea(model, data, z, z, z)[j]),
            )
        truth["decoupled"] = decoupled
    with open(f"{out}/truth.json", "w") as f:
        json.dump(truth, f, indent=1)


if __name__ == "__main__":
    main(*sys.argv[1:4])
