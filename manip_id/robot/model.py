"""Robots: loading a model by name, URDF path or ``"msd"``; active joints; joint-level terms.

A :class:`Robot` wraps a fixed-base Pinocchio model together with the layout of
its parameter vector::

    theta = [body_1 (10), ..., body_nb (10), joint terms]

where each body block is Pinocchio's standard inertial parameters of the body
carried by joint ``i`` (``Inertia.toDynamicParameters()``)::

    [m, mcx, mcy, mcz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]   [kg, kg m, kg m^2]

(first moments and inertia about the joint frame origin) and the joint terms
follow, per velocity coordinate ``j``, only those enabled, in the order

    Ia (armature, column ddq_j), fv (viscous, dq_j), fc (Coulomb, sign(dq_j)),
    fo (offset, 1), k (spring, q_j).

Names read ``<joint>.<parameter>``, e.g. ``panda_joint3.Ixx`` or ``panda_joint3.fv``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .._checks import as_float_array, check_finite, random_generator
from .._native import native_stderr_captured
from ..errors import InputError, RobotError
from ..resources import check_model_size
from .friction import NO_SHAPES
from .parameters import (
    INERTIAL_NAMES,
    JOINT_TERM_NAMES,
    UNSET_LIMIT,
    DofLayout,
    ParameterLayout,
    bounded_range,
    bounded_rate,
)
from .profiles import RobotProfile
from .regressor import RegressorEvaluator
from .sidecar import (
    apply_identified,
    identified_joint_model,
    identified_options,
    structure_options,
)
from .sidecar import locked_configuration as sidecar_locked
from .sources import (
    FLOATING_JOINTS,
    FRICTION_KINDS,
    MANIPULATORS,
    OUR_ROBOTS,
    JointTerms,
    Reduction,
    RobotSource,
    available_robots,
    joint_terms,
    load_source,
    locked_names,
    profile_terms,
    reference_configuration,
    resolve_profile,
)
from .transmission import MotorLayout, Transmission, load_transmission
from .urdf_structure import check_no_active_mimic

__all__ = [
    "FRICTION_KINDS",
    "INERTIAL_NAMES",
    "JOINT_TERM_NAMES",
    "MANIPULATORS",
    "OUR_ROBOTS",
    "UNSET_LIMIT",
    "JointTerms",
    "Robot",
    "available_robots",
    "load_robot",
]


class Robot:
    """A fixed-base manipulator and the layout of its dynamic parameters.

    Build one with :func:`load_robot`. Attributes of interest: ``model``
    (Pinocchio model of the active joints), ``nq``, ``nv``, ``joint_names``,
    ``dof_names`` (one per velocity coordinate), ``lower``, ``upper`` [rad or m],
    ``velocity_limit``, ``effort_limit``, ``terms``, ``parameter_names``,
    ``parameter_units``, ``nominal_parameters``, ``settings`` (per-robot extras,
    e.g. the input gain ``b`` of ``"msd"``).
    """

    def __init__(
        self,
        name: str,
        model: pin.Model,
        terms: JointTerms,
        *,
        origin: RobotSource | None = None,
        reduction: Reduction | None = None,
        profile: RobotProfile | None = None,
        transmission: Transmission | None = None,
    ):
        kinds = [model.joints[i].shortname() for i in range(1, model.njoints)]
        floating = [k for k in kinds if k in FLOATING_JOINTS]
        if floating:
            raise RobotError(
                f"robot {name!r} has a floating or multi-DoF base joint ({floating[0]}): "
                "floating-base models are not supported, only fixed-base manipulators"
            )
        if model.nv == 0:
            raise RobotError(f"robot {name!r} has no movable joint")
        check_model_size(model.nv)  # before the first Data is built
        self.name = name
        self.model = model
        self.data = model.createData()
        self.terms = terms
        self._origin, self._reduction = origin, reduction  # for with_terms
        self.source = None if origin is None else origin.source
        self.package_dirs = [] if origin is None else list(origin.package_dirs)
        self._full_model = model if reduction is None else reduction.full_model
        self._locked_ids = [] if reduction is None else list(reduction.locked_ids)
        self._qref = None if reduction is None else reduction.configuration
        self.settings = {} if origin is None else dict(origin.settings)
        #: the identification profile the robot was loaded with (``robots/NAME.toml``), or None
        self.profile = profile
        self._full_geometry = {} if origin is None else dict(origin.geometry)
        self.joint_names: list[str] = [model.names[i] for i in range(1, model.njoints)]
        self.dofs = DofLayout.from_model(model)
        self.dof_names: list[str] = list(self.dofs.names)
        if terms.spring:
            for i in range(1, model.njoints):
                jm = model.joints[i]
                if not (jm.nv == 1 and jm.nq in (1, 2)):
                    raise RobotError(
                        f"a spring term needs one-DoF joints, but {model.names[i]} is "
                        f"{jm.shortname()}"
                    )
        if terms.shapes is not None:
            terms.shapes.check_size(self.nv, f"robot {name!r}")
        if transmission is not None:
            transmission.check_size(model.nv, f"robot {name!r}")
        #: the drive train (:mod:`manip_id.robot.transmission`): motor-side logs, motor terms
        self.transmission = transmission
        args = (self.joint_names, self.dofs, terms.enabled, terms.shapes, terms.mask(self.nv))
        self.layout: ParameterLayout = (
            MotorLayout(*args, motors=transmission)
            if transmission is not None and transmission.n_parameters
            else ParameterLayout(*args)
        )

    # ----------------------------------------------------------------- sizes
    @property
    def nq(self) -> int:
        """Number of configuration coordinates."""
        return self.model.nq

    @property
    def nv(self) -> int:
        """Number of velocity coordinates (= number of joint torques)."""
        return self.model.nv

    @property
    def n_bodies(self) -> int:
        """Number of moving bodies (one per joint of the reduced model)."""
        return self.model.njoints - 1

    @property
    def n_rigid(self) -> int:
        """Number of rigid-body parameters, 10 per body."""
        return 10 * self.n_bodies

    @property
    def n_parameters(self) -> int:
        """Total number of standard parameters (columns of the regressor)."""
        return self.layout.n_parameters

    @property
    def full_model(self) -> pin.Model:
        """The unreduced model (every joint of the URDF, none locked)."""
        return self._full_model

    @property
    def locked_configuration(self) -> np.ndarray:
        """Configuration of :attr:`full_model` the locked joints are held at, shape (nq_full,)
        (the neutral configuration when no joint is locked)."""
        q = self._qref if self._qref is not None else pin.neutral(self._full_model)
        return np.array(q, dtype=float)

    # ---------------------------------------------------------------- limits
    @property
    def lower(self) -> np.ndarray:
        """Lower position limits, shape (nq,) [rad or m]."""
        return np.array(self.model.lowerPositionLimit, dtype=float)

    @property
    def upper(self) -> np.ndarray:
        """Upper position limits, shape (nq,) [rad or m]."""
        return np.array(self.model.upperPositionLimit, dtype=float)

    @property
    def velocity_limit(self) -> np.ndarray:
        """Velocity limits, shape (nv,) [rad/s or m/s]."""
        return np.array(self.model.velocityLimit, dtype=float)

    @property
    def effort_limit(self) -> np.ndarray:
        """Effort limits, shape (nv,) [N m or N]."""
        return np.array(self.model.effortLimit, dtype=float)

    def is_prismatic(self, dof: int) -> bool:
        """Whether velocity coordinate ``dof`` is a translation."""
        return bool(self.dofs.prismatic[dof])

    # ------------------------------------------------------------ parameters
    @cached_property
    def parameter_names(self) -> list[str]:
        """One readable name per regressor column, e.g. ``panda_joint3.Ixx``."""
        return list(self.layout.names)

    @cached_property
    def parameter_units(self) -> list[str]:
        """Unit of each parameter, aligned with :attr:`parameter_names`."""
        return list(self.layout.units)

    @cached_property
    def nominal_parameters(self) -> np.ndarray:
        """Parameters of the model description, shape (p,).

        Rigid bodies from the URDF inertias; joint terms from ``model.armature``,
        ``model.damping`` (viscous), ``model.friction`` (Coulomb), zero offset and
        the per-robot spring stiffness (``settings["spring"]``, else zero).
        """
        rigid = [self.model.inertias[i].toDynamicParameters() for i in range(1, self.model.njoints)]
        per_term = {
            "Ia": np.asarray(self.model.armature, dtype=float),
            "fv": np.asarray(self.model.damping, dtype=float),
            "fc": np.asarray(self.model.friction, dtype=float),
            "fo": np.broadcast_to(
                np.asarray(self.settings.get("offset", 0.0), dtype=float), (self.nv,)
            ),
            "k": np.broadcast_to(
                np.asarray(self.settings.get("spring", 0.0), dtype=float), (self.nv,)
            ),
        }
        zero = np.zeros(self.nv)  # the other laws: no nominal value, unless identified
        for t, v in self.settings.get("joint_term_values", {}).items():
            per_term[t] = np.asarray(v, dtype=float)
        joint = [[per_term.get(t, zero)[dof] for t in self.terms.enabled] for dof in range(self.nv)]
        tr = self.transmission
        motor = np.zeros(0 if tr is None else tr.n_parameters)  # none, unless identified
        known = self.settings.get("motor_term_values")
        if known is not None and len(known) == motor.size:
            motor = np.asarray(known, dtype=float)
        parts = [np.concatenate(rigid), np.asarray(joint, dtype=float).ravel(), motor]
        return np.concatenate(parts)

    def with_terms(self, terms: JointTerms) -> Robot:
        """The same robot with other joint terms (a new :class:`Robot`; the model is shared)."""
        if not isinstance(terms, JointTerms):
            raise InputError(f"terms must be JointTerms, got {type(terms).__name__}")
        out = Robot(
            self.name,
            self.model,
            terms,
            origin=self._origin,
            reduction=self._reduction,
            profile=self.profile,
            transmission=self.transmission,
        )
        out.settings = dict(self.settings)  # an identified robot's offsets, load inertias
        return out

    def with_transmission(self, transmission) -> Robot:
        """The same robot with another drive train (a :class:`~manip_id.robot.transmission.
        Transmission`, a table or a ``.toml`` path; None: none); the model is shared."""
        out = Robot(
            self.name,
            self.model,
            self.terms,
            origin=self._origin,
            reduction=self._reduction,
            profile=self.profile,
            transmission=load_transmission(transmission),
        )
        out.settings = dict(self.settings)
        return out

    def parameter_index(self, name: str) -> int:
        """Column index of a parameter name; the error lists close matches."""
        return self.layout.index(name)

    def rigid_body_parameters(self, theta) -> np.ndarray:
        """The rigid-body block of a parameter vector, shape (n_bodies, 10)."""
        theta = as_float_array(theta, "theta", ndim=1)
        if theta.shape[0] != self.n_parameters:
            raise InputError(f"{theta.shape=} but robot.n_parameters={self.n_parameters}")
        return self.layout.rigid_blocks(theta)

    def with_parameters(self, theta) -> pin.Model:
        """A copy of the model whose inertias and armature are those of ``theta``.

        The armature is ``theta``'s ``Ia`` terms when the robot models armature,
        and zero otherwise: the model then holds exactly the dynamics ``theta``
        describes (a URDF armature the parameter vector cannot represent is
        dropped). Friction and spring terms are not part of a Pinocchio model:
        apply them with :func:`manip_id.robot.regressor.joint_torques`.
        ``theta`` must be finite (:class:`~manip_id.errors.InputError` otherwise).
        """
        blocks = self.rigid_body_parameters(theta)
        check_finite(np.asarray(theta, dtype=float), "theta")
        model = self.model.copy()
        for i, block in enumerate(blocks, start=1):
            model.inertias[i] = pin.Inertia.FromDynamicParameters(np.asarray(block))
        if self.terms.armature:
            model.armature = np.asarray(theta)[self.layout.joint_columns("Ia")].copy()
        else:
            model.armature = np.zeros(self.nv)  # [kg m^2 or kg]
        return model

    # ------------------------------------------------------------- sampling
    def sampling_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Finite position bounds for sampling, shape (nq,) each.

        Unset limits (:func:`~manip_id.robot.parameters.bounded_range`) are replaced by [-pi, pi].
        """
        lo, hi = self.lower.copy(), self.upper.copy()
        wide = ~bounded_range(lo, hi)
        lo[wide], hi[wide] = -math.pi, math.pi
        return lo, hi

    def velocity_bounds(self) -> np.ndarray:
        """Finite velocity bounds for sampling, shape (nv,) (unset limits become 2 [unit/s])."""
        v = self.velocity_limit
        bad = ~bounded_rate(v)
        v[bad] = 2.0
        return v

    def random_states(self, n: int, seed: int = 0, acceleration: float = 5.0):
        """``n`` random states within the joint limits.

        Returns ``(q, dq, ddq)`` of shapes (n, nq), (n, nv), (n, nv): positions
        uniform within the limits (angles of continuous joints uniform in
        [-pi, pi], stored as cos/sin), velocities uniform within +-velocity
        limit, accelerations uniform within +-``acceleration`` [rad/s^2 or m/s^2].
        """
        rng = random_generator(seed)
        lo, hi = self.sampling_bounds()
        q = rng.uniform(lo, hi, size=(n, self.nq))
        for i in range(1, self.model.njoints):
            jm = self.model.joints[i]
            if jm.nq == 2 and jm.nv == 1:  # continuous joint: (cos, sin)
                angle = rng.uniform(-math.pi, math.pi, size=n)
                q[:, jm.idx_q] = np.cos(angle)
                q[:, jm.idx_q + 1] = np.sin(angle)
        vmax = self.velocity_bounds()
        dq = rng.uniform(-vmax, vmax, size=(n, self.nv))
        ddq = rng.uniform(-acceleration, acceleration, size=(n, self.nv))
        return q, dq, ddq

    def random_temperatures(self, n: int, seed: int = 0) -> np.ndarray | None:
        """``n`` random temperatures per DoF, ``T0 + U(-1, 1)`` [degC or K], shape (n, nv),
        when the model has the ``temperature`` law (for rank analyses); else None."""
        if not self.layout.needs_temperature:
            return None
        t0 = (self.layout.shapes or NO_SHAPES).values("temperature_reference", 0.0)
        return t0 + random_generator(seed + 1).uniform(-1.0, 1.0, size=(n, self.nv))

    def neutral(self) -> np.ndarray:
        """A valid configuration in the middle of the limits, shape (nq,)."""
        q = pin.neutral(self.model)
        lo, hi = self.sampling_bounds()
        for i in range(1, self.model.njoints):
            jm = self.model.joints[i]
            if jm.nq == jm.nv:
                s = slice(jm.idx_q, jm.idx_q + jm.nq)
                q[s] = np.clip(q[s], lo[s], hi[s]) if np.all(hi[s] > lo[s]) else q[s]
        return q

    # ------------------------------------------------------------- geometry
    @cached_property
    def visual_model(self) -> pin.GeometryModel:
        """Visual geometry of the active bodies (meshes loaded on first use)."""
        return self._geometry(pin.GeometryType.VISUAL)

    @cached_property
    def collision_model(self) -> pin.GeometryModel:
        """Collision geometry of the active bodies (loaded on first use)."""
        return self._geometry(pin.GeometryType.COLLISION)

    def _geometry(self, kind) -> pin.GeometryModel:
        geom = self._full_geometry.get(kind)
        if geom is None:
            if self.source is None:
                raise RobotError(f"robot {self.name!r} has no URDF to read geometry from")
            try:
                with native_stderr_captured("pinocchio"):  # urdfdom / assimp C++ messages
                    geom = pin.buildGeomFromUrdf(
                        self._full_model, self.source, kind, package_dirs=self.package_dirs
                    )
            except Exception as exc:  # Pinocchio raises plain RuntimeError / ValueError
                raise RobotError(f"cannot load the geometry of {self.source}: {exc}") from exc
        if self._locked_ids:
            _, geom = pin.buildReducedModel(self._full_model, geom, self._locked_ids, self._qref)
        return geom

    @cached_property
    def evaluator(self) -> RegressorEvaluator:
        """The :class:`~manip_id.robot.regressor.RegressorEvaluator` (built on first use)."""
        return RegressorEvaluator(self)

    @cached_property
    def load_model(self) -> pin.Model:
        """The model whose ``rnea`` is the load of the ``load`` friction law: ``model``, or
        for a robot loaded with ``identified=True`` a copy holding the inertias the law was
        identified with (the sidecar's ``load_inertias``, shape (nb, 10)), since the
        exported URDF carries the identified ones."""
        blocks = self.settings.get("load_inertias")
        if blocks is None:
            return self.model
        model = self.model.copy()
        for i, block in enumerate(np.asarray(blocks, dtype=float), start=1):
            model.inertias[i] = pin.Inertia.FromDynamicParameters(block)
        return model

    @cached_property
    def gravity_free_model(self) -> pin.Model:
        """The same model with zero gravity (for velocity-only terms)."""
        model = self.model.copy()
        model.gravity = pin.Motion.Zero()
        return model

    def __repr__(self) -> str:
        return (
            f"Robot({self.name!r}, nq={self.nq}, nv={self.nv}, "
            f"p={self.n_parameters}, terms={self.terms.enabled})"
        )


def frame_id(model: pin.Model, name: str) -> int:
    """The id of the frame ``name`` of ``model``.

    Where frames of several types share the name (a link named as its joint, as the
    one-DoF models are), the link's (BODY) frame is meant, then the joint's; Pinocchio's
    ``getFrameId`` without a type refuses such a name.
    """
    for kind in (pin.BODY, pin.JOINT, pin.FIXED_JOINT, pin.OP_FRAME, pin.SENSOR):
        if model.existFrame(name, kind):
            return int(model.getFrameId(name, kind))
    return int(model.getFrameId(name))


# --------------------------------------------------------------------- loading
@dataclass(frozen=True)
class JointSelection:
    """The joints :func:`load_robot` identifies and where it locks the others.

    Attributes
    ----------
    active : sequence of str or None
        Names of the joints to identify; None: the profile's, else every joint.
    locked_configuration : mapping or sequence or None
        Positions of the locked joints: a full configuration vector of the unreduced
        model (shape (nq,)) or a mapping joint name -> position [rad or m]; None: the
        neutral configuration clipped to the limits.
    """

    active: Sequence[str] | None = None
    locked_configuration: Mapping[str, float] | Sequence[float] | None = None


def load_robot(
    spec: str | Path,
    *,
    armature: bool | None = None,
    friction: Iterable[str] | str | None = None,
    spring: bool | None = None,
    active_joints: Sequence[str] | JointSelection | None = None,
    package_dirs: Sequence[str | Path] = (),
    identified: bool | str | Path | Mapping[str, Any] | None = None,
    profile: str | Path | RobotProfile | bool | None = None,
) -> Robot:
    """Load a fixed-base robot.

    Parameters
    ----------
    spec
        an example-robot-data name (``"panda"``, ...), a URDF path, or ``"msd"`` (a 1-DoF
        mass-spring-damper, ``robots/msd.urdf``).
    armature
        model a rotor inertia per joint (column ddq_j). Default: the profile's, else off.
    friction
        friction kinds per joint, some of ``("viscous", "coulomb",
        "offset")`` (also a comma-separated string). Default: the profile's
        (``"msd"``: viscous), else none.
    spring
        model a linear spring per joint (column q_j). Default: the profile's
        (on for ``"msd"``), else off.
    active_joints
        names of the joints to identify, the others locked at the neutral configuration
        clipped to the limits; or a :class:`JointSelection` that also says where the
        others are locked. Default: the profile's (``robots/panda.toml`` locks the two
        finger joints), else every joint.
    package_dirs
        folders where ``package://`` mesh paths of a URDF are resolved.
    identified
        ``True`` or a sidecar's path, for a URDF written by :func:`manip_id.export.export_urdf`
        (``NAME.identified.json``): its joint terms, active and locked joints, armature,
        offset and spring become the defaults and the nominal parameters; or a result's
        ``model_structure`` (a mapping, :func:`manip_id.robot.sidecar.model_structure`):
        its joint model and drive train become the defaults, the nominal parameters stay
        the URDF's. Explicit arguments win either way.
    profile
        the identification profile (:mod:`manip_id.robot.profiles`): a robot name or a
        ``.toml`` path, a :class:`~manip_id.robot.profiles.RobotProfile`, or False for none.
        Default: ``robots/NAME.toml`` for a robot loaded by name when it exists; a URDF
        loaded by path takes none (its file name decides nothing). Explicit arguments
        override the profile.

    The drive train (:mod:`manip_id.robot.transmission`): the sidecar's, else the profile's
    ``[transmission]``, else none (:meth:`Robot.with_transmission` gives another).
    """
    selection = (
        active_joints
        if isinstance(active_joints, JointSelection)
        else JointSelection(active=active_joints)
    )
    active_joints, locked_configuration = selection.active, selection.locked_configuration
    spec_str = str(spec)
    src = load_source(spec_str, [str(p) for p in package_dirs])
    model, name = src.model, src.name
    sidecar, structure = None, None
    if isinstance(identified, Mapping):
        structure, identified = identified, None
    explicit = {"armature": armature, "friction": friction, "spring": spring}
    if identified is not None and identified is not False:
        sidecar, armature, friction, spring, active_joints = identified_options(
            spec_str, identified, armature, friction, spring, active_joints
        )
        if locked_configuration is None:
            locked_configuration = sidecar_locked(sidecar)
    elif structure is not None:
        armature, friction, spring, active_joints = structure_options(
            structure, armature, friction, spring, active_joints
        )
        if locked_configuration is None:
            locked_configuration = sidecar_locked(structure)
    prof = resolve_profile(profile, name, src.by_path)
    terms = joint_terms(armature, friction, spring, profile_terms(prof))
    described = sidecar if sidecar is not None else structure
    model_fields = None if described is None else identified_joint_model(described, **explicit)
    if model_fields is not None:  # the identified laws, shapes and per-joint models
        terms = JointTerms(**model_fields)

    all_joints = [model.names[i] for i in range(1, model.njoints)]
    profile_joints = active_joints is None and prof is not None  # the profile's selection
    if profile_joints and prof is not None:
        active_joints = prof.active_for(all_joints)
    locked = locked_names(name, all_joints, active_joints)
    if src.source is not None and str(src.source).endswith(".urdf"):
        active = [j for j in all_joints if j not in locked]
        check_no_active_mimic(src.source, name, active, refuse=src.by_path)
    full_model = model
    locked_ids: list[int] = []
    qref = None
    if locked:
        qref = reference_configuration(model, locked_configuration, all_joints)
        locked_ids = [model.getJointId(j) for j in locked]
        model = pin.buildReducedModel(model, locked_ids, qref)
    if profile_joints and described is None and prof is not None:
        prof.check_robot(name, model.nv)  # its per-joint values fit the joints it moves
    robot = Robot(
        name,
        model,
        terms,
        origin=src,
        reduction=Reduction(full_model, tuple(locked_ids), qref) if locked_ids else None,
        profile=prof,
        transmission=_transmission_of(described, prof),
    )
    if sidecar is not None:
        apply_identified(robot, sidecar)
    return robot


def _transmission_of(sidecar, profile) -> Transmission | None:
    """The sidecar's (or model structure's) transmission, else the profile's, else None."""
    if sidecar is not None and sidecar.get("transmission"):
        return Transmission.from_dict(sidecar["transmission"], source="sidecar")
    if profile is not None and profile.transmission is not None:
        return Transmission.from_dict(profile.transmission, source=profile.source or profile.name)
    return None
