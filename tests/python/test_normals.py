"""Hard edges render hard: bodies' normals per face vertex, split at creases (simbake.normals)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from simbake import _core
from simbake.normals import CREASE_ANGLE_DEGREES, corner_normals


def _face_normals(v, t):
    n = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def test_a_box_keeps_its_flat_face_normals():
    v, t = _core.box_mesh(np.array([1.0, 2.0, 0.5]), 3)
    n = corner_normals(v, t)
    assert n.shape == (t.size, 3)
    # every corner carries its own (axis-aligned) face's normal exactly: no blend at edges
    np.testing.assert_allclose(n, np.repeat(_face_normals(v, t), 3, axis=0), atol=1e-12)


def test_a_sphere_stays_smooth():
    v, t = _core.sphere_mesh(1.0, 8)
    n = corner_normals(v, t)
    exact = v[t.reshape(-1)] / np.linalg.norm(v[t.reshape(-1)], axis=1, keepdims=True)
    # corners at one vertex share one normal, within 2.1 degrees of the true sphere's
    # (the cube-projected sphere's own faceting at 8 subdivisions)
    assert np.degrees(np.arccos(np.clip((n * exact).sum(axis=1), -1, 1))).max() < 2.1
    for vertex in (0, 17, 100):
        at = n[t.reshape(-1) == vertex]
        np.testing.assert_allclose(at, np.broadcast_to(at[0], at.shape), atol=1e-12)


@pytest.mark.parametrize("angle, hard", [(CREASE_ANGLE_DEGREES - 1, False), (CREASE_ANGLE_DEGREES + 1, True)])
def test_the_crease_angle_decides(angle, hard):
    """Two triangles folded along the x axis by `angle`: shared corners split only past the threshold."""
    a = math.radians(angle)
    v = np.array([[0, 0, 0], [1, 0, 0], [0.5, 0, -1], [0.5, math.sin(a), math.cos(a)]], dtype=np.float64)
    t = np.array([[0, 1, 2], [1, 0, 3]])
    n = corner_normals(v, t)
    faces = _face_normals(v, t)
    shared_first, shared_second = n[0], n[4]  # vertex 0 in each triangle
    if hard:
        np.testing.assert_allclose(shared_first, faces[0], atol=1e-12)
        np.testing.assert_allclose(shared_second, faces[1], atol=1e-12)
    else:
        np.testing.assert_allclose(shared_first, shared_second, atol=1e-12)


def test_toml_caches_author_face_varying_normals(tmp_path):
    from pxr import Usd, UsdGeom

    import simbake

    scene_file = tmp_path / "box.toml"
    scene_file.write_text('[scene]\nend_frame = 2\n\n[[bodies]]\nname = "crate"\n'
                          'shape = { type = "box", size = [1.0, 1.0, 1.0] }\nposition = [0.0, 2.0, 0.0]\n')
    out = tmp_path / "box.usdc"
    simbake.bake(simbake.load_scene(scene_file), out, qa=False)
    stage = Usd.Stage.Open(str(out))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/crate/crate"))
    assert mesh.GetNormalsInterpolation() == UsdGeom.Tokens.faceVarying
    normals = np.array(mesh.GetNormalsAttr().Get())
    assert len(normals) == len(mesh.GetFaceVertexIndicesAttr().Get())
    assert np.abs(np.abs(normals).max(axis=1) - 1).max() < 1e-6  # all axis-aligned: flat faces
