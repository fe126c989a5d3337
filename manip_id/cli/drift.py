"""``manip-id drift ROBOT --reference RESULT.json --data FILE... [--scheduler SPEC]``.

Each file (``--group-by folder``: the files of each folder together) is identified alone
with the reference's base parameters (one task per file on the fleet path,
:func:`manip_id.drift.drift_files`) and tested against the reference: a chi-square on all
base parameters, and a test per joint-level term ("panda_joint3 viscous friction +31 %
(p < 1e-06)"). ``--json`` writes ``{"drift": {alpha, covariance_kind,
reference, files: [{file, p_value, changed, terms: [{name, change, p_value, changed}]}]}}``.
"""

from __future__ import annotations

import argparse
import os

from .._io import OutputSet
from ..errors import InputError
from ._common import (
    add_robot_arguments,
    add_scheduler_argument,
    check_scheduler,
    reserve_outputs,
    robot_from_args,
)


def register(sub) -> None:
    p = sub.add_parser(
        "drift",
        help="which logs' dynamics changed beyond the noise of a reference identification",
        description="Identify every --data file alone with the reference's base parameters "
        "and test it against --reference: chi-square on the base parameters (both "
        "covariances) and one test per friction / joint term.",
    )
    add_robot_arguments(p)
    p.add_argument("--reference", required=True, metavar="RESULT.json", help="the reference")
    p.add_argument(
        "--data", nargs="+", action="extend", required=True, metavar="FILE",
        help="files to test, each identified alone (FILE@START:STOP windows)",
    )  # fmt: skip
    p.add_argument(
        "--group-by",
        choices=("file", "folder"),
        default="file",
        help="test each file alone (default), or the files of each folder together (one "
        "folder per robot)",
    )
    p.add_argument("--alpha", type=float, default=0.05, help="significance level (0.05)")
    p.add_argument("--window", default=None, metavar="START:STOP", help="window of every file")
    p.add_argument("--cutoff", type=float, default=None, help="low-pass cut-off [Hz]")
    add_scheduler_argument(p, "one task per file")
    p.add_argument("--json", default=None, metavar="OUT", help="write the report as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..drift import drift_files  # the fleet path loads with the command, not with --help
    from ..identification import PreprocessOptions, load_result

    if not 0.0 < args.alpha < 1.0:
        raise InputError(f"--alpha must be a level in (0, 1), got {args.alpha}")
    check_scheduler(args)
    args.outputs = getattr(args, "outputs", None) or OutputSet()
    args.outputs.add_inputs([args.reference])
    outputs = reserve_outputs(args)
    robot = robot_from_args(args)
    reference = load_result(args.reference)
    options = PreprocessOptions(cutoff=args.cutoff)
    data = args.data if args.group_by == "file" else _by_folder(args.data)
    report = drift_files(
        robot,
        reference,
        data,
        alpha=args.alpha,
        scheduler=args.scheduler,
        options=options,
        window=args.window,
    )
    print("\n".join(report.lines()))
    if args.json is not None:
        doc = {"robot": robot.name, "drift": {**report.to_dict(), "reference": args.reference}}
        outputs.write_json(args.json, doc)
    outputs.publish()
    if args.json is not None:
        print(f"wrote {args.json}")
    return 0


def _by_folder(files: list[str]) -> dict[str, list[str]]:
    """``{folder: [its files]}`` in the order the folders first appear (``FILE@WINDOW`` kept)."""
    groups: dict[str, list[str]] = {}
    for f in files:
        path = f if os.path.exists(f) or "@" not in f else f.rsplit("@", 1)[0]
        groups.setdefault(os.path.dirname(os.path.abspath(path)), []).append(f)
    return groups
