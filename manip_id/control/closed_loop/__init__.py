"""Closed-loop simulation of the Slotine-Li adaptive controller on a "true" robot.

Plant. Forward dynamics of the true parameters ``theta``::

    ddq = aba(model(theta), q, dq, tau - tau_joint(q, dq))

where ``model(theta)`` (:meth:`Robot.with_parameters`) carries the true inertias and
armature (``pinocchio.aba`` includes ``model.armature``) and ``tau_joint`` are the
friction, offset and spring torques of ``theta`` (``fv dq + fc sign(dq) + fo + k q``).

Integration. Fixed physics step ``h = 1 / (rate * substeps)`` [s] with
semi-implicit (symplectic) Euler, ``dq+ = dq + h ddq``, ``q+ = integrate(q, h dq+)``
(``pinocchio.integrate``: correct for continuous joints), or classical RK4
(``integrator="rk4"``, four ``aba`` calls per step). The torque is computed at the
control rate and held (zero-order hold) over the ``substeps`` physics steps.

The controller sees ``q``, ``dq`` plus optional Gaussian measurement noise.
Recorded every ``record_every`` control steps: t, q, dq, q_d, tau, s, theta_hat
(and, for composite adaptation, the filtered prediction error).

Pieces. :class:`Plant` (forward dynamics with joint terms, and the integrator),
:class:`SensorNoise` (what the controller sees), :class:`Recorder` (what is logged, at
which stride, and the running sums) and :func:`step` (one control step: measure, torque,
record, plant over one period, adapt). :func:`simulate` checks its inputs and runs
``step`` over the reference, with the options of :class:`ClosedLoopOptions`.

Modules: :mod:`~manip_id.control.closed_loop.reference` (the reference, its limits and the
validation states; payloads), :mod:`~manip_id.control.closed_loop.plant` (plant and sensors),
:mod:`~manip_id.control.closed_loop.recorder` (the log of a run) and
:mod:`~manip_id.control.closed_loop.run` (a step, a run, the comparison with fixed parameters),
:mod:`~manip_id.control.closed_loop.tracking` (a closed-loop log with a known PD/PID
controller, for the closed-loop estimators).
"""

from __future__ import annotations

from .plant import Plant, SensorNoise
from .recorder import Recorder
from .reference import check_reference, default_reference, validation_states, with_payload
from .run import (
    AdaptiveComparison,
    ClosedLoopOptions,
    ClosedLoopRun,
    Setpoint,
    compare_fixed,
    simulate,
    step,
)
from .tracking import TrackingLog, simulate_tracking

__all__ = [
    "AdaptiveComparison",
    "ClosedLoopOptions",
    "ClosedLoopRun",
    "Plant",
    "Recorder",
    "SensorNoise",
    "Setpoint",
    "TrackingLog",
    "check_reference",
    "compare_fixed",
    "default_reference",
    "simulate",
    "simulate_tracking",
    "step",
    "validation_states",
    "with_payload",
]
