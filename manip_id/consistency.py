"""Physical consistency of a standard parameter vector: pseudo-inertias and joint terms.

A body's 10 standard parameters ``pi = [m, h_x, h_y, h_z, I_xx, I_xy, I_yy, I_xz, I_yz,
I_zz]`` (first moment ``h = m c`` [kg m] and inertia ``I`` about the joint frame origin
[kg m^2]) are *density realizable* (some non-negative mass density has them; Wensing,
Kim & Slotine 2017) exactly when its pseudo-inertia is positive semi-definite::

    J(pi) = [[0.5 tr(I) 1 - I,  h],      (4, 4) [kg m^2 | kg m ; kg m | kg]
             [h^T,              m]]

``J`` is the second moment ``int [x; 1][x; 1]^T rho dV``; it is linear in ``pi``
(:func:`pseudo_inertia`). ``J`` positive definite implies ``m > 0``, the inertia
about the centre of mass positive definite and its principal moments obeying the
triangle inequalities. A body is counted consistent here when the smallest
eigenvalue of its ``J`` exceeds ``tolerance * max(|eig J|)`` (default
:data:`EIG_TOLERANCE`, so "positive definite beyond round-off").

Joint terms: armature ``Ia``, viscous ``fv`` and Coulomb ``fc`` friction, their
one-sided forms ``fvp fvn fcp fcn``, the Stribeck excess ``fs = f_static - fc`` and the
sigmoid amplitude ``fsg`` must be ``>= 0`` (:mod:`manip_id.friction`; offset ``fo``,
spring ``k`` and the position harmonics may have either sign).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ._checks import as_float_array, check_finite
from .errors import InputError, ManipIdError

#: Relative eigenvalue tolerance of the consistency check (``lambda_min > tol * lambda_max``).
EIG_TOLERANCE = 1e-10
#: Joint terms that must be non-negative.
NONNEGATIVE_TERMS: tuple[str, ...] = ("Ia", "fv", "fc", "fvp", "fvn", "fcp", "fcn", "fs", "fsg")


def pseudo_inertia_basis() -> np.ndarray:
    """The constant matrices ``E_k`` with ``J(pi) = sum_k pi_k E_k``, shape (10, 4, 4)."""
    E = np.zeros((10, 4, 4))
    E[0, 3, 3] = 1.0  # m
    for k in range(3):  # h
        E[1 + k, k, 3] = E[1 + k, 3, k] = 1.0
    # Sigma = 0.5 tr(I) 1 - I, with I = [[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]
    diag = {4: 0, 6: 1, 9: 2}  # Ixx, Iyy, Izz -> axis
    for k, a in diag.items():
        for b in range(3):
            E[k, b, b] += 0.5
        E[k, a, a] -= 1.0
    off = {5: (0, 1), 7: (0, 2), 8: (1, 2)}  # Ixy, Ixz, Iyz
    for k, (a, b) in off.items():
        E[k, a, b] = E[k, b, a] = -1.0
    return E


_BASIS = pseudo_inertia_basis()


def pseudo_inertia(pi) -> np.ndarray:
    """Pseudo-inertia ``J`` of body parameters ``pi``: (10,) -> (4, 4), (..., 10) -> (..., 4, 4)."""
    pi = as_float_array(pi, "pi")
    if pi.ndim == 0 or pi.shape[-1] != 10:
        raise InputError(f"body parameters have 10 entries, got pi.shape={pi.shape}")
    return np.einsum("...k,kab->...ab", pi, _BASIS)


def parameters_from_pseudo_inertia(J) -> np.ndarray:
    """Inverse of :func:`pseudo_inertia`: (..., 4, 4) -> (..., 10) (``I = tr(Sigma) 1 - Sigma``)."""
    J = as_float_array(J, "J")
    if J.shape[-2:] != (4, 4):
        raise InputError(f"a pseudo-inertia is (4, 4), got J.shape={J.shape}")
    J = 0.5 * (J + np.swapaxes(J, -1, -2))
    S = J[..., :3, :3]
    tr = np.trace(S, axis1=-2, axis2=-1)
    eye = np.eye(3)
    inertia = tr[..., None, None] * eye - S
    out = np.empty(J.shape[:-2] + (10,))
    out[..., 0] = J[..., 3, 3]
    out[..., 1:4] = J[..., :3, 3]
    out[..., 4] = inertia[..., 0, 0]
    out[..., 5] = inertia[..., 0, 1]
    out[..., 6] = inertia[..., 1, 1]
    out[..., 7] = inertia[..., 0, 2]
    out[..., 8] = inertia[..., 1, 2]
    out[..., 9] = inertia[..., 2, 2]
    return out


@dataclass(frozen=True)
class Violation:
    """One broken condition: ``name`` is a body (joint name) or a parameter name."""

    name: str
    condition: str
    value: float

    def __str__(self) -> str:
        return f"{self.name}: {self.condition} (got {self.value:.4g})"


@dataclass(frozen=True)
class ConsistencyReport:
    """The eigenvalue test of a standard parameter vector.

    Attributes
    ----------
    consistent: every body's ``J`` positive definite and every ``Ia, fv, fc >= 0``.
    body_names: one per moving body (its joint's name).
    min_eigenvalues: smallest eigenvalue of each body's ``J``, shape (n_bodies,) [mixed
        kg / kg m^2: the eigenvalue of a matrix holding both].
    max_eigenvalues: largest eigenvalue of each ``J``, shape (n_bodies,).
    violations: each broken condition, by body or parameter name.
    tolerance: relative eigenvalue tolerance used.
    """

    consistent: bool
    body_names: list[str]
    min_eigenvalues: np.ndarray
    max_eigenvalues: np.ndarray
    violations: list[Violation] = field(default_factory=list)
    tolerance: float = EIG_TOLERANCE

    @property
    def bodies_consistent(self) -> np.ndarray:
        """Per body, whether its pseudo-inertia passes the test, shape (n_bodies,) bool."""
        return self.min_eigenvalues > self.tolerance * np.maximum(np.abs(self.max_eigenvalues), 0)

    def messages(self) -> list[str]:
        """One readable line per violation."""
        return [str(v) for v in self.violations]

    def to_dict(self) -> dict:
        """JSON-ready: ``consistent``, per-body ``min_eigenvalue``, ``violations``."""
        return {
            "consistent": bool(self.consistent),
            "tolerance": self.tolerance,
            "bodies": [
                {"name": n, "min_eigenvalue": float(lo), "max_eigenvalue": float(hi)}
                for n, lo, hi in zip(
                    self.body_names, self.min_eigenvalues, self.max_eigenvalues, strict=True
                )
            ],
            "violations": [
                {"name": v.name, "condition": v.condition, "value": float(v.value)}
                for v in self.violations
            ],
        }


class PhysicalConsistencyError(ManipIdError, ValueError):
    """A parameter vector that had to be physical is not; ``violations`` says where."""

    def __init__(self, what: str, violations: Sequence[Violation]):
        self.violations = list(violations)
        shown = "; ".join(str(v) for v in self.violations[:4])
        more = f"; ... {len(self.violations) - 4} more" if len(self.violations) > 4 else ""
        super().__init__(f"{what} is not physically consistent: {shown}{more}")


def _body_violations(name: str, pi: np.ndarray, lam: np.ndarray, tol: float) -> list[Violation]:
    """The conditions a body with a non-positive-definite ``J`` breaks, most basic first."""
    out = [
        Violation(
            name, "pseudo-inertia J not positive definite (smallest eigenvalue)", float(lam[0])
        )
    ]
    m = float(pi[0])
    if m <= 0:
        out.append(Violation(name, "mass m > 0 [kg]", m))
        return out
    c = pi[1:4] / m
    ixx, ixy, iyy, ixz, iyz, izz = pi[4:]
    I_o = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    I_c = I_o - m * (float(c @ c) * np.eye(3) - np.outer(c, c))
    moments = np.linalg.eigvalsh(I_c)
    scale = max(float(np.abs(moments).max()), 1e-300)
    if moments[0] <= tol * scale:
        out.append(
            Violation(name, "inertia about the CoM positive definite [kg m^2]", float(moments[0]))
        )
    else:
        slack = moments.sum() - 2.0 * moments  # each >= 0: triangle inequalities
        if slack.min() <= tol * scale:
            out.append(
                Violation(
                    name,
                    "triangle inequality of the principal moments (I1 + I2 >= I3) [kg m^2]",
                    float(slack.min()),
                )
            )
    return out


def check_consistency(robot, theta, *, tolerance: float = EIG_TOLERANCE) -> ConsistencyReport:
    """Eigenvalue test of ``theta`` (shape (p,)) for ``robot``: which bodies and joints break what.

    Every body's pseudo-inertia ``J`` must have ``lambda_min > tolerance * max|lambda|``;
    every enabled ``Ia``, ``fv``, ``fc`` must be ``>= 0``. Violations name the body
    (its joint) or the parameter, e.g. ``panda_joint7: inertia about the CoM positive
    definite`` or ``panda_joint6.fv: >= 0``.
    """
    theta = as_float_array(theta, "theta", ndim=1)
    if theta.shape != (robot.n_parameters,):
        raise InputError(f"{theta.shape=} but robot.n_parameters={robot.n_parameters}")
    check_finite(theta, "theta", robot.parameter_names)
    if not (np.isfinite(tolerance) and tolerance >= 0):
        raise InputError(f"tolerance must be >= 0, got {tolerance}")
    blocks = theta[: robot.n_rigid].reshape(robot.n_bodies, 10)
    lam = np.linalg.eigvalsh(pseudo_inertia(blocks))  # (n_bodies, 4) ascending
    violations: list[Violation] = []
    for name, pi, ev in zip(robot.joint_names, blocks, lam, strict=True):
        if not ev[0] > tolerance * np.abs(ev).max():
            violations += _body_violations(name, pi, ev, tolerance)
    names = robot.parameter_names
    for k in range(robot.n_rigid, robot.n_parameters):
        term = names[k].rsplit(".", 1)[1]
        if term in NONNEGATIVE_TERMS and theta[k] < 0:
            violations.append(Violation(names[k], ">= 0", float(theta[k])))
    return ConsistencyReport(
        consistent=not violations,
        body_names=list(robot.joint_names),
        min_eigenvalues=lam[:, 0].copy(),
        max_eigenvalues=lam[:, -1].copy(),
        violations=violations,
        tolerance=float(tolerance),
    )


def require_consistent(robot, theta, what: str = "the parameter vector") -> ConsistencyReport:
    """:func:`check_consistency`, raising :class:`PhysicalConsistencyError` on any violation."""
    report = check_consistency(robot, theta)
    if not report.consistent:
        raise PhysicalConsistencyError(what, report.violations)
    return report
