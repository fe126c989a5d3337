"""Where robot models come from: URDF files, example-robot-data, our own robots.

The loading steps of :func:`manip_id.robot.model.load_robot`: find the model (a URDF path,
an example-robot-data name, ``"msd"``), its joint-term flags (:class:`JointTerms`,
from the arguments, else the robot's profile), the joints to lock at a reference
configuration, and the profile (:mod:`manip_id.robot.profiles`).
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from .._checks import as_float_array
from .._io.reading import check_readable, read_json
from .._native import native_stderr_captured
from ..errors import InputError, RobotError, did_you_mean
from .friction import FRICTION_KINDS as FRICTION_KINDS  # re-exported
from .friction import FrictionShapes, FrictionSpec, friction_columns, parse_friction
from .parameters import JOINT_TERM_NAMES
from .profiles import RobotProfile, find_profile, load_profile, robots_dir
from .urdf_structure import check_urdf_structure, negative_mass_inertials

#: Fixed-base manipulators of example-robot-data listed by ``manip-id robots``.
#: Any other fixed-base name of example-robot-data loads too.
MANIPULATORS: tuple[str, ...] = (
    "panda",
    "ur3",
    "ur3_gripper",
    "ur3_limited",
    "ur5",
    "ur5_gripper",
    "ur5_limited",
    "ur10",
    "ur10_limited",
    "talos_arm",
    "z1",
    "xarm7",
    "kinova",
    "bravo7_no_ee",
    "bravo7_gripper",
    "baxter",
    "tiago_no_hand",
    "finger_edu",
    "asr_twodof",
    "double_pendulum",
    "double_pendulum_simple",
    "double_pendulum_continuous",
)
OUR_ROBOTS: tuple[str, ...] = ("msd",)

FLOATING_JOINTS = (
    "JointModelFreeFlyer",
    "JointModelPlanar",
    "JointModelSpherical",
    "JointModelSphericalZYX",
)


@dataclass(frozen=True)
class JointTerms:
    """Which joint-level terms the model carries (for every active joint).

    ``asymmetric``, ``stribeck``, ``sigmoid``, ``harmonics`` (the order of the
    ``position`` law), ``load``, ``temperature`` and ``hysteresis`` are the friction laws of
    :mod:`manip_id.robot.friction`; ``shapes`` their per-DoF shape parameters; ``per_dof``
    (None: all) the terms each DoF keeps, one tuple of term names per DoF (the others'
    columns are zero: a per-joint model).
    """

    armature: bool = False
    viscous: bool = False
    coulomb: bool = False
    offset: bool = False
    spring: bool = False
    asymmetric: bool = False
    stribeck: bool = False
    sigmoid: bool = False
    harmonics: int = 0
    load: bool = False
    temperature: bool = False
    shapes: FrictionShapes | None = None
    per_dof: tuple[tuple[str, ...], ...] | None = None
    hysteresis: bool = False  # the Dahl law (fh), a state of the joint's path

    @property
    def friction(self) -> FrictionSpec:
        """The friction kinds as a :class:`~manip_id.robot.friction.FrictionSpec`."""
        flags = (
            ("viscous", self.viscous),
            ("coulomb", self.coulomb),
            ("offset", self.offset),
            ("asymmetric", self.asymmetric),
            ("stribeck", self.stribeck),
            ("sigmoid", self.sigmoid),
            ("position", self.harmonics > 0),
            ("load", self.load),
            ("temperature", self.temperature),
            ("hysteresis", self.hysteresis),
        )
        return FrictionSpec(frozenset(k for k, on in flags if on), int(self.harmonics))

    @property
    def enabled(self) -> tuple[str, ...]:
        """Short names of the enabled terms, in column order (subset of
        :data:`~manip_id.robot.parameters.JOINT_TERM_NAMES`)."""
        names = friction_columns(self.friction)
        if self.per_dof is not None:  # a per-joint model: the union of the joints' terms
            names = set().union(*self.per_dof)
        if self.armature:
            names.add("Ia")
        if self.spring:
            names.add("k")
        return tuple(n for n in JOINT_TERM_NAMES if n in names)

    def mask(self, nv: int):
        """The layout mask, bool shape (nv, nt), or None when every DoF keeps every term."""
        if self.per_dof is None:
            return None
        if len(self.per_dof) != nv:
            raise InputError(f"per_dof has {len(self.per_dof)} entries but nv={nv}")
        enabled = self.enabled
        return [[t in keep for t in enabled] for keep in self.per_dof]


def available_robots() -> list[str]:
    """Names :func:`load_robot` lists: our own robots, then example-robot-data manipulators."""
    return [*OUR_ROBOTS, *MANIPULATORS]


def joint_terms(armature, friction, spring, defaults: JointTerms) -> JointTerms:
    """The joint-term flags of the arguments (None: the profile's ``defaults``)."""
    if friction is None:
        spec = defaults.friction
    else:
        spec = parse_friction(friction)
    k = spec.kinds
    return JointTerms(
        armature=defaults.armature if armature is None else bool(armature),
        viscous="viscous" in k,
        coulomb="coulomb" in k,
        offset="offset" in k,
        spring=defaults.spring if spring is None else bool(spring),
        asymmetric="asymmetric" in k,
        stribeck="stribeck" in k,
        sigmoid="sigmoid" in k,
        harmonics=spec.harmonics,
        load="load" in k,
        temperature="temperature" in k,
        hysteresis="hysteresis" in k,
        shapes=defaults.shapes if friction is None else None,
    )


def load_urdf(path: Path) -> pin.Model:
    """A Pinocchio model from a URDF file, its parse errors as :class:`RobotError`."""
    check_readable(path, "URDF", "urdf", error=RobotError)
    check_urdf_structure(path)
    try:
        with native_stderr_captured("urdfdom", error=RobotError), warnings.catch_warnings():
            warnings.simplefilter("ignore")  # urdfdom's errors: refused, not a massless body
            model = pin.buildModelFromUrdf(str(path))
    except Exception as exc:
        cause = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise RobotError(f"cannot read URDF {path}: {cause}") from exc
    inertials = negative_mass_inertials(path)
    if inertials:
        _restore_negative_masses(model, inertials)
    return model


def _restore_negative_masses(model: pin.Model, inertials: dict) -> None:
    """The inertia of each joint carrying a link of negative mass, rebuilt as the sum of
    its links' 10 standard parameters (linear: no division by the mass;
    :func:`~manip_id.robot.urdf_structure.negative_mass_inertials`)."""
    bodies: dict[int, list] = {}
    for frame in model.frames:
        if frame.type == pin.FrameType.BODY and frame.name in inertials:
            bodies.setdefault(int(frame.parentJoint), []).append(frame)
    for j, frames in bodies.items():
        if j == 0 or all(inertials[f.name][0] >= 0 for f in frames):
            continue
        total = np.zeros(10)
        for f in frames:
            m, xyz, rpy, (ixx, ixy, ixz, iyy, iyz, izz) = inertials[f.name]
            R = pin.rpy.rpyToMatrix(*rpy)
            I_c = R @ np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]]) @ R.T
            link = pin.Inertia(m, np.array(xyz, dtype=float), I_c)
            total += f.placement.act(link).toDynamicParameters()
        if total[0] != 0:  # (a total of exactly zero has no centre of mass to keep)
            model.inertias[j] = pin.Inertia.FromDynamicParameters(total)


@dataclass(frozen=True)
class RobotSource:
    """A loaded (unreduced) model and where it came from."""

    model: pin.Model
    name: str
    source: str | None
    package_dirs: list[str]
    settings: dict
    geometry: dict
    by_path: bool


@dataclass(frozen=True)
class Reduction:
    """The joints locked out of a loaded model.

    Attributes
    ----------
    full_model : pinocchio.Model
        The model before the reduction (all joints).
    locked_ids : tuple of int
        Joint ids of ``full_model`` held fixed.
    configuration : numpy.ndarray or None
        The configuration of ``full_model`` they are held at [rad or m], shape (nq,).
    """

    full_model: pin.Model
    locked_ids: tuple[int, ...] = ()
    configuration: np.ndarray | None = None


def load_source(spec: str, pkg: list[str]) -> RobotSource:
    """Our robot (``robots/NAME.urdf`` and its ``.json`` settings), a URDF path, or a name
    of example-robot-data."""
    if spec in OUR_ROBOTS:
        base = robots_dir()
        path = base / f"{spec}.urdf"
        model = load_urdf(path)
        settings_file = base / f"{spec}.json"
        settings = read_json(settings_file, "robot settings") if settings_file.is_file() else {}
        return RobotSource(model, spec, str(path), pkg or [str(path.parent)], settings, {}, False)
    if spec.endswith(".urdf") or Path(spec).suffix == ".urdf" or "/" in spec:
        path = Path(spec).expanduser()
        model = load_urdf(path)
        # package://NAME/... resolves in any ancestor folder holding NAME
        pkg = pkg or [str(d) for d in path.resolve().parents]
        return RobotSource(model, path.stem, str(path), pkg, {}, {}, True)
    model, source, pkg_erd, geometry = load_erd(spec)
    return RobotSource(model, spec, source, pkg or pkg_erd, {}, geometry, False)


def profile_terms(prof: RobotProfile | None) -> JointTerms:
    """The joint-term defaults of a profile (none without one)."""
    if prof is None:
        return JointTerms()
    spec = parse_friction(list(prof.friction or ()))
    k = spec.kinds
    return JointTerms(
        armature=bool(prof.armature),
        viscous="viscous" in k,
        coulomb="coulomb" in k,
        offset="offset" in k,
        spring=bool(prof.spring),
        asymmetric="asymmetric" in k,
        stribeck="stribeck" in k,
        sigmoid="sigmoid" in k,
        harmonics=spec.harmonics,
        load="load" in k,
        temperature="temperature" in k,
        hysteresis="hysteresis" in k,
    )


def locked_names(name: str, all_joints: list[str], active_joints) -> list[str]:
    """The joints to lock for ``active_joints`` (None: none), checked against the model."""
    if active_joints is None:
        return []
    active_joints = list(active_joints)
    unknown = [j for j in active_joints if j not in all_joints]
    if unknown:
        raise InputError(
            f"unknown joint {unknown[0]!r} for robot {name!r}"
            f"{did_you_mean(unknown[0], all_joints)}; valid joints: {all_joints}"
        )
    if not active_joints:
        raise InputError("active_joints is empty: at least one joint must move")
    twice = sorted({j for j in active_joints if active_joints.count(j) > 1})
    if twice:
        raise InputError(f"active_joints names {twice[0]!r} twice: give each joint once")
    return [j for j in all_joints if j not in active_joints]


def resolve_profile(profile, name: str, by_path: bool) -> RobotProfile | None:
    """The profile asked for: by name for robots loaded by name, none for a URDF path."""
    if profile is None:
        return None if by_path else find_profile(name)
    if profile is False:
        return None
    if profile is True:
        return load_profile(name)
    if isinstance(profile, RobotProfile):
        return profile
    return load_profile(profile)


def reference_configuration(model: pin.Model, locked, all_joints) -> np.ndarray:
    """The configuration [rad or m] at which locked joints are held, shape (nq,)."""
    q = pin.neutral(model)
    lo, hi = np.asarray(model.lowerPositionLimit), np.asarray(model.upperPositionLimit)
    finite = np.isfinite(lo) & np.isfinite(hi) & (hi >= lo)
    q[finite] = np.clip(q[finite], lo[finite], hi[finite])
    if locked is None:
        return q
    if isinstance(locked, Mapping):
        for joint, value in locked.items():
            if joint not in all_joints:
                raise InputError(
                    f"unknown joint {joint!r} in locked_configuration; valid joints: {all_joints}"
                )
            jm = model.joints[model.getJointId(joint)]
            coords = as_float_array(value, f"the locked position of {joint!r}", ndim=None)
            if coords.size != jm.nq or not np.isfinite(coords).all():
                raise InputError(
                    f"the locked position of {joint!r} must be {jm.nq} finite number(s) "
                    f"[rad or m], got {value!r}"
                )
            q[jm.idx_q : jm.idx_q + jm.nq] = coords.ravel()
        return q
    arr = as_float_array(locked, "locked_configuration", ndim=1)
    if arr.shape != (model.nq,):
        raise InputError(
            f"locked_configuration.shape={arr.shape} but the full model has nq={model.nq}"
        )
    if not np.isfinite(arr).all():
        raise InputError(f"locked_configuration must be finite [rad or m], got {arr.tolist()}")
    return arr.copy()


def load_erd(name: str):
    """Model, URDF path, package folders and prebuilt geometry ({}) of an example-robot-data name.

    The kinematic and inertial model only: the URDF is located as the
    example-robot-data loader does and read by ``pinocchio.buildModelFromUrdf``,
    then its SRDF (rotor parameters, armature, reference configurations) is
    applied as the loader applies it. Visual and collision geometry (meshes)
    are left to :attr:`Robot.visual_model` / :attr:`Robot.collision_model`,
    built on first use. Loaders with their own ``__init__`` or an SDF model go
    through the loader itself (geometry included).
    """
    try:
        # heavy (its package index): imported only to load a robot by name
        from example_robot_data.robots_loader import ROBOTS
        from example_robot_data.utils import RobotLoader, getModelPath, readParamsFromSrdf
    except ImportError as exc:  # pragma: no cover - dependency of the package
        raise RobotError("example-robot-data-loaders is not installed") from exc
    if name not in ROBOTS:
        raise RobotError(
            f"unknown robot {name!r}{did_you_mean(name, available_robots())}; available: "
            f"{', '.join(available_robots())} "
            "or a path to a .urdf file"
        )
    cls = ROBOTS[name]
    floating = RobotError(
        f"robot {name!r} is a floating-base model: not supported "
        "(manip_id identifies fixed-base manipulators)"
    )
    if getattr(cls, "free_flyer", False):
        raise floating
    if cls.__init__ is not RobotLoader.__init__ or not cls.urdf_filename or cls.sdf_filename:
        return _load_erd_loader(name, cls, floating)
    relative = os.path.join(cls.path, cls.urdf_subpath, cls.urdf_filename)
    try:
        model_dir = cls.model_path or getModelPath(relative)
        source = os.path.join(model_dir, relative)
        with native_stderr_captured("urdfdom"), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = pin.buildModelFromUrdf(source)
            if cls.srdf_filename:
                srdf = os.path.join(model_dir, cls.path, cls.srdf_subpath, cls.srdf_filename)
                readParamsFromSrdf(model, srdf, False, cls.has_rotor_parameters, None)
    except Exception as exc:
        raise RobotError(f"cannot load robot {name!r} from example-robot-data: {exc}") from exc
    if model.njoints > 1 and model.joints[1].shortname() in FLOATING_JOINTS:
        raise floating
    return model, source, [str(Path(model_dir).parent.parent)], {}


def _load_erd_loader(name: str, cls, floating: RobotError):
    """:func:`_load_erd` through the example-robot-data loader (builds the geometry too)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            loader = cls()
            wrapper = loader.robot
    except Exception as exc:
        raise RobotError(f"cannot load robot {name!r} from example-robot-data: {exc}") from exc
    model = wrapper.model
    if model.njoints > 1 and model.joints[1].shortname() in FLOATING_JOINTS:
        raise floating
    source = getattr(loader, "df_path", None)
    model_dir = getattr(loader, "model_path", None)
    pkg = [str(Path(model_dir).parent.parent)] if model_dir else []
    geometry = {
        pin.GeometryType.VISUAL: getattr(wrapper, "visual_model", None),
        pin.GeometryType.COLLISION: getattr(wrapper, "collision_model", None),
    }
    return model, (str(source) if source else None), pkg, geometry
