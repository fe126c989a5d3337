"""What earlier results give a payload or drive-gain problem: known base parameters, gains.

:func:`load_known_base` reads the base parameters (and their covariance) of an
identification (``manip-id identify --json``) for ``identify_payload(known_base=...)``;
:func:`load_torque_scale` reads the drive gains of ``manip-id drive-gains --json`` as
the torque scale of ``manip-id identify --torque-scale-from``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._io.fields import Fields
from ..errors import DataError, InputError
from ..identifiability import BaseParameters
from ..identification.document import read_result_json
from ..resources import TORQUE_SCALE_RANGE
from ..robot.model import Robot


@dataclass(frozen=True)
class KnownBase:
    """Base parameters from an earlier identification: names, values (r,), covariance (r, r)."""

    names: list[str]
    estimate: np.ndarray
    covariance: np.ndarray
    robot_name: str = ""
    source: str = ""

    @classmethod
    def from_result(cls, result) -> KnownBase:
        """From an :class:`~manip_id.identification.IdentificationResult`."""
        return cls(
            names=list(result.names),
            estimate=np.asarray(result.estimate, dtype=float),
            covariance=np.asarray(result.covariance, dtype=float),
            robot_name=str(result.robot_name),
            source="IdentificationResult",
        )


def load_known_base(path) -> KnownBase:
    """Base parameters from the JSON of ``manip-id identify --json`` (or ``to_dict()``).

    Reads ``base_parameters`` (``name``, ``value``, ``std``) or ``parameters``
    (``name``, ``estimate``, ``std``), and ``covariance`` when present (else the
    diagonal of the standard deviations). Every field is checked before use
    (:class:`~manip_id._io.fields.Fields`): names are strings, values finite numbers,
    standard deviations finite and >= 0 (or null), the covariance an r x r matrix of
    finite numbers, symmetric with a non-negative diagonal.
    """
    path = Path(path)
    doc = read_result_json(path, "result")
    f = Fields(path)
    rows, key = doc.get("base_parameters"), "value"
    if rows is None:
        rows, key = doc.get("parameters"), "estimate"
    if not isinstance(rows, list) or not rows:
        raise DataError(
            f"{path} holds no base parameters (expected 'base_parameters' from manip-id "
            "identify --json)"
        )
    names, values, std = [], [], []
    for k, row in enumerate(rows):
        row = f.object(row, f"base parameter {k}")
        names.append(f.text(row.get("name"), f"base parameter {k} name"))
        values.append(f.number(row.get(key), f"base parameter {names[-1]} {key}"))
        s = f.optional_number(row.get("std"), f"base parameter {names[-1]} std", minimum=0.0)
        std.append(np.nan if s is None else s)
    if len(set(names)) != len(names):
        raise DataError(f"{path}: a base parameter name appears twice")
    cov = doc.get("covariance")
    if cov is not None:
        cov = f.matrix(cov, "covariance", (len(names), len(names)))
        if not np.allclose(cov, cov.T, rtol=1e-9, atol=0.0) or np.any(np.diag(cov) < 0):
            raise DataError(f"{path}: the covariance is not symmetric with a diagonal >= 0")
    else:
        cov = np.diag(np.nan_to_num(np.array(std), nan=0.0) ** 2)
    robot = doc.get("robot", "")
    return KnownBase(
        names=names,
        estimate=np.array(values),
        covariance=cov,
        robot_name=f.text(robot, "robot") if robot is not None else "",
        source=str(path),
    )


def check_known_base(robot: Robot, base: BaseParameters, known) -> KnownBase:
    if not isinstance(known, KnownBase):
        if hasattr(known, "estimate") and hasattr(known, "covariance"):
            known = KnownBase.from_result(known)
        else:
            raise InputError(
                f"known_base must be a KnownBase or an IdentificationResult, got "
                f"{type(known).__name__}"
            )
    where = f" ({known.source})" if known.source else ""
    if known.robot_name and known.robot_name != robot.name:
        raise DataError(
            f"the known base parameters{where} are of robot {known.robot_name!r}, not "
            f"{robot.name!r}"
        )
    if list(known.names) != list(base.base_names):
        missing = [n for n in base.base_names if n not in known.names]
        extra = [n for n in known.names if n not in base.base_names]
        raise DataError(
            f"the known base parameters{where} do not match {robot.name!r} with joint terms "
            f"{list(robot.terms.enabled) or 'none'}: {len(known.names)} given for "
            f"{base.n_base}; missing {missing[:4]}, unexpected {extra[:4]} (identify with the "
            "same --friction/--armature/--joints)"
        )
    return known


def load_torque_scale(path, robot: Robot | None = None) -> np.ndarray:
    """The drive gains of a ``manip-id drive-gains --json`` result, in joint order, (nv,).

    Every row is checked before use: ``joint`` a string (each once), ``gain`` a finite
    positive number (not a bool, not a string), ``determined`` (when present) true. With
    ``robot``, the result must be of that robot (by name) and its joints
    ``robot.dof_names`` (same order): gains of another robot are refused even when its
    joints happen to share the names.
    """
    path = Path(path)
    doc = read_result_json(path, "drive-gain result")
    f = Fields(path)
    rows = doc.get("drive_gains")
    if not isinstance(rows, list) or not rows:
        raise DataError(
            f"{path} holds no 'drive_gains' (expected the JSON of manip-id drive-gains --json)"
        )
    joints, gains = [], []
    for k, row in enumerate(rows):
        row = f.object(row, f"drive gain {k}")
        joint = f.text(row.get("joint"), f"drive gain {k} joint")
        if "determined" in row and not f.boolean(row["determined"], f"{joint} determined"):
            raise DataError(f"{path}: the drive gain of {joint} was not determined")
        if row.get("gain") is None:
            raise DataError(f"{path}: the drive gain of {joint} was not determined")
        gains.append(
            f.number(
                row["gain"], f"the drive gain of {joint}", positive=True,
                minimum=TORQUE_SCALE_RANGE[0], maximum=TORQUE_SCALE_RANGE[1],
            )
        )  # fmt: skip
        joints.append(joint)
    if len(set(joints)) != len(joints):
        raise DataError(f"{path}: a joint appears twice among the drive gains")
    if robot is not None:
        owner = doc.get("robot")
        if owner is not None and f.text(owner, "robot") != robot.name:
            raise DataError(
                f"{path} holds the drive gains of robot {owner!r}, not of {robot.name!r}"
            )
        f.known_names(joints, robot.dof_names, "joint")
        if joints != list(robot.dof_names):
            raise DataError(
                f"{path} holds gains for the joints {joints} but robot {robot.name!r} has "
                f"{list(robot.dof_names)}"
            )
    return np.array(gains)
