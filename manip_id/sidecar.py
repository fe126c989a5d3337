"""Reading the sidecar JSON of an export back into a robot (the model layer's half).

:mod:`manip_id.export` writes ``OUT.identified.json`` next to an exported ``OUT.urdf``
(``OUT.xml.identified.json`` next to an MJCF file): the identified parameters, the joint
terms a URDF has no field for (armature ``Ia``, offset ``fo``, spring ``k``), the active
and locked joints. ``load_robot(OUT.urdf, identified=True)`` reads it with the functions
here (:func:`identified_options`, :func:`locked_configuration`, :func:`apply_identified`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ._io.fields import Fields
from ._io.reading import read_json
from .errors import DataError, InputError

#: ``format`` field of the sidecar JSON.
SIDECAR_FORMAT = "manip_id identified parameters"
SIDECAR_VERSION = 2

_TERM_FLAGS = {"Ia": "armature", "fv": "viscous", "fc": "coulomb", "fo": "offset", "k": "spring"}


def sidecar_path(path) -> Path:
    """The sidecar JSON of an exported file: ``robot.urdf`` -> ``robot.identified.json``,
    any other (``robot.xml``) -> ``robot.xml.identified.json`` (so that a URDF and an MJCF
    export of one name do not share a sidecar)."""
    p = Path(path)
    if p.suffix.lower() == ".urdf":
        return p.with_name(p.stem + ".identified.json")
    return p.with_name(p.name + ".identified.json")


#: Joint terms that are >= 0 in any physical drive (armature, viscous and Coulomb friction).
_NONNEGATIVE = ("Ia", "fv", "fc", "fvp", "fvn", "fcp", "fcn", "fs", "fsg")


def read_sidecar(path) -> dict:
    """Read and check a sidecar JSON written by an export.

    Every field used is checked before use: ``joints`` an object of per-joint objects of
    finite numbers (armature and friction >= 0), ``active_joints`` and ``joint_terms``
    lists of strings, ``locked_joints`` an object of finite positions. A tampered sidecar
    is refused with one :class:`~manip_id.errors.InputError` line naming the field.
    """
    p = Path(path)
    data = read_json(p, "identified-parameter sidecar", error=InputError)
    if not isinstance(data, dict) or data.get("format") != SIDECAR_FORMAT:
        raise InputError(f"{p} is not a manip_id sidecar (expected format {SIDECAR_FORMAT!r})")
    if not isinstance(data.get("joints"), dict) or not isinstance(data.get("active_joints"), list):
        raise InputError(f"{p}: the sidecar misses 'joints' or 'active_joints'")
    f = Fields(p)
    try:
        f.texts(data["active_joints"], "active_joints")
        f.texts(data.get("joint_terms", []), "joint_terms")
        for joint, terms in data["joints"].items():
            for term, value in f.object(terms, f"joints.{joint}").items():
                low = 0.0 if term in _NONNEGATIVE else None
                f.number(value, f"joints.{joint}.{term}", minimum=low)
        locked = data.get("locked_joints")
        if locked is not None:
            for joint, value in f.object(locked, "locked_joints").items():
                for k, v in enumerate(value if isinstance(value, list) else [value]):
                    f.number(v, f"locked_joints.{joint}[{k}]")
    except DataError as exc:
        raise InputError(str(exc)) from exc
    return data


def identified_options(spec: str, identified, armature, friction, spring, active_joints):
    """The sidecar of an exported URDF and the load options it implies (explicit ones win).

    Returns ``(sidecar, armature, friction, spring, active_joints)`` for
    :func:`manip_id.robot.load_robot`; :func:`locked_configuration` gives the positions
    of the locked joints.
    """
    path = sidecar_path(spec) if identified is True else Path(identified)
    data = read_sidecar(path)
    terms = [t for t in data.get("joint_terms", []) if t in _TERM_FLAGS]
    if armature is None:
        armature = "Ia" in terms
    if friction is None:
        friction = [_TERM_FLAGS[t] for t in terms if t in ("fv", "fc", "fo")]
    if spring is None:
        spring = "k" in terms
    if active_joints is None:
        active_joints = list(data["active_joints"])
    return data, armature, friction, spring, active_joints


def locked_configuration(sidecar: dict) -> dict[str, Any] | None:
    """The sidecar's locked joints as ``JointSelection(locked_configuration=...)`` of
    :func:`manip_id.robot.load_robot` takes them (None for a sidecar without them, version 1)."""
    locked = sidecar.get("locked_joints")
    if not isinstance(locked, dict) or not locked:
        return None
    out: dict[str, Any] = {}
    for name, value in locked.items():
        try:
            coords = np.asarray(value, dtype=float)
        except (TypeError, ValueError) as exc:
            what = f"the sidecar's locked joint {name!r}"
            raise InputError(f"{what} has no position in [rad or m]: {value!r}") from exc
        out[str(name)] = float(coords) if coords.ndim == 0 else coords.tolist()
    return out


def apply_identified(robot, sidecar: dict) -> None:
    """Put the sidecar's armature into ``robot.model`` and its offset and spring into
    ``robot.settings`` (so that ``robot.nominal_parameters`` holds them)."""
    joints = sidecar["joints"]
    unknown = [j for j in joints if j not in robot.dof_names]
    if unknown:
        raise InputError(
            f"the identified-parameter sidecar names joints {unknown[:4]} that robot "
            f"{robot.name!r} does not move (its joints: {list(robot.dof_names)})"
        )
    arm = np.array(robot.model.armature, dtype=float)
    offset, spring = np.zeros(robot.nv), np.zeros(robot.nv)
    for k, dof in enumerate(robot.dof_names):
        terms = joints.get(dof, {})
        if "Ia" in terms:
            arm[k] = float(terms["Ia"])
        offset[k] = float(terms.get("fo", 0.0))
        spring[k] = float(terms.get("k", 0.0))
    robot.model.armature = arm
    robot.settings["offset"] = offset
    if any("k" in joints.get(d, {}) for d in robot.dof_names):
        robot.settings["spring"] = spring
