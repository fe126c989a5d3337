"""Payload and drive-gain identification on the regressor of the robot (Gautier & Briot).

A payload rigidly attached to a frame ``f`` of the robot (a link or operational frame
such as ``tool0``) is one more rigid body on the parent joint ``j`` of ``f``. Its 10
standard parameters expressed in ``f``::

    phi = [m, h_x, h_y, h_z, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz]   [kg, kg m, kg m^2]

(first moment ``h = m c`` [kg m], inertia ``I_O`` about the origin of ``f``) move to
the frame of joint ``j`` by the spatial transform ``jMf = (R, p)`` of the frame
placement (Pinocchio's ``Inertia.se3Action``), a linear map ``phi_j = T(jMf) phi``::

    m_j = m
    h_j = R h + m p
    I_j = R I_O R^T - [R h]x [p]x - [p]x [R h]x - m [p]x^2

so that the payload adds, to the joint torques, the columns of body ``j`` of the
joint torque regressor mapped by ``T`` (:func:`payload_regressor`)::

    tau_p = Y_j(q, dq, ddq) T phi = Y_p(q, dq, ddq) phi        (nv,)

This is ``J_f(q)^T w_f``, with ``w_f`` the payload's wrench from Pinocchio's
``frameBodyRegressor``; the tests check both forms against ``pinocchio.rnea`` on a
model whose ``inertias[j]`` carry the payload.

Payload identification (:func:`identify_payload`). Unloaded runs ``tau = Y_b beta``
and loaded runs ``tau = Y_b beta + Y_p phi`` are solved jointly in one least squares
for ``[beta, psi]``, where ``beta`` are the robot's base parameters and
``psi = phi[ind] + K phi[dep]`` the base parameters of the payload: the structural
rank analysis of ``Y_p`` (at random states) says which combinations of ``phi`` enter
the torques at all (a payload on the last joint of a planar arm, for example, never
shows its inertia about the other axes). Since ``Y_p = Y_b E T`` always lies in the
span of the robot's base columns, the loaded runs alone fix only ``beta + E T phi``;
the unloaded runs separate the two. With ``known_base`` (an earlier identification)
the unloaded runs are replaced by that estimate: ``tau - Y_b beta = Y_p psi``, and the
covariance of ``beta`` is propagated into that of ``psi``.

The results are converted to the centre of mass (:func:`payload_quantities`)::

    c = h / m                                  [m, in f]
    I_c = I_O - m ((c.c) 1 - c c^T)            [kg m^2, about the CoM, axes of f]

with standard deviations by the delta method, ``std_i = sqrt(G_i Cov(phi) G_i^T)``,
``G`` the Jacobian of ``(m, c, I_c)`` with respect to ``phi``. A quantity is
identifiable when every standard payload parameter its formula involves is
(e.g. ``com.x`` needs ``m`` and ``h_x``; ``inertia.Ixx`` needs ``I_xx``, ``m``, ``h_y``,
``h_z``); the others are reported as ``None`` and named.

Physical consistency (``consistent=True``): the payload's pseudo-inertia
``J(phi) = [[0.5 tr(I_O) 1 - I_O, h], [h^T, m]]`` must be positive definite. The least
squares quadratic form restricted to ``psi`` (``(psi - psi_hat)^T Cov(psi)^-1
(psi - psi_hat)``, the robot's ``beta`` minimised out) is minimised under the single
4 x 4 linear matrix inequality ``J(R psi + N z) >= eps 1`` (``z`` spans the
unidentifiable directions ``N``, free to make ``J`` feasible): the one-body case of
the semidefinite program of :mod:`manip_id.estimators.consistent` (cvxpy and
Clarabel) without a prior. ``beta`` follows by its conditional least squares
``beta = beta_hat - A_bb^-1 A_bp (psi - psi_hat)``. The result carries the eigenvalue
test of ``J`` computed afterwards with NumPy; the standard deviations stay those of
the unconstrained fit.

Drive gains (:func:`identify_drive_gains`, Gautier & Briot 2014, "Global identification
of joint drive gains and dynamic parameters of robots"). The logs hold motor currents
``i_j`` [A] where torques should be; ``tau_j = g_j i_j`` with unknown gains ``g``
[N m / A]. Unloaded and loaded runs give the homogeneous system::

    D(i) g - Y_b beta - Y_p phi = 0

which data fix only up to one common scale. A known payload mass (and optionally its
centre of mass and inertia) fixes that scale: the known columns move to the right::

    [D(i), -Y_b, -Y_pu] [g; beta; psi_u] = Y_pk phi_k

solved by ordinary least squares (``method="ols"``; ``"wls"`` weights each joint by its
residual variance) or total least squares (``"tls"``: the smallest right singular
vector of the column-scaled ``[W, -y]``, normalised to the known scale). Those put the
noisy currents in the regressor, an errors-in-variables problem: a gain shrinks by
about ``sigma_i^2 / mean(i^2)`` (1.3 % on a wrist whose current is 3 times its noise)
and the standard deviations do not see it. The default ``"ml"`` starts from OLS and
minimises the residual in current units, ``sum_j ||i_j - (Y_b beta + Y_p phi)_j / g_j||^2
/ sigma_j^2``, by Gauss-Newton on the same accumulated sums: the maximum-likelihood
estimate for Gaussian current noise, unbiased with honest standard deviations.
A joint whose gain the data do not fix (its gain in a direction the data leave
unexcited, e.g. a joint whose current never moves) is named in a warning and its
gain reported as ``None``. The gains feed the torque scale of
``manip-id identify --torque-scale-from RESULT.json`` (:func:`load_torque_scale`).

Modules: :mod:`~manip_id.payload.geometry` (frames, the payload regressor, quantities),
:mod:`~manip_id.payload.runs` (run input and information sums, local or on Dask),
:mod:`~manip_id.payload.known` (known base parameters, torque scale from a result),
:mod:`~manip_id.payload.solve` (the payload solve), :mod:`~manip_id.payload.gains` and
:mod:`~manip_id.payload.gain_estimators` (drive gains), :mod:`~manip_id.payload.result`
(the result types), :mod:`~manip_id.payload.options` (the settings).
"""

from ..errors import PayloadWarning
from .gains import check_known_payload, identify_drive_gains
from .geometry import (
    INERTIA_COMPONENTS,
    PAYLOAD_NAMES,
    QUANTITY_NAMES,
    QUANTITY_UNITS,
    PayloadFrame,
    frame_names,
    payload_frame,
    payload_identifiability,
    payload_quantities,
    payload_regressor,
    payload_transform,
    pseudo_inertia_eigenvalues,
    standard_from_quantities,
)
from .known import KnownBase, load_known_base, load_torque_scale
from .options import GAIN_METHODS, PAYLOAD_METHODS, DriveGainOptions, PayloadOptions
from .result import DriveGainResult, PayloadEstimate, PayloadResult
from .runs import RunSums, run_sums
from .solve import consistent_payload, identify_payload

__all__ = [
    "DriveGainOptions",
    "DriveGainResult",
    "GAIN_METHODS",
    "INERTIA_COMPONENTS",
    "KnownBase",
    "PAYLOAD_METHODS",
    "PAYLOAD_NAMES",
    "PayloadEstimate",
    "PayloadFrame",
    "PayloadOptions",
    "PayloadResult",
    "PayloadWarning",
    "QUANTITY_NAMES",
    "QUANTITY_UNITS",
    "RunSums",
    "consistent_payload",
    "frame_names",
    "identify_drive_gains",
    "identify_payload",
    "check_known_payload",
    "load_known_base",
    "load_torque_scale",
    "payload_frame",
    "payload_identifiability",
    "payload_quantities",
    "payload_regressor",
    "payload_transform",
    "pseudo_inertia_eigenvalues",
    "run_sums",
    "standard_from_quantities",
]
