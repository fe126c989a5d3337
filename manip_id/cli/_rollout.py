"""``identify --refine output-error`` and ``identify --rollout S``: checked before any
work, then given to the library's file run as ``FileOptions(refine=..., rollout=...)``
(:mod:`manip_id.identification.refine`, :mod:`manip_id.identification.rollout`).
"""

from __future__ import annotations

import argparse
import math

from ..controller import load_controller
from ..errors import InputError
from ..identification.closed_loop import ClosedLoopOptions
from ..identification.refine import DEFAULT_HORIZON, RefineOptions
from ..identification.rollout import RolloutOptions


def check_args(args: argparse.Namespace) -> None:
    """Refuse what --refine and --rollout cannot do, before any work."""
    refine_on = getattr(args, "refine", None) is not None
    rollout = getattr(args, "rollout", None)
    if not refine_on and rollout is None:
        for name in ("refine_horizon", "refine_windows"):
            if getattr(args, name, None) is not None:
                flag = "--" + name.replace("_", "-")
                raise InputError(f"{flag} applies to --refine output-error")
        return
    what = "--refine" if refine_on else "--rollout"
    methods = ("ols", "wls") if refine_on else ("ols", "wls", *CLOSED_LOOP)
    if args.simulate or args.model != "dynamic" or args.method not in methods:
        words = "ols or wls" if refine_on else "ols, wls, iv or didim"
        raise InputError(f"{what} applies to --data files, --method {words}, --model dynamic")
    if getattr(args, "scheduler", None) is not None or getattr(args, "per_file", False):
        raise InputError(f"{what} runs on one process: no --scheduler or --per-file")
    if rollout is not None:
        if not (math.isfinite(rollout) and rollout > 0):
            raise InputError(f"--rollout must be a horizon > 0 seconds, got {rollout}")
        if args.validate is None and args.split is None:
            raise InputError("--rollout integrates on validation data: give --validate or --split")
    h = getattr(args, "refine_horizon", None)
    if h is not None and not (refine_on and math.isfinite(h) and h > 0):
        raise InputError(f"--refine-horizon applies to --refine and is > 0 seconds, got {h}")
    n = getattr(args, "refine_windows", None)
    if n is not None and not (refine_on and n >= 1):
        raise InputError(f"--refine-windows applies to --refine and is >= 1, got {n}")


def forward_options(args: argparse.Namespace) -> dict:
    """The :class:`~manip_id.identification.FileOptions` fields of ``--refine`` and
    ``--rollout`` (the library's file run refines and rolls out)."""
    out: dict = {}
    if getattr(args, "refine", None) is not None:
        out["refine"] = RefineOptions(
            horizon=DEFAULT_HORIZON if args.refine_horizon is None else args.refine_horizon,
            windows=args.refine_windows,
        )
    if getattr(args, "rollout", None) is not None:
        out["rollout"] = RolloutOptions(horizon=args.rollout)
    return out


#: The closed-loop estimators of ``--method`` (:mod:`manip_id.identification.closed_loop`).
CLOSED_LOOP = ("iv", "didim")


def check_closed_loop_args(args: argparse.Namespace):
    """Refuse what ``--method iv/didim`` and ``--controller`` cannot do, before any work;
    the controller file read and checked (its size against the robot's once loaded)."""
    closed = args.method in CLOSED_LOOP
    path = getattr(args, "controller", None)
    if not closed:
        if path is not None:
            raise InputError("--controller applies to --method iv or didim")
        return None
    if path is None:
        raise InputError(
            f"--method {args.method} simulates the model in closed loop: give the logs' "
            "controller with --controller FILE.toml"
        )
    if args.simulate or args.model != "dynamic":
        raise InputError(f"--method {args.method} applies to --data files and --model dynamic")
    if getattr(args, "scheduler", None) is not None or getattr(args, "per_file", False):
        raise InputError(
            f"--method {args.method} runs on one process: no --scheduler or --per-file"
        )
    if getattr(args, "refine", None) is not None:
        raise InputError(f"--method {args.method} and --refine both replace the estimate: give one")
    return load_controller(path)


def closed_loop_options(args: argparse.Namespace, nv: int) -> dict:
    """The :class:`~manip_id.identification.FileOptions` field of ``--method iv/didim``."""
    if args.method not in CLOSED_LOOP:
        return {}
    controller = load_controller(args.controller, nv)
    return {"closed_loop": ClosedLoopOptions(args.method, controller)}
