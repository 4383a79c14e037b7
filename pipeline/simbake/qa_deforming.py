"""Cloth against deforming colliders, measured at each collider's own pose at every frame
(simbake.qa's cloth penetration, for the bodies whose surface moves: Body.deformation).

The core's quality figures see the bodies as the solver holds them; a deforming collider's
surface at a frame is known exactly from the shot itself (its time-sampled points, or its
UsdSkel skinning: simbake.usd_deforming), so the cloth is measured against that, apart from
the solver: for every cloth point (each vertex, and each edge's eighths, as the core's figure)
inside the frame's closed triangle mesh, its distance to the mesh's surface. Inside is the
parity of a ray's crossings with the closed mesh (in a direction no mesh lines up with; the
triangles binned across the ray); the distance is the nearest triangle's, exact. Points
outside the mesh's bounding box are outside.

The depth goes into the cloth's vertex and edge penetration of that frame (the larger of the
core's and this one), so the QA's threshold (1 mm past a surface) and warning apply as to any
body.
"""

from __future__ import annotations

import numpy as np

_PAIRS = 1 << 20            # point-triangle pairs per numpy block
_RAY = np.array([0.2718281828, 1.0, 0.1414213562])  # a direction no mesh lines up with
_RAY /= np.linalg.norm(_RAY)
_NEAREST = 16               # triangles looked at first for a point's distance


def has_deforming(scene) -> bool:
    return any(b.deformation is not None for b in scene.bodies)


def _ray_frame() -> tuple[np.ndarray, np.ndarray]:
    u = np.cross(_RAY, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    return u, np.cross(_RAY, u)


def inside_closed(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Whether each point (n, 3) is inside the closed triangle mesh (corners (m, 3, 3)): the
    parity of the triangles a ray from it crosses. The ray's direction is one no mesh's edges
    or vertices line up with (a ray through an edge would count it twice); the triangles are
    binned in a grid across the ray so that each point tests the few in its cell."""
    u, w = _ray_frame()
    p2 = np.stack([points @ u, points @ w], axis=-1)
    t2 = np.stack([corners @ u, corners @ w], axis=-1)             # (m, 3, 2)
    lo, hi = t2.min(axis=1), t2.max(axis=1)
    cell = max(float(np.median(hi - lo)), 1e-9)
    origin = np.minimum(lo.min(axis=0), p2.min(axis=0))
    clo = np.floor((lo - origin) / cell).astype(np.int64)
    chi = np.floor((hi - origin) / cell).astype(np.int64)
    width = int(max(chi[:, 0].max(), np.floor((p2[:, 0] - origin[0]) / cell).max())) + 1
    # (cell, triangle) for every cell a triangle's box covers
    spans = (chi - clo + 1)
    counts = spans[:, 0] * spans[:, 1]
    tri = np.repeat(np.arange(len(corners)), counts)
    k = np.arange(len(tri)) - np.repeat(np.cumsum(counts) - counts, counts)
    cx = clo[tri, 0] + k % spans[tri, 0]
    cy = clo[tri, 1] + k // spans[tri, 0]
    keys = cy * width + cx
    order = np.argsort(keys, kind="stable")
    keys, tri = keys[order], tri[order]
    pc = np.floor((p2 - origin) / cell).astype(np.int64)
    pkey = pc[:, 1] * width + pc[:, 0]
    first, last = np.searchsorted(keys, pkey, "left"), np.searchsorted(keys, pkey, "right")
    n = last - first
    point = np.repeat(np.arange(len(points)), n)
    cand = tri[np.repeat(first, n) + np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)]
    crossings = np.zeros(len(points), dtype=np.int64)
    for s in range(0, len(point), _PAIRS):
        i, t = point[s:s + _PAIRS], cand[s:s + _PAIRS]
        q, a, b, c = p2[i], t2[t, 0], t2[t, 1], t2[t, 2]
        d1 = (b[:, 0] - a[:, 0]) * (q[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (q[:, 0] - a[:, 0])
        d2 = (c[:, 0] - b[:, 0]) * (q[:, 1] - b[:, 1]) - (c[:, 1] - b[:, 1]) * (q[:, 0] - b[:, 0])
        d3 = (a[:, 0] - c[:, 0]) * (q[:, 1] - c[:, 1]) - (a[:, 1] - c[:, 1]) * (q[:, 0] - c[:, 0])
        hit = ((d1 > 0) & (d2 > 0) & (d3 > 0)) | ((d1 < 0) & (d2 < 0) & (d3 < 0))
        # the crossing is ahead of the point along the ray: barycentric height along _RAY
        area = d1 + d2 + d3
        along = (d2 * (corners[t, 0] @ _RAY) + d3 * (corners[t, 1] @ _RAY) + d1 * (corners[t, 2] @ _RAY))
        ahead = along / np.where(area != 0, area, 1.0) > points[i] @ _RAY
        np.add.at(crossings, i[hit & ahead], 1)
    return crossings % 2 == 1


def triangle_distances(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Distance from each point p[k] to the triangle (a[k], b[k], c[k]) (all (n, 3)): the
    plane's closest point when it falls inside the triangle, else the nearest edge's."""
    n = np.cross(b - a, c - a)
    nn = np.einsum("ij,ij->i", n, n)
    safe = np.where(nn > 0, nn, 1.0)
    d_plane = np.einsum("ij,ij->i", p - a, n)
    proj = p - (d_plane / safe)[:, None] * n
    inside = nn > 0
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", np.cross(v - u, proj - u), n) >= 0
    best = np.where(inside, np.abs(d_plane) / np.sqrt(safe), np.inf)
    for u, v in ((a, b), (b, c), (c, a)):
        e = v - u
        ee = np.einsum("ij,ij->i", e, e)
        t = np.clip(np.einsum("ij,ij->i", p - u, e) / np.where(ee > 0, ee, 1.0), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(p - (u + t[:, None] * e), axis=-1))
    return best


def _nearest_bounds(points: np.ndarray, corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each point's distance to the nearest of its _NEAREST triangles by centroid (an upper
    bound of its distance to the mesh), and whether that is its distance: when the last of
    those centroids is no nearer than the bound plus the largest triangle's radius."""
    from scipy.spatial import cKDTree

    centroids = corners.mean(axis=1)
    radius = float(np.linalg.norm(corners - centroids[:, None, :], axis=-1).max())
    k = min(_NEAREST, len(corners))
    far, near = cKDTree(centroids).query(points, k=k)
    far, near = far.reshape(len(points), k), near.reshape(len(points), k)
    flat = near.reshape(-1)
    bound = triangle_distances(np.repeat(points, k, axis=0), corners[flat, 0], corners[flat, 1],
                               corners[flat, 2]).reshape(len(points), k).min(axis=1)
    settled = far[:, -1] >= bound + radius if k < len(corners) else np.ones(len(points), dtype=bool)
    return bound, settled


def nearest_distances(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Each point's (n, 3) distance to the nearest of the triangles (m, 3, 3), exact: the
    bound of _nearest_bounds, and for a point it does not settle every triangle whose centroid
    is within the bound plus the largest triangle's radius (no other can be nearer)."""
    from scipy.spatial import cKDTree

    bound, settled = _nearest_bounds(points, corners)
    open_ = np.flatnonzero(~settled)
    if len(open_):
        centroids = corners.mean(axis=1)
        radius = float(np.linalg.norm(corners - centroids[:, None, :], axis=-1).max())
        found = cKDTree(centroids).query_ball_point(points[open_], bound[open_] + radius)
        counts = np.array([len(f) for f in found])
        tri = np.concatenate([np.asarray(f, dtype=np.int64) for f in found])
        d = triangle_distances(np.repeat(points[open_], counts, axis=0), corners[tri, 0], corners[tri, 1],
                               corners[tri, 2])
        bound[open_] = np.minimum(bound[open_], np.minimum.reduceat(d, np.cumsum(counts) - counts))
    return bound


def deepest_distance(points: np.ndarray, corners: np.ndarray) -> float:
    """The largest over the points (n, 3) of the distance to the nearest of the triangles
    (m, 3, 3), exact. Each point's _NEAREST triangles by centroid first give an upper bound
    of its distance, which is its distance when every other triangle is further: its centroid
    is no nearer than the last of those, so the triangle no nearer than that less its radius.
    The others are looked at against every triangle, deepest bound first, until a bound is
    below the deepest distance found (a sphere's centre is equally far from all triangles)."""
    if len(points) == 0:
        return 0.0
    bound, settled = _nearest_bounds(points, corners)
    best = float(bound[settled].max()) if settled.any() else 0.0
    for i in np.flatnonzero(~settled)[np.argsort(-bound[~settled], kind="stable")]:
        if bound[i] <= best:
            break
        q = np.broadcast_to(points[i], (len(corners), 3))
        best = max(best, float(triangle_distances(q, corners[:, 0], corners[:, 1], corners[:, 2]).min()))
    return best


def penetration(points: np.ndarray, vertices: np.ndarray, triangles: np.ndarray) -> float:
    """The deepest of `points` (n, 3) inside the closed mesh (vertices, triangles): its
    distance to the surface (m), 0 when none is inside."""
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    near = points[np.all((points >= lo) & (points <= hi), axis=1)]
    if len(near) == 0:
        return 0.0
    corners = vertices[triangles]
    inside = near[inside_closed(near, corners)]
    return deepest_distance(inside, corners)


def _edges(triangles) -> np.ndarray:
    e = np.sort(np.asarray(triangles, dtype=np.int64)[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    return np.unique(e, axis=0)


class DeformingPenetration:
    """Each cloth's penetration into the scene's deforming colliders at every recorded frame."""

    EIGHTHS = np.arange(1, 8) / 8.0

    def __init__(self, scene):
        self.start = scene.start_frame
        self.surfaces = [b.deformation for b in scene.bodies if b.deformation is not None]
        # a USD shot's cloth has its triangles; a grid cloth (TOML) is measured at its vertices
        self.edges = [_edges(c.mesh_triangles) if c.mesh_triangles is not None else None for c in scene.cloths]

    def measure(self, frame: int, cloth: int, points: np.ndarray) -> tuple[float, float]:
        """(deepest vertex, deepest edge point) of cloth `cloth` at `points` (n, 3) inside any
        deforming collider at `frame` (m)."""
        k = frame - self.start
        edges = self.edges[cloth]
        vertex = edge = 0.0
        for surface in self.surfaces:
            vertices = surface.vertices[min(max(k, 0), len(surface.vertices) - 1)]
            v, e = self._measure_surface(points, edges, vertices, surface.triangles)
            vertex, edge = max(vertex, v), max(edge, e)
        return vertex, edge

    def _measure_surface(self, points, edges, vertices, triangles) -> tuple[float, float]:
        """(deepest vertex, deepest edge point) inside one closed mesh. An edge's points are
        looked at only where they can be inside: not when both ends are outside and bounds
        of their distances to the surface add up to more than the edge's length (a point of
        the edge inside would put a crossing of the surface within its distance along the
        edge of each end), so the figure is the one of every edge's eighths."""
        lo, hi = vertices.min(axis=0), vertices.max(axis=0)
        in_box = np.all((points >= lo) & (points <= hi), axis=1)
        corners = vertices[triangles]
        inside = np.zeros(len(points), dtype=bool)
        if in_box.any():
            inside[in_box] = inside_closed(points[in_box], corners)
        vertex = deepest_distance(points[inside], corners)
        if edges is None or not len(edges):
            return vertex, 0.0
        a, b = points[edges[:, 0]], points[edges[:, 1]]
        length = np.linalg.norm(b - a, axis=1)
        # the distance to the mesh's box: at most the distance to its surface
        box = np.linalg.norm(np.maximum(lo - points, 0) + np.maximum(points - hi, 0), axis=1)
        ends = edges[inside[edges[:, 0]] | inside[edges[:, 1]]]
        open_ = ~(inside[edges[:, 0]] | inside[edges[:, 1]])
        near = open_ & (box[edges[:, 0]] + box[edges[:, 1]] <= length * (1 + 1e-9))
        if near.any():
            # no triangle is nearer than its centroid less its radius: a bound of the
            # distance to the surface from the nearest centroid and the largest radius
            from scipy.spatial import cKDTree

            centroids = corners.mean(axis=1)
            radius = float(np.linalg.norm(corners - centroids[:, None, :], axis=-1).max())
            used = np.unique(edges[near])
            distance = np.zeros(len(points))
            distance[used] = np.maximum(cKDTree(centroids).query(points[used])[0] - radius, 0.0)
            near &= distance[edges[:, 0]] + distance[edges[:, 1]] <= length * (1 + 1e-9)
        kept = np.concatenate([ends, edges[near]])
        if not len(kept):
            return vertex, 0.0
        a, b = points[kept[:, 0]], points[kept[:, 1]]
        samples = (a[:, None, :] + self.EIGHTHS[None, :, None] * (b - a)[:, None, :]).reshape(-1, 3)
        return vertex, penetration(samples, vertices, triangles)

    def fold_into(self, cloths: dict, figures: dict, frame: int, world) -> None:
        """The last recorded frame's cloth figures (simbake.qa.QualityRecorder's) raised to
        this measure where it is deeper."""
        deepest = figures["cloth_penetration"][-1]
        for i, c in enumerate(cloths.values()):
            vertex, edge = self.measure(frame, i, np.asarray(world.cloth_state(i)[0], dtype=np.float64))
            c["vertex_penetration"][-1] = max(c["vertex_penetration"][-1], vertex)
            c["edge_penetration"][-1] = max(c["edge_penetration"][-1], edge)
            deepest = max(deepest, vertex, edge)
        figures["cloth_penetration"][-1] = deepest
