"""Points inside a closed triangle mesh and how deep, in numpy: the reference the core's
measure (simbake._core.closed_mesh_depth, which the QA uses) is tested against, written apart
from it, and the tests' own check of cloth against deforming colliders.

Inside is the parity of a ray's crossings with the closed mesh (in a direction no mesh lines
up with; the triangles binned across the ray); the distance is the nearest triangle's, exact.
"""

from __future__ import annotations

import numpy as np

_PAIRS = 1 << 20            # point-triangle pairs per numpy block
_RAY = np.array([0.2718281828, 1.0, 0.1414213562])  # a direction no mesh lines up with
_RAY /= np.linalg.norm(_RAY)
_NEAREST = 16               # triangles looked at first for a point's distance


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
