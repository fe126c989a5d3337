"""Where a payload sits and what it adds to the torques: frames, its regressor, its quantities.

A payload at frame ``f`` is one more rigid body on ``f``'s parent joint ``j``; its 10
standard parameters in ``f``, ``phi = [m, h (3), I_O (6)]`` [kg, kg m, kg m^2], move
to the joint's frame by the linear map ``phi_j = T(jMf) phi`` (Pinocchio's
``Inertia.se3Action``, :func:`payload_transform`), so ``tau_p = Y_j T phi =
Y_p phi`` (:func:`payload_regressor`). :func:`payload_quantities` converts ``phi``
to mass, centre of mass and inertia about the CoM, with the Jacobian the delta
method needs. The math is in :mod:`manip_id.payload`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .._checks import as_float_array
from ..errors import InputError
from ..identifiability import RankAnalysis, analyze
from ..physics.consistency import pseudo_inertia
from ..robot.model import INERTIAL_NAMES, Robot, frame_id
from ..robot.regressor import DEFAULT_CHUNK, check_states

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
DEPENDS: tuple[tuple[int, ...], ...] = (
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
#: Index pairs of the 6 inertia components in a 3 x 3 matrix.
SYM6 = ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2))
#: Structural analysis of the payload columns: random states drawn.
STRUCTURAL_STATES = 200


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
        return np.r_[m, R @ h + m * p, [Ij[a, b] for a, b in SYM6]]

    return np.stack([act(e) for e in np.eye(10)], axis=1)


def _sym3(six) -> np.ndarray:
    xx, xy, yy, xz, yz, zz = six
    return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])


@dataclass(frozen=True)
class PayloadFrame:
    """Where a payload sits: a frame of the robot and its parent joint.

    Attributes
    ----------
    name
        frame name (as in the URDF: a link, an operational frame, a joint)
    frame_id
        Pinocchio frame index in ``robot.model``
    joint_id
        Pinocchio index of the parent joint (1 .. njoints - 1)
    joint_name
        its name
    body
        position of that joint's body in the parameter vector (0-based)
    placement
        the frame in the joint's frame, ``jMf``
    transform
        ``T`` of :func:`payload_transform`, shape (10, 10)
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
    fid = frame_id(model, frame)
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
    frame
        a frame name of ``robot`` or a :class:`PayloadFrame`
    q
        positions [rad or m], shape (nq,) or (N, nq); dq, ddq: shape (nv,) or (N, nv)

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
    values = np.r_[m, c, [Ic[a, b] for a, b in SYM6]]
    G = np.zeros((10, 10))
    G[0, 0] = 1.0
    G[1:4, 0] = -h / m**2
    G[1:4, 1:4] = np.eye(3) / m
    dm = (hh / m**2) * np.eye(3) - np.outer(h, h) / m**2
    for i, (a, b) in enumerate(SYM6):
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
    return np.r_[m, m * c, [IO[a, b] for a, b in SYM6]]


def pseudo_inertia_eigenvalues(phi) -> np.ndarray:
    """Eigenvalues (ascending) of the payload's pseudo-inertia ``J(phi)``, shape (4,)."""
    return np.linalg.eigvalsh(pseudo_inertia(np.asarray(phi, dtype=float)))
