"""Identifiability: rank, base parameters, unidentifiable and unexcited directions.

Start with :func:`analyze`: ``analyze(robot)`` tells what no data of the robot
can identify (structural), ``analyze(Y, robot=robot)`` or ``analyze(dataset,
robot=robot)`` what these data excite. The members of the package::

    results.py      BaseParameters, RankAnalysis (and its text report)
    accumulator.py  RFactorAccumulator: the (p, p) factor R streamed over chunks
    qr.py           the QR math on R: tolerances, base columns, K, null space, directions
    notes.py        why blocks of a robot's parameters never enter its dynamics
    analysis.py     the entry points: analyze, structural_analysis, analyze_trajectory,
                    analyze_information, analyze_dataset

The math they share:

The regressor ``Y`` (stacked, shape (M, p)) maps parameters to torques,
``tau = Y theta``. What any data can identify is its row space; what no data
of this robot can identify is the null space of the *structural* regressor
(Y stacked over generic states). Every quantity here depends on ``Y`` only
through its Gram matrix ``A = Y^T Y`` (the information matrix), so the
analysis runs on any factor ``R`` with ``R^T R = A``: a ``(p, p)`` triangular
factor accumulated chunk by chunk (``R <- qr([R; Y_chunk])``), never the
stacked ``Y`` of a million samples.

Column scaling. Parameters have different units, so rank decisions are made on
the column-scaled regressor ``Y_s = Y S^-1``, ``S = diag(||y_j||)``; a column
with ``||y_j|| <= tol * max_k ||y_k||`` counts as zero (the parameter never
enters the data).

Tolerance ``tol`` (relative, dimensionless). The numerical rank is the number
of singular values of ``Y_s`` above ``tol * sigma_max(Y_s)``. Default for a
regressor or a robot: ``max(max(M, p) * eps, 1e-8)`` (:func:`default_tolerance`;
``eps`` = 2.2e-16). The round-off part is ``numpy.linalg.matrix_rank``'s; the
floor :data:`TOLERANCE_FLOOR` = 1e-8 catches couplings that exist only through
rounded numbers of a URDF (``rpy="1.5708"`` for pi/2, offsets of 1e-7 m): on
kinova and bravo7 they give columns of relative size 1e-7..1e-10 that column
scaling would otherwise promote to "identifiable" parameters no data could
resolve (a scaled condition number of 1e8 leaves no digit of a double). For an
information matrix the default is ``p * sqrt(eps)`` (1e-6 for p = 70): forming
``Y^T Y`` squares the condition number, so singular values below about
``sqrt(eps) * sigma_max`` are lost in round-off.

Base parameters (Gautier's QR method). The columns of ``Y_s`` are processed in
parameter order with a Gram-Schmidt QR; a column whose diagonal element
``|R_jj|`` (its distance to the span of the columns kept so far) is at most
``tol * sigma_max`` is pivoted to the end: it is *dependent*. The kept columns
are the *independent* ones, ``Y = [Y_1 Y_2] P``, and ``Y_2 = Y_1 K`` with
``K = R_11^-1 R_12``, so::

    Y theta = Y_1 (theta_1 + K theta_2) = Y_1 theta_base

Keeping the earliest independent columns is deterministic (no ties) and
regroups later bodies' parameters into earlier ones, the way the symbolic
rules do (``panda_joint2.Izz + 0.0841*panda_joint3.m``). Should this ordered
selection disagree with the SVD rank, the first ``rank`` pivots of LAPACK's
column-pivoted QR (``dgeqp3``, first maximum wins ties) are used instead.

Unidentifiable directions: the columns of ``N = P^T [-K; I]``, one per
dependent parameter: moving ``theta`` along ``e_d - K[:, d] theta_1`` leaves
every torque unchanged. This basis is sparse and readable by construction.

Clean-up. A scaled regrouping coefficient ``|K_id| ||y_d|| / ||y_i||`` below
:data:`ROUNDOFF_THRESHOLD` (1e-10) is round-off of the solve and is set to zero
in ``K``; expressions also drop terms below :data:`COEFFICIENT_THRESHOLD`
(1e-6: such couplings come from URDF angles like ``1.5708`` for pi/2) and print
four significant digits. ``K`` and ``null_space`` keep those small terms, so
``Y @ null_space`` vanishes to round-off.
"""

from ..errors import format_direction
from .accumulator import RFactorAccumulator
from .analysis import (
    MIN_SAMPLES,
    ROWS_PER_PARAMETER,
    analyze,
    analyze_dataset,
    analyze_information,
    analyze_trajectory,
    structural_analysis,
)
from .qr import (
    COEFFICIENT_THRESHOLD,
    EXCITATION_TOLERANCE,
    REGROUPED_NOTE,
    ROUNDOFF_THRESHOLD,
    TOLERANCE_FLOOR,
    default_tolerance,
    has_regrouped,
)
from .results import BaseParameters, RankAnalysis

__all__ = [
    "COEFFICIENT_THRESHOLD",
    "EXCITATION_TOLERANCE",
    "MIN_SAMPLES",
    "REGROUPED_NOTE",
    "ROUNDOFF_THRESHOLD",
    "ROWS_PER_PARAMETER",
    "TOLERANCE_FLOOR",
    "BaseParameters",
    "RFactorAccumulator",
    "RankAnalysis",
    "analyze",
    "analyze_dataset",
    "analyze_information",
    "analyze_trajectory",
    "default_tolerance",
    "format_direction",
    "has_regrouped",
    "structural_analysis",
]
