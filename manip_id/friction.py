"""Friction and drive laws of a joint: their regressor columns, shapes and formulas.

Every law is linear in its coefficients once its *shape* parameters are fixed, so it
enters the regressor as columns of joint ``j``'s row (``dq = dq_j``, ``q = q_j``)::

    viscous       fv dq                                            fv [N m s/rad]
    coulomb       fc sign(dq)                                      fc [N m]
    offset        fo                                               fo [N m]
    asymmetric    fvp dq [dq > 0] + fvn dq [dq < 0]                fvp, fvn [N m s/rad]
                  + fcp [dq > 0] - fcn [dq < 0]                    fcp, fcn [N m]
    stribeck      (fc + (fs - fc) exp(-(dq/vs)^2)) sign(dq)
                  = fc sign(dq) + fs' exp(-(dq/vs)^2) sign(dq)     fs' = fs - fc [N m]
    sigmoid       fsg (S(a (dq + c)) - S(a c)),  S(x) = 1/(1 + e^-x)  fsg [N m]
    position      sum_k hks sin(k q) + hkc cos(k q),  k = 1..K      hks, hkc [N m]
    load          fl |tau_load| sign(dq)                             fl [1]
    hysteresis    fh s,  ds/dq = (1 - s sign(dq)) / xc  (Dahl)        fh [N m]

(prismatic joints: N, N s/m). ``asymmetric`` replaces ``viscous`` and ``coulomb``; with
``offset`` its Coulomb pair is ``coulomb`` + ``offset`` (torque ``fc + fo`` for dq > 0
and ``-fc + fo`` for dq < 0: the same span away from rest), so it keeps ``fc`` then.
``stribeck`` adds ``fs'`` to ``coulomb`` (the static friction is ``fs = fc + fs'``).
``sigmoid`` is the per-joint form of Gaz et al. (2019, the Panda's published model):
``phi1 = fsg``, ``phi2 = a``, ``phi3 = c``; the ``- S(a c)`` makes it zero at rest.

``load`` is Coulomb friction growing with the joint's load (strain-wave gears):
``tau_load = rnea(q, dq, ddq)`` of the *nominal* rigid-body model (the robot's URDF
inertias), a known signal, so the law stays linear in ``fl``. It needs the measured
acceleration: the dynamic model only (not the Slotine-Li regressor, the energy and
momentum models or the closed-loop plant, which refuse it).

``hysteresis`` is the pre-sliding (Dahl) friction: a state ``s`` in [-1, 1] driven by
the joint's displacement, not its velocity. Between reversals it approaches
``sign(dq)`` exponentially with the distance travelled, over ``xc`` [rad or m]; over a
sample step of displacement ``d = q_k - q_(k-1)`` exactly::

    s_k = sign(d) + (s_(k-1) - sign(d)) exp(-|d| / xc),     s = 0 before the first sample

so ``fh s`` follows the friction's square wave at reversals with a rounded edge of a few
``xc`` instead of the jump of ``sign(dq)``. The state depends on the path since the
start of the trajectory (:func:`hysteresis_state`, carried across blocks by
:class:`HysteresisCarry`), so the law needs the samples in order: one sample alone
(the one-sample regressor, forward simulation) cannot evaluate it.

Shapes (:class:`FrictionShapes`): the Stribeck velocity ``vs`` [rad/s], the sigmoid
slope ``a`` [s/rad] and shift ``c`` [rad/s], the hysteresis length ``xc`` [rad], per
DoF. They are fixed when the linear solve runs;
:mod:`manip_id.identification.selection` chooses them by variable projection (a grid,
each point solved from its accumulated sums, then refined).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from .errors import InputError

#: Friction kinds ``--friction`` accepts (``position`` takes ``position:K``).
FRICTION_KINDS: tuple[str, ...] = (
    "viscous",
    "coulomb",
    "offset",
    "asymmetric",
    "stribeck",
    "sigmoid",
    "position",
    "load",
    "hysteresis",
)
#: Highest harmonic order of the ``position`` law.
MAX_HARMONICS = 4
#: Default harmonic order of ``position``.
DEFAULT_HARMONICS = 2
#: Default Stribeck velocity [rad/s], sigmoid slope [s/rad] and shift [rad/s].
DEFAULT_STRIBECK_VELOCITY = 0.05
DEFAULT_SIGMOID_SLOPE = 50.0
DEFAULT_SIGMOID_SHIFT = 0.0
#: Default hysteresis (Dahl) length xc [rad or m].
DEFAULT_HYSTERESIS_LENGTH = 0.005


@dataclass(frozen=True)
class FrictionShapes:
    """Shape parameters of the nonlinear laws, one value per DoF (tuples of length nv).

    Attributes
    ----------
    stribeck_velocity : tuple of float or None
        ``vs`` [rad/s or m/s] per DoF (None: :data:`DEFAULT_STRIBECK_VELOCITY`).
    sigmoid_slope : tuple of float or None
        ``a`` [s/rad or s/m] per DoF (None: :data:`DEFAULT_SIGMOID_SLOPE`).
    sigmoid_shift : tuple of float or None
        ``c`` [rad/s or m/s] per DoF (None: :data:`DEFAULT_SIGMOID_SHIFT`).
    hysteresis_length : tuple of float or None
        ``xc`` [rad or m] per DoF (None: :data:`DEFAULT_HYSTERESIS_LENGTH`).
    """

    stribeck_velocity: tuple[float, ...] | None = None
    sigmoid_slope: tuple[float, ...] | None = None
    sigmoid_shift: tuple[float, ...] | None = None
    hysteresis_length: tuple[float, ...] | None = None

    def __post_init__(self):
        for name in ("stribeck_velocity", "sigmoid_slope", "hysteresis_length"):
            v = getattr(self, name)
            if v is not None and not all(np.isfinite(x) and x > 0 for x in v):
                raise InputError(f"{name} must be positive and finite per DoF, got {v}")
        if self.sigmoid_shift is not None and not all(np.isfinite(self.sigmoid_shift)):
            raise InputError(f"sigmoid_shift must be finite per DoF, got {self.sigmoid_shift}")

    def values(self, name: str, default: float) -> np.ndarray | float:
        """The per-DoF values of field ``name`` (an array), or ``default`` when unset."""
        v = getattr(self, name)
        return default if v is None else np.asarray(v, dtype=float)

    def to_dict(self) -> dict:
        """JSON-ready fields (None for unset)."""
        return {
            k: None if getattr(self, k) is None else list(map(float, getattr(self, k)))
            for k in ("stribeck_velocity", "sigmoid_slope", "sigmoid_shift", "hysteresis_length")
        }

    @classmethod
    def from_dict(cls, data: dict | None) -> FrictionShapes:
        """The inverse of :meth:`to_dict` (None: all defaults)."""
        data = data or {}
        return cls(**{k: None if v is None else tuple(v) for k, v in data.items()})


NO_SHAPES = FrictionShapes()


def _sigmoid(x):
    return 0.5 * (1.0 + np.tanh(0.5 * x))  # 1/(1 + e^-x) without overflow


def stribeck_column(vel, shapes: FrictionShapes | None):
    """``exp(-(dq/vs)^2) sign(dq)``, shape like ``vel`` (..., nv)."""
    vs = (shapes or NO_SHAPES).values("stribeck_velocity", DEFAULT_STRIBECK_VELOCITY)
    return np.exp(-np.square(vel / vs)) * np.sign(vel)


def sigmoid_column(vel, shapes: FrictionShapes | None):
    """``S(a (dq + c)) - S(a c)``, shape like ``vel`` (..., nv)."""
    s = shapes or NO_SHAPES
    a = s.values("sigmoid_slope", DEFAULT_SIGMOID_SLOPE)
    c = s.values("sigmoid_shift", DEFAULT_SIGMOID_SHIFT)
    return _sigmoid(a * (vel + c)) - _sigmoid(a * c)


# the columns of the joint-term table (``parameters.JOINT_TERMS``): (angles, vel, acc, shapes)
def viscous_positive(angles, vel, acc, shapes=None):
    """``dq [dq > 0]``."""
    return np.where(vel > 0, vel, 0.0)


def viscous_negative(angles, vel, acc, shapes=None):
    """``dq [dq < 0]``."""
    return np.where(vel < 0, vel, 0.0)


def coulomb_positive(angles, vel, acc, shapes=None):
    """``[dq > 0]``."""
    return (vel > 0).astype(float)


def coulomb_negative(angles, vel, acc, shapes=None):
    """``-[dq < 0]``."""
    return -(vel < 0).astype(float)


def stribeck_term(angles, vel, acc, shapes=None):
    """:func:`stribeck_column` in the table's signature."""
    return stribeck_column(vel, shapes)


def sigmoid_term(angles, vel, acc, shapes=None):
    """:func:`sigmoid_column` in the table's signature."""
    return sigmoid_column(vel, shapes)


def load_column(load, vel, *_):
    """``|tau_load| sign(dq)``, shape like ``vel`` (..., nv); ``load`` [N m or N]."""
    return np.abs(load) * np.sign(vel)


# ------------------------------------------------------- hysteresis (Dahl) law
@dataclass(frozen=True)
class HysteresisCarry:
    """The hysteresis state at the end of a block: where the next block starts from.

    Attributes
    ----------
    angle : ndarray
        The last joint angle per DoF, shape (nv,) [rad or m].
    state : ndarray
        The Dahl state ``s`` there, shape (nv,) [-].
    """

    angle: np.ndarray
    state: np.ndarray


@dataclass(frozen=True)
class HysteresisTrace:
    """:func:`hysteresis_state` of one block: the state per sample and the carry."""

    state: np.ndarray  # (N, nv) [-]
    carry: HysteresisCarry


def hysteresis_state(angles, shapes: FrictionShapes | None, start=None) -> HysteresisTrace:
    """The Dahl state ``s`` of every sample of a block of joint angles (module docstring).

    Parameters
    ----------
    angles : ndarray
        Joint angles in sample order, shape (N, nv) [rad or m].
    shapes : FrictionShapes or None
        ``hysteresis_length`` per DoF (None: :data:`DEFAULT_HYSTERESIS_LENGTH`).
    start : HysteresisCarry or None
        The state at the end of the previous block of the same trajectory (None: the
        block starts the trajectory, ``s = 0`` and no step before its first sample).

    Returns
    -------
    HysteresisTrace
        ``state`` (N, nv) and the carry after the last sample.
    """
    q = np.asarray(angles, dtype=float)
    xc = (shapes or NO_SHAPES).values("hysteresis_length", DEFAULT_HYSTERESIS_LENGTH)
    if start is None:
        prev, s = q[:1], np.zeros(q.shape[1])
    else:
        prev, s = start.angle[None, :], np.array(start.state, dtype=float)
    step = np.diff(q, axis=0, prepend=prev if q.shape[0] else q[:0])
    sigma, decay = np.sign(step), np.exp(-np.abs(step) / xc)
    out = np.empty_like(q)
    for k in range(q.shape[0]):  # s_k = sigma + (s_(k-1) - sigma) exp(-|d|/xc)
        s = sigma[k] + (s - sigma[k]) * decay[k]
        out[k] = s
    last = q[-1].copy() if q.shape[0] else prev[0].copy()
    return HysteresisTrace(out, HysteresisCarry(last, s.copy()))


def _harmonic(angles, vel, acc, shapes=None, *, order: int, cosine: bool):
    return np.cos(order * angles) if cosine else np.sin(order * angles)


def harmonic_column(order: int, cosine: bool):
    """The column function of ``sin(k q)`` or ``cos(k q)`` (``k = order``; picklable)."""
    return partial(_harmonic, order=int(order), cosine=bool(cosine))


@dataclass(frozen=True)
class FrictionSpec:
    """A parsed ``--friction`` list.

    Attributes
    ----------
    kinds : frozenset of str
        The kinds (:data:`FRICTION_KINDS`).
    harmonics : int
        Order K of ``position`` (0 when not requested).
    """

    kinds: frozenset
    harmonics: int = 0


def parse_friction(friction) -> FrictionSpec:
    """A list of kinds or a comma-separated string (``"viscous,coulomb,position:3"``).

    ``position`` alone takes :data:`DEFAULT_HARMONICS` harmonics.
    """
    if isinstance(friction, str):
        friction = [f for f in friction.replace(",", " ").split() if f]
    if not isinstance(friction, list | tuple | set | frozenset):
        raise InputError(
            f"friction must be a list of kinds or a comma-separated string, got {friction!r}"
        )
    kinds, harmonics = set(), 0
    for f in friction:
        name, _, order = str(f).partition(":")
        if name not in FRICTION_KINDS:
            raise InputError(
                f"unknown friction kind {f!r}; expected some of {list(FRICTION_KINDS)}"
            )
        if order and name != "position":
            raise InputError(f"friction kind {name!r} takes no order (got {f!r})")
        if name == "position":
            try:
                harmonics = int(order) if order else DEFAULT_HARMONICS
            except ValueError:
                harmonics = -1
            if not 1 <= harmonics <= MAX_HARMONICS:
                raise InputError(
                    f"position friction takes an order 1..{MAX_HARMONICS} ('position:K'), got {f!r}"
                )
        kinds.add(name)
    return FrictionSpec(frozenset(kinds), harmonics)


def friction_columns(spec: FrictionSpec) -> set[str]:
    """The joint-term names (``parameters.JOINT_TERMS``) a friction spec enables."""
    k = spec.kinds
    out = {n for n, kind in (("fv", "viscous"), ("fc", "coulomb"), ("fo", "offset")) if kind in k}
    if "asymmetric" in k:
        out -= {"fv", "fc"}
        out |= {"fvp", "fvn"} | ({"fc"} if "offset" in k else {"fcp", "fcn"})
    if "stribeck" in k:
        out |= {"fs"} | ({"fcp", "fcn"} if "fcp" in out else {"fc"})
    if "sigmoid" in k:
        out.add("fsg")
    if "load" in k:
        out.add("fl")
    if "hysteresis" in k:
        out.add("fh")
    for order in range(1, spec.harmonics + 1):
        out |= {f"h{order}s", f"h{order}c"}
    return out
