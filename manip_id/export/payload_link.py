"""An identified payload back into the robot: a fixed link carrying its mass and inertia.

:func:`export_payload_urdf` copies the robot's URDF and adds::

    <link name="payload">
      <inertial> <origin xyz="c" rpy="0 0 0"/> <mass value="m"/> <inertia .../> </inertial>
    </link>
    <joint name="payload_joint" type="fixed">
      <parent link="L"/> <child link="payload"/> <origin xyz="p" rpy="r"/>
    </joint>

where ``L`` is the link ``FRAME`` belongs to (the frame itself when it is a link; the child
link of a joint frame; the link an operational frame hangs on) and ``(p, r)`` the frame
in that link. The payload is a :class:`PayloadLink`, as ``manip-id payload`` reports it:
mass ``m`` [kg],
centre of mass ``c`` (3,) [m] in FRAME and inertia about the centre of mass ``I_c``
(6,: ``Ixx, Ixy, Iyy, Ixz, Iyz, Izz``, or (3, 3)) [kg m^2] in FRAME's axes. Its
pseudo-inertia must be positive definite (a consistent estimate,
``manip-id payload --consistent``). The robot with the payload link then has the
torques of the robot plus the payload: identify on loaded data with it needs no payload
terms. Mesh references are written as in :mod:`manip_id.export.meshes`.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .._checks import as_float_array, check_finite
from .._io import atomic_write_text, json_text
from ..errors import InputError, RobotError
from ..physics.consistency import EIG_TOLERANCE, PhysicalConsistencyError, Violation, pseudo_inertia
from ..robot.model import frame_id
from .meshes import rewrite_meshes
from .sidecar import sidecar_document
from .urdf import ExportResult, body_check, check_output, read_urdf, set_inertial

_SIX = ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2))


def _inertia_matrix(inertia) -> np.ndarray:
    arr = as_float_array(inertia, "inertia")
    if arr.shape == (6,):
        out = np.zeros((3, 3))
        for v, (a, b) in zip(arr, _SIX, strict=True):
            out[a, b] = out[b, a] = v
        return out
    if arr.shape == (3, 3):
        return 0.5 * (arr + arr.T)
    raise InputError(f"inertia is (6,) or (3, 3), got inertia.shape={arr.shape}")


def _attachment(full: pin.Model, frame: str) -> tuple[str, pin.SE3]:
    """The link FRAME belongs to and FRAME's placement in it."""
    if not isinstance(frame, str) or not full.existFrame(frame):
        links = [f.name for f in full.frames if f.type == pin.BODY]
        raise InputError(f"no frame {frame!r} in the robot; its links: {', '.join(links)}")
    if full.existFrame(frame, pin.BODY):
        return frame, pin.SE3.Identity()
    fid = frame_id(full, frame)
    f = full.frames[fid]
    link = next(
        (g for g in full.frames if g.type == pin.BODY and g.parentFrame == fid),
        None,
    )
    cur = f
    while link is None and cur.type != pin.BODY:
        cur = full.frames[cur.parentFrame]
        link = cur if cur.type == pin.BODY else None
    if link is None or link.parentJoint != f.parentJoint:
        raise InputError(f"frame {frame!r} is on no link rigidly attached to it")
    return link.name, link.placement.actInv(f.placement)


def _checked_payload(frame: str, mass, com, inertia) -> tuple[float, np.ndarray, np.ndarray]:
    m = float(as_float_array(mass, "mass", ndim=0))
    c = as_float_array(com, "com", ndim=1)
    if c.shape != (3,):
        raise InputError(f"com has 3 entries [m], got com.shape={c.shape}")
    Ic = _inertia_matrix(inertia)
    check_finite(np.r_[m, c, Ic.ravel()], "payload")
    if not m > 0:
        raise PhysicalConsistencyError(f"the payload at {frame}", [Violation(frame, "m > 0", m)])
    I_o = Ic + m * (float(c @ c) * np.eye(3) - np.outer(c, c))  # about the frame origin
    phi = np.r_[m, m * c, [I_o[a, b] for a, b in _SIX]]  # [kg, kg m, kg m^2]
    lam = np.linalg.eigvalsh(pseudo_inertia(phi))
    if not lam[0] > EIG_TOLERANCE * np.abs(lam).max():
        raise PhysicalConsistencyError(
            f"the payload at {frame} (identify it with --consistent)",
            [Violation(frame, "pseudo-inertia J positive definite (smallest eigenvalue)", lam[0])],
        )
    return m, c, Ic


@dataclass(frozen=True)
class PayloadLink:
    """A payload to fix to the robot as a link, as ``manip-id payload`` reports it.

    Checked when exported: mass positive, centre of mass of 3 entries, the pseudo-inertia
    positive definite.

    Attributes
    ----------
    frame : str
        The frame the payload is fixed to (a link, a joint, an operational frame).
    mass : float
        Payload mass [kg].
    com : array_like, shape (3,)
        Centre of mass in ``frame`` [m].
    inertia : array_like, shape (6,) or (3, 3)
        Inertia about the centre of mass, ``frame`` axes, (6,) as ``Ixx, Ixy, Iyy, Ixz,
        Iyz, Izz`` [kg m^2].
    name : str
        Name of the new link (its joint is ``NAME_joint``).
    """

    frame: str
    mass: float
    com: Any
    inertia: Any
    name: str = "payload"


@dataclass(frozen=True)
class PayloadTexts:
    """The URDF with the payload link, its sidecar object and where the link went."""

    urdf: str
    sidecar: dict
    parent_link: str


def payload_urdf_texts(
    robot,
    payload: PayloadLink,
    urdf_name: str = "robot.urdf",
    *,
    source=None,
    provenance: Mapping | None = None,
) -> PayloadTexts:
    """The texts of :func:`export_payload_urdf`, without writing them."""
    frame, name = payload.frame, payload.name
    m, c, Ic = _checked_payload(frame, payload.mass, payload.com, payload.inertia)
    src, root = read_urdf(robot, source)
    taken = {str(e.get("name")) for e in root if e.tag in ("link", "joint")}
    if name in taken or f"{name}_joint" in taken:
        raise InputError(f"the robot has a link or joint named {name!r} already: choose a name")
    parent, placement = _attachment(robot.full_model, frame)
    link = ET.SubElement(root, "link", {"name": name})
    set_inertial(link, m, c, Ic)
    joint = ET.SubElement(root, "joint", {"name": f"{name}_joint", "type": "fixed"})
    ET.SubElement(joint, "parent", {"link": parent})
    ET.SubElement(joint, "child", {"link": name})
    rpy = pin.rpy.matrixToRpy(placement.rotation)
    xyz = " ".join(repr(float(v)) for v in placement.translation)
    ET.SubElement(joint, "origin", {"xyz": xyz, "rpy": " ".join(repr(float(v)) for v in rpy)})
    unresolved = rewrite_meshes(root, src.parent, robot.package_dirs)
    side = sidecar_document(
        robot,
        robot.nominal_parameters,
        target=str(urdf_name),
        source=str(src),
        provenance=provenance,
    )
    side["meshes"] = {"written": "absolute", "unresolved": unresolved}
    side["payload"] = {
        "link": name,
        "frame": frame,
        "parent_link": parent,
        "mass": m,
        "com": c.tolist(),
        "inertia": [float(Ic[a, b]) for a, b in _SIX],
    }
    text = '<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(root, "unicode") + "\n"
    try:
        model = pin.buildModelFromXML(text)
    except Exception as exc:  # Pinocchio raises plain RuntimeError / ValueError
        raise RobotError(f"cannot build the exported model of {src}: {exc}") from exc
    side["min_eigenvalues"] = body_check(model)
    return PayloadTexts(text, side, parent)


def export_payload_urdf(
    robot,
    payload: PayloadLink,
    path,
    *,
    force: bool = False,
    provenance: Mapping | None = None,
) -> ExportResult:
    """Write the robot's URDF with the payload as a fixed link at ``frame``, and its sidecar.

    Parameters
    ----------
    robot : Robot
        The robot the payload was identified on (its URDF is copied).
    payload : PayloadLink
        The frame, mass [kg], centre of mass [m] and inertia about it [kg m^2], and the
        new link's name.
    path : path
        The ``.urdf`` to write; refused if it exists unless ``force`` (checked first).
    provenance : mapping, optional
        Command, source data and uncertainty for the sidecar.
    """
    out, side = check_output(path, force)
    src = Path(robot.source or "")
    if src.is_file() and src.resolve() == out.resolve():
        raise InputError(f"{out} is the robot's own URDF: write the export elsewhere")
    texts = payload_urdf_texts(robot, payload, out.name, provenance=provenance)
    atomic_write_text(out, texts.urdf)
    atomic_write_text(side, json_text(texts.sidecar))
    unresolved = texts.sidecar["meshes"]["unresolved"]
    return ExportResult(out, side, [], unresolved, [], texts.sidecar["min_eigenvalues"])
