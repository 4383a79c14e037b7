"""Cloth attachments (issue 34): cloth points bound at the first frame to a body's nearest
surface point and carried with it (TOML ``attach = { to, points }``, USD
``simbake:cloth:attachTo`` / ``simbake:cloth:attached``).

The shots come from tests/data/shots/make_deforming.py: a cape sewn to the swaying sphere (its
surface known in closed form at every frame), with time-sampled points or skinned, and a sleeve
on an arm that UsdSkel bends 90 degrees at the elbow (the arm's skinning written out with numpy
there, apart from UsdSkel and simbake). Each test says what it measures against.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

import simbake
from conftest import bake_error, module_from_file
from mesh_reference import penetration

pxr = pytest.importorskip("pxr")
from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics, Vt  # noqa: E402

SHOTS = Path(__file__).resolve().parents[1] / "data" / "shots"
shots = module_from_file(SHOTS / "make_deforming.py")
STRAIN = 0.1 * 1.01  # the cloths' strain limit (the default) + 1%


def test_checked_in_attachment_shots_are_what_the_generator_writes(tmp_path):
    for name, write in (("caped_sphere", shots.write_caped_sphere),
                        ("caped_skinned_sphere", lambda p: shots.write_caped_sphere(p, skinned=True)),
                        ("sleeve", shots.write_sleeve)):
        write(tmp_path / f"{name}.usda")
        assert (tmp_path / f"{name}.usda").read_text() == (SHOTS / f"{name}.usda").read_text(), name


def _points(stage, path: str, frame: int) -> np.ndarray:
    return np.array(UsdGeom.Mesh(stage.GetPrimAtPath(path)).GetPointsAttr().Get(frame), dtype=np.float64)


def _edges(triangles) -> np.ndarray:
    return np.unique(np.sort(np.asarray(triangles)[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0)


def _eighths(points: np.ndarray, edges: np.ndarray) -> np.ndarray:
    a, b = points[edges[:, 0]], points[edges[:, 1]]
    return (a[:, None] + (np.arange(1, 8) / 8.0)[None, :, None] * (b - a)[:, None]).reshape(-1, 3)


def _strain(points: np.ndarray, rest: np.ndarray, edges: np.ndarray) -> float:
    length = np.linalg.norm(points[edges[:, 1]] - points[edges[:, 0]], axis=1)
    return float((length / np.linalg.norm(rest[edges[:, 1]] - rest[edges[:, 0]], axis=1) - 1.0).max())


# --------------------------------------------------------------------------------------------
# a cape on a deforming body
# --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("skinned", [False, True], ids=["points", "skinned"])
def test_a_cape_rides_the_swaying_sphere(tmp_path, skinned):
    """The cape's top row is sewn to the sphere, which sways 0.1 m and swells by 20 mm. Its
    attached points are measured against the closed form: the sphere is c(t) + r(t) u, a uniform
    swelling and a translation, so a point bound to its mesh keeps its offset p0 - s0 from its
    bound surface point and the bound point scales about the centre: p(t) = c(t) + (r/r0)(p0 - c0)
    + (1 - r/r0)(p0 - s0). The last term is at most |1 - r/r0| (h + the facets' sag) = 0.057 x
    6.7 mm = 0.38 mm, and the skinned sphere's half-float scales add up to 0.2 mm (test_deforming):
    within 0.6 mm of c(t) + (r/r0)(p0 - c0) at every frame; the QA's own figure (attachment_drift,
    rebound with numpy) stays under 1 mm. At every frame, too: no cloth point or edge eighth more
    than 1 mm inside the sphere's mesh at that frame, none inside the sphere's closed form, strain
    (from the cache's points and the rest shape) within the limit + 1%, no self-intersecting
    pair; and the cape hangs down the sphere's back, below its centre."""
    shot = SHOTS / ("caped_skinned_sphere.usda" if skinned else "caped_sphere.usda")
    scene = simbake.load_scene(shot)
    (body,), (cape,) = scene.bodies, scene.cloths
    assert cape.attach_to == body.name and cape.attached == tuple(range(shots.CAPE["columns"]))
    out = tmp_path / "c.usdc"
    stats = simbake.bake(scene, out, threads=1)
    stage = Usd.Stage.Open(str(out))
    edges = _edges(cape.mesh_triangles)
    attached = np.array(cape.attached)
    c0, r0 = shots.sphere_at(shots.START, shots.CAPE["dr"])
    p0 = None
    for k, frame in enumerate(range(scene.start_frame, scene.end_frame + 1)):
        points = _points(stage, "/World/Cape", frame)
        p0 = points[attached] if p0 is None else p0
        centre, radius = shots.sphere_at(frame, shots.CAPE["dr"])
        expected = centre + (radius / r0) * (p0 - c0)
        assert np.linalg.norm(points[attached] - expected, axis=1).max() <= 0.6e-3, frame
        surface = body.deformation.vertices[k]
        assert penetration(points, surface, body.deformation.triangles) <= 1e-3, frame
        assert penetration(_eighths(points, edges), surface, body.deformation.triangles) <= 1e-3, frame
        assert (np.linalg.norm(points - centre, axis=1) - radius).min() >= -1e-3, frame
        assert _strain(points, cape.mesh_vertices, edges) <= STRAIN, frame
    assert points[:, 1].min() < shots.Y0 - 0.1  # hanging down the back
    qa = json.loads(stats.qa.read_text())
    assert max(qa["figures"]["attachment_drift"]) <= 1e-3
    assert max(qa["cloths"]["Cape"]["attachment_drift"]) <= 1e-5
    assert max(qa["figures"]["cloth_self_intersections"]) == 0
    assert not stats.warnings, stats.warnings


def test_the_qas_binding_is_to_the_first_nearest_of_every_triangle():
    """The QA binds an attached point to the first (by index) of its nearest triangles,
    comparing only those that can be nearest; the same triangles as comparing every one, for
    points on the sphere's vertices (nearest several triangles at once) and off its surface."""
    from simbake.qa_attachments import bind_to_mesh, closest_on_triangles

    from simbake import _core

    sphere = _core.sphere_mesh(1.0, 16)
    v, f = np.asarray(sphere[0], dtype=np.float64), np.asarray(sphere[1])
    rng = np.random.default_rng(2)
    points = np.concatenate([v[rng.integers(0, len(v), 100)], v[rng.integers(0, len(v), 200)]
                             + rng.normal(0, 0.05, (200, 3))])
    corners = v[f]
    expected = []
    for p in points:
        q = np.broadcast_to(p, (len(f), 3))
        w = closest_on_triangles(q, corners[:, 0], corners[:, 1], corners[:, 2])
        d = q - (w[:, :1] * corners[:, 0] + w[:, 1:2] * corners[:, 1] + w[:, 2:] * corners[:, 2])
        expected.append(np.argmin(np.einsum("ij,ij->i", d, d)))
    np.testing.assert_array_equal(bind_to_mesh(points, v, f)[0], expected)


def test_the_qa_warns_when_attached_points_leave_their_body(tmp_path, monkeypatch):
    """The QA judges the attached points against the body it is given, apart from the solver:
    given the sphere moved 10 mm further along x at each frame than the solver saw it (the
    solver's cape rides the sphere to round-off, the cape test), it binds the points at the
    first frame and finds them off their body by exactly that shift (a translation moves a
    point bound to a triangle by itself), 20 mm at frame 3, and warns."""
    from dataclasses import replace

    import simbake.qa
    from simbake.qa_attachments import AttachmentDrift

    def shifted(scene):
        (body,) = scene.bodies
        d = body.deformation
        moved = d.vertices + np.arange(len(d.vertices))[:, None, None] * np.array([0.01, 0.0, 0.0])
        return replace(scene, bodies=(replace(body, deformation=replace(d, vertices=moved)),))

    monkeypatch.setattr(simbake.qa, "AttachmentDrift", lambda scene: AttachmentDrift(shifted(scene)))
    stats = simbake.bake(simbake.load_scene(SHOTS / "caped_sphere.usda"), tmp_path / "c.usdc", end_frame=3, threads=1)
    drift = json.loads(stats.qa.read_text())["cloths"]["Cape"]["attachment_drift"]
    assert drift[0] < 1e-9 and abs(drift[1] - 0.01) < 1e-9 and abs(drift[2] - 0.02) < 1e-9, drift
    assert any("cloth 'Cape' attached points off their body" in w for w in stats.warnings), stats.warnings


# --------------------------------------------------------------------------------------------
# a sleeve on a bending arm
# --------------------------------------------------------------------------------------------

def _winding(ring: np.ndarray, centre: np.ndarray, axis: np.ndarray) -> float:
    """How many times the closed polygon `ring` goes round the line through `centre` along `axis`."""
    u = np.cross(axis, [0.0, 1.0, 0.0] if abs(axis[1]) < 0.9 else [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    w = np.cross(axis, u)
    angles = np.arctan2((ring - centre) @ w, (ring - centre) @ u)
    steps = np.diff(np.concatenate([angles, angles[:1]]))
    return float(np.sum((steps + np.pi) % (2 * np.pi) - np.pi) / (2 * np.pi))


def test_a_sleeve_stays_on_an_arm_bending_at_the_elbow(tmp_path):
    """The arm as UsdSkel skins it (simbake's reading) is the generator's own linear blend to
    1e-5 m (float32 points and weights). Against that arm at every frame: no sleeve point or
    edge eighth more than 1 mm inside it, no self-intersecting pair (the QA's count), strain
    within the limit + 1% (from the cache), the sewn ring on the arm (the QA's attachment_drift
    under 1 mm); and nothing pinches through at the elbow: every ring of the sleeve still goes
    once round the arm's axis (the axis skinned as the arm is, at the ring's nearest point), the
    arm bent 90 degrees at the end."""
    scene = simbake.load_scene(SHOTS / "sleeve.usda")
    (arm,), (sleeve,) = scene.bodies, scene.cloths
    assert sleeve.attach_to == arm.name and arm.deformation.source == "skel"
    out = tmp_path / "s.usdc"
    stats = simbake.bake(scene, out, threads=1)
    stage = Usd.Stage.Open(str(out))
    edges = _edges(sleeve.mesh_triangles)
    triangles = arm.deformation.triangles
    n, m = shots.SLEEVE["rings"], shots.SLEEVE["segments"]
    x = np.linspace(shots.ARM["start"], shots.ARM["end"], 301)
    axis_rest = np.stack([x, np.full_like(x, shots.ARM_Y), np.zeros_like(x)], axis=-1)
    for k, frame in enumerate(range(scene.start_frame, scene.end_frame + 1)):
        surface = shots.arm_at(frame)
        assert np.abs(arm.deformation.vertices[k] - surface).max() < 1e-5, frame
        points = _points(stage, "/World/Sleeve", frame)
        assert penetration(points, surface, triangles) <= 1e-3, frame
        assert penetration(_eighths(points, edges), surface, triangles) <= 1e-3, frame
        assert _strain(points, sleeve.mesh_vertices, edges) <= STRAIN, frame
    assert shots.elbow_angle(scene.end_frame) == pytest.approx(math.pi / 2)
    axis = shots.arm_at(scene.end_frame, axis_rest)
    for i in range(n):
        ring = points[i * m:(i + 1) * m]
        j = int(np.argmin(np.linalg.norm(axis - ring.mean(axis=0), axis=1)))
        direction = axis[min(j + 1, len(axis) - 1)] - axis[max(j - 1, 0)]
        assert abs(abs(_winding(ring, axis[j], direction / np.linalg.norm(direction))) - 1.0) < 1e-6, i
    qa = json.loads(stats.qa.read_text())
    assert max(qa["figures"]["cloth_self_intersections"]) == 0
    assert max(qa["figures"]["attachment_drift"]) <= 1e-3
    assert not stats.warnings, stats.warnings


# --------------------------------------------------------------------------------------------
# a cloth on a keyed rigid body (TOML), and the same in USD
# --------------------------------------------------------------------------------------------

TURN = (math.cos(math.pi / 4), 0.0, math.sin(math.pi / 4), 0.0)  # a quarter turn about y
MOVER = f"""
[scene]
fps = 24
end_frame = 24

[[bodies]]
name = "mover"
shape = {{ type = "box", size = [0.4, 0.4, 0.4] }}
kinematic = true
position = [0.0, 1.0, 0.0]
keys = [{{ time = 0.0 }}, {{ time = 1.0, position = [0.5, 1.25, 0.0], orientation = [{TURN[0]!r}, 0.0, {TURN[2]!r}, 0.0] }}]

[[cloths]]
name = "sheet"
grid = {{ size = [0.5, 0.75], resolution = [5, 7] }}
position = [0.0, 0.75, 0.125]
area_density = 0.25
stretch_stiffness = 512.0
attach = {{ to = "mover", points = [0, 1, 2, 3, 4] }}
"""


def _pose(stage, path: str, frame: int):
    prim = stage.GetPrimAtPath(path)
    t = np.array(prim.GetAttribute("xformOp:translate").Get(frame), dtype=np.float64)
    q = prim.GetAttribute("xformOp:orient").Get(frame)
    w, (x, y, z) = q.GetReal(), q.GetImaginary()
    return t, np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def test_a_cloth_rides_a_keyed_body_that_moves_and_turns(tmp_path):
    """A sheet whose first row is attached 50 mm under a keyed box that rises, moves and turns
    a quarter turn in 1 s: at every frame of the cache the attached points are the box's pose
    (its cache's translate and orient) applied to where they were in its frame at the first
    frame, to the cache's float32 rounding (1e-6 m); the sheet hangs from them within its
    strain limit + 1%."""
    path = tmp_path / "mover.toml"
    path.write_text(MOVER)
    out = tmp_path / "m.usdc"
    stats = simbake.bake(simbake.load_scene(path), out, threads=1)
    stage = Usd.Stage.Open(str(out))
    t0, r0 = _pose(stage, "/World/mover", 1)
    local = (_points(stage, "/World/sheet", 1)[:5] - t0) @ r0
    turned = False
    for frame in range(1, 25):
        t, r = _pose(stage, "/World/mover", frame)
        points = _points(stage, "/World/sheet", frame)
        assert np.abs(points[:5] - (local @ r.T + t)).max() < 1e-6, frame
        turned = turned or r[0, 0] < math.cos(math.radians(86.0))  # (frame 24 is 23/24 s: 86.25 degrees)
    assert turned
    qa = json.loads(stats.qa.read_text())
    assert max(qa["figures"]["cloth_strain"]) <= STRAIN and max(qa["figures"]["attachment_drift"]) <= 1e-6
    assert not stats.warnings, stats.warnings


def _mover_shot(path: Path) -> Path:
    """MOVER as a USD shot: a kinematic Cube keyed at every frame (the TOML keys' own
    interpolation: linear, and the turn at a constant rate), the sheet a Mesh with the TOML
    grid's points and triangles, attached to the cube."""
    from simbake.assets import grid_mesh

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, "Y")
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(24)
    stage.SetTimeCodesPerSecond(24)
    stage.SetFramesPerSecond(24)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/World").GetPrim())
    cube = UsdGeom.Cube.Define(stage, "/World/mover")
    cube.CreateSizeAttr(0.4)
    translate, orient = cube.AddTranslateOp(), cube.AddOrientOp(UsdGeom.XformOp.PrecisionDouble)
    for frame in range(1, 25):
        s = (frame - 1) / 24.0
        translate.Set(Gf.Vec3d(0.5 * s, 1.0 + 0.25 * s, 0.0), frame)
        orient.Set(Gf.Quatd(math.cos(math.pi / 4 * s), 0.0, math.sin(math.pi / 4 * s), 0.0), frame)
    UsdPhysics.CollisionAPI.Apply(cube.GetPrim())
    UsdPhysics.RigidBodyAPI.Apply(cube.GetPrim()).CreateKinematicEnabledAttr(True)
    vertices, triangles = grid_mesh((0.5, 0.75), (5, 7))
    sheet = UsdGeom.Mesh.Define(stage, "/World/sheet")
    sheet.CreatePointsAttr(Vt.Vec3fArray.FromNumpy((vertices + [0.0, 0.75, 0.125]).astype(np.float32)))
    sheet.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(triangles)))
    sheet.CreateFaceVertexIndicesAttr(Vt.IntArray(triangles.reshape(-1).tolist()))
    prim = sheet.GetPrim()
    prim.AddAppliedSchema("SimbakeClothAPI")
    prim.CreateAttribute("simbake:cloth:areaDensity", Sdf.ValueTypeNames.Float).Set(0.25)
    prim.CreateAttribute("simbake:cloth:stretchStiffness", Sdf.ValueTypeNames.Float).Set(512.0)
    prim.CreateRelationship("simbake:cloth:attachTo").SetTargets([cube.GetPath()])
    prim.CreateAttribute("simbake:cloth:attached", Sdf.ValueTypeNames.IntArray).Set(Vt.IntArray([0, 1, 2, 3, 4]))
    stage.GetRootLayer().Save()
    return path


def test_the_toml_and_usd_forms_give_the_same_result(tmp_path):
    """The same keyed box and attached sheet from TOML and from USD: the same attachment in the
    scene (the body by its own name, the same points), and the same cloth at every frame. The
    inputs differ only by float32 rounding (USD's points, the keys' quaternions at each frame):
    within 1e-5 m, against the sheet's 0.2 m swing."""
    toml = tmp_path / "mover.toml"
    toml.write_text(MOVER)
    shot = _mover_shot(tmp_path / "mover.usda")
    a, b = simbake.load_scene(toml), simbake.load_scene(shot)
    assert (a.cloths[0].attach_to, a.cloths[0].attached) == ("mover", (0, 1, 2, 3, 4))
    assert (b.cloths[0].attach_to, b.cloths[0].attached) == ("mover", (0, 1, 2, 3, 4))
    simbake.bake(a, tmp_path / "a.usdc", threads=1)
    simbake.bake(b, tmp_path / "b.usdc", threads=1)
    sa, sb = Usd.Stage.Open(str(tmp_path / "a.usdc")), Usd.Stage.Open(str(tmp_path / "b.usdc"))
    swing = 0.0
    for frame in range(1, 25):
        pa, pb = _points(sa, "/World/sheet", frame), _points(sb, "/World/sheet", frame)
        assert np.abs(pa - pb).max() < 1e-5, frame
        swing = max(swing, np.abs(pa - _points(sa, "/World/sheet", 1)).max())
    assert swing > 0.2


# --------------------------------------------------------------------------------------------
# bad input
# --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("given, key, problem", [
    ('attach = { to = "ghost", points = [0, 1] }', "cloths[0].attach.to", "no body named 'ghost' (bodies: mover)"),
    ('attach = { to = "mover", points = [0, 1, 35] }', "cloths[0].attach.points[2]",
     "vertex index out of range: the 5x7 grid has 35 vertices, got 35"),
    ('attach = { to = "mover", points = [0, 1, 2, 1] }', "cloths[0].attach.points[3]",
     "vertex 1 is listed twice (also points[1])"),
    ('pinned = [0]\nattach = { to = "mover", points = [0, 1] }', "cloths[0].attach.points[0]",
     "vertex 0 is also pinned (pinned[0]); a point is either pinned or attached"),
    ('attach = { to = "mover", points = [] }', "cloths[0].attach.points", "must list at least one vertex index"),
    ('attach = { onto = "mover", points = [0] }', "cloths[0].attach.onto", "unknown key (allowed: to, points)"),
    ('attach = { to = "mover", points = [0, 1.5] }', "cloths[0].attach.points[1]", "must be an integer, got float 1.5"),
    ('attach = { points = [0] }', "cloths[0].attach.to", "missing required key"),
])
def test_bad_toml_attachments_are_one_line_errors(tmp_path, capsys, given, key, problem):
    """Each problem is one line naming the file, the key and what is wrong; exit 2, no output."""
    path = tmp_path / "bad.toml"
    path.write_text(MOVER.replace('attach = { to = "mover", points = [0, 1, 2, 3, 4] }', given))
    err = bake_error(path, tmp_path / "bad.usdc", capsys)
    assert err.endswith(f"{path}: {key}: {problem}"), err


def test_a_mesh_cloth_attached_point_out_of_range_is_a_one_line_error(tmp_path, capsys):
    """A mesh cloth's vertex count is known once its file is read: the point is checked then."""
    (tmp_path / "sheet.obj").write_text("v 0 0.75 0\nv 0.1 0.75 0\nv 0 0.75 0.1\nf 1 2 3\n")
    text = MOVER.replace('grid = { size = [0.5, 0.75], resolution = [5, 7] }', 'mesh = "sheet.obj"')
    path = tmp_path / "bad.toml"
    path.write_text(text)
    err = bake_error(path, tmp_path / "bad.usdc", capsys)
    assert err.endswith(f"{path}: cloths[0].attach.points: vertex 3 does not exist (the cloth has 3)"), err


@pytest.mark.parametrize("edit, problem", [
    (lambda p: p.GetRelationship("simbake:cloth:attachTo").AddTarget("/World/ground"),
     "/World/sheet.simbake:cloth:attachTo: must target one prim, the body the attached points ride; it targets 2"),
    (lambda p: p.GetRelationship("simbake:cloth:attachTo").SetTargets(["/World/nothing"]),
     "/World/sheet.simbake:cloth:attachTo: </World/nothing> is not a simulated body"),
    (lambda p: p.GetRelationship("simbake:cloth:attachTo").ClearTargets(True),
     "/World/sheet.simbake:cloth:attachTo: must target one prim, the body the attached points ride; it targets 0"),
    (lambda p: p.GetAttribute("simbake:cloth:attached").Set(Vt.IntArray([])),
     "/World/sheet.simbake:cloth:attached: lists no point"),
    (lambda p: p.GetAttribute("simbake:cloth:attached").Set(Vt.IntArray([0, 40])),
     "/World/sheet.simbake:cloth:attached: point 40 does not exist (the mesh has 35)"),
    (lambda p: p.GetAttribute("simbake:cloth:attached").Set(Vt.IntArray([0, 1, 0])),
     "/World/sheet.simbake:cloth:attached: point 0 is listed twice (at 0 and 2)"),
    (lambda p: p.CreateAttribute("simbake:cloth:pinned", Sdf.ValueTypeNames.IntArray).Set(Vt.IntArray([1])),
     "/World/sheet.simbake:cloth:attached: point 1 is also in simbake:cloth:pinned"),
])
def test_bad_usd_attachments_are_one_line_errors(tmp_path, capsys, edit, problem):
    shot = _mover_shot(tmp_path / "bad.usda")
    stage = Usd.Stage.Open(str(shot))
    if "targets 2" in problem:  # (a second target: a ground plane)
        ground = UsdGeom.Plane.Define(stage, "/World/ground")
        ground.CreateAxisAttr("Y")
        UsdPhysics.CollisionAPI.Apply(ground.GetPrim())
    edit(stage.GetPrimAtPath("/World/sheet"))
    stage.GetRootLayer().Save()
    err = bake_error(shot, tmp_path / "bad.usdc", capsys)
    assert problem in err and "bad.usda" in err, err
