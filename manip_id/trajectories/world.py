"""The robot's collision geometry and its world: distances and their gradients.

World file (TOML, base frame, metres)::

    [[plane]]              # the free side is normal . x >= offset
    normal = [0, 0, 1]
    offset = -0.01
    [[box]]                # size = full edge lengths, position = centre, rpy optional [rad]
    size = [1.2, 0.8, 0.05]
    position = [0.5, 0, -0.03]
    [[sphere]]
    radius = 0.1
    position = [0.4, 0.3, 0.5]
    [[cylinder]]           # axis along the local z
    radius = 0.05
    length = 0.6
    position = [0.4, -0.3, 0.3]

Pairs checked: every two link geometries whose joints are neither the same nor
parent and child, minus the pairs the robot's SRDF disables (when one is found),
and every link geometry against every world object, except geometries attached
to the base or the first moving joint (they sit on the table). Mesh geometries
are replaced by their convex hulls: the hull contains the mesh, so a hull
distance never exceeds the mesh distance (safe), and convex distances (GJK) are
fast and continuous in the configuration.

For a pair with witness points ``p1, p2`` and normal ``n`` (from 1 to 2),
``d = n . (p2 - p1)`` and ``dd/dq = n^T (J_p2 - J_p1)``, where ``J_p`` is the
linear Jacobian of the point ``p`` fixed to its joint (zero for a world object).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import coal  # type: ignore[import-untyped]
import numpy as np
import pinocchio as pin
import tomllib

from ..errors import InputError, RobotError
from ..robot.model import Robot

SHAPES = ("plane", "box", "sphere", "cylinder")


@dataclass(frozen=True)
class WorldObject:
    """An obstacle: ``kind`` in :data:`SHAPES`, sizes [m], placement in the base frame."""

    kind: str
    name: str
    dims: tuple[float, ...]
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def geometry(self):
        if self.kind == "plane":
            n = np.array(self.dims[:3])
            return coal.Halfspace(n / np.linalg.norm(n), self.dims[3] / np.linalg.norm(n))
        if self.kind == "box":
            return coal.Box(*self.dims)
        if self.kind == "sphere":
            return coal.Sphere(self.dims[0])
        return coal.Cylinder(self.dims[0], self.dims[1])

    def placement(self) -> pin.SE3:
        if self.kind == "plane":
            return pin.SE3.Identity()
        return pin.SE3(pin.rpy.rpyToMatrix(*self.rpy), np.array(self.position))


@dataclass(frozen=True)
class World:
    """Obstacles in the robot's base frame (module docstring)."""

    objects: tuple[WorldObject, ...] = field(default_factory=tuple)

    @classmethod
    def load(cls, path) -> World:
        """Read a world TOML file; errors name the entry and the expected keys."""
        try:
            with open(path, "rb") as fh:
                doc = tomllib.load(fh)
        except OSError as exc:
            raise InputError(f"cannot read the world file {path}: {exc}") from exc
        except tomllib.TOMLDecodeError as exc:
            raise InputError(f"world file {path} is not valid TOML: {exc}") from exc
        return cls.from_dict(doc, str(path))

    @classmethod
    def from_dict(cls, doc: dict, source: str = "world") -> World:
        unknown = sorted(set(doc) - set(SHAPES))
        if unknown:
            raise InputError(f"{source}: expected tables {', '.join(SHAPES)}, got {unknown}")
        objects = []
        for kind in SHAPES:
            entries = doc.get(kind, [])
            if not isinstance(entries, list):
                raise InputError(f"{source}: expected [[{kind}]] entries, got {type(entries)}")
            for k, e in enumerate(entries):
                objects.append(_object(kind, f"{kind}{k}", e, source))
        return cls(tuple(objects))


_KEYS = {
    "plane": ({"normal": 3, "offset": 0}, {}),
    "box": ({"size": 3, "position": 3}, {"rpy": 3}),
    "sphere": ({"radius": 0, "position": 3}, {}),
    "cylinder": ({"radius": 0, "length": 0, "position": 3}, {"rpy": 3}),
}


def _object(kind: str, name: str, entry: dict, source: str) -> WorldObject:
    required, optional = _KEYS[kind]
    where = f"{source}: [[{kind}]] #{name[len(kind) :]}"
    if not isinstance(entry, dict):
        raise InputError(f"{where}: expected a table, got {entry!r}")
    extra = sorted(set(entry) - set(required) - set(optional))
    missing = sorted(set(required) - set(entry))
    if extra or missing:
        raise InputError(
            f"{where}: expected keys {sorted(required)} (optional {sorted(optional)}), "
            f"missing {missing}, unknown {extra}"
        )
    vals = {}
    for key, size in {**required, **optional}.items():
        if key not in entry:
            continue
        v = np.asarray(entry[key], dtype=object)
        ok = (v.shape == ((size,) if size else ())) and all(
            isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)
            for x in np.ravel(v)
        )
        if not ok:
            shape = f"{size} numbers" if size else "a number"
            raise InputError(f"{where}: {key} must be {shape} [m], got {entry[key]!r}")
        vals[key] = tuple(float(x) for x in np.ravel(v))
    for key in ("size", "radius", "length"):
        if key in vals and min(vals[key]) <= 0:
            raise InputError(f"{where}: {key} must be positive [m], got {entry[key]!r}")
    if kind == "plane":
        if np.linalg.norm(vals["normal"]) == 0:
            raise InputError(f"{where}: normal must be a non-zero vector, got {entry['normal']!r}")
        return WorldObject(kind, name, (*vals["normal"], *vals["offset"]))
    dims = {"box": vals.get("size"), "sphere": vals.get("radius")}.get(kind)
    if kind == "cylinder":
        dims = (*vals["radius"], *vals["length"])
    pos = vals["position"]
    return WorldObject(kind, name, tuple(dims), pos, vals.get("rpy", (0.0, 0.0, 0.0)))  # type: ignore[arg-type]


def srdf_path(robot: Robot) -> str | None:
    """The robot's SRDF: example-robot-data's for a robot name, else ``../srdf/NAME.srdf``."""
    try:
        from example_robot_data.robots_loader import ROBOTS
        from example_robot_data.utils import getModelPath

        cls = ROBOTS.get(robot.name)
        if cls is not None and cls.srdf_filename:
            rel = os.path.join(cls.path, cls.urdf_subpath, cls.urdf_filename or "")
            base = cls.model_path or getModelPath(rel)
            path = os.path.join(base, cls.path, cls.srdf_subpath, cls.srdf_filename)
            if os.path.isfile(path):
                return path
    except Exception:  # noqa: BLE001 - no loader, or not one of its robots: look beside the URDF
        pass
    if not robot.source or not str(robot.source).endswith(".urdf"):
        return None
    folder, stem = os.path.split(os.path.splitext(str(robot.source))[0])
    for cand in (
        os.path.join(folder, stem + ".srdf"),
        os.path.join(folder, "..", "srdf", stem + ".srdf"),
    ):
        if os.path.isfile(cand):
            return cand
    return None


@dataclass(frozen=True)
class Closest:
    """The closest pair of one configuration: distance [m], the pair's names, witness points."""

    distance: float
    pair: tuple[str, str]
    points: tuple[np.ndarray, np.ndarray]


class CollisionScene:
    """Robot geometry (convex hulls) plus world objects, with the pairs to check."""

    def __init__(self, robot: Robot, world: World | None = None, *, self_collision: bool = True):
        self.robot = robot
        model = robot.model
        geom = robot.collision_model.copy()
        for g in geom.geometryObjects:
            if isinstance(g.geometry, coal.BVHModelBase):
                g.geometry.buildConvexRepresentation(False)
                g.geometry = g.geometry.convex
        n_robot = len(geom.geometryObjects)
        world = world or World()
        for obj in world.objects:
            geom.addGeometryObject(
                pin.GeometryObject(obj.name, 0, 0, obj.placement(), obj.geometry())
            )
        pairs: list[tuple[int, int]] = []
        if self_collision:
            geom.addAllCollisionPairs()
            srdf = srdf_path(robot)
            if srdf is not None:
                pin.removeCollisionPairs(model, geom, srdf)
            for cp in geom.collisionPairs:
                a, b = sorted((cp.first, cp.second))
                if b >= n_robot:
                    continue
                ja, jb = geom.geometryObjects[a].parentJoint, geom.geometryObjects[b].parentJoint
                if ja == jb or model.parents[ja] == jb or model.parents[jb] == ja:
                    continue
                pairs.append((a, b))
        first_moving = 1
        for w in range(n_robot, len(geom.geometryObjects)):
            for a in range(n_robot):
                if geom.geometryObjects[a].parentJoint > first_moving:
                    pairs.append((a, w))
        geom.removeAllCollisionPairs()
        for a, b in pairs:
            geom.addCollisionPair(pin.CollisionPair(a, b))
        self.geom = geom
        self.gdata = pin.GeometryData(geom)
        self.data = model.createData()
        self.pairs = pairs
        self.names = [g.name for g in geom.geometryObjects]
        self.n_robot = n_robot
        self.reach = _reach(model, geom, n_robot)

    @property
    def n_pairs(self) -> int:
        return len(self.pairs)

    def distances(self, q: np.ndarray) -> np.ndarray:
        """Distances [m] of every pair at ``q``, shape (n_pairs,) (negative: overlap)."""
        pin.computeDistances(self.robot.model, self.data, self.geom, self.gdata, q)
        return np.array([r.min_distance for r in self.gdata.distanceResults])

    def witness_points(self, q: np.ndarray, pair: int) -> tuple[np.ndarray, np.ndarray]:
        """The nearest points [m] (base frame) of pair number ``pair`` at ``q``, one on each."""
        self.distances(q)
        res = self.gdata.distanceResults[int(pair)]
        return np.array(res.getNearestPoint1()), np.array(res.getNearestPoint2())

    def closest(self, q: np.ndarray, gradient: bool = False):
        """The closest pair at ``q`` (:class:`Closest`) and, with ``gradient``, dd/dv (nv,)."""
        # computeDistances returns the pair of the least distance: no list of every pair
        k = int(pin.computeDistances(self.robot.model, self.data, self.geom, self.gdata, q))
        res = self.gdata.distanceResults[k]
        p1, p2 = np.array(res.getNearestPoint1()), np.array(res.getNearestPoint2())
        a, b = self.pairs[k]
        best = Closest(float(res.min_distance), (self.names[a], self.names[b]), (p1, p2))
        if not gradient:
            return best, None
        model, data = self.robot.model, self.data
        pin.computeJointJacobians(model, data, q)
        n = np.array(res.normal)
        grad = n @ (self._point_jacobian(b, p2) - self._point_jacobian(a, p1))
        return best, grad

    def _point_jacobian(self, gid: int, p: np.ndarray) -> np.ndarray:
        model, data = self.robot.model, self.data
        j = self.geom.geometryObjects[gid].parentJoint
        if j == 0:
            return np.zeros((3, model.nv))
        J = pin.getJointJacobian(model, data, j, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        r = p - data.oMi[j].translation
        return J[:3] - pin.skew(r) @ J[3:]

    def point_speed_bound(self, dq: np.ndarray) -> float:
        """Upper bound of the speed [m/s] of any robot geometry point at joint velocities ``dq``."""
        return float(np.abs(dq) @ self.reach)


def _reach(model: pin.Model, geom: pin.GeometryModel, n_robot: int) -> np.ndarray:
    """Per DoF, an upper bound [m] of the distance from its joint origin to any geometry point
    carried by it, valid in every configuration (sum of the rigid offsets along the chain)."""
    reach = np.zeros(model.nv)
    for g in geom.geometryObjects[:n_robot]:
        g.geometry.computeLocalAABB()
        radius = (
            float(g.geometry.aabb_radius)
            + float(np.linalg.norm(g.placement.translation))
            + float(np.linalg.norm(g.geometry.aabb_center))
        )
        j, length = g.parentJoint, radius
        while j > 0:
            jm = model.joints[j]
            for i in range(jm.idx_v, jm.idx_v + jm.nv):
                reach[i] = max(reach[i], length)
            length += float(np.linalg.norm(model.jointPlacements[j].translation))
            j = model.parents[j]
    return reach


def check_robot_geometry(robot: Robot) -> None:
    """Raise :class:`RobotError` when the robot has no collision geometry to check."""
    if len(robot.collision_model.geometryObjects) == 0:
        raise RobotError(f"robot {robot.name!r} has no collision geometry (its URDF has none)")
