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
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .._io.reading import read_toml
from ..errors import InputError, RobotError
from .friction import FRICTION_KINDS
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
        return [j for j in all_joints if j not in set(self.locked_joints or ())]


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
    """A :class:`RobotProfile` from the parsed TOML tables (module docstring)."""
    where = source or name
    _check_keys(raw, "", where)
    model = _table(raw, "model", where)
    joints = _table(raw, "joints", where)
    exc = _table(raw, "excitation", where)
    data = _table(raw, "data", where)
    friction = model.get("friction")
    if friction is not None:
        friction = tuple(_strings(friction, "model.friction", where))
        bad = [f for f in friction if f.partition(":")[0] not in _FRICTION]
        if bad:
            raise InputError(
                f"profile {where}: model.friction holds {bad[0]!r}; expected some of "
                f"{list(_FRICTION)}"
            )
    if "active" in joints and "locked" in joints:
        raise InputError(f"profile {where}: give joints.active or joints.locked, not both")
    active = joints.get("active")
    locked = joints.get("locked")
    return RobotProfile(
        name=name,
        source=source,
        description=str(raw.get("description", "")),
        friction=friction,
        armature=_bool(model, "armature", where),
        spring=_bool(model, "spring", where),
        active_joints=None if active is None else tuple(_strings(active, "joints.active", where)),
        locked_joints=None if locked is None else tuple(_strings(locked, "joints.locked", where)),
        excitation=ExcitationProfile(
            harmonics=_positive(exc, "harmonics", where, integer=True),
            period=_positive(exc, "period", where),
            margin=_fraction(exc, "margin", where),
            acceleration_limit=_positive_values(exc, "acceleration_limit", where),
        ),
        torque_scale=_positive_values(data, "torque_scale", where, positive=False),
        columns=_table(data, "columns", where) or None,
        transmission=_transmission_table(raw, where),
    )


def _transmission_table(raw: Mapping[str, Any], where: str) -> dict[str, Any] | None:
    """The ``[transmission]`` table, checked by building it once, or None."""
    if "transmission" not in raw:
        return None
    table = _table(raw, "transmission", where)
    return Transmission.from_dict(table, source=where).to_dict()


# ------------------------------------------------------------------ checking
def _check_keys(table: Mapping[str, Any], name: str, where: str) -> None:
    allowed = _KEYS.get(name)
    if allowed is None:
        return
    unknown = [k for k in table if k not in allowed]
    if unknown:
        prefix = f"{name}." if name else ""
        raise InputError(
            f"profile {where}: unknown key {prefix}{unknown[0]!r}; expected some of {list(allowed)}"
        )


def _table(raw: Mapping[str, Any], key: str, where: str) -> dict[str, Any]:
    value = raw.get(key, {})
    if not isinstance(value, Mapping):
        raise InputError(f"profile {where}: {key} must be a table, got {type(value).__name__}")
    _check_keys(value, key, where)
    return dict(value)


def _strings(value: Any, key: str, where: str) -> list[str]:
    if isinstance(value, str):
        value = [v for v in value.replace(",", " ").split() if v]
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise InputError(f"profile {where}: {key} must be a list of names, got {value!r}")
    return list(value)


def _bool(table: Mapping[str, Any], key: str, where: str) -> bool | None:
    value = table.get(key)
    if value is None or isinstance(value, bool):
        return value
    raise InputError(f"profile {where}: {key} must be true or false, got {value!r}")


def _number(value: Any, key: str, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise InputError(f"profile {where}: {key} must be a finite number, got {value!r}")
    return float(value)


def _positive(table, key: str, where: str, *, integer: bool = False) -> Any:
    if key not in table:
        return None
    value = _number(table[key], key, where)
    if value <= 0 or (integer and value != int(value)):
        kind = "a positive integer" if integer else "positive"
        raise InputError(f"profile {where}: {key} must be {kind}, got {table[key]!r}")
    return int(value) if integer else value


def _fraction(table, key: str, where: str) -> float | None:
    if key not in table:
        return None
    value = _number(table[key], key, where)
    if not 0 <= value < 0.5:
        raise InputError(f"profile {where}: {key} must be in [0, 0.5), got {value}")
    return value


def _positive_values(table, key: str, where: str, *, positive: bool = True) -> Any:
    if key not in table:
        return None
    raw = table[key]
    values = [raw] if not isinstance(raw, list) else raw
    nums = [_number(v, key, where) for v in values]
    bad = any(v <= 0 for v in nums) if positive else any(v == 0 for v in nums)
    if not nums or bad:
        what = "positive" if positive else "non-zero"
        raise InputError(f"profile {where}: {key} must be {what}, got {raw!r}")
    return nums[0] if not isinstance(raw, list) else tuple(nums)
