"""Where the scene's camera stands so that the robot fills the view.

A pinhole camera with vertical field of view ``fov`` looks from ``position`` at the
world origin, world ``z`` up. A point ``x`` [m] has camera coordinates
``(x_r, x_u, x_f) = ((x - p) . r, (x - p) . u, (x - p) . f)`` with ``f = -p / |p|``,
``r = f x z / |f x z|``, ``u = r x f``, and normalized image coordinates
``y = x_u / (x_f tan(fov / 2))`` (vertical, in [-1, 1] on screen) and
``x = x_r / (x_f tan(fov / 2) aspect)``. The *fill* of a set of points is the share of
the view height their image spans, ``(max y - min y) / 2``; it decreases with the
distance ``|p|`` along a fixed direction, which :func:`place_camera` finds by bisection.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from ..errors import InputError

#: meshcat's default camera: vertical field of view [deg].
FOV = 75.0
#: Width over height of the view the placement assumes (a report's scene panel).
ASPECT = 1.2
#: The default viewing direction, from the target towards the camera (world, z up).
DIRECTION = (1.0, 0.7, 0.45)


@dataclass(frozen=True)
class CameraPlacement:
    """A camera looking at the world origin.

    Attributes
    ----------
    position : numpy.ndarray
        Camera position [m], shape (3,), world frame (z up).
    fill : float
        Share of the view height the framed points span [-].
    width_fill : float
        Share of the view width they span [-].
    target : numpy.ndarray
        Where the camera looks, relative to the centre of the points' box [m], shape (3,):
        perspective draws the near side larger, so the box's centre is not the image's;
        the target puts the points' image in the middle of the view.
    """

    position: np.ndarray
    fill: float
    width_fill: float
    target: np.ndarray = field(default_factory=lambda: np.zeros(3))


def image_extent(points, position, *, fov: float = FOV, aspect: float = ASPECT):
    """``(height share, width share)`` of the view that ``points`` (shape (n, 3)) span,
    seen from ``position`` towards the origin; ``(inf, inf)`` when a point is behind
    the camera or on its plane."""
    coords = image_coordinates(points, position, fov=fov, aspect=aspect)
    if coords is None:
        return np.inf, np.inf
    y, x = coords
    return float(np.ptp(y)) / 2.0, float(np.ptp(x)) / 2.0


def image_coordinates(points, position, *, fov: float = FOV, aspect: float = ASPECT):
    """Normalized image coordinates ``(y, x)`` (each shape (n,), in [-1, 1] on screen) of
    ``points`` seen from ``position`` towards the origin; None when a point is behind the
    camera or on its plane."""
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    p = np.asarray(position, dtype=float)
    f = -p / np.linalg.norm(p)
    up = np.array([0.0, 0.0, 1.0])
    r = np.cross(f, up)
    r = r / np.linalg.norm(r) if np.linalg.norm(r) > 1e-12 else np.array([1.0, 0.0, 0.0])
    u = np.cross(r, f)
    rel = pts - p
    depth = rel @ f
    if np.any(depth <= 1e-9):
        return None
    t = np.tan(np.radians(fov) / 2)
    return (rel @ u) / (depth * t), (rel @ r) / (depth * t * aspect)


def _distance(points, direction, share: float, *, fov: float, aspect: float) -> float:
    """The distance along ``direction`` where ``points`` span ``share`` of the view in
    height and at most ``share`` in width (bisection on a decreasing function)."""

    def extent(dist: float) -> float:
        h, w = image_extent(points, dist * direction, fov=fov, aspect=aspect)
        return max(h, w)

    lo, hi = 1e-6, 1.0
    while extent(hi) > share:
        hi *= 2.0
        if hi > 1e9:
            raise InputError("the scene's points do not fit any camera distance")
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if extent(mid) > share:
            lo = mid
        else:
            hi = mid
    return hi


#: Azimuths [deg] :func:`view_direction` tries, at the elevation of :data:`DIRECTION`.
AZIMUTHS = tuple(range(0, 360, 15))
#: Preference for the default azimuth in :func:`view_direction`: a direction's score is
#: its projected area times ``1 + DEFAULT_PREFERENCE cos(azimuth - default azimuth)``.
DEFAULT_PREFERENCE = 0.15


def view_direction(points, default=DIRECTION) -> np.ndarray:
    """A viewing direction (unit, from the target towards the camera) that shows ``points``
    (shape (n, 3) [m]) broadside: at the elevation of ``default``, the azimuth of
    :data:`AZIMUTHS` whose orthographic image has the largest bounding box (width times
    height), the default one preferred by :data:`DEFAULT_PREFERENCE` (so a robot that looks
    alike from every side keeps it). An arm stretched along the default line of sight is
    seen from its side instead of end-on."""
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    d0 = np.asarray(default, dtype=float)
    d0 = d0 / np.linalg.norm(d0)
    elevation = np.arcsin(np.clip(d0[2], -1.0, 1.0))
    az0 = np.arctan2(d0[1], d0[0])
    best, best_score = d0, -np.inf
    for az in np.radians(AZIMUTHS):
        d = np.array([np.cos(az), np.sin(az), 0.0]) * np.cos(elevation)
        d[2] = np.sin(elevation)
        r = np.cross(-d, [0.0, 0.0, 1.0])
        r = r / np.linalg.norm(r)
        u = np.cross(r, -d)
        area = float(np.ptp(pts @ r) * np.ptp(pts @ u))  # [m^2]
        score = area * (1.0 + DEFAULT_PREFERENCE * np.cos(az - az0))
        if score > best_score + 1e-12:
            best, best_score = d, score
    return best


def place_camera(
    points,
    *,
    direction=DIRECTION,
    fill: float = 0.8,
    fov: float = FOV,
    aspect: float = ASPECT,
) -> CameraPlacement:
    """The camera for ``points`` (shape (n, 3) [m], centred on the origin; a scene passes
    every pose of its animation, the robot's swept volume): they span ``fill`` of the view
    height, or of its width when they are wider, seen along ``direction`` and centred."""
    d = np.asarray(direction, dtype=float)
    d = d / np.linalg.norm(d)
    kw: dict[str, Any] = dict(fov=fov, aspect=aspect)
    points = np.asarray(points, dtype=float)
    r = np.cross(-d, [0.0, 0.0, 1.0])
    r = r / np.linalg.norm(r) if np.linalg.norm(r) > 1e-12 else np.array([1.0, 0.0, 0.0])
    u = np.cross(r, -d)
    t = np.tan(np.radians(fov) / 2)

    def off_centre(target: np.ndarray, dist: float) -> tuple[float, float]:
        coords = image_coordinates(points - target, dist * d, **kw)
        if coords is None:
            return np.inf, np.inf
        y, x = coords
        return 0.5 * (y.max() + y.min()), 0.5 * (x.max() + x.min())  # [-]

    target = np.zeros(3)
    dist = _distance(points, d, fill, **kw)
    cy, cx = off_centre(target, dist)
    for _ in range(12):  # damped steps towards the target that centres the image
        if max(abs(cy), abs(cx)) < 1e-3:
            break
        trial = target + 0.5 * dist * t * (cy * u + cx * aspect * r)  # [m]
        trial_dist = _distance(points - trial, d, fill, **kw)
        ty, tx = off_centre(trial, trial_dist)
        if max(abs(ty), abs(tx)) >= max(abs(cy), abs(cx)):
            break  # no better: keep the last
        target, dist, cy, cx = trial, trial_dist, ty, tx
    h, w = image_extent(points - target, dist * d, **kw)
    return CameraPlacement(position=dist * d, fill=h, width_fill=w, target=target)


def convex_hull(points: np.ndarray) -> np.ndarray:
    """The vertices of the convex hull of ``points`` (shape (n, 3) [m]): their image spans
    what all the points' image spans (a perspective image's extremes over a convex set lie
    at its vertices), at a fraction of the cost. All points when the hull is flat."""
    try:
        return points[ConvexHull(points).vertices]
    except (QhullError, ValueError):
        return points
