"""Cloth against deforming colliders, measured at each collider's own pose at every frame
(simbake.qa's cloth penetration, for the bodies whose surface moves: Body.deformation).

The core's quality figures see the bodies as the solver holds them; a deforming collider's
surface at a frame is known exactly from the shot itself (its time-sampled points, or its
UsdSkel skinning: simbake.usd_deforming), so the cloth is measured against that, apart from
the solver: for every cloth point (each vertex, and each edge's eighths, as the core's figure)
inside the frame's closed triangle mesh, its distance to the mesh's surface. Inside is the
parity of a ray's crossings with the closed mesh; the distance is the nearest triangle's,
exact (the core's closed_mesh_depth, core/geometry/closed_mesh.h, which shares nothing with
the solver's contacts; tests/python/mesh_reference.py is its numpy reference).

The depth goes into the cloth's vertex and edge penetration of that frame (the larger of the
core's and this one), so the QA's threshold (1 mm past a surface) and warning apply as to any
body.
"""

from __future__ import annotations

import numpy as np

from . import _core

_NO_EDGES = np.zeros((0, 2), dtype=np.int64)


def has_deforming(scene) -> bool:
    return any(b.deformation is not None for b in scene.bodies)


def _edges(triangles) -> np.ndarray:
    e = np.sort(np.asarray(triangles, dtype=np.int64)[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    return np.unique(e, axis=0)


class DeformingPenetration:
    """Each cloth's penetration into the scene's deforming colliders at every recorded frame."""

    def __init__(self, scene):
        self.start = scene.start_frame
        self.surfaces = [b.deformation for b in scene.bodies if b.deformation is not None]
        # a USD shot's cloth has its triangles; a grid cloth (TOML) is measured at its vertices
        self.edges = [_edges(c.mesh_triangles) if c.mesh_triangles is not None else None for c in scene.cloths]

    def measure(self, frame: int, cloth: int, points: np.ndarray, threads: int = 0) -> tuple[float, float]:
        """(deepest vertex, deepest edge point) of cloth `cloth` at `points` (n, 3) inside any
        deforming collider at `frame` (m), on at most `threads` CPUs (0: all)."""
        k = frame - self.start
        edges = self.edges[cloth]
        vertex = edge = 0.0
        for surface in self.surfaces:
            vertices = surface.vertices[min(max(k, 0), len(surface.vertices) - 1)]
            v, e = _core.closed_mesh_depth(vertices, surface.triangles, points,
                                           _NO_EDGES if edges is None else edges, threads)
            vertex, edge = max(vertex, v), max(edge, e)
        return vertex, edge

    def fold_into(self, cloths: dict, figures: dict, frame: int, world) -> None:
        """The last recorded frame's cloth figures (simbake.qa.QualityRecorder's) raised to
        this measure where it is deeper."""
        deepest = figures["cloth_penetration"][-1]
        for i, c in enumerate(cloths.values()):
            points = np.asarray(world.cloth_state(i)[0], dtype=np.float64)
            vertex, edge = self.measure(frame, i, points, world.settings.threads)
            c["vertex_penetration"][-1] = max(c["vertex_penetration"][-1], vertex)
            c["edge_penetration"][-1] = max(c["edge_penetration"][-1], edge)
            deepest = max(deepest, vertex, edge)
        figures["cloth_penetration"][-1] = deepest
