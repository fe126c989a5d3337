"""``manip-id identify`` once it runs: the options checked (before any work), the outputs
reserved, then one run path: log files, here or on Dask (:mod:`._files`), the
acceleration-free models (:mod:`._acceleration_free`) or a
simulation (:mod:`._simulated`). The options are declared in :mod:`.identify`.
"""

from __future__ import annotations

import argparse
import math
import time

from ..datasets import Window
from ..errors import InputError
from ..export import check_output, sidecar_path
from . import _acceleration_free, _files, _rollout, _simulated
from ._common import (
    FLEET_METHODS,
    check_preprocess_args,
    explicit_workers,
    fleet_wanted,
    parse_floats,
    quiet_stdout,
    reserve_outputs,
)
from ._runtime import check_scheduler, consistent_options


# -------------------------------------------------------------------- checks
def _check_args(args) -> None:
    _rollout.check_closed_loop_args(args)  # first: --method iv/didim without --controller
    if not args.simulate:
        given = [n for n in ("duration", "noise", "seed") if getattr(args, n) is not None]
        rate = getattr(args, "rate", None)  # with --data: files without a time column
        if rate is not None and not (math.isfinite(rate) and rate > 0):
            raise InputError(f"--rate must be a positive frequency [Hz], got {rate}")
        if given or args.optimize:
            raise InputError(f"--{(given or ['optimize'])[0]} applies to --simulate only")
    else:
        for name in ("duration", "rate"):
            value = getattr(args, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise InputError(f"--{name} must be positive, got {value}")
        if args.noise is not None and not (math.isfinite(args.noise) and args.noise >= 0):
            raise InputError(f"--noise must be >= 0 (relative), got {args.noise}")
    if args.column and args.simulate and args.validate is None:
        raise InputError("--column applies to CSV data files (--data, --validate) only")
    if args.split is not None and not 0.0 < args.split < 1.0:
        raise InputError(f"--split must be a fraction in (0, 1), got {args.split}")
    check_preprocess_args(args)
    for name in ("poorly_identified", "condition_limit"):
        value = getattr(args, name, None)
        if value is not None and not (math.isfinite(value) and value > 0):
            raise InputError(f"--{name.replace('_', '-')} must be positive, got {value}")
    if explicit_workers(args) > 1 and args.method in ("rls", "gradient"):
        raise InputError(f"--workers applies to ols and wls; {args.method} runs in sample order")
    if getattr(args, "friction", None) == "auto" and (
        args.simulate
        or args.model != "dynamic"
        or args.method not in ("ols", "wls")
        or fleet_wanted(args)
    ):
        raise InputError(
            "--friction auto applies to --data files with --method ols or wls and the "
            "dynamic model, without --scheduler or --per-file"
        )
    _check_consistent_args(args)
    _check_fleet(args)
    _check_files(args)
    _rollout.check_args(args)


def _check_consistent_args(args) -> None:
    """--consistent, --solver, --prior, --prior-weight, --bounds, --mass-range, --total-mass,
    --export-urdf, --export-mjcf (before any work)."""
    given = [
        f"--{n.replace('_', '-')}"
        for n, default in (
            ("solver", "sdp"),
            ("prior", "nominal"),
            ("prior_weight", None),
            ("bounds", "geometry"),
            ("mass_range", None),
            ("total_mass", None),
        )
        if getattr(args, n) != default
    ]
    consistent_options(args)  # the options' own checks (solver, prior, weight, bounds)
    if not args.consistent:
        exports = (("--export-urdf", args.export_urdf), ("--export-mjcf", args.export_mjcf))
        for flag, value in exports:
            if value:
                raise InputError(f"{flag} needs a physically consistent estimate: add --consistent")
        if given:
            raise InputError(f"{given[0]} applies to --consistent only")
        return
    if args.method not in ("ols", "wls"):
        raise InputError(f"--consistent applies to --method ols or wls, got {args.method}")
    if fleet_wanted(args):
        raise InputError(
            "--consistent does not combine with --scheduler or --per-file (the fleet path) "
            "yet: run it without them (several --data files are accumulated alike)"
        )
    if getattr(args, "refine", None) and (args.export_urdf or args.export_mjcf):
        raise InputError(
            "--refine gives base parameters, not a physical model: an export writes the "
            "consistent estimate, so export without --refine (or later: manip-id export "
            "ROBOT --model RESULT.json of the consistent run)"
        )
    if args.export_urdf:
        check_output(args.export_urdf, force=args.force)
    if args.export_mjcf:
        check_output(args.export_mjcf, force=args.force, suffixes=(".xml",))


def _check_files(args: argparse.Namespace) -> None:
    """Refuse option combinations the file path does not do, before any work."""
    if getattr(args, "torque_scale_from", None) is not None:  # manip-id drive-gains --json
        if args.simulate or args.torque_scale is not None:
            raise InputError("--torque-scale-from applies to --data files, without --torque-scale")
        # checked against the robot (its name and its joints, in order) once it is loaded
    if args.simulate:
        for name in ("window", "torque_scale", "velocity_deadband", "topic", "delay", "time_unit"):
            if getattr(args, name, None) is not None:
                raise InputError(f"--{name.replace('_', '-')} applies to --data files")
        for name in ("drop_bad_rows", "trim_standstill"):
            if getattr(args, name, False):
                raise InputError(f"--{name.replace('_', '-')} applies to --data files")
        return
    if getattr(args, "trim_standstill", False) and fleet_wanted(args):
        raise InputError(
            "--trim-standstill needs the pre-fit audit, which --scheduler / --per-file do not run"
        )
    if getattr(args, "model", "dynamic") != "dynamic":  # files read whole, without a FileSpec
        for name in ("delay", "time_unit", "trim_standstill", "transmission", "rate"):
            if getattr(args, name, None) not in (None, False):
                raise InputError(f"--{name.replace('_', '-')} applies to --model dynamic")
    if args.velocity_deadband is not None:
        eps = args.velocity_deadband
        if not (math.isfinite(eps) and eps > 0):
            raise InputError(f"--velocity-deadband must be positive [rad/s], got {eps}")
        if args.method in ("rls", "gradient"):
            raise InputError(
                "--velocity-deadband applies to ols and wls (the online laws take every sample)"
            )
    if args.torque_scale is not None:
        parse_floats(args.torque_scale, "--torque-scale")
    if args.window is not None:
        Window.parse(args.window, "--window")
    if args.split is not None and args.data is not None and len(args.data) > 1:
        raise InputError(
            "--split cuts one file; with several --data files give --validate files "
            "(or windows FILE@START:STOP)"
        )


def _check_fleet(args: argparse.Namespace) -> None:
    """Refuse what the fleet path does not do, before any work."""
    if args.block is not None and not fleet_wanted(args):
        raise InputError("--block applies with --scheduler or --per-file")
    if not fleet_wanted(args):
        return
    opt = "--scheduler" if args.scheduler is not None else "--per-file"
    if args.simulate:
        raise InputError(f"{opt} works on --data files, not on --simulate")
    if args.method not in FLEET_METHODS:
        raise InputError(
            f"{opt} accumulates ols or wls; {args.method} runs in sample order on one process"
        )
    if args.split is not None:
        raise InputError(f"{opt} identifies whole files: give validation files with --validate")
    if explicit_workers(args) > 1:
        raise InputError("--workers forks local processes; with --scheduler use local:N")
    if args.block is not None and args.block < 1:
        raise InputError(f"--block must be >= 1 samples, got {args.block}")
    check_scheduler(args)


# ----------------------------------------------------------------------- run
def run(args: argparse.Namespace) -> int:
    """``manip-id identify`` (``--quiet``: nothing on stdout)."""
    with quiet_stdout(args):
        return _run(args)


def _run(args: argparse.Namespace) -> int:
    t_start = time.perf_counter()
    _check_args(args)
    outputs = reserve_outputs(args)  # every output checked (and the report claimed) first
    if args.export_urdf:
        outputs.file(sidecar_path(args.export_urdf), "--export-urdf sidecar")
    if args.export_mjcf:
        outputs.file(args.export_mjcf, "--export-mjcf")
        outputs.file(sidecar_path(args.export_mjcf), "--export-mjcf sidecar")
    if fleet_wanted(args):  # many files, one task each (Dask with --scheduler)
        return _files.run(args, outputs, t_start)
    if args.model != "dynamic":  # energy / momentum: whole arrays, no ddq
        return _acceleration_free.run(args, outputs, t_start)
    if not args.simulate:  # log files: read in chunks, each preprocessed alone
        return _files.run(args, outputs, t_start)
    return _simulated.run(args, outputs, t_start)
