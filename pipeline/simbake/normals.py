"""Normals that render hard edges hard: per triangle corner ("faceVarying"), split at creases.

A corner's normal is the area-weighted average of the normals of the triangles around its
vertex that turn less than ``CREASE_ANGLE_DEGREES`` from its own triangle: a box's faces
meet at 90 degrees and keep their own flat normals (a corner no longer gets
(-0.577, 0.577, -0.577), and a box's 3x3-per-face grid no longer shades across a third of
each face), while a tessellated sphere, capsule or torus (neighbours a few tens of degrees
apart at most) stays smooth. 45 degrees sits between the two: flat faces meeting at 90
degrees (boxes, tables, brackets) are hard, curved surfaces tessellated with 8 or more
segments per quarter turn are smooth.
"""

from __future__ import annotations

import math

import numpy as np

CREASE_ANGLE_DEGREES = 45.0


def corner_normals(vertices: np.ndarray, triangles: np.ndarray,
                   crease_angle: float = CREASE_ANGLE_DEGREES) -> np.ndarray:
    """(3 * triangles, 3) unit normals, one per triangle corner in face-vertex order."""
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    area_normal = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])  # 2 x area x unit
    length = np.linalg.norm(area_normal, axis=1, keepdims=True)
    unit = np.divide(area_normal, length, out=np.zeros_like(area_normal), where=length > 0)

    # corners grouped by vertex; every pair of corners sharing a vertex, both directions
    corner_vertex = t.reshape(-1)
    corner_face = np.repeat(np.arange(len(t)), 3)
    order = np.argsort(corner_vertex, kind="stable")
    counts = np.bincount(corner_vertex, minlength=len(v))
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    degree = counts[corner_vertex[order]]  # per sorted corner: how many corners share its vertex
    first = starts[corner_vertex[order]]
    a = np.repeat(np.arange(len(order)), degree)  # sorted corner
    b = first[a] + (np.arange(len(a)) - np.repeat(np.cumsum(degree) - degree, degree))  # its partners
    fa, fb = corner_face[order[a]], corner_face[order[b]]
    keep = np.einsum("ij,ij->i", unit[fa], unit[fb]) >= math.cos(math.radians(crease_angle)) - 1e-12
    normals = np.zeros((len(order), 3))
    np.add.at(normals, order[a[keep]], area_normal[fb[keep]])
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)
    degenerate = length[:, 0] == 0
    normals[degenerate] = unit[corner_face[degenerate]]
    return normals
