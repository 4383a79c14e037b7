"""Attached cloth points against where their body carries them, at every frame (simbake.qa's
``attachment_drift``), measured apart from the solver.

An attached point is bound at the first frame to the nearest point of its body's surface and
keeps its offset from it in the surface's frame (README, "Cloth attachments"). Here the binding
is made again, with numpy, from the first recorded frame: for a rigid body (dynamic, keyed or
static) the point in the body's mesh frame, from the body's pose; for a deforming collider
(Body.deformation) the nearest point of its triangle mesh at the first frame (triangle,
barycentric weights) and the offset in that triangle's frame ``[e1, n x e1, n]``. At every
frame the point's bound position is computed from the body's pose at that frame, or from the
collider's own mesh at that frame (its time-sampled points, or its UsdSkel skinning, as the
shot gives them: simbake.usd_deforming), and the figure is the largest distance of an
attached point from its bound position (m).

A point nearest an edge or a vertex of a deforming mesh is nearest several triangles; it binds
to the first (by index), as the core does, which only matters when the point is off the
surface and the triangles there turn differently.
"""

from __future__ import annotations

import numpy as np

from .rotations import quat_matrix

_NEAREST = 16  # triangles whose distance bounds a point's nearest


def has_attachments(scene) -> bool:
    return any(c.attached for c in scene.cloths)


def closest_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Barycentric weights (n, 3) of the point of triangle (a[k], b[k], c[k]) nearest p[k] (all
    (n, 3)): the regions of Ericson's "Real-Time Collision Detection" 5.1.5, vectorized."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = np.einsum("ij,ij->i", ab, ap), np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3, d4 = np.einsum("ij,ij->i", ab, bp), np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5, d6 = np.einsum("ij,ij->i", ab, cp), np.einsum("ij,ij->i", ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    w = np.zeros((len(p), 3))
    done = np.zeros(len(p), dtype=bool)

    def take(mask, weights):
        nonlocal done
        mask = mask & ~done
        w[mask] = weights[mask] if weights.ndim == 2 else weights
        done |= mask

    def safe(x):
        return np.where(x != 0, x, 1.0)

    one = np.ones(len(p))
    zero = np.zeros(len(p))
    take((d1 <= 0) & (d2 <= 0), np.array([1.0, 0.0, 0.0]))                       # vertex a
    take((d3 >= 0) & (d4 <= d3), np.array([0.0, 1.0, 0.0]))                      # vertex b
    t = d1 / safe(d1 - d3)
    take((vc <= 0) & (d1 >= 0) & (d3 <= 0), np.stack([one - t, t, zero], -1))    # edge ab
    take((d6 >= 0) & (d5 <= d6), np.array([0.0, 0.0, 1.0]))                      # vertex c
    t = d2 / safe(d2 - d6)
    take((vb <= 0) & (d2 >= 0) & (d6 <= 0), np.stack([one - t, zero, t], -1))    # edge ac
    t = (d4 - d3) / safe((d4 - d3) + (d5 - d6))
    take((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0), np.stack([zero, one - t, t], -1))  # edge bc
    denom = safe(va + vb + vc)
    v, u = vb / denom, vc / denom
    take(np.ones(len(p), dtype=bool), np.stack([one - v - u, v, u], -1))         # the face
    return w


def triangle_frames(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Each triangle's frame (n, 3, 3), columns e1 (along a -> b), n x e1 and its unit normal n."""
    e1 = b - a
    e1 = e1 / np.linalg.norm(e1, axis=1, keepdims=True)
    n = np.cross(b - a, c - a)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    return np.stack([e1, np.cross(n, e1), n], axis=-1)


def _squared_distances(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Squared distance from each point points[k] to the triangle corners[k] (both (n, ...))."""
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    w = closest_on_triangles(points, a, b, c)
    d = points - (w[:, :1] * a + w[:, 1:2] * b + w[:, 2:] * c)
    return np.einsum("ij,ij->i", d, d)


def _nearest_triangles(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Each point's nearest triangle (the first of the nearest by index). Only the triangles
    whose centroid is within the point's distance to its _NEAREST nearest centroids' triangles
    plus the largest triangle's radius can be nearer, so only those are compared."""
    from scipy.spatial import cKDTree

    centroids = corners.mean(axis=1)
    radius = float(np.linalg.norm(corners - centroids[:, None, :], axis=-1).max())
    tree = cKDTree(centroids)
    k = min(_NEAREST, len(corners))
    near = tree.query(points, k=k)[1].reshape(len(points), k)
    squared = _squared_distances(np.repeat(points, k, axis=0), corners[near.reshape(-1)])
    bound = np.sqrt(squared.reshape(len(points), k).min(axis=1))
    found = tree.query_ball_point(points, bound * (1 + 1e-9) + radius * (1 + 1e-9) + 1e-12)
    which = np.empty(len(points), dtype=np.int64)
    for i, tri in enumerate(found):
        tri = np.sort(np.asarray(tri, dtype=np.int64))
        which[i] = tri[np.argmin(_squared_distances(np.broadcast_to(points[i], (len(tri), 3)), corners[tri]))]
    return which


def bind_to_mesh(points: np.ndarray, vertices: np.ndarray, triangles: np.ndarray):
    """Each point's nearest triangle of the mesh (the first of the nearest), the barycentric
    weights of its nearest point there, and its offset from that point in the triangle's frame."""
    corners = vertices[triangles]
    areas = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    usable = np.flatnonzero(areas > 0)
    which = usable[_nearest_triangles(points, corners[usable])]
    a, b, c = corners[which, 0], corners[which, 1], corners[which, 2]
    weights = closest_on_triangles(points, a, b, c)
    near = weights[:, :1] * a + weights[:, 1:2] * b + weights[:, 2:] * c
    offset = np.einsum("kji,kj->ki", triangle_frames(a, b, c), points - near)
    return which, weights, offset


def carried_on_mesh(vertices: np.ndarray, triangles: np.ndarray, which, weights, offset) -> np.ndarray:
    """The bound positions (bind_to_mesh's) on the mesh at `vertices`."""
    corners = vertices[triangles[which]]
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    near = weights[:, :1] * a + weights[:, 1:2] * b + weights[:, 2:] * c
    return near + np.einsum("kij,kj->ki", triangle_frames(a, b, c), offset)


class AttachmentDrift:
    """Each attached cloth's points against their bound positions at every recorded frame."""

    def __init__(self, scene):
        self.start = scene.start_frame
        index = {b.name: i for i, b in enumerate(scene.bodies)}
        self.bodies = scene.bodies
        # (cloth index, its attached points, its body's index)
        self.attached = [(k, np.asarray(c.attached, dtype=np.int64), index[c.attach_to])
                         for k, c in enumerate(scene.cloths) if c.attached]
        self.bound: list = []  # per attachment, made at the first recorded frame

    def measure(self, frame: int, world) -> dict[int, float]:
        """Cloth index -> the largest distance of its attached points from their bound positions
        at `frame` (m), the world as it is at that frame (its bodies' poses and cloths' points)."""
        translations, orientations = (np.asarray(a, dtype=np.float64) for a in world.mesh_poses())
        out = {}
        for n, (cloth, points, body) in enumerate(self.attached):
            x = np.asarray(world.cloth_state(cloth)[0], dtype=np.float64)[points]
            deformation = self.bodies[body].deformation
            k = min(max(frame - self.start, 0), len(deformation.vertices) - 1) if deformation is not None else 0
            if n == len(self.bound):  # the first frame: bind
                if deformation is not None:
                    self.bound.append(bind_to_mesh(x, deformation.vertices[k], np.asarray(deformation.triangles)))
                else:
                    r = quat_matrix(orientations[body])
                    self.bound.append((x - translations[body]) @ r)
            if deformation is not None:
                expected = carried_on_mesh(deformation.vertices[k], np.asarray(deformation.triangles), *self.bound[n])
            else:
                expected = self.bound[n] @ quat_matrix(orientations[body]).T + translations[body]
            out[cloth] = float(np.linalg.norm(x - expected, axis=1).max())
        return out
