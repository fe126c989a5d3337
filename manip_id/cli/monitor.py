"""``manip-id monitor ROBOT --model RESULT.json --calibrate FILE... --data FILE...``.

Calibrates per-joint bounds of the momentum observer's residual on collision-free files
(:func:`manip_id.monitor.calibrate_thresholds`), runs the observer over the ``--data``
files and prints the detections as time intervals (the files' own time [s]); ``--json``
writes ``{"thresholds", "detections": [{file, start, stop, joints, peak}], "files"}``,
``--report`` a folder with the residuals against their bounds per file. ``--thresholds
MONITOR.json`` instead of ``--calibrate`` reuses the bounds (and gains) of an earlier run.

File options as ``identify``'s: ``FILE@START:STOP`` windows, ``--window``,
``--torque-scale``, ``--drop-bad-rows``, ``--topic``, ``--column``. The files are read
unfiltered (an online observer sees raw signals); a column map applies to the CSV files,
a topic to the bags. The model is ``--model RESULT.json``, or an exported URDF given as
ROBOT with ``--identified`` (its sidecar; the robot's own parameters are the model).
"""

from __future__ import annotations

from ._common import (
    add_robot_arguments,
    command,
)


def register(sub) -> None:
    p = sub.add_parser(
        "monitor",
        help="collision / external-torque monitor on an identified model",
        description="Run the generalized-momentum observer on an identified model: bounds "
        "from collision-free --calibrate files at a false-alarm rate, then detections (time "
        "intervals, joints, peak residual) on the --data files.",
    )
    add_robot_arguments(p)
    p.add_argument(
        "--identified",
        action="store_true",
        help="ROBOT is a URDF written by --export-urdf: read its sidecar (NAME.identified.json)",
    )
    p.add_argument(
        "--model",
        metavar="RESULT.json",
        default=None,
        help="identification result (identify --json, a report's result.json); not needed "
        "for an exported URDF with --identified",
    )
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument(
        "--calibrate", nargs="+", action="extend", metavar="FILE",
        help="collision-free files for the bounds",
    )  # fmt: skip
    src.add_argument(
        "--thresholds", metavar="MONITOR.json", default=None,
        help="bounds calibrated before (the --json of an earlier run); the observer takes "
        "their gains",
    )  # fmt: skip
    p.add_argument(
        "--data", nargs="+", action="extend", required=True, metavar="FILE",
        help="files to monitor",
    )  # fmt: skip
    p.add_argument(
        "--false-alarm", type=float, default=1e-3, metavar="RATE",
        help="false-alarm rate per sample, any joint (default 1e-3)",
    )  # fmt: skip
    p.add_argument("--gain", default=None, metavar="K[,K...]", help="observer gain [1/s] (25)")
    p.add_argument(
        "--filter-gain",
        default=None,
        metavar="K2[,K2...]",
        help="second low-pass of the residual [1/s] (default 25; 'none': first-order observer)",
    )
    g = p.add_argument_group("data files")
    g.add_argument("--window", default=None, metavar="START:STOP", help="window of every file")
    g.add_argument("--torque-scale", default=None, metavar="G[,G...]", help="torque gains")
    g.add_argument("--topic", default=None, help="ROS bags: the JointState topic")
    g.add_argument("--drop-bad-rows", action="store_true", help="drop rows with NaN/Inf")
    g.add_argument(
        "--column", action="append", default=[], metavar="FIELD=COLUMNS",
        help="CSV column map (repeatable), as identify's: --column t=stamp --column q='pos*'",
    )  # fmt: skip
    p.add_argument("--json", default=None, metavar="OUT", help="write the detections as JSON")
    p.add_argument("--report", default=None, metavar="DIR", help="write a report folder")
    p.add_argument("--force", action="store_true", help="replace a non-empty --report folder")
    p.set_defaults(func=command("manip_id.cli._monitor"))
