"""Identification models that need no acceleration: energy over intervals, filtered momentum.

The dynamic model ``tau = Y(q, dq, ddq) theta`` needs ``ddq``, which on real
logs comes from differentiating filtered positions twice. Two other forms of
the same equations of motion, linear in the same ``theta``, need only ``q``,
``dq`` and ``tau``.

Energy (Gautier & Khalil). With ``H = K + U`` (kinetic plus potential energy)
and the joint terms' power ``dq^T tau_joint``, the power balance
``tau^T dq = dH/dt + dq^T tau_joint`` integrated over ``[t_a, t_b]`` reads::

    int tau^T dq dt = [h(t_b) - h(t_a)] theta + int d(t) dt theta       (one scalar row)

    h = kinetic + potential energy regressors     (Pinocchio), 10 columns per body
      + 1/2 dq_j^2 for the armature Ia_j          (its kinetic energy)
    d = dq_j^2 (fv_j), |dq_j| (fc_j), dq_j (fo_j), q_j dq_j (spring k_j)

Momentum. ``p = M(q) dq = Y_p(q, dq) theta`` and ``dp/dt = tau + dK/dq - g - tau_joint``
(``dK/dq = C^T dq`` with Christoffel's C), so ``tau = dp/dt + Y_h(q, dq) theta`` with
``Y_h theta = g - C^T dq + tau_joint``. With ``F(s) = lambda/(s + lambda)``,
``F[dp/dt] = lambda (p - F[p])`` (filter of ``p`` started at ``p(0)``)::

    F[tau] = ( lambda (Y_p - F[Y_p]) + F[Y_h] ) theta                     (nv rows)

Both are linear regressions with the same standard parameters, so they
accumulate into :class:`~manip_id.estimators.InformationAccumulator` and the
usual solve, standard deviations and errors apply. Their null space is that of
the dynamic model (a parameter vector with ``H == const`` for every motion
has ``M == 0`` and ``g == 0``, hence ``Y theta == 0``, and conversely), so the
base parameters are the robot's own (:func:`check_energy_base` verifies it).

Rows. Energy: consecutive windows of ``window_length`` seconds (an even number
of sampling intervals, Simpson's rule, ``O(h^4)``). Momentum: the filter is
integrated exactly for a cubic interpolation of its inputs (``O(h^4)``);
rows are taken every ``window_length`` seconds with ``lambda = 3 /
window_length`` by default, so that the filtered noise of two rows is
correlated by ``exp(-3) = 0.05`` only and the least-squares covariance holds.
When no window is given it is chosen from the data (:mod:`~.window`: the default
when it gives at least 5 rows per base parameter, else the longest window that does).
"""

from .energy import (
    DEFAULT_WINDOW,
    EnergyBaseCheck,
    accumulate_energy,
    check_energy_base,
    energy_rows,
    window_samples,
)
from .momentum import accumulate_momentum, momentum_regressors, momentum_rows
from .window import ROWS_PER_PARAMETER, WindowChoice, choose_window

MODELS: tuple[str, ...] = ("dynamic", "energy", "momentum")

__all__ = [
    "DEFAULT_WINDOW",
    "MODELS",
    "ROWS_PER_PARAMETER",
    "EnergyBaseCheck",
    "WindowChoice",
    "accumulate_energy",
    "accumulate_momentum",
    "check_energy_base",
    "choose_window",
    "energy_rows",
    "momentum_regressors",
    "momentum_rows",
    "window_samples",
]
