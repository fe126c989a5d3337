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
sigmoid amplitude ``fsg`` must be ``>= 0`` (:mod:`manip_id.robot.friction`; offset ``fo``,
spring ``k`` and the position harmonics may have either sign).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._checks import as_float_array, check_finite
from ..errors import InputError, PhysicalConsistencyError

#: Relative eigenvalue tolerance of the consistency check (``lambda_min > tol * lambda_max``).
EIG_TOLERANCE = 1e-10
#: Joint terms that must be non-negative.
NONNEGATIVE_TERMS: tuple[str, ...] = (
    "Ia",
    "fv",
    "fc",
    "fvp",
    "fvn",
    "fcp",
    "fcn",
    "fs",
    "fsg",
    "fh",
)


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
    consistent
        every body's ``J`` positive definite and every ``Ia, fv, fc >= 0``.
    body_names
        one per moving body (its joint's name).
    min_eigenvalues
        smallest eigenvalue of each body's ``J``, shape (n_bodies,) [mixed
        kg / kg m^2: the eigenvalue of a matrix holding both].
    max_eigenvalues
        largest eigenvalue of each ``J``, shape (n_bodies,).
    violations
        each broken condition, by body or parameter name.
    tolerance
        relative eigenvalue tolerance used.
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


def _body_violations(name: str, pi: np.ndarray, lam: np.ndarray, tol: float) -> list[Violation]:
    """The conditions a body with a non-positive-definite ``J`` breaks, most basic first."""
    out = [
        Violation(
            name, "pseudo-inertia J not positive definite (smallest eigenvalue)", float(lam[0])
        )
    ]
    m = float(pi[0])
    # a mass at the round-off level of J (minimum-norm parameters leave 1e-17 kg where the
    # data fix no mass) is no mass: c = (m c) / m would be a meaningless 1e17 m
    if m <= tol * max(float(np.abs(lam).max()), 1e-300):
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


# ------------------------------------------------------------------ plausibility
#: A body is implausible when its mass is more than this factor from its nominal mass.
MASS_RATIO_LIMIT = 3.0


def ellipsoid_matrix(center, shape) -> np.ndarray:
    """``Q_bar`` (4, 4) of the ellipsoid ``{x : (x - c)^T Q^-1 (x - c) <= 1}``.

    ``Q_bar = [[-Q^-1, Q^-1 c], [c^T Q^-1, 1 - c^T Q^-1 c]]``, so that
    ``[x; 1]^T Q_bar [x; 1] = 1 - (x - c)^T Q^-1 (x - c)`` (>= 0 inside) and, for a body
    of pseudo-inertia ``J``, ``tr(J Q_bar) = int rho (1 - (x - c)^T Q^-1 (x - c)) dV``
    (Wensing, Kim & Slotine 2017). ``center`` (3,) [m], ``shape`` ``Q`` (3, 3) positive
    definite [m^2] (semi-axes: square roots of its eigenvalues).
    """
    c = as_float_array(center, "center", ndim=1)
    Q = as_float_array(shape, "shape", ndim=2)
    if c.shape != (3,) or Q.shape != (3, 3):
        raise InputError(
            f"an ellipsoid needs center (3,) and shape (3, 3), got {c.shape}, {Q.shape}"
        )
    if np.linalg.eigvalsh(0.5 * (Q + Q.T))[0] <= 0:
        raise InputError("the ellipsoid's shape matrix Q must be positive definite")
    Qi = np.linalg.inv(0.5 * (Q + Q.T))
    out = np.empty((4, 4))
    out[:3, :3] = -Qi
    out[:3, 3] = out[3, :3] = Qi @ c
    out[3, 3] = 1.0 - c @ Qi @ c
    return out


def ellipsoid_rows(Qbar) -> np.ndarray:
    """``d`` with ``tr(J(pi) Q_bar) = d . pi`` (the ellipsoid LMI is linear in ``pi``):
    (4, 4) -> (10,), (..., 4, 4) -> (..., 10)."""
    return np.einsum("kab,...ab->...k", _BASIS, as_float_array(Qbar, "Qbar"))


@dataclass(frozen=True)
class BodyPlausibility:
    """How plausible one body's parameters are against its nominal body and its link.

    Attributes
    ----------
    name
        str
        The body (its joint's name).
    mass, nominal_mass
        float
        [kg].
    mass_ratio
        float or None
        ``mass / nominal_mass`` [-] (None for a massless nominal body).
    com_inside
        bool or None
        Whether the centre of mass lies inside the bounding ellipsoid (None: no ellipsoid).
    inside
        bool or None
        Whether the mass distribution fits the ellipsoid (``tr(J Q_bar) >= 0``).
    flags
        list of str
        What is implausible, e.g. ``"mass 3.4x nominal"``.
    """

    name: str
    mass: float
    nominal_mass: float
    mass_ratio: float | None
    com_inside: bool | None
    inside: bool | None
    flags: list[str] = field(default_factory=list)

    def message(self) -> str:
        """``"shoulder_lift_joint: 43.7 kg, 3.4x nominal (12.9 kg); ..."``."""
        text = f"{self.name}: {self.mass:.3g} kg"
        if self.mass_ratio is not None:
            text += f", {self.mass_ratio:.2g}x nominal ({self.nominal_mass:.3g} kg)"
        rest = [f for f in self.flags if not f.startswith("mass ")]
        return text + ("; " + "; ".join(rest) if rest else "")

    def to_dict(self) -> dict:
        def num(x):
            return None if x is None or not np.isfinite(x) else float(x)

        return {
            "name": self.name,
            "mass": num(self.mass),
            "nominal_mass": num(self.nominal_mass),
            "mass_ratio": num(self.mass_ratio),
            "com_inside_ellipsoid": self.com_inside,
            "inside_ellipsoid": self.inside,
            "plausible": not self.flags,
            "flags": list(self.flags),
        }


@dataclass(frozen=True)
class PlausibilityReport:
    """Per body, mass against nominal and position against its link; the total mass.

    Attributes
    ----------
    bodies
        list of BodyPlausibility
    total_mass, nominal_total_mass
        float
        Sums over the moving bodies [kg].
    ratio_limit
        float
        Masses beyond ``[1/limit, limit]`` times nominal are flagged.
    """

    bodies: list[BodyPlausibility]
    total_mass: float
    nominal_total_mass: float
    ratio_limit: float = MASS_RATIO_LIMIT

    @property
    def plausible(self) -> bool:
        return not any(b.flags for b in self.bodies)

    @property
    def implausible(self) -> list[BodyPlausibility]:
        return [b for b in self.bodies if b.flags]

    def messages(self) -> list[str]:
        """One line per implausible body (:meth:`BodyPlausibility.message`)."""
        return [b.message() for b in self.implausible]

    def to_dict(self) -> dict:
        return {
            "plausible": self.plausible,
            "mass_ratio_limit": float(self.ratio_limit),
            "total_mass": float(self.total_mass),
            "nominal_total_mass": float(self.nominal_total_mass),
            "bodies": [b.to_dict() for b in self.bodies],
        }


def check_plausibility(
    robot, theta, ellipsoids=None, *, ratio_limit: float = MASS_RATIO_LIMIT
) -> PlausibilityReport:
    """Masses against the nominal ones and bodies against their bounding ellipsoids.

    A body is flagged when its mass is outside ``[1/ratio_limit, ratio_limit]`` times
    its nominal mass, when its centre of mass ``c_m = h / m`` is outside its ellipsoid
    (``[c_m; 1]^T Q_bar [c_m; 1] < 0``) or its mass distribution does not fit in it
    (``tr(J Q_bar) < 0``, :func:`ellipsoid_matrix`). ``ellipsoids``: ``Q_bar`` per
    body, shape (n_bodies, 4, 4), or None (masses only).
    """
    theta = as_float_array(theta, "theta", ndim=1)
    if theta.shape != (robot.n_parameters,):
        raise InputError(f"{theta.shape=} but robot.n_parameters={robot.n_parameters}")
    nb = robot.n_bodies
    pi = theta[: 10 * nb].reshape(nb, 10)
    pi0 = np.asarray(robot.nominal_parameters, dtype=float)[: 10 * nb].reshape(nb, 10)
    E = None if ellipsoids is None else as_float_array(ellipsoids, "ellipsoids", ndim=3)
    bodies = []
    for i, name in enumerate(robot.joint_names):
        m, m0 = float(pi[i, 0]), float(pi0[i, 0])
        ratio = m / m0 if m0 > 0 else None
        flags = []
        if ratio is not None and not (1.0 / ratio_limit <= ratio <= ratio_limit):
            flags.append(f"mass {ratio:.2g}x nominal")
        com_in = inside = None
        if E is not None:
            slack = float(ellipsoid_rows(E[i]) @ pi[i])
            inside = bool(slack >= -1e-9 * max(abs(m), 1e-12))
            if m > 0:
                x = np.r_[pi[i, 1:4] / m, 1.0]
                com_in = bool(x @ E[i] @ x >= -1e-9)
            if com_in is False:
                flags.append("centre of mass outside its link's bounding ellipsoid")
            elif not inside:
                flags.append("mass spread beyond its link's bounding ellipsoid")
        bodies.append(BodyPlausibility(name, m, m0, ratio, com_in, inside, flags))
    return PlausibilityReport(
        bodies, float(pi[:, 0].sum()), float(pi0[:, 0].sum()), float(ratio_limit)
    )
