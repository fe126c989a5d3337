"""``manip-id convert IN OUT``: rewrite any supported input as NPZ, CSV or MCAP, streamed.

IN is anything ``--data`` reads (NPZ, CSV with ``--column``, a ROS 2 bag with
``--topic``, the Panda log folder), with an optional window ``IN@START:STOP``
[s] or ``IN@#A:#B`` [rows]; OUT's suffix picks the format (``.npz``, ``.csv``,
``.mcap``; or ``--format``). Rows are read and written block by block (memory
independent of the length), checked as for identification (NaN rows refused,
or dropped with ``--drop-bad-rows``; ``--torque-scale`` applied), and OUT is
checked before the work and appears only once complete.
"""

from __future__ import annotations

import argparse

from .._io import OutputSet
from ..datasets import Layout, RowCounts, iter_rows, open_source, parse_file_spec
from ..datasets.io import output_format, write_rows_to
from ..datasets.stream import torque_scale_vector
from ..errors import DataError
from ._common import column_map, parse_floats


def register(sub) -> None:
    p = sub.add_parser(
        "convert",
        help="rewrite a data file as NPZ, CSV or MCAP",
        description="Rewrite IN (NPZ, CSV, ROS 2 bag, Panda log folder; IN@START:STOP or "
        "IN@#A:#B for a window) as OUT in the format of its suffix (.npz, .csv, .mcap), "
        "block by block.",
    )
    p.add_argument("input", metavar="IN", help="input file or folder, optionally IN@WINDOW")
    p.add_argument("output", metavar="OUT", help="output file: .npz, .csv or .mcap")
    p.add_argument(
        "--format",
        choices=("npz", "csv", "mcap"),
        default=None,
        help="output format [default: from OUT's suffix]",
    )
    p.add_argument(
        "--topic", default=None, help="ROS bags: the JointState topic [default: the only one]"
    )
    p.add_argument(
        "--column",
        action="append",
        default=[],
        metavar="FIELD=COLUMNS",
        help="CSV column map (as for manip-id identify)",
    )
    p.add_argument(
        "--torque-scale",
        metavar="G[,G...]",
        default=None,
        help="multiply the torque columns: one gain, or one per joint (e.g. drive gains from "
        "current [A] to torque [N m]) [default: 1, the torques as recorded]",
    )
    p.add_argument(
        "--drop-bad-rows",
        action="store_true",
        help="drop (and count) rows holding NaN/Inf instead of refusing the file [default: refuse]",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    spec = parse_file_spec(args.input, columns=column_map(args.column), topic=args.topic)
    outputs = getattr(args, "outputs", None) or OutputSet()
    outputs.add_inputs([spec.path])
    out = outputs.file(args.output, "OUT")
    fmt = output_format(out, args.format)
    src = open_source(spec)
    scale = None
    if args.torque_scale is not None:
        scale = torque_scale_vector(
            parse_floats(args.torque_scale, "--torque-scale"), src.layout.nv, "--torque-scale"
        )
    # a JointState bag carries neither ddq nor a temperature: the rows' first columns
    layout = src.layout if fmt != "mcap" else Layout(src.layout.nq, src.layout.nv)

    passes: list[RowCounts] = []

    def blocks():
        counts = RowCounts()
        passes.append(counts)
        for rows in iter_rows(
            src, spec.window, torque_scale=scale, drop_bad_rows=args.drop_bad_rows, counts=counts
        ):
            yield rows[:, : layout.width]

    n = 0
    if fmt == "npz":  # the .npy headers need the row count: one counting pass
        for rows in blocks():
            n += rows.shape[0]
    try:
        outputs.write(out, lambda tmp: write_rows_to(tmp, fmt, blocks, n, layout, src.joint_names))
    except DataError as exc:
        msg = str(exc)
        raise DataError(msg if str(spec.path) in msg else f"{spec.label}: {msg}") from exc
    outputs.publish()
    counts = passes[0]
    dropped = f", {counts.n_dropped} bad rows dropped" if counts.n_dropped else ""
    dropped_fields = [f for f in ("ddq", "temp") if f in src.layout.slices]
    note = ""
    if fmt == "mcap" and dropped_fields:
        note = f" ({', '.join(dropped_fields)} not carried by JointState)"
    print(f"wrote {out}: {counts.n_read} samples from {spec.label} as {fmt}{dropped}{note}")
    return 0
