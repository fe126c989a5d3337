"""Mesh references of an exported robot: loadable from wherever the file is written.

A URDF names its meshes ``package://PKG/path`` (resolved against package folders the
reader must be given), by a path relative to the URDF, or absolutely. An exported file
lives elsewhere, so the export rewrites every ``<mesh filename>`` it can resolve into an
**absolute path** (``meshes="absolute"``, the default): ``package://PKG/path`` is the
first ``DIR/PKG/path`` that exists among the robot's
:attr:`~manip_id.robot.model.Robot.package_dirs`; a relative path is taken from the source
URDF's folder. ``pinocchio.RobotWrapper.BuildFromURDF(out)`` and MuJoCo then find them
without ``package_dirs``. ``meshes="keep"`` leaves the references as they were.
References that resolve to no file are left as they were and listed.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path

from ..errors import InputError

#: How mesh references are written.
MESH_POLICIES: tuple[str, ...] = ("absolute", "keep")


def resolve_mesh(filename: str, base: Path, package_dirs: Sequence[str]) -> Path | None:
    """The file a mesh reference names, or None when it resolves to no file.

    Parameters
    ----------
    filename: ``package://PKG/path``, ``file://path``, an absolute or a relative path
    base: folder of the URDF that holds the reference (relative paths start there)
    package_dirs: folders holding the packages named by ``package://``
    """
    if filename.startswith("package://"):
        rest = filename[len("package://") :]
        for d in package_dirs:
            candidate = Path(d) / rest
            if candidate.is_file():
                return candidate.resolve()
        return None
    if filename.startswith("file://"):
        filename = filename[len("file://") :]
    path = Path(filename)
    if not path.is_absolute():
        path = base / path
    return path.resolve() if path.is_file() else None


def rewrite_meshes(
    root: ET.Element, base: Path, package_dirs: Sequence[str], policy: str = "absolute"
) -> list[str]:
    """Rewrite every ``<mesh filename>`` under ``root`` by ``policy``; returns the unresolved."""
    if policy not in MESH_POLICIES:
        raise InputError(f"meshes must be one of {list(MESH_POLICIES)}, got {policy!r}")
    unresolved: list[str] = []
    for mesh in root.iter("mesh"):
        name = mesh.get("filename")
        if name is None:
            continue
        path = resolve_mesh(name, base, package_dirs)
        if path is None:
            unresolved.append(name)
        elif policy == "absolute":
            mesh.set("filename", str(path))
    return unresolved
