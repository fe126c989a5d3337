"""Transmissions: gear ratios, coupled joints, motor-side signals and motor terms.

An industrial drive train maps the joint positions ``q`` to the motor positions
``theta`` linearly::

    theta = R (q - offset)            R: (n, n), invertible
    dtheta = R dq,   ddtheta = R ddq
    tau_joint = R^T tau_motor         (power: tau_motor^T dtheta = tau_joint^T dq)

The diagonal of ``R`` holds the gear ratios (signs allowed), the off-diagonal entries
the couplings (a wrist where motor 6 drives joints 5 and 6 has ``R[5, 4] != 0``).
``offset`` is the joint position at which every motor reads zero.

A log recorded on the motor side (``signals = "motor"``) is converted to the joint
side before anything else reads it (:meth:`Transmission.to_joint`)::

    q = R^-1 theta + offset,  dq = R^-1 dtheta,  ddq = R^-1 ddtheta,  tau = R^T tau_motor

Motor terms act on the motor's own velocity and are mapped back by ``R^T``: motor
``i`` with rotor inertia ``Ia``, viscous ``fv``, Coulomb ``fc`` friction and an offset
``fo`` adds the joint torques::

    tau_joint += R^T e_i (Ia_i ddtheta_i + fv_i dtheta_i + fc_i sign(dtheta_i) + fo_i)

so a coupled motor's terms appear in the torque of every joint it drives. They are
extra regressor columns after the joint terms, named ``motor6.Ia``, ``motor6.fv``,
``motor6.fc``, ``motor6.fo`` (motor-major), in motor-side units (kg m^2, N m s/rad,
N m, N m). For a diagonal ``R`` with ratio ``r_j`` they equal joint-side terms::

    Ia_joint = r^2 Ia,   fv_joint = r^2 fv,   fc_joint = |r| fc,   fo_joint = r fo

(:meth:`Transmission.joint_equivalent`); when joint-side terms of the same kind are
modelled too, the base-parameter reduction regroups the duplicates.

A transmission file (``--transmission FILE.toml``) or the ``[transmission]`` table of
a robot profile holds::

    matrix = [[100, 0], [0, 50]]      # R, square (one row per motor)
    offset = [0.0, 0.0]               # [rad or m], default zeros
    signals = "motor"                 # or "joint" (the log is already joint-side)
    motor_terms = ["inertia", "viscous", "coulomb"]   # any of inertia, viscous,
                                                      # coulomb, offset
    motor_names = ["m1", "m2"]        # default motor1, motor2, ...
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._io.reading import read_toml
from ..errors import InputError, shorten
from .parameters import ColumnOwner, ParameterLayout

#: Motor term kinds -> their short parameter names, in column order.
MOTOR_TERMS: dict[str, str] = {"inertia": "Ia", "viscous": "fv", "coulomb": "fc", "offset": "fo"}
#: Motor-side units of each short name (a rotary motor).
MOTOR_UNITS: dict[str, str] = {"Ia": "kg m^2", "fv": "N m s/rad", "fc": "N m", "fo": "N m"}
#: Keys of a transmission table.
KEYS: tuple[str, ...] = ("matrix", "offset", "signals", "motor_terms", "motor_names")
SIGNALS: tuple[str, ...] = ("motor", "joint")
#: Largest condition number of R taken as invertible.
MAX_CONDITION = 1e12


#: The largest magnitude of a transmission matrix entry (a gear ratio, motor per joint):
#: beyond it the number is no drive's (harmonic drives reach a few hundred).
MAX_RATIO = 1e6
#: The largest magnitude of a joint offset [rad or m] (the plausible positions).
MAX_OFFSET = 1e4


def _matrix(value: Any, where: str) -> np.ndarray:
    try:
        R = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{where}: matrix must be a square array of numbers: {exc}") from exc
    if R.ndim != 2 or R.shape[0] != R.shape[1] or R.shape[0] == 0:
        raise InputError(f"{where}: matrix must be square (n, n), got shape {R.shape}")
    if not np.isfinite(R).all():
        raise InputError(f"{where}: matrix must be finite, got {shorten(R.tolist())}")
    if np.abs(R).max() > MAX_RATIO:
        raise InputError(
            f"{where}: matrix entries must be gear ratios of magnitude <= {MAX_RATIO:g} "
            f"(motor per joint), got {float(np.abs(R).max()):g}"
        )
    cond = np.linalg.cond(R)
    if not cond < MAX_CONDITION:
        raise InputError(
            f"{where}: matrix must be invertible (theta = R (q - offset)), but its condition "
            f"number is {cond:.3g}"
        )
    return R


@dataclass(frozen=True, eq=False)
class Transmission:
    """The linear map between joints and motors (module docstring).

    Attributes
    ----------
    matrix : array, shape (n, n)
        ``R`` with ``theta = R (q - offset)``.
    offset : array, shape (n,)
        Joint positions at which the motors read zero [rad or m].
    signals : str
        ``"motor"``: logs hold motor-side positions, velocities, accelerations and
        torques; ``"joint"``: they are joint-side already.
    motor_terms : tuple of str
        Motor terms modelled, some of :data:`MOTOR_TERMS` (``"inertia"``, ...).
    motor_names : tuple of str
        One name per motor (default ``motor1``, ``motor2``, ...).
    """

    matrix: ArrayLike
    offset: ArrayLike | None = None
    signals: str = "joint"
    motor_terms: Sequence[str] = ()
    motor_names: Sequence[str] | None = None
    source: str = field(default="", compare=False)

    def __post_init__(self):
        where = f"transmission {self.source}".strip()
        R = _matrix(self.matrix, where)
        R.setflags(write=False)
        n = R.shape[0]
        off = np.zeros(n) if self.offset is None else np.array(self.offset, dtype=float)
        if off.shape != (n,) or not np.isfinite(off).all() or np.abs(off).max() > MAX_OFFSET:
            raise InputError(
                f"{where}: offset must be {n} finite values of magnitude <= {MAX_OFFSET:g} "
                f"[rad or m], got {shorten(off.tolist())}"
            )
        off.setflags(write=False)
        if self.signals not in SIGNALS:
            raise InputError(f"{where}: signals must be 'motor' or 'joint', got {self.signals!r}")
        terms = [self.motor_terms] if isinstance(self.motor_terms, str) else self.motor_terms
        terms = tuple(str(t) for t in terms)
        bad = [t for t in terms if t not in MOTOR_TERMS]
        if bad:
            raise InputError(
                f"{where}: motor_terms holds {bad[0]!r}; expected some of {list(MOTOR_TERMS)}"
            )
        terms = tuple(t for t in MOTOR_TERMS if t in terms)  # column order, no repeats
        names = (
            tuple(f"motor{i + 1}" for i in range(n))
            if self.motor_names is None
            else tuple(str(m) for m in self.motor_names)
        )
        if len(names) != n or len(set(names)) != n or not all(names):
            raise InputError(f"{where}: motor_names must be {n} distinct names, got {names}")
        object.__setattr__(self, "matrix", R)
        object.__setattr__(self, "offset", off)
        object.__setattr__(self, "motor_terms", terms)
        object.__setattr__(self, "motor_names", names)

    # ------------------------------------------------------------------ reading
    @classmethod
    def from_dict(cls, raw: Mapping[str, Any], source: str = "") -> Transmission:
        """A transmission from a parsed table (module docstring)."""
        where = f"transmission {source}".strip()
        if not isinstance(raw, Mapping):
            raise InputError(f"{where} must be a table, got {type(raw).__name__}")
        unknown = [k for k in raw if k not in KEYS]
        if unknown:
            raise InputError(f"{where}: unknown key {unknown[0]!r}; expected some of {list(KEYS)}")
        if "matrix" not in raw:
            raise InputError(f"{where}: needs a matrix (theta = R (q - offset))")
        return cls(
            raw["matrix"],
            raw.get("offset"),
            str(raw.get("signals", "joint")),
            tuple(raw.get("motor_terms", ())),
            raw.get("motor_names"),
            source=source,
        )

    @classmethod
    def from_toml(cls, path: str | Path) -> Transmission:
        """Read a transmission file: the keys at the top level or in a ``[transmission]``
        table (a robot profile's)."""
        raw = read_toml(Path(path).expanduser(), "transmission file", error=InputError)
        table = raw.get("transmission", raw) if isinstance(raw, Mapping) else raw
        return cls.from_dict(table, source=str(path))

    def to_dict(self) -> dict:
        """The JSON / TOML table of this transmission (:meth:`from_dict` reads it back)."""
        return {
            "matrix": self.R.tolist(),
            "offset": self.q0.tolist(),
            "signals": self.signals,
            "motor_terms": list(self.motor_terms),
            "motor_names": list(self.motor_names or ()),
        }

    # -------------------------------------------------------------------- sizes
    @property
    def R(self) -> np.ndarray:
        """The matrix ``R``, shape (n, n)."""
        return np.asarray(self.matrix)

    @property
    def q0(self) -> np.ndarray:
        """The offset, shape (n,) [rad or m]."""
        return np.asarray(self.offset)

    @property
    def n(self) -> int:
        """Number of motors (= joints)."""
        return self.R.shape[0]

    @cached_property
    def R_inv(self) -> np.ndarray:
        """``R^-1``, shape (n, n)."""
        return np.linalg.inv(self.R)

    @property
    def is_diagonal(self) -> bool:
        """Whether no motor drives more than one joint."""
        return bool(np.all(self.R == np.diag(np.diag(self.R))))

    @property
    def ratios(self) -> np.ndarray:
        """The diagonal of ``R`` (gear ratios), shape (n,)."""
        return np.diag(self.R).copy()

    @property
    def term_names(self) -> tuple[str, ...]:
        """Short names of the motor terms, in column order (``"Ia"``, ``"fv"``, ...)."""
        return tuple(MOTOR_TERMS[t] for t in self.motor_terms)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names of the motor-term columns, motor-major: ``motor1.Ia, motor1.fv, ...``."""
        return tuple(f"{m}.{t}" for m in self.motor_names or () for t in self.term_names)

    @property
    def parameter_units(self) -> tuple[str, ...]:
        """Units of the motor-term columns, aligned with :attr:`parameter_names`."""
        return tuple(MOTOR_UNITS[t] for _ in self.motor_names or () for t in self.term_names)

    @property
    def n_parameters(self) -> int:
        """Number of motor-term columns."""
        return self.n * len(self.motor_terms)

    def check_size(self, nv: int, what: str = "the robot") -> None:
        """Raise :class:`InputError` unless the transmission has ``nv`` motors."""
        if self.n != nv:
            raise InputError(
                f"the transmission has {self.n} motors (matrix {self.R.shape}) but {what} "
                f"has nv={nv} joints"
            )

    # ----------------------------------------------------------------- signals
    def to_joint(self, theta=None, dtheta=None, ddtheta=None, tau_motor=None):
        """Joint-side signals from motor-side ones, each of shape (..., n) or None.

        Returns ``(q, dq, ddq, tau)``: ``q = R^-1 theta + offset`` [rad],
        ``dq = R^-1 dtheta``, ``ddq = R^-1 ddtheta``, ``tau = R^T tau_motor`` [N m].
        """
        Ri = self.R_inv
        q = None if theta is None else np.asarray(theta, float) @ Ri.T + self.q0
        dq = None if dtheta is None else np.asarray(dtheta, float) @ Ri.T
        ddq = None if ddtheta is None else np.asarray(ddtheta, float) @ Ri.T
        tau = None if tau_motor is None else np.asarray(tau_motor, float) @ self.R
        return q, dq, ddq, tau

    def to_motor(self, q=None, dq=None, ddq=None, tau=None):
        """Motor-side signals from joint-side ones (the inverse of :meth:`to_joint`).

        Returns ``(theta, dtheta, ddtheta, tau_motor)``: ``theta = R (q - offset)``,
        ``dtheta = R dq``, ``ddtheta = R ddq``, ``tau_motor = R^-T tau``.
        """
        R = self.R
        theta = None if q is None else (np.asarray(q, float) - self.q0) @ R.T
        dtheta = None if dq is None else np.asarray(dq, float) @ R.T
        ddtheta = None if ddq is None else np.asarray(ddq, float) @ R.T
        tau_m = None if tau is None else np.asarray(tau, float) @ self.R_inv
        return theta, dtheta, ddtheta, tau_m

    def convert_rows(self, block: np.ndarray, slices: Mapping[str, slice]) -> np.ndarray:
        """Packed rows (:mod:`manip_id.datasets.layout`) converted to the joint side: a
        copy with ``q``, ``dq``, ``tau`` and (when present) ``ddq`` mapped; the block itself
        when ``signals == "joint"``."""
        if self.signals == "joint":
            return block
        out = block.copy()
        sq, sdq, stau = slices["q"], slices["dq"], slices["tau"]
        width = sq.stop - sq.start
        if width != self.n or sdq.stop - sdq.start != self.n:
            raise InputError(
                f"the transmission has {self.n} motors but the log has {width} position "
                f"and {sdq.stop - sdq.start} velocity columns"
            )
        q, dq, ddq, tau = self.to_joint(
            block[:, sq],
            block[:, sdq],
            block[:, slices["ddq"]] if "ddq" in slices else None,
            block[:, stau],
        )
        out[:, sq], out[:, sdq], out[:, stau] = q, dq, tau
        if ddq is not None:
            out[:, slices["ddq"]] = ddq
        return out

    # -------------------------------------------------------------- motor terms
    def motor_values(self, dq, ddq) -> np.ndarray:
        """The motor-side term values ``f_k(dtheta_i, ddtheta_i)``, shape (..., n, nt_m):
        ``Ia: ddtheta_i, fv: dtheta_i, fc: sign(dtheta_i), fo: 1``."""
        dth = np.asarray(dq, float) @ self.R.T
        cols = []
        for t in self.term_names:
            if t == "Ia":
                cols.append(np.asarray(ddq, float) @ self.R.T)
            elif t == "fv":
                cols.append(dth)
            elif t == "fc":
                cols.append(np.sign(dth))
            else:
                cols.append(np.ones_like(dth))
        return np.stack(cols, axis=-1) if cols else np.zeros((*dth.shape, 0))

    def columns(self, dq, ddq) -> np.ndarray:
        """The regressor columns of the motor terms, shape (..., n, n_parameters).

        Entry ``[j, i nt + k]`` is ``R[i, j] f_k(dtheta_i, ddtheta_i)``: motor ``i``'s term
        ``k`` mapped to joint ``j`` by ``R^T``. ``dq``, ``ddq``: joint velocities and
        accelerations, shape (..., n).
        """
        vals = self.motor_values(dq, ddq)  # (..., n_motor, nt)
        # (..., joint j, motor i, term k) = R[i, j] vals[..., i, k]
        out = self.R.T[:, :, None] * vals[..., None, :, :]
        return out.reshape(*out.shape[:-2], self.n_parameters)

    def torques(self, coefficients, dq, ddq) -> np.ndarray:
        """Joint torques of the motor terms with values ``coefficients`` (n_parameters,),
        shape like ``dq`` [N m]."""
        c = np.asarray(coefficients, dtype=float)
        if c.shape != (self.n_parameters,):
            raise InputError(
                f"motor term values: shape {c.shape} but the transmission has "
                f"{self.n_parameters} ({', '.join(self.parameter_names)})"
            )
        return self.columns(dq, ddq) @ c

    def joint_equivalent(self, coefficients) -> dict[str, np.ndarray]:
        """For a diagonal ``R``: the joint-side terms equal to the motor terms with values
        ``coefficients`` (module docstring), short name -> shape (n,)."""
        if not self.is_diagonal:
            raise InputError("joint-side equivalents of motor terms need a diagonal matrix R")
        c = np.asarray(coefficients, dtype=float).reshape(self.n, len(self.motor_terms))
        r = self.ratios
        scale = {"Ia": r**2, "fv": r**2, "fc": np.abs(r), "fo": r}
        return {t: scale[t] * c[:, k] for k, t in enumerate(self.term_names)}

    def __repr__(self) -> str:
        return (
            f"Transmission(n={self.n}, signals={self.signals!r}, "
            f"motor_terms={list(self.motor_terms)}, diagonal={self.is_diagonal})"
        )


class MotorLayout(ParameterLayout):
    """A :class:`~manip_id.robot.parameters.ParameterLayout` with a transmission's motor terms as
    its last columns, after the joint terms (``motor6.Ia``, ...: :attr:`Transmission.
    parameter_names`); ``motors`` is the transmission. Owners of motor columns have kind
    ``"motor"``, the motor's index and the joint of the same index."""

    def __init__(self, *args, motors: Transmission, **kwargs):
        super().__init__(*args, **kwargs)
        motors.check_size(self.nv)
        self.motors = motors

    @property
    def motor_start(self) -> int:
        """First motor-term column, 10 nb + nt nv."""
        return self.n_rigid + self.n_terms * self.nv

    @property
    def n_parameters(self) -> int:
        """Number of standard parameters p = 10 nb + nt nv + motor terms."""
        return self.motor_start + self.motors.n_parameters

    @cached_property
    def names(self) -> tuple[str, ...]:
        """The joint layout's names, then the motor terms' (``motor6.Ia``)."""
        return (*super().names, *self.motors.parameter_names)

    @cached_property
    def units(self) -> tuple[str, ...]:
        """The joint layout's units, then the motor terms' (motor side)."""
        return (*super().units, *self.motors.parameter_units)

    def joint_block(self, theta: ArrayLike) -> np.ndarray:
        """The joint-term parameters, (..., p) -> (..., nv, nt); a view when possible."""
        arr = self._check_theta(theta)
        block = arr[..., self.n_rigid : self.motor_start]
        return block.reshape(*arr.shape[:-1], self.nv, self.n_terms)

    def motor_block(self, theta: ArrayLike) -> np.ndarray:
        """The motor-term parameters, (..., p) -> (..., n_motor); a view."""
        return self._check_theta(theta)[..., self.motor_start :]

    def owner(self, column: int) -> ColumnOwner:
        """What column ``column`` belongs to (a body, a joint term or a motor term)."""
        col = int(column)
        if not self.motor_start <= col < self.n_parameters:
            return super().owner(col)
        motor, k = divmod(col - self.motor_start, len(self.motors.motor_terms))
        return ColumnOwner("motor", motor, self.dofs.joints[motor], self.motors.term_names[k])

    def __repr__(self) -> str:
        return f"{super().__repr__()[:-1]}, motors={self.motors!r})"


def load_transmission(spec) -> Transmission | None:
    """A :class:`Transmission` from itself, a mapping (a table) or a ``.toml`` path; None
    passes through."""
    if spec is None or isinstance(spec, Transmission):
        return spec
    if isinstance(spec, Mapping):
        return Transmission.from_dict(spec)
    if isinstance(spec, str | Path):
        return Transmission.from_toml(spec)
    raise InputError(
        f"a transmission must be a Transmission, a table or a .toml path, got {type(spec).__name__}"
    )
