"""``manip-id identify``: base parameters of a robot from a log or a simulation.

Pipeline: load (``--data``: NPZ, CSV or a Panda log folder) or simulate
(``--simulate``), split off validation data (``--split`` or ``--validate``),
preprocess each part alone (resampling, zero-phase low-pass, ddq by central
differences, edge trimming: :func:`manip_id.signals.preprocess`), identify the
base parameters, print a table and optionally write JSON (atomically).
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

from ..datasets import Dataset, check_robot, load_dataset
from ..errors import InputError
from ..signals import DEFAULT_CUTOFF, DEFAULT_ORDER, preprocess
from . import _files, _fleet
from ._common import add_robot_arguments, reserve_outputs, robot_from_args

METHODS = ("ols", "wls", "rls", "gradient")
SIM_DEFAULTS = {"duration": 20.0, "rate": 200.0, "noise": 0.01, "seed": 0}
#: A progress bar appears on stderr (a terminal, without --quiet) once a run passes this [s].
PROGRESS_DELAY = 2.0
#: Set by ``run`` from ``--quiet``: no progress bar.
_QUIET = [False]


def register(sub) -> None:
    p = sub.add_parser(
        "identify",
        help="identify base parameters from data or a simulation",
        description="Identify the base dynamic parameters of ROBOT from measured data (--data) or "
        "from a simulated excitation (--simulate); print the parameters with their "
        "relative standard deviations, the condition number and the relative torque "
        "errors on training and validation data.",
    )
    add_robot_arguments(p)
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument(
        "--data",
        metavar="FILE",
        nargs="+",
        action="extend",
        help="one or more measurement files (--data a b, or --data a --data b; each read in "
        "chunks and preprocessed on its own): .npz (t, q, dq, tau[, ddq, joint_names]), .csv "
        "(t,q_<joint>...,dq_<joint>...,tau_<joint>...), a ROS 2 bag (rosbag2 folder or "
        ".mcap) or a Panda log folder; FILE@START:STOP [s] or FILE@#A:#B [rows] for a window",
    )
    p.add_argument(
        "--column",
        action="append",
        default=[],
        metavar="FIELD=COLUMNS",
        help="CSV column map for other layouts (repeatable): FIELD is t, q, dq, ddq, tau or "
        "joint_names; COLUMNS a header name, a glob such as 'pos*', or a comma-separated list of "
        "names or 0-based indices, e.g. --column t=stamp --column q='pos*'",
    )
    src.add_argument(
        "--simulate",
        action="store_true",
        help="simulate measurements along a random Fourier excitation",
    )
    sim = p.add_argument_group("simulation (with --simulate)")
    sim.add_argument(
        "--duration",
        type=float,
        default=None,
        help=f"seconds [default {SIM_DEFAULTS['duration']:g}]",
    )
    sim.add_argument(
        "--rate",
        type=float,
        default=None,
        help=f"sampling rate [Hz] [default {SIM_DEFAULTS['rate']:g}]",
    )
    sim.add_argument(
        "--noise",
        type=float,
        default=None,
        help="torque noise, relative to each joint's RMS torque "
        f"[default {SIM_DEFAULTS['noise']:g}]",
    )
    sim.add_argument(
        "--seed",
        type=int,
        default=None,
        help=f"seed of trajectory and noise [default {SIM_DEFAULTS['seed']}]",
    )
    sim.add_argument(
        "--optimize",
        action="store_true",
        help="optimize the excitation (condition number) instead of a random one",
    )
    p.add_argument("--method", choices=METHODS, default="ols", help="estimator [default ols]")
    p.add_argument(
        "--model",
        choices=("dynamic", "energy", "momentum"),
        default="dynamic",
        help="dynamic: tau = Y(q, dq, ddq) theta [default]; energy (over intervals) or "
        "momentum (filtered): no acceleration, only q and dq filtered (one --data file)",
    )
    p.add_argument(
        "--window-length",
        type=float,
        default=None,
        metavar="SECONDS",
        help="energy interval / momentum row spacing [s] (default 0.2; momentum filter "
        "bandwidth 3 / SECONDS rad/s)",
    )
    val = p.add_mutually_exclusive_group()
    val.add_argument(
        "--validate",
        metavar="FILE",
        nargs="+",
        action="extend",
        help="one or more validation files (same formats and windows as --data)",
    )
    val.add_argument(
        "--split",
        type=float,
        metavar="FRACTION",
        help="identify on the first FRACTION of the samples, validate on the rest",
    )
    sig = p.add_argument_group(
        "signal processing (for data without ddq, or when --cutoff is given)"
    )
    sig.add_argument(
        "--cutoff",
        type=float,
        default=None,
        help=f"low-pass cut-off [Hz] [default {DEFAULT_CUTOFF:g}]",
    )
    sig.add_argument(
        "--order",
        type=int,
        default=DEFAULT_ORDER,
        help=f"Butterworth order [default {DEFAULT_ORDER}]",
    )
    sig.add_argument(
        "--trim",
        type=float,
        default=None,
        help="seconds dropped at each end of each part [default: the filter's edge transient]",
    )
    sig.add_argument("--decimate", type=int, default=1, help="keep every D-th sample [default 1]")
    p.add_argument("--json", metavar="OUT", help="write the results as JSON to OUT")
    p.add_argument(
        "--report",
        metavar="DIR",
        help="write a report folder: result.json, torque fit, residuals, singular values, "
        "trajectory vs limits (--simulate), the robot scene (scene.html) and index.html",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="replace a non-empty --report folder or an existing --export-urdf file",
    )
    p.add_argument(
        "--quiet",
        action="store_true",
        help="print nothing but errors and warnings (no progress bar, no tables)",
    )
    rep = p.add_argument_group("report and flags")
    rep.add_argument(
        "--scene-assets",
        choices=("inline", "external"),
        default="inline",
        help="inline: scene.html stands alone; external: the viewer script and the scene data "
        "are written once beside it (meshcat.min.js, scene-data.js) [default inline]",
    )
    rep.add_argument(
        "--poorly-identified",
        type=float,
        default=None,
        metavar="PERCENT",
        help="flag a base parameter 'poorly identified' above this std [%%] [default 10]",
    )
    rep.add_argument(
        "--condition-limit",
        type=float,
        default=None,
        metavar="C",
        help="warn when the condition number exceeds C [default 100]",
    )
    p.add_argument("--chunk", type=int, default=1024, help="samples per regressor chunk")
    p.add_argument(
        "--workers",
        type=int,
        default=1,
        help="processes accumulating parts of the data (ols, wls; default 1)",
    )
    phys = p.add_argument_group("physically consistent estimation (ols, wls)")
    phys.add_argument(
        "--consistent",
        action="store_true",
        help="estimate standard parameters that describe a real robot: every body's "
        "pseudo-inertia positive definite, armature and viscous/Coulomb friction >= 0, the "
        "same least-squares fit through the base parameters",
    )
    phys.add_argument(
        "--solver",
        default="sdp",
        metavar="{sdp,logchol}",
        help="sdp: semidefinite program (cvxpy + Clarabel); logchol: log-Cholesky "
        "Levenberg-Marquardt [default sdp]",
    )
    phys.add_argument(
        "--prior",
        default="nominal",
        metavar="{nominal,none}",
        help="what fills the directions the data cannot identify: the URDF's parameters "
        "(log-det divergence) or none (feasibility alone) [default nominal]",
    )
    phys.add_argument(
        "--prior-weight",
        type=float,
        default=None,
        help="weight of the prior against the fit measured in standard deviations, the OLS "
        "ones inflated by the feasibility fit's chi-square over its expected value when the "
        "residuals are not white [default 0.1]",
    )
    phys.add_argument(
        "--export-urdf",
        metavar="OUT.urdf",
        help="write the robot's URDF with the identified inertias and friction (needs "
        "--consistent); armature and offset go to OUT.identified.json next to it",
    )
    _fleet.add_arguments(p)
    _files.add_arguments(p)
    p.set_defaults(func=run)


# ------------------------------------------------------------------- helpers
def _progress(total_hint: int = 0):
    """A callable(done, total) drawing a tqdm bar on stderr, or None.

    The bar shows when stderr is a terminal and ``--quiet`` was not given, and only
    once the run has taken :data:`PROGRESS_DELAY` seconds; otherwise nothing is
    printed (logs and pipes stay clean).
    """
    if _QUIET[0] or not sys.stderr.isatty():
        return None
    state: dict = {"bar": None}

    def report(done: int, total: int) -> None:
        bar = state["bar"]
        if bar is None:
            from tqdm import tqdm

            bar = state["bar"] = tqdm(
                total=max(total, total_hint, 1),
                desc="identify",
                unit=" samples",
                file=sys.stderr,
                delay=PROGRESS_DELAY,
                leave=False,
                dynamic_ncols=True,
            )
        if total > bar.total:
            bar.total = total
        bar.update(max(done - bar.n, 0))
        if done >= total:
            bar.close()

    return report


def _finite(x):
    x = float(x)
    return x if math.isfinite(x) else None


def _prepare(ds: Dataset, args, what: str) -> Dataset:
    """Preprocess when ddq is missing or a cut-off was asked for."""
    if ds.ddq is not None and args.cutoff is None and args.decimate == 1 and args.trim is None:
        return ds
    cutoff = DEFAULT_CUTOFF if args.cutoff is None else args.cutoff
    try:
        return preprocess(
            ds, cutoff=cutoff, order=args.order, decimate=args.decimate, trim=args.trim
        )
    except InputError as exc:
        raise InputError(f"{what}: {exc}") from exc


def _column_map(specs: list[str]) -> dict | None:
    """``["t=stamp", "q=pos*", "tau=3,4,5"]`` -> a column map for :func:`load_dataset`."""
    if not specs:
        return None
    out: dict = {}
    for spec in specs:
        field, sep, cols = spec.partition("=")
        if not sep or not field.strip() or not cols.strip():
            raise InputError(f"--column expects FIELD=COLUMNS, e.g. q='pos*', got {spec!r}")
        names = [c.strip() for c in cols.split(",") if c.strip()]
        items: list[int | str] = [int(c) if c.lstrip("-").isdigit() else c for c in names]
        field = field.strip()
        out[field] = items if field in ("joint_names",) or len(items) > 1 else items[0]
    return out


def _check_args(args) -> None:
    if not args.simulate:
        given = [n for n in ("duration", "rate", "noise", "seed") if getattr(args, n) is not None]
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
    if args.cutoff is not None and not (math.isfinite(args.cutoff) and args.cutoff > 0):
        raise InputError(f"--cutoff must be a positive frequency [Hz], got {args.cutoff}")
    if args.trim is not None and not (math.isfinite(args.trim) and args.trim >= 0):
        raise InputError(f"--trim must be >= 0 seconds, got {args.trim}")
    if args.decimate < 1:
        raise InputError(f"--decimate must be >= 1, got {args.decimate}")
    if args.chunk < 1:
        raise InputError(f"--chunk must be >= 1, got {args.chunk}")
    for name in ("poorly_identified", "condition_limit"):
        value = getattr(args, name, None)
        if value is not None and not (math.isfinite(value) and value > 0):
            raise InputError(f"--{name.replace('_', '-')} must be positive, got {value}")
    if args.workers < 1:
        raise InputError(f"--workers must be >= 1, got {args.workers}")
    if args.workers > 1 and args.method in ("rls", "gradient"):
        raise InputError(f"--workers applies to ols and wls; {args.method} runs in sample order")
    if getattr(args, "friction", None) == "auto" and (
        args.simulate
        or args.model != "dynamic"
        or args.method not in ("ols", "wls")
        or _fleet.wanted(args)
    ):
        raise InputError(
            "--friction auto applies to --data files with --method ols or wls and the "
            "dynamic model, without --scheduler or --per-file"
        )
    _check_consistent_args(args)
    _fleet.check(args)
    _files.check(args)


def _check_consistent_args(args) -> None:
    """--consistent, --solver, --prior, --prior-weight, --export-urdf (before any work)."""
    from ..estimators.consistent import DEFAULT_PRIOR_WEIGHT, check_options

    given = [
        f"--{n.replace('_', '-')}"
        for n, default in (("solver", "sdp"), ("prior", "nominal"), ("prior_weight", None))
        if getattr(args, n) != default
    ]
    if args.prior_weight is None:
        args.prior_weight = DEFAULT_PRIOR_WEIGHT
    check_options(args.solver, args.prior, args.prior_weight)
    if not args.consistent:
        if args.export_urdf:
            raise InputError(
                "--export-urdf needs a physically consistent estimate: add --consistent"
            )
        if given:
            raise InputError(f"{given[0]} applies to --consistent only")
        return
    if args.method not in ("ols", "wls"):
        raise InputError(f"--consistent applies to --method ols or wls, got {args.method}")
    if _fleet.wanted(args):
        raise InputError("--consistent is not available with several data files yet")
    if args.export_urdf:
        from ..export import check_output

        check_output(args.export_urdf, force=args.force)


def _export(robot, result, args, outputs) -> None:
    """Stage the exported URDF and its sidecar (published with the other outputs)."""
    from ..export import export_texts, sidecar_path

    texts = export_texts(robot, result.standard.values, args.export_urdf)
    outputs.write_text(args.export_urdf, texts.urdf)
    outputs.write_json(sidecar_path(args.export_urdf), texts.sidecar)


def _consistent_kwargs(args) -> dict:
    from ..identification import ConsistentOptions

    return dict(
        consistent=ConsistentOptions(
            enabled=args.consistent,
            solver=args.solver,
            prior=args.prior,
            prior_weight=args.prior_weight,
        )
    )


def _simulation_stream(robot, args):
    """The simulated record of the ``--simulate`` options, as a block-wise stream."""
    from ..simulation import SimulationStream
    from ..trajectories import optimize_excitation, random_trajectory

    opts = {
        k: (SIM_DEFAULTS[k] if getattr(args, k) is None else getattr(args, k)) for k in SIM_DEFAULTS
    }
    # the robot's profile (robots/NAME.toml [excitation]) sets the design, else 5 harmonics
    design = {"harmonics": 5, **(robot.profile.excitation.design_kwargs() if robot.profile else {})}
    seed = int(opts["seed"])  # --seed is parsed as an int, its default is 0
    if args.optimize:
        traj = optimize_excitation(robot, seed=seed, **design).trajectory
    else:
        traj = random_trajectory(robot, seed=seed, **design)
    opts["period"] = float(traj.period)  # [s] the excitation repeats after it
    stream = SimulationStream(
        robot,
        traj,
        duration=opts["duration"],
        rate=opts["rate"],
        noise_tau=opts["noise"],
        seed=seed,
    )
    return stream, opts


def _simulate(robot, args):
    """The simulated record of the ``--simulate`` options, whole (:class:`SimulatedData`)."""
    from ..simulation import check_simulation_memory

    stream, opts = _simulation_stream(robot, args)
    check_simulation_memory(robot, stream.n_samples)
    return stream.simulated_data(), opts


def _streams(args) -> bool:
    """Whether ``--simulate`` runs block by block: least squares, nothing needing whole arrays."""
    return (
        args.simulate
        and args.method in ("ols", "wls")
        and args.report is None
        and args.validate is None
        and args.cutoff is None
        and args.trim is None
        and args.decimate == 1
    )


def _run_stream(robot, args, outputs, timings: dict, t_start: float) -> int:
    """``--simulate`` with least squares, the record simulated and accumulated in blocks.

    Memory O(N nv) for the noise-free torques (:class:`~manip_id.simulation.SimulationStream`)
    plus one block, instead of the whole record's arrays; same samples, same split
    (:meth:`~manip_id.datasets.Dataset.split`) and same estimate as the whole-array path.
    """
    from types import SimpleNamespace

    from ..identification import RunOptions, identify_chunks

    t0 = time.perf_counter()
    stream, opts = _simulation_stream(robot, args)
    stream.tau_true  # noqa: B018 (the noise-free torques, computed once)
    timings["simulate"] = time.perf_counter() - t0
    source: dict = {"simulated": opts}
    n = stream.n_samples
    k = n
    if args.split is not None:  # as Dataset.split
        k = min(max(int(round(args.split * n)), 2), n - 2)
        source["split"] = args.split
    report_progress = _progress(n)

    def progress(done: int, total: int) -> None:  # serial: samples of k; workers: parts
        if report_progress is not None:
            report_progress(done, total if args.workers > 1 else k)

    train = stream.parts(args.workers, 0, k) if args.workers > 1 else stream.blocks(0, k)
    result = identify_chunks(
        robot,
        train,
        method=args.method,
        validation=stream.blocks(k, n) if k < n else None,
        run=RunOptions(chunk=args.chunk, workers=args.workers, progress=progress),
        **_consistent_kwargs(args),
    )
    timings.update({name: float(v) for name, v in dict(result.timings).items()})
    timings["total"] = time.perf_counter() - t_start
    valid = SimpleNamespace(n_samples=n - k) if k < n else None
    theta_true = np.asarray(stream.theta_true, dtype=float)
    report = _result_document(
        robot, result, SimpleNamespace(n_samples=k), valid, theta_true, timings, args, source, None
    )
    print(result.table())
    print(_summary(robot, report))
    if args.json:
        outputs.write_json(args.json, report)
    if args.export_urdf:
        _export(robot, result, args, outputs)
    outputs.publish()
    if args.json:
        print(f"wrote {args.json}")
    if args.export_urdf:
        print(f"wrote {args.export_urdf}")
    return 0


# ----------------------------------------------------------------------- run
def run(args: argparse.Namespace) -> int:
    if not getattr(args, "quiet", False):
        return _run(args)
    import contextlib
    import io

    _QUIET[0] = True
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            return _run(args)
    finally:
        _QUIET[0] = False


def _run(args: argparse.Namespace) -> int:
    t_start = time.perf_counter()
    _check_args(args)
    outputs = reserve_outputs(args)  # every output checked (and the report claimed) first
    if args.export_urdf:
        from ..export import sidecar_path

        outputs.file(sidecar_path(args.export_urdf), "--export-urdf sidecar")
    if _fleet.wanted(args):  # many files, one task each (Dask with --scheduler)
        return _fleet.run(args, outputs, t_start)
    if args.model != "dynamic":  # energy / momentum: whole arrays, no ddq
        return _run_acceleration_free(args, outputs, t_start)
    if not args.simulate:  # log files: read in chunks, each preprocessed alone
        return _files.run(args, outputs, t_start)
    # from here on --simulate: the log files (--data) went to _files.run above
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    validation = None
    if args.validate is not None:  # read the file first: bad data fail before the robot loads
        if len(args.validate) > 1:
            raise InputError("--simulate takes one --validate file")
        validation = load_dataset(args.validate[0], columns=_column_map(args.column))
    timings["load"] = time.perf_counter() - t0
    robot = robot_from_args(args)
    if _streams(args):  # simulated least squares: block by block, bounded memory
        return _run_stream(robot, args, outputs, timings, t_start)

    t0 = time.perf_counter()
    sim, opts = _simulate(robot, args)
    data, theta_true = sim.dataset, np.asarray(sim.theta_true, dtype=float)
    source: dict = {"simulated": opts}
    timings["simulate"] = time.perf_counter() - t0
    if validation is not None:
        check_robot(validation, robot)
        source["validate"] = str(args.validate)
    full = data
    if validation is None and args.split is not None:
        data, validation = data.split(args.split)
        source["split"] = args.split

    t0 = time.perf_counter()
    train = _prepare(data, args, "training data")
    valid = None if validation is None else _prepare(validation, args, "validation data")
    timings["preprocess"] = time.perf_counter() - t0
    settings = train.meta.get("preprocess")

    from ..identification import RunOptions, identify

    result = identify(
        robot,
        train.q,
        train.dq,
        train.ddq,
        train.tau,
        method=args.method,
        validation=None if valid is None else (valid.q, valid.dq, valid.ddq, valid.tau),
        run=RunOptions(
            chunk=args.chunk,
            workers=args.workers,
            progress=_progress(train.n_samples + (0 if valid is None else valid.n_samples)),
        ),
        **_consistent_kwargs(args),
    )
    timings.update({k: float(v) for k, v in dict(result.timings).items()})
    timings["total"] = time.perf_counter() - t_start

    report = _result_document(
        robot, result, train, valid, theta_true, timings, args, source, settings
    )
    parts = [("train", train, data.t, data.tau)]
    if valid is not None and validation is not None:  # valid is validation preprocessed
        parts.append(("validation", valid, validation.t, validation.tau))
    add_raw_reference(report, robot, result, parts, args.chunk)
    print(result.table())
    print(_summary(robot, report))
    if args.json:
        outputs.write_json(args.json, report)
    if args.report is not None:
        path = _write_report(robot, result, full, train, valid, report, args)
    if args.export_urdf:
        _export(robot, result, args, outputs)
    outputs.publish()  # all outputs appear together, once all are complete
    if args.json:
        print(f"wrote {args.json}")
    if args.export_urdf:
        print(f"wrote {args.export_urdf} and its sidecar")
    if args.report is not None:
        print(f"wrote the report to {path}/index.html")
    return 0


def _run_acceleration_free(args, outputs, t_start: float) -> int:
    """``--model energy|momentum``: one file or a simulation, whole; q, dq filtered only."""
    from ..identification import ModelOptions, RunOptions, identify

    if args.workers > 1 or _fleet.wanted(args):
        raise InputError(f"--model {args.model} runs in one process (no --workers, --scheduler)")
    if args.data is not None and len(args.data) > 1:
        raise InputError(f"--model {args.model} takes one --data file, got {len(args.data)}")
    if args.validate is not None and len(args.validate) > 1:
        raise InputError(f"--model {args.model} takes one --validate file")
    if args.window_length is not None and not (
        math.isfinite(args.window_length) and args.window_length > 0
    ):
        raise InputError(f"--window-length must be a positive time [s], got {args.window_length}")
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    columns = _column_map(args.column)
    data = None if args.simulate else load_dataset(args.data[0], columns=columns)
    validation = None if args.validate is None else load_dataset(args.validate[0], columns=columns)
    timings["load"] = time.perf_counter() - t0
    robot = robot_from_args(args)
    theta_true = None
    if data is None:  # --simulate
        sim, opts = _simulate(robot, args)
        data, theta_true = sim.dataset, np.asarray(sim.theta_true, dtype=float)
        source: dict = {"simulated": opts}
    else:
        check_robot(data, robot)
        source = {"data": str(args.data[0])}
    if validation is not None:
        check_robot(validation, robot)
        source["validate"] = str(args.validate[0])
    full = data
    if validation is None and args.split is not None:
        data, validation = data.split(args.split)
        source["split"] = args.split
    t0 = time.perf_counter()
    if args.simulate and args.cutoff is None and args.decimate == 1 and args.trim is None:
        train = data  # uniform and noise on tau only: nothing to filter
    else:  # resampled, q and dq filtered; tau left raw (the models integrate it)
        cutoff = DEFAULT_CUTOFF if args.cutoff is None else args.cutoff
        try:
            train = preprocess(
                data,
                cutoff=cutoff,
                order=args.order,
                decimate=args.decimate,
                trim=args.trim,
                filter_torque=False,
            )
        except InputError as exc:
            raise InputError(f"training data: {exc}") from exc
    valid = None if validation is None else _prepare(validation, args, "validation data")
    timings["preprocess"] = time.perf_counter() - t0
    steps = np.diff(train.t)
    dt = float(np.mean(steps))
    if np.ptp(steps) > 1e-6 * dt:
        raise InputError(
            f"--model {args.model} needs uniform samples; steps range over "
            f"[{steps.min():g}, {steps.max():g}] s (give --cutoff to resample)"
        )
    result = identify(
        robot,
        train.q,
        train.dq,
        None,
        train.tau,
        method=args.method,
        validation=None if valid is None else (valid.q, valid.dq, valid.ddq, valid.tau),
        run=RunOptions(chunk=args.chunk),
        model=ModelOptions(args.model, window_length=args.window_length, dt=dt),
        **_consistent_kwargs(args),
    )
    timings.update({k: float(v) for k, v in dict(result.timings).items()})
    timings["total"] = time.perf_counter() - t_start
    settings = train.meta.get("preprocess")
    report = _result_document(
        robot, result, train, valid, theta_true, timings, args, source, settings
    )
    report["model"] = args.model
    window = result.context.get("window") or {}
    report["window_length"] = window.get("length", args.window_length)  # the one used [s]
    if window:
        report["window"] = window
    report["outputs"] = list(result.output_names)
    print(result.table())
    rel = report["relative_error"]
    if rel["per_joint_validation"] is None:  # the model's own outputs, not the joints
        shown = {**report, "joints": report["outputs"]}
    else:
        shown = report
    print(_summary(robot, shown).replace("relative torque error: train", "relative error: train"))
    if window:
        how = "chosen from the data: " + window["rule"] if window["chosen"] else "given"
        print(f"window: {window['length']:.4g} s ({window['samples']} sampling intervals; {how})")
    if args.json:
        outputs.write_json(args.json, report)
    if args.report is not None:
        path = _write_report(robot, result, full, train, valid, report, args)
    if args.export_urdf:
        _export(robot, result, args, outputs)
    outputs.publish()
    if args.json:
        print(f"wrote {args.json}")
    if args.export_urdf:
        print(f"wrote {args.export_urdf} and its sidecar")
    if args.report is not None:
        print(f"wrote the report to {path}/index.html")
    return 0


def _pct(x) -> str:
    return "n/a" if x is None else f"{100 * float(x):.3g} %"


def report_summary(report: dict, source: str) -> dict:
    """The report's summary rows: errors in percent as the CLI prints them, the nominal
    model beside the identified one, and the preprocessing stated."""
    rel = report["relative_error"]
    pre = report.get("preprocess") or {}
    summary = {
        "robot": report["robot"],
        "method": report["method"]
        + ("" if report.get("model", "dynamic") == "dynamic" else f" ({report['model']} model)"),
        "source": source,
        "training samples": report["n_samples"],
        "validation samples": report.get("n_validation_samples"),
        "base parameters": f"{report['n_base']} of {report['n_parameters']}",
        "condition number": report["condition_number"],
        "relative torque error, train": f"{_pct(rel['train'])} (nominal URDF model "
        f"{_pct(rel.get('nominal_train'))})",
        "relative torque error, validation": f"{_pct(rel['validation'])} (nominal URDF model "
        f"{_pct(rel.get('nominal_validation'))})",
        "reference torques": report.get("reference_torques", "raw"),
    }
    if pre:
        rate = pre.get("rate")
        summary["preprocessing"] = (
            f"low-pass {pre['cutoff']:g} Hz (Butterworth order {pre['order']}, zero-phase) on "
            f"q, dq{', tau' if pre.get('filter_torque') else ''}; ddq by central differences; "
            f"{pre.get('trim', 0)} samples trimmed at each end of each part (filter edges)"
            + ("" if pre.get("decimate", 1) == 1 else f"; every {pre['decimate']}th sample")
            + (f"; resampled at {rate:g} Hz" if pre.get("resampled") and rate else "")
        )
    else:
        summary["preprocessing"] = "none (the data's own accelerations, unfiltered)"
    src = report.get("source") or {}
    if src.get("split") is not None:
        summary["validation"] = f"the last {100 * (1 - src['split']):.0f} % of the record"
    windows = [f.get("window") for f in report.get("files", []) if f.get("window")]
    if windows:
        summary["windows"] = ", ".join(windows)
    band = report.get("velocity_deadband")
    if band:
        summary["velocity deadband"] = f"{band['eps']:g} rad/s; rows left out: " + ", ".join(
            f"{j} {n}" for j, n in band["excluded_rows"].items()
        )
    if "parameter_error" in report:
        summary["base parameter error vs truth"] = _pct(report["parameter_error"])
    n_bad = sum(bool(p["flags"]) for p in report["base_parameters"])
    summary["flagged parameters"] = f"{n_bad} of {report['n_base']}"
    return summary


def report_parameter_rows(report: dict) -> list[dict]:
    """The parameter table, trustworthy rows first (no flag, smallest std), flagged rows
    after (non-physical ones last) and highlighted."""
    truth = report.get("true_base_parameters")
    rows = []
    for i, p in enumerate(report["base_parameters"]):
        flags = list(p["flags"])
        sp = p["std_percent"]
        rank = (2 if "non-physical" in flags else 1 if flags else 0, np.inf if sp is None else sp)
        rows.append(
            (
                rank,
                {
                    "name": p["name"],
                    "unit": p["unit"],
                    "identified": p["value"],
                    "nominal": p["nominal"],
                    **({"true": truth[i]} if truth is not None else {}),
                    "std": p["std"],
                    "std [%]": sp,
                    "flags": ", ".join(flags) or "ok",
                    "expression": p["expression"],
                    "_class": "bad" if "non-physical" in flags else "warn" if flags else "",
                },
            )
        )
    return [row for _, row in sorted(rows, key=lambda x: x[0])]


def report_quality_rows(report: dict) -> list[dict]:
    """The data-quality section: one row per file (training and validation)."""
    rows = []
    for kind, key in (("training", "data_quality"), ("validation", "validation_data_quality")):
        for q in report.get(key) or []:
            row: dict[str, str | int | float | None] = {"part": kind}
            for k, v in q.items():
                if isinstance(v, str | int | float | bool) or v is None:
                    row[k] = v
                elif isinstance(v, list) and all(isinstance(x, str) for x in v):
                    row[k] = "; ".join(v) or "none"
            rows.append(row)
    return rows


def _history_figure(robot, result, train, report):
    """parameter_history.png of an online method, or None without a record."""
    from ..viz import figures

    h = result.history
    if h is None or len(h.t) < 2:
        return None
    samples = np.minimum(np.arange(len(h.t)) * max(result.n_samples // 1000, 1), len(train.t) - 1)
    t = train.t[samples]
    truth = report.get("true_base_parameters")  # a simulation's
    if truth is not None:
        ref, label = np.asarray(truth, dtype=float), "truth"
    else:
        ref, label = np.asarray(result.estimate, dtype=float), "final estimate"
    rms = float(np.sqrt(np.mean(np.asarray(train.tau) ** 2)) * np.sqrt(robot.nv))
    return lambda path: figures.online_history(
        path,
        t,
        h.theta,
        names=result.names,
        reference=ref,
        reference_label=label,
        prediction_error=h.error,
        torque_rms=rms,
        title=f"{report['method']} on {robot.name}: convergence of the base parameters",
    )


def build_scene(robot, result, full, title: str, notes: list, assets: str = "inline"):
    """The report's scene, or None (with a note) when it cannot be drawn: never fatal."""
    from ..errors import InfeasibleTrajectoryError
    from ..viz.meshcat_scene import RobotScene, link_identifiability

    try:
        scene = RobotScene(robot, title=title)
        scene.assets = assets
        if full is not None:
            try:
                scene.animate(full.t, full.q)
            except InfeasibleTrajectoryError as exc:
                notes.append(f"scene not animated: {exc}")
        scene.add_inertia(robot.nominal_parameters, label="nominal")
        if result.standard is not None and result.standard.solver:  # --consistent
            # the estimate the user asked for: shown at first (the nominal set may be hidden)
            scene.add_inertia(result.standard.values, label="identified (consistent)", visible=True)
        ind = result.base.independent
        flags = np.zeros(robot.n_parameters, dtype=bool)
        flags[ind] = True
        rel = np.full(robot.n_parameters, np.inf)
        est = np.asarray(result.estimate, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            rel[ind] = np.asarray(result.std, dtype=float) / np.abs(est)
        scene.color_by_identifiability(
            link_identifiability(robot, identifiable=flags, relative_std=rel, threshold=0.1)
        )
    except Exception as exc:  # a picture never fails the finished identification
        notes.append(f"3-D scene not drawn: {type(exc).__name__}: {exc}")
        return None
    notes += list(scene.notes)
    return scene


def _write_report(robot, result, full, train, valid, report: dict, args):
    """The report folder of an identification (see :func:`manip_id.viz.report.write_report`)."""
    from dataclasses import replace

    from ..viz import figures
    from ..viz.report import write_report

    source = "simulated" if args.simulate else ", ".join(map(str, args.data))
    run_name = f"{robot.name}, {report['method']}, {source}, {train.n_samples} training samples"
    nominal = replace(result, estimate=result.nominal)
    pred = result.predict(robot, train.q, train.dq, train.ddq, chunk=args.chunk)
    npred = nominal.predict(robot, train.q, train.dq, train.ddq, chunk=args.chunk)
    t, tau, val_start = train.t, train.tau, None
    res_kw: dict = {}
    if valid is not None:
        vpred = result.predict(robot, valid.q, valid.dq, valid.ddq, chunk=args.chunk)
        vnom = nominal.predict(robot, valid.q, valid.dq, valid.ddq, chunk=args.chunk)
        tv = valid.t
        if tv[0] <= t[-1]:  # separate validation files: drawn after the training record
            step = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
            tv = tv - tv[0] + t[-1] + step
        val_start = float(tv[0])
        t = np.concatenate([t, tv])
        tau = np.vstack([tau, valid.tau])
        pred, npred = np.vstack([pred, vpred]), np.vstack([npred, vnom])
        res_kw = dict(t_validation=valid.t, residual_validation=valid.tau - vpred)
    joints = list(robot.dof_names)
    rel = report["relative_error"]
    use_val = rel.get("per_joint_validation") is not None
    e_id = rel["per_joint_validation"] if use_val else rel["train_per_joint"]
    e_nom = rel.get("nominal_per_joint_validation" if use_val else "nominal_train_per_joint")
    errors = list(zip(e_id, e_nom or [None] * len(joints), strict=True))
    units = ["N" if robot.is_prismatic(j) else "N m" for j in range(robot.nv)]
    part = "validation" if use_val else "train"
    pre = report.get("preprocess") or {}
    reference = f"filtered at {pre['cutoff']:g} Hz" if pre.get("filter_torque") else "raw"
    ra = result.rank_analysis
    figs = {
        "torque_fit": lambda path: figures.torque_comparison(
            path,
            t,
            tau,
            pred,
            npred,
            validation_start=val_start,
            joint_names=joints,
            units=units,
            errors=errors,
            reference=reference,
            title=f"measured, identified and nominal torques ({part} errors in the titles): "
            f"{run_name}",
        ),
        "residuals": lambda path: figures.residuals(
            path,
            train.t,
            train.tau - result.predict(robot, train.q, train.dq, train.ddq, chunk=args.chunk),
            joint_names=joints,
            units=units,
            title=f"residuals tau - Y_b theta_b: {run_name}",
            **res_kw,
        ),
        "singular_values": lambda path: figures.singular_values(
            path,
            ra.singular_values_scaled,
            tolerance=ra.tolerance,
            rank=ra.rank,
            title=f"singular values of the data's base regressor: {robot.name}, "
            f"{ra.n_rows} rows, rank {ra.rank} of {ra.n_parameters}",
        ),
    }
    history = _history_figure(robot, result, train, report)
    if history is not None:
        figs["parameter_history"] = history
    if args.simulate:
        figs["trajectory"] = lambda path: figures.trajectory_limits(
            path,
            full.t,
            full.q,
            lower=robot.lower,
            upper=robot.upper,
            joint_names=joints,
            title=f"simulated excitation of {robot.name} against its position limits",
        )
    notes = list(report["warnings"])
    scene = build_scene(
        robot,
        result,
        full,
        f"manip-id identify: {run_name}",
        notes,
        getattr(args, "scene_assets", "inline"),
    )
    quality = report_quality_rows(report)
    return write_report(
        args.report_claim,
        title=f"manip-id identify: {run_name}",
        summary=report_summary(report, source),
        parameter_table=report_parameter_rows(report),
        figures=figs,
        scene=scene,
        json_result=report,
        notes=notes,
        force=args.force,
        tables={"Data quality": quality} if quality else None,
    )


def _result_document(
    robot, result, train, valid, theta_true, timings, args, source, settings
) -> dict:
    """The run's JSON: the result's one schema (:meth:`IdentificationResult.to_dict`,
    :mod:`manip_id.results`) with what only the command knows (source, preprocessing,
    the reference torques, validation samples, the truth of a simulation)."""
    from dataclasses import replace

    ctx: dict = {
        "n_validation_samples": 0 if valid is None else int(valid.n_samples),
        "joint_terms": list(robot.terms.enabled),
        "source": source,
        "preprocess": None
        if settings is None
        else {k: getattr(settings, k) for k in settings.__dataclass_fields__},
        "reference_torques": _reference_torques(settings),
    }
    warnings_ = []
    if settings is not None and settings.filter_torque:
        warnings_.append(
            f"the reference torques were low-pass filtered at {settings.cutoff:g} Hz "
            f"(zero-phase Butterworth, order {settings.order}): the errors and figures "
            "compare the models with the filtered torques, not the raw ones"
        )
    sim = source.get("simulated") if isinstance(source, dict) else None
    if sim and source.get("split") is not None and sim.get("period"):
        trained = float(source["split"]) * float(sim["duration"])  # [s]
        if trained >= float(sim["period"]):
            warnings_.append(
                f"the validation data repeat the training motion: the excitation is periodic "
                f"({sim['period']:g} s) and --split {source['split']:g} trains on "
                f"{trained:g} s, more than one period; the validation error then measures "
                "noise, not prediction on new motion (use --validate with another trajectory)"
            )
    ctx["warnings"] = warnings_
    if theta_true is not None:
        estimate = np.asarray(result.estimate, dtype=float)
        std = np.asarray(result.std, dtype=float)
        beta_true = np.asarray(result.base.to_base(theta_true), dtype=float)
        err = estimate - beta_true
        ctx["parameter_error"] = _finite(np.linalg.norm(err) / np.linalg.norm(beta_true))
        ctx["parameter_error_in_std"] = _finite(
            np.max(np.abs(err) / np.where(std > 0, std, np.inf))
        )
        ctx["true_base_parameters"] = beta_true.tolist()
    result = replace(
        result,
        method=args.method,
        timings={k: float(v) for k, v in timings.items()},
        context={**result.context, **ctx},
    )
    return result.to_dict(
        poorly_identified=getattr(args, "poorly_identified", None),
        condition_limit=getattr(args, "condition_limit", None),
    )


def add_raw_reference(report: dict, robot, result, parts, chunk: int) -> None:
    """When the reference torques were filtered, the errors against the raw ones too.

    parts: ``(name, processed, t_raw, tau_raw)`` with name "train" or "validation",
    ``processed`` holding t, q, dq, ddq, tau (the filtered samples) and the raw torques
    of the same record [N m] (scaled as the processed ones) at times ``t_raw`` [s]; the raw
    torques are interpolated linearly at the processed times (the processed samples
    are the raw ones, trimmed, or resampled on a uniform grid).
    Adds ``relative_error_raw`` {train, validation, nominal_train, nominal_validation}
    and states both references in ``reference_torques``.
    """
    from dataclasses import replace

    pre = report.get("preprocess") or {}
    if not pre.get("filter_torque"):
        return
    nominal = replace(result, estimate=result.nominal)
    out: dict = {}
    for name, proc, t_raw, tau_raw in parts:
        t_raw = np.asarray(t_raw, dtype=float)
        if proc is None or proc.t[0] < t_raw[0] - 1e-9 or proc.t[-1] > t_raw[-1] + 1e-9:
            return  # the processed times are not on the raw record's clock: not comparable
        raw = np.column_stack(
            [np.interp(proc.t, t_raw, np.asarray(tau_raw)[:, j]) for j in range(robot.nv)]
        )
        for key, model in (("", result), ("nominal_", nominal)):
            pred = model.predict(robot, proc.q, proc.dq, proc.ddq, chunk=chunk)
            out[f"{key}{name}"] = _finite(np.linalg.norm(raw - pred) / np.linalg.norm(raw))
    if not out:
        return
    report["relative_error_raw"] = out
    pct = {k: "n/a" if v is None else f"{100 * v:.3g} %" for k, v in out.items()}
    report["reference_torques"] += (
        f"; against the raw torques at the same samples: identified model train "
        f"{pct.get('train', 'n/a')}"
        + (f", validation {pct['validation']}" if "validation" in pct else "")
        + f" (nominal model train {pct.get('nominal_train', 'n/a')}"
        + (f", validation {pct['nominal_validation']}" if "nominal_validation" in pct else "")
        + ")"
    )


def _reference_torques(settings) -> str:
    """Which torques the errors are measured against, in words."""
    if settings is None or not settings.filter_torque:
        return "raw (as measured, not filtered)"
    return f"filtered at {settings.cutoff:g} Hz (zero-phase Butterworth, order {settings.order})"


def _summary(robot, report: dict) -> str:
    rel = report["relative_error"]

    def pct(x):
        return "n/a" if x is None else f"{100 * x:.3f} %"

    lines = [
        f"robot {report['robot']}: {report['n_base']} base parameters of {report['n_parameters']}, "
        f"{report['n_samples']} training samples, method {report['method']}",
        f"condition number {report['condition_number']:.6g}"
        if report["condition_number"]
        else "condition number n/a",
        f"relative torque error: train {pct(rel['train'])}, validation {pct(rel['validation'])}",
        f"nominal model (URDF): train {pct(rel.get('nominal_train'))}, validation "
        f"{pct(rel.get('nominal_validation'))}",
    ]
    if report.get("reference_torques"):
        lines.append(f"reference torques: {report['reference_torques']}")
    per_joint = rel["per_joint_validation"] or rel["train_per_joint"]
    label = "validation" if rel["per_joint_validation"] else "train"
    lines.append(
        f"per joint ({label}): "
        + ", ".join(f"{j} {pct(e)}" for j, e in zip(report["joints"], per_joint, strict=True))
    )
    if "parameter_error" in report:
        lines.append(
            f"base parameter error vs truth: {pct(report['parameter_error'])} "
            f"(max {report['parameter_error_in_std']:.2f} std)"
        )
    return "\n".join(lines)
