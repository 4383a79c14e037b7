"""Deforming bodies in TOML scenes: ``mesh_sequence = "frames/body.%04d.obj"``, one mesh file a
frame (issue 34). They are read into the same Body.deformation as a USD shot's deforming
collider and baked by the same machinery; the TOML cache writes the body's points and level
sets at every frame.

The frames are the swelling, swaying sphere of tests/data/shots/make_deforming.py (its closed
form at every frame), written here as OBJ files; the same sphere with time-sampled points is
the checked-in deforming_sphere.usda.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import simbake
from conftest import bake_error, module_from_file
from simbake.cli import main
from mesh_reference import penetration

pxr = pytest.importorskip("pxr")
from pxr import Usd, UsdGeom  # noqa: E402

SHOTS = Path(__file__).resolve().parents[1] / "data" / "shots"
shots = module_from_file(SHOTS / "make_deforming.py")

SCENE = """
[scene]
fps = 24
end_frame = {end}

[ground]

[[bodies]]
name = "Body"
mesh_sequence = "frames/body.%04d.obj"
kinematic = true
{placement}

[[cloths]]
name = "Sheet"
grid = {{ size = [1.2, 1.2], resolution = [25, 25] }}
position = [0.0, 0.95, 0.0]
area_density = 0.2
stretch_stiffness = 500.0
bend_stiffness = 0.0002
"""


def _frames(folder: Path, frames, triangles=None) -> Path:
    """The sphere at each frame as frames/body.NNNN.obj (exact decimal coordinates)."""
    unit, _, _ = shots.unit_sphere()
    triangles = shots.unit_sphere_triangles() if triangles is None else triangles
    (folder / "frames").mkdir(exist_ok=True)
    for frame in frames:
        centre, radius = shots.sphere_at(frame)
        lines = [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in centre + radius * unit]
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in triangles]
        (folder / "frames" / f"body.{frame:04d}.obj").write_text("\n".join(lines) + "\n")
    return folder


def _scene(folder: Path, end: int = 12, placement: str = "") -> Path:
    path = folder / "scene.toml"
    path.write_text(SCENE.format(end=end, placement=placement))
    return path


def test_a_mesh_sequence_is_a_deforming_body_like_a_shots(tmp_path):
    """Read: the body's surface at every frame is its file's, which is the sphere's closed form
    and the USD shot's time-sampled points (float32 there: to 1e-6 m); placed by position.
    Baked (12 frames): the sheet is never more than 1 mm inside the sphere at its frame; until
    it reaches the sphere (frame 5) it lies within 0.1 mm of the same sheet baked from the USD
    shot, whose float32 points (the sheet's too) differ from the TOML grid's by 3e-8 m. Once
    the sheet folds over the sphere that rounding is amplified as any perturbation of a
    draping cloth is (the same bodies to the bit, measured: 35 um at frame 5, 2.9 mm at frame
    6, 59 mm at 12), so later frames are checked against the surface alone. The cache holds
    the body's points at every frame and names a level set a frame."""
    _frames(tmp_path, range(1, 13))
    scene = simbake.load_scene(_scene(tmp_path))
    (body,) = scene.bodies
    d = body.deformation
    assert body.kinematic and d.source == "sequence" and d.vertices.shape[0] == 12
    shot = simbake.load_scene(SHOTS / "deforming_sphere.usda", end_frame=12)
    assert np.abs(d.vertices - shot.bodies[0].deformation.vertices).max() < 1e-6
    np.testing.assert_array_equal(d.triangles, shot.bodies[0].deformation.triangles)
    placed = simbake.load_scene(_scene(tmp_path, placement="position = [1.0, 0.0, 0.5]")).bodies[0].deformation
    np.testing.assert_allclose(placed.vertices, d.vertices + [1.0, 0.0, 0.5], atol=1e-15)
    out = tmp_path / "toml.usdc"
    simbake.bake(scene, out, threads=1)
    simbake.bake(shot, tmp_path / "shot.usdc", threads=1)
    stage, other = Usd.Stage.Open(str(out)), Usd.Stage.Open(str(tmp_path / "shot.usdc"))
    body_points = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Body/Body")).GetPointsAttr()
    vdbs = stage.GetPrimAtPath("/World/Body/levelset/surface").GetAttribute("filePath")
    assert vdbs.GetTimeSamples() == [float(f) for f in range(1, 13)]
    for k, frame in enumerate(range(1, 13)):
        sheet = np.array(UsdGeom.Mesh(stage.GetPrimAtPath("/World/Sheet")).GetPointsAttr().Get(frame))
        assert penetration(sheet.astype(np.float64), d.vertices[k], d.triangles) <= 1e-3, frame
        from_shot = np.array(UsdGeom.Mesh(other.GetPrimAtPath("/World/Sheet")).GetPointsAttr().Get(frame))
        if frame <= 5:
            assert np.abs(sheet - from_shot).max() < 1e-4, frame
        assert np.abs(np.array(body_points.Get(frame)) - d.vertices[k]).max() < 1e-6, frame
        assert (out.parent / vdbs.Get(frame).path).resolve().is_file()
    assert main(["check", str(out)]) == 0


def test_frames_is_the_sequence_of_its_range(tmp_path):
    """--frames 3:6 reads frames 3 to 6 only (the others need not exist)."""
    _frames(tmp_path, range(3, 7))
    scene = simbake.load_scene(_scene(tmp_path), start_frame=3, end_frame=6)
    d = scene.bodies[0].deformation
    centre, radius = shots.sphere_at(6)
    assert d.vertices.shape[0] == 4
    assert np.abs(np.linalg.norm(d.vertices[-1] - centre, axis=1) - radius).max() < 1e-12
    assert len([p for p in scene.input_files() if p.suffix == ".obj"]) == 4


@pytest.mark.parametrize("edit, key, problem", [
    ("missing", "bodies[0].mesh_sequence", "no such file: {folder}/frames/body.0007.obj"),
    ("topology", "bodies[0].mesh_sequence", "(frame 5) has 482 vertices and 960 triangles, not frame 1's 482 and 960 "
                                            "in the same order: a deforming body keeps one topology"),
    ("dynamic", "bodies[0].mesh_sequence", "a deforming body is kinematic: add kinematic = true"),
    ("keys", "bodies[0].keys", "does not apply to a deforming body (mesh_sequence): its frames move it"),
    ("pattern", "bodies[0].mesh_sequence", "must hold one frame-number field such as %04d"),
    ("both", "bodies[0].mesh", "cannot be given together with mesh_sequence"),
])
def test_bad_mesh_sequences_are_one_line_errors(tmp_path, capsys, edit, key, problem):
    triangles = shots.unit_sphere_triangles()
    _frames(tmp_path, range(1, 13))
    if edit == "missing":
        (tmp_path / "frames" / "body.0007.obj").unlink()
    if edit == "topology":  # the same triangles in another order at frame 5
        _frames(tmp_path, [5], triangles[::-1])
    path = _scene(tmp_path)
    text = path.read_text()
    text = {"dynamic": text.replace("kinematic = true", "kinematic = false"),
            "keys": text.replace("kinematic = true", "kinematic = true\nkeys = [{ time = 0.0 }]"),
            "pattern": text.replace("body.%04d.obj", "body.obj"),
            "both": text.replace("kinematic = true", 'kinematic = true\nmesh = "frames/body.0001.obj"')}.get(edit, text)
    path.write_text(text)
    err = bake_error(path, tmp_path / "bad.usdc", capsys)
    assert f"{path}: {key}: " in err and problem.format(folder=tmp_path) in err, err
