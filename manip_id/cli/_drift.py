"""``manip-id drift`` once it runs (the options are declared in :mod:`.drift`)."""

from __future__ import annotations

import argparse
import os

from .._io import OutputSet
from ..errors import InputError
from ..identification import PreprocessOptions, load_result
from ..monitor.drift import drift_files
from ._common import (
    reserve_outputs,
)
from ._runtime import (
    check_scheduler,
    robot_from_args,
)


def run(args: argparse.Namespace) -> int:

    if not 0.0 < args.alpha < 1.0:
        raise InputError(f"--alpha must be a level in (0, 1), got {args.alpha}")
    check_scheduler(args)
    args.outputs = getattr(args, "outputs", None) or OutputSet()
    args.outputs.add_inputs([args.reference])
    outputs = reserve_outputs(args)
    robot = robot_from_args(args, args.reference)
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
