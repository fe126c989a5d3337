"""``identify --refine output-error`` and ``identify --rollout S``: the hooks of the file
path (:mod:`._files`) into :mod:`manip_id.identification.refine` and
:mod:`manip_id.identification.rollout`.

The training and validation files are read again, whole and preprocessed as the fit read
them (:func:`~manip_id.identification.rollout.read_logs`); a rollout is integrated on the
validation files.
"""

from __future__ import annotations

import argparse
import math
import time

from ..errors import InputError
from ..identification.refine import DEFAULT_HORIZON, RefineOptions, refine
from ..identification.rollout import RolloutOptions, read_logs, rollout_validation


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
    if args.simulate or args.model != "dynamic" or args.method not in ("ols", "wls"):
        raise InputError(f"{what} applies to --data files, --method ols or wls, --model dynamic")
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


def refine_files(args, robot, result, specs, vspecs, options, timings: dict):
    """The result refined by output error on the training files (``args.refine``)."""
    if getattr(args, "refine", None) is None:
        return result
    t0 = time.perf_counter()
    train = read_logs(robot, specs, options)
    valid = read_logs(robot, vspecs, options) if vspecs else None
    opts = RefineOptions(
        horizon=DEFAULT_HORIZON if args.refine_horizon is None else args.refine_horizon,
        windows=args.refine_windows,
    )
    out = refine(result, robot, train, validation=valid, options=opts)
    rec = out.context["refinement"]
    print(
        f"output-error refinement: {rec['windows']} windows of {rec['horizon']:.3g} s, "
        f"{rec['iterations']} iterations, cost {rec['cost_before']:.4g} -> {rec['cost_after']:.4g}"
    )
    timings["refine"] = time.perf_counter() - t0
    return out


def rollout_files(args, robot, result, vspecs, options, report: dict) -> None:
    """``report["rollout"]`` of the validation files (``args.rollout``); the figure's data
    kept as ``args.rollout_report`` for the report folder."""
    if getattr(args, "rollout", None) is None:
        return
    logs = read_logs(robot, vspecs, options)
    rep = rollout_validation(robot, result, logs, options=RolloutOptions(horizon=args.rollout))
    print(rep.table())
    report["rollout"] = rep.to_dict()
    args.rollout_report = rep
