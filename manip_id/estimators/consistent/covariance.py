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

When a linear constraint is active (a mass held at its range, a body on its bounding
ellipsoid), the true sensitivity is the projection of ``G`` onto the constraints' tangent;
the unconstrained ``G`` then over-states the spread of the parameters the constraint
holds, so those bodies are listed (:func:`active_bodies`) and their std are upper bounds.
"""

from __future__ import annotations

import numpy as np

from ...consistency import pseudo_inertia, pseudo_inertia_basis
from .problem import ConsistentProblem

#: A body's constraint counts as active when its mass is within this relative distance of
#: a mass bound, or its pseudo-inertia's least eigenvalue (less the margin) is below this
#: fraction of its largest.
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
    """``G = d theta / d beta_ls = 2 H^+ P^T C^-1`` at the solution ``theta``, shape (p, r)."""
    P, W = problem.P, problem.W
    Cinv = W.T @ W
    H = 2.0 * P.T @ Cinv @ P
    if problem.weight:
        H = H + problem.weight * prior_hessian(problem, theta)
    d = np.sqrt(np.clip(np.diag(H), 0.0, None))
    d = np.where(d > 0, d, 1.0)
    Hinv = np.linalg.pinv(H / np.outer(d, d), hermitian=True) / np.outer(d, d)
    return 2.0 * Hinv @ P.T @ Cinv


def active_bodies(problem: ConsistentProblem, theta: np.ndarray) -> list[int]:
    """Bodies whose constraints are active at ``theta``: the barrier margin, a bounding
    ellipsoid (``tr(J Q_bar) <= 1e-3 m``), a mass range, the total mass (all bodies)."""
    nb, b = problem.n_bodies, problem.bounds
    J = pseudo_inertia(np.asarray(theta[: 10 * nb]).reshape(nb, 10))
    masses = np.asarray(theta[: 10 * nb : 10], dtype=float)
    if b is not None and b.total_mass is not None:
        total = float(masses.sum())
        if min(abs(total - t) for t in b.total_mass) <= ACTIVE_TOL * max(abs(total), 1e-12):
            return list(range(nb))
    out = []
    for i in range(nb):
        m = float(masses[i])
        ev = np.linalg.eigvalsh(J[i] - problem.margin[i] * np.eye(4))
        active = ev[0] <= ACTIVE_TOL * max(abs(ev[-1]), 1e-300)
        if b is not None and b.ellipsoids is not None:
            active |= float(np.trace(J[i] @ b.ellipsoids[i])) <= 1e-3 * max(abs(m), 1e-12)
        if b is not None and b.mass_range is not None:
            lo, hi = b.mass_range[i]
            active |= min(abs(m - lo), abs(m - hi)) <= ACTIVE_TOL * max(abs(m), 1e-12)
        if active:
            out.append(i)
    return out
