"""Meshes for the scene: decimated by vertex clustering, read once per file and size.

Vertices [m] of shape (V, 3) and triangles (F, 3) of vertex indices; a mesh is decimated
to at most ``max_triangles`` triangles (:func:`decimate_mesh`) and sent as binary arrays.
"""

from __future__ import annotations

import warnings

import numpy as np

#: Triangles kept per mesh at most (vertex clustering); meshes are sent as binary arrays.
MAX_TRIANGLES = 3000
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


def mesh_arrays(obj, max_triangles: int):
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
