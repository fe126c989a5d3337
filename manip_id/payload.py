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
"""

from __future__ import annotations

import json
import math
import time
import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pinocchio as pin

from ._checks import as_float_array, check_finite
from .errors import DataError, InputError, RankDeficiencyError
from .estimators import InformationAccumulator, LeastSquaresSolution, solve_accumulator
from .identifiability import BaseParameters, RankAnalysis, analyze, analyze_information
from .regressor import DEFAULT_CHUNK, check_states
from .robot import INERTIAL_NAMES, Robot

#: The payload's standard parameter names, in Pinocchio's order, expressed in its frame.
PAYLOAD_NAMES: tuple[str, ...] = tuple(f"payload.{n}" for n in INERTIAL_NAMES)
#: Components of an inertia matrix, in the order of the JSON and of ``phi[4:]``.
INERTIA_COMPONENTS: tuple[str, ...] = ("Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")
#: Names of the derived quantities, in the order of :func:`payload_quantities`.
QUANTITY_NAMES: tuple[str, ...] = (
    "mass",
    "com.x",
    "com.y",
    "com.z",
    *(f"inertia.{c}" for c in INERTIA_COMPONENTS),
)
QUANTITY_UNITS: tuple[str, ...] = ("kg", "m", "m", "m", *("kg m^2",) * 6)
#: Which standard payload parameters (indices of ``phi``) each derived quantity needs.
_DEPENDS: tuple[tuple[int, ...], ...] = (
    (0,),
    (0, 1),
    (0, 2),
    (0, 3),
    (4, 0, 2, 3),  # Ixx: m, h_y, h_z
    (5, 0, 1, 2),  # Ixy: m, h_x, h_y
    (6, 0, 1, 3),  # Iyy: m, h_x, h_z
    (7, 0, 1, 3),  # Ixz: m, h_x, h_z
    (8, 0, 2, 3),  # Iyz: m, h_y, h_z
    (9, 0, 1, 2),  # Izz: m, h_x, h_y
)
_SYM6 = ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2))
#: Structural analysis of the payload columns: random states drawn.
STRUCTURAL_STATES = 200
#: Significance level of the test that the loaded runs show a payload at all.
PAYLOAD_SIGNIFICANCE = 1e-3
#: Margin of the pseudo-inertia LMI of the consistent payload [SI units].
CONSISTENCY_MARGIN = 1e-9
#: Relative eigenvalue tolerance of the consistency test (that of :mod:`manip_id.consistency`).
_EIG_TOL = 1e-10
#: Methods of :func:`identify_payload` and :func:`identify_drive_gains`.
PAYLOAD_METHODS: tuple[str, ...] = ("wls", "ols")
GAIN_METHODS: tuple[str, ...] = ("ml", "ols", "wls", "tls")


class PayloadWarning(UserWarning):
    """A payload or drive-gain result the user should look at (also in ``result.warnings``)."""


# ====================================================================== geometry
def payload_transform(placement: pin.SE3) -> np.ndarray:
    """The linear map ``T`` with ``phi_joint = T @ phi_frame``, shape (10, 10).

    ``placement`` is the frame's placement in its parent joint's frame (``jMf``); ``T``
    equals ``placement.act(pin.Inertia.FromDynamicParameters(phi)).toDynamicParameters()``
    for every ``phi`` (the formula of the module docstring, linear in ``phi``, so that
    it also holds for parameter vectors that are no physical inertia).
    """
    R = np.asarray(placement.rotation)
    p = np.asarray(placement.translation)
    P = pin.skew(p)

    def act(phi: np.ndarray) -> np.ndarray:
        m, h = phi[0], phi[1:4]
        inertia = _sym3(phi[4:])
        H = pin.skew(R @ h)
        Ij = R @ inertia @ R.T - H @ P - P @ H - m * P @ P  # [kg m^2]
        return np.r_[m, R @ h + m * p, [Ij[a, b] for a, b in _SYM6]]

    return np.stack([act(e) for e in np.eye(10)], axis=1)


def _sym3(six) -> np.ndarray:
    xx, xy, yy, xz, yz, zz = six
    return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])


@dataclass(frozen=True)
class PayloadFrame:
    """Where a payload sits: a frame of the robot and its parent joint.

    Attributes
    ----------
    name: frame name (as in the URDF: a link, an operational frame, a joint)
    frame_id: Pinocchio frame index in ``robot.model``
    joint_id: Pinocchio index of the parent joint (1 .. njoints - 1)
    joint_name: its name
    body: position of that joint's body in the parameter vector (0-based)
    placement: the frame in the joint's frame, ``jMf``
    transform: ``T`` of :func:`payload_transform`, shape (10, 10)
    """

    name: str
    frame_id: int
    joint_id: int
    joint_name: str
    body: int
    placement: pin.SE3
    transform: np.ndarray

    @property
    def columns(self) -> slice:
        """The regressor columns of the parent joint's body."""
        return slice(10 * self.body, 10 * self.body + 10)


def frame_names(robot: Robot) -> list[str]:
    """Frames a payload can be attached to: every frame on a moving joint, model order."""
    model = robot.model
    out: list[str] = []
    for f in model.frames:
        if f.parentJoint > 0 and f.name not in out:
            out.append(f.name)
    return out


def payload_frame(robot: Robot, frame: str) -> PayloadFrame:
    """Look up ``frame`` in ``robot``; unknown or fixed frames raise, listing the valid ones."""
    if not isinstance(frame, str) or not frame:
        raise InputError(f"frame must be a frame name of the robot, got {frame!r}")
    model = robot.model
    valid = frame_names(robot)
    if not model.existFrame(frame):
        raise InputError(
            f"robot {robot.name!r} has no frame {frame!r}; frames on moving joints: "
            + ", ".join(valid)
        )
    fid = int(model.getFrameId(frame))
    f = model.frames[fid]
    jid = int(f.parentJoint)
    if jid == 0:
        raise InputError(
            f"frame {frame!r} of {robot.name!r} is fixed to the base: a payload there loads no "
            "joint; frames on moving joints: " + ", ".join(valid)
        )
    placement = pin.SE3(f.placement)
    return PayloadFrame(
        name=frame,
        frame_id=fid,
        joint_id=jid,
        joint_name=str(model.names[jid]),
        body=jid - 1,
        placement=placement,
        transform=payload_transform(placement),
    )


def payload_regressor(robot: Robot, frame: str | PayloadFrame, q, dq, ddq) -> np.ndarray:
    """Torque regressor of a payload at ``frame``: ``tau_p = Y_p @ phi``.

    Parameters
    ----------
    frame: a frame name of ``robot`` or a :class:`PayloadFrame`
    q: positions [rad or m], shape (nq,) or (N, nq); dq, ddq: shape (nv,) or (N, nv)

    Returns
    -------
    ``Y_p`` of shape (nv, 10) or (N, nv, 10) [N m per unit of ``phi``], ``phi`` the
    payload's parameters in the frame (module docstring).
    """
    pf = frame if isinstance(frame, PayloadFrame) else payload_frame(robot, frame)
    batched, (q, dq, ddq) = check_states(robot, q=q, dq=dq, ddq=ddq)
    ev = robot.evaluator
    if not batched:
        return ev.regressor(q, dq, ddq)[:, pf.columns] @ pf.transform
    out = np.empty((q.shape[0], robot.nv, 10))
    for c in ev.iter_regressor(q, dq, ddq, DEFAULT_CHUNK):
        out[c.start : c.stop] = c.Y[:, :, pf.columns] @ pf.transform
    return out


def payload_identifiability(
    robot: Robot,
    frame: str | PayloadFrame,
    *,
    columns: Sequence[int] | np.ndarray | None = None,
    seed: int = 0,
) -> RankAnalysis:
    """Structural rank analysis of the payload columns: which combinations enter the torques.

    ``Y_p`` stacked over :data:`STRUCTURAL_STATES` random states within the limits;
    ``columns`` restricts it to some of the 10 parameters (the unknown ones of a
    drive-gain problem). The result's ``base`` holds the payload base parameters and
    ``unidentifiable`` the directions no data can see. Cached on the robot per frame
    and columns (treat the result as read-only).
    """
    pf = frame if isinstance(frame, PayloadFrame) else payload_frame(robot, frame)
    cols = np.arange(10) if columns is None else np.asarray(columns, dtype=np.intp)
    cache = robot.__dict__.setdefault("_payload_identifiability", {})
    key = (pf.name, tuple(int(c) for c in cols), int(seed), robot.n_parameters)
    if key not in cache:
        q, dq, ddq = robot.random_states(STRUCTURAL_STATES, seed=seed)
        Yp = payload_regressor(robot, pf, q, dq, ddq)[:, :, cols]
        cache[key] = analyze(Yp, names=[PAYLOAD_NAMES[i] for i in cols])
    return cache[key]


# ====================================================================== quantities
def payload_quantities(phi) -> tuple[np.ndarray, np.ndarray]:
    """Mass, centre of mass and inertia about the CoM from ``phi`` (10,), and their Jacobian.

    Returns ``(values, G)``: ``values = [m, c_x, c_y, c_z, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]``
    [kg, m, kg m^2] (inertia about the CoM, axes of the frame) and ``G = d values /
    d phi``, shape (10, 10). ``m`` must be non-zero.
    """
    phi = as_float_array(phi, "phi", ndim=1)
    if phi.shape != (10,):
        raise InputError(f"phi.shape={phi.shape} but a payload has 10 parameters")
    m, h = float(phi[0]), phi[1:4]
    if m == 0.0:
        raise InputError("the payload mass is zero: no centre of mass")
    c = h / m  # [m]
    hh = float(h @ h)
    Ic = _sym3(phi[4:]) - (hh / m) * np.eye(3) + np.outer(h, h) / m  # [kg m^2]
    values = np.r_[m, c, [Ic[a, b] for a, b in _SYM6]]
    G = np.zeros((10, 10))
    G[0, 0] = 1.0
    G[1:4, 0] = -h / m**2
    G[1:4, 1:4] = np.eye(3) / m
    dm = (hh / m**2) * np.eye(3) - np.outer(h, h) / m**2
    for i, (a, b) in enumerate(_SYM6):
        G[4 + i, 4 + i] = 1.0
        G[4 + i, 0] = dm[a, b]
        for k in range(3):
            e = np.zeros(3)
            e[k] = 1.0
            dk = -(2.0 * h[k] / m) * np.eye(3) + (np.outer(e, h) + np.outer(h, e)) / m
            G[4 + i, 1 + k] = dk[a, b]
    return values, G


def standard_from_quantities(mass: float, com=None, inertia=None) -> np.ndarray:
    """``phi`` (10,) of a payload of ``mass`` [kg], ``com`` (3,) [m] and ``inertia`` about
    the CoM (6,: Ixx, Ixy, Iyy, Ixz, Iyz, Izz) [kg m^2]; missing parts are zero."""
    c = np.zeros(3) if com is None else as_float_array(com, "com", ndim=1)
    Ic = np.zeros(6) if inertia is None else as_float_array(inertia, "inertia", ndim=1)
    if c.shape != (3,) or Ic.shape != (6,):
        raise InputError(f"com has 3 entries and inertia 6, got {c.shape} and {Ic.shape}")
    m = float(mass)
    IO = _sym3(Ic) + m * (float(c @ c) * np.eye(3) - np.outer(c, c))
    return np.r_[m, m * c, [IO[a, b] for a, b in _SYM6]]


def pseudo_inertia_eigenvalues(phi) -> np.ndarray:
    """Eigenvalues (ascending) of the payload's pseudo-inertia ``J(phi)``, shape (4,)."""
    from .consistency import pseudo_inertia

    return np.linalg.eigvalsh(pseudo_inertia(np.asarray(phi, dtype=float)))


# ====================================================================== results
def _fit_dict(r) -> dict:
    """The JSON of what a payload and a drive-gain result share: the payload, the sample
    counts, the errors, the rows left out, the base parameters, solver, warnings, timings."""
    return {
        "payload": r.payload.to_dict(),
        "n_samples": dict(r.n_samples),
        "relative_error": {k: _f(v) for k, v in r.relative_error.items()},
        "relative_error_per_joint": {
            k: [_f(x) for x in v] for k, v in r.relative_error_per_joint.items()
        },
        "rows_left_out": dict(zip(r.dof_names, (int(x) for x in r.rows_left_out), strict=True)),
        "sigma2": _f(r.sigma2),
        "condition_number": _f(r.condition_number),
        "base_parameters": [
            {"name": n, "expression": e, "value": _f(x), "std": _f(s)}
            for n, e, x, s in zip(
                r.base_names, r.base_expressions, r.base_estimate, r.base_std, strict=True
            )
        ],
        "solver": r.solver,
        "warnings": list(r.warnings),
        "timings": {k: round(float(v), 6) for k, v in r.timings.items()},
    }


def _f(x):
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


@dataclass(frozen=True)
class PayloadEstimate:
    """An identified (or partly given) payload, in its frame, with its uncertainty.

    Attributes
    ----------
    frame: frame name; parent_joint: the joint carrying it
    standard: ``phi`` (10,): m [kg], h = m c [kg m], inertia about the frame origin
        [kg m^2]; the representative with zero unidentifiable components
    standard_std: standard deviations of ``phi`` (10,) (NaN where not identifiable)
    values: ``[m, c (3), I_c (6)]`` [kg, m, kg m^2] (inertia about the CoM, frame axes)
    std: their standard deviations (delta method), shape (10,); NaN where not identifiable
    identifiable: per quantity of :data:`QUANTITY_NAMES`, whether the data fix it
    standard_identifiable: per standard parameter, whether the data fix it
    known: per quantity, whether it was given (drive gains with a known payload)
    combinations: the payload base parameters the data fix, in standard names
    unidentifiable: the directions of ``phi`` no data can see
    min_eigenvalue: smallest eigenvalue of the pseudo-inertia ``J(phi)`` (NumPy eigvalsh)
        of :attr:`standard`
    physically_consistent: ``min_eigenvalue > 1e-10 max|eig J|``; ``None`` when some
        directions of ``phi`` are not identifiable and no consistent fit chose them
    """

    frame: str
    parent_joint: str
    standard: np.ndarray
    standard_std: np.ndarray
    values: np.ndarray
    std: np.ndarray
    identifiable: np.ndarray
    standard_identifiable: np.ndarray
    known: np.ndarray
    combinations: list[str]
    unidentifiable: list[str]
    min_eigenvalue: float
    physically_consistent: bool | None

    @property
    def mass(self) -> float:
        """Mass [kg]."""
        return float(self.values[0])

    @property
    def com(self) -> np.ndarray:
        """Centre of mass in the frame [m], shape (3,)."""
        return self.values[1:4].copy()

    @property
    def inertia(self) -> np.ndarray:
        """Inertia about the CoM (Ixx, Ixy, Iyy, Ixz, Iyz, Izz) [kg m^2], shape (6,)."""
        return self.values[4:].copy()

    def _shown(self, i: int, arr: np.ndarray):
        return _f(arr[i]) if (self.identifiable[i] or self.known[i]) else None

    def to_dict(self) -> dict:
        """The JSON ``payload`` block; what the data do not identify is ``None``."""
        v = [self._shown(i, self.values) for i in range(10)]
        s = [
            None if self.known[i] else (_f(self.std[i]) if self.identifiable[i] else None)
            for i in range(10)
        ]
        return {
            "frame": self.frame,
            "parent_joint": self.parent_joint,
            "mass": v[0],
            "mass_std": s[0],
            "com": v[1:4],
            "com_std": s[1:4],
            "inertia": v[4:],
            "inertia_std": s[4:],
            "inertia_components": list(INERTIA_COMPONENTS),
            "units": {"mass": "kg", "com": "m", "inertia": "kg m^2 (about the CoM, frame axes)"},
            "identifiable": [
                n for n, ok in zip(QUANTITY_NAMES, self.identifiable, strict=True) if ok
            ],
            "not_identifiable": [
                n
                for n, ok, kn in zip(QUANTITY_NAMES, self.identifiable, self.known, strict=True)
                if not ok and not kn
            ],
            "known": [n for n, kn in zip(QUANTITY_NAMES, self.known, strict=True) if kn],
            "identifiable_combinations": list(self.combinations),
            "unidentifiable_directions": list(self.unidentifiable),
            "standard_parameters": [
                {
                    "name": n,
                    "value": _f(x) if ok else None,
                    "std": _f(sd) if ok else None,
                    "identifiable": bool(ok),
                }
                for n, x, sd, ok in zip(
                    PAYLOAD_NAMES,
                    self.standard,
                    self.standard_std,
                    self.standard_identifiable,
                    strict=True,
                )
            ],
            "physically_consistent": (
                None if self.physically_consistent is None else bool(self.physically_consistent)
            ),
            "pseudo_inertia_min_eigenvalue": _f(self.min_eigenvalue),
        }

    def table(self) -> str:
        """One line per quantity: value, standard deviation, or why it is missing."""
        lines = [f"payload at {self.frame} (parent joint {self.parent_joint}):"]
        for i, (n, u) in enumerate(zip(QUANTITY_NAMES, QUANTITY_UNITS, strict=True)):
            if self.known[i]:
                lines.append(f"  {n:<12} {self.values[i]:13.6g} {u:<7} (given)")
            elif self.identifiable[i]:
                lines.append(f"  {n:<12} {self.values[i]:13.6g} {u:<7} +- {self.std[i]:.3g}")
            else:
                lines.append(f"  {n:<12} {'-':>13} {u:<7} not identifiable from these torques")
        if self.physically_consistent is None:
            lines.append(
                "  physically consistent: not decided (unidentifiable directions are free; "
                "a consistent fit chooses them)"
            )
        else:
            state = "yes" if self.physically_consistent else "NO"
            lines.append(
                f"  physically consistent: {state} (smallest pseudo-inertia eigenvalue "
                f"{self.min_eigenvalue:.3g})"
            )
        return "\n".join(lines)


@dataclass(frozen=True)
class PayloadResult:
    """Payload identification: the payload, the robot's base parameters, the fit.

    Attributes
    ----------
    robot_name, method ("ols" or "wls"), payload (:class:`PayloadEstimate`)
    base_names, base_expressions: the robot's base parameters
    base_estimate, base_std: their estimate (or the known one) and standard deviations (r,)
    known_base: whether the base parameters came from an earlier identification
    consistent: whether the payload was constrained to be physically consistent
    sigma2: residual variance [(N m)^2]; condition_number: of the joint regressor
    n_samples: {"unloaded": N_u, "loaded": N_l}
    relative_error: {"unloaded": e_u, "loaded": e_l} (``||tau - tau_hat|| / ||tau||``)
    relative_error_per_joint: the same per joint, (nv,) each
    rows_left_out: per joint, rows dropped by the velocity deadband
    payload_test: the Wald statistic that the loaded runs show a payload, its degrees
        of freedom and p-value
    solver: how it was solved; warnings: what the user should know; timings [s]
    runs: {"unloaded": [...], "loaded": [...]}, per run what its source reported
        (:attr:`RunSums.runs`: a file's data quality and preprocessing, read where the
        run was accumulated; None for arrays)
    """

    robot_name: str
    method: str
    payload: PayloadEstimate
    base_names: list[str]
    base_expressions: list[str]
    base_estimate: np.ndarray
    base_std: np.ndarray
    known_base: bool
    consistent: bool
    sigma2: float
    condition_number: float
    n_samples: dict
    relative_error: dict
    relative_error_per_joint: dict
    rows_left_out: np.ndarray
    payload_test: dict
    solver: str
    dof_names: list[str]
    warnings: list[str] = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    runs: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """JSON-ready: ``payload`` and the fit (lists, floats, None)."""
        return {
            "command": "payload",
            "robot": self.robot_name,
            "joints": list(self.dof_names),
            "method": self.method,
            "consistent": self.consistent,
            "known_base": self.known_base,
            **_fit_dict(self),
            "payload_test": {
                k: _f(v) if k != "dof" else int(v) for k, v in self.payload_test.items()
            },
        }

    def table(self) -> str:
        """A readable summary."""
        re = self.relative_error
        lines = [
            f"payload identification of {self.robot_name} ({self.method.upper()}"
            + (", consistent" if self.consistent else "")
            + (", known base" if self.known_base else "")
            + f"): {self.n_samples['unloaded']} unloaded + {self.n_samples['loaded']} loaded "
            "samples",
            self.payload.table(),
            "relative torque error: "
            + ", ".join(f"{k} {100 * v:.3f} %" for k, v in re.items() if v is not None),
            f"solver: {self.solver}",
        ]
        return "\n".join(lines)


@dataclass(frozen=True)
class DriveGainResult:
    """Drive gains ``tau_j = g_j i_j`` [N m / A per joint], with the base and payload parameters.

    Attributes
    ----------
    robot_name, method ("ols" or "tls"), dof_names
    gains, gains_std: shape (nv,) [N m / A] (NaN where not determined)
    determined: per joint, whether the data fix its gain
    payload: :class:`PayloadEstimate` (``known`` marks the given quantities)
    base_names, base_expressions, base_estimate, base_std: the robot's base parameters
        [in torque units]
    sigma2: residual variance, [A^2] for "ml" (current units), [(N m)^2] otherwise;
        condition_number: of the homogeneous system with the known columns moved right
    n_samples, relative_error, relative_error_per_joint: as :class:`PayloadResult`, the
        error relative to the torques ``g_j i_j``
    rows_left_out: per joint, rows dropped by the velocity deadband
    solver, warnings, timings, runs (as :class:`PayloadResult`)
    """

    robot_name: str
    method: str
    dof_names: list[str]
    gains: np.ndarray
    gains_std: np.ndarray
    determined: np.ndarray
    payload: PayloadEstimate
    base_names: list[str]
    base_expressions: list[str]
    base_estimate: np.ndarray
    base_std: np.ndarray
    sigma2: float
    condition_number: float
    n_samples: dict
    relative_error: dict
    relative_error_per_joint: dict
    rows_left_out: np.ndarray
    solver: str
    warnings: list[str] = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    runs: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """JSON-ready: ``drive_gains`` (one per joint, in joint order) and ``torque_scale``."""
        gains = []
        for j, name in enumerate(self.dof_names):
            ok = bool(self.determined[j])
            g, s = (_f(self.gains[j]), _f(self.gains_std[j])) if ok else (None, None)
            pct = None
            if ok and g not in (None, 0.0) and s is not None:
                pct = 100.0 * s / abs(g)
            gains.append({"joint": name, "gain": g, "std": s, "std_percent": pct, "determined": ok})
        return {
            "command": "drive-gains",
            "robot": self.robot_name,
            "joints": list(self.dof_names),
            "method": self.method,
            "drive_gains": gains,
            "torque_scale": [g["gain"] for g in gains],
            "units": "N m / A (N / A for prismatic joints): torque = gain * current",
            **_fit_dict(self),
        }

    def table(self) -> str:
        """A readable summary: one line per joint gain, then the payload."""
        lines = [
            f"drive gains of {self.robot_name} ({self.method.upper()}): "
            f"{self.n_samples['unloaded']} unloaded + {self.n_samples['loaded']} loaded samples"
        ]
        w = max(len(n) for n in self.dof_names)
        for j, name in enumerate(self.dof_names):
            if self.determined[j]:
                pct = 100.0 * self.gains_std[j] / abs(self.gains[j]) if self.gains[j] else math.inf
                lines.append(
                    f"  {name:<{w}}  {self.gains[j]:12.6g} +- {self.gains_std[j]:.3g}  "
                    f"({pct:.3g} %)"
                )
            else:
                lines.append(f"  {name:<{w}}  {'-':>12}  not determined by these data")
        lines.append(self.payload.table())
        lines.append(f"solver: {self.solver}")
        return "\n".join(lines)


# ====================================================================== data blocks
@dataclass(frozen=True)
class _Run:
    """One run: a label, a function giving fresh blocks ``(q, dq, ddq, tau)``, joint names,
    and its arrays when it is in memory (for the check that loaded runs are not unloaded)."""

    label: str
    blocks: Callable[[], Iterable[tuple]]
    names: tuple | None = None
    arrays: tuple | None = None


@dataclass(frozen=True)
class _InMemory:
    """The blocks of a run held in memory: one block, the arrays themselves."""

    arrays: tuple

    def __call__(self) -> list[tuple]:
        return [self.arrays]


def _blocks(data, what: str) -> list[_Run]:
    """``data`` as a list of runs.

    Takes a Dataset (with ``ddq``), a tuple ``(q, dq, ddq, tau)`` of arrays, a function
    of no argument returning an iterable of such tuples (a long log read block by block,
    e.g. from :func:`manip_id.pipeline.iter_processed`), or a list of those.
    """
    if data is None:
        return []
    if (
        callable(data)
        or (hasattr(data, "tau") and hasattr(data, "q"))
        or (isinstance(data, tuple) and len(data) == 4 and np.ndim(data[0]) == 2)
    ):
        data = [data]
    out = []
    for k, item in enumerate(data):
        label = f"{what} run {k}"
        if callable(item):
            source = getattr(item, "label", None)  # e.g. a file read block by block
            out.append(_Run(label if not isinstance(source, str) else f"{label} ({source})", item))
            continue
        if hasattr(item, "tau") and hasattr(item, "q"):
            if getattr(item, "ddq", None) is None:
                raise InputError(
                    f"{what} dataset {k} has no accelerations (ddq): preprocess it first "
                    "(manip_id.signals.preprocess)"
                )
            arrays = (item.q, item.dq, item.ddq, item.tau)
            names = getattr(item, "joint_names", None)
        else:
            try:
                q, dq, ddq, tau = item
            except (TypeError, ValueError) as exc:
                raise InputError(
                    f"{what} data: each run must be a Dataset, a tuple (q, dq, ddq, tau) or a "
                    f"function returning such blocks; item {k} is {type(item).__name__}"
                ) from exc
            arrays, names = (q, dq, ddq, tau), None
        out.append(_Run(label, _InMemory(arrays), None if names is None else tuple(names), arrays))
    return out


def _check_block(robot: Robot, block: tuple, where: str, names=None):
    try:
        q, dq, ddq, tau = block
    except (TypeError, ValueError) as exc:
        raise InputError(f"{where}: each block must be a tuple (q, dq, ddq, tau)") from exc
    if names is not None and list(names) != list(robot.dof_names):
        raise DataError(
            f"{where} names the joints {list(names)} but robot {robot.name!r} has "
            f"{list(robot.dof_names)}"
        )
    try:
        batched, (q, dq, ddq) = check_states(robot, q=q, dq=dq, ddq=ddq)
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from exc
    if not batched:
        raise InputError(f"{where}: give N samples (2-D arrays), got q.shape={q.shape}")
    tau = as_float_array(tau, "tau", ndim=2)
    if tau.shape != dq.shape:
        raise InputError(
            f"{where}: tau.shape={tau.shape} but expected {dq.shape} (N, robot.nv={robot.nv})"
        )
    try:
        check_finite(tau, "tau", robot.dof_names)
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from exc
    return q, dq, ddq, tau


def _check_distinct(unloaded: list, loaded: list) -> None:
    """Loaded runs that are unloaded ones carry no payload information."""
    for i, lb in enumerate(loaded):
        for k, ub in enumerate(unloaded):
            if lb.arrays is None or ub.arrays is None:
                continue
            same = all(
                np.shape(a) == np.shape(b) and np.array_equal(np.asarray(a), np.asarray(b))
                for a, b in zip(lb.arrays, ub.arrays, strict=True)
            )
            if same:
                raise DataError(
                    f"loaded run {i} is the same data as unloaded run {k}: the loaded runs "
                    "carry no payload information (record them with the payload mounted)"
                )
    names = {tuple(b.names) for b in unloaded + loaded if b.names is not None}
    if len(names) > 1:
        raise DataError(
            "the unloaded and loaded runs name different joints: "
            + " vs ".join(str(list(n)) for n in sorted(names))
        )


Design = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True, eq=False)
class _PayloadDesign:
    """Rows of one chunk of the payload problem (picklable: a Dask task's argument).

    ``kind``: "unloaded" ``[Y_b, 0]``, "loaded" ``[Y_b, Y_p T]`` (unknowns ``[beta, psi]``)
    or "known" ``[Y_p T, Y_b]`` (loaded runs with a known base, unknowns ``[psi, beta]``);
    the right-hand side is the torque.
    """

    kind: str
    ind: np.ndarray  # the robot's base columns, (r,)
    cols: slice  # the payload's 10 columns of the parent joint
    T: np.ndarray  # payload base columns in those, (10, k)

    @property
    def n_cols(self) -> int:
        return int(self.ind.size + self.T.shape[1])

    def __call__(self, Y: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.kind == "unloaded":
            X = np.zeros((Y.shape[0], Y.shape[1], self.n_cols))
            X[:, :, : self.ind.size] = Y[:, :, self.ind]
            return X, tau
        Yp = Y[:, :, self.cols] @ self.T
        if self.kind == "loaded":
            return np.concatenate([Y[:, :, self.ind], Yp], axis=2), tau
        return np.concatenate([Yp, Y[:, :, self.ind]], axis=2), tau


@dataclass(frozen=True, eq=False)
class _GainDesign:
    """Rows ``[D(i), -Y_b, -Y_pu] [g; beta; psi_u] = Y_pk phi_k`` of one chunk (picklable).

    The "torque" columns of the run hold the motor currents ``i`` [A]; unloaded runs
    have no payload columns and a zero right-hand side.
    """

    loaded: bool
    ind: np.ndarray  # the robot's base columns, (r,)
    cols: slice  # the payload's 10 columns of the parent joint
    T_u: np.ndarray  # unknown payload base columns in those, (10, k_u)
    T_k: np.ndarray  # the known payload's torque direction, (10,)
    nv: int

    @property
    def n_cols(self) -> int:
        return int(self.nv + self.ind.size + self.T_u.shape[1])

    def __call__(self, Y: np.ndarray, cur: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n, nv, r = Y.shape[0], self.nv, self.ind.size
        diag = np.arange(nv)
        X = np.zeros((n, nv, self.n_cols))
        X[:, diag, diag] = cur
        X[:, :, nv : nv + r] = -Y[:, :, self.ind]
        if not self.loaded:
            return X, np.zeros((n, nv))
        X[:, :, nv + r :] = -(Y[:, :, self.cols] @ self.T_u)
        return X, Y[:, :, self.cols] @ self.T_k


@dataclass
class RunSums:
    """The information sums of some runs (what a Dask task returns; they add).

    Attributes
    ----------
    acc: the accumulated rows of the runs' design
    left_out: rows left out by the velocity deadband per joint, shape (nv,)
    runs: per run, in order, what its source reports (``summary()`` of a run given as
        a callable object that has one, e.g. a file's data quality and preprocessing;
        else None)
    """

    acc: InformationAccumulator
    left_out: np.ndarray
    runs: list = field(default_factory=list)

    def __add__(self, other: RunSums) -> RunSums:
        return RunSums(self.acc + other.acc, self.left_out + other.left_out, self.runs + other.runs)


def run_sums(
    robot: Robot,
    run: _Run,
    design: Design,
    chunk: int = DEFAULT_CHUNK,
    deadband: float | None = None,
) -> RunSums:
    """One run's information sums: the body of the local loop and of a Dask task.

    Reads the run's blocks (a file is read on the worker when the run's blocks come
    from a callable object that reads it), checks each against the robot and
    accumulates ``design(Y, tau) -> (X (n, nv, p), z (n, nv))`` over chunks of
    ``chunk`` samples. Rows of joint ``j`` with ``|dq_j| < deadband`` [rad/s] are left
    out (their row of X and z zeroed, which removes them from every sum).

    Parameters
    ----------
    robot: the robot (:func:`manip_id.fleet.portable_robot` for a worker)
    run: the run (its label, blocks and joint names); picklable for a worker
    design: the rows of the problem, a picklable callable with ``n_cols``
    chunk: samples per regressor chunk; deadband: see above

    Raises
    ------
    InputError / DataError: naming the run (its file for a file), whatever went wrong.
    """
    from .errors import ManipIdError

    ev = robot.evaluator
    acc = InformationAccumulator(int(design.n_cols), robot.nv)  # type: ignore[attr-defined]
    left_out = np.zeros(robot.nv, dtype=np.int64)
    try:
        for block in run.blocks():
            q, dq, ddq, tau = _check_block(robot, block, run.label, run.names)
            for c in ev.iter_regressor(q, dq, ddq, int(chunk)):
                X, z = design(c.Y, tau[c.start : c.stop])
                if deadband is not None:
                    keep = np.abs(dq[c.start : c.stop]) >= deadband  # (n, nv)
                    X = X * keep[:, :, None]
                    z = z * keep
                    left_out += (~keep).sum(axis=0)
                acc.add(X, z, check=False)
    except ManipIdError as exc:
        if run.label in str(exc):
            raise
        cls = InputError if isinstance(exc, InputError) else DataError
        raise cls(f"{run.label}: {exc}") from exc
    except Exception as exc:
        raise DataError(f"{run.label}: {type(exc).__name__}: {exc}") from exc
    summary = getattr(run.blocks, "summary", None)
    return RunSums(acc, left_out, [summary() if callable(summary) else None])


def _accumulate_runs(
    robot: Robot,
    groups: Sequence[tuple[list[_Run], Design]],
    *,
    chunk: int,
    deadband: float | None,
    scheduler=None,
) -> list[RunSums]:
    """Each group's runs summed, one :func:`run_sums` task per run, added in a tree.

    ``scheduler``: None (this process, nothing of Dask imported) or any scheduler of
    :func:`manip_id.fleet.identify_files` (``"local[:N]"``, ``"tcp://HOST:PORT"``, a
    scheduler JSON file, a ``distributed.Client``). The same tasks and the same tree
    either way; a failing run fails the whole call (no partial sums).
    """
    from .fleet import SPLIT_EVERY, _Dask, _Serial, _tree, portable_robot

    backend = _Serial() if scheduler is None else _Dask(scheduler)
    worker_robot = robot if scheduler is None else portable_robot(robot)
    try:
        roots = []
        for runs, design in groups:
            leaves = [
                backend.submit(run_sums, worker_robot, run, design, int(chunk), deadband)
                for run in runs
            ]
            roots.append(_tree(backend, leaves, SPLIT_EVERY))
        return list(backend.gather(roots))
    finally:
        backend.close()


def _sub_accumulator(acc: InformationAccumulator, cols: np.ndarray, offset=None, known=None):
    """An accumulator over ``cols`` of ``acc`` for ``z - X[:, other] known``."""
    cols = np.asarray(cols, dtype=np.intp)
    A = acc.A_joint
    b = acc.b_joint
    zz = acc.zz_joint
    out = InformationAccumulator(cols.size, acc.nv)
    Ab, bb, zb = [], [], np.empty(acc.nv)
    for j in range(acc.nv):
        Aj = A[j][np.ix_(cols, cols)]
        bj = b[j][cols]
        zj = zz[j]
        if offset is not None:
            oc = np.asarray(offset, dtype=np.intp)
            bj = bj - A[j][np.ix_(cols, oc)] @ known
            zj = zj - 2.0 * b[j][oc] @ known + known @ A[j][np.ix_(oc, oc)] @ known
        Ab.append(Aj)
        bb.append(bj)
        zb[j] = zj
    out.add_sums(Ab, bb, zb, acc.n)
    return out


def _check_deadband(deadband) -> float | None:
    if deadband is None:
        return None
    d = float(deadband)
    if not (math.isfinite(d) and d >= 0):
        raise InputError(f"velocity_deadband must be >= 0 [rad/s], got {deadband}")
    return d if d > 0 else None


def _warn(messages: list[str], text: str, stacklevel: int = 3) -> None:
    """Record ``text`` and warn; ``stacklevel`` 3 points at the caller of the function that
    calls this one (4 from a step of it), i.e. at the user's call."""
    messages.append(text)
    warnings.warn(text, PayloadWarning, stacklevel=stacklevel)


def _relative_errors(accs: dict, x: np.ndarray) -> tuple[dict, dict]:
    total, per = {}, {}
    for key, acc in accs.items():
        if acc is None or acc.n == 0:
            continue
        rss = acc.residual_sum_of_squares(x)
        zz = acc.zz_joint
        total[key] = float(np.sqrt(rss.sum() / zz.sum())) if zz.sum() > 0 else float("nan")
        with np.errstate(divide="ignore", invalid="ignore"):
            per[key] = np.sqrt(rss / zz)
    return total, per


def _dof_factor(acc: InformationAccumulator, rank: int, left_out: np.ndarray) -> float:
    """Covariance correction for rows left out: ``(M - rank) / (M - left_out - rank)``."""
    m = acc.n_rows
    dropped = int(left_out.sum())
    if dropped == 0:
        return 1.0
    if m - dropped - rank <= 0:
        raise InputError(
            f"the velocity deadband leaves {m - dropped} rows for {rank} parameters: "
            "lower it or give more data"
        )
    return (m - rank) / (m - dropped - rank)


# ====================================================================== known base
@dataclass(frozen=True)
class KnownBase:
    """Base parameters from an earlier identification: names, values (r,), covariance (r, r)."""

    names: list[str]
    estimate: np.ndarray
    covariance: np.ndarray
    robot_name: str = ""
    source: str = ""

    @classmethod
    def from_result(cls, result) -> KnownBase:
        """From an :class:`~manip_id.identification.IdentificationResult`."""
        return cls(
            names=list(result.names),
            estimate=np.asarray(result.estimate, dtype=float),
            covariance=np.asarray(result.covariance, dtype=float),
            robot_name=str(result.robot_name),
            source="IdentificationResult",
        )


def load_known_base(path) -> KnownBase:
    """Base parameters from the JSON of ``manip-id identify --json`` (or ``to_dict()``).

    Reads ``base_parameters`` (``name``, ``value``, ``std``) or ``parameters``
    (``name``, ``estimate``, ``std``), and ``covariance`` when present (else the
    diagonal of the standard deviations).
    """
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise DataError(f"no such result file: {path}") from exc
    except (OSError, ValueError) as exc:
        raise DataError(f"cannot read {path} as the JSON of an identification: {exc}") from exc
    if not isinstance(doc, dict):
        raise DataError(f"{path} is not the JSON object of an identification")
    rows, key = doc.get("base_parameters"), "value"
    if rows is None:
        rows, key = doc.get("parameters"), "estimate"
    if not isinstance(rows, list) or not rows:
        raise DataError(
            f"{path} holds no base parameters (expected 'base_parameters' from manip-id "
            "identify --json)"
        )
    try:
        names = [str(r["name"]) for r in rows]
        values = np.array([float(r[key]) for r in rows])
        std = np.array([float(r["std"]) if r.get("std") is not None else np.nan for r in rows])
    except (KeyError, TypeError, ValueError) as exc:
        raise DataError(f"{path}: a base parameter lacks name, {key} or std ({exc})") from exc
    if not np.isfinite(values).all():
        raise DataError(f"{path}: a base parameter value is missing or not finite")
    cov = doc.get("covariance")
    if cov is not None:
        cov = np.asarray(cov, dtype=float)
        if cov.shape != (len(names),) * 2 or not np.isfinite(cov).all():
            cov = None
    if cov is None:
        cov = np.diag(np.nan_to_num(std, nan=0.0) ** 2)
    return KnownBase(
        names=names,
        estimate=values,
        covariance=cov,
        robot_name=str(doc.get("robot", "")),
        source=str(path),
    )


def _check_known_base(robot: Robot, base: BaseParameters, known) -> KnownBase:
    if not isinstance(known, KnownBase):
        if hasattr(known, "estimate") and hasattr(known, "covariance"):
            known = KnownBase.from_result(known)
        else:
            raise InputError(
                f"known_base must be a KnownBase or an IdentificationResult, got "
                f"{type(known).__name__}"
            )
    where = f" ({known.source})" if known.source else ""
    if known.robot_name and known.robot_name != robot.name:
        raise DataError(
            f"the known base parameters{where} are of robot {known.robot_name!r}, not "
            f"{robot.name!r}"
        )
    if list(known.names) != list(base.base_names):
        missing = [n for n in base.base_names if n not in known.names]
        extra = [n for n in known.names if n not in base.base_names]
        raise DataError(
            f"the known base parameters{where} do not match {robot.name!r} with joint terms "
            f"{list(robot.terms.enabled) or 'none'}: {len(known.names)} given for "
            f"{base.n_base}; missing {missing[:4]}, unexpected {extra[:4]} (identify with the "
            "same --friction/--armature/--joints)"
        )
    return known


# ====================================================================== payload
def _payload_estimate(
    pf: PayloadFrame,
    ra: RankAnalysis,
    cols: np.ndarray,
    psi: np.ndarray,
    cov_psi: np.ndarray,
    *,
    phi_known: np.ndarray | None = None,
    known_cols: np.ndarray | None = None,
    phi_override: np.ndarray | None = None,
) -> PayloadEstimate:
    """Assemble the payload from its base estimate ``psi`` over the payload ``cols``."""
    ind = cols[ra.base.independent]  # indices into phi (10,)
    R = np.zeros((10, ind.size))
    R[ind, np.arange(ind.size)] = 1.0
    phi = R @ psi
    if phi_known is not None:
        phi = phi + phi_known
    if phi_override is not None:
        phi = phi_override
    cov_phi = R @ cov_psi @ R.T
    null = np.zeros((10, ra.null_space.shape[1]))
    null[cols] = ra.null_space
    scale = np.linalg.norm(null, axis=0)
    null = null / np.where(scale > 0, scale, 1.0)
    std_ident = np.ones(10, dtype=bool)
    if null.size:
        std_ident = np.abs(null).max(axis=1) < 1e-9
    known_std = np.zeros(10, dtype=bool)
    if known_cols is not None:
        known_std[np.asarray(known_cols, dtype=np.intp)] = True
    std_ident = std_ident & ~known_std
    fixed = std_ident | known_std
    ident = np.array([all(fixed[k] for k in dep) for dep in _DEPENDS])
    known_q = np.array([all(known_std[k] for k in dep) for dep in _DEPENDS])
    ident = ident & ~known_q
    phi_std = np.sqrt(np.maximum(np.diag(cov_phi), 0.0))
    phi_std = np.where(std_ident, phi_std, np.nan)
    if phi[0] != 0.0:
        values, G = payload_quantities(phi)
        std = np.sqrt(np.maximum(np.einsum("ik,kl,il->i", G, cov_phi, G), 0.0))
    else:
        values, std = np.full(10, np.nan), np.full(10, np.nan)
        values[0] = 0.0
    std = np.where(ident, std, np.nan)
    lam = pseudo_inertia_eigenvalues(phi)
    consistent: bool | None = bool(lam[0] > _EIG_TOL * np.abs(lam).max())
    if not fixed.all() and phi_override is None:
        consistent = None  # the free directions decide: only the constrained fit says
    return PayloadEstimate(
        frame=pf.name,
        parent_joint=pf.joint_name,
        standard=phi,
        standard_std=phi_std,
        values=values,
        std=std,
        identifiable=ident,
        standard_identifiable=std_ident,
        known=known_q,
        combinations=list(ra.base.expressions),
        unidentifiable=list(ra.unidentifiable),
        min_eigenvalue=float(lam[0]),
        physically_consistent=consistent,
    )


def consistent_payload(
    psi_hat,
    cov_psi,
    payload_base: BaseParameters,
    *,
    margin: float | None = None,
) -> tuple[np.ndarray, str]:
    """The physically consistent payload closest to an estimate, in its covariance metric.

    Minimise ``(S phi - psi_hat)^T Cov^-1 (S phi - psi_hat)`` over the payload's 10
    standard parameters ``phi`` subject to ``J(phi) >= margin 1`` (one 4 x 4 LMI), ``S``
    the payload's base map (``psi = S phi``). This is the one-body case of
    :mod:`manip_id.estimators.consistent` (its SDP, cvxpy and Clarabel) without a prior:
    the unidentifiable directions of ``phi`` only have to make ``J`` feasible. The
    default margin is ``1e-8 max|eig J(phi_hat)|``. Returns ``(phi, status)``.
    """
    from .estimators.consistent import ConsistentProblem, base_map, solve_sdp

    psi_hat = as_float_array(psi_hat, "psi_hat", ndim=1)
    k = psi_hat.size
    cov = as_float_array(cov_psi, "cov_psi", ndim=2)
    if cov.shape != (k, k) or payload_base.n_base != k:
        raise InputError(
            f"cov_psi.shape={cov.shape} and the payload base has {payload_base.n_base} "
            f"parameters, but psi_hat has {k}"
        )
    w, V = np.linalg.eigh(0.5 * (cov + cov.T))
    keep = w > max(float(w.max()), 0.0) * 1e-14
    if not keep.any():  # a noise-free fit: measure it in units of the estimate
        w, V = np.ones(k), np.eye(k)
        keep = np.ones(k, dtype=bool)
        w = w * (np.maximum(np.abs(psi_hat), 1e-12) * 1e-8) ** 2
        V = np.eye(k)
    W = (V[:, keep] / np.sqrt(w[keep])).T  # W^T W = Cov^-1 on its range
    P = base_map(payload_base, 10)
    G = np.zeros((10, k))
    G[payload_base.independent, np.arange(k)] = 1.0
    if margin is None:
        lam = np.abs(pseudo_inertia_eigenvalues(G @ psi_hat))
        margin = 1e-8 * float(lam.max()) if lam.max() > 0 else CONSISTENCY_MARGIN
    problem = ConsistentProblem(
        P=P,
        beta_ls=psi_hat,
        W=W,
        n_bodies=1,
        nonnegative=np.zeros(0, dtype=np.intp),
        theta0=G @ psi_hat,
        J0=None,
        term_scale=np.zeros(0),
        margin=np.array([float(margin)]),
        weight=0.0,
        independent=np.asarray(payload_base.independent, dtype=np.intp),
        dependent=np.asarray(payload_base.dependent, dtype=np.intp),
        names=list(PAYLOAD_NAMES),
    )
    phi, status, iters = solve_sdp(problem)
    return phi, f"Clarabel SDP ({status}, {iters} iterations, margin {float(margin):.3g})"


@dataclass(frozen=True)
class _PayloadProblem:
    """The checked inputs of :func:`identify_payload` and the payload's structure."""

    pf: PayloadFrame
    base: BaseParameters
    pra: RankAnalysis  # structural analysis of the payload's 10 columns
    unloaded: list[_Run]
    loaded: list[_Run]
    known: KnownBase | None
    deadband: float | None
    T: np.ndarray  # payload base columns in the frame of the parent joint, (10, k)

    @property
    def r(self) -> int:
        return self.base.n_base

    @property
    def k(self) -> int:
        return int(self.pra.base.independent.size)


@dataclass(frozen=True)
class _PayloadSums:
    """The accumulated information of the payload problem."""

    acc: InformationAccumulator  # the system solved: [beta, psi], or psi with known beta
    acc_u: InformationAccumulator | None  # unloaded runs (None with a known base)
    acc_l: InformationAccumulator  # loaded runs (with a known base: the system solved)
    full: InformationAccumulator | None  # known base: loaded sums over [psi, beta]
    left_out: np.ndarray  # rows left out by the deadband per joint, (nv,)
    names: list[str]
    runs: dict = field(default_factory=dict)  # per kind, the runs' summaries (RunSums.runs)


@dataclass(frozen=True)
class _PayloadFit:
    """The least-squares fit of the payload problem (then, optionally, made consistent)."""

    ls: LeastSquaresSolution
    ra: RankAnalysis
    f: float  # covariance correction for the rows left out
    x: np.ndarray
    beta: np.ndarray
    psi: np.ndarray
    cov_psi: np.ndarray
    cov_beta: np.ndarray
    solver: str
    phi_override: np.ndarray | None = None


def _payload_inputs(
    robot: Robot,
    unloaded,
    loaded,
    frame: str,
    *,
    known_base,
    method: str,
    velocity_deadband,
    base: BaseParameters | None,
    timings: dict[str, float],
) -> _PayloadProblem:
    """Read and check the inputs of :func:`identify_payload`, with the structural analysis."""
    if method not in PAYLOAD_METHODS:
        raise InputError(f"method must be one of {list(PAYLOAD_METHODS)}, got {method!r}")
    deadband = _check_deadband(velocity_deadband)
    pf = payload_frame(robot, frame)
    t0 = time.perf_counter()
    if base is None:
        base = analyze(robot).base
    pra = payload_identifiability(robot, pf)
    timings["structural_analysis"] = time.perf_counter() - t0
    if pra.rank == 0:
        raise InputError(
            f"a payload at {frame!r} (on {pf.joint_name}) enters no joint torque of {robot.name!r}"
        )
    ub, lb = _blocks(unloaded, "unloaded"), _blocks(loaded, "loaded")
    if not lb:
        raise InputError("no loaded runs: give the runs recorded with the payload mounted")
    if known_base is None and not ub:
        raise InputError("no unloaded runs: give them, or the base parameters (known_base)")
    _check_distinct(ub, lb)
    known = None if known_base is None else _check_known_base(robot, base, known_base)
    T = pf.transform[:, pra.base.independent]
    return _PayloadProblem(pf, base, pra, ub, lb, known, deadband, T)


def _payload_accumulate(
    robot: Robot, prob: _PayloadProblem, chunk: int, scheduler=None
) -> _PayloadSums:
    """Accumulate the joint payload problem over the runs (see the module docstring),
    one :func:`run_sums` task per run (on Dask with ``scheduler``)."""
    ind, T, cols_b = np.asarray(prob.base.independent, dtype=np.intp), prob.T, prob.pf.columns
    r = prob.r
    db = prob.deadband
    if prob.known is None:
        su, sl = _accumulate_runs(
            robot,
            [
                (prob.unloaded, _PayloadDesign("unloaded", ind, cols_b, T)),
                (prob.loaded, _PayloadDesign("loaded", ind, cols_b, T)),
            ],
            chunk=chunk,
            deadband=db,
            scheduler=scheduler,
        )
        names = [*prob.base.base_names, *prob.pra.base.base_names]
        info = {"unloaded": su.runs, "loaded": sl.runs}
        return _PayloadSums(
            su.acc + sl.acc, su.acc, sl.acc, None, su.left_out + sl.left_out, names, info
        )

    (sk,) = _accumulate_runs(
        robot,
        [(prob.loaded, _PayloadDesign("known", ind, cols_b, T))],
        chunk=chunk,
        deadband=db,
        scheduler=scheduler,
    )
    full, k = sk.acc, prob.k
    known = prob.known.estimate
    acc = _sub_accumulator(full, np.arange(k), offset=np.arange(k, k + r), known=known)
    names = list(prob.pra.base.base_names)
    info = {"unloaded": [], "loaded": sk.runs}
    return _PayloadSums(acc, None, acc, full, sk.left_out, names, info)


def _payload_solve(prob: _PayloadProblem, sums: _PayloadSums, method: str, nv: int):
    """Rank check and least squares; the covariance of ``psi`` (with a known base's)."""
    acc, r, k = sums.acc, prob.r, prob.k
    if acc.n_rows <= acc.p:
        raise InputError(f"{acc.n_rows} equations for {acc.p} parameters: give more samples")
    ra = analyze_information(acc.A, sums.names, n_rows=acc.n_rows)
    if ra.rank < acc.p:
        raise RankDeficiencyError(
            ra.rank,
            acc.p,
            ra.unidentifiable,
            subject="these runs",
            what="directions of the joint payload problem",
            hint="unloaded runs must excite the robot's base parameters, loaded runs the payload's",
        )
    ls = solve_accumulator(acc, method=method, names=sums.names, rank_rtol=ra.tolerance)
    f = _dof_factor(acc, ls.rank, sums.left_out)
    x = ls.estimate
    cov = ls.covariance * f
    if prob.known is None:
        beta, psi = x[:r], x[r:]
        cov_psi = cov[r:, r:]
        cov_beta = cov[:r, :r]
    else:
        assert sums.full is not None
        psi, beta = x, prob.known.estimate
        cov_psi = cov
        # propagate the known base's covariance: psi = A_pp^-1 (b_p - A_pb beta)
        Aw = sums.full.A_joint
        wts = ls.weights if ls.weights is not None else np.ones(nv)
        A_all = np.einsum("j,jab->ab", wts, Aw)
        G = np.linalg.solve(A_all[:k, :k], A_all[:k, k:])
        cov_psi = cov_psi + G @ prob.known.covariance @ G.T
        cov_beta = prob.known.covariance
    return _PayloadFit(ls, ra, f, x, beta, psi, cov_psi, cov_beta, ls.solver)


def _payload_shown(prob: _PayloadProblem, sums: _PayloadSums, fit: _PayloadFit) -> dict:
    """The test that the loaded data show a payload at all (DataError when they do not)."""
    if prob.known is None:
        test = _payload_test(fit.psi, fit.cov_psi, sums.acc_l.A[prob.r :, prob.r :], sums.acc_l.zz)
    else:
        assert sums.full is not None
        test = _payload_test(fit.psi, fit.cov_psi, sums.acc.A, sums.full.zz)
    if not test["significant"]:
        raise DataError(
            f"the loaded runs carry no payload information: the payload's torques are not "
            f"distinguishable from zero (Wald statistic {test['statistic']:.3g} for "
            f"{test['dof']} parameters, p-value {test['p_value']:.3g}, payload share of the "
            f"loaded torques {test['share']:.2e}); were the loaded runs recorded with the "
            "payload mounted, and are they other runs than the unloaded ones?"
        )
    return test


def _payload_consistent_fit(
    prob: _PayloadProblem, sums: _PayloadSums, fit: _PayloadFit
) -> _PayloadFit:
    """The fit with the payload's pseudo-inertia positive definite (``beta`` follows)."""
    pb, r = prob.pra.base, prob.r
    phi_c, status = consistent_payload(fit.psi, fit.cov_psi, pb)
    psi_c = phi_c[pb.independent] + (pb.K @ phi_c[pb.dependent] if pb.dependent.size else 0.0)
    beta = fit.beta
    if prob.known is None:  # beta follows by its conditional least squares
        acc, ls = sums.acc, fit.ls
        A = acc.A if ls.weights is None else acc.weighted(ls.weights)[0]
        beta = beta - np.linalg.solve(A[:r, :r], A[:r, r:] @ (psi_c - fit.psi))
        x = np.r_[beta, psi_c]
    else:
        x = psi_c
    solver = f"{fit.solver}; payload pseudo-inertia positive definite by {status}"
    return replace(fit, x=x, beta=beta, psi=psi_c, solver=solver, phi_override=phi_c)


def _payload_warnings(robot: Robot, pf: PayloadFrame, est: PayloadEstimate, messages) -> None:
    """Warn of a non-positive mass, a non-physical payload, and what does not show."""
    if est.identifiable[0] and est.mass <= 0:
        _warn(
            messages,
            f"the identified payload mass is {est.mass:.4g} kg (not positive): are the "
            "unloaded and loaded runs swapped? (or use consistent=True / --consistent)",
            stacklevel=4,
        )
    elif est.physically_consistent is False:
        _warn(
            messages,
            f"the identified payload is not physically consistent (smallest pseudo-inertia "
            f"eigenvalue {est.min_eigenvalue:.3g}); use consistent=True (--consistent)",
            stacklevel=4,
        )
    missing = [n for n, ok in zip(QUANTITY_NAMES, est.identifiable, strict=True) if not ok]
    if missing:
        _warn(
            messages,
            f"a payload at {pf.name} (on {pf.joint_name}) does not show "
            f"{', '.join(missing)} in the joint torques of {robot.name}: not identifiable",
            stacklevel=4,
        )


def _payload_errors(prob: _PayloadProblem, sums: _PayloadSums, x: np.ndarray):
    """Relative torque errors ``(rel, rel_per_joint)`` per kind of run."""
    if prob.known is None:
        return _relative_errors({"unloaded": sums.acc_u, "loaded": sums.acc_l}, x)
    # residual of tau - Y_b beta - Y_p psi, relative to the loaded torques
    assert sums.full is not None
    rss = sums.acc.residual_sum_of_squares(x)
    zz = sums.full.zz_joint
    rel = {"loaded": float(np.sqrt(rss.sum() / zz.sum())) if zz.sum() > 0 else math.nan}
    with np.errstate(divide="ignore", invalid="ignore"):
        rel_j = {"loaded": np.sqrt(rss / zz)}
    return rel, rel_j


def identify_payload(
    robot: Robot,
    unloaded,
    loaded,
    frame: str,
    *,
    known_base=None,
    method: str = "wls",
    consistent: bool = False,
    velocity_deadband: float | None = None,
    chunk: int = DEFAULT_CHUNK,
    base: BaseParameters | None = None,
    scheduler=None,
) -> PayloadResult:
    """Identify a payload rigidly attached to ``frame`` from unloaded and loaded runs.

    Parameters
    ----------
    robot: the robot (its joint terms decide the base columns)
    unloaded: runs without the payload: a Dataset (with ddq), a tuple ``(q, dq, ddq,
        tau)`` of arrays ((N, nq), (N, nv) x 3 [rad, rad/s, rad/s^2, N m]), a function of
        no argument returning an iterable of such tuples (a long log streamed block by
        block), or a list of those; may be empty/None with ``known_base``
    loaded: runs with the payload mounted, the same forms
    frame: the frame or link the payload is fixed to (e.g. ``"tool0"``)
    known_base: base parameters from an earlier identification
        (:class:`KnownBase`, :func:`load_known_base`, or an IdentificationResult)
        used instead of the unloaded runs
    method: "wls" (default: each joint weighted by its residual variance, re-estimated
        from the residuals) or "ols". Noise that differs from joint to joint (the rule on
        a real arm) leaves the OLS standard deviations wrong (mass: predicted 1.1 g,
        observed 2.0 g in ``experiments/payload.py``) and its estimate 2-30 times less
        precise; WLS's are right
    consistent: constrain the payload's pseudo-inertia to be positive definite
    velocity_deadband: leave out the rows of joint j where ``|dq_j| <`` this [rad/s]
    chunk: samples per regressor chunk; base: the robot's base parametrization
    scheduler: None (accumulate in this process; nothing of Dask is imported), or a Dask
        scheduler as in :func:`manip_id.fleet.identify_files` (``"local[:N]"``,
        ``"tcp://HOST:PORT"``, a scheduler JSON file, a ``distributed.Client``): each run
        is one task (:func:`run_sums`, runs and their blocks must pickle), the sums are
        added in a tree on the cluster and the solve happens here; the result equals the
        local one to round-off

    Returns
    -------
    :class:`PayloadResult`; the math is in the module docstring. Raises
    :class:`InputError` for an unknown frame (listing the valid ones) or a payload that
    does not enter the torques, :class:`DataError` for loaded runs without payload
    information or runs of another robot, :class:`RankDeficiencyError` for data that
    do not excite the parameters.
    """
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    prob = _payload_inputs(
        robot,
        unloaded,
        loaded,
        frame,
        known_base=known_base,
        method=method,
        velocity_deadband=velocity_deadband,
        base=base,
        timings=timings,
    )
    t0 = time.perf_counter()
    sums = _payload_accumulate(robot, prob, chunk, scheduler)
    timings["accumulate"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    fit = _payload_solve(prob, sums, method, robot.nv)
    timings["solve"] = time.perf_counter() - t0
    test = _payload_shown(prob, sums, fit)
    if consistent:
        t0 = time.perf_counter()
        fit = _payload_consistent_fit(prob, sums, fit)
        timings["consistent"] = time.perf_counter() - t0

    # uncertainty: the payload's quantities and the base parameters' standard deviations
    est = _payload_estimate(
        prob.pf, prob.pra, np.arange(10), fit.psi, fit.cov_psi, phi_override=fit.phi_override
    )
    messages: list[str] = []
    _payload_warnings(robot, prob.pf, est, messages)
    rel, rel_j = _payload_errors(prob, sums, fit.x)
    beta_std = np.sqrt(np.maximum(np.diag(fit.cov_beta), 0.0))
    timings["total"] = time.perf_counter() - t_start
    return PayloadResult(
        robot_name=robot.name,
        method=method,
        payload=est,
        base_names=list(prob.base.base_names),
        base_expressions=list(prob.base.expressions),
        base_estimate=np.asarray(fit.beta, dtype=float),
        base_std=beta_std,
        known_base=prob.known is not None,
        consistent=bool(consistent),
        sigma2=float(fit.ls.sigma2 * fit.f),
        condition_number=float(fit.ra.condition_number),
        n_samples={
            "unloaded": int(0 if sums.acc_u is None else sums.acc_u.n),
            "loaded": int(sums.acc_l.n),
        },
        relative_error=rel,
        relative_error_per_joint=rel_j,
        rows_left_out=sums.left_out,
        payload_test={k2: v for k2, v in test.items() if k2 != "significant"},
        solver=fit.solver,
        dof_names=list(robot.dof_names),
        warnings=messages,
        timings=timings,
        runs=sums.runs,
    )


def _payload_test(psi, cov_psi, A_pp: np.ndarray, zz: float) -> dict:
    """Wald test of ``psi = 0`` and the payload's share ``||Y_p psi|| / ||tau||`` of the
    loaded torques (``A_pp = Y_p^T Y_p`` on the loaded runs, ``zz = ||tau||^2``)."""
    from scipy.stats import chi2

    k = psi.size
    share = float(np.sqrt(max(psi @ A_pp @ psi, 0.0) / zz)) if zz > 0 else 0.0
    w, V = np.linalg.eigh(0.5 * (cov_psi + cov_psi.T))
    big = w > max(w.max(), 0.0) * 1e-14
    proj = V[:, big].T @ psi
    with np.errstate(divide="ignore", invalid="ignore"):
        stat = float(np.sum(proj**2 / w[big])) if big.any() else math.inf
    if not big.any() and np.allclose(psi, 0):
        stat = 0.0
    p_value = float(chi2.sf(stat, k)) if math.isfinite(stat) else 0.0
    significant = p_value < PAYLOAD_SIGNIFICANCE and share > 1e-9
    return {
        "statistic": stat,
        "dof": k,
        "p_value": p_value,
        "share": share,
        "significant": significant,
    }


# ====================================================================== drive gains
@dataclass(frozen=True)
class _GainProblem:
    """The checked inputs of :func:`identify_drive_gains` and the payload's structure.

    The unknowns are ``[g (nv), beta (r), psi_u (k)]``: the gains, the robot's base
    parameters and the base parameters of the payload's unknown columns.
    """

    pf: PayloadFrame
    base: BaseParameters
    all_ra: RankAnalysis  # structural analysis of all 10 payload columns
    pra: RankAnalysis | None  # ... of the unknown ones (None: every one is known)
    unloaded: list[_Run]
    loaded: list[_Run]
    deadband: float | None
    known_cols: np.ndarray  # known payload columns among the 10
    unknown_cols: np.ndarray
    phi_k: np.ndarray  # their known values
    nv: int

    @property
    def r(self) -> int:
        return self.base.n_base

    @property
    def pind(self) -> np.ndarray:
        """Unknown payload base columns among the 10."""
        if self.pra is None:
            return np.zeros(0, dtype=np.intp)
        return self.unknown_cols[self.pra.base.independent]

    @property
    def p(self) -> int:
        return self.nv + self.r + int(self.pind.size)


@dataclass(frozen=True)
class _GainSums:
    """The accumulated information of ``[D(i), -Y_b, -Y_pu] x = Y_pk phi_k``."""

    acc: InformationAccumulator
    acc_u: InformationAccumulator
    acc_l: InformationAccumulator
    left_out: np.ndarray  # rows left out by the deadband per joint, (nv,)
    names: list[str]
    runs: dict = field(default_factory=dict)  # per kind, the runs' summaries (RunSums.runs)


def _known_payload(payload_mass, payload_com, payload_inertia):
    """The payload's known mass [kg], centre of mass [m] and inertia [kg m^2], checked."""
    try:
        mass = float(payload_mass)
    except (TypeError, ValueError) as exc:
        raise InputError(f"payload_mass must be a number [kg], got {payload_mass!r}") from exc
    if not (math.isfinite(mass) and mass > 0):
        raise InputError(f"the payload mass must be > 0 [kg], got {payload_mass}")
    if payload_inertia is not None and payload_com is None:
        raise InputError(
            "a known payload inertia (about its centre of mass) needs its centre of mass too"
        )
    com = None
    if payload_com is not None:
        com = as_float_array(payload_com, "payload_com", ndim=1)
        if com.shape != (3,) or not np.isfinite(com).all():
            raise InputError(f"payload_com must be 3 finite numbers [m], got {com.tolist()}")
    inertia = None
    if payload_inertia is not None:
        inertia = as_float_array(payload_inertia, "payload_inertia", ndim=1)
        if inertia.shape != (6,) or not np.isfinite(inertia).all():
            raise InputError(
                "payload_inertia must be 6 finite numbers (Ixx, Ixy, Iyy, Ixz, Iyz, Izz) "
                f"[kg m^2], got {inertia.tolist()}"
            )
    return mass, com, inertia


def _gain_inputs(
    robot: Robot,
    unloaded,
    loaded,
    frame: str,
    payload_mass,
    *,
    payload_com,
    payload_inertia,
    method: str,
    velocity_deadband,
    base: BaseParameters | None,
    timings: dict[str, float],
) -> _GainProblem:
    """Read and check the inputs of :func:`identify_drive_gains`, with the structure."""
    if method not in GAIN_METHODS:
        raise InputError(f"method must be one of {list(GAIN_METHODS)}, got {method!r}")
    mass, com, inertia = _known_payload(payload_mass, payload_com, payload_inertia)
    deadband = _check_deadband(velocity_deadband)
    pf = payload_frame(robot, frame)
    known_cols = (
        [0]
        + ([1, 2, 3] if com is not None else [])
        + (list(range(4, 10)) if inertia is not None else [])
    )
    unknown_cols = np.array([i for i in range(10) if i not in known_cols], dtype=np.intp)
    known_cols_a = np.array(known_cols, dtype=np.intp)
    phi_full = standard_from_quantities(mass, com, inertia)
    phi_k = phi_full[known_cols_a]

    t0 = time.perf_counter()
    if base is None:
        base = analyze(robot).base
    all_ra = payload_identifiability(robot, pf)
    if unknown_cols.size:
        pra = payload_identifiability(robot, pf, columns=unknown_cols)
    else:
        pra = None
    timings["structural_analysis"] = time.perf_counter() - t0
    rank_u = 0 if pra is None else pra.rank
    if all_ra.rank <= rank_u:
        raise InputError(
            f"the known payload parameters ({', '.join(PAYLOAD_NAMES[i] for i in known_cols)}) "
            f"at {frame!r} do not enter the torques of {robot.name!r} apart from the unknown "
            "ones, so they cannot fix the scale of the gains (give more of the payload, e.g. "
            "its centre of mass, or attach it elsewhere)"
        )
    ub, lb = _blocks(unloaded, "unloaded"), _blocks(loaded, "loaded")
    if not lb or not ub:
        raise InputError("drive gains need both unloaded and loaded runs")
    _check_distinct(ub, lb)
    return _GainProblem(
        pf, base, all_ra, pra, ub, lb, deadband, known_cols_a, unknown_cols, phi_k, robot.nv
    )


def _gain_accumulate(robot: Robot, prob: _GainProblem, chunk: int, scheduler=None) -> _GainSums:
    """Accumulate ``[D(i), -Y_b, -Y_pu] [g; beta; psi_u] = Y_pk phi_k`` over the runs,
    one :func:`run_sums` task per run (on Dask with ``scheduler``)."""
    ind, cols_b = np.asarray(prob.base.independent, dtype=np.intp), prob.pf.columns
    T_u = prob.pf.transform[:, prob.pind]
    T_k = prob.pf.transform[:, prob.known_cols] @ prob.phi_k
    su, sl = _accumulate_runs(
        robot,
        [
            (prob.unloaded, _GainDesign(False, ind, cols_b, T_u, T_k, prob.nv)),
            (prob.loaded, _GainDesign(True, ind, cols_b, T_u, T_k, prob.nv)),
        ],
        chunk=chunk,
        deadband=prob.deadband,
        scheduler=scheduler,
    )
    gain_names = [f"{d}.gain" for d in robot.dof_names]
    pnames = [] if prob.pra is None else prob.pra.base.base_names
    names = [*gain_names, *prob.base.base_names, *pnames]
    info = {"unloaded": su.runs, "loaded": sl.runs}
    return _GainSums(su.acc + sl.acc, su.acc, sl.acc, su.left_out + sl.left_out, names, info)


def _gains_determined(
    robot: Robot, acc: InformationAccumulator, ra: RankAnalysis, p: int, messages: list[str]
) -> np.ndarray:
    """Which gains the data fix, shape (nv,) bool; warns of the others and of unexcited
    base/payload directions."""
    nv = robot.nv
    determined = np.ones(nv, dtype=bool)
    if ra.rank < p:
        d = np.sqrt(np.maximum(np.diag(acc.A), 0.0))  # column norms; a zero column (a
        d = np.where(d > 0, d, d.max() if d.max() > 0 else 1.0)  # current never seen) counts
        N = ra.null_space * d[:, None]
        N = N / np.maximum(np.linalg.norm(N, axis=0), 1e-300)
        involved = np.abs(N[:nv]).max(axis=1) > 1e-6 if N.size else np.zeros(nv, bool)
        determined = ~involved
        others = [
            e
            for e, col in zip(ra.unidentifiable, N.T, strict=True)
            if np.abs(col[:nv]).max() <= 1e-6
        ]
        if involved.any():
            bad = [robot.dof_names[j] for j in np.flatnonzero(involved)]
            _warn(
                messages,
                f"the data do not determine the drive gain of {', '.join(bad)}: its current "
                "is not tied to the payload's known torque (e.g. a vertical axis the payload's "
                "gravity never loads, or a joint that never moves); excite that joint with "
                "the payload mounted",
                stacklevel=4,
            )
        if others:
            _warn(
                messages,
                f"these runs leave {len(others)} base/payload direction(s) unexcited: "
                + "; ".join(others[:4]),
                stacklevel=4,
            )
    return determined


def _gains_solve(
    sums: _GainSums,
    ra: RankAnalysis,
    method: str,
    nv: int,
    p: int,
    determined: np.ndarray,
    messages: list[str],
) -> tuple[np.ndarray, np.ndarray, float, str]:
    """OLS/WLS with the known columns on the right, then TLS or ML from it:
    ``(x, covariance, sigma2, solver)``."""
    acc, left_out = sums.acc, sums.left_out
    ls = solve_accumulator(
        acc,
        method="wls" if method == "wls" else "ols",
        names=sums.names,
        minimum_norm=ra.rank < p,
        rank_rtol=ra.tolerance,
    )
    f = _dof_factor(acc, ls.rank, left_out)
    x, cov, sigma2 = ls.estimate, ls.covariance * f, ls.sigma2 * f
    solver = f"{'WLS' if method == 'wls' else 'OLS'} with the known payload columns on the "
    solver += "right-hand side; " + ls.solver
    if method == "tls":
        if ra.rank < p:
            _warn(
                messages,
                "TLS needs a full-rank system: kept the minimum-norm OLS solution",
                stacklevel=4,
            )
        else:
            x = _tls(acc)
            rss = acc.residual_sum_of_squares(x)
            sigma2_t = float(rss.sum() / max(acc.n_rows - int(left_out.sum()) - p, 1))
            cov = cov * (sigma2_t / sigma2) if sigma2 > 0 else cov
            sigma2 = sigma2_t
            solver = (
                "TLS: smallest right singular vector of the column-scaled [W, -y], scaled to "
                "the known payload; covariance sigma^2 (W^T W)^-1 at the TLS estimate"
            )
    elif method == "ml":  # damped steps leave the unexcited directions where OLS put them
        x, cov, sigma2, what = _ml_gains(acc, nv, x, acc.n - left_out, determined)
        solver = f"{what}, started from OLS ({ls.solver})"
    return x, cov, sigma2, solver


def _gains_uncertainty(
    robot: Robot, x: np.ndarray, cov: np.ndarray, determined: np.ndarray, messages: list[str]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(gains, gains_std, std)``: the gains and their standard deviations (NaN where the
    data do not fix them), and every parameter's; warns of gains that came out <= 0."""
    nv = robot.nv
    gains = x[:nv].copy()
    std_all = np.sqrt(np.maximum(np.diag(cov), 0.0))
    gains_std = std_all[:nv].copy()
    gains[~determined] = np.nan
    gains_std[~determined] = np.nan
    neg = [robot.dof_names[j] for j in range(nv) if determined[j] and gains[j] <= 0]
    if neg:
        _warn(
            messages,
            f"the drive gain of {', '.join(neg)} came out <= 0: check the current's sign "
            "convention of that joint",
            stacklevel=4,
        )
    return gains, gains_std, std_all


def _gain_payload(prob: _GainProblem, x: np.ndarray, cov: np.ndarray) -> PayloadEstimate:
    """The payload: its known part and, when some is unknown, the estimate of the rest."""
    nv, r = prob.nv, prob.r
    phi_known = np.zeros(10)
    phi_known[prob.known_cols] = prob.phi_k
    if prob.pra is None:
        return _known_estimate(prob.pf, phi_known, prob.all_ra)
    return _payload_estimate(
        prob.pf,
        prob.pra,
        prob.unknown_cols,
        x[nv + r :],
        cov[nv + r :, nv + r :],
        phi_known=phi_known,
        known_cols=prob.known_cols,
    )


def _gain_errors(sums: _GainSums, x: np.ndarray, nv: int, p: int) -> tuple[dict, dict]:
    """Relative errors in torque units: residuals over ``||g i||``, per kind of run."""
    rel, rel_j = {}, {}
    for key, a in (("unloaded", sums.acc_u), ("loaded", sums.acc_l)):
        rss = a.residual_sum_of_squares(x)
        xg = np.zeros(p)
        xg[:nv] = x[:nv]
        tt = np.maximum(np.einsum("a,jab,b->j", xg, a.A_joint, xg), 0.0)  # ||g_j i_j||^2
        rel[key] = float(np.sqrt(rss.sum() / tt.sum())) if tt.sum() > 0 else float("nan")
        with np.errstate(divide="ignore", invalid="ignore"):
            rel_j[key] = np.sqrt(rss / tt)
    return rel, rel_j


def identify_drive_gains(
    robot: Robot,
    unloaded,
    loaded,
    frame: str,
    payload_mass: float,
    *,
    payload_com=None,
    payload_inertia=None,
    method: str = "ml",
    velocity_deadband: float | None = None,
    chunk: int = DEFAULT_CHUNK,
    base: BaseParameters | None = None,
    scheduler=None,
) -> DriveGainResult:
    """Drive gains ``g`` (``tau_j = g_j i_j``), base and payload parameters from currents.

    Parameters
    ----------
    robot: the robot
    unloaded, loaded: runs as in :func:`identify_payload`, with motor currents [A] in
        the torque columns
    frame: the frame the payload is fixed to
    payload_mass: the payload's known mass [kg], > 0 (it fixes the scale)
    payload_com: its centre of mass in ``frame`` [m], shape (3,), when known
    payload_inertia: its inertia about the CoM in ``frame`` axes [kg m^2],
        (Ixx, Ixy, Iyy, Ixz, Iyz, Izz), when known (needs ``payload_com``)
    method: "ml" (default: maximum likelihood under current noise, Gauss-Newton from
        the OLS start, :func:`_ml_gains`), "ols" (ordinary least squares with the known
        columns on the right-hand side, Gautier & Briot), "wls" (the same, each joint
        weighted by its residual variance) or "tls" (total least squares of the scaled
        system). OLS/WLS/TLS hold the noisy currents in the regressor: they shrink a
        gain by about ``sigma_i^2 / mean(i^2)`` and their standard deviations are
        optimistic where a joint's current is small against its noise; ML is not.
    velocity_deadband: leave out the rows of joint j where ``|dq_j| <`` this [rad/s]
    scheduler: None (this process) or a Dask scheduler, as in :func:`identify_payload`

    Returns
    -------
    :class:`DriveGainResult`. A joint whose gain the data do not fix gets a
    :class:`PayloadWarning` naming it and ``determined=False``.
    """
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    prob = _gain_inputs(
        robot,
        unloaded,
        loaded,
        frame,
        payload_mass,
        payload_com=payload_com,
        payload_inertia=payload_inertia,
        method=method,
        velocity_deadband=velocity_deadband,
        base=base,
        timings=timings,
    )
    nv, r, p = prob.nv, prob.r, prob.p
    t0 = time.perf_counter()
    sums = _gain_accumulate(robot, prob, chunk, scheduler)
    timings["accumulate"] = time.perf_counter() - t0
    acc = sums.acc
    if acc.n_rows <= p:
        raise InputError(f"{acc.n_rows} equations for {p} parameters: give more samples")
    if acc.zz == 0:
        raise DataError(
            "the payload's known part produces no torque on these loaded runs: nothing fixes "
            "the scale of the gains"
        )

    t0 = time.perf_counter()
    messages: list[str] = []
    ra = analyze_information(acc.A, sums.names, n_rows=acc.n_rows)
    determined = _gains_determined(robot, acc, ra, p, messages)
    _check_payload_present(acc, nv, determined, robot.dof_names)
    x, cov, sigma2, solver = _gains_solve(sums, ra, method, nv, p, determined, messages)
    timings["solve"] = time.perf_counter() - t0

    gains, gains_std, std_all = _gains_uncertainty(robot, x, cov, determined, messages)
    est = _gain_payload(prob, x, cov)
    rel, rel_j = _gain_errors(sums, x, nv, p)
    timings["total"] = time.perf_counter() - t_start
    return DriveGainResult(
        robot_name=robot.name,
        method=method,
        dof_names=list(robot.dof_names),
        gains=gains,
        gains_std=gains_std,
        determined=determined,
        payload=est,
        base_names=list(prob.base.base_names),
        base_expressions=list(prob.base.expressions),
        base_estimate=x[nv : nv + r],
        base_std=std_all[nv : nv + r],
        sigma2=float(sigma2),
        condition_number=float(ra.condition_number),
        n_samples={"unloaded": int(sums.acc_u.n), "loaded": int(sums.acc_l.n)},
        relative_error=rel,
        relative_error_per_joint=rel_j,
        rows_left_out=sums.left_out,
        solver=solver,
        warnings=messages,
        timings=timings,
        runs=sums.runs,
    )


def _known_estimate(pf: PayloadFrame, phi: np.ndarray, ra: RankAnalysis) -> PayloadEstimate:
    """A fully given payload (every parameter known)."""
    values, _ = payload_quantities(phi)
    lam = pseudo_inertia_eigenvalues(phi)
    return PayloadEstimate(
        frame=pf.name,
        parent_joint=pf.joint_name,
        standard=phi,
        standard_std=np.full(10, np.nan),
        values=values,
        std=np.full(10, np.nan),
        identifiable=np.zeros(10, dtype=bool),
        standard_identifiable=np.zeros(10, dtype=bool),
        known=np.ones(10, dtype=bool),
        combinations=[],
        unidentifiable=list(ra.unidentifiable),
        min_eigenvalue=float(lam[0]),
        physically_consistent=bool(lam[0] > _EIG_TOL * np.abs(lam).max()),
    )


def _check_payload_present(
    acc: InformationAccumulator, nv: int, determined: np.ndarray, dof_names, z_min: float = 5.0
) -> None:
    """Refuse loaded runs that show no payload: free its torque's scale ``s`` and test it.

    The homogeneous system ``[D(i), -X, -c] [g; theta; s] = 0`` (``c`` the known payload
    torque) with the best-informed determined gain fixed to 1 is solved for the rest;
    the loaded runs carry the payload when ``s`` (``1/g_ref`` in truth) is at least
    ``z_min`` standard deviations from zero. All sums come from ``acc``.
    """
    if not determined.any():
        return
    A, b, zz = acc.A, acc.b, acc.zz
    p = acc.p
    G = np.zeros((p + 1, p + 1))  # Gram of [D(i), -X, -c]
    G[:p, :p] = A
    G[:p, p] = G[p, :p] = -b
    G[p, p] = zz
    diag = np.diag(A)[:nv]
    ref = int(np.flatnonzero(determined)[np.argmax(diag[determined])])
    rest = np.array([k for k in range(p + 1) if k != ref])
    Arr = G[np.ix_(rest, rest)]
    brr = -G[rest, ref]
    d = np.sqrt(np.maximum(np.diag(Arr), 0.0))
    d = np.where(d > 0, d, 1.0)
    Ainv = np.linalg.pinv(Arr / np.outer(d, d), hermitian=True) / np.outer(d, d)
    x = Ainv @ brr
    rss = max(G[ref, ref] - 2.0 * brr @ x + x @ Arr @ x, 0.0)
    dof = max(acc.n_rows - np.linalg.matrix_rank(Arr / np.outer(d, d), hermitian=True), 1)
    s, s_std = float(x[-1]), float(np.sqrt(max(rss / dof * Ainv[-1, -1], 0.0)))
    if s_std == 0.0 and s != 0.0:
        return
    if not abs(s) > z_min * s_std:
        raise DataError(
            "the loaded runs carry no payload information: with the gain of "
            f"{dof_names[ref]} fixed, the payload's torque scale comes out {s:.3g} +- "
            f"{s_std:.2g}, not distinguishable from zero; were the loaded runs recorded "
            "with the payload mounted, and is the payload's frame right?"
        )


def _ml_gains(
    acc: InformationAccumulator,
    nv: int,
    x0: np.ndarray,
    n_rows: np.ndarray,
    active: np.ndarray | None = None,
    *,
    reweight: int = 3,
    max_iter: int = 100,
    tol: float = 1e-13,
) -> tuple[np.ndarray, np.ndarray, float, str]:
    """Maximum likelihood under current noise: residuals in current units, from the sums.

    With ``k_j = 1/g_j`` and the torque model ``tau_j = X_j theta + c_j`` (``X`` the
    base and unknown payload columns, ``c`` the known payload torque), the current
    residual ``e_j = i_j - k_j (X_j theta + c_j)`` of every joint has, with
    ``theta~ = [theta; 1]`` and ``X~ = [X, c]``::

        ||e_j||^2 = i_j.i_j - 2 k_j (X~_j^T i_j).theta~ + k_j^2 theta~^T X~_j^T X~_j theta~

    All these sums are blocks of the OLS accumulator of ``[D(i), -X] x = c``, so
    Gauss-Newton (Levenberg-damped) on ``sum_j w_j ||e_j||^2`` needs no data pass;
    ``w_j = 1/sigma_j^2`` are re-estimated from the residuals ``reweight`` times.
    Unlike OLS, whose regressor holds the noisy currents (an errors-in-variables
    problem: the gains shrink by about ``sigma_i^2 / mean(i^2)``), this is unbiased at
    low current-to-noise ratios. Joints not ``active`` (gains the data do not determine)
    keep their start and their rows stay out of the cost; directions without
    information do not move (damped steps). Returns ``(x = [g, theta], covariance,
    sigma2 [A^2], description)``; the covariance is ``(J^T W J)^+`` mapped to ``g`` by
    ``dg/dk = -g^2``.
    """
    active = np.ones(nv, dtype=bool) if active is None else np.asarray(active, dtype=bool)
    A, b, zz = acc.A_joint, acc.b_joint, acc.zz_joint
    p = acc.p
    m = p - nv
    S = np.empty((nv, m + 1, m + 1))
    s = np.empty((nv, m + 1))
    ii = np.empty(nv)
    for j in range(nv):
        S[j, :m, :m] = A[j, nv:, nv:]
        S[j, :m, m] = S[j, m, :m] = -b[j, nv:]
        S[j, m, m] = zz[j]
        s[j, :m] = -A[j, nv:, j]
        s[j, m] = b[j, j]
        ii[j] = A[j, j, j]
    k = np.where(active, 1.0 / np.where(active, x0[:nv], 1.0), 0.0)
    theta = x0[nv:].copy()
    free = np.r_[np.flatnonzero(active), nv + np.arange(m)]  # parameters that move

    def rss(k, theta):
        tt = np.r_[theta, 1.0]
        St = S @ tt  # (nv, m + 1)
        return np.maximum(ii - 2.0 * k * (s @ tt) + k**2 * (St @ tt), 0.0)

    def normal(k, theta, w):
        tt = np.r_[theta, 1.0]
        St = S @ tt
        H = np.zeros((p, p))
        grad = np.zeros(p)
        for j in range(nv):
            H[j, j] = w[j] * tt @ St[j]
            H[j, nv:] = H[nv:, j] = w[j] * k[j] * St[j, :m]
            H[nv:, nv:] += w[j] * k[j] ** 2 * S[j, :m, :m]
            grad[j] = -w[j] * (s[j] @ tt - k[j] * (tt @ St[j]))
            grad[nv:] += -w[j] * k[j] * (s[j, :m] - k[j] * St[j, :m])
        return H, grad

    dof_j = np.maximum(n_rows - p / nv, 1.0)
    floor = (1e-9) ** 2 * ii / np.maximum(n_rows, 1)
    w = active.astype(float)
    q = free.size

    def solve_step(H, grad, lam):
        Hf, gf = H[np.ix_(free, free)], grad[free]
        dg = np.diag(Hf)
        d = np.where(dg > 0, np.sqrt(np.where(dg > 0, dg, 1.0)), 1.0)
        stepf = -np.linalg.solve(Hf / np.outer(d, d) + lam * np.eye(q), gf / d) / d
        step = np.zeros(p)
        step[free] = stepf
        return step

    iters = 0
    for _ in range(max(int(reweight), 1) + 1):
        cost = float(w @ rss(k, theta))
        lam = 1e-6
        for _ in range(int(max_iter)):
            iters += 1
            H, grad = normal(k, theta, w)
            step = None
            while lam < 1e12:
                try:
                    step = solve_step(H, grad, lam)
                except np.linalg.LinAlgError:
                    lam *= 10.0
                    continue
                new = float(w @ rss(k + step[:nv], theta + step[nv:]))
                if new <= cost:
                    break
                lam *= 10.0
                step = None
            if step is None:
                break
            k, theta = k + step[:nv], theta + step[nv:]
            done = cost - new <= tol * max(cost, 1e-300)
            cost = new
            lam = max(lam / 10.0, 1e-12)
            if done:
                break
        var = np.maximum(rss(k, theta) / dof_j, np.maximum(floor, 1e-300))
        w = np.where(active, 1.0 / var, 0.0)
    H, _ = normal(k, theta, w)
    Hf = H[np.ix_(free, free)]
    dg = np.diag(Hf)
    d = np.where(dg > 0, np.sqrt(np.where(dg > 0, dg, 1.0)), 1.0)
    cov_xi = np.zeros((p, p))
    cov_xi[np.ix_(free, free)] = np.linalg.pinv(Hf / np.outer(d, d), hermitian=True) / np.outer(
        d, d
    )
    Jt = np.eye(p)
    kk = np.where(active, k, 1.0)
    Jt[np.arange(nv), np.arange(nv)] = -1.0 / kk**2
    cov = Jt @ cov_xi @ Jt.T
    g = np.where(active, 1.0 / kk, x0[:nv])
    res = rss(k, theta)[active]
    sigma2 = float(res.sum() / max(int(n_rows[active].sum()) - q, 1))
    what = (
        f"ML in current units (Gauss-Newton on sum_j ||i_j - (X_j theta + c_j) / g_j||^2 / "
        f"sigma_j^2 from the sums, {iters} iterations)"
    )
    return np.r_[g, theta], 0.5 * (cov + cov.T), sigma2, what


def _tls(acc: InformationAccumulator) -> np.ndarray:
    """Total least squares of ``W x ~ y`` from its sums: ``C = [W y]^T [W y]``, scaled."""
    A, b, zz = acc.A, acc.b, acc.zz
    C = np.block([[A, b[:, None]], [b[None, :], np.array([[zz]])]])
    d = np.sqrt(np.maximum(np.diag(C), 0.0))
    d = np.where(d > 0, d, 1.0)
    Cs = C / np.outer(d, d)
    w, V = np.linalg.eigh(0.5 * (Cs + Cs.T))
    v = V[:, 0] / d
    if v[-1] == 0:
        raise InputError("total least squares found no solution with the known payload scale")
    return -v[:-1] / v[-1]


# ====================================================================== torque scale
def load_torque_scale(path, robot: Robot | None = None) -> np.ndarray:
    """The drive gains of a ``manip-id drive-gains --json`` result, in joint order, (nv,).

    With ``robot``, the result's joints must be ``robot.dof_names`` (same order). Every
    gain must have been determined and be positive.
    """
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise DataError(f"no such drive-gain result: {path}") from exc
    except (OSError, ValueError) as exc:
        raise DataError(f"cannot read {path} as JSON: {exc}") from exc
    rows = doc.get("drive_gains") if isinstance(doc, dict) else None
    if not isinstance(rows, list) or not rows:
        raise DataError(
            f"{path} holds no 'drive_gains' (expected the JSON of manip-id drive-gains --json)"
        )
    try:
        joints = [str(r["joint"]) for r in rows]
        gains = [r["gain"] for r in rows]
    except (KeyError, TypeError) as exc:
        raise DataError(f"{path}: each drive gain needs 'joint' and 'gain' ({exc})") from exc
    bad = [j for j, g in zip(joints, gains, strict=True) if g is None]
    if bad:
        raise DataError(f"{path}: the drive gain of {', '.join(bad)} was not determined")
    g = np.asarray(gains, dtype=float)
    if not np.isfinite(g).all() or np.any(g <= 0):
        j = int(np.argmin(np.where(np.isfinite(g), g, -np.inf)))
        raise DataError(f"{path}: the drive gain of {joints[j]} is {gains[j]}, not positive")
    if robot is not None and joints != list(robot.dof_names):
        raise DataError(
            f"{path} holds gains for the joints {joints} but robot {robot.name!r} has "
            f"{list(robot.dof_names)}"
        )
    return g


__all__ = [
    "DriveGainResult",
    "KnownBase",
    "PAYLOAD_NAMES",
    "PayloadEstimate",
    "PayloadFrame",
    "PayloadResult",
    "PayloadWarning",
    "consistent_payload",
    "frame_names",
    "identify_drive_gains",
    "identify_payload",
    "load_known_base",
    "load_torque_scale",
    "payload_frame",
    "payload_identifiability",
    "payload_quantities",
    "payload_regressor",
    "payload_transform",
    "standard_from_quantities",
]
