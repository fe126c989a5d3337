"""The sidecar JSON of every export: what a URDF or MJCF file cannot say, and where it came from.

``OUT.identified.json`` next to ``OUT.urdf`` (``OUT.xml.identified.json`` next to an MJCF
``OUT.xml``, :func:`sidecar_path`) holds:

- ``parameters``: the identified standard parameter vector (name, value, unit);
- ``joints``: per joint its identified terms (armature ``Ia``, viscous ``fv``, Coulomb
  ``fc``, offset ``fo``, spring ``k``): armature and offset have no URDF field;
- ``active_joints``, ``locked_joints`` (name -> position), ``joint_terms``: how the robot
  was identified;
- ``composites``: per body, the link holding the identified composite, the links it
  carries and their share (:mod:`manip_id.export.links`);
- ``meshes``: how mesh references were written and those that did not resolve;
- ``provenance`` (when given): the command, the source data, an uncertainty summary;
- ``payload`` (payload exports): the link, its frame, mass, centre of mass and inertia.

``load_robot(OUT.urdf, identified=True)`` reads it back (:func:`identified_options`,
:func:`apply_identified`).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError

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


def locked_joints(robot) -> dict[str, Any]:
    """The joints locked for the identification and their positions [rad or m] (a list of
    the joint's coordinates for a joint of several, e.g. a continuous joint's cos, sin)."""
    full, q = robot.full_model, robot.locked_configuration
    out: dict[str, Any] = {}
    for i in range(1, full.njoints):
        name = full.names[i]
        if name not in robot.joint_names:
            jm = full.joints[i]
            coords = [float(v) for v in q[jm.idx_q : jm.idx_q + jm.nq]]
            out[name] = coords[0] if jm.nq == 1 else coords
    return out


def sidecar_document(
    robot, theta: np.ndarray, *, target: str, source: str, provenance: Mapping | None = None
) -> dict:
    """The sidecar object of an export of ``robot`` with parameters ``theta`` (shape (p,))."""
    names = robot.parameter_names
    values = dict(zip(names, (float(v) for v in theta), strict=True))
    doc = {
        "format": SIDECAR_FORMAT,
        "version": SIDECAR_VERSION,
        "target": target,
        "robot": robot.name,
        "source": source,
        "active_joints": list(robot.joint_names),
        "locked_joints": locked_joints(robot),
        "joint_terms": list(robot.terms.enabled),
        "joints": {
            dof: {t: values[f"{dof}.{t}"] for t in robot.terms.enabled if f"{dof}.{t}" in values}
            for dof in robot.dof_names
        },
        "parameters": [
            {"name": n, "value": values[n], "unit": u}
            for n, u in zip(names, robot.parameter_units, strict=True)
        ],
    }
    if provenance:
        doc["provenance"] = dict(provenance)
    return doc


def command_options(options: Mapping) -> dict:
    """The options of a command that JSON can hold (numbers, text, flags, lists of them)."""
    plain = (str, int, float, bool, type(None))
    out: dict[str, object] = {}
    for key, value in options.items():
        if key.startswith("_") or callable(value):
            continue
        if isinstance(value, plain):
            out[key] = value
        elif isinstance(value, list | tuple) and all(isinstance(v, plain) for v in value):
            out[key] = list(value)
    return out


def _finite(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


def identification_provenance(command: str, options: Mapping, result=None) -> dict:
    """The sidecar's ``provenance`` of an export made by ``command``.

    Parameters
    ----------
    command : str
        The command, e.g. ``"manip-id identify"``.
    options : mapping
        Its options (``vars(args)``; only what JSON can hold is kept).
    result : IdentificationResult, optional
        Its uncertainty summary: the base parameters with their standard deviations, the
        relative torque errors (train, validation), the condition number, the samples.
    """
    doc: dict = {"command": command, "options": command_options(options)}
    if result is None:
        return doc
    err = result.relative_error
    doc["uncertainty"] = {
        "base_parameters": [
            {"name": n, "value": _finite(v), "std": _finite(sd)}
            for n, v, sd in zip(result.names, result.estimate, result.std, strict=True)
        ],
        "relative_error_train": _finite(err.train),
        "relative_error_validation": None if err.validation is None else _finite(err.validation),
        "condition_number": _finite(result.condition_number),
        "n_samples": int(result.n_samples),
    }
    return doc


def read_sidecar(path) -> dict:
    """Read and check a sidecar JSON written by an export."""
    p = Path(path)
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise InputError(f"no identified-parameter sidecar at {p}") from exc
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read the identified-parameter sidecar {p}: {exc}") from exc
    if not isinstance(data, dict) or data.get("format") != SIDECAR_FORMAT:
        raise InputError(f"{p} is not a manip_id sidecar (expected format {SIDECAR_FORMAT!r})")
    if not isinstance(data.get("joints"), dict) or not isinstance(data.get("active_joints"), list):
        raise InputError(f"{p}: the sidecar misses 'joints' or 'active_joints'")
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
    """The sidecar's locked joints as ``load_robot(locked_configuration=...)`` takes them
    (None for a sidecar without them, version 1)."""
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
