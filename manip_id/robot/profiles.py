"""Robot profiles: per-robot identification defaults, one TOML file per robot.

A profile ``robots/NAME.toml`` holds what a user would otherwise type for that
robot every time; :func:`manip_id.robot.model.load_robot` and the command line use it
for ``NAME`` and explicit arguments or options override it. Every table and key
is optional::

    description = "Franka Emika Panda: the arm without its fingers"

    [model]
    friction = ["viscous", "coulomb"]   # default friction model (manip_id.robot.friction kinds)
    armature = false                    # model a rotor inertia per joint
    spring = false                      # model a linear spring per joint

    [joints]
    active = ["panda_joint1", ...]      # the joints to identify, or
    locked = ["panda_finger_joint1"]    # the joints to lock (not both)

    [excitation]
    harmonics = 5                       # Fourier harmonics per joint
    period = 10.0                       # [s]
    margin = 0.05                       # relative margin to the joint limits
    acceleration_limit = 6.0            # [rad/s^2 or m/s^2], one value or one per joint

    [data]
    torque_scale = 1.0                  # one gain or one per joint (non-zero): tau = scale * column
    [data.columns]                      # CSV column map (see manip_id.datasets)
    q = "q*"

    [transmission]                      # the drive train (manip_id.robot.transmission)
    matrix = [[100, 0], [0, 50]]        # theta = R (q - offset)
    signals = "motor"                   # the logs are motor-side
    motor_terms = ["inertia", "viscous", "coulomb"]

A URDF loaded by path takes no profile unless one is named (``profile=`` or
``--profile``): its file name decides nothing.

Every key is checked when the file is read (:func:`parse_profile`, through
:class:`~manip_id._io.fields.Fields`: types, finite numbers within :data:`LIMITS`,
distinct joints) and against the robot when it is loaded (:meth:`RobotProfile.active_for`,
:meth:`RobotProfile.check_robot`); each failure is one :class:`InputError` naming the
file and the key.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .._io.fields import Fields
from .._io.reading import read_toml
from ..errors import InputError, RobotError, shorten
from ..resources import MAX_HARMONICS, TORQUE_SCALE_RANGE
from .friction import FRICTION_KINDS, parse_friction
from .transmission import Transmission

#: Keys a profile may hold, per table ("" is the top level).
_KEYS: dict[str, tuple[str, ...]] = {
    "": ("description", "model", "joints", "excitation", "data", "transmission"),
    "model": ("friction", "armature", "spring"),
    "joints": ("active", "locked"),
    "excitation": ("harmonics", "period", "margin", "acceleration_limit"),
    "data": ("torque_scale", "columns"),
}
_FRICTION = FRICTION_KINDS


def robots_dir() -> Path:
    """The folder of our robot files and profiles.

    Installed: the package data ``manip_id/robots/``; in the source tree (editable
    install or a checkout): ``robots/`` beside ``manip_id/``.
    """
    here = Path(__file__).resolve().parent.parent  # manip_id/
    installed = here / "robots"
    if (installed / "msd.urdf").is_file():
        return installed
    return here.parent / "robots"


@dataclass(frozen=True)
class ExcitationProfile:
    """Excitation defaults: harmonics, period [s], margin, acceleration limit [rad/s^2 or m/s^2]."""

    harmonics: int | None = None
    period: float | None = None
    margin: float | None = None
    acceleration_limit: float | tuple[float, ...] | None = None

    @property
    def wf(self) -> float | None:
        """Base pulsation ``2 pi / period`` [rad/s], or None."""
        return None if self.period is None else 2.0 * math.pi / self.period

    def design_kwargs(self) -> dict[str, Any]:
        """The keyword arguments it sets of :func:`~manip_id.trajectories.random_trajectory`
        and :func:`~manip_id.trajectories.design_excitation` (``harmonics``, ``wf``,
        ``margin``, ``acceleration_limit``)."""
        out: dict[str, Any] = {}
        if self.harmonics is not None:
            out["harmonics"] = self.harmonics
        if self.period is not None:
            out["wf"] = self.wf
        if self.margin is not None:
            out["margin"] = self.margin
        if self.acceleration_limit is not None:
            out["acceleration_limit"] = self.acceleration_limit
        return out


@dataclass(frozen=True)
class RobotProfile:
    """The identification defaults of one robot (module docstring).

    ``None`` means "not set by the profile": the library default applies.
    """

    name: str
    source: str = ""
    description: str = ""
    friction: tuple[str, ...] | None = None
    armature: bool | None = None
    spring: bool | None = None
    active_joints: tuple[str, ...] | None = None
    locked_joints: tuple[str, ...] | None = None
    excitation: ExcitationProfile = field(default_factory=ExcitationProfile)
    torque_scale: float | tuple[float, ...] | None = None
    columns: Mapping[str, Any] | None = None
    #: the ``[transmission]`` table (:mod:`manip_id.robot.transmission`), checked, or None
    transmission: Mapping[str, Any] | None = None

    def active_for(self, all_joints: list[str]) -> list[str] | None:
        """The active joints among ``all_joints`` this profile asks for (None: all).

        Raises :class:`InputError` when the profile names a joint the model does not have.
        """
        named = self.active_joints if self.active_joints is not None else self.locked_joints
        if named is None:
            return None
        unknown = [j for j in named if j not in all_joints]
        if unknown:
            raise InputError(
                f"profile {self.source or self.name}: unknown joint {unknown[0]!r}; "
                f"the model's joints: {all_joints}"
            )
        if self.active_joints is not None:
            return list(self.active_joints)
        active = [j for j in all_joints if j not in set(self.locked_joints or ())]
        if not active:
            raise InputError(
                f"profile {self.source or self.name}: joints.locked locks every joint of the "
                "model; at least one joint must move"
            )
        return active

    def check_robot(self, robot_name: str, nv: int) -> None:
        """The per-joint values (``excitation.acceleration_limit``, ``data.torque_scale``,
        the transmission) hold one value or one per joint of a robot that moves the
        profile's joints (``nv`` of them); :class:`InputError` naming the file and key."""
        where = self.source or self.name
        for key, values in (
            ("excitation.acceleration_limit", self.excitation.acceleration_limit),
            ("data.torque_scale", self.torque_scale),
        ):
            if isinstance(values, tuple) and len(values) not in (1, nv):
                raise InputError(
                    f"profile {where}: {key} holds {len(values)} values, but {robot_name} moves "
                    f"{nv} joint(s): give one value or one per joint"
                )
        if self.transmission is not None:
            tr = Transmission.from_dict(self.transmission, source=where)
            try:
                tr.check_size(nv, robot_name)
            except InputError as err:
                raise InputError(f"profile {where}: transmission: {err}") from err


def profile_path(name: str) -> Path:
    """Where the profile of robot ``name`` lives: ``robots_dir() / f"{name}.toml"``."""
    return robots_dir() / f"{name}.toml"


def load_profile(spec: str | Path) -> RobotProfile:
    """Read a profile: a robot name (``robots/NAME.toml``) or a path to a TOML file.

    Raises :class:`RobotError` for a name without a profile or an unreadable file, and
    :class:`InputError` (naming the file and the key) for an invalid one.
    """
    s = str(spec)
    path = Path(s).expanduser() if s.endswith(".toml") or "/" in s else profile_path(s)
    if not path.exists():
        where = f"no file {path}" if path != profile_path(s) else f"no {path.name} in {path.parent}"
        raise RobotError(f"cannot read the robot profile {s!r}: {where}")
    raw = read_toml(path, "robot profile", error=RobotError)
    return parse_profile(raw, name=path.stem, source=str(path))


def find_profile(name: str) -> RobotProfile | None:
    """The profile of robot ``name`` when ``robots/NAME.toml`` exists, else None."""
    if not name or "/" in name or name.endswith((".urdf", ".toml")):
        return None
    return load_profile(name) if profile_path(name).is_file() else None


def parse_profile(raw: Mapping[str, Any], *, name: str, source: str = "") -> RobotProfile:
    """A :class:`RobotProfile` from the parsed TOML tables (module docstring).

    Every key is checked at the door through :class:`~manip_id._io.fields.Fields`: unknown
    keys, wrong types, non-finite numbers and numbers outside :data:`LIMITS` raise one
    :class:`InputError` naming the file, the key and what was expected. (Joint names are
    checked against the robot by :meth:`RobotProfile.check_robot` when it is loaded.)
    """
    where = source or name
    f = Fields(f"profile {where}", error=InputError)
    _check_keys(raw, "", where)
    model = _table(raw, "model", where)
    joints = _table(raw, "joints", where)
    exc = _table(raw, "excitation", where)
    data = _table(raw, "data", where)
    friction = model.get("friction")
    if friction is not None:
        friction = tuple(_strings(f, friction, "model.friction"))
        bad = [x for x in friction if x.partition(":")[0] not in _FRICTION]
        if bad:
            raise InputError(
                f"profile {where}: model.friction holds {bad[0]!r}; expected some of "
                f"{list(_FRICTION)}"
            )
        try:
            parse_friction(list(friction))
        except InputError as err:
            raise InputError(f"profile {where}: model.friction: {err}") from err
    if "active" in joints and "locked" in joints:
        raise InputError(f"profile {where}: give joints.active or joints.locked, not both")
    active, locked = joints.get("active"), joints.get("locked")
    acc_lo, acc_hi = LIMITS["acceleration_limit"]
    ts_lo, ts_hi = TORQUE_SCALE_RANGE
    return RobotProfile(
        name=name,
        source=source,
        description=f.text(raw.get("description", ""), "description"),
        friction=friction,
        armature=_bool(f, model, "model.armature"),
        spring=_bool(f, model, "model.spring"),
        active_joints=_joints(f, active, "joints.active"),
        locked_joints=_joints(f, locked, "joints.locked"),
        excitation=ExcitationProfile(
            harmonics=_harmonics(f, exc),
            period=_in(f, exc, "period", "excitation.period"),
            margin=_fraction(f, exc, "excitation.margin"),
            acceleration_limit=_values(
                f,
                exc.get("acceleration_limit"),
                "excitation.acceleration_limit",
                f"positive numbers <= {acc_hi:g} [rad/s^2 or m/s^2]",
                lambda v: acc_lo < v <= acc_hi,
            ),
        ),  # fmt: skip
        torque_scale=_values(
            f,
            data.get("torque_scale"),
            "data.torque_scale",
            f"non-zero numbers of magnitude in [{ts_lo:g}, {ts_hi:g}] (a gain to N m)",
            lambda v: ts_lo <= abs(v) <= ts_hi,
        ),  # fmt: skip
        columns=_columns(f, data.get("columns")),
        transmission=_transmission_table(raw, where),
    )


def _transmission_table(raw: Mapping[str, Any], where: str) -> dict[str, Any] | None:
    """The ``[transmission]`` table, checked by building it once, or None."""
    if "transmission" not in raw:
        return None
    table = _table(raw, "transmission", where)
    return Transmission.from_dict(table, source=where).to_dict()


# ------------------------------------------------------------------ checking
#: The ranges of a profile's numbers (absurd values are refused at the door): an excitation
#: period [s] of 10 ms to about three hours, accelerations up to 1e6 [rad/s^2 or m/s^2].
LIMITS: dict[str, tuple[float, float]] = {
    "period": (1e-2, 1e4),
    "acceleration_limit": (0.0, 1e6),
}


def _check_keys(table: Mapping[str, Any], name: str, where: str) -> None:
    allowed = _KEYS.get(name)
    if allowed is None:
        return
    unknown = [k for k in table if k not in allowed]
    if unknown:
        prefix = f"{name}." if name else ""
        raise InputError(
            f"profile {where}: unknown key {prefix}{shorten(unknown[0])!r}; expected some of "
            f"{list(allowed)}"
        )


def _table(raw: Mapping[str, Any], key: str, where: str) -> dict[str, Any]:
    value = raw.get(key, {})
    if not isinstance(value, Mapping):
        raise InputError(f"profile {where}: {key} must be a table, got {type(value).__name__}")
    _check_keys(value, key, where)
    return dict(value)


def _strings(f: Fields, value: Any, key: str) -> list[str]:
    """A list of names, or one string of names separated by commas or spaces."""
    if isinstance(value, str):
        value = [v for v in value.replace(",", " ").split() if v]
    return f.texts(value, key)


def _joints(f: Fields, value: Any, key: str) -> tuple[str, ...] | None:
    """A list of distinct joint names (or None)."""
    if value is None:
        return None
    names = _strings(f, value, key)
    if not names and key == "joints.active":
        raise f.fail(key, "a non-empty list of joint names (at least one joint moves)", value)
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise f.fail(key, "distinct joint names", f"{shorten(twice[0])!r} twice")
    return tuple(names)


def _bool(f: Fields, table: Mapping[str, Any], key: str) -> bool | None:
    value = table.get(key.rpartition(".")[2])
    return None if value is None else f.boolean(value, key)


def _harmonics(f: Fields, table: Mapping[str, Any]) -> int | None:
    if "harmonics" not in table:
        return None
    value = table["harmonics"]
    what = f"a positive integer <= {MAX_HARMONICS}"
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= MAX_HARMONICS:
        if isinstance(value, float) and value.is_integer() and 1 <= value <= MAX_HARMONICS:
            return int(value)
        raise f.fail("excitation.harmonics", what, value)
    return int(value)


def _in(f: Fields, table: Mapping[str, Any], key: str, field: str) -> float | None:
    """A number in the range of :data:`LIMITS` ``[key]`` (or None)."""
    if key not in table:
        return None
    lo, hi = LIMITS[key]
    return f.number(table[key], field, minimum=lo, maximum=hi)


def _fraction(f: Fields, table: Mapping[str, Any], field: str) -> float | None:
    key = field.rpartition(".")[2]
    if key not in table:
        return None
    value = f.number(table[key], field)
    if not 0 <= value < 0.5:
        raise f.fail(field, "in [0, 0.5)", table[key])
    return abs(value)


def _values(f: Fields, raw: Any, field: str, what: str, ok) -> Any:
    """One number or a non-empty list of numbers each passing ``ok`` (or None)."""
    if raw is None:
        return None
    items = f.list(raw, field, nonempty=True) if isinstance(raw, list) else [raw]
    nums = [f.number(v, field if len(items) == 1 else f"{field}[{k}]") for k, v in enumerate(items)]
    for k, v in enumerate(nums):
        if not ok(v):
            raise f.fail(field if not isinstance(raw, list) else f"{field}[{k}]", what, items[k])
    return nums[0] if not isinstance(raw, list) else tuple(nums)


def _columns(f: Fields, raw: Any) -> dict[str, Any] | None:
    """The ``[data.columns]`` table: per field a column name or pattern, a 0-based index,
    or a non-empty list of them (the fields themselves are checked where the map is used,
    by the data readers)."""
    if raw is None:
        return None
    table = f.object(dict(raw) if isinstance(raw, Mapping) else raw, "data.columns")
    for key, value in table.items():
        field = f"data.columns.{key}"
        items = value if isinstance(value, list) else [value]
        if not items:
            raise f.fail(field, "a column, a pattern or a list of them", value)
        for item in items:
            ok = (isinstance(item, str) and item.strip()) or (
                isinstance(item, int) and not isinstance(item, bool)
            )
            if not ok:
                raise f.fail(field, "column names, patterns or 0-based indices", value)
    return table or None
