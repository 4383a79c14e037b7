"""Baked level sets become assets: each .vdb a bake used, beside the cache, as a guide Volume."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from simbake.cli import main

from pxr import Usd, UsdGeom, UsdValidation, UsdVol

MESH = Path(__file__).resolve().parents[2] / "assets" / "meshes" / "lshape.obj"
SCENE = f"""
[scene]
end_frame = 4
[ground]
[[bodies]]
name = "a"
mesh = "{MESH}"
position = [0.0, 1.0, 0.0]
[[bodies]]
name = "b"
mesh = "{MESH}"
position = [0.0, 3.0, 0.0]
[[bodies]]
name = "ball"
shape = {{ type = "sphere", radius = 0.2 }}
position = [1.0, 1.0, 0.0]
"""


@pytest.mark.parametrize("clips", [None, 2])
def test_each_mesh_body_shows_the_level_set_it_used(tmp_path, clips):
    (tmp_path / "s.toml").write_text(SCENE)
    out = tmp_path / "out.usdc"
    assert main(["bake", str(tmp_path / "s.toml"), "-o", str(out), "-q"] + (["--clips", str(clips)] if clips else [])) == 0
    files = sorted((tmp_path / "out.vdb").iterdir())
    assert len(files) == 1 and files[0].suffix == ".vdb"  # two copies of one mesh share one grid
    stage = Usd.Stage.Open(str(out))
    for body in ("a", "b"):
        volume = UsdVol.Volume(stage.GetPrimAtPath(f"/World/{body}/levelset"))
        assert volume and UsdGeom.Imageable(volume).ComputePurpose() == UsdGeom.Tokens.guide
        field_path = volume.GetFieldPath("surface")
        field = UsdVol.OpenVDBAsset(stage.GetPrimAtPath(field_path))
        assert field.GetFieldNameAttr().Get() == "surface"
        asset = field.GetFilePathAttr().Get()
        assert not Path(asset.path).is_absolute()  # relative: the cache and its folder move together
        assert Path(asset.resolvedPath) == files[0]
    assert not stage.GetPrimAtPath("/World/ball/levelset")  # analytic: no grid
    context = UsdValidation.ValidationContext(UsdValidation.ValidationRegistry().GetOrLoadAllValidators())
    assert [e.GetMessage() for e in context.Validate(stage)] == []
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporaries left


def test_no_mesh_bodies_no_folder(tmp_path):
    (tmp_path / "s.toml").write_text('[scene]\nend_frame = 2\n[[bodies]]\nname = "ball"\n'
                                     'shape = { type = "sphere", radius = 0.2 }\n')
    assert main(["bake", str(tmp_path / "s.toml"), "-o", str(tmp_path / "o.usdc"), "-q"]) == 0
    assert not (tmp_path / "o.vdb").exists()


SHOTS = Path(__file__).resolve().parents[2] / "assets" / "scenes"


@pytest.mark.parametrize("shot, clips", [("shot.usda", None), ("shot_cm_zup.usda", None), ("shot.usda", 10)])
def test_a_shots_mesh_colliders_show_their_level_sets(tmp_path, shot, clips):
    """The shot's capsule becomes a mesh with a level set: its .vdb beside the cache, a guide
    Volume lined up with the capsule at every frame. The capsule is a Gprim (OpenUSD forbids
    a Gprim under it), so the Volume is its sibling Pill_levelset (a def under the parent's
    over), following the body with a time-sampled xformOp:transform."""
    from pxr import Sdf

    out, composed = tmp_path / "c.usdc", tmp_path / "s.usda"
    assert main(["bake", str(SHOTS / shot), "-o", str(out), "--shot", str(composed), "-q"]
                + (["--clips", str(clips)] if clips else [])) == 0
    files = sorted((tmp_path / "c.vdb").iterdir())
    assert len(files) == 1 and files[0].suffix == ".vdb"  # the capsule's; boxes and spheres are analytic
    layer = Sdf.Layer.FindOrOpen(str(tmp_path / "c.clips" / "topology.usdc") if clips else str(out))
    assert layer.GetPrimAtPath("/World/Props/Pill").specifier == Sdf.SpecifierOver
    assert layer.GetPrimAtPath("/World/Props").specifier == Sdf.SpecifierOver
    assert layer.GetPrimAtPath("/World/Props/Pill_levelset").specifier == Sdf.SpecifierDef
    stage = Usd.Stage.Open(str(composed))
    for path in ("/World/Props/Crate", "/World/Props/Ball", "/World/Block", "/World/Pusher"):
        assert not stage.GetPrimAtPath(f"{path}/levelset")
    volume = UsdVol.Volume(stage.GetPrimAtPath("/World/Props/Pill_levelset"))
    assert volume and UsdGeom.Imageable(volume).ComputePurpose() == UsdGeom.Tokens.guide
    field = UsdVol.OpenVDBAsset(stage.GetPrimAtPath(volume.GetFieldPath("surface")))
    assert field.GetFieldNameAttr().Get() == "surface"
    asset = field.GetFilePathAttr().Get()
    assert not Path(asset.path).is_absolute() and Path(asset.resolvedPath) == files[0]
    # the grid (metres, Y up, in the body's frame) lies on the capsule at every frame
    for frame in (1, 12, 36):
        guide = UsdGeom.BBoxCache(frame, [UsdGeom.Tokens.guide]).ComputeWorldBound(volume.GetPrim()).ComputeAlignedRange()
        pill = UsdGeom.BBoxCache(frame, [UsdGeom.Tokens.default_]).ComputeWorldBound(
            stage.GetPrimAtPath("/World/Props/Pill")).ComputeAlignedRange()
        size = np.array(pill.GetSize())
        assert size.max() > 0
        np.testing.assert_allclose(np.array(guide.GetMin()), np.array(pill.GetMin()), atol=0.02 * size.max())
        np.testing.assert_allclose(np.array(guide.GetMax()), np.array(pill.GetMax()), atol=0.02 * size.max())
    context = UsdValidation.ValidationContext(UsdValidation.ValidationRegistry().GetOrLoadAllValidators())
    assert [e.GetMessage() for e in context.Validate(stage)] == []
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_a_shot_body_xform_holds_its_level_set_volume(tmp_path):
    """A rigid-body Xform whose collider is a child Cylinder (cm, Z up): ``levelset`` under the
    body's prim (an over), a def Volume lined up with the cylinder as the body falls."""
    from pxr import Gf, Sdf, UsdPhysics

    stage = Usd.Stage.CreateNew(str(tmp_path / "can.usda"))
    UsdGeom.SetStageUpAxis(stage, "Z")
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(6)
    stage.SetTimeCodesPerSecond(24)
    UsdPhysics.Scene.Define(stage, "/World/PhysicsScene")
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/World").GetPrim())
    body = UsdGeom.Xform.Define(stage, "/World/Can")
    body.AddTranslateOp().Set(Gf.Vec3d(10, 20, 200))
    body.AddRotateXOp().Set(30.0)
    UsdPhysics.RigidBodyAPI.Apply(body.GetPrim())
    can = UsdGeom.Cylinder.Define(stage, "/World/Can/Shape")
    can.CreateRadiusAttr(10.0)
    can.CreateHeightAttr(40.0)
    can.AddTranslateOp().Set(Gf.Vec3d(0, 5, 0))
    UsdPhysics.CollisionAPI.Apply(can.GetPrim())
    block = UsdGeom.Cube.Define(stage, "/World/Block")  # something to touch: the can needs its grid
    block.CreateSizeAttr(50.0)
    block.AddTranslateOp().Set(Gf.Vec3d(0, 0, -25))
    UsdPhysics.CollisionAPI.Apply(block.GetPrim())
    stage.GetRootLayer().Save()
    out, composed = tmp_path / "c.usdc", tmp_path / "s.usda"
    assert main(["bake", str(tmp_path / "can.usda"), "-o", str(out), "--shot", str(composed), "-q"]) == 0
    layer = Sdf.Layer.FindOrOpen(str(out))
    assert layer.GetPrimAtPath("/World/Can").specifier == Sdf.SpecifierOver
    assert layer.GetPrimAtPath("/World/Can/levelset").specifier == Sdf.SpecifierDef
    result = Usd.Stage.Open(str(composed))
    volume = result.GetPrimAtPath("/World/Can/levelset")
    assert volume.IsA(UsdVol.Volume)
    for frame in (1, 6):
        guide = UsdGeom.BBoxCache(frame, [UsdGeom.Tokens.guide]).ComputeWorldBound(volume).ComputeAlignedRange()
        shape = UsdGeom.BBoxCache(frame, [UsdGeom.Tokens.default_]).ComputeWorldBound(
            result.GetPrimAtPath("/World/Can/Shape")).ComputeAlignedRange()
        np.testing.assert_allclose(np.array(guide.GetMin()), np.array(shape.GetMin()), atol=1.0)
        np.testing.assert_allclose(np.array(guide.GetMax()), np.array(shape.GetMax()), atol=1.0)
    context = UsdValidation.ValidationContext(UsdValidation.ValidationRegistry().GetOrLoadAllValidators())
    assert [e.GetMessage() for e in context.Validate(result)] == []
