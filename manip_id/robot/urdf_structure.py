"""The structure of a URDF checked at load, before Pinocchio reads it.

Pinocchio's URDF reader accepts some descriptions that are no robot and says nothing:
a link that is the child of two joints loses one of them (the model then holds fewer
joints than the file, and parameter names repeat), a joint axis ``0 0 0`` has no
direction, inverted limits make every configuration infeasible. :func:`check_urdf_structure`
refuses each with one line naming the joint or link:

- every link is the child of at most one joint;
- every joint axis is three finite numbers, not all zero;
- every limit of a revolute or prismatic joint is finite where given, ``lower <= upper``,
  and ``velocity`` and ``effort`` are >= 0.

Inertias are not structure: ``manip-id view`` needs none, and the commands that use them
check them (a negative mass in a simulated URDF is refused by the simulation's check of
the nominal parameters).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

from .._io.reading import read_text
from ..errors import RobotError


def _numbers(text: str | None, count: int, where: str) -> list[float] | None:
    if text is None:
        return None
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        return None  # not a number: the URDF reader names it
    if len(values) != count:
        return None
    if not all(math.isfinite(v) for v in values):
        raise RobotError(f"{where} must be {count} finite numbers, got {text!r}")
    return values


def _check_joint(joint: ET.Element, where: str, parents: dict[str, str]) -> None:
    name = joint.get("name", "?")
    child = joint.find("child")
    link = child.get("link") if child is not None else None
    if link is not None:
        if link in parents:
            raise RobotError(
                f"{where}: link {link!r} is the child of two joints, {parents[link]!r} and "
                f"{name!r} (each link has one parent joint)"
            )
        parents[link] = name
    axis = joint.find("axis")
    if axis is not None and joint.get("type") not in ("fixed", "floating", "planar"):
        xyz = _numbers(axis.get("xyz"), 3, f"{where}: the axis of joint {name!r}")
        if xyz is not None and not any(xyz):
            raise RobotError(f"{where}: the axis of joint {name!r} is 0 0 0 (no direction)")
    limit = joint.find("limit")
    if limit is None or joint.get("type") not in ("revolute", "prismatic"):
        return
    bounds: dict[str, float | None] = {}
    for key in ("lower", "upper", "velocity", "effort"):
        value = _numbers(limit.get(key), 1, f"{where}: the {key} limit of joint {name!r}")
        bounds[key] = None if value is None else value[0]
    lo, hi = bounds["lower"], bounds["upper"]
    if lo is not None and hi is not None and lo > hi:
        raise RobotError(f"{where}: joint {name!r} has lower limit {lo:g} > upper limit {hi:g}")
    for key in ("velocity", "effort"):
        bound = bounds[key]
        if bound is not None and bound < 0:
            raise RobotError(f"{where}: joint {name!r} has a negative {key} limit {bound:g}")


def check_urdf_structure(path) -> None:
    """Refuse a URDF file whose structure Pinocchio would read wrongly (module docstring).

    Raises :class:`~manip_id.errors.RobotError` naming the file and the joint or link;
    the file is read through :func:`manip_id._io.reading.read_text` (a regular file within
    the URDF budget). XML syntax errors are left to Pinocchio's reader, which names them.
    """
    text = read_text(path, "URDF", "urdf", error=RobotError)
    try:
        root = ET.fromstring(text)
    except ET.ParseError:
        return  # the URDF reader reports the syntax error
    if root.tag != "robot":
        return
    parents: dict[str, str] = {}
    for joint in root.iter("joint"):
        if joint.find("child") is not None:  # a transmission's <joint> has no child
            _check_joint(joint, str(path), parents)
