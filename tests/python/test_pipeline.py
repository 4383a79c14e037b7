"""End to end through the Python API: scene file -> simbake.bake -> USD cache read back with pxr.

Every physical expectation here has a closed-form answer (a bounce apex, a body at rest, a
kinematic body's straight line, a free fall of the centre of mass), so a wrong number in the
core, a wrong pose convention in the driver or a wrong sample in the writer all show up.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest
from pxr import Sdf, Usd

import simbake
from simbake import _core

G = 9.81


# --------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------

def open_stage(path: Path) -> Usd.Stage:
    """The file as it is on disk now (never a layer cached in this process by an earlier bake)."""
    layer = Sdf.Layer.OpenAsAnonymous(str(path))
    assert layer is not None, f"{path} does not open as USD"
    return Usd.Stage.Open(layer)


def samples(stage: Usd.Stage, prim: str, attr: str = "xformOp:translate"):
    """(time codes, values as an (n, k) float array) of one attribute's time samples."""
    a = stage.GetPrimAtPath(f"/World/{prim}").GetAttribute(attr)
    assert a, f"/World/{prim}.{attr} is missing"
    times = a.GetTimeSamples()
    values = [a.Get(t) for t in times]
    if attr == "xformOp:orient":
        rows = [[q.GetReal(), *q.GetImaginary()] for q in values]
    else:
        rows = [list(v) for v in values]
    return np.asarray(times, dtype=float), np.asarray(rows, dtype=float).reshape(len(times), -1)


def value_at(stage: Usd.Stage, prim: str, attr: str, frame: float) -> np.ndarray:
    v = stage.GetPrimAtPath(f"/World/{prim}").GetAttribute(attr).Get(Usd.TimeCode(frame))
    if attr == "xformOp:orient":
        return np.array([v.GetReal(), *v.GetImaginary()])
    return np.array(list(v), dtype=float)


def quat_to_matrix(q) -> np.ndarray:
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def bake_file(scene_path: Path, out: Path):
    return simbake.bake(simbake.load_scene(scene_path), out)


def levelset_files(cache: Path) -> dict[str, float]:
    """name -> mtime (ns) of every cached grid."""
    d = cache / "levelsets"
    if not d.is_dir():
        return {}
    return {p.name: p.stat().st_mtime_ns for p in d.iterdir()}


def write_offset_lshape(meshes, tmp_path: Path, offset) -> Path:
    """A copy of lshape.obj whose vertices are moved by `offset` (the mesh origin then lies
    far from the centre of mass, which is where the driver's pose bookkeeping can go wrong)."""
    out = []
    for line in meshes["lshape"].read_text().splitlines():
        if line.startswith("v "):
            x, y, z = (float(c) for c in line.split()[1:4])
            out.append(f"v {x + offset[0]:.6f} {y + offset[1]:.6f} {z + offset[2]:.6f}")
        else:
            out.append(line)
    path = tmp_path / "lshape_offset.obj"
    path.write_text("\n".join(out) + "\n")
    return path


# --------------------------------------------------------------------------------------------
# frames, samples and stage timing
# --------------------------------------------------------------------------------------------

def test_bake_stats_and_one_sample_per_frame(write_scene, tmp_path):
    scene_path = write_scene("""
        [scene]
        fps = 30
        start_frame = 5
        end_frame = 20
        [ground]
        [[bodies]]
        name = "ball"
        shape = { type = "sphere", radius = 0.2 }
        position = [0.0, 1.0, 0.0]
        [[bodies]]
        name = "crate"
        shape = { type = "box", size = [0.3, 0.3, 0.3] }
        position = [1.0, 0.5, 0.0]
        angular_velocity = [0.0, 2.0, 0.0]
        [[bodies]]
        name = "pedestal"
        shape = { type = "box", size = [0.5, 0.5, 0.5] }
        position = [-1.0, 0.25, 0.0]
        kinematic = true
    """)
    scene = simbake.load_scene(scene_path)
    out = tmp_path / "out.usdc"
    stats = simbake.bake(scene, out)

    assert stats.frames == 20 - 5 + 1
    assert out.is_file()
    stage = open_stage(out)
    expected = np.arange(5, 21, dtype=float)
    for name in ("ball", "crate"):
        for attr in ("xformOp:translate", "xformOp:orient"):
            times, _ = samples(stage, name, attr)
            assert np.array_equal(times, expected), (name, attr, times)
    # a kinematic body that never moves is written once (a default), not per frame
    pedestal = stage.GetPrimAtPath("/World/pedestal").GetAttribute("xformOp:translate")
    assert pedestal.GetNumTimeSamples() == 0
    assert np.allclose(list(pedestal.Get()), [-1.0, 0.25, 0.0], atol=1e-12)


def test_initial_state_and_time_codes(write_scene, tmp_path):
    scene_path = write_scene("""
        [scene]
        fps = 30
        start_frame = 7
        end_frame = 16
        [[bodies]]
        name = "ball"
        shape = { type = "sphere", radius = 0.1 }
        position = [0.25, 2.0, -0.5]
        orientation = [0.8, 0.0, 0.6, 0.0]
        linear_velocity = [1.0, 0.0, 0.0]
    """)
    out = tmp_path / "out.usda"
    bake_file(scene_path, out)
    stage = open_stage(out)
    layer = stage.GetRootLayer()

    # the initial state is the sample at start_frame, untouched by any step
    assert np.allclose(value_at(stage, "ball", "xformOp:translate", 7), [0.25, 2.0, -0.5], atol=1e-12)
    assert np.allclose(value_at(stage, "ball", "xformOp:orient", 7), [0.8, 0.0, 0.6, 0.0], atol=1e-12)
    # the time codes span exactly start..end
    times, values = samples(stage, "ball")
    assert times[0] == 7 and times[-1] == 16 and len(times) == 10
    assert layer.startTimeCode == 7 and layer.endTimeCode == 16
    # both rates equal the scene fps (a viewer plays at the wrong speed otherwise)
    assert layer.timeCodesPerSecond == 30 and layer.framesPerSecond == 30
    # and frames really are 1/fps apart: x moves at 1 m/s with nothing in the way
    assert np.allclose(np.diff(values[:, 0]), 1.0 / 30, rtol=0, atol=1e-9)


# --------------------------------------------------------------------------------------------
# determinism and the level-set cache
# --------------------------------------------------------------------------------------------

MIXED_SCENE = """
    [scene]
    fps = 24
    end_frame = 16
    [ground]
    restitution = 0.2
    [[bodies]]
    name = "ring"
    mesh = "torus.obj"
    position = [0.0, 0.8, 0.0]
    orientation = [0.9238795, 0.3826834, 0.0, 0.0]
    angular_velocity = [1.0, 0.0, 2.0]
    [[bodies]]
    name = "ball"
    shape = { type = "sphere", radius = 0.15 }
    position = [0.6, 0.4, 0.0]
    linear_velocity = [-1.0, 0.0, 0.0]
    restitution = 0.5
    [[bodies]]
    name = "crate"
    shape = { type = "box", size = [0.3, 0.3, 0.3] }
    position = [-0.6, 0.6, 0.0]
    angular_velocity = [0.0, 0.0, 3.0]
    [[bodies]]
    name = "pedestal"
    shape = { type = "box", size = [0.6, 0.2, 0.6] }
    position = [0.0, 0.1, 0.0]
    kinematic = true
"""


def test_bake_is_deterministic(write_scene, meshes, tmp_path, simbake_cache_dir):
    scene_path = write_scene(MIXED_SCENE)
    # the same name in two folders: the cache refers to its level sets as ./cache.vdb/...
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    a, b = tmp_path / "a" / "cache.usdc", tmp_path / "b" / "cache.usdc"
    bake_file(scene_path, a)       # cold: the torus grid is baked in memory
    assert levelset_files(simbake_cache_dir), "the torus grid should have been cached"
    bake_file(scene_path, b)       # warm: the torus grid is read back from the .vdb
    # identical bytes: no timestamps, no temp names, and a grid read from the cache is the
    # same grid that was baked (otherwise the ring's trajectory would differ)
    assert a.read_bytes() == b.read_bytes()
    # and the bodies did something (an empty or static cache is trivially deterministic)
    stage = open_stage(a)
    _, ring = samples(stage, "ring")
    assert np.abs(ring[-1] - ring[0]).max() > 0.05


LEVELSET_SCENE = """
    [scene]
    fps = 24
    end_frame = 2
    [ground]
    [[bodies]]
    name = "ring"
    mesh = "torus.obj"
    position = [0.0, 0.5, 0.0]
    voxel_size = {ring_voxel}
    [[bodies]]
    name = "bracket"
    mesh = "lshape.obj"
    position = [1.5, 0.5, 0.0]
"""


def test_levelset_cache_is_reused(write_scene, meshes, tmp_path, simbake_cache_dir):
    scene_path = write_scene(LEVELSET_SCENE.format(ring_voxel=0.0))
    bake_file(scene_path, tmp_path / "a.usdc")
    first = levelset_files(simbake_cache_dir)
    assert len(first) == 2 and all(n.endswith(".vdb") for n in first), first
    for name in first:  # each one a readable grid
        assert _core.LevelSet.read(str(simbake_cache_dir / "levelsets" / name)).active_voxel_count > 0

    bake_file(scene_path, tmp_path / "b.usdc")
    assert levelset_files(simbake_cache_dir) == first  # same files, none rewritten, none added

    # another voxel size for one body is another grid; the other body's grid is reused
    write_scene(LEVELSET_SCENE.format(ring_voxel=0.015))
    bake_file(scene_path, tmp_path / "c.usdc")
    third = levelset_files(simbake_cache_dir)
    assert len(third) == 3 and set(first) < set(third)
    assert all(third[n] == first[n] for n in first)


@pytest.mark.parametrize("damage", ["garbage", "truncated", "empty"])
def test_corrupt_levelset_cache_is_rebaked(write_scene, meshes, tmp_path, simbake_cache_dir, damage):
    scene_path = write_scene(LEVELSET_SCENE.format(ring_voxel=0.0))
    (tmp_path / "good").mkdir()
    (tmp_path / "again").mkdir()
    good = tmp_path / "good" / "cache.usdc"  # one name: the cache refers to ./cache.vdb/...
    bake_file(scene_path, good)
    files = sorted((simbake_cache_dir / "levelsets").iterdir())
    originals = {p: p.read_bytes() for p in files}
    for p, data in originals.items():
        if damage == "garbage":
            p.write_bytes(b"this is not a VDB file\n" * 100)
        elif damage == "truncated":
            p.write_bytes(data[: len(data) // 2])
        else:
            p.write_bytes(b"")

    again = tmp_path / "again" / "cache.usdc"
    bake_file(scene_path, again)
    # the damaged entries were baked again and replaced by readable grids, not trusted...
    for p in files:
        assert _core.LevelSet.read(str(p)).active_voxel_count > 0
    assert sorted((simbake_cache_dir / "levelsets").iterdir()) == files  # no strays or temps
    # ...and the bake is exactly what it was with a sound cache
    assert again.read_bytes() == good.read_bytes()


def test_no_grid_for_a_body_nothing_can_touch(write_scene, meshes, tmp_path, simbake_cache_dir):
    scene_path = write_scene("""
        [scene]
        fps = 24
        end_frame = 12
        [ground]
        [[bodies]]
        name = "ring"
        mesh = "torus.obj"
        position = [0.0, 0.3, 0.0]
    """)
    out = tmp_path / "out.usdc"
    bake_file(scene_path, out)
    assert out.is_file()
    assert levelset_files(simbake_cache_dir) == {}
    # it still lands on the ground (the ground test uses surface samples, not a grid):
    # the torus tube has radius 0.1, so its centre comes to rest near y = 0.1
    _, ring = samples(open_stage(out), "ring")
    assert ring[-1, 1] == pytest.approx(0.1, abs=0.01)


def test_no_grid_for_kinematic_bodies_alone(write_scene, meshes, tmp_path, simbake_cache_dir):
    scene_path = write_scene("""
        [scene]
        fps = 24
        end_frame = 3
        [ground]
        [[bodies]]
        name = "ring"
        mesh = "torus.obj"
        position = [0.0, 0.1, 0.0]
        kinematic = true
        [[bodies]]
        name = "bracket"
        mesh = "lshape.obj"
        position = [0.0, 0.3, 0.0]
        kinematic = true
    """)
    out = tmp_path / "out.usdc"
    bake_file(scene_path, out)
    assert out.is_file()
    assert levelset_files(simbake_cache_dir) == {}


# --------------------------------------------------------------------------------------------
# physics through the whole pipeline, read back from the USD
# --------------------------------------------------------------------------------------------

def test_bounce_apex_is_e_squared_times_drop_height(write_scene, tmp_path):
    e, r, h = 0.5, 0.1, 1.0
    scene_path = write_scene(f"""
        [scene]
        fps = 240
        start_frame = 1
        end_frame = 200
        [solver]
        substeps = 4
        [ground]
        friction = 0.0
        restitution = {e}
        [[bodies]]
        name = "ball"
        shape = {{ type = "sphere", radius = {r} }}
        position = [0.0, {r + h}, 0.0]
        friction = 0.0
        restitution = {e}
    """)
    out = tmp_path / "bounce.usdc"
    bake_file(scene_path, out)
    _, ball = samples(open_stage(out), "ball")
    bottom = ball[:, 1] - r
    impact = int(np.argmin(bottom))
    assert bottom[impact] < 0.02, "the ball never reached the ground"
    # 200 frames at 240 fps: 0.45 s of fall and 0.23 s of rise fit well inside
    apex = bottom[impact:].max()
    assert impact + 1 < len(bottom) - 1 and np.argmax(bottom[impact:]) + impact < len(bottom) - 1
    assert apex == pytest.approx(e * e * h, rel=0.05)
    # frictionless and dropped straight: no sideways drift
    assert np.abs(ball[:, [0, 2]]).max() < 1e-9


def test_box_at_rest_stays_put(write_scene, tmp_path):
    scene_path = write_scene("""
        [scene]
        fps = 24
        end_frame = 49
        [ground]
        friction = 0.5
        [[bodies]]
        name = "crate"
        shape = { type = "box", size = [0.4, 0.4, 0.4] }
        position = [0.3, 0.2, -0.1]
    """)
    out = tmp_path / "rest.usdc"
    bake_file(scene_path, out)  # 2 s after the first frame
    stage = open_stage(out)
    _, t = samples(stage, "crate")
    _, q = samples(stage, "crate", "xformOp:orient")
    assert len(t) == 49
    assert np.abs(t - [0.3, 0.2, -0.1]).max() < 1e-4
    # nor does it tip or turn: every orientation stays within ~1e-4 rad of identity
    assert np.abs(q[:, 1:]).max() < 5e-5


def test_kinematic_body_moves_exactly_v_t(write_scene, tmp_path):
    v = np.array([0.5, -0.25, 1.5])
    scene_path = write_scene(f"""
        [scene]
        fps = 24
        start_frame = 0
        end_frame = 24
        [[bodies]]
        name = "conveyor"
        shape = {{ type = "box", size = [1.0, 0.1, 0.4] }}
        position = [1.0, 2.0, 3.0]
        linear_velocity = [{v[0]}, {v[1]}, {v[2]}]
        kinematic = true
        [[bodies]]
        name = "ball"
        shape = {{ type = "sphere", radius = 0.1 }}
        position = [5.0, 5.0, 5.0]
    """)
    out = tmp_path / "kinematic.usdc"
    bake_file(scene_path, out)
    stage = open_stage(out)
    times, t = samples(stage, "conveyor")
    _, q = samples(stage, "conveyor", "xformOp:orient")
    assert len(times) == 25
    expected = np.array([1.0, 2.0, 3.0]) + np.outer(times / 24.0, v)  # no gravity on it
    assert np.abs(t - expected).max() < 1e-9
    assert np.abs(q - [1.0, 0.0, 0.0, 0.0]).max() < 1e-12


def test_pose_is_the_mesh_origin_not_the_centre_of_mass(write_scene, meshes, tmp_path):
    import trimesh

    offset = (0.5, 0.2, -0.3)
    mesh_path = write_offset_lshape(meshes, tmp_path, offset)
    position = np.array([0.3, 2.0, -0.2])
    orientation = np.array([0.5, 0.5, 0.5, 0.5])  # 120 degrees about (1, 1, 1)
    omega = np.array([1.0, 3.0, -2.0])
    scene_path = write_scene(f"""
        [scene]
        fps = 24
        start_frame = 3
        end_frame = 15
        [solver]
        substeps = 8
        [[bodies]]
        name = "bracket"
        mesh = "{mesh_path.name}"
        position = [{position[0]}, {position[1]}, {position[2]}]
        orientation = [{orientation[0]}, {orientation[1]}, {orientation[2]}, {orientation[3]}]
        angular_velocity = [{omega[0]}, {omega[1]}, {omega[2]}]
        linear_velocity = [0.5, 1.0, 0.0]
    """)
    out = tmp_path / "offset.usdc"
    bake_file(scene_path, out)
    stage = open_stage(out)
    times, t = samples(stage, "bracket")
    _, q = samples(stage, "bracket", "xformOp:orient")

    # frame start_frame is exactly the scene's pose of the mesh origin
    assert times[0] == 3
    assert np.abs(t[0] - position).max() < 1e-6
    assert np.abs(q[0] - orientation).max() < 1e-6

    # and every later pose puts the centre of mass on its ballistic path: the spin about an
    # off-centre origin must not drag the centre of mass around
    com_mesh = trimesh.load(str(mesh_path), force="mesh").center_mass
    com = np.array([ti + quat_to_matrix(qi) @ com_mesh for ti, qi in zip(t, q)])
    s = (times - times[0]) / 24.0
    c0 = position + quat_to_matrix(orientation) @ com_mesh
    ballistic = c0 + np.outer(s, [0.5, 1.0, 0.0]) + np.outer(0.5 * s * s, [0.0, -G, 0.0])
    dt = 1.0 / 24 / 8
    assert np.abs(com - ballistic).max() < G * s[-1] * dt  # the integrator's O(dt) drift at most
    # the origin itself is far from the centre of mass, so a driver that wrote the centre of
    # mass (or rotated about the origin) would be off by ~|offset| here
    assert np.linalg.norm(com_mesh) > 0.3


# --------------------------------------------------------------------------------------------
# what is not implemented yet is refused, cleanly
# --------------------------------------------------------------------------------------------

def test_cloth_cache_has_sampled_points_normals_extent_velocities(write_scene, tmp_path):
    scene_path = write_scene("""
        [scene]
        fps = 24
        end_frame = 13
        [ground]
        [[cloths]]
        name = "sheet"
        grid = { size = [1.0, 0.5], resolution = [11, 6] }
        position = [0.0, 1.0, 0.0]
        pinned = [0, 10]
    """)
    stats = simbake.bake(simbake.load_scene(scene_path), tmp_path / "cloth.usdc")
    stage = open_stage(tmp_path / "cloth.usdc")
    mesh = stage.GetPrimAtPath("/World/sheet")
    assert mesh.GetTypeName() == "Mesh"
    for attr in ("points", "normals", "extent", "velocities"):
        assert mesh.GetAttribute(attr).GetTimeSamples() == [float(f) for f in range(1, 14)], attr
    for attr in ("faceVertexCounts", "faceVertexIndices"):
        assert mesh.GetAttribute(attr).GetNumTimeSamples() == 0, attr  # topology written once
    assert len(mesh.GetAttribute("faceVertexIndices").Get()) == 3 * 2 * 10 * 5
    points = [np.array(mesh.GetAttribute("points").Get(f)) for f in (1, 13)]
    # vertex (i, j) is j * nx + i, the grid centred on position: vertex 0 at (-x, -z), 10 at (+x, -z)
    assert np.allclose(points[0][0], [-0.5, 1.0, -0.25]) and np.allclose(points[0][10], [0.5, 1.0, -0.25])
    # the pinned corners stay; the free edge falls (half a second under gravity)
    assert np.allclose(points[1][[0, 10]], points[0][[0, 10]])
    assert points[1][60][1] < 0.9
    # velocities are metres per second: the mean of the two ends' velocities agrees with the
    # motion between the frames (the trapezoid rule; 10% covers the frame's own curvature)
    v = 0.5 * (np.array(mesh.GetAttribute("velocities").Get(12)) + np.array(mesh.GetAttribute("velocities").Get(13)))
    finite_difference = (np.array(mesh.GetAttribute("points").Get(13)) - np.array(mesh.GetAttribute("points").Get(12))) * 24
    assert np.abs(v - finite_difference).max() < 0.1 * np.abs(finite_difference).max() + 1e-3
    assert stats.frames == 13


def test_cloth_pinned_index_out_of_range_for_a_mesh_is_an_error(write_scene, meshes, tmp_path):
    scene_path = write_scene("""
        [scene]
        end_frame = 3
        [[cloths]]
        name = "cape"
        mesh = "torus.obj"
        pinned = [0, 99999]
    """)
    with pytest.raises(simbake.SceneError) as info:
        simbake.bake(simbake.load_scene(scene_path), tmp_path / "cape.usdc")
    assert info.value.key == "cloths[0].pinned" and "99999" in str(info.value)
    assert not (tmp_path / "cape.usdc").exists()


def test_unreadable_cloth_mesh_is_a_one_line_error(write_scene, tmp_path):
    (tmp_path / "junk.obj").write_text("v 0 0\nf 1 2\nthis is not a mesh\n")
    scene_path = write_scene("""
        [scene]
        end_frame = 3
        [[cloths]]
        name = "cape"
        mesh = "junk.obj"
    """)
    with pytest.raises(simbake.SceneError) as info:
        simbake.bake(simbake.load_scene(scene_path), tmp_path / "cape.usdc")
    assert info.value.key == "cloths[0].mesh" and "junk.obj" in str(info.value)
    assert "\n" not in str(info.value)
    assert not (tmp_path / "cape.usdc").exists()
