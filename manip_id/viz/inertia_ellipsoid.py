"""The equivalent inertia ellipsoid of each body (the math is in :mod:`manip_id.viz`).

A body block ``[m, mcx, mcy, mcz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` (kg, kg m, kg m^2; first
moment and inertia about the joint origin) is drawn as the homogeneous solid ellipsoid
with the same mass, centre of mass and rotational inertia.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._checks import as_float_array, check_finite
from ..errors import InputError
from ..robot.model import Robot


@dataclass(frozen=True)
class EquivalentEllipsoid:
    """The solid ellipsoid with the inertia of one body (see :mod:`manip_id.viz`).

    Attributes
    ----------
    joint: name of the joint carrying the body.
    mass: m [kg].
    com: centre of mass in the joint frame [m], shape (3,).
    axes: principal axes as columns, a rotation matrix, shape (3, 3).
    moments: principal moments of inertia about the CoM [kg m^2], shape (3,).
    semi_axes: semi-axes along ``axes`` [m], shape (3,); NaN when not physical.
    physical: whether the block admits the ellipsoid.
    note: why it does not (empty when physical).
    """

    joint: str
    mass: float
    com: np.ndarray
    axes: np.ndarray
    moments: np.ndarray
    semi_axes: np.ndarray
    physical: bool
    note: str = ""

    @property
    def placement(self) -> np.ndarray:
        """Homogeneous transform joint frame <- ellipsoid frame, shape (4, 4)."""
        T = np.eye(4)
        T[:3, :3] = self.axes
        T[:3, 3] = self.com
        return T


def equivalent_ellipsoid(block, joint: str = "") -> EquivalentEllipsoid:
    """Equivalent solid ellipsoid of one 10-parameter body block.

    ``block = [m, mcx, mcy, mcz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` [kg, kg m, kg m^2],
    inertia about the joint origin. Non-physical blocks return ``physical=False``
    with a note; they are never an error.
    """
    b = as_float_array(block, "block", ndim=1)
    if b.shape != (10,):
        raise InputError(f"a body block has 10 parameters, got block.shape={b.shape}")
    check_finite(b, "block")
    m = float(b[0])
    nan3 = np.full(3, np.nan)
    if m <= 0:
        return EquivalentEllipsoid(
            joint, m, nan3, np.eye(3), nan3, nan3, False, f"{joint}: mass {m:.4g} kg <= 0"
        )
    c = b[1:4] / m
    ixx, ixy, iyy, ixz, iyz, izz = b[4:]
    I_o = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    I_c = I_o - m * (float(c @ c) * np.eye(3) - np.outer(c, c))
    moments, axes = np.linalg.eigh(I_c)
    if np.linalg.det(axes) < 0:
        axes[:, 2] *= -1.0
    scale = max(float(np.abs(moments).max()), 1e-300)
    tol = 1e-9 * scale
    if moments.min() <= tol:
        return EquivalentEllipsoid(
            joint,
            m,
            c,
            axes,
            moments,
            nan3,
            False,
            f"{joint}: inertia about the CoM is not positive definite "
            f"(smallest moment {moments.min():.3g} kg m^2)",
        )
    sq = 5.0 / (2.0 * m) * (moments.sum() - 2.0 * moments)
    if sq.min() < -tol * 5.0 / (2.0 * m):
        return EquivalentEllipsoid(
            joint,
            m,
            c,
            axes,
            moments,
            nan3,
            False,
            f"{joint}: principal moments {np.round(moments, 6).tolist()} "
            "violate the triangle inequality",
        )
    return EquivalentEllipsoid(joint, m, c, axes, moments, np.sqrt(np.clip(sq, 0.0, None)), True)


def inertia_ellipsoids(robot: Robot, theta) -> list[EquivalentEllipsoid]:
    """Equivalent ellipsoid of every body of ``theta`` (shape (p,)), in body order."""
    blocks = robot.rigid_body_parameters(theta)
    return [equivalent_ellipsoid(blk, j) for blk, j in zip(blocks, robot.joint_names, strict=True)]


# ------------------------------------------------------------- identifiability


def degenerate_shape(semi_axes, ratio: float = 10.0) -> str:
    """``"a rod (mass concentrated on a line)"``, ``"a disc (mass concentrated on a
    plane)"`` or ``""``: an ellipsoid whose sorted semi-axes [m] differ by more than
    ``ratio``."""
    a0, a1, a2 = np.sort(np.asarray(semi_axes, dtype=float))
    if a2 > ratio * a1:
        return "a rod (mass concentrated on a line)"
    if a1 > ratio * a0:
        return "a disc (mass concentrated on a plane)"
    return ""
