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

from ..datasets import Layout, RowCache, load_dataset
from ..errors import InputError
from ..identification import (
    RunOptions,
    identify_dataset,
    identify_datasets,
    iter_processed,
    scan_file,
    split_file,
)
from ..identification.selection import select_model_files
from ..identification.temperature import (
    check_scans_temperature,
    check_sources_temperature,
    reference_from_scans,
    reference_text,
)
from ..viz.report_document import (
    ReportSamples,
    RunContext,
    add_file_info,
    add_raw_reference,
    result_document,
)
from . import _rollout
from ._common import data_column_map, file_specs, profile_from_args, progress
from ._runtime import (
    before_fit,
    consistent_kwargs,
    preprocess_options,
    print_result,
    robot_from_args,
    write_outputs,
)


def collect(robot, specs, options, scans) -> SimpleNamespace:
    """The preprocessed files in memory, one after the other (time shifted to increase)."""
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
    f = Layout.processed(nq, nv, rows.shape[1]).unpack(rows)
    fields: dict = {"temp": None, **f}  # temp: the temperature law's, when measured
    return SimpleNamespace(**fields, n_samples=rows.shape[0], settings=settings)


def _scan(robot, args: argparse.Namespace, specs, vspecs, options, timings: dict):
    """The pre-fit audit (printed), then each training and validation file scanned
    (``--split``: the one file cut first). A slow format (CSV, ROS bags) is parsed once:
    the audit's pass records its rows, which the scans read back."""
    check_sources_temperature(robot, specs + (vspecs or []))  # before the audit's output
    with RowCache() as cache:
        t0 = time.perf_counter()
        audited, audit = before_fit(robot, specs + (vspecs or []), options, args, cache=cache)
        specs = audited[: len(specs)]
        vspecs = None if vspecs is None else audited[len(specs) :]
        timings["audit"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        scans = {s: scan_file(robot, s, options, cache=cache) for s in specs + (vspecs or [])}
        source: dict = {"data": [s.label for s in specs]}
        if vspecs is None and args.split is not None:
            train_spec, valid_spec = split_file(
                robot, specs[0], args.split, options, scans[specs[0]], cache=cache
            )
            for old in scans.values():
                old.discard()
            specs, vspecs = [train_spec], [valid_spec]
            scans = {s: scan_file(robot, s, options, cache=cache) for s in specs + vspecs}
            source["split"] = args.split
    if vspecs is not None:
        source["validate"] = [s.label for s in vspecs]
    timings["scan"] = time.perf_counter() - t0
    for s in specs:
        print(scans[s].quality.text())
    for s in vspecs or []:
        print("validation " + scans[s].quality.text())
    return SimpleNamespace(specs=specs, vspecs=vspecs, scans=scans, source=source, audit=audit)


def _select_friction(robot, args, options, files: SimpleNamespace, timings: dict):
    """``--friction auto``: the joint model chosen per joint (one fit per candidate and
    shape, plain least squares; --consistent applies to the chosen model), printed;
    ``(robot with the chosen model, selection)``, or ``(robot, None)``."""
    if args.friction != "auto":
        return robot, None
    t0 = time.perf_counter()
    robot, _, selection = select_model_files(
        robot,
        files.specs,
        validation=files.vspecs,
        options=options,
        method=args.method,
        run=RunOptions(chunk=args.chunk, workers=args.workers),
        scans=files.scans,
    )
    timings["friction_selection"] = time.perf_counter() - t0
    print(selection.text())
    return robot, selection


def _note_selection(report: dict, robot, selection) -> None:
    """The selection's keys in the document (the same as select_model's result context)."""
    report["friction_selection"] = selection.to_dict()
    report["friction_criterion"] = selection.criterion
    report["joint_terms_per_joint"] = dict(
        zip(robot.dof_names, map(list, selection.terms.per_dof or ()), strict=True)
    )
    if selection.terms.shapes is not None:
        report["friction_shapes"] = selection.terms.shapes.to_dict()


def _identify_online(robot, args, options, files: SimpleNamespace, timings: dict):
    """rls / gradient: the files in memory, in sample order; (result, train, valid)."""
    t0 = time.perf_counter()
    train = collect(robot, files.specs, options, files.scans)
    valid = None if files.vspecs is None else collect(robot, files.vspecs, options, files.scans)
    timings["preprocess"] = time.perf_counter() - t0
    result = identify_dataset(  # (the processed rows as a dataset: with temp, if any)
        robot,
        train,
        method=args.method,
        validation=valid,
        run=RunOptions(chunk=args.chunk, progress=progress(args, train.n_samples)),
        uncertainty=args.uncertainty,
    )
    return result, train, valid


def _raw_parts(specs, vspecs, train, valid, options) -> list:
    """``(name, processed, t_raw, tau_raw)`` of one training (and one validation) file for
    :func:`manip_id.viz.report_document.add_raw_reference`; [] for several files."""
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


def _print_files(args, report: dict, accumulated: bool) -> None:
    """The deadband's left-out rows and the validation error per file, when there are any."""
    if accumulated and args.velocity_deadband is not None:
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


def run(args: argparse.Namespace, outputs, t_start: float) -> int:
    """``manip-id identify --data ...`` (after the outputs were reserved)."""
    timings: dict[str, float] = {}
    profile = profile_from_args(args)  # robots/ROBOT.toml [data]: defaults of the options
    colmap = data_column_map(args, profile)
    specs = file_specs(args.data, args, colmap)  # bad specs fail before the robot loads
    vspecs = file_specs(args.validate, args, colmap) if args.validate is not None else None
    robot = robot_from_args(args)
    options = preprocess_options(args, robot.nv, None if profile is None else profile.torque_scale)
    f = _scan(robot, args, specs, vspecs, options, timings)
    check_scans_temperature(robot, [f.scans[s] for s in f.vspecs or []])
    robot = reference_from_scans(robot, [f.scans[s] for s in f.specs])  # the law's T0
    if (text := reference_text(robot)) is not None:
        print(text)
    robot, selection = _select_friction(robot, args, options, f, timings)
    train = valid = None
    if args.method in ("rls", "gradient"):  # sample order, in memory
        result, train, valid = _identify_online(robot, args, options, f, timings)
        files, settings = None, train.settings
        n_valid = 0 if valid is None else valid.n_samples
    else:
        result = identify_datasets(
            robot,
            f.specs,
            validation=f.vspecs,
            options=options,
            method=args.method,
            run=RunOptions(
                chunk=args.chunk,
                workers=args.workers,
                progress=progress(args, sum(f.scans[s].n for s in f.specs)),
            ),
            scans=f.scans,
            uncertainty=args.uncertainty,
            **consistent_kwargs(args),
        )
        result = _rollout.refine_files(args, robot, result, f.specs, f.vspecs, options, timings)
        files = result.files or {}
        settings = files["train"][0].settings
        n_valid = 0 if f.vspecs is None else sum(x.n_samples for x in files["validation"])
    timings.update({k: float(v) for k, v in dict(result.timings).items() if k != "scan"})
    timings["total"] = time.perf_counter() - t_start
    ctx = RunContext(
        method=args.method,
        source=f.source,
        n_validation=n_valid,
        settings=settings,
        timings=timings,
        poorly_identified=getattr(args, "poorly_identified", None),
        condition_limit=getattr(args, "condition_limit", None),
    )
    report = result_document(robot, result, ctx)
    add_file_info(report, robot, f.specs, f.vspecs, f.scans, files, options, result)
    report["audit"] = f.audit.to_dict()
    _rollout.rollout_files(args, robot, result, f.vspecs, options, report)
    if selection is not None:
        _note_selection(report, robot, selection)
    if args.report is not None and train is None:  # the report draws the samples
        train = collect(robot, f.specs, options, f.scans)
        valid = None if f.vspecs is None else collect(robot, f.vspecs, options, f.scans)
    if train is not None:  # the samples are in memory anyway
        parts = _raw_parts(f.specs, f.vspecs, train, valid, options)
        add_raw_reference(report, robot, result, parts, args.chunk)
    print_result(report)
    _print_files(args, report, files is not None)
    return write_outputs(args, outputs, robot, result, report, ReportSamples(train, valid, train))
