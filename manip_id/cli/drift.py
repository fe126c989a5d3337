"""``manip-id drift ROBOT --reference RESULT.json --data FILE... [--scheduler SPEC]``.

Each file (``--group-by folder``: the files of each folder together) is identified alone
with the reference's base parameters (one task per file on the fleet path,
:func:`manip_id.monitor.drift.drift_files`) and tested against the reference: a chi-square on all
base parameters, and a test per joint-level term ("panda_joint3 viscous friction +31 %
(p < 1e-06)"). ``--json`` writes ``{"drift": {alpha, covariance_kind,
reference, files: [{file, p_value, changed, terms: [{name, change, p_value, changed}]}]}}``.
"""

from __future__ import annotations

from ._common import (
    add_robot_arguments,
    add_scheduler_argument,
    command,
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
    p.add_argument("--alpha", type=float, default=0.05, help="significance level [default 0.05]")
    p.add_argument(
        "--window",
        default=None,
        metavar="START:STOP",
        help="window of every file [default: whole files]",
    )
    p.add_argument(
        "--cutoff",
        type=float,
        default=None,
        help="low-pass cut-off [Hz] [default: that of identify]",
    )
    add_scheduler_argument(p, "one task per file")
    p.add_argument(
        "--json", default=None, metavar="OUT", help="write the report as JSON [default: none]"
    )
    p.set_defaults(func=command("manip_id.cli._drift"))
