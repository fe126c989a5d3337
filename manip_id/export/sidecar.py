"""The sidecar JSON of every export: what a URDF or MJCF file cannot say, and where it came from.

``OUT.identified.json`` next to ``OUT.urdf`` (``OUT.xml.identified.json`` next to an MJCF
``OUT.xml``, :func:`sidecar_path`) holds:

- ``parameters``: the identified standard parameter vector (name, value, unit);
- ``joints``: per joint its identified terms (armature ``Ia``, viscous ``fv``, Coulomb
  ``fc``, offset ``fo``, spring ``k``, and the coefficients of the other friction laws of
  :mod:`manip_id.robot.friction`: ``fvp, fvn, fcp, fcn, fs, fsg, hks, hkc, fl``): armature,
  offset and the laws have no URDF field;
- ``joint_model``: the laws (``JointTerms`` flags), the order of ``position``, the shapes
  (Stribeck ``vs``, sigmoid slope ``a`` and shift ``c`` per DoF) and each joint's own
  model (``per_dof``, after ``--friction auto``);
- ``load_inertias`` (with the ``load`` law): the rigid-body parameters, shape (nb, 10),
  whose ``rnea`` is the law's load torque (the URDF's nominal ones, not the exported);
- ``active_joints``, ``locked_joints`` (name -> position), ``joint_terms``: how the robot
  was identified;
- ``transmission`` and ``motor_terms`` (a robot with a drive train,
  :mod:`manip_id.robot.transmission`): the matrix ``R``, offset, signals and motor terms, and the
  identified motor terms by name (``motor6.Ia``: no URDF field);
- ``composites``: per body, the link holding the identified composite, the links it
  carries and their share (:mod:`manip_id.export.links`);
- ``meshes``: how mesh references were written and those that did not resolve;
- ``provenance`` (when given): the command, the source data, an uncertainty summary;
- ``payload`` (payload exports): the link, its frame, mass, centre of mass and inertia.

``load_robot(OUT.urdf, identified=True)`` reads it back (:func:`identified_options`,
:func:`apply_identified`).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..metrics import finite_or_none
from ..robot.sidecar import (  # noqa: F401  (re-exported: the reading half lives in the model layer)
    MODEL_FLAGS,
    SIDECAR_FORMAT,
    SIDECAR_VERSION,
    apply_identified,
    identified_options,
    joint_model_document,
    locked_configuration,
    locked_joints,
    read_sidecar,
    sidecar_path,
)


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
    doc["joint_model"] = joint_model_document(robot.terms)
    if robot.terms.load:  # the load torque's inertias: the exported URDF has other ones
        load = robot.load_model
        doc["load_inertias"] = [
            [float(v) for v in load.inertias[i].toDynamicParameters()]
            for i in range(1, load.njoints)
        ]
    tr = robot.transmission
    if tr is not None:  # the drive train, and the motor terms by name (no URDF field)
        doc["transmission"] = tr.to_dict()
        doc["motor_terms"] = {n: values[n] for n in tr.parameter_names if n in values}
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
            {"name": n, "value": finite_or_none(v), "std": finite_or_none(sd)}
            for n, v, sd in zip(result.names, result.estimate, result.std, strict=True)
        ],
        "relative_error_train": finite_or_none(err.train),
        "relative_error_validation": None
        if err.validation is None
        else finite_or_none(err.validation),
        "condition_number": finite_or_none(result.condition_number),
        "n_samples": int(result.n_samples),
    }
    return doc
