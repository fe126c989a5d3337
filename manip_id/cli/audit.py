"""``manip-id audit ROBOT --data FILE...``: the log auditor, and its run before every fit.

The command prints the audit (:mod:`manip_id.audit`) of each file against the
nominal model of ROBOT as one compact table and its findings, with the options
they recommend, and writes it as JSON (``--json``: ``{"audit": {"files": [...]}}``).
``identify``, ``payload`` and ``drive-gains`` run the same audit on their files
before the fit (:func:`before_fit`), print the same table and save it in their
JSON as ``audit``. This module also holds the stream options those commands share
(:func:`add_stream_arguments`): ``--delay``, ``--time-unit``, ``--trim-standstill``.
"""

from __future__ import annotations

from ._common import (
    add_file_arguments,
    add_robot_arguments,
    add_stream_arguments,
    command,
)


def register(sub) -> None:
    p = sub.add_parser(
        "audit",
        help="check log files against the nominal model before a fit",
        description="Audit measurement files against the nominal model of ROBOT: per file and "
        "joint the measured/nominal torque scale and sign (currents, gear ratios, flipped "
        "signs), the delay of the torque stream, the torque offset, the standstill share; per "
        "file the time unit, positions (degrees, offsets, wrap-around), rest at the edges, "
        "static files and bad rows. Prints one table and the options the findings recommend.",
    )
    add_robot_arguments(p)
    p.add_argument(
        "--data",
        metavar="FILE",
        nargs="+",
        action="extend",
        required=True,
        help="one or more measurement files, as for 'manip-id identify' (FILE@START:STOP [s], "
        "FILE@#A:#B [rows])",
    )
    p.add_argument(
        "--column",
        action="append",
        default=[],
        metavar="FIELD=COLUMNS",
        help="CSV column map for other layouts (repeatable), as for 'manip-id identify'",
    )
    p.add_argument(
        "--cutoff",
        type=float,
        default=None,
        help="low-pass cut-off [Hz] for files without ddq [default that of identify]",
    )
    p.add_argument("--json", metavar="OUT", help="write the audit as JSON to OUT")
    p.add_argument(
        "--report",
        metavar="DIR",
        default=None,
        help="write a report folder: the findings and what to fix first, then a table per "
        "file and joint [default: none]",
    )
    p.add_argument("--force", action="store_true", help="replace a --report folder manip-id wrote")
    add_file_arguments(p)
    add_stream_arguments(p, trim=False)
    p.set_defaults(func=command("manip_id.cli._audit"))
