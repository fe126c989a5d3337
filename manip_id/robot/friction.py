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
    temperature   fvt (T - T0) dq + fct (T - T0) sign(dq)            fvt [N m s/(rad K)]
                                                                     fct [N m/K]
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

``temperature`` makes the viscous and Coulomb coefficients linear in the joint's measured
temperature ``T`` (degC or K: only differences enter): ``fv(T) = fv + fvt (T - T0)`` and
``fc(T) = fc + fct (T - T0)``, so it adds the columns ``(T - T0) dq`` and ``(T - T0)
sign(dq)`` to ``viscous`` and ``coulomb``. ``T`` is a measured signal (a ``temp`` field of
the data: one column per DoF, or one broadcast to every DoF); the reference ``T0`` is a
shape, fixed before the solve: by default the training data's mean temperature per DoF,
from the sums of :class:`TemperatureStats` (so every path that adds sums agrees).

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
slope ``a`` [s/rad] and shift ``c`` [rad/s], the reference temperature ``T0`` [degC or
K], the hysteresis length ``xc`` [rad], per DoF. They are fixed when the linear solve
runs; :mod:`manip_id.identification.selection` chooses them by variable projection (a
grid, each point solved from its accumulated sums, then refined).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from ..errors import InputError

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
    "temperature",
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


#: The fields of :class:`FrictionShapes`.
SHAPE_FIELDS = (
    "stribeck_velocity",
    "sigmoid_slope",
    "sigmoid_shift",
    "temperature_reference",
    "temperature_low",
    "temperature_high",
    "hysteresis_length",
)


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
    temperature_reference : tuple of float or None
        ``T0`` [degC or K] per DoF of the ``temperature`` law (None: 0, the raw
        temperature; the identification sets the training data's mean).
    temperature_low, temperature_high : tuple of float or None
        The training data's temperature range per DoF [degC or K], where the law was
        fitted (the physically consistent estimate keeps ``fv(T)``, ``fc(T)`` >= 0 there).
    hysteresis_length : tuple of float or None
        ``xc`` [rad or m] per DoF (None: :data:`DEFAULT_HYSTERESIS_LENGTH`).
    """

    stribeck_velocity: tuple[float, ...] | None = None
    sigmoid_slope: tuple[float, ...] | None = None
    sigmoid_shift: tuple[float, ...] | None = None
    temperature_reference: tuple[float, ...] | None = None
    temperature_low: tuple[float, ...] | None = None
    temperature_high: tuple[float, ...] | None = None
    hysteresis_length: tuple[float, ...] | None = None

    def __post_init__(self):
        for name in SHAPE_FIELDS:  # each None or a sequence of real numbers, kept as floats
            v = getattr(self, name)
            if v is None:
                continue
            if isinstance(v, (str, bytes)) or np.iscomplexobj(v):
                raise InputError(f"{name} takes one real number per DoF, got {v!r:.80}")
            try:
                values = tuple(float(x) for x in np.atleast_1d(np.asarray(v, dtype=float)))
            except (TypeError, ValueError) as exc:
                raise InputError(f"{name} takes one real number per DoF, got {v!r:.80}") from exc
            if np.ndim(v) > 1 or not values:
                raise InputError(f"{name} takes one real number per DoF, got {v!r:.80}")
            object.__setattr__(self, name, values)
        for name in ("stribeck_velocity", "sigmoid_slope", "hysteresis_length"):
            v = getattr(self, name)
            if v is not None and not all(np.isfinite(x) and x > 0 for x in v):
                raise InputError(f"{name} must be positive and finite per DoF, got {v}")
        for name in SHAPE_FIELDS[2:]:
            v = getattr(self, name)
            if v is not None and not all(np.isfinite(v)):
                raise InputError(f"{name} must be finite per DoF, got {v}")

    def check_size(self, nv: int, robot: str = "the robot") -> None:
        """Raise :class:`~manip_id.errors.InputError` unless every set field has ``nv`` values."""
        for name in SHAPE_FIELDS:
            v = getattr(self, name)
            if v is not None and len(v) != nv:
                raise InputError(
                    f"FrictionShapes.{name} has {len(v)} value(s) but {robot} has nv={nv} DoF"
                )

    def values(self, name: str, default: float) -> np.ndarray | float:
        """The per-DoF values of field ``name`` (an array), or ``default`` when unset."""
        v = getattr(self, name)
        return default if v is None else np.asarray(v, dtype=float)

    def to_dict(self) -> dict:
        """JSON-ready fields (None for unset)."""
        return {
            k: None if getattr(self, k) is None else list(map(float, getattr(self, k)))
            for k in SHAPE_FIELDS
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


def temperature_difference(temp, vel, shapes: FrictionShapes | None) -> np.ndarray:
    """``T - T0``, shape like ``vel`` (..., nv): ``temp`` (..., nv) or (..., 1) [degC or K]
    broadcast to every DoF, ``T0`` the shapes' ``temperature_reference`` (None: 0)."""
    t0 = (shapes or NO_SHAPES).values("temperature_reference", 0.0)
    return np.broadcast_to(np.asarray(temp, dtype=float), np.shape(vel)) - t0


def viscous_temperature(temp, vel, shapes=None):
    """``(T - T0) dq``, shape like ``vel`` (..., nv)."""
    return temperature_difference(temp, vel, shapes) * vel


def coulomb_temperature(temp, vel, shapes=None):
    """``(T - T0) sign(dq)``, shape like ``vel`` (..., nv)."""
    return temperature_difference(temp, vel, shapes) * np.sign(vel)


@dataclass(frozen=True)
class TemperatureStats:
    """Sums of a temperature signal per column: count, sum, min, max (they merge by ``+``).

    Attributes
    ----------
    n : int
        Samples summed.
    total, low, high : numpy.ndarray
        Per column sum, minimum and maximum [degC or K], shape (k,) (k = 1 or nv).
    """

    n: int
    total: np.ndarray
    low: np.ndarray
    high: np.ndarray

    @classmethod
    def of(cls, temp) -> TemperatureStats:
        """The sums of ``temp`` (N, k) [degC or K]."""
        t = np.asarray(temp, dtype=float).reshape(np.shape(temp)[0], -1)
        return cls(t.shape[0], t.sum(axis=0), t.min(axis=0), t.max(axis=0))

    def __add__(self, other: TemperatureStats) -> TemperatureStats:
        if self.total.shape != other.total.shape:
            raise InputError(
                f"temperature columns differ between data sets: {self.total.size} and "
                f"{other.total.size}"
            )
        return TemperatureStats(
            self.n + other.n,
            self.total + other.total,
            np.minimum(self.low, other.low),
            np.maximum(self.high, other.high),
        )

    def per_dof(self, nv: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(mean, min, max)`` per DoF [degC or K], each (nv,) (one column broadcast)."""
        if self.n < 1:
            raise InputError("no temperature samples to take the reference T0 from")
        return tuple(  # type: ignore[return-value]
            np.broadcast_to(v, (nv,)).astype(float)
            for v in (self.total / self.n, self.low, self.high)
        )


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


def hysteresis_column(state, vel, shapes=None):
    """The ``fh`` column: the Dahl state ``s`` (..., nv) of :func:`hysteresis_state` as is."""
    return np.asarray(state, dtype=float)


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
    if "temperature" in k:
        out |= {"fvt", "fct"}
    if "hysteresis" in k:
        out.add("fh")
    for order in range(1, spec.harmonics + 1):
        out |= {f"h{order}s", f"h{order}c"}
    return out
