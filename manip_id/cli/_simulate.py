"""``manip-id simulate`` once it runs: the logs simulated, written into a staged folder,
published complete (the options are declared in :mod:`.simulate`).

Run ``k`` of a group (``unloaded``, then one group per ``--payload`` mass) follows its own
excitation (:func:`._simulated.excitation`, seed ``SEED + k``, the loaded groups after
the unloaded ones), so any two files of the folder hold different motions: one may train
and another validate. The truth is the robot's nominal parameter vector (with the payload
on the last body for the loaded runs, :func:`manip_id.control.closed_loop.with_payload`).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._io import write_json
from ..control.closed_loop import with_payload
from ..datasets import Dataset, save_dataset
from ..errors import InputError
from ..simulation import MeasurementNoise, check_simulation_memory, simulate
from ..trajectories import read_design
from ._common import SIM_DEFAULTS, parse_floats, reserve_outputs
from ._runtime import robot_from_args
from ._simulated import excitation

#: The payload's lever in the last joint's frame: 0.1 m along its axis (``with_payload``).
LEVER = 0.1  # [m]


@dataclass(frozen=True)
class Run:
    """One log to write: its file name, seed and payload mass [kg] (0: unloaded)."""

    name: str
    seed: int
    mass: float


def _check(args: argparse.Namespace) -> tuple[list[float], list[Run]]:
    """The payload masses and the runs of the options, refused before any work."""
    if args.files < 1:
        raise InputError(f"--files must be >= 1, got {args.files}")
    for name in ("duration", "rate"):
        value = getattr(args, name)
        if not (math.isfinite(value) and value > 0):
            raise InputError(f"--{name} must be a positive number, got {value}")
    if not (math.isfinite(args.noise) and args.noise >= 0):
        raise InputError(f"--noise must be >= 0 (relative to the RMS torque), got {args.noise}")
    if args.duration * args.rate < 10:
        raise InputError(
            f"--duration {args.duration:g} s at --rate {args.rate:g} Hz gives fewer than 10 samples"
        )
    masses = [] if args.payload is None else parse_floats(args.payload, "--payload")
    if any(m <= 0 for m in masses):
        raise InputError(f"--payload masses must be > 0 [kg], got {args.payload}")
    width = len(str(args.files - 1))
    groups = [("run", 0.0)] + [(f"payload_{m:g}kg", m) for m in masses]
    runs = [
        Run(f"{prefix}_{k:0{width}d}.{args.format}", args.seed + g * args.files + k, mass)
        for g, (prefix, mass) in enumerate(groups)
        for k in range(args.files)
    ]
    return masses, runs


def _gains(args: argparse.Namespace, nv: int) -> np.ndarray | None:
    """The ``--drive-gains`` per joint [N m/A], shape (nv,), or None (torques written)."""
    if args.drive_gains is None:
        return None
    gains = np.array(parse_floats(args.drive_gains, "--drive-gains"))
    if gains.size == 1:
        gains = np.full(nv, gains[0])
    if gains.shape != (nv,):
        raise InputError(f"--drive-gains takes 1 or {nv} gains (one per joint), got {gains.size}")
    if np.any(gains <= 0):
        raise InputError(f"--drive-gains must be > 0 [N m/A], got {args.drive_gains}")
    return gains


def _log(robot, run: Run, theta: np.ndarray, args, gains) -> Dataset:
    """The simulated log of one run (currents tau / gains in the torque columns with gains)."""
    traj = args.design if args.design is not None else excitation(robot, run.seed)
    if traj.nv != robot.nv:
        raise InputError(f"--trajectory has {traj.nv} joints but {robot.name!r} has {robot.nv}")
    sim = simulate(
        robot,
        traj,
        duration=args.duration,
        rate=args.rate,
        theta=theta,
        noise=MeasurementNoise(tau=args.noise),
        seed=run.seed,
    )
    data = sim.dataset
    if gains is not None:
        data = dataclasses.replace(data, tau=data.tau / gains)  # [A]
    return data


def _readme(robot, args, masses: list[float], runs: list[Run], gains) -> str:
    """The README.txt of the folder: what was simulated, and commands to try on it."""
    last = robot.joint_names[-1]
    lines = [
        f"Simulated logs of {robot.name} written by manip-id simulate.",
        "",
        f"robot: {robot.name}; joint terms: {', '.join(robot.terms.enabled) or 'none'}",
        "truth: the robot's nominal parameters (truth.json: every parameter by name)",
        (
            f"motion: the designed excitation {args.trajectory} in every file (noise seed "
            f"{runs[0].seed} for the first, +1 per file)"
            if args.trajectory
            else f"motion: one random Fourier excitation per file (seed {runs[0].seed} for the "
            "first, +1 per file); no two files repeat a motion"
        ),
        f"samples: {args.duration:g} s at {args.rate:g} Hz per file; q, dq and ddq exact"
        + (" (ddq not in MCAP bags)" if args.format == "mcap" else ""),
        f"torque noise: Gaussian, std {args.noise:g} x each joint's RMS torque",
    ]
    if masses:
        lines.append(
            f"payload: point mass(es) {', '.join(f'{m:g}' for m in masses)} kg at {LEVER:g} m "
            f"along the axis of {last}, on its body (payload --frame {last})"
        )
    if gains is not None:
        lines.append(
            "torque columns: motor currents tau / gain [A], gains [N m/A]: "
            + ", ".join(f"{g:g}" for g in gains)
        )
    lines += ["", "files:"] + [
        f"  {r.name}  seed {r.seed}" + (f", payload {r.mass:g} kg" if r.mass else "") for r in runs
    ]
    return "\n".join(lines) + "\n"


def _truth(robot, args, masses: list[float], runs: list[Run], gains) -> dict:
    """truth.json: the parameters behind the logs, by name."""
    theta = robot.nominal_parameters
    return {
        "robot": robot.name,
        "joint_terms": list(robot.terms.enabled),
        "parameters": dict(zip(robot.parameter_names, map(float, theta), strict=True)),
        "payload": {
            "masses": masses,
            "frame": robot.joint_names[-1],
            "com": [float(v) for v in _lever(robot, theta)],
        }
        if masses
        else None,
        "noise": {"tau_relative": args.noise},
        "duration": args.duration,
        "rate": args.rate,
        "drive_gains": None if gains is None else [float(g) for g in gains],
        "files": [{"name": r.name, "seed": r.seed, "payload_mass": r.mass} for r in runs],
    }


def _lever(robot, theta: np.ndarray) -> np.ndarray:
    """The payload's centre of mass in the last joint's frame [m], as ``with_payload`` puts it."""
    i = 10 * (robot.n_bodies - 1)
    added = with_payload(robot, theta, 1.0)[i + 1 : i + 4] - theta[i + 1 : i + 4]
    return added  # [kg m] of a 1 kg mass: the lever [m]


def run(args: argparse.Namespace) -> int:
    args.design = None
    if args.trajectory is not None:
        args.design, design_duration = read_design(args.trajectory)
        args.duration = design_duration if args.duration is None else args.duration
    elif args.duration is None:
        args.duration = SIM_DEFAULTS["duration"]
    masses, runs = _check(args)
    outputs = reserve_outputs(args)
    claim = outputs.report(args.out, "--out", force=args.force)  # checked and claimed first
    robot = robot_from_args(args)
    gains = _gains(args, robot.nv)
    check_simulation_memory(robot, int(round(args.duration * args.rate)))
    theta = robot.nominal_parameters

    def fill(folder: Path) -> None:
        for r in runs:
            truth = with_payload(robot, theta, r.mass) if r.mass else theta
            save_dataset(_log(robot, r, truth, args, gains), folder / r.name, format=args.format)
            print(f"simulated {r.name}")
        (folder / "README.txt").write_text(_readme(robot, args, masses, runs, gains))
        write_json(folder / "truth.json", _truth(robot, args, masses, runs, gains))

    path = claim.build(fill)
    outputs.publish()  # the folder appears complete, or not at all
    print(f"wrote {len(runs)} log(s), README.txt and truth.json to {path}")
    return 0
