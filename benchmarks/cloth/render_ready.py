"""Whether a baked cloth cache is ready to render, checked apart from the core: what
tests/python/test_cloth_render_ready.py asserts of every shipped cloth scene and
benchmarks/cloth/render_check.py reports for any scene (render_ready_failures).

At every written frame:
- layers through layers: the cloth's triangles against each other by crossings.py (NumPy
  alone; the cloth benchmark counts the peers' crossings with it): its own candidate search, a
  grid over the triangles' boxes, and its own predicate: where an edge crosses a triangle's
  plane, and that point's barycentric coordinates, instead of the core's signed volumes. A
  crossing counts when the edge's two ends lie on opposite sides of the plane by more than
  round-off (1e-9 of the longest edge of the pair) and the crossing point lies inside the
  triangle by as much;
- strain: the largest edge strain |l| / L - 1 (L from the first frame, the rest shape) within
  the cloth's strain limit + 1% of it (the QA's warning threshold);
- cloth inside bodies: each cloth edge sampled at its ends and eighths, against the ground
  plane and each analytic body's exact distance (box and sphere, at the body's pose read from
  the cache): no sample deeper than 0.5 mm past the surface (half a pixel of a 2 m shot at
  1080p; the cloth's thickness is not counted). Mesh bodies (cloth_demo's ring) are checked
  against their own triangles as written in the cache, not the level set the core collides
  with: a sample is inside where the mesh's winding number (the sum of its triangles' solid
  angles, van Oosterom and Strackee) is over 1/2, and its depth is its distance to the
  nearest triangle;
- body edges through the cloth: each box's 12 edges, and every edge of a mesh body, against
  every cloth triangle, with the same crossing predicate as for the layers: none.
"""

from __future__ import annotations

import numpy as np

from benchmarks.cloth.crossings import crossing_count, segments_through

STRAIN_SLACK = 0.01      # of the strain limit (the QA's warning threshold)
DEEPEST_INSIDE = 0.5e-3  # (m) a cloth edge's sample past a body's surface


MESSAGES = {
    "strain": f"strain over the limit + {STRAIN_SLACK:.0%} of it at (cloth, frame)",
    "inside": "cloth edges deeper than 0.5 mm in a body or the ground at (cloth, body, frame), mm",
    "through": "box edges through cloth triangles at (cloth, body, frame)",
    "mesh_through": "mesh body edges through cloth triangles at (cloth, body, frame)",
}


def mesh_edges(triangles: np.ndarray) -> np.ndarray:
    """The unique edges (i < j) of a triangle mesh."""
    e = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    return np.unique(np.sort(e, axis=1), axis=0)


def largest_strain(points: np.ndarray, edges: np.ndarray, rest: np.ndarray) -> float:
    return float((np.linalg.norm(points[edges[:, 1]] - points[edges[:, 0]], axis=1) / rest - 1).max())


def analytic_distance(shape, p: np.ndarray) -> np.ndarray:
    """Signed distance (negative inside) of body-space points p (k, 3) to a box or sphere."""
    if shape.kind == "sphere":
        return np.linalg.norm(p, axis=1) - shape.radius
    q = np.abs(p) - 0.5 * np.asarray(shape.size)
    return np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0)


def edge_samples(points: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Each edge's ends and eighths, (9 nedge, 3)."""
    s = np.linspace(0, 1, 9)[:, None, None]
    return ((1 - s) * points[edges[:, 0]] + s * points[edges[:, 1]]).reshape(-1, 3)


def box_edges(size) -> np.ndarray:
    """The 12 edges of a box centred at the origin, (12, 2, 3)."""
    h = 0.5 * np.asarray(size)
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * h
    pairs = [(a, b) for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]
    return np.array([[corners[a], corners[b]] for a, b in pairs])


def winding_number(p: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """The winding number of a closed triangle mesh (corners (m, 3, 3), outward) about points
    p (k, 3): 1 inside, 0 outside; the solid angle of each triangle by van Oosterom and
    Strackee's formula."""
    a, b, c = (corners[None, :, i, :] - p[:, None, :] for i in range(3))
    la, lb, lc = (np.linalg.norm(v, axis=2) for v in (a, b, c))
    det = np.einsum("kmi,kmi->km", a, np.cross(b, c))
    div = (la * lb * lc + np.einsum("kmi,kmi->km", a, b) * lc + np.einsum("kmi,kmi->km", b, c) * la
           + np.einsum("kmi,kmi->km", c, a) * lb)
    return (2 * np.arctan2(det, div)).sum(axis=1) / (4 * np.pi)


def triangle_distance(p: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Distance of points p (k, 3) to the nearest of the triangles corners (m, 3, 3): the
    nearest point of each triangle by minimising over its plane's projection clamped to the
    triangle (the projection when inside, else the nearest point of the nearest edge)."""
    a, b, c = (corners[None, :, i, :] for i in range(3))
    q = p[:, None, :]
    n = np.cross(b - a, c - a)
    n = n / np.linalg.norm(n, axis=2, keepdims=True)
    projected = q - np.einsum("kmi,kmi->km", q - a, n)[..., None] * n
    # barycentric signs of the projection: inside when all three sub-areas face along n
    inside = np.ones(projected.shape[:2], dtype=bool)
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("kmi,kmi->km", np.cross(v - u, projected - u), n) >= 0
    best = np.where(inside, np.linalg.norm(q - projected, axis=2), np.inf)
    for u, v in ((a, b), (b, c), (c, a)):
        t = np.clip(np.einsum("kmi,kmi->km", q - u, v - u) / np.einsum("kmi,kmi->km", v - u, v - u), 0, 1)
        best = np.minimum(best, np.linalg.norm(q - (u + t[..., None] * (v - u)), axis=2))
    return best.min(axis=1)


def ray_crossings(p: np.ndarray, corners: np.ndarray, axis: int, chunk: int = 4096) -> np.ndarray:
    """How many triangles (corners (m, 3, 3)) a ray from each point p (k, 3) along +axis
    crosses: the triangles whose boxes across the ray hold the point and that reach past it,
    then an exact test in the plane across the ray (the point strictly inside the projected
    triangle, by the signs of its three edge functions) and where along the ray it is crossed."""
    b, c = (axis + 1) % 3, (axis + 2) % 3
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    counts = np.zeros(len(p), dtype=np.int64)
    for start in range(0, len(p), chunk):
        q = p[start:start + chunk]
        near = ((lo[None, :, b] <= q[:, None, b]) & (q[:, None, b] <= hi[None, :, b])
                & (lo[None, :, c] <= q[:, None, c]) & (q[:, None, c] <= hi[None, :, c])
                & (q[:, None, axis] <= hi[None, :, axis]))
        k, t = np.nonzero(near)
        if len(k) == 0:
            continue
        T, Q = corners[t], q[k]
        u = T[:, :, [b, c]] - Q[:, None, [b, c]]                        # corners about the point, (n, 3, 2)
        edge = u[:, :, 0] * np.roll(u, -1, axis=1)[:, :, 1] - u[:, :, 1] * np.roll(u, -1, axis=1)[:, :, 0]
        area = edge.sum(axis=1)                                          # twice the projected area
        inside = (np.all(edge > 0, axis=1) | np.all(edge < 0, axis=1)) & (area != 0)
        # the barycentric weight of corner i is the edge function of the edge opposite it
        w = np.roll(edge, -1, axis=1) / np.where(area != 0, area, 1)[:, None]
        along = (w * T[:, :, axis]).sum(axis=1)
        hit = inside & (along > Q[:, axis])
        counts[start:start + chunk] += np.bincount(k[hit], minlength=len(q))
    return counts


# Three ray directions in no special relation to a mesh's own axes (the rows of a rotation by
# 0.3, 0.7 and 1.1 rad about z, y and x): a ray along an axis from a box's centre meets the
# subdivided box exactly on its faces' edges, where the parity miscounts
_RAYS = (np.array([[np.cos(0.3), -np.sin(0.3), 0], [np.sin(0.3), np.cos(0.3), 0], [0, 0, 1]])
         @ np.array([[np.cos(0.7), 0, np.sin(0.7)], [0, 1, 0], [-np.sin(0.7), 0, np.cos(0.7)]])
         @ np.array([[1, 0, 0], [0, np.cos(1.1), -np.sin(1.1)], [0, np.sin(1.1), np.cos(1.1)]]))


def inside_mesh(p: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Whether each point p (k, 3) is inside the closed mesh `corners` (m, 3, 3): the parity
    of a ray's crossings, along three directions (_RAYS), the majority of the three (a ray
    exactly through an edge or a corner may miscount; three do not all do so)."""
    p, corners = p @ _RAYS.T, corners @ _RAYS.T   # the rays along the axes of this frame
    votes = sum((ray_crossings(p, corners, axis) % 2) for axis in range(3))
    return votes >= 2


def mesh_depth(samples: np.ndarray, corners: np.ndarray) -> float:
    """The deepest of the points `samples` inside the closed mesh `corners` (m), 0 if none
    is; only the points inside the mesh's box are looked at."""
    lo, hi = corners.min(axis=(0, 1)), corners.max(axis=(0, 1))
    near = samples[np.all((samples >= lo) & (samples <= hi), axis=1)]
    inner = near[inside_mesh(near, corners)] if len(near) else near
    deepest = 0.0
    for start in range(0, len(inner), 512):
        deepest = max(deepest, float(triangle_distance(inner[start:start + 512], corners).max()))
    return deepest


def transform(matrix: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Points p (k, 3) by a USD (row-vector) 4x4 matrix."""
    return p @ matrix[:3, :3] + matrix[3, :3]


def segments_through_mesh(segments: np.ndarray, points: np.ndarray, triangles: np.ndarray,
                          chunk: int = 256) -> int:
    """How many (segment, triangle) pairs cross, segments (k, 2, 3); boxes first."""
    corners = points[triangles]
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    seg_lo, seg_hi = segments.min(axis=1), segments.max(axis=1)
    count = 0
    for start in range(0, len(segments), chunk):
        near = np.all((lo[None] <= seg_hi[start:start + chunk, None]) & (seg_lo[start:start + chunk, None] <= hi[None]),
                      axis=2)
        k, t = np.nonzero(near)
        if len(k) == 0:
            continue
        p, q = segments[start + k, 0], segments[start + k, 1]
        count += int(segments_through(p, q, corners[t], np.linalg.norm(q - p, axis=1)).sum())
    return count


def render_ready_failures(scene, cache) -> tuple[dict, dict]:
    """Every check above on a baked cache of `scene`, at every frame: the crossing triangle
    pairs by (cloth, frame), and the other checks' failures by check name (strain, inside,
    through, mesh_through), each a dict keyed by (cloth[, body], frame)."""
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(str(cache))
    frames = range(scene.start_frame, scene.end_frame + 1)
    # the bodies' poses at every frame; a mesh body's triangles and edges, in its own frame,
    # as the cache writes them
    bodies = [b for b in scene.bodies if b.shape.kind in ("box", "sphere", "mesh")]
    poses = {b.name: [np.array(UsdGeom.Xformable(stage.GetPrimAtPath(f"/World/{b.name}"))
                               .ComputeLocalToWorldTransform(f)) for f in frames] for b in bodies}
    meshes = {}
    for b in bodies:
        if b.shape.kind == "mesh":
            body_mesh = UsdGeom.Mesh(stage.GetPrimAtPath(f"/World/{b.name}/{b.name}"))
            body_points = np.asarray(body_mesh.GetPointsAttr().Get(), dtype=np.float64)
            body_triangles = np.asarray(body_mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
            meshes[b.name] = (body_points, body_triangles, body_points[mesh_edges(body_triangles)])
    crossings, strains, inside, through, mesh_through = {}, {}, {}, {}, {}
    for cloth in scene.cloths:
        mesh = UsdGeom.Mesh(stage.GetPrimAtPath(f"/World/{cloth.name}"))
        triangles = np.asarray(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
        edges = mesh_edges(triangles)
        first = np.asarray(mesh.GetPointsAttr().Get(scene.start_frame), dtype=np.float64)
        rest = np.linalg.norm(first[edges[:, 1]] - first[edges[:, 0]], axis=1)
        for i, frame in enumerate(frames):
            points = np.asarray(mesh.GetPointsAttr().Get(frame), dtype=np.float64)
            # layers through layers
            count = crossing_count(points, triangles)
            if count:
                crossings[(cloth.name, frame)] = count
            # strain within the limit
            strain = largest_strain(points, edges, rest)
            if cloth.strain_limit > 0 and strain > cloth.strain_limit * (1 + STRAIN_SLACK):
                strains[(cloth.name, frame)] = round(strain, 5)
            samples = edge_samples(points, edges)
            # cloth edges under the ground (the plane y = height)
            if scene.ground is not None:
                depth = scene.ground.height - samples[:, 1].min()
                if depth > DEEPEST_INSIDE:
                    inside[(cloth.name, "ground", frame)] = round(1000 * depth, 2)
            for body in bodies:
                matrix = poses[body.name][i]
                # cloth edges inside the body
                local = transform(np.linalg.inv(matrix), samples)
                if body.name in meshes:
                    body_points, body_triangles, body_edges = meshes[body.name]
                    depth = mesh_depth(local, body_points[body_triangles])
                else:
                    depth = -analytic_distance(body.shape, local).min()
                if depth > DEEPEST_INSIDE:
                    inside[(cloth.name, body.name, frame)] = round(1000 * depth, 2)
                # the body's edges through the cloth
                if body.name in meshes:
                    segments = meshes[body.name][2]
                elif body.shape.kind == "box":
                    segments = box_edges(body.shape.size)
                else:
                    continue
                segments = transform(matrix, segments.reshape(-1, 3)).reshape(-1, 2, 3)
                count = segments_through_mesh(segments, points, triangles)
                if count:
                    (mesh_through if body.name in meshes else through)[(cloth.name, body.name, frame)] = count
    return crossings, {"strain": strains, "inside": inside, "through": through, "mesh_through": mesh_through}
