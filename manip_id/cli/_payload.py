"""``manip-id payload`` once it runs, and the real-log runs that payload and drive-gains
share: files scanned, streamed block by block, the result printed and saved (the
options are declared in :mod:`.payload`).
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

from .._io import OutputSet
from ..datasets import RowCache, parse_file_spec
from ..errors import DataError, InputError
from ..execution import portable_robot
from ..export import PayloadLink, check_output, payload_urdf_texts, sidecar_path
from ..export.sidecar import identification_provenance
from ..identification import PreprocessOptions, iter_processed, scan_file
from ..payload import identify_payload, load_known_base, load_torque_scale
from ..viz.payload_report import write_payload_report
from ._common import (
    check_preprocess_args,
    column_map,
    parse_floats,
    quiet_stdout,
    spec_options,
    write_json,
)
from ._runtime import before_fit, check_frame, check_scheduler, print_warnings, robot_from_args


# ------------------------------------------------------------------ reading
def check_run_args(args) -> None:
    """Option checks that need no data."""
    check_preprocess_args(args)
    if args.order < 1:
        raise InputError(f"--order must be >= 1, got {args.order}")
    d = args.velocity_deadband
    if d is not None and not (math.isfinite(d) and d >= 0):
        raise InputError(f"--velocity-deadband must be >= 0 [rad/s], got {d}")


def _spec(text: str, args, colmap=None):
    """A file spec (path and window) of the real-log readers."""
    return parse_file_spec(
        text, window=args.window, columns=colmap, topic=args.topic, **spec_options(args)
    )


def _options(args, scale=None):
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
    :func:`manip_id.identification.fleet.portable_robot`, so the run pickles small); its quality and
    preprocessing come back through :meth:`summary`.
    """

    def __init__(self, robot, spec, options, scan: bool = True, cache: RowCache | None = None):
        self.robot, self.spec, self.options = robot, spec, options
        # bad files fail here, named; ``cache``: the rows the pre-fit audit parsed
        self.scan = scan_file(robot, spec, options, cache=cache) if scan else None
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
    colmap = column_map(args.column)
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
    runs: dict[str, list] = {"unloaded": [], "loaded": []}
    quality: dict[str, list] = {"unloaded": [], "loaded": []}
    with RowCache() as cache:  # a slow format parsed once: the audit records, the scans replay
        if scan:  # the pre-fit audit, printed and saved as "audit" (not where tasks read files)
            audited, audit = before_fit(
                robot,
                specs_u + specs_l,
                options,
                args,
                currents=args.command == "drive-gains",
                cache=cache,
            )
            specs_u, specs_l = audited[: len(specs_u)], audited[len(specs_u) :]
        for what, specs in (("unloaded", specs_u), ("loaded", specs_l)):
            for spec in specs:
                run = StreamedRun(robot, spec, options, scan=scan, cache=cache)
                if run.scan is not None:
                    if getattr(args, "verbose", False):  # else in the JSON only
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


def reserve_report(args, inputs: list[str]):
    """Check and claim the --report folder before the work (None without one)."""
    if getattr(args, "report", None) is None:
        return None
    if getattr(args, "outputs", None) is None:
        args.outputs = OutputSet()
    args.outputs.add_inputs(inputs)
    return args.outputs.report(args.report, "--report", force=args.force)


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


def publish_outputs(args, doc: dict, report=None) -> None:
    """Write the --json output and the report (``report(claim)`` builds it), then publish
    every output of the command together and say where they are."""
    publish_json(args, doc)
    claim = getattr(args, "report_claim", None)
    if report is not None and claim is not None:
        report(claim)
    outputs = getattr(args, "outputs", None)
    if outputs is not None:
        outputs.publish()
    if args.json:
        print(f"wrote {args.json}")
    if getattr(args, "export_urdf", None):
        print(f"wrote {args.export_urdf} and its sidecar")
    if claim is not None:
        print(f"wrote the report to {args.report}/index.html")


def publish_json(args, doc: dict) -> None:
    """Stage the --json output (through the OutputSet when there is one)."""
    if not args.json:
        return
    outputs = getattr(args, "outputs", None)
    if outputs is not None:
        outputs.write_json(args.json, doc)
    else:
        write_json(args.json, doc)


#: The single-file inputs besides the runs (checked against the outputs too).
INPUT_FILES = ("known_base", "torque_scale_from")


def input_paths(args) -> list[str]:
    """The input files (paths without their windows), for the output checks."""
    out = []
    for t in [*args.unloaded, *args.loaded, *(getattr(args, k, None) for k in INPUT_FILES)]:
        if t is None:
            continue
        p = Path(t)
        if not p.exists() and "@" in t:
            p = Path(t.rpartition("@")[0])
        out.append(str(p))
    return out


def run_quality(result, *, verbose: bool = False) -> tuple[dict, list]:
    """From the runs' summaries a result brings back (files scanned on the workers): the
    data quality per kind of run (printed) and the preprocessing per run."""
    quality: dict[str, list] = {"unloaded": [], "loaded": []}
    settings = []
    for what in ("unloaded", "loaded"):
        for info in result.runs.get(what, []):
            q, s = info["quality"], info["settings"]
            if verbose:
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
    """``manip-id payload`` (``--quiet``: nothing on stdout)."""
    with quiet_stdout(args):
        return _run(args)


def _run(args: argparse.Namespace) -> int:
    t_start = time.perf_counter()
    check_run_args(args)
    if args.known_base is not None and args.unloaded:
        raise InputError("give --unloaded runs or --known-base RESULT.json, not both")
    if args.known_base is None and not args.unloaded:
        raise InputError("give the --unloaded runs (or --known-base RESULT.json)")

    check_scheduler(args)
    args.report_claim = reserve_report(args, input_paths(args))
    reserve_json(args, input_paths(args))
    _reserve_export(args, input_paths(args))
    known = load_known_base(args.known_base) if args.known_base is not None else None
    robot = robot_from_args(args, args.known_base)  # the known base's joint model
    check_frame(robot, args.frame)
    scale = None
    if args.torque_scale is not None and args.torque_scale_from is not None:
        raise InputError("give --torque-scale or --torque-scale-from, not both")
    if args.torque_scale is not None:
        scale = parse_floats(args.torque_scale, "--torque-scale")
    elif args.torque_scale_from is not None:  # the gains drive-gains identified
        scale = [float(g) for g in load_torque_scale(args.torque_scale_from, robot)]
    distributed = args.scheduler is not None
    if distributed:  # the tasks read the files: send them a light robot
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
        quality, settings = run_quality(result, verbose=getattr(args, "verbose", False))
    doc["data_quality"] = quality
    doc["source"] = source
    doc["torque_scale"] = scale
    doc["preprocess"] = settings if distributed else preprocess_settings(unloaded + loaded)
    doc["timings"]["command_total"] = round(time.perf_counter() - t_start, 6)
    print(result.table())
    print_warnings(doc)
    _stage_export(args, robot, result)
    publish_outputs(
        args, doc, lambda claim: write_payload_report(claim, robot, doc, force=args.force)
    )
    return 0


def _reserve_export(args, inputs: list[str]) -> None:
    """Check --export-urdf before the work: --consistent given, the file new unless --force."""
    if not args.export_urdf:
        return
    if not args.consistent:
        raise InputError("--export-urdf needs a physically consistent payload: add --consistent")
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
    p = result.payload
    prov = identification_provenance("manip-id payload", vars(args))
    prov["uncertainty"] = p.to_dict()
    link = PayloadLink(args.frame, p.mass, p.com, p.inertia)
    texts = payload_urdf_texts(robot, link, args.export_urdf, provenance=prov)
    args.outputs.write_text(args.export_urdf, texts.urdf)
    args.outputs.write_json(sidecar_path(args.export_urdf), texts.sidecar)
