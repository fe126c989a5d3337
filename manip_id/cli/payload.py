"""``manip-id payload``: the inertial parameters of a payload from unloaded and loaded runs.

Pipeline: scan every ``--unloaded`` and ``--loaded`` file first with the real-log
readers (:func:`manip_id.identification.scan_file`: its window, ``FILE@START:STOP`` or
``--window``, ``--torque-scale``, checks and the data-quality summary, printed), then
stream each file's rows (:func:`manip_id.identification.iter_processed`: preprocessed on its
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

from ._common import (
    add_execution_arguments,
    add_quiet_verbose,
    add_robot_arguments,
    add_scheduler_argument,
    add_stream_arguments,
    command,
)


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
    p.add_argument(
        "--report",
        metavar="DIR",
        default=None,
        help="write a report folder (index.html with the answers first, result.json"
        + (", the robot with the payload's inertia ellipsoid" if p.prog.endswith("payload") else "")
        + ") [default: none]",
    )
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
        help="base parameters of an earlier 'manip-id identify --json' instead of --unloaded; "
        "its joint terms and joints are the model's (no --friction to repeat)",
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
        "--torque-scale-from",
        metavar="RESULT.json",
        default=None,
        help="the drive gains of 'manip-id drive-gains --json' as --torque-scale",
    )
    p.add_argument(
        "--export-urdf",
        metavar="OUT.urdf",
        default=None,
        help="write the robot's URDF with the payload as a fixed link at FRAME (needs "
        "--consistent); sidecar OUT.identified.json [default: no export]",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="replace an existing --export-urdf file or a --report folder manip-id wrote "
        "[default: refuse]",
    )
    add_scheduler_argument(
        p,
        "each file is one task (read, preprocessed and accumulated on a worker), the sums "
        "are added on the cluster and the payload is solved here",
    )
    add_quiet_verbose(
        p,
        "also print each file's data quality and the pre-fit audit's table "
        "[default: the audit in one line; the data quality is in --json]",
    )
    p.set_defaults(func=command("manip_id.cli._payload"))
