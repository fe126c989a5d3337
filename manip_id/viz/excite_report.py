"""The report folder of ``manip-id excite --report DIR``: a dry run to look at before the run.

Drawn from the :class:`~manip_id.trajectories.ExcitationDesign` alone (its
:meth:`~manip_id.trajectories.ExcitationDesign.to_dict` is ``result.json``). Answers first:

- *Does it stay within the limits?* per joint and limit kind the peak use of the allowed
  range [%] (100 % = the limit less the ``--margin``), the table of ``limit_usage``;
- *How close does it come to the robot itself and to the world?* the least clearance [m],
  between which link geometries (or a link and a ``--world`` object), at what time, against
  the clearance asked for;
- *How informative is it?* the criterion against the median of the random starts (same
  limits), the condition number, the predicted relative std of each base parameter;
- with ``--from``: *What does it add to the earlier data?* the poorly identified base
  parameters of the result, their relative std before and after (predicted).

The scene animates the designed motion with the ``--world`` objects and marks the closest
approach (the witness points on both members, at its time: ``scene.html#t=<time>``).
"""

from __future__ import annotations

import html
import math
from pathlib import Path

import meshcat.geometry as mg
import numpy as np
import pinocchio as pin

from ..trajectories.design import POOR
from ..trajectories.fourier import trajectory_to_configuration
from ..trajectories.verify import KINDS
from .excite_figures import limit_usage_figure, motion_figure, std_figure
from .link_colors import css_color, hex_color
from .meshcat_scene import RobotScene
from .report import SCENE, ReportContent, html_table, write_report
from .report_tables import number
from .scene_page import LegendSection

#: Colours of the world objects and of the closest-approach marker (RGBA).
WORLD_COLOR, MARK_COLOR = (0.55, 0.45, 0.30, 0.45), (0.85, 0.10, 0.10, 1.0)
#: Side of the square drawn for a ``[[plane]]`` [m] (the plane itself is unbounded).
PLANE_SIDE = 2.0
#: Radius of the spheres that mark the closest points [m].
MARK_RADIUS = 0.02
#: Animation frames per second of the scene.
FPS = 25.0


def _esc(x) -> str:
    return html.escape(str(x))


def _pct(x) -> str:
    return "n/a" if x is None or not np.isfinite(x) else f"{100 * float(x):.3g} %"


def usage_rows(design) -> list[dict]:
    """Per joint, the peak use of each limit [% of the allowed range]; "no limit" if unset."""
    rows = []
    for j, name in enumerate(design.joint_names):
        row: dict = {"joint": name}
        worst = 0.0
        for kind in KINDS:
            u = float(design.check.usage[kind][j])
            row[f"{kind} [%]"] = "no limit" if not np.isfinite(u) else number(100 * u, 3)
            worst = max(worst, u if np.isfinite(u) else 0.0)
        row["_class"] = "bad" if worst > 1 + 1e-9 else ("warn" if worst > 0.95 else "")
        rows.append(row)
    return rows


def _limits_answer(design) -> tuple[str, str]:
    use = design.check.max_usage()
    worst = max((v for v in use.values() if v is not None), default=0.0)
    parts = []
    for kind in KINDS:
        u = design.check.usage[kind]
        if not np.isfinite(u).any():
            parts.append(f"{kind}: no limit")
            continue
        j = int(np.nanargmax(u))
        parts.append(f"{kind} {_pct(u[j])} ({_esc(design.joint_names[j])})")
    word = (
        '<span class="yes">Within every limit</span>'
        if worst <= 1 + 1e-9
        else '<span class="no">A limit is exceeded</span>'
    )
    head = (
        f'<p class="verdict">{word} at every sample of the run ({design.rate:g} Hz), with the '
        f"{100 * design.options.margin:g} % margin. Peak use of the allowed range: "
        + "; ".join(parts)
        + ".</p>"
    )
    return "Does it stay within the limits?", head + html_table(usage_rows(design))


def _clearance_answer(design) -> tuple[str, str]:
    c = design.check
    if c.closest_pair is None or not math.isfinite(c.min_clearance):
        return (
            "How close does it come to itself and to the world?",
            "<p>No clearance was checked (no collision geometry, or self-collision off and no "
            "--world).</p>",
        )
    a, b = c.closest_pair
    need = design.options.clearance
    ok = c.min_clearance >= need
    word = '<span class="yes">clear</span>' if ok else '<span class="no">too close</span>'
    text = (
        f'<p class="verdict">Least clearance <b>{number(c.min_clearance, 3)} m</b> between '
        f"<b>{_esc(a)}</b> and <b>{_esc(b)}</b> at t = {c.closest_time:.3f} s ({word}: "
        f"{number(need, 3)} m asked for, plus up to {number(c.clearance_allowance, 3)} m for "
        f'the motion between samples). <a href="{SCENE}#t={c.closest_time:.3f}">Open the '
        "scene at that time</a> (the closest points are marked in red).</p>"
    )
    objects = [] if design.world is None else list(design.world.objects)
    if objects:
        text += (
            "<p>World: "
            + ", ".join(f"{_esc(o.name)} ({_esc(_describe(o))})" for o in objects)
            + ".</p>"
        )
    return "How close does it come to itself and to the world?", text


def _information_answer(design) -> tuple[str, str]:
    rel = design.predicted_relative_std
    finite = rel[np.isfinite(rel)]
    gmean = float(np.exp(np.mean(np.log(finite)))) if finite.size else float("nan")
    poor = [p for p in design.poorly_identified(POOR) if p[1] > POOR]  # after the run
    better = design.criterion < design.criterion_random
    text = (
        f'<p class="verdict">Criterion {_esc(design.criterion_kind)} = '
        f"<b>{number(design.criterion, 5)}</b> against {number(design.criterion_random, 5)}, "
        "the median of the random starts within the same limits (lower is better: "
        + ('<span class="yes">better</span>' if better else '<span class="no">not better</span>')
        + "); condition number of the new motion's information "
        f"{number(design.condition_number, 3)}.</p>"
        f"<p>Predicted relative std of the {rel.size} base parameters (geometric mean "
        f"{_pct(gmean)}); {len(poor)} above {100 * POOR:g} %"
        + (": " + ", ".join(_esc(n) for n, _, _ in poor[:12]) if poor else "")
        + (" ..." if len(poor) > 12 else "")
        + " (the figure and the parameter table below).</p>"
    )
    return "How informative is it?", text


def _sequential_answer(design, source: str) -> tuple[str, str]:
    rows = [
        {
            "parameter": name,
            "before [%]": number(100 * before, 3) if before is not None else "n/a",
            "after, predicted [%]": number(100 * after, 3),
            "after / before": number(after / before, 3) if before else "n/a",
            "_class": "warn" if after > POOR else "",
        }
        for name, after, before in design.poorly_identified(POOR)
    ]
    text = (
        f"<p>The base parameters that {_esc(source)} leaves above {100 * POOR:g} % relative std, "
        "or that stay above it with this motion added (predicted for the combined data):</p>"
    )
    return "What does it add to the earlier data?", text + html_table(rows, "(none)")


def parameter_rows(design) -> list[dict]:
    """Per base parameter: the value the relative std is taken against, the predicted std
    and relative std [%] (and before, with a prior)."""
    rel, prior = design.predicted_relative_std, design.prior_relative_std
    rows = []
    for i, name in enumerate(design.base_names):
        row: dict = {
            "name": name,
            "value": number(design.reference[i]),
            "predicted std": number(design.predicted_std[i], 3),
        }
        if prior is not None:
            row["relative std before [%]"] = _pct(prior[i]).removesuffix(" %")
        row["predicted relative std [%]"] = _pct(rel[i]).removesuffix(" %")
        row["_class"] = "warn" if np.isfinite(rel[i]) and rel[i] > POOR else ""
        rows.append(row)
    return rows


def _describe(obj) -> str:
    d = obj.dims
    if obj.kind == "plane":
        return f"normal ({d[0]:g}, {d[1]:g}, {d[2]:g}), offset {d[3]:g} m"
    at = "(" + ", ".join(f"{v:g}" for v in obj.position) + ") m"
    if obj.kind == "box":
        return f"box {d[0]:g} x {d[1]:g} x {d[2]:g} m at {at}"
    if obj.kind == "sphere":
        return f"sphere of radius {d[0]:g} m at {at}"
    return f"cylinder of radius {d[0]:g} m, length {d[1]:g} m at {at}"


def _object_geometry(obj):
    """A world object as meshcat geometry and its placement (4x4, base frame)."""
    if obj.kind == "plane":
        n = np.asarray(obj.dims[:3], dtype=float)
        unit = n / np.linalg.norm(n)
        z = np.array([0.0, 0.0, 1.0])
        R = pin.Quaternion.FromTwoVectors(z, unit).matrix()
        thick = 0.004  # [m]: drawn just below the free side
        T = pin.SE3(R, unit * (obj.dims[3] / np.linalg.norm(n)) - unit * thick / 2).homogeneous
        return mg.Box([PLANE_SIDE, PLANE_SIDE, thick]), T
    T = obj.placement().homogeneous
    if obj.kind == "box":
        return mg.Box(list(obj.dims)), T
    if obj.kind == "sphere":
        return mg.Sphere(obj.dims[0]), T
    turn = np.eye(4)  # meshcat cylinders lie along y, coal's along z
    turn[:3, :3] = pin.rpy.rpyToMatrix(math.pi / 2, 0.0, 0.0)
    return mg.Cylinder(obj.dims[1], obj.dims[0]), T @ turn


def excite_scene(robot, design, title: str) -> RobotScene:
    """The designed motion animated, the world objects, the closest approach marked."""
    t, angles, _, _ = design.samples(min(design.rate, 2 * FPS))
    scene = RobotScene(robot, title=title)
    scene.animate(t, trajectory_to_configuration(robot, angles), fps=FPS)
    objects = [] if design.world is None else list(design.world.objects)
    swatch = f'<span class="sw" style="background:{css_color(WORLD_COLOR)}"></span>'
    lines = [f"{swatch} {_esc(o.name)}: {_esc(_describe(o))}" for o in objects]
    material = mg.MeshLambertMaterial(
        color=hex_color(WORLD_COLOR), opacity=WORLD_COLOR[3], transparent=True
    )
    for k, obj in enumerate(objects):
        geometry, T = _object_geometry(obj)
        last = k == len(objects) - 1  # the legend once, with every object
        legend = LegendSection("world (--world)", lines) if last else None
        scene.add_object(obj.name, geometry, material, T, legend)
    corners = [_object_corners(o) for o in objects if o.kind != "plane"]  # planes: unbounded
    if corners:
        scene.frame_points(np.vstack(corners))  # the camera frames the objects too
    _mark_closest(scene, design.check)
    return scene


def _object_corners(obj) -> np.ndarray:
    """The corners of a bounded world object's box, base frame [m], shape (8, 3)."""
    d = obj.dims
    half = {
        "box": 0.5 * np.asarray(d[:3], dtype=float),
        "sphere": np.full(3, float(d[0])),
        "cylinder": np.array([d[0], d[0], 0.5 * d[1]], dtype=float),  # coal: along z
    }[obj.kind]
    signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)])
    T = obj.placement()
    return (signs * half) @ T.rotation.T + T.translation


def _mark_closest(scene: RobotScene, c) -> None:
    """Red spheres at the witness points of the closest approach and a rod across the gap."""
    if c.closest_points is None or c.closest_pair is None:
        return
    mark = mg.MeshBasicMaterial(color=hex_color(MARK_COLOR))
    p1, p2 = (np.asarray(p, dtype=float) for p in c.closest_points)
    swatch = f'<span class="sw" style="background:{css_color(MARK_COLOR)}"></span>'
    legend = LegendSection(
        "closest approach",
        [
            f"{swatch} {number(c.min_clearance, 3)} m, {_esc(c.closest_pair[0])} / "
            f"{_esc(c.closest_pair[1])}",
            f"at t = {c.closest_time:.3f} s, in red (add #t={c.closest_time:.3f} to the "
            "page's address to open it there)",
        ],
    )
    for k, p in enumerate((p1, p2)):
        T = pin.SE3(np.eye(3), p).homogeneous
        scene.add_object(
            f"closest/point{k}", mg.Sphere(MARK_RADIUS), mark, T, legend if k else None
        )
    gap = float(np.linalg.norm(p2 - p1))
    if gap > 1e-6:  # the gap as a rod (meshcat cylinders lie along y)
        y = np.array([0.0, 1.0, 0.0])
        R = pin.Quaternion.FromTwoVectors(y, (p2 - p1) / gap).matrix()
        T = pin.SE3(R, 0.5 * (p1 + p2)).homogeneous
        scene.add_object("closest/gap", mg.Cylinder(gap, 0.4 * MARK_RADIUS), mark, T)


def write_excite_report(folder, robot, design, doc: dict, *, source=None, force=False) -> Path:
    """The report folder of an excitation design; returns its path.

    folder: a claimed :class:`~manip_id._io.ReportFolder` (or a path); design: the
    :class:`~manip_id.trajectories.ExcitationDesign`; doc: the command's JSON (written as
    result.json); source: the ``--from`` result file, or None.
    """
    title = (
        f"manip-id excite {robot.name}: {design.duration:g} s, "
        f"{design.trajectory.harmonics} harmonics, criterion {design.criterion_kind}"
    )
    notes: list[str] = []
    try:
        scene = excite_scene(robot, design, title)
        notes += list(scene.notes)
    except Exception as exc:  # a picture never fails the finished design
        scene = None
        notes.append(f"3-D scene not drawn: {type(exc).__name__}: {exc}")
    questions = [_limits_answer(design), _clearance_answer(design), _information_answer(design)]
    if design.prior_std is not None:
        questions.append(_sequential_answer(design, source or "the result"))
    figures = {
        "limit_usage": lambda path: limit_usage_figure(path, design),
        "motion": lambda path: motion_figure(path, design, robot),
        "predicted_std": lambda path: std_figure(path, design, POOR),
    }
    content = ReportContent(
        title=title,
        summary=_summary(robot, design, source),
        parameter_table=parameter_rows(design),
        figures=figures,
        scene=scene,
        json_result=doc,
        notes=notes,
        questions=questions,
    )
    return write_report(folder, content, force=force)


def _summary(robot, design, source) -> dict:
    c = design.check
    out = {
        "robot": robot.name,
        "duration [s]": design.duration,
        "harmonics": design.trajectory.harmonics,
        "base frequency [Hz]": design.trajectory.wf / (2 * math.pi),
        "rate [Hz]": design.rate,
        f"criterion {design.criterion_kind}": design.criterion,
        "criterion, median of the random starts": design.criterion_random,
        "condition number": design.condition_number,
        "least clearance [m]": c.min_clearance if math.isfinite(c.min_clearance) else None,
        "clearance asked for [m]": design.options.clearance,
        "margin": design.options.margin,
        "world objects": 0 if design.world is None else len(design.world.objects),
        "design time [s]": design.design_time,
    }
    if source is not None:
        out["designed to add to"] = str(source)
    return out
