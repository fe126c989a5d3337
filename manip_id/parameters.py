"""The parameter layout: names, units, body blocks, joint-term columns, standard <-> base.

The standard parameter vector of a robot with ``nb`` moving bodies and ``nv``
velocity coordinates is::

    theta = [body_1 (10), ..., body_nb (10), joint terms (nv * nt)]      shape (p,)

Body ``i`` holds Pinocchio's standard inertial parameters of the body carried
by joint ``i`` (``Inertia.toDynamicParameters()``), about the joint frame origin::

    [m, mcx, mcy, mcz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]        [kg, kg m, kg m^2]

The joint terms follow, DoF-major: the ``nt`` enabled terms of DoF 0, then of
DoF 1, ..., so the column of term ``t`` of DoF ``j`` is

    joint_column(j, t) = 10 nb + j nt + position of t among the enabled terms.

:data:`JOINT_TERMS` is the one table of the joint terms: for each, its
regressor column (only row ``j`` is non-zero), its units and its torque
``tau_j = theta_(j, t) * column_j``::

    Ia  armature   ddq_j           [kg m^2 | kg]
    fv  viscous    dq_j            [N m s/rad | N s/m]
    fc  Coulomb    sign(dq_j)      [N m | N]
    fo  offset     1               [N m | N]
    k   spring     q_j             [N m/rad | N/m]
    fvp, fvn       dq_j [dq_j > 0], dq_j [dq_j < 0]        [N m s/rad | N s/m]
    fcp, fcn       [dq_j > 0], -[dq_j < 0]                  [N m | N]
    fs  Stribeck   exp(-(dq_j/vs_j)^2) sign(dq_j)           [N m | N]
    fsg sigmoid    S(a_j (dq_j + c_j)) - S(a_j c_j)         [N m | N]
    hks, hkc       sin(k q_j), cos(k q_j), k = 1..4         [N m | N]
    fl  load       |tau_load_j| sign(dq_j)                  [1]
    fvt, fct       (T_j - T0_j) dq_j, (T_j - T0_j) sign(dq_j)  [N m s/(rad K) | N m/K]
    fh  hysteresis s_j, the Dahl state of q_j's path         [N m | N]

(the friction laws, their shapes ``vs, a, c`` and how they combine:
:mod:`manip_id.friction`). A layout may switch terms off for some DoFs
(``mask``): their columns stay, identically zero, so the base parameters drop them.

(revolute | prismatic units; ``q_j`` is the joint angle, ``atan2(sin, cos)``
for a continuous joint stored as (cos, sin): see :class:`DofLayout`).

Limits. A position range wider than :data:`UNSET_LIMIT` (1e3 rad or m), an
infinite or empty one, and a velocity limit that is not positive, infinite or
above :data:`UNSET_LIMIT` count as *unset* (URDFs write 1e10 or nothing):
:func:`bounded_range` and :func:`bounded_rate` are that rule.

Standard <-> base lives in one place, :class:`~manip_id.identifiability.BaseParameters`
(``to_base``, ``from_base``): with independent columns ``I``, dependent ``D``,
regrouping ``K``::

    theta_base = theta[I] + K theta[D]                       (standard -> base)
    theta      = P^T [theta_base; 0]                         (base -> standard, minimum
                                                              support: zero on D)

Physical consistency (pseudo-inertias, :func:`check_consistency`) lives in
:mod:`manip_id.consistency`; this module re-exports it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from .consistency import ConsistencyReport as ConsistencyReport  # re-exported
from .consistency import check_consistency as check_consistency  # re-exported
from .consistency import parameters_from_pseudo_inertia as parameters_from_pseudo_inertia
from .consistency import pseudo_inertia
from .consistency import pseudo_inertia_basis as pseudo_inertia_basis  # re-exported
from .errors import InputError
from .friction import (
    MAX_HARMONICS,
    FrictionShapes,
    coulomb_negative,
    coulomb_positive,
    coulomb_temperature,
    harmonic_column,
    hysteresis_column,
    load_column,
    sigmoid_term,
    stribeck_term,
    viscous_negative,
    viscous_positive,
    viscous_temperature,
)

if TYPE_CHECKING:  # pragma: no cover
    import pinocchio as pin

#: Inertial parameter names of one body, in Pinocchio's order.
INERTIAL_NAMES: tuple[str, ...] = tuple("m mcx mcy mcz Ixx Ixy Iyy Ixz Iyz Izz".split())
#: Units of the inertial parameters of one body, aligned with :data:`INERTIAL_NAMES`.
INERTIAL_UNITS: tuple[str, ...] = ("kg", "kg m", "kg m", "kg m", *("kg m^2",) * 6)
#: Number of standard inertial parameters of one body.
BODY_SIZE = 10
#: Limits wider than this [rad, m, rad/s or m/s] are treated as unset.
UNSET_LIMIT = 1e3


# ------------------------------------------------------------------ joint terms
def _armature(angles, vel, acc, shapes=None):
    return acc


def _viscous(angles, vel, acc, shapes=None):
    return vel


def _coulomb(angles, vel, acc, shapes=None):
    return np.sign(vel)


def _offset(angles, vel, acc, shapes=None):
    return np.ones_like(vel)


def _spring(angles, vel, acc, shapes=None):
    return angles


_NEEDS = {
    "load": "the load torque (positions, velocities and accelerations of every joint)",
    "temp": "the measured temperature (a temp field of the data)",
    "history": "the samples in order (a state of the joint's path), not one sample alone",
}


@dataclass(frozen=True)
class JointTerm:
    """One joint-level term: its regressor column, its units and its torque.

    Attributes
    ----------
    name
        short name used in parameter names (``panda_joint3.fv``).
    flag
        the :class:`~manip_id.robot.JointTerms` attribute that enables it.
    column_text
        the regressor entry of row ``j``, as text (``"sign(dq_j)"``).
    unit_revolute, unit_prismatic
        unit of the parameter for a revolute / prismatic DoF.
    needs_angles
        whether the column uses the joint angle ``q_j``.
    needs
        the signal the column is built from: ``"load"`` (nominal rigid-body torque), ``"temp"``
        (measured temperature) or ``"history"`` (the path's Dahl state); None: none.
    """

    name: str
    flag: str
    column_text: str
    unit_revolute: str
    unit_prismatic: str
    needs_angles: bool
    _column: Callable[..., Any]
    needs: str | None = None

    def column(self, angles, vel, acc, shapes=None, load=None, temp=None, history=None):
        """Regressor entries of this term, shape like ``vel`` (..., nv).

        ``angles`` (..., nv) [rad or m] (``k``, the harmonics; may be None otherwise), ``vel``
        [rad/s or m/s], ``acc`` [rad/s^2 or m/s^2] (``Ia``); ``shapes`` the per-DoF shapes
        (None: defaults, :mod:`manip_id.friction`); the signals of :attr:`needs`: ``load`` the
        nominal rigid-body torque (..., nv) [N m or N] (``fl``), ``temp`` the temperature
        (..., nv) or (..., 1) [degC or K] (``fvt``, ``fct``), ``history`` the Dahl state
        (..., nv) of the samples' path (:func:`~manip_id.friction.hysteresis_state`, ``fh``).
        """
        if self.needs is not None:
            signal = {"load": load, "temp": temp, "history": history}[self.needs]
            if signal is None:
                raise InputError(
                    f"the {self.name} term ({self.column_text}) needs {_NEEDS[self.needs]}"
                )
            return self._column(signal, vel, shapes)
        return self._column(angles, vel, acc, shapes)

    def torque(self, coefficient, angles, vel, acc, shapes=None, load=None, temp=None):
        """``coefficient * column`` [N m or N], shape like ``vel`` (not for ``fh``)."""
        return coefficient * self.column(angles, vel, acc, shapes, load, temp)

    def unit(self, prismatic: bool) -> str:
        """Unit of this term's parameter for a prismatic or revolute DoF."""
        return self.unit_prismatic if prismatic else self.unit_revolute


#: The joint-term table, in column order.
JOINT_TERMS: tuple[JointTerm, ...] = (
    JointTerm("Ia", "armature", "ddq_j", "kg m^2", "kg", False, _armature),
    JointTerm("fv", "viscous", "dq_j", "N m s/rad", "N s/m", False, _viscous),
    JointTerm("fc", "coulomb", "sign(dq_j)", "N m", "N", False, _coulomb),
    JointTerm("fo", "offset", "1", "N m", "N", False, _offset),
    JointTerm("k", "spring", "q_j", "N m/rad", "N/m", True, _spring),
    JointTerm(
        "fvp", "asymmetric", "dq_j [dq_j > 0]", "N m s/rad", "N s/m", False, viscous_positive
    ),
    JointTerm(
        "fvn", "asymmetric", "dq_j [dq_j < 0]", "N m s/rad", "N s/m", False, viscous_negative
    ),
    JointTerm("fcp", "asymmetric", "[dq_j > 0]", "N m", "N", False, coulomb_positive),
    JointTerm("fcn", "asymmetric", "-[dq_j < 0]", "N m", "N", False, coulomb_negative),
    JointTerm("fs", "stribeck", "exp(-(dq_j/vs_j)^2) sign(dq_j)", "N m", "N", False, stribeck_term),
    JointTerm(
        "fsg", "sigmoid", "S(a_j (dq_j + c_j)) - S(a_j c_j)", "N m", "N", False, sigmoid_term
    ),
    *(
        JointTerm(
            f"h{k}{'c' if cos else 's'}",
            "position",
            f"{'cos' if cos else 'sin'}({k} q_j)",
            "N m",
            "N",
            True,
            harmonic_column(k, cos),
        )
        for k in range(1, MAX_HARMONICS + 1)
        for cos in (False, True)
    ),
    JointTerm("fl", "load", "|tau_load_j| sign(dq_j)", "1", "1", False, load_column, "load"),
    *(
        JointTerm(n, "temperature", text, ur, up, False, f, "temp")
        for n, text, ur, up, f in (
            ("fvt", "(T_j - T0_j) dq_j", "N m s/(rad K)", "N s/(m K)", viscous_temperature),
            ("fct", "(T_j - T0_j) sign(dq_j)", "N m/K", "N/K", coulomb_temperature),
        )
    ),
    JointTerm(
        "fh", "hysteresis", "s_j (Dahl state)", "N m", "N", True, hysteresis_column, "history"
    ),
)
#: Joint-level term names, in the order their columns appear for each joint.
JOINT_TERM_NAMES: tuple[str, ...] = tuple(t.name for t in JOINT_TERMS)
#: The table by short name.
JOINT_TERM: dict[str, JointTerm] = {t.name: t for t in JOINT_TERMS}


def joint_term(name: str) -> JointTerm:
    """The :class:`JointTerm` called ``name`` (one of ``Ia fv fc fo k``)."""
    try:
        return JOINT_TERM[name]
    except KeyError:
        raise InputError(
            f"unknown joint term {name!r}; expected one of {list(JOINT_TERM_NAMES)}"
        ) from None


# ----------------------------------------------------------------------- limits
def bounded_range(lower: ArrayLike, upper: ArrayLike) -> np.ndarray:
    """Which position ranges are set: finite, non-empty and at most :data:`UNSET_LIMIT` wide.

    ``lower``, ``upper``: shape (n,) [rad or m]. Returns a bool array of shape (n,).
    """
    lo = np.asarray(lower, dtype=float)
    hi = np.asarray(upper, dtype=float)
    with np.errstate(invalid="ignore"):
        return np.isfinite(lo) & np.isfinite(hi) & (hi > lo) & (hi - lo <= UNSET_LIMIT)


def bounded_rate(limit: ArrayLike) -> np.ndarray:
    """Which velocity (or effort) limits are set: finite, positive, at most :data:`UNSET_LIMIT`."""
    v = np.asarray(limit, dtype=float)
    with np.errstate(invalid="ignore"):
        return np.isfinite(v) & (v > 0) & (v <= UNSET_LIMIT)


# ------------------------------------------------------------------- DoF layout
def is_prismatic_joint(shortname: str) -> bool:
    """Whether a Pinocchio joint model (``JointModelPX``, ``JointModelPrismaticUnaligned``,
    ...) translates."""
    return "Prismatic" in shortname or (
        shortname.startswith("JointModelP") and shortname != "JointModelPlanar"
    )


@dataclass(frozen=True)
class DofLayout:
    """Where each velocity coordinate (DoF) of a model lives.

    Attributes
    ----------
    names
        one name per DoF: the joint name, with ``[k]`` for multi-DoF joints.
    joints
        the joint owning each DoF, length nv.
    q_index
        index in ``q`` of each DoF's coordinate, shape (nv,) (the cos entry
        of a continuous joint).
    continuous
        whether each DoF is a continuous joint stored as (cos, sin), shape (nv,).
    prismatic
        whether each DoF translates, shape (nv,).
    unsupported
        joints that are neither one coordinate per DoF nor continuous
        (``"name (JointModelX)"``); empty for the manipulators we load.
    """

    names: tuple[str, ...]
    joints: tuple[str, ...]
    q_index: np.ndarray
    continuous: np.ndarray
    prismatic: np.ndarray
    unsupported: tuple[str, ...] = ()

    @classmethod
    def from_model(cls, model: pin.Model) -> DofLayout:
        """The DoF layout of a Pinocchio model (joint 0, the universe, is skipped)."""
        names, joints, idx, cont, pris, bad = [], [], [], [], [], []
        for i in range(1, model.njoints):
            jm = model.joints[i]
            kind = jm.shortname()
            joint = str(model.names[i])
            is_cont = jm.nq == 2 and jm.nv == 1
            if jm.nq != jm.nv and not is_cont:
                bad.append(f"{joint} ({kind}, nq={jm.nq}, nv={jm.nv})")
            for k in range(jm.nv):
                names.append(joint if jm.nv == 1 else f"{joint}[{k}]")
                joints.append(joint)
                idx.append(jm.idx_q + (0 if is_cont else k))
                cont.append(is_cont)
                pris.append(is_prismatic_joint(kind))
        return cls(
            tuple(names),
            tuple(joints),
            np.array(idx, dtype=int),
            np.array(cont, dtype=bool),
            np.array(pris, dtype=bool),
            tuple(bad),
        )

    @property
    def nv(self) -> int:
        """Number of DoFs."""
        return len(self.names)

    @cached_property
    def has_continuous(self) -> bool:
        """Whether any DoF is a continuous joint."""
        return bool(self.continuous.any())

    def require_coordinates(self, what: str) -> None:
        """Raise :class:`InputError` unless every joint has one coordinate per DoF or is
        continuous; ``what`` says who needs it."""
        if self.unsupported:
            raise InputError(
                f"joint {self.unsupported[0]}: {what} need one coordinate per DoF "
                "or continuous (cos, sin) joints"
            )

    def angles(self, q: np.ndarray) -> np.ndarray:
        """Joint coordinate per DoF, shape (..., nq) -> (..., nv) [rad or m].

        Continuous joints give ``atan2(sin, cos)`` in (-pi, pi].
        """
        out = q[..., self.q_index]
        if self.has_continuous:
            c = self.continuous
            out[..., c] = np.arctan2(q[..., self.q_index[c] + 1], q[..., self.q_index[c]])
        return out

    def configuration(self, angles: np.ndarray, nq: int) -> np.ndarray:
        """Configurations from joint angles, shape (..., nv) -> (..., nq).

        Continuous joints are written as (cos, sin); the inverse of :meth:`angles`.
        """
        angles = np.asarray(angles, dtype=float)
        q = np.zeros((*angles.shape[:-1], nq))
        plain = ~self.continuous
        q[..., self.q_index[plain]] = angles[..., plain]
        if self.has_continuous:
            c = self.continuous
            q[..., self.q_index[c]] = np.cos(angles[..., c])
            q[..., self.q_index[c] + 1] = np.sin(angles[..., c])
        return q


# ------------------------------------------------------------- parameter layout
@dataclass(frozen=True)
class ColumnOwner:
    """What one column of theta belongs to.

    ``kind`` is ``"body"`` or ``"joint"``; ``index`` the body index (0-based) or the
    DoF index; ``joint`` the joint name (a body is named by the joint carrying it);
    ``parameter`` the short name (``"Ixx"``, ``"fv"``).
    """

    kind: str
    index: int
    joint: str
    parameter: str


class ParameterLayout:
    """The layout of a standard parameter vector (module docstring).

    Parameters
    ----------
    body_names
        the joint carrying each moving body, length nb.
    dofs
        the :class:`DofLayout` of the model.
    terms
        the enabled joint terms, in column order (a subsequence of
        :data:`JOINT_TERM_NAMES`).
    shapes
        the per-DoF shapes of the nonlinear laws (None: their defaults).
    mask
        which terms each DoF carries, bool shape (nv, nt) (None: all); a masked-out
        entry's column is identically zero.
    """

    def __init__(
        self,
        body_names: Sequence[str],
        dofs: DofLayout,
        terms: Sequence[str],
        shapes: FrictionShapes | None = None,
        mask: ArrayLike | None = None,
    ):
        self.body_names: tuple[str, ...] = tuple(body_names)
        self.dofs = dofs
        terms = tuple(terms)
        for t in terms:
            joint_term(t)
        if list(terms) != [t for t in JOINT_TERM_NAMES if t in terms]:
            raise InputError(f"joint terms {terms} are not in column order {JOINT_TERM_NAMES}")
        self.terms: tuple[str, ...] = terms
        self.term_table: tuple[JointTerm, ...] = tuple(JOINT_TERM[t] for t in terms)
        self.shapes = shapes
        self.mask: np.ndarray | None = None
        if mask is not None:
            m = np.asarray(mask, dtype=bool)
            if m.shape != (dofs.nv, len(terms)):
                raise InputError(
                    f"mask.shape={m.shape} but expected (nv, nt)={dofs.nv, len(terms)}"
                )
            self.mask = None if m.all() else m

    # ------------------------------------------------------------------ sizes
    @property
    def n_bodies(self) -> int:
        """Number of moving bodies nb."""
        return len(self.body_names)

    @property
    def n_rigid(self) -> int:
        """Number of rigid-body parameters, 10 nb."""
        return BODY_SIZE * self.n_bodies

    @property
    def nv(self) -> int:
        """Number of DoFs."""
        return self.dofs.nv

    @property
    def n_terms(self) -> int:
        """Number of enabled joint terms per DoF, nt."""
        return len(self.terms)

    @property
    def n_parameters(self) -> int:
        """Number of standard parameters p = 10 nb + nt nv."""
        return self.n_rigid + self.n_terms * self.nv

    # ------------------------------------------------------------ names, units
    @cached_property
    def names(self) -> tuple[str, ...]:
        """One readable name per column, e.g. ``panda_joint3.Ixx``, ``panda_joint3.fv``."""
        names = [f"{j}.{p}" for j in self.body_names for p in INERTIAL_NAMES]
        for dof in self.dofs.names:
            names += [f"{dof}.{t}" for t in self.terms]
        return tuple(names)

    @cached_property
    def units(self) -> tuple[str, ...]:
        """Unit of each column, aligned with :attr:`names`."""
        units = list(INERTIAL_UNITS) * self.n_bodies
        for prismatic in self.dofs.prismatic:
            units += [t.unit(bool(prismatic)) for t in self.term_table]
        return tuple(units)

    @cached_property
    def _index(self) -> dict[str, int]:
        return {n: i for i, n in enumerate(self.names)}

    def index(self, name: str) -> int:
        """Column of a parameter name; the error lists the parameters of the same joint."""
        try:
            return self._index[name]
        except KeyError:
            joint = name.split(".")[0]
            close = [n for n in self.names if n.startswith(joint + ".")]
            raise InputError(
                f"unknown parameter {name!r}; parameters of {joint!r}: {close or 'none'}"
            ) from None

    # ------------------------------------------------------------------ blocks
    def body_slice(self, body: int | str) -> slice:
        """Columns of one body's 10 inertial parameters (body index or joint name)."""
        i = self._body_index(body)
        return slice(BODY_SIZE * i, BODY_SIZE * (i + 1))

    def _body_index(self, body: int | str) -> int:
        if isinstance(body, str):
            if body not in self.body_names:
                raise InputError(f"unknown body {body!r}; bodies: {list(self.body_names)}")
            return self.body_names.index(body)
        i = int(body)
        if not 0 <= i < self.n_bodies:
            raise InputError(f"body index {i} out of range for {self.n_bodies} bodies")
        return i

    def _check_theta(self, theta: ArrayLike) -> np.ndarray:
        arr = np.asarray(theta)
        if arr.ndim == 0 or arr.shape[-1] != self.n_parameters:
            raise InputError(f"theta.shape={arr.shape} but n_parameters={self.n_parameters}")
        return arr

    def rigid_blocks(self, theta: ArrayLike) -> np.ndarray:
        """The bodies' inertial parameters, (..., p) -> (..., nb, 10); a view when possible."""
        arr = self._check_theta(theta)
        return arr[..., : self.n_rigid].reshape(*arr.shape[:-1], self.n_bodies, BODY_SIZE)

    def joint_block(self, theta: ArrayLike) -> np.ndarray:
        """The joint-term parameters, (..., p) -> (..., nv, nt); a view when possible."""
        arr = self._check_theta(theta)
        return arr[..., self.n_rigid :].reshape(*arr.shape[:-1], self.nv, self.n_terms)

    def has_term(self, term: str) -> bool:
        """Whether the joint term ``term`` (``"Ia"``, ``"fv"``, ...) is enabled."""
        return term in self.terms

    def joint_column(self, dof: int, term: str) -> int:
        """Column of joint term ``term`` of DoF ``dof``: ``10 nb + dof nt + position(term)``."""
        if term not in self.terms:
            joint_term(term)  # unknown name: its own error
            raise InputError(f"joint term {term!r} is not modelled; enabled: {list(self.terms)}")
        dof = int(dof)
        if not 0 <= dof < self.nv:
            raise InputError(f"dof {dof} out of range for nv={self.nv}")
        return self.n_rigid + dof * self.n_terms + self.terms.index(term)

    def joint_columns(self, term: str) -> np.ndarray:
        """Columns of joint term ``term`` for every DoF, shape (nv,)."""
        first = self.joint_column(0, term)
        return first + self.n_terms * np.arange(self.nv)

    def owner(self, column: int) -> ColumnOwner:
        """What column ``column`` belongs to (a body's inertial parameter or a joint term)."""
        col = int(column)
        if not 0 <= col < self.n_parameters:
            raise InputError(f"column {col} out of range for {self.n_parameters} parameters")
        if col < self.n_rigid:
            body, k = divmod(col, BODY_SIZE)
            return ColumnOwner("body", body, self.body_names[body], INERTIAL_NAMES[k])
        dof, k = divmod(col - self.n_rigid, self.n_terms)
        return ColumnOwner("joint", dof, self.dofs.joints[dof], self.terms[k])

    @cached_property
    def owner_joints(self) -> tuple[str, ...]:
        """The joint owning each column (the joint carrying the body, or the DoF's joint)."""
        return tuple(self.owner(c).joint for c in range(self.n_parameters))

    # ------------------------------------------------------------ joint terms
    @cached_property
    def needs_load(self) -> bool:
        """Whether a term needs the load torque (the ``load`` law)."""
        return any(t.needs == "load" for t in self.term_table)

    @cached_property
    def needs_temperature(self) -> bool:
        """Whether a term needs the measured temperature (the ``temperature`` law)."""
        return any(t.needs == "temp" for t in self.term_table)

    def joint_values(self, angles, vel, acc, load=None, temp=None, history=None) -> np.ndarray:
        """Joint-term regressor entries, shape (..., nv, nt) (see :data:`JOINT_TERMS`),
        with the layout's shapes, zero where the mask switches a term off; the signals
        ``load``, ``temp``, ``history`` as in :meth:`JointTerm.column` (None if unused)."""
        shapes, sig = self.shapes, (load, temp, history)
        vals = np.stack([t.column(angles, vel, acc, shapes, *sig) for t in self.term_table], -1)
        return vals if self.mask is None else vals * self.mask

    # ------------------------------------------------------- physical consistency
    def pseudo_inertias(self, theta: ArrayLike) -> np.ndarray:
        """Each body's pseudo-inertia ``J = [[0.5 tr(I) 1 - I, h], [h^T, m]]``, shape (nb, 4, 4).

        ``I`` about the joint frame origin [kg m^2], ``h = m c`` [kg m], ``m`` [kg]
        (:func:`manip_id.consistency.pseudo_inertia`); ``J`` is positive definite for a
        physically realizable body.
        """
        return pseudo_inertia(self.rigid_blocks(theta))

    def __repr__(self) -> str:
        return (
            f"ParameterLayout(bodies={self.n_bodies}, nv={self.nv}, "
            f"terms={self.terms}, p={self.n_parameters})"
        )
