"""A meshcat scene of the robot: meshes, motion, inertia ellipsoids, identifiability colors.

The scene is recorded offline (no server, no network): every meshcat command
is kept in a scene tree, exactly as meshcat's own server keeps it, and
exported either as one standalone HTML file (three.js from the meshcat
package is embedded) or replayed into a live viewer on 127.0.0.1.

Node paths::

    robot/visuals/<geometry>          visual meshes (Pinocchio's MeshcatVisualizer)
    inertia/<label>/<joint>           equivalent inertia ellipsoids of a parameter set

Animation frames are ``k / fps`` [s] after the first time stamp; the viewer's
"Animations" panel has play/pause and a time slider. The exported page reads
``#t=<seconds>`` from its URL to open paused at that time.
"""

from __future__ import annotations

import base64
import html as html_lib
import json
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import meshcat
import meshcat.geometry as mg
import numpy as np
import pinocchio as pin
import umsgpack
from meshcat.animation import Animation
from meshcat.servers.tree import SceneTree, find_node, walk

from .._checks import as_float_array, check_finite
from .._io import atomic_write_text
from ..errors import InfeasibleTrajectoryError, InputError, ManipIdError
from ..parameters import bounded_range
from ..robot import Robot
from .meshcat_server import MeshcatServer

#: Colors of successive parameter sets (RGBA): nominal, then compared ones.
SET_COLORS: tuple[tuple[float, float, float, float], ...] = (
    (0.15, 0.45, 0.95, 0.45),
    (0.95, 0.45, 0.10, 0.45),
    (0.55, 0.20, 0.80, 0.45),
    (0.10, 0.70, 0.55, 0.45),
)
GREY = (0.6, 0.6, 0.6, 1.0)
_ROBOT_ROOT = "robot"
#: Triangles kept per mesh at most (vertex clustering); meshes are sent as binary arrays.
MAX_TRIANGLES = 3000
#: A parameter set is hidden at first when one of its ellipsoids is wider than this
#: fraction of the robot's size (the diagonal of its bounding box); a toggle shows it.
HIDE_WIDER_THAN = 0.5
_MESH_CACHE: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}


def decimate_mesh(vertices, faces, max_triangles: int = MAX_TRIANGLES):
    """Fewer triangles by vertex clustering: ``(vertices (n, 3), faces (m, 3))``.

    Vertices are merged per cell of a regular grid (each cell's mean), faces that
    collapse are dropped; the cell is halved until at most ``max_triangles`` remain
    (or kept as is when the mesh is already small). The shape stays within one cell
    of the original everywhere.
    """
    V = np.asarray(vertices, dtype=float)
    F = np.asarray(faces, dtype=np.int64)
    if len(F) <= max_triangles or len(V) == 0:
        return V, F
    lo, hi = V.min(axis=0), V.max(axis=0)
    size = float(np.linalg.norm(hi - lo)) or 1.0
    best = None
    for cells in (12, 17, 24, 34, 48, 68, 96, 136, 192):
        h = size / cells  # [m] cell edge
        ijk = np.floor((V - lo) / h).astype(np.int64)  # grid cell of each vertex
        key = (ijk[:, 0] * (cells + 2) + ijk[:, 1]) * (cells + 2) + ijk[:, 2]
        _, cell, counts = np.unique(key, return_inverse=True, return_counts=True)
        cell = cell.ravel()
        merged = np.zeros((counts.size, 3))
        np.add.at(merged, cell, V)
        merged /= counts[:, None]
        f = cell[F]
        f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
        srt = np.sort(f, axis=1)
        n = np.int64(counts.size)
        first = np.unique((srt[:, 0] * n + srt[:, 1]) * n + srt[:, 2], return_index=True)[1]
        f = f[np.sort(first)]  # each merged triangle once, its orientation kept
        if len(f) > max_triangles:
            break
        best = (merged, f)
    if best is None:
        return V, F
    used, inv = np.unique(best[1], return_inverse=True)
    return best[0][used], inv.reshape(-1, 3)


def _mesh_arrays(obj, max_triangles: int):
    """``(vertices, faces)`` of a geometry object's mesh, unscaled and decimated, or None
    for primitives (box, cylinder, sphere) and empty meshes."""
    geom = obj.geometry
    if not hasattr(geom, "num_tris") or geom.num_tris == 0:
        return None
    key = (obj.meshPath, geom.num_tris, geom.num_vertices, max_triangles)
    if key not in _MESH_CACHE:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            V = np.asarray(geom.vertices(), dtype=float).reshape(-1, 3)
            tri = geom.tri_indices
            F = np.array([[t[0], t[1], t[2]] for t in map(tri, range(geom.num_tris))])
        scale = np.asarray(obj.meshScale, dtype=float)
        V = V / np.where(scale != 0, scale, 1.0)  # the BVH holds scaled vertices
        _MESH_CACHE[key] = decimate_mesh(V, F, max_triangles)
    return _MESH_CACHE[key]


# ------------------------------------------------------------------ ellipsoids
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

    identifiable: per standard parameter, bool, shape (p,): whether it is
        identifiable (e.g. a base parameter on its own, or excited by the data).
    relative_std: per standard parameter, shape (p,): ``std / |value|`` [-];
        infinite or NaN counts as undetermined.
    threshold: a parameter is determined when its relative std is at most this.

    At least one of the two is needed; with both, a parameter must pass both.
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


def _rotation_y_to(axis: np.ndarray) -> np.ndarray:
    """A rotation matrix taking the y axis to the unit vector ``axis``, shape (3, 3)."""
    y = np.array([0.0, 1.0, 0.0])
    v = np.cross(y, axis)
    c = float(y @ axis)
    if np.linalg.norm(v) < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + c)


def _hex(color) -> int:
    r, g, b = (int(round(255 * float(np.clip(x, 0, 1)))) for x in color[:3])
    return r * 256**2 + g * 256 + b


def _css(color) -> str:
    return f"#{_hex(color):06x}"


# ------------------------------------------------------------------ trajectory
def check_trajectory(robot: Robot, t, q, *, tolerance: float = 1e-6):
    """Validated ``(t, q)``: t [s] shape (N,) strictly increasing, q shape (N, nq) within limits.

    Raises :class:`InputError` for wrong shapes or non-finite values and
    :class:`InfeasibleTrajectoryError` (carrying joint, limit, excess) for a
    position outside the robot's finite limits by more than ``tolerance``.
    """
    q = as_float_array(q, "q", ndim=(1, 2))
    if q.ndim == 1:
        q = q[None, :]
    if q.shape[1] != robot.nq:
        raise InputError(f"q.shape={q.shape} but robot.nq={robot.nq} ({robot.name})")
    t = as_float_array(t, "t", ndim=1)
    if t.shape[0] != q.shape[0]:
        raise InputError(f"t.shape={t.shape} but q.shape={q.shape}: one time per row of q")
    check_finite(t, "t")
    check_finite(q, "q")
    if t.shape[0] > 1 and np.any(np.diff(t) <= 0):
        k = int(np.argmax(np.diff(t) <= 0)) + 1
        raise InputError(f"time must increase strictly: t[{k}]={t[k]} after t[{k - 1}]={t[k - 1]}")
    lo, hi = robot.lower, robot.upper
    names = _q_names(robot)
    bounded = bounded_range(lo, hi)
    for i in np.flatnonzero(bounded):
        below, above = lo[i] - q[:, i].min(), q[:, i].max() - hi[i]
        excess = max(below, above)
        if excess > tolerance:
            k = int(np.argmin(q[:, i]) if below >= above else np.argmax(q[:, i]))
            raise InfeasibleTrajectoryError(
                f"trajectory leaves the position limits of {names[i]}: q={q[k, i]:.4g} at "
                f"sample {k} (t={t[k]:.4g} s), limits [{lo[i]:.4g}, {hi[i]:.4g}]",
                joint=names[i],
                limit="position",
                excess=float(excess),
            )
    return t, q


def _q_names(robot: Robot) -> list[str]:
    names = []
    for i in range(1, robot.model.njoints):
        nq = robot.model.joints[i].nq
        names += (
            [robot.model.names[i]]
            if nq == 1
            else [f"{robot.model.names[i]}[{k}]" for k in range(nq)]
        )
    return names


# ----------------------------------------------------------------- recording
class _RecordingWindow:
    """Stands in for meshcat's ViewerWindow: keeps the scene tree instead of sending it.

    The tree holds, per path, the last object, its properties, its transform and
    the animation, as meshcat's server does for a newly connected browser.
    """

    def __init__(self):
        self.tree = SceneTree()

    def send(self, command) -> None:
        data = command.lower()
        packed = umsgpack.packb(data)
        kind = data["type"]
        path = [p for p in data.get("path", "").split("/") if p]
        if kind == "set_object":
            node = find_node(self.tree, path)
            node.object = packed
            node.properties = []
        elif kind == "set_transform":
            find_node(self.tree, path).transform = packed
        elif kind == "set_property":
            node = find_node(self.tree, path)
            node.properties = [
                p for p in node.properties if umsgpack.unpackb(p)["property"] != data["property"]
            ]
            node.properties.append(packed)
        elif kind == "set_animation":
            find_node(self.tree, path).animation = packed
        elif kind == "delete":
            if path:
                parent = find_node(self.tree, path[:-1])
                parent.pop(path[-1], None)
            else:
                self.tree = SceneTree()

    def commands(self) -> list[bytes]:
        """Packed commands in replay order (objects, properties, transforms, animation)."""
        out: list[bytes] = []
        animations: list[bytes] = []
        for node in walk(self.tree):
            if node.object is not None:
                out.append(node.object)
            out.extend(node.properties)
            if node.transform is not None:
                out.append(node.transform)
            if node.animation is not None:
                animations.append(node.animation)
        return out + animations

    def get_image(self):  # pragma: no cover - Pinocchio only checks that it exists
        raise ManipIdError("an offline scene has no image; export it with write_html")


class _OfflineVisualizer(meshcat.Visualizer):
    """A meshcat.Visualizer bound to a :class:`_RecordingWindow` (no server)."""

    def get_image(self, *args):  # pragma: no cover
        return self.window.get_image()


@dataclass
class _Legend:
    title: str
    lines: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


class RobotScene:
    """The robot in a meshcat scene, built offline.

    >>> scene = RobotScene(robot)                      # visual meshes (or URDF primitives)
    >>> scene.animate(t, q)                            # time slider, shapes (N,), (N, nq)
    >>> scene.add_inertia(robot.nominal_parameters, label="nominal")
    >>> scene.color_by_identifiability(link_identifiability(robot, identifiable=flags))
    >>> scene.write_html("scene.html")                 # standalone, opens without a server

    Parameters
    ----------
    robot: the robot; its ``visual_model`` is loaded here.
    q: configuration shown before any animation, shape (nq,); default ``robot.neutral()``.
    title: a line shown in the page's legend.
    show_robot: draw the meshes (False draws only ellipsoids; the browser test
        uses it for a background reference).
    """

    def __init__(
        self,
        robot: Robot,
        *,
        q=None,
        title: str = "",
        show_robot: bool = True,
        max_triangles: int = MAX_TRIANGLES,
    ):
        self.robot = robot
        self.title = title or f"{robot.name}"
        self.max_triangles = int(max_triangles)
        self._window = _RecordingWindow()
        self._vis = _OfflineVisualizer(window=self._window)
        self._model = robot.model
        self._data = robot.model.createData()
        self.notes: list[str] = []
        #: "meshes", "capsules" (no mesh could be loaded: simple link geometry) or "none"
        self.geometry = "none"
        self._geom = pin.GeometryModel()
        if show_robot:
            try:
                self._geom = robot.visual_model.copy()
                self.geometry = "meshes"
            except ManipIdError as exc:
                self.notes.append(
                    f"the robot's meshes could not be loaded ({exc}); the links are drawn as "
                    "capsules between the joint frames"
                )
            if self.geometry == "meshes" and self._geom.ngeoms == 0:
                self.notes.append(
                    "the URDF has no visual geometry; the links are drawn as capsules between "
                    "the joint frames"
                )
            if self._geom.ngeoms == 0:
                self.geometry = "capsules"
        self._geom_data = self._geom.createData()
        self._capsules: list[tuple[str, int, np.ndarray]] = []
        self._sets: list[tuple[str, list[EquivalentEllipsoid], tuple]] = []
        self._legend: list[_Legend] = []
        self._t: np.ndarray | None = None
        self._q: np.ndarray | None = None
        self._link_colors: dict[int, tuple] | None = None
        q0 = robot.neutral() if q is None else check_trajectory(robot, [0.0], q)[1][0]
        self._q_static = q0
        self._size = self._joint_box_size(q0)
        self._load_meshes()
        self._place_all(q0, self._vis)
        self._set_camera(q0)

    # ------------------------------------------------------------- building
    def _load_meshes(self) -> None:
        from pinocchio.visualize import MeshcatVisualizer

        self._viz = MeshcatVisualizer(self._model, None, self._geom)
        self._viz.initViewer(viewer=self._vis)
        self._viz.viewerRootNodeName = _ROBOT_ROOT
        self._viz.viewerVisualGroupName = f"{_ROBOT_ROOT}/visuals"
        self._viz.viewerCollisionGroupName = f"{_ROBOT_ROOT}/collisions"
        self._boxes: dict[str, np.ndarray] = {}
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            for obj in self._geom.geometryObjects:
                if self._link_colors is None:
                    color = tuple(float(c) for c in obj.meshColor)
                    if not any(color[:3]) or obj.meshPath.lower().endswith(".dae"):
                        color = GREY  # Collada materials are not read from the decimated mesh
                else:
                    color = self._link_colors.get(obj.parentJoint, GREY)
                mesh = _mesh_arrays(obj, self.max_triangles)
                if mesh is None:  # primitives: Pinocchio's loader (small objects)
                    self._viz.loadViewerGeometryObject(
                        obj, pin.GeometryType.VISUAL, np.array(color)
                    )
                    continue
                V, F = mesh
                material = mg.MeshLambertMaterial(
                    color=_hex(color), opacity=float(color[3]), transparent=float(color[3]) < 1.0
                )
                self._vis[self._node(obj)].set_object(
                    mg.TriangularMeshGeometry(V.astype(np.float32), F.astype(np.uint32)), material
                )
                self._boxes[self._node(obj)] = np.array([V.min(axis=0), V.max(axis=0)])
        for w in caught:
            self.notes.append(f"mesh: {w.message}")
        if self.geometry == "capsules":
            self._load_capsules()

    def _joint_box_size(self, q) -> float:
        pin.forwardKinematics(self._model, self._data, q)
        pts = np.array([self._data.oMi[i].translation for i in range(self._model.njoints)])
        return max(float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0))), 0.1)  # [m]

    def _load_capsules(self) -> None:
        """Simple link geometry: a cylinder from each joint to its children's joints (or to
        the body's centre of mass for a last body) and a sphere at each joint."""
        model = self._model
        radius = 0.025 * max(self._size, 0.2)  # [m]
        self._capsules = []
        children: dict[int, list[int]] = {}
        for i in range(1, model.njoints):
            children.setdefault(int(model.parents[i]), []).append(i)
        for body in range(1, model.njoints):
            color = (self._link_colors or {}).get(body, GREY)
            material = mg.MeshLambertMaterial(color=_hex(color))
            name = model.names[body]
            ends = [model.jointPlacements[c].translation for c in children.get(body, [])]
            if not ends:
                ends = [np.asarray(model.inertias[body].lever, dtype=float)]
            for k, end in enumerate(ends):
                length = float(np.linalg.norm(end))
                if length < 1e-4:
                    continue
                axis = np.asarray(end, dtype=float) / length
                T = np.eye(4)
                T[:3, :3] = _rotation_y_to(axis)  # meshcat cylinders lie along y
                T[:3, 3] = 0.5 * np.asarray(end, dtype=float)
                path = f"{_ROBOT_ROOT}/links/{name}/segment{k}"
                self._vis[path].set_object(mg.Cylinder(length, radius), material)
                self._capsules.append((path, body, T))
                self._boxes[path] = np.array([np.minimum(0, end), np.maximum(0, end)])
            path = f"{_ROBOT_ROOT}/links/{name}/joint"
            self._vis[path].set_object(mg.Sphere(1.5 * radius), material)
            self._capsules.append((path, body, np.eye(4)))

    def _node(self, obj) -> str:
        return f"{_ROBOT_ROOT}/visuals/{obj.name}"

    def _transforms(self, q) -> dict[str, np.ndarray]:
        """World transforms of every node at configuration ``q``."""
        from pinocchio.visualize.meshcat_visualizer import applyScalingOnHomegeneousTransform

        pin.forwardKinematics(self._model, self._data, q)
        out: dict[str, np.ndarray] = {}
        if self._geom.ngeoms:
            pin.updateGeometryPlacements(self._model, self._data, self._geom, self._geom_data)
            for k, obj in enumerate(self._geom.geometryObjects):
                T = self._geom_data.oMg[k].homogeneous
                out[self._node(obj)] = applyScalingOnHomegeneousTransform(T, obj.meshScale)
        for path, body, T_local in self._capsules:
            out[path] = self._data.oMi[body].homogeneous @ T_local
        for label, ellipsoids, _ in self._sets:
            for body, ell in enumerate(ellipsoids, start=1):
                if ell.physical:
                    out[f"inertia/{label}/{ell.joint}"] = (
                        self._data.oMi[body].homogeneous @ ell.placement
                    )
        return out

    def _place_all(self, q, vis) -> None:
        for path, T in self._transforms(q).items():
            vis[path].set_transform(T)

    def _set_camera(self, qs) -> None:
        """Aim the camera at the robot's bounding box over configurations ``qs``: every
        joint origin and the placed box of every mesh (or capsule)."""
        qs = np.atleast_2d(qs)
        qs = qs[np.linspace(0, len(qs) - 1, min(len(qs), 60)).astype(int)]
        found: list = []
        corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        for q in qs:
            pin.forwardKinematics(self._model, self._data, q)
            found += [self._data.oMi[i].translation.copy() for i in range(self._model.njoints)]
            for path, T in self._transforms(q).items():  # every mesh's box, placed
                box = self._boxes.get(path)
                if box is None:
                    continue
                local = np.where(corners == 0, box[0], box[1])  # (8, 3) [m]
                found += list(local @ T[:3, :3].T + T[:3, 3])  # T carries the mesh scale
        pts = np.array(found)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        center = 0.5 * (lo + hi)
        size = max(float(np.linalg.norm(hi - lo)), 0.25)
        # The viewer's orbit controls always aim at the world origin: shift the scene
        # (robot and world axes) so that the centre of the motion sits there; the
        # viewer's grid would no longer be the floor, so it is hidden.
        shift = pin.SE3(np.eye(3), -center).homogeneous
        for node in ("/meshcat", "/Axes"):
            self._vis[node].set_transform(shift)
        self._vis["/Grid"].set_property("visible", False)
        # camera offset in the viewer's y-up camera frame: world (dx, dy, dz) -> (dx, dz, -dy)
        d = 0.6 * size * np.array([1.0, 0.7, 0.45])
        self._vis["/Cameras/default/rotated/<object>"].set_property(
            "position", [float(d[0]), float(d[2]), float(-d[1])]
        )

    # ------------------------------------------------------------ public API
    def animate(
        self, t, q, *, fps: float = 30.0, max_frames: int = 1500, play: bool = True
    ) -> RobotScene:
        """Animate along positions ``q`` [rad or m], shape (N, nq), at times ``t`` [s], shape (N,).

        The clip has frames every ``1/fps`` s (fewer, evenly spread, when the
        motion would need more than ``max_frames``); each frame shows the
        sample nearest in time. A trajectory outside the joint limits raises
        :class:`InfeasibleTrajectoryError`.
        """
        t, q = check_trajectory(self.robot, t, q)
        if not (np.isfinite(fps) and fps > 0) or max_frames < 2:
            raise InputError(f"need fps > 0 and max_frames >= 2, got {fps=}, {max_frames=}")
        self._t, self._q = t, q
        self._anim_options = (float(fps), int(max_frames), bool(play))
        self._build_animation()
        return self

    def _build_animation(self) -> None:
        if self._t is None or self._q is None:  # set together by animate
            return
        t, q = self._t, self._q
        fps, max_frames, play = self._anim_options
        duration = float(t[-1] - t[0])
        n_frames = int(np.floor(duration * fps)) + 1
        if n_frames > max_frames:
            n_frames = max_frames
            fps = (n_frames - 1) / duration
        if n_frames < 2:
            self._place_all(q[0], self._vis)
            return
        times = t[0] + np.arange(n_frames) / fps
        idx = np.clip(np.searchsorted(t, times), 1, len(t) - 1)
        idx -= (times - t[idx - 1]) < (t[idx] - times)
        anim = Animation(default_framerate=fps)
        for frame, k in enumerate(idx):
            with anim.at_frame(self._vis, frame) as f:
                for path, T in self._transforms(q[k]).items():
                    f[path].set_transform(T)
        self._place_all(q[idx[0]], self._vis)
        self._set_camera(q[idx])
        self._vis.set_animation(anim, play=play, repetitions=1)
        self.duration = (n_frames - 1) / fps

    def add_inertia(
        self, theta, *, label: str = "nominal", color=None, visible: bool | None = None
    ) -> list[str]:
        """Draw the equivalent inertia ellipsoid of each body of ``theta`` (shape (p,)).

        Bodies whose block is not physically consistent are skipped; the
        returned notes (also in :attr:`notes` and in the HTML legend) say why.
        visible: shown at first; default: unless one of its ellipsoids is wider
        than :data:`HIDE_WIDER_THAN` times the robot's size (it would hide the arm).
        The page's legend has a check box per set that shows or hides it.
        """
        if not isinstance(label, str) or not label or "/" in label:
            raise InputError(f"label must be a non-empty name without '/', got {label!r}")
        if any(lb == label for lb, _, _ in self._sets):
            raise InputError(f"a parameter set labelled {label!r} is already drawn")
        ellipsoids = inertia_ellipsoids(self.robot, theta)
        color = tuple(color) if color is not None else SET_COLORS[len(self._sets) % len(SET_COLORS)]
        if len(color) not in (3, 4):
            raise InputError(f"color must be RGB or RGBA floats, got {color!r}")
        color = (*color[:3], color[3] if len(color) == 4 else 0.45)
        material = mg.MeshLambertMaterial(
            color=_hex(color), opacity=float(color[3]), transparent=float(color[3]) < 1.0
        )
        notes = []
        for ell in ellipsoids:
            if ell.physical:
                radii = np.maximum(ell.semi_axes, 1e-4)
                self._vis[f"inertia/{label}/{ell.joint}"].set_object(mg.Ellipsoid(radii), material)
            else:
                notes.append(f"{label}: {ell.note} (not drawn)")
        self._sets.append((label, ellipsoids, color))
        self.notes.extend(notes)
        drawn = sum(e.physical for e in ellipsoids)
        widest = max(
            (2.0 * float(np.max(e.semi_axes)) for e in ellipsoids if e.physical), default=0.0
        )  # [m]
        too_wide = widest > HIDE_WIDER_THAN * self._size
        shown = (not too_wide) if visible is None else bool(visible)
        self._vis[f"inertia/{label}"].set_property("visible", shown)
        why = (
            f" (hidden at first: {widest:.2f} m wide, more than {HIDE_WIDER_THAN:g} of the "
            f"robot's {self._size:.2f} m)"
            if too_wide and visible is None
            else ""
        )
        path = json.dumps(["meshcat", "inertia", label])
        box = (
            f'<input type="checkbox" {"checked " if shown else ""}'
            f'onchange=\'viewer.set_property({html_lib.escape(path)}, "visible", '
            "this.checked); viewer.set_dirty()'>"
        )
        self._legend.append(
            _Legend(
                f"inertia ellipsoids: {html_lib.escape(label)}",
                [
                    f"<label>{box}"
                    f'<span class="sw" style="background:{_css(color)}"></span> '
                    f"{html_lib.escape(label)}: {drawn} of {len(ellipsoids)} bodies{why}</label>"
                ],
                notes,
            )
        )
        self._place_all(self._q_static, self._vis)
        self._build_animation()
        return notes

    def color_by_identifiability(self, ident: LinkIdentifiability) -> RobotScene:
        """Color each link's meshes by its determined share (red 0, yellow 0.5, green 1)."""
        if tuple(ident.joints) != tuple(self.robot.joint_names):
            raise InputError(
                f"identifiability is for joints {list(ident.joints)}, "
                f"but the robot has {self.robot.joint_names}"
            )
        colors = {0: GREY}
        for body, s in enumerate(ident.share, start=1):
            colors[body] = share_color(s)
        self._link_colors = colors
        self._vis[f"{_ROBOT_ROOT}/visuals"].delete()
        self._vis[f"{_ROBOT_ROOT}/links"].delete()
        self._geom = self._geom.copy()
        self._load_meshes()
        self._place_all(self._q_static, self._vis)
        self._build_animation()
        lines = []
        for j, s, d, n in zip(
            ident.joints, ident.share, ident.determined, ident.total, strict=True
        ):
            lines.append(
                f'<span class="sw" style="background:{_css(share_color(s))}"></span> '
                f"{html_lib.escape(j)}: {int(d)}/{int(n)} determined ({100 * s:.0f}%)"
            )
        scale = " ".join(
            f'<span class="sw" style="background:{_css(share_color(s))}"></span>{s:g}'
            for s in (0.0, 0.25, 0.5, 0.75, 1.0)
        )
        self._legend.append(
            _Legend(
                f"identifiability ({html_lib.escape(ident.criterion)})",
                [f"share determined: {scale}", *lines],
            )
        )
        return self

    # -------------------------------------------------------------- output
    def commands(self) -> list[bytes]:
        """The scene as msgpack-packed meshcat commands, in replay order."""
        return self._window.commands()

    #: "inline" (one standalone page) or "external": the viewer script and the scene's
    #: commands in files beside the page (:meth:`asset_files`), written once
    assets: str = "inline"
    #: file names of the external assets
    VIEWER_JS, DATA_JS = "meshcat.min.js", "scene-data.js"

    def html(self) -> str:
        """A standalone HTML page of the scene (three.js embedded, no network needed).

        Open it with ``#t=<seconds>`` appended to the URL to start paused at that time.
        With ``assets = "external"`` the page loads :attr:`VIEWER_JS` and :attr:`DATA_JS`
        from its folder instead (:meth:`asset_files`).
        """
        if self.assets not in ("inline", "external"):
            raise InputError(f"assets must be 'inline' or 'external', got {self.assets!r}")
        legend = self._legend_html()
        title = html_lib.escape(self.title)
        if self.assets == "external":
            return _PAGE.format(
                title=title,
                viewer=f'<script src="{self.VIEWER_JS}"></script>',
                data=f'<script src="{self.DATA_JS}"></script>',
                legend=legend,
            )
        return _PAGE.format(
            title=title,
            viewer=f"<script>\n{_viewer_js()}\n</script>",
            data=f"<script>\n{self._data_js()}\n</script>",
            legend=legend,
        )

    def _data_js(self) -> str:
        payload = json.dumps([base64.b64encode(c).decode("ascii") for c in self.commands()])
        return f"var commands = {payload};"

    def asset_files(self) -> dict[str, str]:
        """The files an ``assets = "external"`` page loads: name -> text (empty inline)."""
        if self.assets != "external":
            return {}
        return {self.VIEWER_JS: _viewer_js(), self.DATA_JS: self._data_js()}

    def _legend_html(self) -> str:
        parts = [f"<b>{html_lib.escape(self.title)}</b>"]
        if self.geometry == "capsules":
            parts.append(
                '<span class="note">simple link geometry: capsules between the joint frames '
                "(no mesh could be loaded)</span>"
            )
        if self._t is not None:
            parts.append(
                f"motion: {len(self._t)} samples over {self._t[-1] - self._t[0]:.3g} s "
                "(Animations panel: play, pause, time)"
            )
        for leg in self._legend:
            parts.append(f"<b>{leg.title}</b>")
            parts.extend(leg.lines)
            parts.extend(f'<span class="note">{html_lib.escape(n)}</span>' for n in leg.notes)
        return "<br>".join(parts)

    def write_html(self, path) -> Path:
        """Write :meth:`html` to ``path`` atomically (temporary file, then rename), and the
        external assets (:meth:`asset_files`) beside it."""
        path = Path(path)
        for name, text in self.asset_files().items():
            atomic_write_text(path.parent / name, text)
        return atomic_write_text(path, self.html())

    def serve(self, open_browser: bool = False, host: str = "127.0.0.1") -> LiveView:
        """Replay the scene into a live meshcat viewer; returns the :class:`LiveView`.

        The meshcat server is started here (:func:`manip_id.viz.meshcat_server.start_server`)
        with its web server on ``host`` only (127.0.0.1 by default) and its command
        socket on 127.0.0.1; it stops with :meth:`LiveView.stop`, or with this process
        whatever ends it. Its URL is ``view.url``.
        """
        import contextlib
        import io

        from .meshcat_server import start_server

        server = start_server(host)
        try:
            with contextlib.redirect_stdout(io.StringIO()):  # meshcat prints its URL
                vis = meshcat.Visualizer(zmq_url=server.zmq_url)
            for packed in self.commands():
                data = umsgpack.unpackb(packed)
                vis.window.zmq_socket.send_multipart(
                    [data["type"].encode(), data.get("path", "").encode(), packed]
                )
                vis.window.zmq_socket.recv()
        except BaseException:
            server.stop()
            raise
        view = LiveView(vis, server)
        if open_browser:
            webbrowser_open(view.url)
        return view


def webbrowser_open(url: str) -> None:  # pragma: no cover - interactive
    import webbrowser

    webbrowser.open(url, new=2)


@dataclass
class LiveView:
    """A scene replayed into a running meshcat server (see :meth:`RobotScene.serve`)."""

    visualizer: meshcat.Visualizer
    server: MeshcatServer

    @property
    def url(self) -> str:
        """The viewer's address, on the server's host."""
        return self.server.web_url

    def stop(self) -> None:
        """Close the connection and stop the server process."""
        try:
            self.visualizer.window.zmq_socket.close(linger=0)
        finally:
            self.server.stop()

    def __enter__(self) -> LiveView:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def _viewer_js() -> str:
    """meshcat's viewer (three.js included), as the meshcat package ships it."""
    return (Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js").read_text()


_PAGE = """<!DOCTYPE html>
<html>
<head><meta charset="utf-8"><title>{title}</title>
<style>
body {{ margin: 0; }}
#meshcat-pane {{ width: 100vw; height: 100vh; overflow: hidden; }}
#legend {{ position: absolute; left: 8px; bottom: 8px; max-width: 46vw; max-height: 45vh;
  overflow: auto; background: rgba(255,255,255,0.85); font: 12px sans-serif; padding: 6px 8px;
  border-radius: 4px; line-height: 1.5; }}
#legend .sw {{ display: inline-block; width: 11px; height: 11px; border: 1px solid #444;
  vertical-align: middle; margin: 0 3px; }}
#legend .note {{ color: #a33; }}
</style></head>
<body>
<div id="meshcat-pane"></div>
<div id="legend">{legend}</div>
{viewer}
{data}
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
for (const b64 of commands) {{
  const raw = atob(b64);
  const bytes = new Uint8Array(raw.length);
  for (let i = 0; i < raw.length; i++) bytes[i] = raw.charCodeAt(i);
  viewer.handle_command_bytearray(bytes);
}}
(function () {{
  const m = /[#&]t=([0-9.eE+-]+)/.exec(window.location.hash);
  if (m && viewer.animator && viewer.animator.actions.length) {{
    const t = parseFloat(m[1]);
    viewer.animator.pause();
    viewer.animator.seek(t);
    viewer.animator.display_progress(t);
  }}
}})();
</script>
</body>
</html>
"""
