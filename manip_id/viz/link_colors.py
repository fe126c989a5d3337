"""Colors of the scene: a link's identifiability share (red 0, yellow 0.5, green 1), RGBA
floats in [0, 1] and their hexadecimal / CSS forms."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..errors import InputError
from ..robot.model import Robot


@dataclass(frozen=True)
class LinkIdentifiability:
    """How well each link's parameters are determined.

    Attributes
    ----------
    joints: joint names, one per body, shape (n_bodies,).
    share: determined fraction per link in [0, 1], shape (n_bodies,).
    determined: number of determined parameters per link.
    total: number of parameters per link.
    criterion: a sentence saying what "determined" means here.
    """

    joints: tuple[str, ...]
    share: np.ndarray
    determined: np.ndarray
    total: np.ndarray
    criterion: str


def link_identifiability(
    robot: Robot,
    *,
    identifiable=None,
    relative_std=None,
    threshold: float = 0.1,
) -> LinkIdentifiability:
    """Share of each link's parameters that the data determine.

    Parameters
    ----------
    robot : Robot
        The robot.
    identifiable : array_like of bool, shape (p,), optional
        Per standard parameter, whether it is identifiable (e.g. a base parameter on its
        own, or excited by the data).
    relative_std : array_like, shape (p,), optional
        Per standard parameter, ``std / |value|`` [-]; infinite or NaN counts as
        undetermined.
    threshold : float
        A parameter is determined when its relative std is at most this.

    Notes
    -----
    At least one of ``identifiable`` and ``relative_std`` is needed; with both, a parameter
    must pass both.
    """
    p = robot.n_parameters
    if identifiable is None and relative_std is None:
        raise InputError("link_identifiability needs identifiable= and/or relative_std=")
    ok = np.ones(p, dtype=bool)
    parts = []
    if identifiable is not None:
        flags = np.asarray(identifiable)
        if flags.shape != (p,) or flags.dtype.kind not in "bi":
            raise InputError(
                f"identifiable must be {p} booleans (one per parameter of "
                f"{robot.name}), got shape {flags.shape} dtype {flags.dtype}"
            )
        ok &= flags.astype(bool)
        parts.append("identifiable")
    if relative_std is not None:
        rel = np.asarray(relative_std, dtype=float)
        if rel.shape != (p,):
            raise InputError(f"relative_std.shape={rel.shape} but robot.n_parameters={p}")
        if not np.isfinite(threshold) or threshold <= 0:
            raise InputError(f"threshold must be a positive number, got {threshold}")
        ok &= np.isfinite(rel) & (rel <= threshold)
        parts.append(f"relative std <= {threshold:g}")
    owner = robot.layout.owner_joints
    det = np.array(
        [sum(1 for o, k in zip(owner, ok, strict=True) if o == j and k) for j in robot.joint_names]
    )
    tot = np.array([sum(1 for o in owner if o == j) for j in robot.joint_names])
    share = det / np.maximum(tot, 1)
    return LinkIdentifiability(tuple(robot.joint_names), share, det, tot, " and ".join(parts))


def share_color(share: float) -> tuple[float, float, float, float]:
    """Red (0) -> yellow (0.5) -> green (1), RGBA."""
    s = float(np.clip(share, 0.0, 1.0))
    red, yellow, green = (
        np.array([0.85, 0.15, 0.1]),
        np.array([0.95, 0.8, 0.1]),
        np.array([0.15, 0.7, 0.2]),
    )
    rgb = red + (yellow - red) * (2 * s) if s <= 0.5 else yellow + (green - yellow) * (2 * s - 1)
    return (float(rgb[0]), float(rgb[1]), float(rgb[2]), 1.0)


def hex_color(color) -> int:
    r, g, b = (int(round(255 * float(np.clip(x, 0, 1)))) for x in color[:3])
    return r * 256**2 + g * 256 + b


def css_color(color) -> str:
    return f"#{hex_color(color):06x}"


def link_names(model) -> list[str]:
    """The link each joint moves, per joint ``1 .. njoints - 1`` of a Pinocchio model: the
    first BODY frame the joint carries (the URDF's child link; the joint's name when none)."""
    names: dict[int, str] = {}
    for frame in model.frames:  # in the order the URDF's links were added
        j = int(frame.parentJoint)
        if frame.type == pin.BODY and j > 0:
            names.setdefault(j, frame.name)
    return [names.get(j, model.names[j]) for j in range(1, model.njoints)]
