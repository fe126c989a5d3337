"""The identified model as MuJoCo MJCF: inertias, armature, damping, friction loss, meshes.

:func:`export_mjcf` writes the robot of :func:`~manip_id.export.urdf.export_urdf` (the
same links and composites, every joint of the URDF free again) as an MJCF file:

- one ``<body>`` per joint of the unreduced Pinocchio model of that URDF, placed by the
  joint placement (``pos``, ``quat`` = ``w x y z``); links on fixed joints are merged into
  it as Pinocchio merges them;
- its ``<inertial pos mass fullinertia>``: mass [kg], centre of mass [m] and inertia about
  it ``Ixx Iyy Izz Ixy Ixz Iyz`` [kg m^2] in the body frame;
- its ``<joint>``: ``hinge`` or ``slide`` along the joint's motion axis, ``range`` from the
  position limits, ``armature`` = ``Ia`` [kg m^2], ``damping`` = ``fv`` [N m s/rad],
  ``frictionloss`` = ``fc`` [N m], ``stiffness`` = ``k`` [N m/rad] (``springref`` 0) for
  the identified joints; the URDF's own values for the others;
- a ``<motor>`` per identified joint (``ctrl`` = joint torque, ``ctrlrange`` the effort
  limit when the URDF sets one), for a controller to drive the model;
- the ``<visual>`` (group 1, no contact) and ``<collision>`` (group 3, hidden by
  MuJoCo's viewer; group 0, shown, for a link whose visual was left out) geometry of the
  links: boxes, cylinders, spheres and meshes MuJoCo reads (STL, OBJ, MSH; others,
  e.g. COLLADA, are left out and listed), by absolute path.

MuJoCo's inverse dynamics of the file (``mj_inverse`` with contacts, limits and friction
loss disabled) is then ``M(q) ddq + C(q, dq) dq + g(q) + Ia ddq + fv dq + k q`` of the
identified parameters; the Coulomb ``fc sign(dq)`` is MuJoCo's friction-loss constraint,
a soft constraint that equals it in steady sliding (``qacc = 0``) and mixes in the
acceleration otherwise. A continuous joint (``cos, sin`` in Pinocchio) is a hinge without
range (its angle in MuJoCo). The offset ``fo`` has no MJCF field: it is in the sidecar.

Nothing here imports ``mujoco``: the text is written by hand and MuJoCo is only needed to
load it (the optional extra ``manip_id[mujoco]``).
"""

from __future__ import annotations

import warnings
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from .._io import atomic_write_text, json_text
from ..errors import ExportWarning, RobotError
from ..robot.parameters import bounded_range, bounded_rate
from .links import Composite, urdf_floats
from .sidecar import sidecar_path
from .urdf import (
    ExportedTree,
    ExportResult,
    body_check,
    check_output,
    checked_theta,
    exported_sidecar,
    exported_tree,
)

#: Mesh file formats MuJoCo reads.
MUJOCO_MESH_FORMATS: tuple[str, ...] = (".stl", ".obj", ".msh")
_HINGE_ATOL = 1e-12


def _vec(v) -> str:
    return " ".join(repr(float(x)) for x in np.asarray(v, dtype=float).ravel())


def _quat(R: np.ndarray) -> str:
    x, y, z, w = pin.Quaternion(np.asarray(R)).coeffs()
    return _vec([w, x, y, z])


def _origin(el: ET.Element) -> pin.SE3:
    origin = el.find("origin")
    xyz = urdf_floats(None if origin is None else origin.get("xyz"), 3)
    rpy = urdf_floats(None if origin is None else origin.get("rpy"), 3)
    return pin.SE3(pin.rpy.rpyToMatrix(*rpy), xyz)


@dataclass
class _Assets:
    """Mesh assets by (file, scale) and the meshes left out."""

    meshes: dict[tuple[str, str], str]
    skipped: list[str]

    def mesh(self, filename: str, scale: str) -> str | None:
        path = Path(filename)
        readable = path.is_absolute() and path.is_file()  # MuJoCo refuses a missing mesh
        if path.suffix.lower() not in MUJOCO_MESH_FORMATS or not readable:
            if filename not in self.skipped:
                self.skipped.append(filename)
            return None
        key = (str(path), scale)
        if key not in self.meshes:
            self.meshes[key] = f"mesh{len(self.meshes)}"
        return self.meshes[key]


def _geom(kind: str, el: ET.Element, placement: pin.SE3, assets: _Assets) -> ET.Element | None:
    """The MJCF ``<geom>`` of a URDF ``<visual>`` or ``<collision>`` (None: left out)."""
    shape = el.find("geometry")
    if shape is None or len(shape) == 0:
        return None
    g = shape[0]
    attrs: dict[str, str] = {}
    if g.tag == "mesh":
        name = assets.mesh(str(g.get("filename", "")), g.get("scale", "1 1 1"))
        if name is None:
            return None
        attrs = {"type": "mesh", "mesh": name}
    elif g.tag == "box":
        attrs = {"type": "box", "size": _vec(0.5 * urdf_floats(g.get("size"), 3))}
    elif g.tag == "cylinder":
        r, length = float(g.get("radius", 0)), float(g.get("length", 0))
        attrs = {"type": "cylinder", "size": _vec([r, 0.5 * length])}
    elif g.tag == "sphere":
        attrs = {"type": "sphere", "size": _vec([float(g.get("radius", 0))])}
    else:
        return None
    pose = placement * _origin(el)
    attrs.update(pos=_vec(pose.translation), quat=_quat(pose.rotation))
    if kind == "visual":
        attrs.update(group="1", contype="0", conaffinity="0")
    else:
        attrs.update(group="3")
    return ET.Element("geom", attrs)


def _joint_terms(robot, theta: np.ndarray, model: pin.Model, i: int) -> dict[str, float]:
    """Armature, damping, friction loss and stiffness of joint ``i`` of the exported model."""
    name = model.names[i]
    values = dict(zip(robot.parameter_names, theta, strict=True))
    if name in robot.dof_names:
        return {t: float(values.get(f"{name}.{t}", 0.0)) for t in ("Ia", "fv", "fc", "k")}
    full = robot.full_model
    v = full.joints[full.getJointId(name)].idx_v
    return {
        "Ia": float(full.armature[v]),
        "fv": float(full.damping[v]),
        "fc": float(full.friction[v]),
        "k": 0.0,
    }


def _joint(robot, theta: np.ndarray, model: pin.Model, i: int) -> ET.Element:
    jm = model.joints[i]
    if jm.nv != 1:
        raise RobotError(f"joint {model.names[i]!r} ({jm.shortname()}) has no MJCF counterpart")
    jd = jm.createData()
    jm.calc(jd, pin.neutral(model))
    S = np.asarray(jd.S).ravel()  # [linear; angular] motion subspace
    hinge = np.linalg.norm(S[3:]) > _HINGE_ATOL
    axis = S[3:] if hinge else S[:3]
    terms = _joint_terms(robot, theta, model, i)
    attrs = {
        "name": model.names[i],
        "type": "hinge" if hinge else "slide",
        "axis": _vec(axis / np.linalg.norm(axis)),
        "armature": repr(terms["Ia"]),
        "damping": repr(terms["fv"]),
        "frictionloss": repr(terms["fc"]),
    }
    if terms["k"]:
        attrs.update(stiffness=repr(terms["k"]), springref="0")
    lo, hi = model.lowerPositionLimit[jm.idx_q], model.upperPositionLimit[jm.idx_q]
    if jm.nq == 1 and bool(bounded_range(np.array([lo]), np.array([hi]))[0]):
        attrs["range"] = _vec([lo, hi])
    return ET.Element("joint", attrs)


def _motors(robot) -> ET.Element:
    """One ``<motor>`` per identified joint: ``ctrl`` is the joint torque [N m or N]
    (``gear`` 1), limited to the URDF's effort limit when it is set."""
    actuator = ET.Element("actuator")
    effort = robot.effort_limit
    bounded = bounded_rate(effort)
    for k, dof in enumerate(robot.dof_names):
        attrs = {"name": f"{dof}_motor", "joint": dof, "gear": "1"}
        if bounded[k]:
            attrs["ctrlrange"] = _vec([-effort[k], effort[k]])
        ET.SubElement(actuator, "motor", attrs)
    return actuator


def _inertial(inertia: pin.Inertia) -> ET.Element:
    Ic = np.asarray(inertia.inertia)
    full = [Ic[0, 0], Ic[1, 1], Ic[2, 2], Ic[0, 1], Ic[0, 2], Ic[1, 2]]
    return ET.Element(
        "inertial",
        {"pos": _vec(inertia.lever), "mass": repr(float(inertia.mass)), "fullinertia": _vec(full)},
    )


def _body_name(name: str, used: set[str]) -> str:
    """``name``, or ``name_1``, ``name_2``... when MuJoCo reserves it (``world``) or it is
    taken; renamed bodies are said in an :class:`~manip_id.errors.ExportWarning`."""
    out, k = name, 0
    while out in used:
        k += 1
        out = f"{name}_{k}"
    used.add(out)
    if out != name:
        warnings.warn(
            f"MJCF export: link {name!r} is a name MuJoCo reserves or already used: written "
            f"as body {out!r}",
            ExportWarning,
            stacklevel=4,
        )
    return out


def _bodies(robot, theta, exp: ExportedTree, model: pin.Model, world: ET.Element, assets) -> None:
    """Fill ``world`` with one nested ``<body>`` per joint of ``model`` and the geoms."""
    bodies: dict[int, ET.Element] = {0: world}
    used = {"world"}  # MuJoCo's own body: a link of that name would not load
    for i in range(1, model.njoints):  # parents come first in Pinocchio's order
        M = model.jointPlacements[i]
        name = _body_name(exp.tree.child_of.get(model.names[i], model.names[i]), used)
        body = ET.SubElement(
            bodies[model.parents[i]],
            "body",
            {"name": name, "pos": _vec(M.translation), "quat": _quat(M.rotation)},
        )
        body.append(_inertial(model.inertias[i]))
        body.append(_joint(robot, theta, model, i))
        bodies[i] = body
    for link, el in exp.tree.links.items():
        if not model.existFrame(link, pin.BODY):
            continue
        frame = model.frames[model.getFrameId(link, pin.BODY)]
        body = bodies[frame.parentJoint]
        visuals = [_geom("visual", part, frame.placement, assets) for part in el.findall("visual")]
        body.extend(g for g in visuals if g is not None)
        for part in el.findall("collision"):
            geom = _geom("collision", part, frame.placement, assets)
            if geom is not None:
                if None in visuals:  # a visual left out: its collision shape is shown instead
                    geom.set("group", "0")
                body.append(geom)


@dataclass(frozen=True)
class MjcfText:
    """The MJCF text, its sidecar object and what the export decided (see ExportResult)."""

    xml: str
    sidecar: dict
    composites: list[Composite]
    unresolved: list[str]
    skipped: list[str]
    min_eigenvalues: dict[str, float]


def mjcf_text(
    robot,
    theta,
    name: str = "robot.xml",
    *,
    source=None,
    carried: str = "auto",
    provenance: Mapping | None = None,
) -> MjcfText:
    """The MJCF text and sidecar of :func:`export_mjcf`, without writing them."""
    theta = checked_theta(robot, theta)
    exp = exported_tree(robot, theta, source=source, carried=carried, meshes="absolute")
    model = exp.model()
    check = body_check(model)
    root = ET.Element("mujoco", {"model": robot.name})
    ET.SubElement(
        root,
        "compiler",
        {"angle": "radian", "inertiafromgeom": "false", "balanceinertia": "false"},
    )
    ET.SubElement(root, "option", {"gravity": _vec(robot.model.gravity.linear)})
    asset = ET.SubElement(root, "asset")
    world = ET.SubElement(root, "worldbody")
    assets = _Assets({}, [])
    _bodies(robot, theta, exp, model, world, assets)
    for (file, scale), mesh_name in assets.meshes.items():
        ET.SubElement(asset, "mesh", {"name": mesh_name, "file": file, "scale": scale})
    if not assets.meshes:
        root.remove(asset)
    root.append(_motors(robot))
    ET.indent(root)
    side = exported_sidecar(robot, theta, exp, name, provenance)
    side["meshes"]["left_out"] = assets.skipped
    side["min_eigenvalues"] = check
    side["not_in_file"] = [t for t in robot.terms.enabled if t == "fo"]  # offset: no MJCF field
    text = ET.tostring(root, encoding="unicode") + "\n"
    return MjcfText(text, side, exp.composites, exp.unresolved, assets.skipped, check)


def export_mjcf(
    robot,
    theta,
    path,
    *,
    force: bool = False,
    source=None,
    carried: str = "auto",
    provenance: Mapping | None = None,
) -> ExportResult:
    """Write the identified robot as MuJoCo MJCF (``.xml``) and its sidecar.

    Parameters
    ----------
    robot : Robot
        The robot ``theta`` was identified for.
    theta : array_like, shape (p,)
        Standard parameters; refused unless physically consistent.
    path : path
        The ``.xml`` file; refused if it exists unless ``force`` (checked first). Its
        sidecar is ``path + ".identified.json"``.
    source, carried, provenance
        As for :func:`~manip_id.export.urdf.export_urdf`.

    Returns
    -------
    ExportResult
        The files written (atomically), the composites and the meshes left out.
    """
    out, _ = check_output(path, force, suffixes=(".xml",))
    texts = mjcf_text(robot, theta, out.name, source=source, carried=carried, provenance=provenance)
    atomic_write_text(out, texts.xml)
    side = sidecar_path(out)
    atomic_write_text(side, json_text(texts.sidecar))
    return ExportResult(
        out, side, texts.composites, texts.unresolved, texts.skipped, texts.min_eigenvalues
    )
