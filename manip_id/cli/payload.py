"""``manip-id payload``: the inertial parameters of a payload from unloaded and loaded runs.

Pipeline: scan every ``--unloaded`` and ``--loaded`` file first with the real-log
readers (:func:`manip_id.pipeline.scan_file`: its window, ``FILE@START:STOP`` or
``--window``, ``--torque-scale``, checks and the data-quality summary, printed), then
stream each file's rows (:func:`manip_id.pipeline.iter_processed`: preprocessed on its
own in overlapping blocks when it has no accelerations) into
:func:`manip_id.payload.identify_payload`, memory bounded whatever the files' length:
the robot's base
parameters and the payload's parameters in one least squares, or, with
``--known-base RESULT.json`` (the JSON of ``manip-id identify``), the payload alone.
Prints the payload (mass, centre of mass and inertia about it, in FRAME, with
standard deviations, and what the torques cannot show) and writes JSON with ``--json``.

The helpers here (reading the runs, the shared options) serve ``manip-id drive-gains`` too.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

from ..errors import DataError, InputError
from ._common import add_execution_arguments, add_robot_arguments, robot_from_args, write_json


# ------------------------------------------------------------------ options
def add_run_arguments(p: argparse.ArgumentParser, *, unloaded_required: bool) -> None:
    """``--unloaded``, ``--loaded``, ``--frame`` and the data options shared with drive-gains."""
    p.add_argument(
        "--unloaded",
        nargs="+",
        action="extend",
        default=[],
        metavar="FILE",
        required=unloaded_required,
        help="runs without the payload (.npz, .csv, ROS 2 bag, Panda log folder); "
        "FILE@START:STOP or FILE@#A:#B selects a window; repeatable",
    )
    p.add_argument(
        "--loaded",
        nargs="+",
        action="extend",
        default=[],
        metavar="FILE",
        required=True,
        help="runs with the payload mounted (same forms); repeatable",
    )
    p.add_argument(
        "--frame",
        required=True,
        help="the frame or link the payload is fixed to (e.g. tool0)",
    )
    p.add_argument(
        "--window",
        metavar="START:STOP",
        default=None,
        help="window of every file without its own: seconds of the file's time, or #A:#B rows",
    )
    p.add_argument(
        "--column",
        action="append",
        default=[],
        metavar="FIELD=COLUMNS",
        help="CSV column map (see manip-id identify --help); repeatable",
    )
    p.add_argument("--topic", default=None, help="ROS 2 bag topic of sensor_msgs/JointState")
    p.add_argument(
        "--drop-bad-rows",
        action="store_true",
        help="drop (and count) rows holding NaN/Inf instead of refusing the file",
    )
    p.add_argument(
        "--velocity-deadband",
        type=float,
        default=None,
        metavar="EPS",
        help="leave out the rows of joint j where |dq_j| < EPS [rad/s] (standstill)",
    )
    sig = p.add_argument_group("signal processing (data without ddq, or with --cutoff)")
    sig.add_argument("--cutoff", type=float, default=None, help="low-pass cut-off [Hz] [default 3]")
    sig.add_argument("--order", type=int, default=4, help="Butterworth order [default 4]")
    sig.add_argument(
        "--trim",
        type=float,
        default=None,
        help="seconds dropped at each end of each file [default: the filter's edge transient]",
    )
    sig.add_argument("--decimate", type=int, default=1, help="keep every D-th sample [default 1]")
    add_execution_arguments(p, workers=False)
    p.add_argument("--json", metavar="OUT", help="write the result as JSON to OUT")
    from .audit import add_stream_arguments

    add_stream_arguments(p)


def register(sub) -> None:
    p = sub.add_parser(
        "payload",
        help="identify a payload's mass, centre of mass and inertia",
        description="Identify the inertial parameters of a payload rigidly attached to FRAME "
        "from runs without it (--unloaded, or --known-base) and with it (--loaded): mass [kg], "
        "centre of mass [m, in FRAME], inertia about the centre of mass [kg m^2, FRAME axes], "
        "with standard deviations and the components the torques cannot show.",
    )
    add_robot_arguments(p)
    add_run_arguments(p, unloaded_required=False)
    p.add_argument(
        "--known-base",
        metavar="RESULT.json",
        default=None,
        help="base parameters of an earlier 'manip-id identify --json' instead of --unloaded",
    )
    p.add_argument(
        "--consistent",
        action="store_true",
        help="keep the payload physically consistent (pseudo-inertia positive definite)",
    )
    p.add_argument(
        "--method",
        choices=("wls", "ols"),
        default="wls",
        help="wls: each joint weighted by its residual variance (default); ols: unweighted",
    )
    p.add_argument(
        "--torque-scale",
        default=None,
        metavar="G[,G...]",
        help="multiply the torque columns of every file (one value, or one per joint)",
    )
    p.add_argument(
        "--export-urdf",
        metavar="OUT.urdf",
        default=None,
        help="write the robot's URDF with the payload as a fixed link at FRAME (needs "
        "--consistent); sidecar OUT.identified.json",
    )
    p.add_argument("--force", action="store_true", help="replace an existing --export-urdf file")
    from ._fleet import add_scheduler_argument

    add_scheduler_argument(
        p,
        "each file is one task (read, preprocessed and accumulated on a worker), the sums "
        "are added on the cluster and the payload is solved here",
    )
    p.set_defaults(func=run)


# ------------------------------------------------------------------ reading
def parse_floats(text: str | None, what: str, n: int | None = None) -> list[float] | None:
    """``"1,2,3"`` -> [1.0, 2.0, 3.0]; ``n`` values when given; None passes through."""
    if text is None:
        return None
    try:
        values = [float(v) for v in str(text).split(",") if v.strip()]
    except ValueError as exc:
        raise InputError(f"{what} takes comma-separated numbers, got {text!r}") from exc
    if n is not None and len(values) != n:
        raise InputError(f"{what} takes {n} comma-separated numbers, got {len(values)}: {text!r}")
    if not values or not all(math.isfinite(v) for v in values):
        raise InputError(f"{what} takes finite numbers, got {text!r}")
    return values


def check_run_args(args) -> None:
    """Option checks that need no data."""
    if args.cutoff is not None and not (math.isfinite(args.cutoff) and args.cutoff > 0):
        raise InputError(f"--cutoff must be a positive frequency [Hz], got {args.cutoff}")
    if args.trim is not None and not (math.isfinite(args.trim) and args.trim >= 0):
        raise InputError(f"--trim must be >= 0 seconds, got {args.trim}")
    if args.decimate < 1:
        raise InputError(f"--decimate must be >= 1, got {args.decimate}")
    if args.order < 1:
        raise InputError(f"--order must be >= 1, got {args.order}")
    if args.chunk < 1:
        raise InputError(f"--chunk must be >= 1, got {args.chunk}")
    d = args.velocity_deadband
    if d is not None and not (math.isfinite(d) and d >= 0):
        raise InputError(f"--velocity-deadband must be >= 0 [rad/s], got {d}")


def _column_map(specs: list[str]):
    from .identify import _column_map as column_map

    return column_map(specs)


def _spec(text: str, args, colmap=None):
    """A file spec (path and window) of the real-log readers."""
    from ..datasets import parse_file_spec
    from .audit import spec_options

    return parse_file_spec(
        text, window=args.window, columns=colmap, topic=args.topic, **spec_options(args)
    )


def _options(args, scale=None):
    from ..identification import PreprocessOptions

    eps = args.velocity_deadband
    return PreprocessOptions(
        cutoff=args.cutoff,
        order=args.order,
        trim=args.trim,
        decimate=args.decimate,
        torque_scale=None if scale is None else tuple(scale),
        velocity_deadband=eps if eps else None,
        drop_bad_rows=args.drop_bad_rows,
    )


class StreamedRun:
    """One file read by the real-log pipeline: scanned once (quality summary, checks),
    then its preprocessed rows streamed block by block as ``(q, dq, ddq, tau)``.

    ``scan=False``: the file is scanned when the blocks are first asked for, where the
    run is accumulated (a Dask worker with ``--scheduler``: give a light robot,
    :func:`manip_id.fleet.portable_robot`, so the run pickles small); its quality and
    preprocessing come back through :meth:`summary`.
    """

    def __init__(self, robot, spec, options, scan: bool = True):
        from ..identification import scan_file

        self.robot, self.spec, self.options = robot, spec, options
        # bad files fail here, named
        self.scan = scan_file(robot, spec, options) if scan else None
        self.settings: Any = None  # PreprocessSettings once streamed (None: ddq as is)

    @property
    def label(self) -> str:
        """The file spec as written: ``path[@window]``."""
        return self.spec.label

    def summary(self) -> dict:
        """The file, its data quality and the preprocessing applied (after the blocks)."""
        return {
            "file": self.spec.label,
            "quality": None if self.scan is None else self.scan.quality,
            "settings": self.settings,
        }

    def __call__(self):
        from ..identification import iter_processed, scan_file

        nq, nv = self.robot.nq, self.robot.nv
        if self.scan is None:
            self.scan = scan_file(self.robot, self.spec, self.options)
        try:
            self.settings, rows = iter_processed(self.robot, self.spec, self.options, self.scan)
            for r in rows:
                yield (
                    r[:, 1 : 1 + nq],
                    r[:, 1 + nq : 1 + nq + nv],
                    r[:, 1 + nq + 2 * nv : 1 + nq + 3 * nv],
                    r[:, 1 + nq + nv : 1 + nq + 2 * nv],
                )
        finally:
            self.scan.discard()


def read_runs(args, robot, scale=None, scan: bool = True) -> tuple[list, list, dict]:
    """The unloaded and loaded runs as streamed runs, and a description of their sources.

    Every file is scanned first (checks and the data-quality summary, printed), so that a
    bad file fails, named, before the long work; ``scan=False`` (``--scheduler``): the
    files are scanned by the tasks that accumulate them (quality: :func:`run_quality`).
    """
    colmap = _column_map(args.column)
    specs_u = [_spec(t, args, colmap) for t in args.unloaded]
    specs_l = [_spec(t, args, colmap) for t in args.loaded]
    for sl in specs_l:
        for su in specs_u:
            same_path = Path(sl.path).resolve() == Path(su.path).resolve()
            if same_path and sl.window == su.window:
                raise DataError(
                    f"{sl.label} is given as both an unloaded and a loaded run: the loaded runs "
                    "must be recorded with the payload mounted"
                )
    options = _options(args, scale)
    audit = None
    if not scan and getattr(args, "trim_standstill", False):
        raise InputError("--trim-standstill needs the pre-fit audit, which --scheduler skips")
    if scan:  # the pre-fit audit, printed and saved as "audit" (not where tasks read the files)
        from .audit import before_fit

        audited, audit = before_fit(
            robot, specs_u + specs_l, options, args, currents=args.command == "drive-gains"
        )
        specs_u, specs_l = audited[: len(specs_u)], audited[len(specs_u) :]
    runs: dict[str, list] = {"unloaded": [], "loaded": []}
    quality: dict[str, list] = {"unloaded": [], "loaded": []}
    for what, specs in (("unloaded", specs_u), ("loaded", specs_l)):
        for spec in specs:
            run = StreamedRun(robot, spec, options, scan=scan)
            if run.scan is not None:
                print(f"{what} " + run.scan.quality.text())
                quality[what].append(run.scan.quality.to_dict())
            runs[what].append(run)
    source = {
        "unloaded": [s.label for s in specs_u],
        "loaded": [s.label for s in specs_l],
        "data_quality": quality,
        "options": options.to_dict(),
        "audit": None if audit is None else audit.to_dict(),
    }
    return runs["unloaded"], runs["loaded"], source


def reserve_json(args, inputs: list[str]):
    """Check the --json output before the work (the command's OutputSet when there is one)."""
    if not args.json:
        return None
    outputs = getattr(args, "outputs", None)
    if outputs is not None:
        outputs.add_inputs(inputs)
        outputs.file(args.json, "--json")
    else:
        for i in inputs:
            if Path(i).exists() and Path(i).resolve() == Path(args.json).resolve():
                raise InputError(f"--json {args.json} is one of the inputs")
    return args.json


def publish_json(args, doc: dict) -> None:
    """Write the --json output (through the OutputSet when there is one)."""
    if not args.json:
        return
    outputs = getattr(args, "outputs", None)
    if outputs is not None:
        outputs.write_json(args.json, doc)
        outputs.publish()
    else:
        write_json(args.json, doc)
    print(f"wrote {args.json}")


def input_paths(args) -> list[str]:
    """The input files (paths without their windows), for the output checks."""
    out = []
    for t in [*args.unloaded, *args.loaded, getattr(args, "known_base", None)]:
        if t is None:
            continue
        p = Path(t)
        if not p.exists() and "@" in t:
            p = Path(t.rpartition("@")[0])
        out.append(str(p))
    return out


def run_quality(result) -> tuple[dict, list]:
    """From the runs' summaries a result brings back (files scanned on the workers): the
    data quality per kind of run (printed) and the preprocessing per run."""
    quality: dict[str, list] = {"unloaded": [], "loaded": []}
    settings = []
    for what in ("unloaded", "loaded"):
        for info in result.runs.get(what, []):
            q, s = info["quality"], info["settings"]
            print(f"{what} " + q.text())
            quality[what].append(q.to_dict())
            settings.append(
                {
                    "file": info["file"],
                    "preprocess": None
                    if s is None
                    else {k: getattr(s, k) for k in s.__dataclass_fields__},
                }
            )
    return quality, settings


def preprocess_settings(runs: list) -> list:
    """Per run, the preprocessing applied (None: the file's own ddq used as is)."""
    out = []
    for run in runs:
        s = run.settings
        out.append(
            {
                "file": run.spec.label,
                "preprocess": None
                if s is None
                else {k: getattr(s, k) for k in s.__dataclass_fields__},
            }
        )
    return out


# ---------------------------------------------------------------------- run
def run(args: argparse.Namespace) -> int:
    t_start = time.perf_counter()
    check_run_args(args)
    if args.known_base is not None and args.unloaded:
        raise InputError("give --unloaded runs or --known-base RESULT.json, not both")
    if args.known_base is None and not args.unloaded:
        raise InputError("give the --unloaded runs (or --known-base RESULT.json)")
    from ._fleet import check_scheduler

    check_scheduler(args)
    reserve_json(args, input_paths(args))
    _reserve_export(args, input_paths(args))
    from ..payload import identify_payload, load_known_base

    known = load_known_base(args.known_base) if args.known_base is not None else None
    robot = robot_from_args(args)
    scale = None
    if args.torque_scale is not None:
        scale = parse_floats(args.torque_scale, "--torque-scale")
    distributed = args.scheduler is not None
    if distributed:  # the tasks read the files: send them a light robot
        from ..execution import portable_robot

        unloaded, loaded, source = read_runs(args, portable_robot(robot), scale, scan=False)
    else:
        unloaded, loaded, source = read_runs(args, robot, scale)
    if args.known_base is not None:
        source["known_base"] = str(args.known_base)
    source["scheduler"] = args.scheduler or "this process"
    result = identify_payload(
        robot,
        unloaded,
        loaded,
        args.frame,
        known_base=known,
        method=args.method,
        consistent=args.consistent,
        velocity_deadband=args.velocity_deadband,
        chunk=args.chunk,
        scheduler=args.scheduler,
    )
    doc = result.to_dict()
    doc["audit"] = source.pop("audit")
    quality = source.pop("data_quality")
    settings = None
    if distributed:
        quality, settings = run_quality(result)
    doc["data_quality"] = quality
    doc["source"] = source
    doc["torque_scale"] = scale
    doc["preprocess"] = settings if distributed else preprocess_settings(unloaded + loaded)
    doc["timings"]["command_total"] = round(time.perf_counter() - t_start, 6)
    print(result.table())
    _stage_export(args, robot, result)
    if args.json or not args.export_urdf:
        publish_json(args, doc)
    else:
        args.outputs.publish()
    if args.export_urdf:
        print(f"wrote {args.export_urdf} and its sidecar")
    return 0


def _reserve_export(args, inputs: list[str]) -> None:
    """Check --export-urdf before the work: --consistent given, the file new unless --force."""
    if not args.export_urdf:
        return
    if not args.consistent:
        raise InputError("--export-urdf needs a physically consistent payload: add --consistent")
    from .._io import OutputSet
    from ..export import check_output, sidecar_path

    check_output(args.export_urdf, force=args.force)
    if getattr(args, "outputs", None) is None:
        args.outputs = OutputSet()
    args.outputs.add_inputs(inputs)
    args.outputs.file(args.export_urdf, "--export-urdf")
    args.outputs.file(sidecar_path(args.export_urdf), "--export-urdf sidecar")


def _stage_export(args, robot, result) -> None:
    """Write the payload link into the robot's URDF (published with the other outputs)."""
    if not args.export_urdf:
        return
    from ..export import payload_urdf_texts, sidecar_path
    from ..export.sidecar import identification_provenance

    p = result.payload
    prov = identification_provenance("manip-id payload", vars(args))
    prov["uncertainty"] = p.to_dict()
    texts = payload_urdf_texts(
        robot, args.frame, p.mass, p.com, p.inertia, args.export_urdf, provenance=prov
    )
    args.outputs.write_text(args.export_urdf, texts.urdf)
    args.outputs.write_json(sidecar_path(args.export_urdf), texts.sidecar)
