"""Deforming colliders (issue 34, first slice): a USD collider Mesh with time-sampled points,
or one skinned by UsdSkel, read at every frame; the QA measures cloth inside it at its own pose.

The shots come from tests/data/shots/make_deforming.py: a sphere whose points swell and sway
(radius and centre known in closed form at every frame), the same sphere skinned to one
joint, and a slab whose points rise under a ball.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import simbake
from conftest import module_from_file
from simbake.cli import main
from mesh_reference import deepest_distance, inside_closed, penetration

pxr = pytest.importorskip("pxr")
from pxr import Usd, UsdGeom, Vt  # noqa: E402

SHOTS = Path(__file__).resolve().parents[1] / "data" / "shots"


shots = module_from_file(SHOTS / "make_deforming.py")


def test_checked_in_shots_are_what_the_generator_writes(tmp_path):
    for name, write in (("deforming_sphere", shots.write_deforming_sphere),
                        ("skinned_sphere", shots.write_skinned_sphere),
                        ("rising_floor", shots.write_rising_floor)):
        write(tmp_path / f"{name}.usda")
        assert (tmp_path / f"{name}.usda").read_text() == (SHOTS / f"{name}.usda").read_text(), name


# --------------------------------------------------------------------------------------------
# reading
# --------------------------------------------------------------------------------------------

def _sphere_error(vertices: np.ndarray, frame: int) -> float:
    """The largest distance of the vertices from the generator's analytic sphere at `frame`."""
    centre, radius = shots.sphere_at(frame)
    return float(np.abs(np.linalg.norm(vertices - centre, axis=1) - radius).max())


def test_time_sampled_points_are_read_at_every_frame():
    scene = simbake.load_scene(SHOTS / "deforming_sphere.usda")
    (body,) = scene.bodies
    d = body.deformation
    assert body.kinematic and d.source == "points"
    assert d.vertices.shape == (shots.END - shots.START + 1, len(shots.unit_sphere()[0]), 3)
    # every vertex on the analytic sphere of its frame; the file holds float32 points (m ~ 0.5:
    # rounding 3e-8), so 1e-6 m
    assert max(_sphere_error(d.vertices[k], shots.START + k) for k in range(len(d.vertices))) < 1e-6
    # the body's shape is the first frame's surface, in world coordinates
    assert body.position == (0.0, 0.0, 0.0) and body.orientation == (1.0, 0.0, 0.0, 0.0)
    np.testing.assert_array_equal(body.shape.mesh_vertices, d.vertices[0])
    assert not [w for w in scene.warnings if "/World/Body" in w], scene.warnings


@pytest.mark.parametrize("method", ["classicLinear", "dualQuaternion"])
def test_skinned_sphere_is_the_same_surface_as_the_sampled_one(tmp_path, method):
    """UsdSkel's skinning (one joint that translates and scales) against the sphere's closed
    form. The SkelAnimation's scales are half floats (a 10-bit mantissa: up to 2^-11 of s ~ 1.2
    relative, 0.35 m x 6e-4 = 2e-4 m), so 3e-4 m."""
    shot = shots.write_skinned_sphere(tmp_path / "skinned.usda", method)
    scene = simbake.load_scene(shot)
    (body,) = scene.bodies
    d = body.deformation
    assert d.source == "skel"
    worst = max(_sphere_error(d.vertices[k], shots.START + k) for k in range(len(d.vertices)))
    assert worst < 3e-4, worst
    # and it moves: the radius changes by 2 DR over the shot
    radii = [np.linalg.norm(v - v.mean(axis=0), axis=1).mean() for v in d.vertices]
    assert max(radii) - min(radii) > 1.9 * shots.DR


def test_skinning_follows_the_skeleton_world_transform(tmp_path):
    """A SkelRoot moved by 1 m along x moves the skinned surface with it (the mesh's own
    transform does not count: UsdSkel ignores it)."""
    shot = shots.write_skinned_sphere(tmp_path / "moved.usda")
    stage = Usd.Stage.Open(str(shot))
    UsdGeom.Xformable(stage.GetPrimAtPath("/World/Character")).AddTranslateOp().Set((1.0, 0.0, 0.0))
    UsdGeom.Xformable(stage.GetPrimAtPath("/World/Character/Body")).AddTranslateOp().Set((0.0, 5.0, 0.0))
    stage.GetRootLayer().Save()
    moved = simbake.load_scene(shot).bodies[0].deformation.vertices
    here = simbake.load_scene(SHOTS / "skinned_sphere.usda").bodies[0].deformation.vertices
    np.testing.assert_allclose(moved - here, np.broadcast_to([1.0, 0.0, 0.0], here.shape), atol=1e-6)


def test_a_point_count_that_changes_is_a_one_line_error(tmp_path, capsys):
    shot = shots.write_deforming_sphere(tmp_path / "bad.usda")
    stage = Usd.Stage.Open(str(shot))
    points = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Body")).GetPointsAttr()
    points.Set(Vt.Vec3fArray(list(points.Get(5))[:-1]), 5)
    stage.GetRootLayer().Save()
    out = tmp_path / "out.usdc"
    assert main(["bake", str(shot), "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err.strip()
    assert "bad.usda: /World/Body.points: has 481 points at time code 5, 482 at the start" in err, err
    assert "\n" not in err and not out.exists()


def test_a_rigid_collider_mesh_is_not_deforming(tmp_path):
    shot = shots.write_deforming_sphere(tmp_path / "still.usda")
    stage = Usd.Stage.Open(str(shot))
    points = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Body")).GetPointsAttr()
    first = points.Get(shots.START)
    points.Clear()
    points.Set(first)
    stage.GetRootLayer().Save()
    (body,) = simbake.load_scene(shot).bodies
    assert body.deformation is None


# --------------------------------------------------------------------------------------------
# the QA's measure, against exact answers
# --------------------------------------------------------------------------------------------

def _cube():
    import trimesh

    box = trimesh.creation.box([1.0, 1.0, 1.0])
    return np.asarray(box.vertices, dtype=np.float64), np.asarray(box.faces, dtype=np.int32)


def test_penetration_of_points_in_a_unit_cube_is_their_depth():
    v, f = _cube()
    # depth to the nearest face, exact: 0.5 - max |x_i|
    rng = np.random.default_rng(3)
    points = rng.uniform(-0.7, 0.7, (4000, 3))
    inside = np.all(np.abs(points) < 0.5, axis=1)
    np.testing.assert_array_equal(inside_closed(points, v[f]), inside)
    depth = 0.5 - np.abs(points[inside]).max(axis=1)
    assert deepest_distance(points[inside], v[f]) == pytest.approx(depth.max(), abs=1e-12)
    assert penetration(points, v, f) == pytest.approx(depth.max(), abs=1e-12)
    assert penetration(points[~inside], v, f) == 0.0
    assert penetration(np.array([[0.0, 0.0, 0.0]]), v, f) == pytest.approx(0.5, abs=1e-12)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_cores_measure_is_the_deepest_vertex_and_edge_eighth_inside(seed):
    """The QA's measure (the core's closed_mesh_depth) for a crumpled sheet of long and short
    edges through a cube: the deepest vertex and edge eighth inside, each eighth looked at one
    by one against the cube's exact depth and the numpy reference; the edges whose two ends
    are outside alone too (some of them cut through the cube)."""
    from simbake import _core

    v, f = _cube()
    rng = np.random.default_rng(seed)
    n = 24
    u, w = np.meshgrid(np.linspace(-1.2, 1.2, n), np.linspace(-1.2, 1.2, n))
    points = np.stack([u.ravel(), 0.3 * np.sin(3 * u.ravel()) + rng.normal(0, 0.08, n * n), w.ravel()], axis=1)
    points[rng.choice(n * n, 40, replace=False)] += rng.normal(0, 0.5, (40, 3))  # some long edges
    quads = np.array([[i * n + j, i * n + j + 1, (i + 1) * n + j] for i in range(n - 1) for j in range(n - 1)]
                     + [[i * n + j + 1, (i + 1) * n + j + 1, (i + 1) * n + j] for i in range(n - 1) for j in range(n - 1)])
    edges = np.unique(np.sort(quads[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0)
    vertex, edge = _core.closed_mesh_depth(v, f, points, edges)
    eighths = _edge_eighths(points, quads)
    inside = np.all(np.abs(eighths) < 0.5, axis=1)
    assert inside.any() and (~inside).any()
    assert edge == pytest.approx(float((0.5 - np.abs(eighths[inside]).max(axis=1)).max()), abs=1e-12)
    assert edge == pytest.approx(penetration(eighths, v, f), abs=1e-12)
    assert vertex == pytest.approx(penetration(points, v, f), abs=1e-12)
    outside = ~np.all(np.abs(points) < 0.5, axis=1)
    open_ = edges[outside[edges[:, 0]] & outside[edges[:, 1]]]
    expected = penetration(_edge_eighths(points, np.c_[open_, open_[:, :1]]), v, f)
    assert expected > 0.04
    assert _core.closed_mesh_depth(v, f, points, open_)[1] == pytest.approx(expected, abs=1e-12)


def test_the_qa_warns_when_cloth_ends_inside_a_deforming_body(tmp_path, monkeypatch):
    """A solver that ignored the collider's motion (the world kept its first pose: what
    simbake did before) leaves the sheet inside the sphere as it swells (its radius grows by
    DR and its centre sways by SWAY by frame 13); the QA measures that at the sphere's own
    pose, apart from the solver, and warns."""
    import simbake.simulate

    monkeypatch.setattr(simbake.simulate, "set_deforming_frames", lambda *args: None)
    out = tmp_path / "c.usdc"
    stats = simbake.bake(simbake.load_scene(SHOTS / "deforming_sphere.usda"), out, end_frame=13, threads=1)
    qa = json.loads(stats.qa.read_text())
    depth = qa["figures"]["cloth_penetration"]
    # independently: the cloth's vertices against the sphere's closed form at frame 13. The
    # mesh's facets are chords: a point's depth in the mesh is its depth in the sphere less at
    # most the facets' sag, the radius less the nearest facet plane's distance from the centre
    points = _cloth_points(out, 13)
    centre, radius = shots.sphere_at(13)
    analytic = float((radius - np.linalg.norm(points - centre, axis=1)).max())
    corners = simbake.load_scene(SHOTS / "deforming_sphere.usda").bodies[0].deformation.vertices[12][
        shots.unit_sphere_triangles()] - centre
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    sag = radius - float(np.abs(np.einsum("ij,ij->i", corners[:, 0], normals) / np.linalg.norm(normals, axis=1)).min())
    assert analytic > 0.1 and 0 < sag < 5e-3
    measured = qa["cloths"]["Sheet"]["vertex_penetration"][-1]
    assert analytic - sag - 1e-6 <= measured <= analytic + 1e-6, (measured, analytic, sag)
    assert depth[-1] >= measured
    assert any("cloth 'Sheet' penetration" in w for w in stats.warnings), stats.warnings


# --------------------------------------------------------------------------------------------
# the deforming collider simulated (core: levelset/deforming_surface.h)
# --------------------------------------------------------------------------------------------

def _cloth_points(cache: Path, frame: int) -> np.ndarray:
    stage = Usd.Stage.Open(str(cache))
    return np.array(UsdGeom.Mesh(stage.GetPrimAtPath("/World/Sheet")).GetPointsAttr().Get(frame), dtype=np.float64)


def _edge_eighths(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    e = np.unique(np.sort(np.asarray(triangles)[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0)
    a, b = points[e[:, 0]], points[e[:, 1]]
    return (a[:, None] + (np.arange(1, 8) / 8.0)[None, :, None] * (b - a)[:, None]).reshape(-1, 3)


LANDED = 8  # the sheet falls 0.15 m onto the sphere's top: sqrt(2 x 0.15 / 9.81) = 0.17 s, frame 5


@pytest.mark.parametrize("shot", ["deforming_sphere", "skinned_sphere"])
def test_a_sheet_on_a_swelling_swaying_sphere_stays_on_its_surface(tmp_path, shot):
    """Every frame: no cloth vertex or edge eighth more than 1 mm inside the sphere's own mesh
    at that frame (measured here with numpy, apart from the solver), nor inside the sphere's
    closed form (the mesh lies inside it); and the sheet rides the sphere's top as it rises
    and falls by 2 DR = 120 mm: the vertex over the centre stays between the cloth's
    thickness h = 5 mm less 1 mm and h + 5 mm above it (it lags a shrinking sphere by what
    gravity lets it fall behind: the top sinks at up to DR w = 0.19 m/s)."""
    scene = simbake.load_scene(SHOTS / f"{shot}.usda")
    out = tmp_path / "c.usdc"
    stats = simbake.bake(scene, out, threads=1)
    body, cloth = scene.bodies[0], scene.cloths[0]
    h = cloth.thickness
    tops = []
    for k, frame in enumerate(range(scene.start_frame, scene.end_frame + 1)):
        points = _cloth_points(out, frame)
        surface = body.deformation.vertices[k]
        assert penetration(points, surface, body.deformation.triangles) <= 1e-3, frame
        assert penetration(_edge_eighths(points, cloth.mesh_triangles), surface, body.deformation.triangles) <= 1e-3
        centre, radius = shots.sphere_at(frame)
        assert (np.linalg.norm(points - centre, axis=1) - radius).min() >= -1e-3, frame
        if frame >= LANDED:
            top = points[np.argmin(np.linalg.norm(points[:, [0, 2]] - centre[[0, 2]], axis=1))]
            tops.append(top[1] - (centre[1] + radius))
    assert h - 1e-3 <= min(tops) and max(tops) <= h + 5e-3, (min(tops), max(tops))
    qa = json.loads(stats.qa.read_text())
    assert max(qa["figures"]["cloth_penetration"]) <= 1e-3
    assert not [w for w in stats.warnings if "penetration" in w], stats.warnings


@pytest.mark.parametrize("rise, end", [(None, None), (0.01, 120)])
def test_a_ball_rides_a_slowly_rising_floor(tmp_path, monkeypatch, rise, end):
    """A rigid ball resting on a slab whose points rise at RISE = 0.1 m/s (the checked-in
    shot), or 0.01 m/s for 5 s (slow enough that the ball would fall asleep if the slab did not
    count as moving), moves up with it and never sinks into it by more than 1 mm (its centre
    against the slab's top, known at every frame)."""
    shot = SHOTS / "rising_floor.usda"
    if rise is not None:
        monkeypatch.setattr(shots, "RISE", rise)
        monkeypatch.setattr(shots, "END", end)
        shot = shots.write_rising_floor(tmp_path / "slow.usda")
    scene = simbake.load_scene(shot)
    out = tmp_path / "c.usdc"
    simbake.bake(scene, out, threads=1)
    stage = Usd.Stage.Open(str(out))
    translate = stage.GetPrimAtPath("/World/Ball").GetAttribute("xformOp:translate")
    gaps = [translate.Get(f)[1] - shots.SLAB["ball_radius"] - shots.slab_top(f)
            for f in range(scene.start_frame, scene.end_frame + 1)]
    assert min(gaps) >= -1e-3, min(gaps)
    # it rose with the slab, not bouncing off it: within 2 mm
    assert max(gaps) <= 2e-3, max(gaps)


def test_the_level_set_of_every_frame_is_written_beside_the_cache(tmp_path):
    """The guide Volume of a deforming collider names one .vdb a frame (a time-sampled
    filePath), each the grid of that frame's surface: phi at that frame's mesh vertices is 0
    to within the grid's trilinear error (a fraction of a voxel)."""
    from simbake import _core

    scene = simbake.load_scene(SHOTS / "deforming_sphere.usda")
    out = tmp_path / "c.usdc"
    simbake.bake(scene, out, end_frame=6, threads=1)
    stage = Usd.Stage.Open(str(out))
    file_path = stage.GetPrimAtPath("/World/Body_levelset/surface").GetAttribute("filePath")
    assert file_path.GetTimeSamples() == [float(f) for f in range(1, 7)]
    names = set()
    for k, frame in enumerate(range(1, 7)):
        vdb = (out.parent / file_path.Get(frame).path).resolve()
        names.add(vdb.name)
        grid = _core.LevelSet.read(str(vdb))
        vertices = scene.bodies[0].deformation.vertices[k]
        assert np.abs(grid.phi(np.ascontiguousarray(vertices))).max() < 0.5 * grid.voxel_size, frame
    assert len(names) == 6 and sorted(p.name for p in (tmp_path / "c.vdb").iterdir()) == sorted(names)


def test_a_surface_faster_than_its_level_sets_reach_is_warned(tmp_path, monkeypatch):
    """A slab rising 2 m/s (83 mm a frame) moves further in a frame than its level sets'
    exterior band reaches: one line says so; the checked-in shots (the sphere moves at most
    21 mm a frame, 1.9 of its 10.9 mm voxels) say nothing."""
    monkeypatch.setattr(shots, "RISE", 2.0)
    scene = simbake.load_scene(shots.write_rising_floor(tmp_path / "fast.usda"))
    lines = [w for w in scene.warnings if "/World/Floor" in w]
    assert len(lines) == 1 and "a vertex moves 83.3 mm in the frame to time code 2" in lines[0], scene.warnings
    for name in ("deforming_sphere", "skinned_sphere", "rising_floor"):
        assert not simbake.load_scene(SHOTS / f"{name}.usda").warnings, name
