"""Layers through layers, counted apart from any solver: pairs of non-adjacent triangles of one
mesh that cross, with NumPy alone (every engine's venv has it), so that simbake's cloth and
the peers' are counted by the same code (benchmarks/cloth) and the render-ready test
(tests/python/test_cloth_render_ready.py) checks simbake's caches with it.

Candidates: triangles whose bounding boxes overlap, found through a grid of cells as large as
the largest triangle's box (each triangle enters the at most 8 cells its box touches).
Predicate: an edge of one triangle crosses the other, where the edge meets the triangle's
plane and that point's barycentric coordinates, instead of signed volumes. A crossing counts
when the edge's two ends lie on opposite sides of the plane by more than round-off (ROUND_OFF
of the longest edge of the pair) and the crossing point lies inside the triangle by as much.
"""

from __future__ import annotations

import numpy as np

ROUND_OFF = 1e-9


def _pairs_within_groups(keys_sorted: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs (a, b), a < b, of equal neighbouring keys in a sorted array."""
    n = len(keys_sorted)
    ends = np.searchsorted(keys_sorted, keys_sorted, side="right")
    counts = ends - np.arange(n) - 1
    first = np.repeat(np.arange(n), counts)
    offsets = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    return first, first + 1 + offsets


def candidate_pairs(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Pairs (i, j), i < j, of triangles whose boxes overlap and that share no vertex."""
    corners = points[triangles]                      # (m, 3, 3)
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    if len(triangles) < 2:
        return np.zeros((0, 2), dtype=np.int64)
    cell = max(float((hi - lo).max()), 1e-12)
    first_cell = np.floor((lo - lo.min(axis=0)) / cell).astype(np.int64)
    last_cell = np.floor((hi - lo.min(axis=0)) / cell).astype(np.int64)   # at most one cell on
    span = last_cell.max(axis=0) + 2
    entries_t, entries_k = [], []
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                c = first_cell + np.array([dx, dy, dz])
                keep = np.all(c <= last_cell, axis=1)
                entries_t.append(np.nonzero(keep)[0])
                entries_k.append(((c[keep, 0] * span[1] + c[keep, 1]) * span[2] + c[keep, 2]))
    t, k = np.concatenate(entries_t), np.concatenate(entries_k)
    order = np.lexsort((t, k))
    t, k = t[order], k[order]
    a, b = _pairs_within_groups(k)
    i, j = np.minimum(t[a], t[b]), np.maximum(t[a], t[b])
    unique = np.unique(i.astype(np.int64) * len(triangles) + j)
    i, j = unique // len(triangles), unique % len(triangles)
    overlap = np.all((lo[i] <= hi[j]) & (lo[j] <= hi[i]), axis=1)
    i, j = i[overlap], j[overlap]
    shared = (triangles[i][:, :, None] == triangles[j][:, None, :]).any(axis=(1, 2))
    return np.stack([i, j], axis=1)[~shared]


def segments_through(p: np.ndarray, q: np.ndarray, B: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Does segment (p[k], q[k]) cross triangle B[k] (corners (k, 3, 3))? Strictly: its ends on
    opposite sides of the plane by more than ROUND_OFF * scale[k], the crossing point inside
    the triangle by as much (barycentric coordinates)."""
    n = np.cross(B[:, 1] - B[:, 0], B[:, 2] - B[:, 0])
    n_len = np.linalg.norm(n, axis=1)
    dp = np.einsum("ij,ij->i", n, p - B[:, 0]) / np.where(n_len > 0, n_len, 1)
    dq = np.einsum("ij,ij->i", n, q - B[:, 0]) / np.where(n_len > 0, n_len, 1)
    tol = ROUND_OFF * scale
    crosses = ((dp > tol) & (dq < -tol)) | ((dp < -tol) & (dq > tol))
    x = p + (q - p) * (dp / np.where(dp != dq, dp - dq, 1))[:, None]
    v0, v1, v2 = B[:, 1] - B[:, 0], B[:, 2] - B[:, 0], x - B[:, 0]
    d00, d01, d11 = (v0 * v0).sum(1), (v0 * v1).sum(1), (v1 * v1).sum(1)
    d20, d21 = (v2 * v0).sum(1), (v2 * v1).sum(1)
    den = np.where(d00 * d11 - d01 * d01 != 0, d00 * d11 - d01 * d01, 1)
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    inside = (v > ROUND_OFF) & (w > ROUND_OFF) & (v + w < 1 - ROUND_OFF)
    return crosses & inside & (n_len > 0)


def edges_through(points: np.ndarray, triangles: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """For pairs (a[k], b[k]) of triangles: does an edge of triangle a cross triangle b?"""
    A, B = points[triangles[a]], points[triangles[b]]  # (k, 3, 3)
    edge = np.max(np.linalg.norm(np.concatenate([A - np.roll(A, 1, axis=1), B - np.roll(B, 1, axis=1)], axis=1),
                                 axis=2), axis=1)
    hit = np.zeros(len(a), dtype=bool)
    for e in range(3):
        hit |= segments_through(A[:, e], A[:, (e + 1) % 3], B, edge)
    return hit


def crossing_count(points: np.ndarray, triangles: np.ndarray, chunk: int = 500_000) -> int:
    """How many pairs of non-adjacent triangles cross (in chunks of pairs, to bound memory)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    triangles = np.asarray(triangles, dtype=np.int64)
    pairs = candidate_pairs(points, triangles)
    count = 0
    for start in range(0, len(pairs), chunk):
        i, j = pairs[start:start + chunk, 0], pairs[start:start + chunk, 1]
        count += int((edges_through(points, triangles, i, j) | edges_through(points, triangles, j, i)).sum())
    return count
