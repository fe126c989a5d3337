"""``manip-id simulate`` once it runs: the logs simulated, written into a staged folder,
published complete (the options are declared in :mod:`.simulate`).

Run ``k`` of a group (``unloaded``, then one group per ``--payload`` mass) follows its own
excitation (:func:`._simulated.excitation`, seed ``SEED + k``, the loaded groups after
the unloaded ones), so any two files of the folder hold different motions: one may train
and another validate. The truth (:func:`truth_parameters`) is the robot's nominal
parameter vector, or one that differs from it as a real robot's does: its joint terms set
(``--joint-terms``), then perturbed within physics (``--perturb``,
:func:`manip_id.physics.perturbation.perturb_parameters`), then a tool mass on the last body
(``--tool``); the loaded runs add their payload on the last body
(:func:`manip_id.control.closed_loop.with_payload`).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import shutil
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._io import write_json
from .._io.fields import Fields
from ..control.closed_loop import TrackingLog, simulate_tracking, with_payload
from ..controller import load_controller
from ..datasets import Dataset, save_dataset
from ..errors import InputError, PhysicalConsistencyError, ResourceError
from ..identification import load_result
from ..monitor import model_from_result
from ..physics.perturbation import MAX_REL, perturb_parameters, require_physical
from ..simulation import MeasurementNoise, check_simulation_memory, simulate
from ..trajectories import read_design
from ._common import SIM_DEFAULTS, parse_floats, reserve_outputs
from ._runtime import robot_from_args
from ._simulated import excitation
from .simulate import LEVER

#: The joint-term names ``--joint-terms`` takes (those of :mod:`manip_id.robot.parameters`).
JOINT_TERMS = ("Ia", "fv", "fc", "fo", "k")
#: At most this many logs in one folder (``--files`` times the number of groups).
MAX_LOGS = 10_000
#: Bounds of the numbers that shape the logs, refused at their option beyond them.
MAX_NOISE = 100.0  # relative to the RMS torque
MAX_STATE_NOISE = 1.0  # [rad or m, rad/s or m/s]
MAX_PAYLOAD = 1e4  # [kg]
GAIN_RANGE = (1e-6, 1e6)  # [N m/A]
#: Bytes per stored value of each format (CSV: a printed float and its comma).
BYTES_PER_VALUE = {"npz": 8, "csv": 25, "mcap": 12}
#: Free disk kept beyond the estimated size of the folder.
DISK_MARGIN = 2**28  # [bytes]


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
    for name in ("position_noise", "velocity_noise"):
        value = getattr(args, name)
        if not (math.isfinite(value) and 0 <= value <= MAX_STATE_NOISE):
            raise InputError(
                f"--{name.replace('_', '-')} must be in [0, {MAX_STATE_NOISE:g}], got {value}"
            )
    if args.controller is not None:
        if args.format == "mcap":
            raise InputError("--controller writes the reference columns: --format npz or csv")
        if args.drive_gains is not None:
            raise InputError("--controller logs the commanded torques: no --drive-gains")
    if not (math.isfinite(args.noise) and 0 <= args.noise <= MAX_NOISE):
        raise InputError(
            f"--noise must be in [0, {MAX_NOISE:g}] (relative to the RMS torque), got {args.noise}"
        )
    if args.duration * args.rate < 10:
        raise InputError(
            f"--duration {args.duration:g} s at --rate {args.rate:g} Hz gives fewer than 10 samples"
        )
    if not (math.isfinite(args.perturb) and 0 <= args.perturb <= MAX_REL):
        raise InputError(f"--perturb must be a fraction in [0, {MAX_REL:g}], got {args.perturb}")
    if not (math.isfinite(args.tool) and args.tool >= 0):
        raise InputError(f"--tool must be a mass >= 0 [kg], got {args.tool}")
    masses = [] if args.payload is None else parse_floats(args.payload, "--payload")
    if any(not 0 < m <= MAX_PAYLOAD for m in masses):
        raise InputError(
            f"--payload masses must be in (0, {MAX_PAYLOAD:g}] [kg], got {_cut(args.payload)}"
        )
    if len(set(masses)) != len(masses):
        twice = next(m for m in masses if masses.count(m) > 1)
        raise InputError(f"--payload lists the mass {twice!r} kg twice; give each mass once")
    if args.files * (1 + len(masses)) > MAX_LOGS:
        raise InputError(
            f"--files {args.files} with {len(masses)} payload mass(es) asks for "
            f"{args.files * (1 + len(masses))} logs; at most {MAX_LOGS} in one folder"
        )
    width = len(str(args.files - 1))
    # the shortest decimal that reads back as the same float: distinct masses, distinct names
    groups = [("run", 0.0)] + [
        (f"payload_{np.format_float_positional(m, trim='-')}kg", m) for m in masses
    ]
    runs = [
        Run(f"{prefix}_{k:0{width}d}.{args.format}", args.seed + g * args.files + k, mass)
        for g, (prefix, mass) in enumerate(groups)
        for k in range(args.files)
    ]
    if len({r.name for r in runs}) != len(runs):  # pragma: no cover - unique by construction
        raise InputError("two simulated logs would have the same file name")
    return masses, runs


def joint_term_values(text: str | None) -> dict[str, float]:
    """``--joint-terms fv=0.4,fc=0.6`` -> {"fv": 0.4, "fc": 0.6} (one value for every joint)."""
    if text is None:
        return {}
    out: dict[str, float] = {}
    for item in str(text).split(","):
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep or name not in JOINT_TERMS:
            raise InputError(
                f"--joint-terms expects TERM=VALUE items with TERM one of {', '.join(JOINT_TERMS)}"
                f", e.g. fv=0.4,fc=0.6; got {item!r}"
            )
        try:
            number = float(value)
        except ValueError:
            raise InputError(f"--joint-terms: {name} takes a number, got {value!r}") from None
        if not math.isfinite(number) or (name != "fo" and number < 0):
            raise InputError(f"--joint-terms: {name} must be a finite number >= 0, got {value!r}")
        out[name] = number
    return out


def truth_parameters(robot, args: argparse.Namespace) -> np.ndarray:
    """The parameters behind the logs, shape (p,): the nominal ones (``--model``: the
    result's) with ``--joint-terms`` set for every joint, perturbed by ``--perturb`` (seed
    ``--seed``), plus the ``--tool`` mass on the last body."""
    if args.model is None:
        theta = robot.nominal_parameters.copy()
    else:  # the identified base parameters, the regrouped columns at the URDF's values
        theta = _model_parameters(robot, Path(args.model))
    values = joint_term_values(args.joint_terms)
    missing = [t for t in values if t not in robot.terms.enabled]
    if missing:
        raise InputError(
            f"--joint-terms sets {', '.join(missing)}, which the robot's model does not have "
            f"(modelled: {', '.join(robot.terms.enabled) or 'none'}); add --friction viscous,"
            "coulomb (fv, fc), offset (fo), --armature (Ia) or --spring (k)"
        )
    joint = robot.layout.joint_block(theta)  # a view into theta, shape (nv, n_terms)
    for term, value in values.items():
        joint[:, robot.terms.enabled.index(term)] = value
    theta = perturb_parameters(robot, args.perturb, seed=args.seed, theta=theta)
    return with_payload(robot, theta, args.tool) if args.tool else theta


def _model_parameters(robot, path: Path) -> np.ndarray:
    """The standard parameters of a saved result, shape (p,): its physically consistent
    standard parameters when it has them (``--consistent``), else its base parameters with
    the regrouped columns at the URDF's values (the same torques); a model that is not
    physically consistent is refused (it cannot be simulated)."""
    result = load_result(path / "result.json" if path.is_dir() else path)
    theta = model_from_result(robot, result, source=str(path)).theta
    rows = result.context.get("standard_parameters")
    if result.context.get("physically_consistent") and isinstance(rows, list):
        values = {r.get("name"): r.get("value") for r in rows if isinstance(r, dict)}
        if set(values) == set(robot.parameter_names):
            f = Fields(path)
            theta = np.array(
                [f.number(values[n], f"standard_parameters {n}") for n in robot.parameter_names]
            )
    try:
        require_physical(robot, theta)
    except PhysicalConsistencyError as exc:
        raise InputError(
            f"--model {path}: its parameters cannot be simulated ({exc}); identify with "
            "--consistent for a physically consistent model"
        ) from None
    return theta


def _cut(text, n: int = 80) -> str:
    """``text`` as quoted in a message, at most ``n`` characters."""
    text = str(text)
    return text if len(text) <= n else f"{text[:n]}... ({len(text)} characters)"


def _check_disk(robot, args, runs: list[Run]) -> None:
    """Refuse a folder whose estimated size exceeds the free disk beside ``--out``."""
    n = int(round(args.duration * args.rate)) + 1
    values = n * (1 + robot.nq + 3 * robot.nv)  # t, q, dq, ddq, tau per sample
    need = len(runs) * values * BYTES_PER_VALUE[args.format]  # [bytes]
    free = shutil.disk_usage(Path(args.out).absolute().parent).free
    if need + DISK_MARGIN > free:
        raise ResourceError(
            f"{len(runs)} log(s) of {n} samples of {robot.nv} joints need about "
            f"{need / 1e9:.3g} GB, but {free / 1e9:.3g} GB are free beside {args.out} "
            f"(keeping {DISK_MARGIN / 1e9:.2g} GB): fewer --files, a shorter --duration or "
            "a lower --rate"
        )


def _gains(args: argparse.Namespace, nv: int) -> np.ndarray | None:
    """The ``--drive-gains`` per joint [N m/A], shape (nv,), or None (torques written)."""
    if args.drive_gains is None:
        return None
    gains = np.array(parse_floats(args.drive_gains, "--drive-gains"))
    if gains.size == 1:
        gains = np.full(nv, gains[0])
    if gains.shape != (nv,):
        raise InputError(f"--drive-gains takes 1 or {nv} gains (one per joint), got {gains.size}")
    lo, hi = GAIN_RANGE
    if np.any(gains < lo) or np.any(gains > hi):
        raise InputError(
            f"--drive-gains must be in [{lo:g}, {hi:g}] [N m/A], got {_cut(args.drive_gains)}"
        )
    return gains


def _noise(args) -> MeasurementNoise:
    return MeasurementNoise(tau=args.noise, q=args.position_noise, dq=args.velocity_noise)


def _tracking_log(robot, run: Run, theta: np.ndarray, args) -> TrackingLog:
    """The closed-loop log of one run (``--controller``)."""
    traj = args.design if args.design is not None else excitation(robot, run.seed)
    if traj.nv != robot.nv:
        raise InputError(f"--trajectory has {traj.nv} joints but {robot.name!r} has {robot.nv}")
    return simulate_tracking(
        robot, traj, args.loop, duration=args.duration, rate=args.rate, theta=theta,
        noise=_noise(args), seed=run.seed,
    )  # fmt: skip


def _save_tracking(log: TrackingLog, controller, path: Path, fmt: str) -> None:
    """A closed-loop log with its reference columns (:mod:`manip_id.controller`)."""
    d = log.dataset
    qc, dqc = controller.q_column, controller.dq_column
    names = tuple(d.joint_names or ())
    if fmt == "npz":
        arrays: dict[str, Any] = {"t": d.t, "q": d.q, "dq": d.dq, "tau": d.tau}
        arrays.update({qc: log.q_ref, dqc: log.dq_ref, "joint_names": np.array(names)})
        with open(path, "wb") as fh:
            np.savez(fh, **arrays)
        return
    header = ["t"] + [f"{f}_{j}" for f in ("q", "dq", "tau", qc, dqc) for j in names]
    rows = np.column_stack([d.t, d.q, d.dq, d.tau, log.q_ref, log.dq_ref])
    np.savetxt(path, rows, delimiter=",", header=",".join(header), comments="", fmt="%.17g")


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
        noise=_noise(args),
        seed=run.seed,
    )
    data = sim.dataset
    tr = robot.transmission
    if tr is not None and tr.signals == "motor":  # a motor-side log: theta = R (q - offset)
        q, dq, ddq, tau = tr.to_motor(data.q, data.dq, data.ddq, data.tau)
        with warnings.catch_warnings():  # motor angles [rad] are large, not degrees
            warnings.filterwarnings("ignore", message=".*degrees.*")
            data = dataclasses.replace(data, q=q, dq=dq, ddq=ddq, tau=tau)
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
        "truth: " + _truth_words(args) + " (truth.json: every parameter by name)",
        (
            f"motion: the designed excitation {args.trajectory} in every file (noise seed "
            f"{runs[0].seed} for the first, +1 per file)"
            if args.trajectory
            else f"motion: one random Fourier excitation per file (seed {runs[0].seed} for the "
            "first, +1 per file); no two files repeat a motion"
        ),
        f"samples: {args.duration:g} s at {args.rate:g} Hz per file; "
        + (
            "q, dq measured (noise below), no ddq"
            if args.controller
            else "q, dq and ddq exact"
            + (" (ddq not in MCAP bags)" if args.format == "mcap" else "")
        ),
        f"torque noise: Gaussian, std {args.noise:g} x each joint's RMS torque",
        f"position noise: Gaussian, std {args.position_noise:g} rad; velocity noise: std "
        f"{args.velocity_noise:g} rad/s",
    ]
    if args.controller:
        lines.append(
            f"closed loop: the {args.loop.kind.upper()} controller of {args.controller} tracks the "
            f"excitation (columns {args.loop.q_column}_<joint>, {args.loop.dq_column}_<joint>; "
            "NPZ arrays of those names), reading the noisy measurement; torque columns: "
            "the commanded torques (identify --method iv --controller "
            f"{args.controller})"
        )
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


def _truth_words(args) -> str:
    """How the truth differs from the URDF, in words."""
    parts = [f"joint terms {args.joint_terms}"] if args.joint_terms else []
    if args.perturb:
        parts.append(f"inertial parameters perturbed by about {100 * args.perturb:g} %")
    if args.tool:
        parts.append(f"a {args.tool:g} kg tool (not in the URDF) at {LEVER:g} m on the last body")
    own = "the robot's nominal parameters" if args.model is None else f"the model of {args.model}"
    return own + (" with " + ", ".join(parts) if parts else "")


def _truth(robot, args, theta, masses: list[float], runs: list[Run], gains) -> dict:
    """truth.json: the parameters behind the logs, by name."""
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
        "differs_from_urdf": {
            "joint_terms": joint_term_values(args.joint_terms),
            "perturb": args.perturb,
            "perturb_seed": args.seed,
            "tool_mass": args.tool,
            "model": args.model,
        },
        "noise": {
            "tau_relative": args.noise,
            "position": args.position_noise,
            "velocity": args.velocity_noise,
        },
        "controller": None if args.loop is None else args.loop.to_dict(),
        "duration": args.duration,
        "rate": args.rate,
        "drive_gains": None if gains is None else [float(g) for g in gains],
        "transmission": None if robot.transmission is None else robot.transmission.to_dict(),
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
    robot = robot_from_args(args, args.model)  # --model: the result's joint model
    if args.trajectory is not None:
        read_design(args.trajectory, robot)  # the design's robot and joints, before work
    gains = _gains(args, robot.nv)
    args.loop = None if args.controller is None else load_controller(args.controller, robot.nv)
    tr = robot.transmission
    if args.loop is not None and tr is not None and tr.signals == "motor":
        raise InputError("--controller writes joint-side logs: no motor-side --transmission")
    check_simulation_memory(robot, int(round(args.duration * args.rate)))
    _check_disk(robot, args, runs)
    theta = truth_parameters(robot, args)

    def fill(folder: Path) -> None:
        for r in runs:
            truth = with_payload(robot, theta, r.mass) if r.mass else theta
            if args.loop is not None:
                log = _tracking_log(robot, r, truth, args)
                _save_tracking(log, args.loop, folder / r.name, args.format)
            else:
                data = _log(robot, r, truth, args, gains)
                save_dataset(data, folder / r.name, format=args.format)
            if not args.quiet:
                print(f"simulated {r.name}")
        (folder / "README.txt").write_text(_readme(robot, args, masses, runs, gains))
        write_json(folder / "truth.json", _truth(robot, args, theta, masses, runs, gains))

    path = claim.build(fill)
    outputs.publish()  # the folder appears complete, or not at all
    if not args.quiet:
        print(f"wrote {len(runs)} log(s), README.txt and truth.json to {path}")
    return 0
