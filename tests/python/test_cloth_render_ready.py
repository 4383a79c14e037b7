"""Every shipped cloth scene, baked and read back from its cache: no layer through another.

At every written frame the cloth's triangles are checked against each other with a test
written here, apart from the core (its own candidate search, a sweep along x over the
triangles' boxes, and its own predicate: where an edge crosses a triangle's plane, and that
point's barycentric coordinates, instead of the core's signed volumes). A crossing counts
when the edge's two ends lie on opposite sides of the plane by more than round-off (1e-9 of
the longest edge of the pair) and the crossing point lies inside the triangle by as much.

The scenes are baked for their first 2 s (49 frames at 24 fps): the drops, impacts and folds
all happen there, and the whole set then bakes in a few minutes on this machine class.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import simbake
from conftest import REPO

CLOTH_SCENES = ["drape", "flag", "tablecloth", "cape_on_mover", "cloth_demo", "heap", "towel_on_rod"]
FRAMES = 49
ROUND_OFF = 1e-9


def candidate_pairs(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Pairs (i, j), i < j, of triangles whose boxes overlap and that share no vertex."""
    corners = points[triangles]                      # (m, 3, 3)
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    order = np.argsort(lo[:, 0], kind="stable")
    lo_sorted = lo[order, 0]
    # for each triangle, the triangles after it (in x order) whose x-range starts before its end
    ends = np.searchsorted(lo_sorted, hi[order, 0], side="right")
    counts = ends - np.arange(len(order)) - 1
    first = np.repeat(np.arange(len(order)), counts)
    offsets = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    second = first + 1 + offsets
    i, j = order[first], order[second]
    overlap = np.all((lo[i] <= hi[j]) & (lo[j] <= hi[i]), axis=1)
    i, j = i[overlap], j[overlap]
    shared = (triangles[i][:, :, None] == triangles[j][:, None, :]).any(axis=(1, 2))
    pairs = np.stack([np.minimum(i, j), np.maximum(i, j)], axis=1)[~shared]
    return pairs


def edges_through(points: np.ndarray, triangles: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """For pairs (a[k], b[k]) of triangles: does an edge of triangle a cross triangle b?"""
    A, B = points[triangles[a]], points[triangles[b]]  # (k, 3, 3)
    edge = np.max(np.linalg.norm(np.concatenate([A - np.roll(A, 1, axis=1), B - np.roll(B, 1, axis=1)], axis=1),
                                 axis=2), axis=1)
    n = np.cross(B[:, 1] - B[:, 0], B[:, 2] - B[:, 0])
    n_len = np.linalg.norm(n, axis=1)
    hit = np.zeros(len(a), dtype=bool)
    for e in range(3):
        p, q = A[:, e], A[:, (e + 1) % 3]
        dp = np.einsum("ij,ij->i", n, p - B[:, 0]) / np.where(n_len > 0, n_len, 1)
        dq = np.einsum("ij,ij->i", n, q - B[:, 0]) / np.where(n_len > 0, n_len, 1)
        tol = ROUND_OFF * edge
        crosses = ((dp > tol) & (dq < -tol)) | ((dp < -tol) & (dq > tol))
        x = p + (q - p) * (dp / np.where(dp != dq, dp - dq, 1))[:, None]
        v0, v1, v2 = B[:, 1] - B[:, 0], B[:, 2] - B[:, 0], x - B[:, 0]
        d00, d01, d11 = (v0 * v0).sum(1), (v0 * v1).sum(1), (v1 * v1).sum(1)
        d20, d21 = (v2 * v0).sum(1), (v2 * v1).sum(1)
        den = np.where(d00 * d11 - d01 * d01 != 0, d00 * d11 - d01 * d01, 1)
        v = (d11 * d20 - d01 * d21) / den
        w = (d00 * d21 - d01 * d20) / den
        inside = (v > ROUND_OFF) & (w > ROUND_OFF) & (v + w < 1 - ROUND_OFF)
        hit |= crosses & inside & (n_len > 0)
    return hit


def crossing_count(points: np.ndarray, triangles: np.ndarray) -> int:
    pairs = candidate_pairs(points, triangles)
    if len(pairs) == 0:
        return 0
    i, j = pairs[:, 0], pairs[:, 1]
    return int((edges_through(points, triangles, i, j) | edges_through(points, triangles, j, i)).sum())


def test_the_check_finds_crossings():
    # a flat grid and the same grid with its far half folded back through the near half
    from simbake.assets import grid_mesh

    points, triangles = grid_mesh((1.0, 1.0), (11, 11))
    assert crossing_count(points, triangles) == 0
    folded = points.copy()
    far = folded[:, 2] > 0.05
    folded[far, 1] = 0.3 * folded[far, 2] * np.sin(7 * folded[far, 0])
    folded[far, 2] = -folded[far, 2] + 0.1 * np.cos(5 * folded[far, 0])
    count = crossing_count(folded, triangles)
    assert count > 10
    from simbake import _core

    assert count == len(_core.intersecting_triangle_pairs(folded, triangles.astype(np.int32)))


@pytest.mark.parametrize("name", CLOTH_SCENES)
def test_shipped_cloth_never_passes_through_itself(name, tmp_path):
    from pxr import Usd, UsdGeom

    scene = simbake.load_scene(REPO / "assets" / "scenes" / f"{name}.toml")
    scene = dataclasses.replace(scene, end_frame=min(scene.end_frame, scene.start_frame + FRAMES - 1))
    stats = simbake.bake(scene, tmp_path / f"{name}.usdc")
    stage = Usd.Stage.Open(str(stats.output))
    worst = {}
    for cloth in scene.cloths:
        mesh = UsdGeom.Mesh(stage.GetPrimAtPath(f"/World/{cloth.name}"))
        triangles = np.asarray(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
        for frame in range(scene.start_frame, scene.end_frame + 1):
            points = np.asarray(mesh.GetPointsAttr().Get(frame), dtype=np.float64)
            count = crossing_count(points, triangles)
            if count:
                worst[(cloth.name, frame)] = count
    assert not worst, f"crossing triangle pairs at (cloth, frame): {worst}"
