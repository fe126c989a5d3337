"""Excitation trajectories: finite Fourier series per joint (Swevers et al.) and their design.

Members: ``fourier.py`` (the series, angles -> configurations), ``limits.py``
(limit checks with a margin), ``excitation.py`` (random trajectories within the
limits, the condition number of one), ``rest.py`` (the series at rest in a start
pose at both ends), ``information.py`` (the information about the base parameters
and the D / cond / E criteria with exact gradients), ``constraints.py`` (limits,
torques and clearance on a time grid), ``world.py`` (collision geometry and the
world file), ``verify.py`` (the check on the run's grid), ``design.py`` (the front
door :func:`design_excitation`), ``writers.py`` (CSV, NPZ, JSON, ROS 2 YAML,
URScript). The math they share:

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
design (:func:`random_trajectory`, :func:`design_excitation`) still needs
finite bounds: it uses
:meth:`Robot.sampling_bounds` ([-pi, pi] for unset positions) and
:meth:`Robot.velocity_bounds` (2 [unit/s] for unset velocities).

Design (:func:`design_excitation`) maximizes the information of the base
regressor ``Y_b(q(t), dq(t), ddq(t))`` (joint terms included) over the free
coefficients of the rest-to-rest series, subject to the limits, the nominal
torques and the clearance, and checks the result on the run's own grid.
"""

from .design import (
    DesignOptions,
    ExcitationDesign,
    PriorInformation,
    design_excitation,
)
from .design_file import read_design
from .excitation import (
    base_columns,
    excitation_condition_number,
    random_trajectory,
)
from .fourier import DEFAULT_WF, FourierTrajectory, trajectory_to_configuration
from .limits import DEFAULT_CHECK_POINTS, LimitUsage, check_limits
from .rest import RestFourier
from .world import World, WorldObject
from .writers import FORMATS, format_of, write_trajectory

__all__ = [
    "DEFAULT_CHECK_POINTS",
    "DEFAULT_WF",
    "FORMATS",
    "DesignOptions",
    "ExcitationDesign",
    "FourierTrajectory",
    "LimitUsage",
    "PriorInformation",
    "RestFourier",
    "World",
    "WorldObject",
    "base_columns",
    "check_limits",
    "design_excitation",
    "excitation_condition_number",
    "format_of",
    "random_trajectory",
    "read_design",
    "trajectory_to_configuration",
    "write_trajectory",
]
