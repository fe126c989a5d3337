"""A meshcat scene of the robot: meshes, motion, inertia ellipsoids, identifiability colors.

The scene is recorded offline (no server, no network): every meshcat command
is kept in a scene tree, exactly as meshcat's own server keeps it
(:class:`~manip_id.viz.scene_page.RecordingWindow`), and exported either as one
standalone HTML file (three.js from the meshcat package is embedded) or replayed into a
live viewer on 127.0.0.1 (:func:`~manip_id.viz.meshcat_server.replay`).

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
from dataclasses import replace
from pathlib import Path

import meshcat.geometry as mg
import numpy as np
import pinocchio as pin
from meshcat.animation import Animation
from pinocchio.visualize import MeshcatVisualizer
from pinocchio.visualize.meshcat_visualizer import applyScalingOnHomegeneousTransform

from .._io import atomic_write_text
from ..errors import InputError, ManipIdError
from ..robot.model import Robot
from .camera import convex_hull, place_camera, view_direction
from .inertia_ellipsoid import (
    EquivalentEllipsoid,
    degenerate_shape,
    equivalent_ellipsoid,
    inertia_ellipsoids,
)
from .link_colors import (
    LinkIdentifiability,
    css_color,
    hex_color,
    link_identifiability,
    link_names,
    share_color,
)
from .meshcat_server import LiveView, replay
from .meshes import MAX_TRIANGLES, decimate_mesh, mesh_arrays
from .scene_page import LegendSection, OfflineVisualizer, RecordingWindow, page_html, viewer_js
from .trajectory_check import check_trajectory

#: Re-exported: the scene's parts of earlier releases live in their own modules now.
__all__ = [
    "EquivalentEllipsoid",
    "LinkIdentifiability",
    "LiveView",
    "RobotScene",
    "check_trajectory",
    "decimate_mesh",
    "equivalent_ellipsoid",
    "inertia_ellipsoids",
    "link_identifiability",
    "share_color",
]

#: Styles of successive parameter sets, (RGBA, wire frame): the first (the reference, e.g.
#: the nominal model) a dark translucent wire frame, the next ones solid and translucent in
#: blue, purple and teal (the arm shows through them); none of them on the links'
#: red-yellow-green identifiability scale.
SET_STYLES: tuple[tuple[tuple[float, float, float, float], bool], ...] = (
    ((0.12, 0.12, 0.12, 0.55), True),
    ((0.10, 0.35, 0.90, 0.35), False),
    ((0.55, 0.15, 0.75, 0.35), False),
    ((0.00, 0.55, 0.65, 0.35), False),
)
GREY = (0.6, 0.6, 0.6, 1.0)
Y_AXIS = np.array([0.0, 1.0, 0.0])
_ROBOT_ROOT = "robot"
#: Share of the view (height, or width when wider) the robot's swept volume spans: every
#: pose of the animation (or the one pose of a still scene) fits in the view.
FILL = 0.9
#: Poses of an animation whose points make up the swept volume the camera frames.
SWEPT_POSES = 60
#: Mesh vertices per mesh and pose in the swept volume (a sample of each mesh's).
SWEPT_VERTICES = 40


# ------------------------------------------------------------------ trajectory
def _set_entry(label: str, color, wire: bool, shown: bool, count: str) -> str:
    """A parameter set's legend line: a check box that shows or hides it, its swatch
    (dashed for a wire frame), its label and how many bodies it draws (translucent)."""
    path = json.dumps(["meshcat", "inertia", label])
    box = (
        f'<input type="checkbox" {"checked " if shown else ""}'
        f'onchange=\'viewer.set_property({html_lib.escape(path)}, "visible", '
        "this.checked); viewer.set_dirty()'>"
    )
    return (
        f"<label>{box}"
        f'<span class="sw{" wire" if wire else ""}" style="background:'
        f'{css_color(color)}; border-color:{css_color(color)}"></span> '
        f"{html_lib.escape(label)}: {count}{' (wire frame)' if wire else ''}</label>"
    )


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
        self._window = RecordingWindow()
        self._vis = OfflineVisualizer(window=self._window)
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
        self._legend: list[LegendSection] = []
        self._t: np.ndarray | None = None
        self._q: np.ndarray | None = None
        self._link_colors: dict[int, tuple] | None = None
        self._framed_extra = np.zeros((0, 3))  # [m] world points the camera frames too
        q0 = robot.neutral() if q is None else check_trajectory(robot, [0.0], q)[1][0]
        self._q_static = q0
        self._size = self._joint_box_size(q0)
        self._load_meshes()
        self._place_all(q0, self._vis)
        self._set_camera(q0)

    # ------------------------------------------------------------- building
    def _load_meshes(self) -> None:
        self._viz = MeshcatVisualizer(self._model, None, self._geom)
        self._viz.initViewer(viewer=self._vis)
        self._viz.viewerRootNodeName = _ROBOT_ROOT
        self._viz.viewerVisualGroupName = f"{_ROBOT_ROOT}/visuals"
        self._viz.viewerCollisionGroupName = f"{_ROBOT_ROOT}/collisions"
        self._boxes: dict[str, np.ndarray] = {}
        self._vertices: dict[str, np.ndarray] = {}  # a sample of each mesh's, for framing
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            for obj in self._geom.geometryObjects:
                if self._link_colors is None:
                    color = tuple(float(c) for c in obj.meshColor)
                    if not any(color[:3]) or obj.meshPath.lower().endswith(".dae"):
                        color = GREY  # Collada materials are not read from the decimated mesh
                else:
                    color = self._link_colors.get(obj.parentJoint, GREY)
                mesh = mesh_arrays(obj, self.max_triangles)
                if mesh is None:  # primitives: Pinocchio's loader (small objects)
                    self._viz.loadViewerGeometryObject(
                        obj, pin.GeometryType.VISUAL, np.array(color)
                    )
                    continue
                V, F = mesh
                material = mg.MeshLambertMaterial(
                    color=hex_color(color),
                    opacity=float(color[3]),
                    transparent=float(color[3]) < 1.0,
                )
                self._vis[self._node(obj)].set_object(
                    mg.TriangularMeshGeometry(V.astype(np.float32), F.astype(np.uint32)), material
                )
                self._boxes[self._node(obj)] = np.array([V.min(axis=0), V.max(axis=0)])
                self._vertices[self._node(obj)] = V[:: max(1, len(V) // 300)]
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
            material = mg.MeshLambertMaterial(color=hex_color(color))
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
                T[:3, :3] = pin.Quaternion.FromTwoVectors(Y_AXIS, axis).matrix()  # meshcat: along y
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

    def _points(self, q, vertices: int = 0) -> np.ndarray:
        """Every joint origin and the corners of every placed mesh (or capsule) box at
        configuration ``q`` (``vertices`` > 0: about that many of each mesh's vertices
        instead of its box), world frame [m], shape (n, 3)."""
        corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        pin.forwardKinematics(self._model, self._data, q)
        found = [self._data.oMi[i].translation.copy() for i in range(self._model.njoints)]
        for path, T in self._transforms(q).items():  # every mesh's box, placed
            box = self._boxes.get(path)
            if box is None:
                continue
            local = self._vertices.get(path) if vertices else None
            if local is not None:
                local = local[:: max(1, len(local) // vertices)]
            else:
                local = np.where(corners == 0, box[0], box[1])  # (8, 3) [m]
            found += list(local @ T[:3, :3].T + T[:3, 3])  # T carries the mesh scale
        return np.array(found)

    def _set_camera(self, q_start, qs=None) -> None:
        """Frame the robot's swept volume: the points of every pose of the motion ``qs``
        (shape (N, nq), :data:`SWEPT_POSES` of them spread evenly; the start pose
        ``q_start`` alone without a motion) span :data:`FILL` of the view, seen broadside
        and centred (:func:`~manip_id.viz.camera.place_camera`), so the whole motion stays
        in view; and the points given to :meth:`frame_points` (world objects)."""
        self._frame_args = (q_start, qs)
        poses = [np.asarray(q_start, dtype=float)]
        if qs is not None:
            qs = np.atleast_2d(qs)
            poses += list(qs[np.linspace(0, len(qs) - 1, min(len(qs), SWEPT_POSES)).astype(int)])
        swept = np.vstack([self._points(q, vertices=SWEPT_VERTICES) for q in poses])
        swept = np.vstack([swept, self._framed_extra])
        center = 0.5 * (swept.min(axis=0) + swept.max(axis=0))
        pad = center + 0.1 * np.vstack([np.eye(3), -np.eye(3)])  # a robot of a point: 20 cm
        swept = convex_hull(np.vstack([swept, pad]) - center)
        self.camera = place_camera(swept, direction=view_direction(swept), fill=FILL)
        center = center + self.camera.target  # the image of the swept volume centred
        self.view_center = center  # [m], world: the point the camera looks at
        # The viewer's orbit controls always aim at the world origin: shift the scene
        # (robot and world axes) so that the centre of the swept volume sits there; the
        # viewer's grid would no longer be the floor, so it is hidden.
        shift = pin.SE3(np.eye(3), -center).homogeneous
        for node in ("/meshcat", "/Axes"):
            self._vis[node].set_transform(shift)
        self._vis["/Grid"].set_property("visible", False)
        # camera offset in the viewer's y-up camera frame: world (dx, dy, dz) -> (dx, dz, -dy)
        d = self.camera.position
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
        self._framed = False  # the camera frames this motion once
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
        if not self._framed:
            self._set_camera(q[idx[0]], q[idx])
            self._framed = True
        self._vis.set_animation(anim, play=play, repetitions=1)
        self.duration = (n_frames - 1) / fps

    def add_inertia(
        self,
        theta,
        *,
        label: str = "nominal",
        color=None,
        visible: bool | None = None,
        wireframe: bool | None = None,
        bodies=None,
        estimated: bool = False,
    ) -> list[str]:
        """Draw the equivalent inertia ellipsoid of each body of ``theta`` (shape (p,)).

        Bodies whose block is not physically consistent are skipped; the
        returned notes (also in :attr:`notes`, and shortened and folded in the HTML legend)
        say why, and which ellipsoids are degenerate. Bodies are named by their link.
        visible: shown at first (default False: ellipsoids hide the arm; the page's legend
        has a check box per set that shows or hides it).
        color, wireframe: the set's style; default: the next of :data:`SET_STYLES` (the
        first set a dark translucent wire frame, the others translucent blue, purple, teal).
        bodies: names of the joints whose bodies are drawn (default: every body), e.g.
        the one carrying a payload.
        estimated: the set was estimated from data (not a given model such as the nominal
        or the true one): a degenerate ellipsoid is then explained by the data fixing
        only grouped terms of the body's inertia.
        """
        if not isinstance(label, str) or not label or "/" in label:
            raise InputError(f"label must be a non-empty name without '/', got {label!r}")
        if any(lb == label for lb, _, _ in self._sets):
            raise InputError(f"a parameter set labelled {label!r} is already drawn")
        ellipsoids = inertia_ellipsoids(self.robot, theta)
        if bodies is not None:  # the others are kept (body order) but neither drawn nor noted
            keep = set(bodies)
            ellipsoids = [
                e if e.joint in keep else replace(e, physical=False, note="") for e in ellipsoids
            ]
        default, wire = SET_STYLES[len(self._sets) % len(SET_STYLES)]
        color = tuple(color) if color is not None else default
        wire = wire if wireframe is None else bool(wireframe)
        if len(color) not in (3, 4):
            raise InputError(f"color must be RGB or RGBA floats, got {color!r}")
        color = (*color[:3], color[3] if len(color) == 4 else 0.45)
        material = mg.MeshLambertMaterial(
            color=hex_color(color),
            opacity=float(color[3]),
            transparent=float(color[3]) < 1.0,
            wireframe=wire,
        )
        notes, short = [], []
        links = dict(zip(self.robot.joint_names, link_names(self._model), strict=True))
        grouped = ": the data fix only grouped terms of this body's inertia" if estimated else ""
        for ell in ellipsoids:
            link = links.get(ell.joint, ell.joint)
            if ell.physical:
                radii = np.maximum(ell.semi_axes, 1e-4)
                self._vis[f"inertia/{label}/{ell.joint}"].set_object(mg.Ellipsoid(radii), material)
                shape = degenerate_shape(radii)
                if shape:
                    across = f"{2 * float(np.max(radii)):.2f} m across"
                    notes.append(f"{label}: {link}'s ellipsoid is {shape} ({across}){grouped}")
                    short.append(f"{link}: {shape.split(' (')[0]}, {across}")
            elif ell.note:
                notes.append(f"{label}: {link}: {ell.note} (not drawn)")
                short.append(f"{link}: not drawn ({ell.note.removeprefix(ell.joint + ': ')})")
        if estimated and any("grouped" in n for n in notes):
            short.append("degenerate: the data fix only grouped terms of these bodies' inertia")
        self._sets.append((label, ellipsoids, color))
        self.notes.extend(notes)
        drawn = sum(e.physical for e in ellipsoids)
        n_bodies = len(ellipsoids) if bodies is None else len(set(bodies))
        shown = bool(visible)
        self._vis[f"inertia/{label}"].set_property("visible", shown)
        entry = _set_entry(label, color, wire, shown, f"{drawn} of {n_bodies} bodies")
        self._legend.append(
            LegendSection(f"inertia ellipsoids: {html_lib.escape(label)}", [entry], short)
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
        for j, link, s, d, n in zip(
            ident.joints,
            link_names(self._model),
            ident.share,
            ident.determined,
            ident.total,
            strict=True,
        ):
            lines.append(
                f'<span class="sw" style="background:{css_color(share_color(s))}"></span> '
                f'<span title="parameters {html_lib.escape(j)}.*">{html_lib.escape(link)}</span>'
                f": {int(d)}/{int(n)} determined ({100 * s:.0f}%)"
            )
        scale = " ".join(
            f'<span class="sw" style="background:{css_color(share_color(s))}"></span>{s:g}'
            for s in (0.0, 0.25, 0.5, 0.75, 1.0)
        )
        self._legend.append(
            LegendSection(
                f"identifiability ({html_lib.escape(ident.criterion)})",
                [f"share determined: {scale}", *lines],
            )
        )
        return self

    def frame_points(self, points) -> None:
        """Frame ``points`` (world [m], shape (n, 3); e.g. a world object) with the robot."""
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        self._framed_extra = np.vstack([self._framed_extra, pts[np.isfinite(pts).all(1)]])
        self._set_camera(*self._frame_args)

    def add_object(self, name: str, geometry, material, transform, legend=None) -> None:
        """A fixed meshcat ``geometry`` with ``material`` at ``transform`` (4x4, world frame
        [m]) under ``world/<name>``; ``legend``: a :class:`LegendSection` for the page."""
        self._vis[f"world/{name}"].set_object(geometry, material)
        self._vis[f"world/{name}"].set_transform(np.asarray(transform, dtype=float))
        if legend is not None:
            self._legend.append(legend)

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
            return page_html(
                title,
                legend,
                viewer=f'<script src="{self.VIEWER_JS}"></script>',
                data=f'<script src="{self.DATA_JS}"></script>',
            )
        return page_html(
            title,
            legend,
            viewer=f"<script>\n{viewer_js()}\n</script>",
            data=f"<script>\n{self._data_js()}\n</script>",
        )

    def _data_js(self) -> str:
        payload = json.dumps([base64.b64encode(c).decode("ascii") for c in self.commands()])
        return f"var commands = {payload};"

    def asset_files(self) -> dict[str, str]:
        """The files an ``assets = "external"`` page loads: name -> text (empty inline)."""
        if self.assets != "external":
            return {}
        return {self.VIEWER_JS: viewer_js(), self.DATA_JS: self._data_js()}

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
        parts.extend(leg.html() for leg in self._legend)
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

        The meshcat server (:func:`~manip_id.viz.meshcat_server.start_server`) listens on
        ``host`` (web) and 127.0.0.1 (commands); it stops with :meth:`LiveView.stop` or
        with this process. Its URL is ``view.url``.
        """
        return replay(self.commands(), host, open_browser)
