"""Plausibility bounds of a consistent estimate: each body inside its link, masses in range.

Physical consistency (``J_i >= 0``) allows any mass, however large, and any density
however far from the link. A body whose mass lies inside an ellipsoid
``E = {x : (x - c)^T Q^-1 (x - c) <= 1}`` [m, in the body's joint frame] has
(Wensing, Kim & Slotine 2017, the ellipsoid LMI)::

    tr(J Q_bar) = int rho(x) (1 - (x - c)^T Q^-1 (x - c)) dV >= 0,

    Q_bar = [[-Q^-1,      Q^-1 c          ],        (4, 4)
             [c^T Q^-1,   1 - c^T Q^-1 c  ]]

(:func:`manip_id.physics.consistency.ellipsoid_matrix`), linear in the body's parameters
``pi``: ``tr(J(pi) Q_bar) = d . pi`` with ``d = E^T vec(Q_bar)`` (``E`` the basis of
:func:`manip_id.physics.consistency.pseudo_inertia_basis`). With ``J >= 0`` it is the
condition that some density supported in ``E`` has these parameters.

The ellipsoid of each body (:func:`body_bounds`, ``bounds="geometry"``):

- from the link's collision geometry, else its visual geometry, when the robot's
  URDF loads them (:attr:`manip_id.robot.model.Robot.collision_model`; loaded only when
  bounds are asked for): every geometry object on the body's joint (for a composite
  of links joined by fixed or locked joints, the union of their geometry), meshes
  by their vertices, primitives (boxes, cylinders, spheres, capsules, ...) by the
  corners of their local bounding box, all placed in the joint frame; the ellipsoid
  is Khachiyan's minimum-volume ellipsoid of these points
  (:func:`minimum_volume_ellipsoid`, scaled to hold every point exactly), its
  semi-axes enlarged by :data:`GEOMETRY_MARGIN`;
- else from the kinematic segment: the joint's origin, its child joints' origins and
  the frames on the body, each padded by a radius ``r = max(KINEMATIC_RADIUS[0] L,
  KINEMATIC_RADIUS[1])`` (``L`` the segment's length [m]; a body with no other point
  is a sphere of radius ``KINEMATIC_RADIUS[1]``);
- when the nominal (URDF) body itself is not inside, its ellipsoid is enlarged about
  the same centre until it is (by :data:`NOMINAL_SLACK`), and the source says so: a
  bound never rules out the robot's own model.

Optional mass bounds: ``mass_range = (lo, hi)`` relative to each body's nominal mass
(``lo m0_i <= m_i <= hi m0_i``) and ``total_mass = (M, tol)`` [kg]
(``|sum_i m_i - M| <= tol``). All bounds are linear in ``theta``: the SDP adds them
as constraints; the log-Cholesky solver is checked against them afterwards
(:func:`manip_id.estimators.consistent.solve_consistent`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...errors import InputError, RobotError
from ...physics.consistency import ellipsoid_matrix, ellipsoid_rows, pseudo_inertia

#: Kinds of bounds: ellipsoids from the robot's geometry (or kinematics), or none.
BOUNDS: tuple[str, ...] = ("geometry", "none")
#: Relative enlargement of the semi-axes of an ellipsoid from the link's geometry.
GEOMETRY_MARGIN = 0.05
#: Radius of the kinematic fallback: ``max(fraction * segment length, minimum [m])``.
KINEMATIC_RADIUS: tuple[float, float] = (0.25, 0.05)
#: Directions along which a large point cloud keeps its extreme points (Khachiyan's input).
EXTREME_DIRECTIONS = 200
#: Thinnest extent of a point cloud along a principal axis before it is padded [m].
MIN_THICKNESS = 0.01
#: Enlargement (of ``Q``) beyond the least that holds the nominal body, when it must.
NOMINAL_SLACK = 1.1
#: Tolerance of a bound in the check of a result: ``d . pi >= -TOL m`` [kg], masses
#: within ``TOL`` of their bounds (relative).
TOLERANCE = 1e-6
#: Default tolerance of a total mass given without one, relative to it.
TOTAL_MASS_TOLERANCE = 0.05


@dataclass(frozen=True)
class BoundsOptions:
    """Which plausibility bounds the consistent estimate obeys (module docstring).

    Attributes
    ----------
    bounds
        str
        "geometry" (each body's mass inside a bounding ellipsoid of its link) or "none".
    mass_range
        tuple of float or None
        ``(lo, hi)``: each body's mass within ``[lo, hi]`` times its nominal mass [-].
    total_mass
        tuple of float or None
        ``(M, tol)``: the moving bodies' total mass within ``M +- tol`` [kg].
    """

    bounds: str = "geometry"
    mass_range: tuple[float, float] | None = None
    total_mass: tuple[float, float] | None = None

    def __post_init__(self):
        if self.bounds not in BOUNDS:
            raise InputError(f"bounds must be one of {list(BOUNDS)}, got {self.bounds!r}")
        if self.mass_range is not None:
            lo, hi = _pair(self.mass_range, "mass_range")
            if not (0 <= lo <= 1 <= hi):
                raise InputError(
                    f"mass_range (lo, hi) relative to the nominal masses needs 0 <= lo <= 1 "
                    f"<= hi, got {self.mass_range}"
                )
            object.__setattr__(self, "mass_range", (lo, hi))
        if self.total_mass is not None:
            m, tol = _pair(self.total_mass, "total_mass")
            if not (m > 0 and tol >= 0):
                raise InputError(
                    f"total_mass (kg, tol) needs kg > 0 and tol >= 0, got {self.total_mass}"
                )
            object.__setattr__(self, "total_mass", (m, tol))

    @property
    def active(self) -> bool:
        """Whether any bound is asked for."""
        return self.bounds != "none" or self.mass_range is not None or self.total_mass is not None


def _pair(value, what: str) -> tuple[float, float]:
    try:
        a, b = (float(v) for v in value)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{what} must be two numbers, got {value!r}") from exc
    if not (math.isfinite(a) and math.isfinite(b)):
        raise InputError(f"{what} must be finite, got {value!r}")
    return a, b


def parse_total_mass(text: str) -> tuple[float, float]:
    """``"KG"`` or ``"KG+-TOL"`` [kg] as ``(KG, TOL)``; TOL defaults to
    :data:`TOTAL_MASS_TOLERANCE` ``* KG``."""
    parts = str(text).replace("±", "+-").split("+-")
    try:
        m = float(parts[0])
        tol = float(parts[1]) if len(parts) == 2 else TOTAL_MASS_TOLERANCE * m
    except (ValueError, IndexError) as exc:
        raise InputError(f"total mass must read KG or KG+-TOL [kg], got {text!r}") from exc
    if len(parts) > 2:
        raise InputError(f"total mass must read KG or KG+-TOL [kg], got {text!r}")
    return m, tol


def bound_options(bounds: str, mass_range: str | None, total_mass: str | None) -> BoundsOptions:
    """:class:`BoundsOptions` from the command line's ``--bounds``, ``--mass-range LO,HI``
    and ``--total-mass KG[+-TOL]`` (None: not given); bad text raises :class:`InputError`."""
    mr = None
    if mass_range is not None:
        try:
            lo, hi = (float(x) for x in str(mass_range).split(","))
        except ValueError as exc:
            raise InputError(f"--mass-range must read LO,HI, got {mass_range!r}") from exc
        mr = (lo, hi)
    tm = None if total_mass is None else parse_total_mass(total_mass)
    return BoundsOptions(bounds, mass_range=mr, total_mass=tm)


@dataclass(frozen=True)
class BodyBounds:
    """The linear bounds of a consistent problem, per body (module docstring).

    Attributes
    ----------
    body_names
        list of str
        One per moving body (its joint's name).
    ellipsoids
        numpy.ndarray or None
        ``Q_bar`` of each body's bounding ellipsoid, shape (n_bodies, 4, 4); None
        without ellipsoid bounds.
    sources
        list of str
        Per body, where its ellipsoid came from ("collision geometry", "visual
        geometry", "kinematic segment", with ", semi-axes xF to hold the nominal body"
        when it had to grow).
    mass_range
        numpy.ndarray or None
        ``[lo, hi]`` of each body's mass [kg], shape (n_bodies, 2).
    total_mass
        tuple of float or None
        ``(lo, hi)`` of the total mass [kg].
    """

    body_names: list[str]
    ellipsoids: np.ndarray | None
    sources: list[str]
    mass_range: np.ndarray | None = None
    total_mass: tuple[float, float] | None = None

    @property
    def rows(self) -> np.ndarray | None:
        """``d_i`` with ``tr(J(pi_i) Q_bar_i) = d_i . pi_i``, shape (n_bodies, 10)."""
        return None if self.ellipsoids is None else ellipsoid_rows(self.ellipsoids)

    def violations(self, theta: np.ndarray) -> list[str]:
        """The bounds ``theta`` breaks beyond :data:`TOLERANCE`, one readable line each."""
        nb = len(self.body_names)
        pi = np.asarray(theta, dtype=float)[: 10 * nb].reshape(nb, 10)
        m = pi[:, 0]
        out = []
        rows = self.rows
        if rows is not None:
            slack = np.einsum("ik,ik->i", rows, pi)
            for n, s, mi in zip(self.body_names, slack, m, strict=True):
                if s < -TOLERANCE * max(abs(mi), 1e-12):
                    out.append(f"{n}: mass outside its bounding ellipsoid (tr(J Q) = {s:.3g})")
        if self.mass_range is not None:
            for n, mi, (lo, hi) in zip(self.body_names, m, self.mass_range, strict=True):
                if mi < lo * (1 - TOLERANCE) or mi > hi * (1 + TOLERANCE):
                    out.append(f"{n}: mass {mi:.4g} kg outside [{lo:.4g}, {hi:.4g}] kg")
        if self.total_mass is not None:
            lo, hi = self.total_mass
            total = float(m.sum())
            if total < lo * (1 - TOLERANCE) or total > hi * (1 + TOLERANCE):
                out.append(f"total mass {total:.4g} kg outside [{lo:.4g}, {hi:.4g}] kg")
        return out

    def to_dict(self) -> dict:
        """JSON-ready: per body its ellipsoid's source, the mass bounds."""
        return {
            "bodies": [
                {
                    "name": n,
                    "ellipsoid_source": s,
                    "mass_range": None if self.mass_range is None else self.mass_range[i].tolist(),
                }
                for i, (n, s) in enumerate(zip(self.body_names, self.sources, strict=True))
            ],
            "total_mass": None if self.total_mass is None else list(self.total_mass),
        }


def bound_constraints(bounds: BodyBounds, theta) -> list:
    """The bounds as constraints on a cvxpy expression ``theta`` (linear, module docstring)."""
    nb = len(bounds.body_names)
    cons = []
    rows = bounds.rows
    if rows is not None:
        for i in range(nb):
            cons.append(rows[i] @ theta[10 * i : 10 * i + 10] >= 0)
    masses = [theta[10 * i] for i in range(nb)]
    if bounds.mass_range is not None:
        for i in range(nb):
            cons += [masses[i] >= bounds.mass_range[i, 0], masses[i] <= bounds.mass_range[i, 1]]
    if bounds.total_mass is not None:
        total = sum(masses[1:], masses[0])
        cons += [total >= bounds.total_mass[0], total <= bounds.total_mass[1]]
    return cons


# ------------------------------------------------------------------ ellipsoids
def minimum_volume_ellipsoid(points, tolerance: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """Khachiyan's minimum-volume ellipsoid holding ``points`` (n, 3) [m]: ``(c, Q)``.

    ``E = {x : (x - c)^T Q^-1 (x - c) <= 1}``; the iteration stops within ``tolerance``
    of the optimum and ``Q`` is then scaled so that every point is inside (a point
    cloud thinner than :data:`MIN_THICKNESS` along a principal axis is first padded to
    that thickness, so that ``Q`` stays positive definite). A large cloud (a visual
    mesh) is first reduced to its extreme points along :data:`EXTREME_DIRECTIONS`
    directions (the ellipsoid of those, then scaled to hold every point).
    """
    every = np.asarray(points, dtype=float).reshape(-1, 3)
    P = _padded(_extreme_points(every))
    n, d = P.shape
    Qh = np.vstack([P.T, np.ones(n)])  # (d + 1, n)
    u = np.full(n, 1.0 / n)
    for _ in range(10_000):
        X = (Qh * u) @ Qh.T
        M = np.einsum("in,ij,jn->n", Qh, np.linalg.inv(X), Qh)
        j = int(np.argmax(M))
        step = (M[j] - d - 1.0) / ((d + 1.0) * (M[j] - 1.0))
        if step <= tolerance:
            break
        u *= 1.0 - step
        u[j] += step
    c = P.T @ u
    S = (P.T * u) @ P - np.outer(c, c)
    Q = d * S  # E = {(x - c)^T (d S)^-1 (x - c) <= 1}
    D = np.vstack([P, every]) - c
    reach = np.einsum("ni,ij,nj->n", D, np.linalg.inv(Q), D).max()
    return c, Q * max(float(reach), 1.0)


def _extreme_points(P: np.ndarray) -> np.ndarray:
    """The points of ``P`` extreme along :data:`EXTREME_DIRECTIONS` directions spread
    over the sphere (a Fibonacci lattice), without repeats; ``P`` itself when small."""
    if P.shape[0] <= 2 * EXTREME_DIRECTIONS:
        return P
    k = np.arange(EXTREME_DIRECTIONS) + 0.5
    z = 1.0 - 2.0 * k / EXTREME_DIRECTIONS
    phi = np.pi * (1.0 + 5.0**0.5) * k
    r = np.sqrt(1.0 - z**2)
    dirs = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)  # (K, 3)
    proj = P @ dirs.T  # (n, K)
    keep = np.unique(np.r_[proj.argmax(axis=0), proj.argmin(axis=0)])
    return P[keep]


def _padded(P: np.ndarray) -> np.ndarray:
    """``P`` with two points added along each principal axis thinner than MIN_THICKNESS."""
    mean = P.mean(axis=0)
    _, s, Vt = np.linalg.svd(P - mean, full_matrices=False)
    extent = np.ptp((P - mean) @ Vt.T, axis=0) if P.shape[0] > 1 else np.zeros(3)
    extra = [
        mean + sign * 0.5 * MIN_THICKNESS * Vt[k]
        for k in range(Vt.shape[0])
        if extent[k] < MIN_THICKNESS
        for sign in (-1.0, 1.0)
    ]
    if P.shape[0] < 4 or Vt.shape[0] < 3:  # too few points for three axes: a small cube
        extra += [mean + 0.5 * MIN_THICKNESS * np.array(v) for v in _cube()]
    return np.vstack([P, *extra]) if extra else P


def _cube() -> list[tuple[float, float, float]]:
    return [(a, b, c) for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)]


def _geometry_points(robot, kind: str) -> dict[int, np.ndarray]:
    """Per joint id, the points of its geometry objects in the joint frame [m]."""
    geom = robot.collision_model if kind == "collision" else robot.visual_model
    out: dict[int, list] = {}
    for obj in geom.geometryObjects:
        pts = _object_points(obj.geometry)
        if pts is None or pts.size == 0 or not np.isfinite(pts).all():
            continue
        M = obj.placement
        out.setdefault(int(obj.parentJoint), []).append(
            pts @ np.asarray(M.rotation).T + M.translation
        )
    return {j: np.vstack(v) for j, v in out.items()}


def _object_points(g) -> np.ndarray | None:
    """A geometry's points in its own frame: a mesh's vertices (already scaled when
    Pinocchio loaded it), a primitive's local bounding-box corners; None for a geometry
    that offers neither (it is left out)."""
    try:
        if hasattr(g, "vertices"):
            return np.asarray(g.vertices(), dtype=float).reshape(-1, 3)
        g.computeLocalAABB()
        lo, hi = np.asarray(g.aabb_local.min_), np.asarray(g.aabb_local.max_)
    except (AttributeError, RuntimeError, TypeError, ValueError):  # hpp-fcl: exotic types
        return None
    return np.array([[(lo, hi)[a][0], (lo, hi)[b][1], (lo, hi)[c][2]] for a, b, c in _bits()])


def _bits() -> list[tuple[int, int, int]]:
    return [(a, b, c) for a in (0, 1) for b in (0, 1) for c in (0, 1)]


def _kinematic_points(robot, jid: int) -> np.ndarray:
    """The joint's origin, its children's origins and its frames, padded by the radius."""
    model = robot.model
    pts = [np.zeros(3)]
    pts += [
        np.asarray(model.jointPlacements[k].translation)
        for k in range(1, model.njoints)
        if model.parents[k] == jid
    ]
    pts += [np.asarray(f.placement.translation) for f in model.frames if f.parentJoint == jid]
    P = np.array(pts)
    length = float(np.linalg.norm(P[:, None] - P[None], axis=2).max())
    r = max(KINEMATIC_RADIUS[0] * length, KINEMATIC_RADIUS[1])
    offsets = np.vstack([np.eye(3), -np.eye(3)]) * r
    return (P[:, None, :] + offsets[None]).reshape(-1, 3)


def _link_points(robot) -> tuple[dict[int, np.ndarray], str]:
    """Points of each joint's links and where they came from (geometry, else none)."""
    for kind in ("collision", "visual"):
        try:
            pts = _geometry_points(robot, kind)
        except RobotError:  # no URDF or geometry that does not load: the kinematic segment
            continue
        if pts:
            return pts, f"{kind} geometry"
    return {}, ""


def _hold_nominal(c, Q, pi0: np.ndarray) -> tuple[np.ndarray, float]:
    """``Q`` enlarged about ``c`` until the nominal body ``pi0`` is inside (``tr(J Q_bar) >= 0``).

    With ``Sigma_c = int rho (x - c)(x - c)^T`` of the nominal body, ``tr(J Q_bar) =
    m - tr(Sigma_c Q^-1)``, so ``Q s`` holds it for ``s >= tr(Sigma_c Q^-1) / m``.
    """
    J = pseudo_inertia(pi0)
    m, h, S = J[3, 3], J[:3, 3], J[:3, :3]
    Sc = S - np.outer(h, c) - np.outer(c, h) + m * np.outer(c, c)
    need = float(np.trace(Sc @ np.linalg.inv(Q))) / m if m > 0 else 0.0
    if need <= 1.0:
        return Q, 1.0
    return Q * need * NOMINAL_SLACK, math.sqrt(need * NOMINAL_SLACK)


def body_bounds(robot, options: BoundsOptions) -> BodyBounds | None:
    """The bounds of ``robot``'s bodies asked for by ``options`` (None when none are).

    Geometry is loaded here, only when ``options.bounds == "geometry"``.
    """
    if not options.active:
        return None
    nb = robot.n_bodies
    names = list(robot.joint_names)
    nominal = np.asarray(robot.nominal_parameters, dtype=float)[: 10 * nb].reshape(nb, 10)
    ellipsoids, sources = None, ["none"] * nb
    if options.bounds == "geometry":
        ellipsoids, sources = _ellipsoids(robot, nominal)
    mass_range = None
    if options.mass_range is not None:
        lo, hi = options.mass_range
        mass_range = np.stack([lo * nominal[:, 0], hi * nominal[:, 0]], axis=1)
    total = None
    if options.total_mass is not None:
        m, tol = options.total_mass
        total = (max(m - tol, 0.0), m + tol)
    return BodyBounds(names, ellipsoids, sources, mass_range, total)


def _ellipsoids(robot, nominal: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """``Q_bar`` of each body (n_bodies, 4, 4) and the source of each (module docstring)."""
    points, kind = _link_points(robot)
    out, sources = [], []
    for i in range(robot.n_bodies):
        jid = i + 1
        if jid in points:
            c, Q = minimum_volume_ellipsoid(points[jid])
            Q = Q * (1.0 + GEOMETRY_MARGIN) ** 2
            source = kind
        else:
            c, Q = minimum_volume_ellipsoid(_kinematic_points(robot, jid))
            source = "kinematic segment"
        Q, grown = _hold_nominal(c, Q, nominal[i])
        out.append(ellipsoid_matrix(c, Q))
        if grown > 1.0:
            source += f", semi-axes x{grown:.2g} to hold the nominal body"
        sources.append(source)
    return np.stack(out), sources
