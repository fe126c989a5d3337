"""Reading the sidecar JSON of an export back into a robot (the model layer's half).

:mod:`manip_id.export` writes ``OUT.identified.json`` next to an exported ``OUT.urdf``
(``OUT.xml.identified.json`` next to an MJCF file): the identified parameters, the joint
terms a URDF has no field for (armature ``Ia``, offset ``fo``, spring ``k``), the
coefficients of every friction law, the laws themselves (``joint_model``: which laws, the
order of ``position``, the shapes ``vs, a, c, T0`` and the per-joint models, version 3) and the
inertias the ``load`` law's load torque was computed with (``load_inertias``), the active
and locked joints. ``load_robot(OUT.urdf, identified=True)`` reads it with the functions
here (:func:`identified_options`, :func:`locked_configuration`, :func:`apply_identified`).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .._io.fields import Fields
from .._io.reading import read_json
from ..errors import DataError, InputError
from .friction import FrictionShapes

#: ``format`` field of the sidecar JSON.
SIDECAR_FORMAT = "manip_id identified parameters"
SIDECAR_VERSION = 3

_TERM_FLAGS = {"Ia": "armature", "fv": "viscous", "fc": "coulomb", "fo": "offset", "k": "spring"}
#: The on/off fields of :class:`~manip_id.robot.model.JointTerms` in the sidecar's ``joint_model``.
MODEL_FLAGS: tuple[str, ...] = (
    "armature",
    "viscous",
    "coulomb",
    "offset",
    "spring",
    "asymmetric",
    "stribeck",
    "sigmoid",
    "load",
    "temperature",
    "hysteresis",
)


def sidecar_path(path) -> Path:
    """The sidecar JSON of an exported file: ``robot.urdf`` -> ``robot.identified.json``,
    any other (``robot.xml``) -> ``robot.xml.identified.json`` (so that a URDF and an MJCF
    export of one name do not share a sidecar)."""
    p = Path(path)
    if p.suffix.lower() == ".urdf":
        return p.with_name(p.stem + ".identified.json")
    return p.with_name(p.name + ".identified.json")


#: Joint terms that are >= 0 in any physical drive (armature, viscous and Coulomb friction).
_NONNEGATIVE = ("Ia", "fv", "fc", "fvp", "fvn", "fcp", "fcn", "fs", "fsg", "fh")


#: The largest magnitude of a joint term's coefficient (armature [kg m^2], friction [N m],
#: [N m s/rad], spring [N m/rad], ...) a sidecar may hold: beyond it no drive is described
#: (armature 1e308 would overflow every torque computed with it).
MAX_TERM = 1e9
#: The largest magnitude of a standard parameter (``parameters``, ``load_inertias``).
MAX_PARAMETER = 1e12


def read_sidecar(path) -> dict:
    """Read and check a sidecar JSON written by an export.

    Every field used is checked before use: ``joints`` an object of per-joint objects of
    finite numbers within +-:data:`MAX_TERM` (armature and friction >= 0), ``active_joints``
    and ``joint_terms`` lists of strings, ``locked_joints`` an object of finite positions,
    ``parameters`` a list of ``{name, value}`` with distinct names and finite values, and
    ``load_inertias`` rows of 10 finite numbers (within +-:data:`MAX_PARAMETER`). A tampered
    sidecar is refused with one :class:`~manip_id.errors.InputError` line naming the field.
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
                low = 0.0 if term in _NONNEGATIVE else -MAX_TERM
                f.number(value, f"joints.{joint}.{term}", minimum=low, maximum=MAX_TERM)
        locked = data.get("locked_joints")
        if locked is not None:
            for joint, value in f.object(locked, "locked_joints").items():
                for k, v in enumerate(value if isinstance(value, list) else [value]):
                    f.number(v, f"locked_joints.{joint}[{k}]")
        _check_parameters(f, data)
    except DataError as exc:
        raise InputError(str(exc)) from exc
    return data


def _check_parameters(f: Fields, data: dict) -> None:
    """``parameters`` and ``load_inertias`` of a sidecar, when present (module docstring)."""
    seen: set[str] = set()
    for k, row in enumerate(f.list(data.get("parameters", []), "parameters")):
        row = f.object(row, f"parameters[{k}]")
        name = f.text(row.get("name"), f"parameters[{k}].name")
        if name in seen:
            raise DataError(f"{f.where}: parameter {name!r} is listed twice")
        seen.add(name)
        f.number(
            row.get("value"),
            f"parameters[{k}].value ({name})",
            minimum=-MAX_PARAMETER,
            maximum=MAX_PARAMETER,
        )
    blocks = data.get("load_inertias")
    if blocks is not None:
        rows = f.list(blocks, "load_inertias", nonempty=True)
        f.matrix(rows, "load_inertias", (len(rows), 10))
        for i, row in enumerate(rows):
            for j, v in enumerate(row):
                f.number(
                    v, f"load_inertias[{i}][{j}]", minimum=-MAX_PARAMETER, maximum=MAX_PARAMETER
                )


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


def joint_model_document(terms) -> dict:
    """The sidecar's ``joint_model`` of a robot's :class:`~manip_id.robot.model.JointTerms`."""
    shapes = terms.shapes
    return {
        **{f: bool(getattr(terms, f)) for f in MODEL_FLAGS},
        "harmonics": int(terms.harmonics),
        "shapes": None if shapes is None else shapes.to_dict(),
        "per_dof": None if terms.per_dof is None else [list(k) for k in terms.per_dof],
    }


def model_structure(robot) -> dict:
    """The structure of ``robot``'s model, as a result and a sidecar record it: the
    active and locked joints, the joint terms and their laws, the drive train.
    ``load_robot(NAME, identified=...)`` loads the same model again."""
    tr = robot.transmission
    return {
        "robot": robot.name,
        "active_joints": list(robot.joint_names),
        "locked_joints": locked_joints(robot),
        "joint_terms": list(robot.terms.enabled),
        "joint_model": joint_model_document(robot.terms),
        "transmission": None if tr is None else tr.to_dict(),
    }


def identified_options(spec: str, identified, armature, friction, spring, active_joints):
    """The sidecar of an exported URDF and the load options it implies (explicit ones win).

    Returns ``(sidecar, armature, friction, spring, active_joints)`` for
    :func:`manip_id.robot.model.load_robot`; :func:`locked_configuration` gives the positions
    of the locked joints.
    """
    path = sidecar_path(spec) if identified is True else Path(identified)
    data = read_sidecar(path)
    return (data, *structure_options(data, armature, friction, spring, active_joints))


def structure_options(data, armature, friction, spring, active_joints):
    """The load options a model structure (a sidecar, a result's ``model_structure``)
    implies, explicit ones winning: ``(armature, friction, spring, active_joints)``."""
    terms = [t for t in data.get("joint_terms", []) if t in _TERM_FLAGS]
    if armature is None:
        armature = "Ia" in terms
    if friction is None:
        friction = [_TERM_FLAGS[t] for t in terms if t in ("fv", "fc", "fo")]
    if spring is None:
        spring = "k" in terms
    if active_joints is None:
        active_joints = list(data["active_joints"])
    return armature, friction, spring, active_joints


def _toggle(per_dof, term: str, on: bool | None):
    if per_dof is None or on is None:
        return per_dof
    return tuple(tuple(t for t in keep if t != term) + ((term,) if on else ()) for keep in per_dof)


def identified_joint_model(sidecar: Mapping, *, armature=None, friction=None, spring=None):
    """The fields of the :class:`~manip_id.robot.model.JointTerms` the sidecar's ``joint_model``
    records (its laws, ``harmonics``, ``shapes``, ``per_dof``), or None when the caller
    names the friction kinds (``friction`` not None: theirs win) or the sidecar has no
    joint model (version 2). An explicit ``armature`` or ``spring`` flag overrides the
    sidecar's, also in each joint's model."""
    model = sidecar.get("joint_model")
    if friction is not None or model is None:
        return None
    try:
        fields: dict[str, Any] = {f: bool(model.get(f, False)) for f in MODEL_FLAGS}
        fields["harmonics"] = int(model.get("harmonics", 0))
        shapes = model.get("shapes")
        fields["shapes"] = None if shapes is None else FrictionShapes.from_dict(shapes)
        per_dof = model.get("per_dof")
        per_dof = None if per_dof is None else tuple(tuple(map(str, k)) for k in per_dof)
    except (AttributeError, TypeError, ValueError) as exc:
        raise InputError(f"the sidecar's joint_model cannot be read: {model!r}") from exc
    for flag, term, value in (("armature", "Ia", armature), ("spring", "k", spring)):
        if value is not None:
            fields[flag] = bool(value)
            per_dof = _toggle(per_dof, term, bool(value))
    fields["per_dof"] = per_dof
    return fields


def locked_configuration(sidecar: Mapping) -> dict[str, Any] | None:
    """The sidecar's locked joints as ``JointSelection(locked_configuration=...)`` of
    :func:`manip_id.robot.model.load_robot` takes them (None without them, version 1)."""
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
    """Put the sidecar's armature into ``robot.model``, its offset, spring and the
    coefficients of every other joint term into ``robot.settings`` (so that
    ``robot.nominal_parameters`` holds them), and the ``load`` law's inertias
    (``settings["load_inertias"]``, :attr:`~manip_id.robot.model.Robot.load_model`)."""
    joints = sidecar["joints"]
    unknown = [j for j in joints if j not in robot.dof_names]
    if unknown:
        raise InputError(
            f"the identified-parameter sidecar names joints {unknown[:4]} that robot "
            f"{robot.name!r} does not move (its joints: {list(robot.dof_names)})"
        )
    values = {
        t: np.array([float(joints.get(d, {}).get(t, 0.0)) for d in robot.dof_names])
        for t in robot.terms.enabled
        if any(t in joints.get(d, {}) for d in robot.dof_names)
    }
    robot.settings["joint_term_values"] = values
    motor = sidecar.get("motor_terms")
    if motor and robot.transmission is not None:  # the identified motor terms, by name
        names = robot.transmission.parameter_names
        robot.settings["motor_term_values"] = [float(motor.get(n, 0.0)) for n in names]
    blocks = sidecar.get("load_inertias")
    if blocks is not None:
        blocks = np.asarray(blocks, dtype=float)
        if blocks.shape != (robot.n_bodies, 10):
            raise InputError(
                f"the sidecar's load_inertias have shape {blocks.shape}, expected "
                f"(n_bodies, 10)={robot.n_bodies, 10}"
            )
        robot.settings["load_inertias"] = blocks
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
