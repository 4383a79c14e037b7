"""The peer benchmark's mesh measures (benchmarks/peers/scenes.py): the mesh pile's penetration
is read from every engine's poses by this code against the true meshes, so it is checked here
against analytic answers (overlapping sphere meshes, boxes), brute force, and the pipeline's
own scene loader and mass properties."""

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from benchmarks.peers import scenes

ROOT = Path(__file__).resolve().parents[2]


def _generate():
    spec = importlib.util.spec_from_file_location("generate_meshes", ROOT / "assets" / "meshes" / "generate.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _box(size):
    h = np.asarray(size, float) / 2
    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) * h
    # outward-wound triangles of the 8 corners (index = 4 (x > 0) + 2 (y > 0) + (z > 0))
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    t = np.array([tri for a, b, c, d in quads for tri in ((a, b, c), (a, c, d))])
    return v, t


def _pair(probe_a, probe_b, offset, Rb=np.eye(3)):
    return float(scenes.pair_penetration(probe_a, probe_b, np.eye(3)[None], np.zeros((1, 3)),
                                         np.asarray(Rb, float)[None], np.asarray(offset, float)[None])[0])


def test_box_mesh_depth_is_the_distance_to_the_nearest_face():
    v, t = _box((1.0, 0.6, 0.4))
    assert scenes.mass_properties(v, t)[0] == pytest.approx(0.24)
    probe = scenes.MeshProbe(v, t)
    rng = np.random.default_rng(0)
    p = rng.uniform(-0.7, 0.7, (5000, 3)) * [1.0, 0.6, 0.4]
    h = np.array([0.5, 0.3, 0.2])
    inside = (np.abs(p) < h).all(1)
    expected = np.where(inside, (h - np.abs(p)).min(1), 0.0)
    assert np.abs(probe.depth(p) - expected).max() < 1e-12


def test_overlapping_boxes_by_a_known_depth():
    v, t = _box((1.0, 1.0, 1.0))
    probe = scenes.MeshProbe(v, t)
    for d in (0.003, 0.02, 0.1):
        assert _pair(probe, probe, (1.0 - d, 0.0, 0.0)) == pytest.approx(d, abs=1e-12)
    assert _pair(probe, probe, (1.001, 0.0, 0.0)) == 0.0
    # a cube turned 45 degrees about y, its edge 1.1 from the other's centre: the edge is
    # 0.5 + sqrt(1/2) - 1.1 deep in the face (sampled exactly: the edge holds vertices)
    c, s = math.cos(math.pi / 4), math.sin(math.pi / 4)
    turned = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
    assert _pair(probe, probe, (1.1, 0.0, 0.0), turned) == pytest.approx(0.5 + math.sqrt(0.5) - 1.1, abs=1e-9)


def test_two_unit_sphere_meshes_overlapping_by_a_known_depth():
    """Unit spheres (cube-sphere meshes, vertices on the sphere) whose spheres overlap by d:
    the meshes' overlap is d less at most twice the tessellation's sagitta (how far a face
    lies inside the sphere), and never more than d."""
    v, t = _generate().cube_sphere(1.0, 16)
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    n = np.cross(b - a, c - a)
    sagitta = 1.0 - float(np.abs((a * n).sum(1) / np.linalg.norm(n, axis=1)).min())
    assert 0.0 < sagitta < 0.01
    probe = scenes.MeshProbe(v, t, spacing=0.01, cell=0.1)
    rng = np.random.default_rng(1)
    for d in (0.01, 0.03, 0.1):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        measured = _pair(probe, probe, (2.0 - d) * axis)
        assert d - 2.0 * sagitta - 1e-9 <= measured <= d + 1e-9, (d, measured, sagitta)
    assert _pair(probe, probe, (2.001, 0.0, 0.0)) == 0.0


def test_clustered_culling_matches_every_sample():
    shape = scenes.mesh_shape("assets/meshes/torus.obj")
    probe = scenes.mesh_probe("assets/meshes/torus.obj")
    other = scenes.mesh_probe("assets/meshes/lshape.obj")
    rng = np.random.default_rng(2)
    q = rng.normal(size=(12, 4))
    R = scenes.quaternion_matrices(q)
    offset = rng.normal(size=(12, 3))
    offset *= (rng.uniform(0.25, 0.6, 12) / np.linalg.norm(offset, axis=1))[:, None]
    fast = scenes.pair_penetration(probe, other, np.broadcast_to(np.eye(3), (12, 3, 3)), np.zeros((12, 3)), R, offset)
    for k in range(12):
        a_in_b = (probe.samples - offset[k]) @ R[k]
        b_in_a = other.samples @ R[k].T + offset[k]
        assert fast[k] == pytest.approx(max(other.depth(a_in_b).max(), probe.depth(b_in_a).max()), abs=1e-12)
    assert shape.radius == pytest.approx(0.4, abs=1e-5)


def test_exact_pieces_of_the_shipped_meshes():
    torus = scenes.mesh_shape("assets/meshes/torus.obj")
    assert len(torus.pieces) == 32 and all(len(p) == 32 for p in torus.pieces)
    lshape = scenes.mesh_shape("assets/meshes/lshape.obj")
    boxes = [np.ptp(p, axis=0) for p in lshape.pieces]
    assert sum(float(np.prod(b)) for b in boxes) == pytest.approx(lshape.volume, rel=1e-9)
    assert len(scenes.mesh_shape("assets/meshes/sphere.obj").pieces) == 1


def test_mass_properties_match_the_core():
    core = pytest.importorskip("simbake._core")
    for name in ("torus", "lshape", "sphere"):
        shape = scenes.mesh_shape(f"assets/meshes/{name}.obj")
        props = core.mass_properties(shape.vertices, shape.triangles.astype(np.int32))
        assert shape.volume == pytest.approx(props["volume"], rel=1e-12)
        assert np.allclose(shape.centre, props["center"], atol=1e-12)
        assert np.allclose(shape.inertia, props["inertia"], atol=1e-12)
        # principal frame: a rotation that diagonalizes the inertia
        assert np.allclose(shape.axes.T @ shape.inertia @ shape.axes, np.diag(shape.moments), atol=1e-12)
        assert np.linalg.det(shape.axes) == pytest.approx(1.0)


def test_mesh_pile_is_the_pipelines_scene():
    pytest.importorskip("simbake")
    from simbake import load_scene

    scene = scenes.build("pile_meshes")
    sim = load_scene(ROOT / scenes.MESH_PILE)
    assert len(scene.bodies) == len(sim.bodies) == 200
    assert scene.frames == sim.end_frame - sim.start_frame == 144
    assert scene.mu == math.sqrt(sim.bodies[0].friction * sim.ground.friction) == 0.5 and scene.e == 0.0
    for ours, theirs in zip(scene.bodies, sim.bodies):
        assert ROOT / ours.mesh == theirs.shape.mesh_path
        assert ours.position == theirs.position and ours.orientation == theirs.orientation   # bit for bit
        assert ours.angular_velocity == theirs.angular_velocity and ours.density == theirs.density == 700.0
    # principal poses and back give the meshes' origins
    com, q = map(np.array, zip(*[scenes.principal_pose(b) for b in scene.bodies]))
    origin, turn = scenes.mesh_origin_poses(scene, com, q)
    assert np.allclose(origin, [b.position for b in scene.bodies], atol=1e-12)
    signs = np.sign((turn * np.array([b.orientation for b in scene.bodies])).sum(1))[:, None]
    assert np.allclose(turn * signs, [b.orientation for b in scene.bodies], atol=1e-12)


def test_a_resting_pile_measures_zero_and_a_sunk_body_its_depth():
    scene = scenes.build("pile_meshes", 2 / scenes.FPS)
    scene.bodies = scene.bodies[:3]              # torus, L, sphere side by side, 0.6 m up
    p = np.array([b.position for b in scene.bodies])
    q = np.array([b.orientation for b in scene.bodies])
    P, Q = np.stack([p, p, p]), np.stack([q, q, q])
    out = scenes.mesh_penetration(scene, P, Q)
    assert out["penetration_bodies_mm"] == 0.0 and out["penetration_ground_mm"] == 0.0
    # lower the sphere (r 0.2, vertices on it) to 0.15 m: 0.05 m of it below the ground
    P[-1, 2, 1] = 0.15
    out = scenes.mesh_penetration(scene, P, Q)
    lowest = 0.15 + (scenes.quaternion_matrices(q[2]) @ scenes.mesh_shape(scene.bodies[2].mesh).vertices.T)[1].min()
    assert out["penetration_ground_mm"] == pytest.approx(-1000.0 * lowest, abs=1e-9)
    assert 45.0 < out["penetration_ground_mm"] <= 50.0 + 1e-9   # vertices on the sphere, not at its bottom
