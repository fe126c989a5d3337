"""The lesson's mass-spring-damper, shared by ``msd_gradient.py`` and ``drem_concurrent.py``.

Plant ``m y'' + c y' + k y = b u`` with m = 2, c = 0.8, k = 5, b = 1.5 and
``u(t) = 1.2 sin(1.1 t) + 0.7 sin(2.3 t)``, written as the scalar regression

    y'' = phi^T theta,   phi = [-y, -y', u],   theta = [k/m, c/m, b/m] = [2.5, 0.4, 0.75].

At each step k of the loop (dt = 0.002 s, y(0) = 0.4, y'(0) = -0.2): the true
acceleration ``z = phi_k^T theta`` from the current state, every estimator's
update on ``(phi_k, z)``, then explicit Euler on the plant (``y += dt y'``,
``y' += dt y''``). The lesson's gradient law starts at theta_hat(0) = [0.4, 0.1, 0.2]
with Gamma = diag(8, 8, 4).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

M, C, K, B = 2.0, 0.8, 5.0, 1.5  # [kg], [N s/m], [N/m], [N per unit of u]
THETA = np.array([K / M, C / M, B / M])  # [1/s^2, 1/s, N/(kg unit of u)]
THETA0 = np.array([0.4, 0.1, 0.2])
GAMMA = np.array([8.0, 8.0, 4.0])
DT = 0.002  # [s]
Y0, DY0 = 0.4, -0.2  # [m], [m/s]


@dataclass(frozen=True)
class LessonRun:
    """What one run of the loop saw.

    phi: regressors, shape (n_steps, 3); z: accelerations y'' [m/s^2], shape (n_steps,);
    errors: per estimator the absolute prediction errors |eps| before each update,
    each of shape (n_steps,).
    """

    phi: np.ndarray
    z: np.ndarray
    errors: list[np.ndarray]


def u_of(t: float, hold: float | None = None) -> float:
    """The lesson's multisine input at ``t`` [s], held at its value at ``hold`` [s]
    afterwards (None: never held)."""
    if hold is not None:
        t = min(t, hold)
    return 1.2 * np.sin(1.1 * t) + 0.7 * np.sin(2.3 * t)


def run(estimators, n_steps: int, dt: float = DT, hold: float | None = None) -> LessonRun:
    """The lesson's loop driving every estimator on the same plant (module docstring)."""
    y, dy = Y0, DY0  # [m], [m/s]
    phi_all = np.empty((n_steps, 3))
    z_all = np.empty(n_steps)  # [m/s^2]
    errors = [np.empty(n_steps) for _ in estimators]
    phi = np.empty(3)
    for k in range(n_steps):
        phi[0], phi[1], phi[2] = -y, -dy, u_of(k * dt, hold)
        ddy = float(phi @ THETA)  # [m/s^2]
        for est, err in zip(estimators, errors, strict=True):
            est.step(phi, ddy, dt)
            err[k] = abs(est.last_error)
        phi_all[k] = phi
        z_all[k] = ddy
        y, dy = y + dt * dy, dy + dt * ddy
    return LessonRun(phi_all, z_all, errors)


def time_to(history, threshold: float = 0.01) -> float | None:
    """First time [s] after which ``||theta_hat - theta|| / ||theta||`` stays below
    ``threshold`` (None if it is above at the last recorded estimate)."""
    rel = np.linalg.norm(history.theta - THETA, axis=1) / np.linalg.norm(THETA)
    above = np.nonzero(rel > threshold)[0]
    if above.size == 0:
        return float(history.t[0])
    if above[-1] == rel.size - 1:
        return None
    return float(history.t[above[-1] + 1])
