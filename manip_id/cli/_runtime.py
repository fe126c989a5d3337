"""What the commands share once they run: the robot, the library's option objects, the
result printed, the outputs staged and published.

The command modules declare their options with :mod:`._common` (light: ``manip-id
--help`` builds every parser from it); this module loads Pinocchio and the
identification, and is imported by the modules that run the commands.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

from .._native import native_stderr_captured
from ..audit import AuditOptions, audit_files
from ..datasets.stream import torque_scale_vector
from ..errors import InputError, did_you_mean
from ..estimators.consistent import DEFAULT_PRIOR_WEIGHT, check_options
from ..estimators.consistent.bounds import bound_options
from ..execution import available_cores, cap_local_workers
from ..export import export_texts, mjcf_text, sidecar_path
from ..export.sidecar import identification_provenance
from ..identification import ConsistentOptions, PreprocessOptions, read_result_json
from ..identification.run_context import run_keys, with_context
from ..payload import load_torque_scale
from ..robot.model import Robot, load_robot
from ..viz.report_document import ReportOptions, data_in_words
from ._answer import advice_for, answer_text
from ._common import (
    exports_wanted,
    finish,
    identify_report,
    parse_floats,
    profile_option,
    transmission_option,
    warn,
)


def robot_from_args(args: argparse.Namespace, model=None) -> Robot:
    """Load the robot named by :func:`add_robot_arguments` options.

    ``model``: a saved result (``RESULT.json`` or a report folder) the robot is for: the
    model structure it was identified with (joint terms and laws, active joints, drive
    train) is the default; an option that contradicts it is refused in one line.
    """

    structure = None if model is None else result_structure(model, args.robot)
    joints = [j for j in args.joints.split(",") if j] if getattr(args, "joints", None) else None
    with native_stderr_captured("urdfdom"):  # its C++ messages become one warning line
        robot = load_robot(
            args.robot,
            armature=args.armature,
            friction=None if args.friction == "auto" else args.friction,
            spring=args.spring,
            active_joints=joints,
            package_dirs=args.package_dir,
            profile=profile_option(args),
            identified=structure,
        )
    tr = transmission_option(args)  # --transmission, else the profile's
    robot = robot if tr is None else robot.with_transmission(tr)
    if structure is not None:
        check_structure(robot, structure, model)
    return robot


def result_structure(model, robot_spec: str) -> dict | None:
    """The ``model_structure`` of a saved result (None for a result written before it was
    recorded); a result of another robot is refused."""
    path = Path(model)
    doc = read_result_json(path / "result.json" if path.is_dir() else path, "result")
    structure = doc.get("model_structure")
    if not isinstance(structure, dict):
        return None
    name, spec = structure.get("robot"), Path(str(robot_spec)).stem
    if name is not None and name != spec and str(robot_spec) != name:
        raise InputError(f"{model} is a model of robot {name!r}, not of {robot_spec!r}")
    return structure


def check_structure(robot: Robot, structure: dict, model) -> None:
    """Refuse a robot whose joint terms or active joints differ from those ``model`` was
    identified with (an explicit --friction, --armature, --spring, --joints or
    --transmission that contradicts it)."""
    want = (list(structure.get("joint_terms", [])), list(structure.get("active_joints", [])))
    have = (list(robot.terms.enabled), list(robot.joint_names))
    if want[0] != have[0]:
        raise InputError(
            f"{model} was identified with the joint terms {want[0]}, but the options given "
            f"make {have[0]}: leave out --friction, --armature and --spring (the result's "
            "model is used)"
        )
    if want[1] != have[1]:
        raise InputError(
            f"{model} was identified on the joints {want[1]}, but the options given make "
            f"{have[1]}: leave out --joints (the result's joints are used)"
        )


def check_frame(robot, frame: str) -> None:
    """A misspelt ``--frame``: an error naming the closest frame (and the frames on moving
    joints); other frames are left to the library's own checks."""
    model = robot.model
    if model.existFrame(frame):
        return
    hint = did_you_mean(frame, [f.name for f in model.frames])
    if hint:
        moving = [f.name for f in model.frames if int(f.parentJoint) > 0]
        raise InputError(
            f"robot {robot.name!r} has no frame {frame!r}{hint}; frames on moving joints: "
            + ", ".join(moving)
        )


def check_scheduler(args: argparse.Namespace) -> None:
    """Refuse a malformed ``--scheduler`` before any work (nothing of Dask imported)."""
    if getattr(args, "scheduler", None) is not None:
        args.scheduler, asked = cap_local_workers(args.scheduler)
        if asked is not None:  # as --workers is (check_seed_and_workers)
            warn(
                f"--scheduler local:{asked} capped at the {available_cores()} cores of this machine"
            )


def preprocess_options(args: argparse.Namespace, robot: Robot, profile_scale=None):
    """The :class:`~manip_id.identification.PreprocessOptions` of identify's data-file options.

    ``--torque-scale`` (one gain or one per joint), else ``--torque-scale-from`` (the gains
    of ``manip-id drive-gains --json``, checked against ``robot``), else the profile's
    [data] torque_scale.
    """
    nv, scale = robot.nv, None
    if args.torque_scale is not None:
        scale = torque_scale_vector(
            parse_floats(args.torque_scale, "--torque-scale"), nv, "--torque-scale"
        )
    elif getattr(args, "torque_scale_from", None) is not None:
        scale = np.asarray(load_torque_scale(args.torque_scale_from, robot), dtype=float)
    elif profile_scale is not None:  # the robot profile's [data] torque_scale
        scale = torque_scale_vector(profile_scale, nv, "the profile's torque_scale")
    return PreprocessOptions(
        cutoff=args.cutoff,
        order=args.order,
        trim=args.trim,
        decimate=args.decimate,
        torque_scale=None if scale is None else tuple(float(g) for g in scale),
        velocity_deadband=args.velocity_deadband,
        drop_bad_rows=args.drop_bad_rows,
    )


def consistent_options(args: argparse.Namespace) -> ConsistentOptions:
    """The physically consistent estimation options of identify (checked by their own
    constructor; the bounds parsed from their texts)."""
    b = bound_options(args.bounds, args.mass_range, args.total_mass)
    enabled = bool(args.consistent)
    if not enabled:
        check_options(args.solver, args.prior, args.prior_weight or DEFAULT_PRIOR_WEIGHT)
    return ConsistentOptions(
        enabled=enabled,
        solver=args.solver,
        prior=args.prior,
        prior_weight=args.prior_weight,
        bounds=b.bounds,
        mass_range=b.mass_range,
        total_mass=b.total_mass,
    )


def run_document(robot, result, args: argparse.Namespace, ctx, timings: dict, extra=None):
    """The result with the run's context (:mod:`manip_id.identification.run_context`) and
    its timings, and its JSON (``to_dict`` with the flag thresholds of the options)."""
    keys = {**run_keys(robot, result, ctx), **(extra or {})}
    result = replace(with_context(result, keys), timings={k: float(v) for k, v in timings.items()})
    report = result.to_dict(
        poorly_identified=getattr(args, "poorly_identified", None),
        condition_limit=getattr(args, "condition_limit", None),
    )
    return result, report


def stage_export(
    robot, result, args: argparse.Namespace, outputs, theta=None, command="manip-id identify"
) -> None:
    """Stage the exported URDF / MJCF and their sidecars (published with the other outputs);
    ``theta``: the standard parameters to write [default: the result's consistent ones]."""
    prov = identification_provenance(command, vars(args), result)
    theta = result.standard.values if theta is None else theta
    if getattr(args, "export_urdf", None):
        texts = export_texts(robot, theta, args.export_urdf, provenance=prov)
        outputs.write_text(args.export_urdf, texts.urdf)
        outputs.write_json(sidecar_path(args.export_urdf), texts.sidecar)
    if getattr(args, "export_mjcf", None):
        mj = mjcf_text(robot, theta, args.export_mjcf, provenance=prov)
        outputs.write_text(args.export_mjcf, mj.xml)
        outputs.write_json(sidecar_path(args.export_mjcf), mj.sidecar)


def before_fit(robot, specs, options, args, *, currents: bool = False, cache=None):
    """The pre-fit audit of ``specs``: printed, and the specs to fit.

    ``options``: the run's :class:`~manip_id.identification.PreprocessOptions` (torque
    scale, bad rows, deadband, cut-off). ``currents``: the torque columns are expected
    to hold currents (``drive-gains``): no torque-scale finding. With
    ``--trim-standstill`` the specs come back with the windows the audit keeps.
    ``cache``: a :class:`~manip_id.datasets.RowCache` keeping the parsed rows of slow
    formats for the scan that follows. Returns ``(specs, audit)``.
    """
    audit = audit_files(robot, specs, _audit_options(options, currents), cache=cache)
    print(audit.text(verbose=bool(getattr(args, "verbose", False))))
    audit.check()  # every file audited first; then one error naming each unreadable one
    if getattr(args, "trim_standstill", False):
        specs = audit.trimmed()
        kept = [s.label for s in specs]
        print("--trim-standstill: " + ", ".join(kept))
    return specs, audit


def _audit_options(options, currents: bool):
    return AuditOptions(
        torque_scale=options.torque_scale,
        drop_bad_rows=options.drop_bad_rows,
        standstill=options.velocity_deadband,
        cutoff=None if options.cutoff == "auto" else options.cutoff,  # auto: the audit's own
        currents=currents,
    )


def report_options(args: argparse.Namespace, source: str | None = None, rollout=None):
    """The :class:`~manip_id.viz.report_document.ReportOptions` of identify's options
    (``rollout``: the result's rollout validation, drawn in the report)."""

    if source is None:
        source = "simulated" if args.simulate else data_in_words(args.data)
    return ReportOptions(
        source=source,
        simulated=bool(args.simulate),
        chunk=args.chunk,
        scene_assets=getattr(args, "scene_assets", "inline"),
        force=args.force,
        rollout=rollout,
    )


def print_warnings(document: dict) -> None:
    """Every warning of the document (its JSON ``warnings``), once each, on stderr as
    ``manip-id: warning: ...``: what is saved is what is printed, followed by ``Do: ...``
    when an option addresses it (:func:`._answer.advice_for`)."""
    for text in document.get("warnings") or []:
        advice = advice_for(str(text))
        warn(str(text) + ("" if advice is None else f" Do: {advice}."))


def print_result(report: dict, args: argparse.Namespace | None = None) -> None:
    """The run's answer on stdout, first: how much better than the nominal model, the
    verdict, the errors per joint, the flagged parameters (:func:`._answer.answer_text`;
    with ``--verbose`` the full rendering, :func:`manip_id.identification.result_text`).
    The warnings go to stderr (:func:`print_warnings`)."""

    print(answer_text(report, verbose=bool(getattr(args, "verbose", False))))


def note_exports(args: argparse.Namespace, report: dict) -> None:
    """Record in the document the files ``--export-urdf`` / ``--export-mjcf`` write (the
    report links them)."""
    if not exports_wanted(args):
        return
    report["exported"] = {}
    if getattr(args, "export_urdf", None):
        report["exported"]["URDF"] = str(args.export_urdf)
        report["exported"]["sidecar (armature, offsets)"] = str(sidecar_path(args.export_urdf))
    if getattr(args, "export_mjcf", None):
        report["exported"]["MJCF"] = str(args.export_mjcf)
        report["exported"]["MJCF sidecar"] = str(sidecar_path(args.export_mjcf))


def write_outputs(args: argparse.Namespace, outputs, robot, result, report: dict, samples) -> int:
    """Print the warnings of ``report``, stage ``--json``, ``--report`` (``samples``: what it
    draws) and ``--export-urdf``, then publish them all together (:func:`finish`); the exit
    status (0)."""
    print_warnings(report)
    note_exports(args, report)
    if args.json:
        outputs.write_json(args.json, report)
    path = None
    if args.report is not None:
        path = identify_report("write_identify_report")(
            args.report_claim,
            robot,
            result,
            report,
            samples,
            options=report_options(args, rollout=getattr(result, "rollout", None)),
        )
    if exports_wanted(args):
        stage_export(robot, result, args, outputs)
    return finish(args, outputs, path)
