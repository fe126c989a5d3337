"""What the commands share once they run: the robot, the library's option objects, the
result printed, the outputs staged and published.

The command modules declare their options with :mod:`._common` (light: ``manip-id
--help`` builds every parser from it); this module loads Pinocchio and the
identification, and is imported by the modules that run the commands.
"""

from __future__ import annotations

import argparse

from .._native import native_stderr_captured
from ..datasets.stream import torque_scale_vector
from ..errors import InputError, did_you_mean
from ..execution import parse_scheduler
from ..export import export_texts, sidecar_path
from ..identification import ConsistentOptions, PreprocessOptions, result_text
from ..robot import Robot, load_robot
from ..viz.identify_report import write_identify_report
from ..viz.report_document import ReportOptions
from ._common import finish, parse_floats, print_warnings, profile_option


def robot_from_args(args: argparse.Namespace) -> Robot:
    """Load the robot named by :func:`add_robot_arguments` options."""

    joints = [j for j in args.joints.split(",") if j] if getattr(args, "joints", None) else None
    with native_stderr_captured("urdfdom"):  # its C++ messages become one warning line
        return load_robot(
            args.robot,
            armature=args.armature,
            friction=args.friction,
            spring=args.spring,
            active_joints=joints,
            package_dirs=args.package_dir,
            profile=profile_option(args),
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
        parse_scheduler(args.scheduler)


def preprocess_options(args: argparse.Namespace, nv: int, profile_scale=None):
    """The :class:`~manip_id.identification.PreprocessOptions` of identify's data-file options.

    ``--torque-scale`` (one gain or one per joint), else the profile's [data] torque_scale.
    """

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


def consistent_kwargs(args: argparse.Namespace) -> dict:
    """The physically consistent estimation options of identify, as keyword arguments."""

    return dict(
        consistent=ConsistentOptions(
            enabled=args.consistent,
            solver=args.solver,
            prior=args.prior,
            prior_weight=args.prior_weight,
        )
    )


def stage_export(robot, result, args: argparse.Namespace, outputs) -> None:
    """Stage the exported URDF and its sidecar (published with the other outputs)."""

    texts = export_texts(robot, result.standard.values, args.export_urdf)
    outputs.write_text(args.export_urdf, texts.urdf)
    outputs.write_json(sidecar_path(args.export_urdf), texts.sidecar)


def report_options(args: argparse.Namespace, source: str | None = None):
    """The :class:`~manip_id.viz.report_document.ReportOptions` of identify's options."""

    if source is None:
        source = "simulated" if args.simulate else ", ".join(map(str, args.data))
    return ReportOptions(
        source=source,
        simulated=bool(args.simulate),
        chunk=args.chunk,
        scene_assets=getattr(args, "scene_assets", "inline"),
        force=args.force,
    )


def print_result(report: dict) -> None:
    """The run's result on stdout: the one text rendering of its document
    (:func:`manip_id.identification.result_text`; the warnings go to stderr,
    :func:`print_warnings`), then a simulation's base-parameter error against its truth."""

    print(result_text({**report, "warnings": []}))
    if report.get("parameter_error") is not None:
        worst = report.get("parameter_error_in_std")
        print(
            f"base parameter error vs truth: {100 * report['parameter_error']:.3f} %"
            + ("" if worst is None else f" (max {worst:.2f} std)")
        )


def note_exports(args: argparse.Namespace, report: dict) -> None:
    """Record in the document the files ``--export-urdf`` writes (the report links them)."""
    if getattr(args, "export_urdf", None):
        report["exported"] = {
            "URDF": str(args.export_urdf),
            "sidecar (armature, offsets)": str(sidecar_path(args.export_urdf)),
        }


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
        path = write_identify_report(
            args.report_claim, robot, result, report, samples, options=report_options(args)
        )
    if args.export_urdf:
        stage_export(robot, result, args, outputs)
    return finish(args, outputs, path)
