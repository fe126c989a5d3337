"""A nominal model made physical: the nearest consistent inertias to a URDF's non-physical ones.

A body is physical when its pseudo-inertia (:mod:`manip_id.physics.consistency`)::

    J = [[Sigma_c + m c c^T, m c], [m c^T, m]],   Sigma_c = 0.5 tr(I_c) 1 - I_c

is positive definite: ``m > 0`` and the second moment about the centre of mass
``Sigma_c`` (the inertia ``I_c`` about the CoM rearranged) positive definite, which
is the triangle inequality of the principal moments. :func:`repair_nominal` leaves
every body that passes :func:`~manip_id.physics.consistency.check_consistency` exactly as
it is and, for each other body, keeps what a URDF's author usually gets right (the
mass and the centre of mass) and replaces ``Sigma_c`` by its nearest matrix in the
Frobenius norm with eigenvalues at least ``sigma_min`` (eigenvalues clipped in the
principal axes, which are kept)::

    Sigma_c = R diag(s) R^T   ->   R diag(max(s_i, sigma_min)) R^T
    sigma_min = max(FLOOR * max(s), m * LENGTH_MIN^2)

(``FLOOR`` relative, ``LENGTH_MIN`` [m] the thickness of the thinnest solid allowed).
A negative mass is taken as a sign slip (``|m|``, the first moment kept, so the
centre of mass flips); a zero mass becomes :data:`MASS_MIN` at the joint origin.
Negative armature or friction (``Ia``, ``fv``, ``fc``) becomes 0.

Why not the consistent estimator's log-det prior (:mod:`manip_id.estimators.consistent`):
its divergence ``D(J || J0) = tr(J0^-1 J) - log det(J0^-1 J) - 4`` needs the
reference ``J0`` positive definite, which a non-physical body's is not by definition,
and its problem couples all bodies through a data fit, while a repair must leave the
physical bodies untouched. The log-det divergence between the repaired and the
URDF's other (physical) bodies is therefore not defined either; the table reports
what changed in the URDF's own terms.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._checks import as_float_array
from ..errors import InputError
from .consistency import NONNEGATIVE_TERMS, ConsistencyReport, check_consistency

#: Smallest second moment about the CoM relative to the largest one.
FLOOR = 1e-3
#: Thickness [m] of the thinnest solid a repaired body may be.
LENGTH_MIN = 1e-3
#: Mass [kg] given to a body of zero (or non-finite) mass.
MASS_MIN = 1e-3


@dataclass(frozen=True)
class BodyChange:
    """What the repair did to one body (its joint's name).

    ``before`` / ``after``: the 10 standard parameters (about the joint origin);
    ``moments_before`` / ``moments_after``: principal moments of the inertia about the
    CoM [kg m^2]; ``reasons``: the violations that made it non-physical.
    """

    body: str
    before: np.ndarray
    after: np.ndarray
    moments_before: np.ndarray
    moments_after: np.ndarray
    reasons: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {
            "body": self.body,
            "reasons": list(self.reasons),
            "mass": [float(self.before[0]), float(self.after[0])],
            "principal_moments_before": self.moments_before.tolist(),
            "principal_moments_after": self.moments_after.tolist(),
            "before": self.before.tolist(),
            "after": self.after.tolist(),
        }


@dataclass(frozen=True)
class RepairResult:
    """The repaired parameters ``theta`` (p,), one :class:`BodyChange` per repaired body,
    the joint terms set to 0 (names), and the independent check of ``theta``."""

    theta: np.ndarray
    bodies: list[BodyChange]
    joint_terms: list[str]
    consistency: ConsistencyReport

    @property
    def changed(self) -> bool:
        return bool(self.bodies or self.joint_terms)

    def table(self) -> str:
        """A row per repaired body: mass, and the principal moments before and after."""
        if not self.changed:
            return "every body is physical: nothing to repair"
        lines = [
            f"{'body':<24} {'mass [kg]':>20}  {'principal moments about the CoM [kg m^2]':<44}",
        ]
        for b in self.bodies:
            mass = (
                f"{b.before[0]:.4g}"
                if b.before[0] == b.after[0]
                else f"{b.before[0]:.4g} -> {b.after[0]:.4g}"
            )
            mb = " ".join(f"{x:.3g}" for x in b.moments_before)
            ma = " ".join(f"{x:.3g}" for x in b.moments_after)
            lines.append(f"{b.body[-24:]:<24} {mass:>20}  {mb} -> {ma}")
            lines += [f"{'':<24}   {r}" for r in b.reasons]
        for name in self.joint_terms:
            lines.append(f"{name:<24} set to 0 (was negative)")
        ok = "passes" if self.consistency.consistent else "FAILS"
        lines.append(f"the repaired model {ok} the eigenvalue test of its pseudo-inertias")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return {
            "bodies": [b.to_dict() for b in self.bodies],
            "joint_terms": list(self.joint_terms),
            "consistency": self.consistency.to_dict(),
        }


def _parameters(m: float, c: np.ndarray, I_c: np.ndarray) -> np.ndarray:
    """Body parameters about the joint origin from mass, CoM and inertia about the CoM."""
    I_o = I_c + m * (float(c @ c) * np.eye(3) - np.outer(c, c))
    return np.array([m, *(m * c), I_o[0, 0], I_o[0, 1], I_o[1, 1], I_o[0, 2], I_o[1, 2], I_o[2, 2]])


def repair_body(pi) -> np.ndarray:
    """The repaired parameters of one body (see the module docstring), shape (10,).

    ``pi``: ``[m, mcx, mcy, mcz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` (kg, kg m, kg m^2), real and
    finite; anything else raises :class:`~manip_id.errors.InputError` (complex values, a
    wrong length, NaN or Inf).
    """
    pi = as_float_array(pi, "repair_body's body parameters pi", ndim=1)
    if pi.shape != (10,):
        raise InputError(
            f"repair_body takes the 10 parameters of one body [m, mcx, mcy, mcz, Ixx, Ixy, "
            f"Iyy, Ixz, Iyz, Izz], got {pi.shape=}"
        )
    if not np.isfinite(pi).all():
        raise InputError(f"repair_body's body parameters must be finite, got {pi.tolist()}")
    m = float(pi[0])
    if not np.isfinite(m) or m == 0:
        m_new, c, I_c = MASS_MIN, np.zeros(3), np.zeros((3, 3))
    else:
        m_new = abs(m)
        c = pi[1:4] / m_new  # the first moment kept
        I_c = _inertia_about(pi, m_new, c)
    sigma = 0.5 * np.trace(I_c) * np.eye(3) - I_c
    s, R = np.linalg.eigh(0.5 * (sigma + sigma.T))
    floor = max(FLOOR * float(s.max()), m_new * LENGTH_MIN**2)
    s = np.maximum(s, floor)
    sigma = (R * s) @ R.T
    I_c = np.trace(sigma) * np.eye(3) - sigma
    return _parameters(m_new, c, I_c)


def _inertia_about(pi: np.ndarray, m: float, c: np.ndarray) -> np.ndarray:
    """The inertia about ``c`` [kg m^2] of the URDF's inertia about the origin, for mass ``m``."""
    ixx, ixy, iyy, ixz, iyz, izz = pi[4:]
    I_o = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    return I_o - m * (float(c @ c) * np.eye(3) - np.outer(c, c))


def _moments(pi: np.ndarray) -> np.ndarray:
    m = float(pi[0])
    if not np.isfinite(m) or m == 0:
        return np.full(3, np.nan)
    return np.linalg.eigvalsh(_inertia_about(pi, abs(m), pi[1:4] / abs(m)))


def repair_nominal(robot, theta=None) -> RepairResult:
    """The nearest physical parameters to ``robot``'s nominal ones (see the module docstring).

    Parameters
    ----------
    robot: a :class:`~manip_id.robot.model.Robot` (its URDF inertias and joint terms).
    theta: the parameters to repair, shape (p,); default ``robot.nominal_parameters``.

    Returns
    -------
    :class:`RepairResult`: the bodies that passed the eigenvalue test are unchanged,
    bit for bit; ``consistency`` checks the result independently.
    """
    theta = (
        robot.nominal_parameters.copy()
        if theta is None
        else np.array(as_float_array(theta, "theta", ndim=1))
    )
    if theta.shape != (robot.n_parameters,):
        raise InputError(f"{theta.shape=} but robot.n_parameters={robot.n_parameters}")
    report = check_consistency(robot, np.nan_to_num(theta))
    ok = report.bodies_consistent
    out = theta.copy()
    bodies: list[BodyChange] = []
    for i, name in enumerate(robot.joint_names):
        if ok[i]:
            continue
        block = theta[10 * i : 10 * i + 10]
        new = repair_body(block)
        out[10 * i : 10 * i + 10] = new
        reasons = [
            f"{v.condition} (got {v.value:.4g})" for v in report.violations if v.name == name
        ]
        bodies.append(BodyChange(name, block.copy(), new, _moments(block), _moments(new), reasons))
    terms: list[str] = []
    for k, name in enumerate(robot.parameter_names[robot.n_rigid :], start=robot.n_rigid):
        if name.rsplit(".", 1)[1] in NONNEGATIVE_TERMS and out[k] < 0:
            out[k] = 0.0
            terms.append(name)
    return RepairResult(out, bodies, terms, check_consistency(robot, out))
