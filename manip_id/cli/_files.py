"""``manip-id identify --data FILE...``: log files read in chunks, each preprocessed alone.

The data-input side of ``manip-id identify``: several files (``--data a b`` or
``--data a --data b``, never one silently dropped), windows (``FILE@START:STOP``
in seconds from the file's first stamp, ``FILE@#A:#B`` in rows, ``--window``
for files without one), ``--torque-scale G | G1,...,Gn``, ``--velocity-deadband
EPS``, ``--topic`` (ROS bags), ``--drop-bad-rows``. Every file is scanned first
(bad input fails naming the file before the long work) and its data-quality
summary printed; least squares (ols, wls) then accumulates each file in chunks
(:func:`manip_id.identification.identify_datasets`), memory bounded whatever
the files' length. The online laws (rls, gradient) run in sample order on the
preprocessed files held in memory, one after the other.
"""

from __future__ import annotations

import argparse
import time
from types import SimpleNamespace

import numpy as np

from ..errors import InputError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The data-file options of ``manip-id identify`` (besides --data and --validate)."""
    g = parser.add_argument_group("data files (--data, --validate)")
    g.add_argument(
        "--window",
        metavar="START:STOP",
        default=None,
        help="window of every file given without one: seconds from the file's first stamp "
        "(2.5:30, :30, 2.5:) or rows (#1000:#5000); a file takes its own as FILE@START:STOP",
    )
    g.add_argument(
        "--torque-scale",
        metavar="G[,G...]",
        default=None,
        help="multiply the torque columns: one gain, or one per joint (drive gains from "
        "current [A] to torque [N m], gear ratios); recorded in the JSON",
    )
    g.add_argument(
        "--torque-scale-from",
        metavar="RESULT.json",
        default=None,
        help="the drive gains of 'manip-id drive-gains --json' as --torque-scale",
    )
    g.add_argument(
        "--velocity-deadband",
        type=float,
        metavar="EPS",
        default=None,
        help="leave out the rows of joint j where |dq_j| < EPS [rad/s] (standstill, where the "
        "Coulomb term sign(dq) is noise); the JSON counts them per joint",
    )
    g.add_argument(
        "--topic",
        default=None,
        help="ROS bags: the sensor_msgs/msg/JointState topic [default: the only one]",
    )
    g.add_argument(
        "--drop-bad-rows",
        action="store_true",
        help="drop (and count) rows holding NaN/Inf instead of refusing the file",
    )


def parse_floats(text: str, what: str) -> list[float]:
    """``"1.5,2,3"`` -> [1.5, 2.0, 3.0], with a clear error."""
    try:
        values = [float(x) for x in str(text).split(",") if x.strip()]
    except ValueError:
        raise InputError(f"{what} expects numbers separated by commas, got {text!r}") from None
    if not values:
        raise InputError(f"{what} expects at least one number, got {text!r}")
    return values


def check(args: argparse.Namespace) -> None:
    """Refuse option combinations the file path does not do, before any work."""
    if getattr(args, "torque_scale_from", None) is not None:  # manip-id drive-gains --json
        from ..payload import load_torque_scale

        if args.simulate or args.torque_scale is not None:
            raise InputError("--torque-scale-from applies to --data files, without --torque-scale")
        gains = load_torque_scale(args.torque_scale_from)
        args.torque_scale = ",".join(repr(float(g)) for g in gains)
    if args.simulate:
        for name in ("window", "torque_scale", "velocity_deadband", "topic"):
            if getattr(args, name) is not None:
                raise InputError(f"--{name.replace('_', '-')} applies to --data files")
        if args.drop_bad_rows:
            raise InputError("--drop-bad-rows applies to --data files")
        return
    if args.velocity_deadband is not None:
        eps = args.velocity_deadband
        if not (np.isfinite(eps) and eps > 0):
            raise InputError(f"--velocity-deadband must be positive [rad/s], got {eps}")
        if args.method in ("rls", "gradient"):
            raise InputError(
                "--velocity-deadband applies to ols and wls (the online laws take every sample)"
            )
    if args.torque_scale is not None:
        parse_floats(args.torque_scale, "--torque-scale")
    if args.window is not None:
        from ..datasets import Window

        Window.parse(args.window, "--window")
    if args.split is not None and args.data is not None and len(args.data) > 1:
        raise InputError(
            "--split cuts one file; with several --data files give --validate files "
            "(or windows FILE@START:STOP)"
        )


def _options(args, nv: int, profile_scale=None):
    from ..datasets.stream import torque_scale_vector
    from ..identification import PreprocessOptions

    scale = None
    if args.torque_scale is not None:
        scale = torque_scale_vector(
            parse_floats(args.torque_scale, "--torque-scale"), nv, "--torque-scale"
        )
    elif profile_scale is not None:  # the robot profile's [data] torque_scale
        scale = torque_scale_vector(profile_scale, nv, "the profile's torque_scale")
    return PreprocessOptions(
        cutoff=args.cutoff,
        order=args.order,
        trim=args.trim,
        decimate=args.decimate,
        torque_scale=None if scale is None else tuple(scale.tolist()),
        velocity_deadband=args.velocity_deadband,
        drop_bad_rows=args.drop_bad_rows,
    )


def _specs(values, args, colmap):
    from ..datasets import parse_file_spec

    return [
        parse_file_spec(v, window=args.window, columns=colmap, topic=args.topic)
        for v in values or []
    ]


def _collect(robot, specs, options, scans) -> SimpleNamespace:
    """The preprocessed files in memory, one after the other (time shifted to increase)."""
    from ..identification import iter_processed

    nq, nv = robot.nq, robot.nv
    parts: list[np.ndarray] = []
    settings, shift = None, 0.0
    for spec in specs:
        s, blocks = iter_processed(robot, spec, options, scans[spec])
        settings = settings or s
        rows = np.vstack(list(blocks))
        if rows.shape[1] < 1 + nq + 3 * nv:
            raise InputError(f"{spec.label}: no accelerations")
        if parts:
            prev = parts[-1]
            step = float(np.median(np.diff(rows[:, 0]))) if rows.shape[0] > 1 else 1.0
            shift = prev[-1, 0] + step - rows[0, 0]
            rows = rows.copy()
            rows[:, 0] += shift
        parts.append(rows)
    rows = np.vstack(parts)
    return SimpleNamespace(
        t=rows[:, 0],
        q=rows[:, 1 : 1 + nq],
        dq=rows[:, 1 + nq : 1 + nq + nv],
        tau=rows[:, 1 + nq + nv : 1 + nq + 2 * nv],
        ddq=rows[:, 1 + nq + 2 * nv : 1 + nq + 3 * nv],
        n_samples=rows.shape[0],
        settings=settings,
    )


def run(args: argparse.Namespace, outputs, t_start: float, robot=None) -> int:
    """``manip-id identify --data ...`` (after the outputs were reserved)."""
    from ..identification import RunOptions, identify, identify_datasets, scan_file, split_file
    from ..identification.selection import select_model_files
    from . import identify as cmd
    from ._common import profile_from_args, robot_from_args

    timings: dict[str, float] = {}
    profile = profile_from_args(args)  # robots/ROBOT.toml [data]: defaults of the options
    colmap = cmd._column_map(args.column)
    if colmap is None and profile is not None and profile.columns:
        colmap = dict(profile.columns)
    specs = _specs(args.data, args, colmap)
    vspecs = _specs(args.validate, args, colmap) if args.validate is not None else None
    robot = robot or robot_from_args(args)
    options = _options(args, robot.nv, None if profile is None else profile.torque_scale)
    t0 = time.perf_counter()
    scans = {s: scan_file(robot, s, options) for s in specs + (vspecs or [])}
    source: dict = {"data": [s.label for s in specs]}
    if vspecs is None and args.split is not None:
        train_spec, valid_spec = split_file(robot, specs[0], args.split, options, scans[specs[0]])
        for old in scans.values():
            old.discard()
        specs, vspecs = [train_spec], [valid_spec]
        scans = {s: scan_file(robot, s, options) for s in specs + vspecs}
        source["split"] = args.split
    if vspecs is not None:
        source["validate"] = [s.label for s in vspecs]
    timings["scan"] = time.perf_counter() - t0
    for s in specs:
        print(scans[s].quality.text())
    for s in vspecs or []:
        print("validation " + scans[s].quality.text())

    selection = None
    if args.friction == "auto":  # one fit per candidate and shape, then the chosen model
        t0 = time.perf_counter()
        robot, _, selection = select_model_files(
            robot,
            specs,
            validation=vspecs,
            options=options,
            method=args.method,
            run=RunOptions(chunk=args.chunk, workers=args.workers),
            scans=scans,
        )  # plain least squares per candidate; --consistent applies to the chosen model
        timings["friction_selection"] = time.perf_counter() - t0
        print(selection.text())
    if args.method in ("rls", "gradient"):  # sample order, in memory
        t0 = time.perf_counter()
        train = _collect(robot, specs, options, scans)
        valid = None if vspecs is None else _collect(robot, vspecs, options, scans)
        timings["preprocess"] = time.perf_counter() - t0
        result = identify(
            robot,
            train.q,
            train.dq,
            train.ddq,
            train.tau,
            method=args.method,
            validation=None if valid is None else (valid.q, valid.dq, valid.ddq, valid.tau),
            run=RunOptions(chunk=args.chunk, progress=cmd._progress(train.n_samples)),
        )
        files = None
        settings = train.settings
        n_valid = None if valid is None else valid.n_samples
    else:
        result = identify_datasets(
            robot,
            specs,
            validation=vspecs,
            options=options,
            method=args.method,
            run=RunOptions(
                chunk=args.chunk,
                workers=args.workers,
                progress=cmd._progress(sum(scans[s].n for s in specs)),
            ),
            scans=scans,
            **cmd._consistent_kwargs(args),
        )
        files = result.files or {}
        settings = files["train"][0].settings
        n_valid = None if vspecs is None else sum(f.n_samples for f in files["validation"])
        train = valid = None  # type: ignore[assignment]
    timings.update({k: float(v) for k, v in dict(result.timings).items() if k != "scan"})
    timings["total"] = time.perf_counter() - t_start
    valid_count = None if n_valid is None else SimpleNamespace(n_samples=n_valid)
    report = cmd._result_document(
        robot,
        result,
        SimpleNamespace(n_samples=result.n_samples),
        valid_count,
        None,
        timings,
        args,
        source,
        settings,
    )
    _add_file_info(report, robot, specs, vspecs, scans, files, options, result)
    if selection is not None:  # the same keys as select_model's result context
        report["friction_selection"] = selection.to_dict()
        report["friction_criterion"] = selection.criterion
        report["joint_terms_per_joint"] = dict(
            zip(robot.dof_names, map(list, selection.terms.per_dof or ()), strict=True)
        )
        if selection.terms.shapes is not None:
            report["friction_shapes"] = selection.terms.shapes.to_dict()
    if args.report is not None or train is not None:  # the samples are in memory anyway
        if train is None:
            train = _collect(robot, specs, options, scans)
            valid = None if vspecs is None else _collect(robot, vspecs, options, scans)
        cmd.add_raw_reference(
            report, robot, result, _raw_parts(specs, vspecs, train, valid, options), args.chunk
        )
    print(result.table())
    print(cmd._summary(robot, report))
    if files is not None and args.velocity_deadband is not None:
        left = report["velocity_deadband"]["excluded_rows"]
        print(
            f"velocity deadband {args.velocity_deadband:g} rad/s: rows left out per joint: "
            + ", ".join(f"{j} {n}" for j, n in left.items())
        )
    per_file = report["relative_error"].get("validation_per_file")
    if per_file and len(per_file) > 1:
        print(
            "validation per file: "
            + ", ".join(f"{e['file']} {100 * (e['error'] or np.nan):.3f} %" for e in per_file)
        )
    if args.json:
        outputs.write_json(args.json, report)
    path = None
    if args.report is not None:
        if train is None:
            train = _collect(robot, specs, options, scans)
            valid = None if vspecs is None else _collect(robot, vspecs, options, scans)
        path = cmd._write_report(robot, result, train, train, valid, report, args)
    if args.export_urdf:
        cmd._export(robot, result, args, outputs)
    outputs.publish()
    if args.json:
        print(f"wrote {args.json}")
    if args.export_urdf:
        print(f"wrote {args.export_urdf} and its sidecar")
    if path is not None:
        print(f"wrote the report to {path}/index.html")
    return 0


def _raw_parts(specs, vspecs, train, valid, options) -> list:
    """``(name, processed, t_raw, tau_raw)`` of one training (and one validation) file for
    :func:`manip_id.cli.identify.add_raw_reference`; [] for several files."""
    from ..datasets import load_dataset

    if len(specs) != 1 or (vspecs is not None and len(vspecs) != 1):
        return []
    parts, raws = [], {}
    for name, spec, proc in (
        ("train", specs[0], train),
        ("validation", (vspecs or [None])[0], valid),
    ):
        if spec is None:
            continue
        key = (str(spec.path), spec.topic)
        if key not in raws:
            raws[key] = load_dataset(
                spec.path, format=spec.format, columns=spec.columns, topic=spec.topic
            )
        raw = raws[key]
        scale = 1.0 if options.torque_scale is None else np.asarray(options.torque_scale)
        parts.append((name, proc, raw.t, raw.tau * scale))
    return parts


def _add_file_info(report, robot, specs, vspecs, scans, files, options, result) -> None:
    joints = list(robot.dof_names)
    report["data_quality"] = [scans[s].quality.to_dict() for s in specs]
    if vspecs is not None:
        report["validation_data_quality"] = [scans[s].quality.to_dict() for s in vspecs]
    report["torque_scale"] = None if options.torque_scale is None else list(options.torque_scale)
    if files is not None:
        report["files"] = [f.summary(joints) for f in files["train"]]
        if files["validation"] is not None:
            report["validation_files"] = [f.summary(joints) for f in files["validation"]]
        if options.velocity_deadband is not None:
            left = np.sum([f.excluded for f in files["train"]], axis=0)
            vleft = (
                None
                if files["validation"] is None
                else np.sum([f.excluded for f in files["validation"]], axis=0)
            )
            report["velocity_deadband"] = {
                "eps": options.velocity_deadband,
                "excluded_rows": dict(zip(joints, map(int, left), strict=True)),
                "excluded_rows_validation": None
                if vleft is None
                else dict(zip(joints, map(int, vleft), strict=True)),
            }
    vpf = result.relative_error.validation_per_file
    if vpf is not None:
        report["relative_error"]["validation_per_file"] = vpf
    warnings_ = [w for s in list(specs) + list(vspecs or []) for w in scans[s].quality.warnings]
    report["data_warnings"] = warnings_
