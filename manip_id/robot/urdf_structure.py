"""The structure of a URDF checked at load, before Pinocchio reads it.

Pinocchio's URDF reader accepts some descriptions that are no robot and says nothing:
a link that is the child of two joints loses one of them (the model then holds fewer
joints than the file, and parameter names repeat), a joint axis ``0 0 0`` has no
direction, inverted limits make every configuration infeasible. :func:`check_urdf_structure`
refuses each with one line naming the joint or link:

- every link is the child of at most one joint;
- every joint axis is three finite numbers, not all zero;
- every limit of a revolute or prismatic joint is finite where given, ``lower <= upper``,
  and ``velocity`` and ``effort`` are >= 0;
- every link's mass and inertia entries are finite and within :data:`MAX_INERTIAL`;
- the robot's size is within :data:`MAX_JOINTS` movable joints, :data:`MAX_LINKS` links and
  :data:`MAX_GEOMETRIES` visual and collision elements, counted in the text before
  Pinocchio builds a model and its data (a 1000-joint file took 23 GB and 44 s to build).

``<mimic>`` joints (:func:`mimic_joints`) are read here and refused by
:func:`check_no_active_mimic` when one end of the pair moves in a URDF given by path:
manip-id models every joint as independent, so simulating, identifying or exporting a
mimicking joint would silently break its constraint. Lock both joints (a profile's or
``--joints``), or remove the element. A robot of example-robot-data keeps its independent
joints (baxter's grippers: 19 joints), with a warning.

Inertias are not structure beyond their magnitude: ``manip-id view`` needs none, and the
commands that use them check them (a negative mass in a simulated URDF is refused by the
simulation's check of the nominal parameters; ``manip-id repair`` takes it as a sign slip,
on the URDF's own values: :func:`negative_mass_inertials`).
"""

from __future__ import annotations

import math
import warnings
import xml.etree.ElementTree as ET

from .._io.reading import read_text
from ..errors import RobotError, RobotWarning

#: The most movable (not fixed) joints of a URDF: beyond it the per-sample regressor is
#: out of reach anyway (:data:`manip_id.resources.REGRESSOR_BUFFER_LIMIT`, some 300 joints).
MAX_JOINTS = 300
#: The most links of a URDF.
MAX_LINKS = 2000
#: The most ``<visual>`` plus ``<collision>`` elements of a URDF.
MAX_GEOMETRIES = 20_000


def _check_size(root: ET.Element, where: str) -> None:
    """Refuse a robot larger than the bounds above, from the parsed text alone."""
    movable = sum(
        1
        for j in root.iter("joint")
        if j.find("child") is not None and j.get("type") not in ("fixed", None)
    )
    counts = {
        "movable joints": (movable, MAX_JOINTS),
        "links": (sum(1 for _ in root.iter("link")), MAX_LINKS),
        "visual and collision elements": (
            sum(1 for _ in root.iter("visual")) + sum(1 for _ in root.iter("collision")),
            MAX_GEOMETRIES,
        ),
    }
    for what, (n, limit) in counts.items():
        if n > limit:
            raise RobotError(
                f"{where} has {n} {what}, above manip-id's limit of {limit}: split the robot "
                "or remove what it does not need (checked before the model is built)"
            )


#: The largest magnitude of a link's mass [kg] and inertia entries [kg m^2]: beyond it the
#: number is no robot's (1e300 kg overflows every torque to inf).
MAX_INERTIAL = 1e6


def _check_inertial(link: ET.Element, where: str) -> None:
    """Refuse a link whose mass or inertia is beyond :data:`MAX_INERTIAL` (or not finite)."""
    inertial = link.find("inertial")
    if inertial is None:
        return
    name = link.get("name")
    items: list[tuple[str, ET.Element | None, tuple[str, ...]]] = [
        ("mass", inertial.find("mass"), ("value",)),
        ("inertia", inertial.find("inertia"), ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")),
    ]
    for what, el, keys in items:
        if el is None:
            continue
        for key in keys:
            text = el.get(key)
            value = _numbers(text, 1, f"{where}: the {what} {key} of link {name!r}")
            if value is not None and abs(value[0]) > MAX_INERTIAL:
                raise RobotError(
                    f"{where}: link {name!r} has {what} {key}={value[0]:g}, beyond manip-id's "
                    f"bound of {MAX_INERTIAL:g} [kg or kg m^2]: check the URDF's units"
                )


def negative_mass_inertials(path) -> dict[str, tuple[float, list[float], list[float], list[float]]]:
    """``{link: (mass, xyz, rpy, [ixx, ixy, ixz, iyy, iyz, izz])}`` of every link's
    ``<inertial>`` when some link of the URDF has a negative mass, else ``{}``.

    Pinocchio cannot hold such a link: adding a body of negative total mass to a joint
    clamps the mass in the division for the centre of mass (``c = m c / max(m, eps)``), so
    its model holds a CoM of some 1e30 m. :func:`~manip_id.robot.sources.load_urdf` rebuilds
    the inertias of those joints from these values (the 10 standard parameters are linear
    in each link's, no division), so that :mod:`manip_id.physics.repair` sees the URDF's
    own body and can take its mass as a sign slip.
    """
    try:
        root = ET.fromstring(read_text(path, "URDF", "urdf", error=RobotError))
    except ET.ParseError:
        return {}
    out: dict[str, tuple[float, list[float], list[float], list[float]]] = {}
    negative = False
    for link in root.iter("link"):
        inertial = link.find("inertial")
        if inertial is None:
            continue
        mass_el = inertial.find("mass")
        mass = _numbers(None if mass_el is None else mass_el.get("value"), 1, "mass")
        origin = inertial.find("origin")
        xyz = _numbers(None if origin is None else origin.get("xyz"), 3, "xyz")
        rpy = _numbers(None if origin is None else origin.get("rpy"), 3, "rpy")
        el = inertial.find("inertia")
        keys = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
        entries = [_numbers(None if el is None else el.get(k), 1, k) for k in keys]
        m = mass[0] if mass else 0.0
        negative = negative or m < 0
        out[str(link.get("name"))] = (
            m, xyz or [0.0] * 3, rpy or [0.0] * 3, [e[0] if e else 0.0 for e in entries]
        )  # fmt: skip
    return out if negative else {}


def mimic_joints(path) -> dict[str, str]:
    """``{joint: the joint it mimics}`` of the ``<mimic>`` elements of a URDF file.

    ``{}`` for a file that is not URDF XML (its reader reports that).
    """
    text = read_text(path, "URDF", "urdf", error=RobotError)
    try:
        root = ET.fromstring(text)
    except ET.ParseError:
        return {}
    out = {}
    for joint in root.iter("joint"):
        mimic = joint.find("mimic")
        if mimic is not None and joint.get("name"):
            out[str(joint.get("name"))] = str(mimic.get("joint"))
    return out


def check_no_active_mimic(path, robot: str, active: list[str], *, refuse: bool = True) -> None:
    """Refuse ``active`` joints that take part in a ``<mimic>`` pair of the URDF ``path``.

    With ``refuse=False`` (a robot of example-robot-data, whose model has always been used
    with independent joints, e.g. baxter's grippers) a :class:`~manip_id.errors.RobotWarning`
    says so instead.
    """
    moving = set(active)
    for follower, leader in mimic_joints(path).items():
        if follower not in moving and leader not in moving:
            continue
        what = f"robot {robot}: joint {follower!r} mimics {leader!r} (<mimic> in {path})"
        if refuse:
            raise RobotError(
                f"{what}, a constraint manip-id does not model: it would simulate, identify "
                "and export them as independent joints; lock both (choose the active joints "
                "without them) or remove the <mimic> element"
            )
        warnings.warn(
            f"{what}: modelled as two independent joints (the constraint is not enforced)",
            RobotWarning,
            stacklevel=3,
        )


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
    _check_size(root, str(path))
    for link in root.iter("link"):
        _check_inertial(link, str(path))
    parents: dict[str, str] = {}
    for joint in root.iter("joint"):
        if joint.find("child") is not None:  # a transmission's <joint> has no child
            _check_joint(joint, str(path), parents)
