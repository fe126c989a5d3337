"""The covariance of the consistent standard parameters, by linearising the consistent solve.

The consistent estimate minimises (:mod:`manip_id.estimators.consistent.problem`)::

    F(theta; beta_ls) = ||W (P theta - beta_ls)||^2 + w D(theta),     W^T W = C^-1
    D(theta) = sum_i [tr(M_i) - log det M_i - 4] + ||(theta_t - theta0_t) / s_t||^2
    M_i = J0_i^-1 (J_i(theta) - eps_i 1)

with ``w`` the prior weight of the final solve (``prior_weight * fit_scale``). Where no
constraint other than the log-det barrier is active (bounding ellipsoids, mass ranges,
total mass: inactive), the solution is a smooth function of the least-squares base
estimate, and the implicit function theorem on ``grad_theta F = 0`` gives::

    H d theta = 2 P^T C^-1 d beta_ls,     H = 2 P^T C^-1 P + w grad^2 D
    grad^2 D:  body i, entries (a, b):  tr(K_i^-1 E_a K_i^-1 E_b),  K_i = J_i - eps_i 1
               joint term t:  2 / s_t^2

(``E_a`` the pseudo-inertia basis, ``J = sum_a pi_a E_a``; ``tr(M)`` is linear), so the
sensitivity ``G = 2 H^+ P^T C^-1`` (shape (p, r)) maps any covariance of ``beta_ls`` to
one of ``theta``: ``Cov(theta) = G Cov(beta_ls) G^T``. With the honest (HAC) covariance
of the least-squares fit this is the honest covariance of the consistent standard
parameters; with the white one, the white. Without a prior (``w = 0``) ``H^+`` leaves the
directions the data do not see at zero variance (they are fixed by the solver's choice,
not by the data).

When linear constraints are active (a friction or armature term at 0, a body on its
bounding ellipsoid ``tr(J Q_bar) = 0``,
a mass at its range, the total mass at its bound; :func:`active_constraints`), the
solution moves on their tangent as long as the active set does not change: with ``Z``
a basis of the null space of the active rows ``a^T``, ``G = 2 Z (Z^T H Z)^+ Z^T P^T
C^-1``. That holds for small changes of ``beta_ls`` only; a constraint that the noise
makes and breaks from draw to draw (near-active) gives a spread between the two, so the
bodies held are named (``constraints_active``). The pseudo-inertia margin is inside the
log-det barrier, whose Hessian takes it into ``H``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...physics.consistency import pseudo_inertia, pseudo_inertia_basis
from .problem import ConsistentProblem

#: A mass (total mass) bound counts as active within this relative distance.
ACTIVE_TOL = 1e-4


def prior_hessian(problem: ConsistentProblem, theta: np.ndarray) -> np.ndarray:
    """``grad^2 D(theta)`` of the module docstring, shape (p, p) (zero without a prior)."""
    p, nb = problem.p, problem.n_bodies
    H = np.zeros((p, p))
    if problem.J0 is None:
        return H
    E = pseudo_inertia_basis()  # (10, 4, 4)
    J = pseudo_inertia(np.asarray(theta[: 10 * nb]).reshape(nb, 10))
    for i in range(nb):
        Kinv = np.linalg.inv(J[i] - problem.margin[i] * np.eye(4))
        F = np.einsum("ab,kbc->kac", Kinv, E)  # K^-1 E_k
        sl = slice(10 * i, 10 * i + 10)
        H[sl, sl] = np.einsum("kab,lba->kl", F, F)
    t = np.arange(10 * nb, p)
    H[t, t] = 2.0 / problem.term_scale**2
    return H


def sensitivity(problem: ConsistentProblem, theta: np.ndarray) -> np.ndarray:
    """``G = d theta / d beta_ls`` at the solution ``theta``, shape (p, r): ``2 H^+ P^T
    C^-1``, on the tangent of the active linear constraints (module docstring)."""
    P, W = problem.P, problem.W
    Cinv = W.T @ W
    H = 2.0 * P.T @ Cinv @ P
    if problem.weight:
        H = H + problem.weight * prior_hessian(problem, theta)
    rows = active_constraints(problem, theta).rows
    Z = np.eye(problem.p)
    if rows.shape[0]:
        _, sv, Vt = np.linalg.svd(rows)
        rank = int(np.sum(sv > 1e-12 * sv[0]))
        Z = Vt[rank:].T  # (p, p - rank): the constraints' tangent
    Hz = Z.T @ H @ Z
    d = np.sqrt(np.clip(np.diag(Hz), 0.0, None))
    d = np.where(d > 0, d, 1.0)
    Hinv = np.linalg.pinv(Hz / np.outer(d, d), hermitian=True) / np.outer(d, d)
    return 2.0 * Z @ Hinv @ Z.T @ P.T @ Cinv


@dataclass(frozen=True)
class ActiveConstraints:
    """The linear constraints active at a consistent solution.

    Attributes
    ----------
    rows : numpy.ndarray
        Their gradients ``a`` (``a^T theta = c`` while active), shape (c, p).
    bodies : list of int
        The bodies they hold.
    terms : list of int
        Indices in ``theta`` of the joint terms held at 0 (``Ia, fv, fc >= 0``).
    """

    rows: np.ndarray
    bodies: list[int]
    terms: list[int]


def active_constraints(problem: ConsistentProblem, theta: np.ndarray) -> ActiveConstraints:
    """The active linear constraints at ``theta``: a nonnegative joint term at 0
    (``<= 1e-6`` of its scale), a bounding ellipsoid (``tr(J Q_bar) <= 1e-3 m``), a mass
    range, the total mass (relative :data:`ACTIVE_TOL`)."""
    nb, b, p = problem.n_bodies, problem.bounds, problem.p
    theta = np.asarray(theta, dtype=float)
    scales = problem.term_scale[np.asarray(problem.nonnegative, dtype=np.intp) - 10 * nb]
    terms = [
        int(t) for t, s in zip(problem.nonnegative, scales, strict=True) if theta[t] <= 1e-6 * s
    ]
    rows: list[np.ndarray] = [np.eye(p)[t] for t in terms]
    bodies: set[int] = set()
    if b is None:
        return ActiveConstraints(np.array(rows).reshape(-1, p), [], terms)
    J = pseudo_inertia(theta[: 10 * nb].reshape(nb, 10))
    masses = theta[: 10 * nb : 10]
    E = pseudo_inertia_basis()
    for i in range(nb):
        m = float(masses[i])
        near = ACTIVE_TOL * max(abs(m), 1e-12)
        if b.ellipsoids is not None and np.trace(J[i] @ b.ellipsoids[i]) <= 1e-3 * abs(m):
            a = np.zeros(p)
            a[10 * i : 10 * i + 10] = np.einsum("kab,ba->k", E, b.ellipsoids[i])
            rows.append(a)
            bodies.add(i)
        if b.mass_range is not None and min(abs(m - x) for x in b.mass_range[i]) <= near:
            rows.append(np.eye(p)[10 * i])
            bodies.add(i)
    if b.total_mass is not None:
        total = float(masses.sum())
        if min(abs(total - t) for t in b.total_mass) <= ACTIVE_TOL * max(abs(total), 1e-12):
            a = np.zeros(p)
            a[: 10 * nb : 10] = 1.0
            rows.append(a)
            bodies |= set(range(nb))
    return ActiveConstraints(np.array(rows).reshape(-1, p), sorted(bodies), terms)
