"""A designed trajectory in the forms robots run: CSV, NPZ, JSON, ROS 2 YAML, URScript.

Each writer takes the samples ``t`` [s] (N,), ``q`` [rad or m], ``dq``, ``ddq``, ``tau``
[N m or N] (N, nv) and the joint names, and writes one file at ``path``:

    csv       header ``t,q_<joint>...,dq_<joint>...,ddq_<joint>...,tau_<joint>...``
              (the package's CSV reader convention; tau = the nominal model's torque)
    npz       arrays t, q, dq, ddq, tau, joint_names
    json      ``{"joint_names", "t", "q", "dq", "ddq", "tau"}`` (lists of rows)
    yaml      a ROS 2 ``trajectory_msgs/msg/JointTrajectory`` (positions, velocities,
              accelerations, effort, time_from_start of every point)
    mcap      a ROS 2 bag (one MCAP file, written with ``rosbags``) holding one
              ``trajectory_msgs/msg/JointTrajectory`` on :data:`TRAJECTORY_TOPIC` at log
              time 0: positions, velocities, accelerations and time_from_start of every
              point, no effort (see below)
    urscript  a UR program: ``movej`` to the start pose, then one ``servoj`` per sample
              with ``t = 1 / rate`` (the controller's own period: 125 Hz CB3, 500 Hz e-Series)

Why a JointTrajectory and not a JointState stream in the bag: a JointState stream is what
a robot reports (its ``joint_state_broadcaster`` publishes ``/joint_states``); replaying
one commands nothing and collides with the live robot's own. A JointTrajectory on the
``joint_trajectory_controller``'s topic is the command: ``ros2 bag play traj.mcap`` hands
the whole motion to the controller, which interpolates between the points at its own
update rate (``--remap`` the topic for a controller of another name). The effort field
stays empty because that controller refuses trajectories with efforts unless it commands
efforts; the CSV, NPZ, JSON and YAML files keep the nominal torques.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..datasets.rosbag import write_messages
from ..errors import InputError

FORMATS = ("csv", "npz", "json", "yaml", "mcap", "urscript")
SUFFIXES = {".csv": "csv", ".npz": "npz", ".json": "json", ".yaml": "yaml", ".yml": "yaml",
            ".mcap": "mcap", ".script": "urscript", ".urscript": "urscript"}  # fmt: skip
#: The topic of the JointTrajectory in an MCAP bag: ros2_controllers' joint_trajectory_controller.
TRAJECTORY_TOPIC = "/joint_trajectory_controller/joint_trajectory"
JOINT_TRAJECTORY = "trajectory_msgs/msg/JointTrajectory"


def format_of(path, fmt: str | None = None) -> str:
    """``fmt`` when given, else the format of the suffix of ``path``."""
    if fmt is not None:
        if fmt not in FORMATS:
            raise InputError(f"format must be one of {', '.join(FORMATS)}, got {fmt!r}")
        return fmt
    suffix = Path(path).suffix.lower()
    if suffix not in SUFFIXES:
        raise InputError(
            f"cannot tell the format of {path} from its suffix {suffix!r}: expected one of "
            f"{', '.join(sorted(SUFFIXES))} or --format {'|'.join(FORMATS)}"
        )
    return SUFFIXES[suffix]


def write_trajectory(path, fmt: str, t, q, dq, ddq, tau, joint_names) -> None:
    """Write the samples in ``fmt`` (module docstring) to ``path``."""
    names = [str(n) for n in joint_names]
    if fmt == "csv":
        _csv(path, t, q, dq, ddq, tau, names)
    elif fmt == "npz":
        with open(path, "wb") as fh:
            np.savez(fh, t=t, q=q, dq=dq, ddq=ddq, tau=tau, joint_names=np.array(names))
    elif fmt == "json":
        doc = {"joint_names": names, **{k: v.tolist() for k, v in
               {"t": t, "q": q, "dq": dq, "ddq": ddq, "tau": tau}.items()}}  # fmt: skip
        Path(path).write_text(json.dumps(doc) + "\n", encoding="utf-8")
    elif fmt == "yaml":
        Path(path).write_text(_joint_trajectory_yaml(t, q, dq, ddq, tau, names), encoding="utf-8")
    elif fmt == "mcap":
        write_joint_trajectory_bag(path, t, q, dq, ddq, names)
    elif fmt == "urscript":
        Path(path).write_text(_urscript(t, q, names), encoding="utf-8")
    else:
        raise InputError(f"format must be one of {', '.join(FORMATS)}, got {fmt!r}")


def _csv(path, t, q, dq, ddq, tau, names) -> None:
    header = ["t"] + [f"{p}_{n}" for p in ("q", "dq", "ddq", "tau") for n in names]
    table = np.column_stack([t, q, dq, ddq, tau])
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(",".join(header) + "\n")
        np.savetxt(fh, table, delimiter=",", fmt="%.10g")


def _floats(row) -> str:
    return "[" + ", ".join(f"{float(v):.10g}" for v in row) + "]"


def _joint_trajectory_yaml(t, q, dq, ddq, tau, names) -> str:
    lines = [
        "header:",
        "  stamp: {sec: 0, nanosec: 0}",
        "  frame_id: ''",
        "joint_names: [" + ", ".join(json.dumps(n) for n in names) + "]",
        "points:",
    ]
    for k in range(t.size):
        sec, nsec = _sec_nsec(t[k])
        lines += [
            f"- positions: {_floats(q[k])}",
            f"  velocities: {_floats(dq[k])}",
            f"  accelerations: {_floats(ddq[k])}",
            f"  effort: {_floats(tau[k])}",
            f"  time_from_start: {{sec: {sec}, nanosec: {nsec}}}",
        ]
    return "\n".join(lines) + "\n"


def _sec_nsec(t: float) -> tuple[int, int]:
    """A time [s] >= 0 as (sec, nanosec) of ROS 2 (nanoseconds rounded)."""
    ns = int(round(float(t) * 1e9))
    return ns // 10**9, ns % 10**9


def write_joint_trajectory_bag(path, t, q, dq, ddq, names, topic: str = TRAJECTORY_TOPIC):
    """One ``trajectory_msgs/msg/JointTrajectory`` (stamp 0: start on receipt) with a point
    per sample, in a bare MCAP bag at ``path`` (module docstring)."""

    def messages(store):
        types = store.types
        Time, Duration = (
            types["builtin_interfaces/msg/Time"],
            types["builtin_interfaces/msg/Duration"],
        )
        Point = types["trajectory_msgs/msg/JointTrajectoryPoint"]
        empty = np.zeros(0)
        points = [
            Point(
                positions=np.ascontiguousarray(q[k], dtype=np.float64),
                velocities=np.ascontiguousarray(dq[k], dtype=np.float64),
                accelerations=np.ascontiguousarray(ddq[k], dtype=np.float64),
                effort=empty,
                time_from_start=Duration(*_sec_nsec(t[k])),
            )
            for k in range(len(t))
        ]
        header = types["std_msgs/msg/Header"](stamp=Time(sec=0, nanosec=0), frame_id="")
        yield 0, types[JOINT_TRAJECTORY](header=header, joint_names=list(names), points=points)

    write_messages(Path(path), topic, JOINT_TRAJECTORY, messages, bare=True)


def _urscript(t, q, names) -> str:
    if q.shape[1] != 6:
        raise InputError(f"URScript drives 6-joint UR arms; this robot has {q.shape[1]} joints")
    dt = float(t[1] - t[0]) if t.size > 1 else 0.008
    lines = [
        "def manip_id_excitation():",
        "  # joints: " + ", ".join(names),
        f"  movej({_floats(q[0])}, a=0.5, v=0.3)",
        "  sleep(0.5)",
    ]
    lines += [f"  servoj({_floats(row)}, t={dt:.6g}, lookahead_time=0.1, gain=300)" for row in q]
    lines += ["  stopj(2.0)", "end", "manip_id_excitation()"]
    return "\n".join(lines) + "\n"
