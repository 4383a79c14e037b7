"""Baked level sets become assets: each .vdb a bake used, beside the cache, as a guide Volume."""

from __future__ import annotations

from pathlib import Path

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
