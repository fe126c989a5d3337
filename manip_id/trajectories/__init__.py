"""Excitation trajectories: finite Fourier series per joint (Swevers et al.).

Members: ``fourier.py`` (the series, angles -> configurations), ``limits.py``
(limit checks with a margin), ``excitation.py`` (random trajectories within the
limits, the condition-number optimum). The math they share:

For joint ``j`` with ``L`` harmonics and base pulsation ``wf`` [rad/s]::

    q_j(t)   = q0_j + sum_l [ a_jl/(l wf) sin(l wf t) - b_jl/(l wf) cos(l wf t) ]
    dq_j(t)  =        sum_l [ a_jl cos(l wf t) + b_jl sin(l wf t) ]
    ddq_j(t) =        sum_l [ -a_jl l wf sin(l wf t) + b_jl l wf cos(l wf t) ]

The trajectory is periodic with period ``2 pi / wf``; velocity and
acceleration are exact (analytic), never differentiated numerically. Position,
velocity and acceleration are linear in the coefficients ``x = (q0, a, b)``,
so joint limits sampled on a time grid are linear inequalities ``G x <= h``.

A trajectory lives in joint coordinates, one per velocity coordinate (shape
(N, nv)). For a continuous joint (Pinocchio stores it as ``(cos, sin)``, so
``nq != nv``) the coordinate is the angle; :func:`trajectory_to_configuration`
maps angles to configurations of shape (N, nq). Continuous joints have no
position limit.

Limits (:func:`check_limits`) with a relative ``margin`` ``m``::

    position      lo + m (hi - lo)  <=  q_j(t)  <=  hi - m (hi - lo)   (URDF limits)
    velocity      |dq_j(t)|   <= (1 - m) robot.velocity_limit_j
    acceleration  |ddq_j(t)|  <= (1 - m) acceleration_limit_j           (when given)

A limit that the description leaves unset (infinite, zero, inverted or wider
than :data:`manip_id.robot.parameters.UNSET_LIMIT` = 1e3) is not checked. Trajectory
design (:func:`random_trajectory`, :func:`optimize_excitation`) still needs
finite bounds: it uses
:meth:`Robot.sampling_bounds` ([-pi, pi] for unset positions) and
:meth:`Robot.velocity_bounds` (2 [unit/s] for unset velocities).

Excitation (:func:`optimize_excitation`) minimizes the condition number of the
base regressor ``W = [Y(q(t_k), dq(t_k), ddq(t_k))[:, base]]_k`` (stacked,
shape (n_points nv, n_base)) over the coefficients, subject to the sampled
limits, with SLSQP (linear constraints, objective ``log cond(W)``).
"""

from .excitation import (
    ExcitationObjective,
    ExcitationResult,
    ExcitationSearch,
    base_columns,
    excitation_condition_number,
    optimize_excitation,
    random_trajectory,
)
from .fourier import DEFAULT_WF, FourierTrajectory, trajectory_to_configuration
from .limits import DEFAULT_CHECK_POINTS, LimitUsage, check_limits

__all__ = [
    "DEFAULT_CHECK_POINTS",
    "DEFAULT_WF",
    "ExcitationObjective",
    "ExcitationResult",
    "ExcitationSearch",
    "FourierTrajectory",
    "LimitUsage",
    "base_columns",
    "check_limits",
    "excitation_condition_number",
    "optimize_excitation",
    "random_trajectory",
    "trajectory_to_configuration",
]
