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

from ..errors import DataError, InputError
from ..identifiability import BaseParameters
from ..identification.document import read_result_json
from ..robot import Robot


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
    diagonal of the standard deviations).
    """
    path = Path(path)
    doc = read_result_json(path, "result")
    rows, key = doc.get("base_parameters"), "value"
    if rows is None:
        rows, key = doc.get("parameters"), "estimate"
    if not isinstance(rows, list) or not rows:
        raise DataError(
            f"{path} holds no base parameters (expected 'base_parameters' from manip-id "
            "identify --json)"
        )
    try:
        names = [str(r["name"]) for r in rows]
        values = np.array([float(r[key]) for r in rows])
        std = np.array([float(r["std"]) if r.get("std") is not None else np.nan for r in rows])
    except (KeyError, TypeError, ValueError) as exc:
        raise DataError(f"{path}: a base parameter lacks name, {key} or std ({exc})") from exc
    if not np.isfinite(values).all():
        raise DataError(f"{path}: a base parameter value is missing or not finite")
    cov = doc.get("covariance")
    if cov is not None:
        cov = np.asarray(cov, dtype=float)
        if cov.shape != (len(names),) * 2 or not np.isfinite(cov).all():
            cov = None
    if cov is None:
        cov = np.diag(np.nan_to_num(std, nan=0.0) ** 2)
    return KnownBase(
        names=names,
        estimate=values,
        covariance=cov,
        robot_name=str(doc.get("robot", "")),
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

    With ``robot``, the result's joints must be ``robot.dof_names`` (same order). Every
    gain must have been determined and be positive.
    """
    path = Path(path)
    doc = read_result_json(path, "drive-gain result")
    rows = doc.get("drive_gains")
    if not isinstance(rows, list) or not rows:
        raise DataError(
            f"{path} holds no 'drive_gains' (expected the JSON of manip-id drive-gains --json)"
        )
    try:
        joints = [str(r["joint"]) for r in rows]
        gains = [r["gain"] for r in rows]
    except (KeyError, TypeError) as exc:
        raise DataError(f"{path}: each drive gain needs 'joint' and 'gain' ({exc})") from exc
    bad = [j for j, g in zip(joints, gains, strict=True) if g is None]
    if bad:
        raise DataError(f"{path}: the drive gain of {', '.join(bad)} was not determined")
    g = np.asarray(gains, dtype=float)
    if not np.isfinite(g).all() or np.any(g <= 0):
        j = int(np.argmin(np.where(np.isfinite(g), g, -np.inf)))
        raise DataError(f"{path}: the drive gain of {joints[j]} is {gains[j]}, not positive")
    if robot is not None and joints != list(robot.dof_names):
        raise DataError(
            f"{path} holds gains for the joints {joints} but robot {robot.name!r} has "
            f"{list(robot.dof_names)}"
        )
    return g
