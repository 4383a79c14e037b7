"""simbake.cache_compare: two caches compared by content (benchmarks/same_bits.py and the wedge
tests rely on it to say "the same cache"), so each kind of difference it claims to see is made
here on a real cache and must be found, and the provenance alone must not count."""

from __future__ import annotations

import shutil

import pytest

import simbake
from simbake.cache_compare import first_difference

SCENE = """
    [scene]
    end_frame = 4
    [ground]
    [[bodies]]
    name = "ball"
    shape = { type = "sphere", radius = 0.25 }
    position = [0.0, 1.0, 0.0]
    linear_velocity = [0.5, 0.0, 0.0]
"""


@pytest.fixture
def cache(write_scene, tmp_path):
    return simbake.bake(simbake.load_scene(write_scene(SCENE)), tmp_path / "a.usdc").output


def _edited(cache, tmp_path, edit):
    """A copy of `cache` with `edit(layer)` applied and saved."""
    from pxr import Sdf

    copy = shutil.copy(cache, tmp_path / "b.usdc")
    layer = Sdf.Layer.FindOrOpen(str(copy))
    edit(layer)
    assert layer.Save()
    return copy


def test_a_cache_is_the_same_as_itself_and_as_a_bake_of_another_file(cache, write_scene, tmp_path):
    assert first_difference(cache, shutil.copy(cache, tmp_path / "copy.usdc")) is None
    # the same scene from another file: its provenance (scene name and hash) differs, not its content
    other = simbake.bake(simbake.load_scene(write_scene(SCENE + "\n# another file\n", "other.toml")),
                         tmp_path / "other.usdc").output
    assert first_difference(cache, other) is None


def test_a_changed_time_sample_is_found(cache, tmp_path):
    from pxr import Gf, Sdf

    path = Sdf.Path("/World/ball.xformOp:translate")

    def nudge(layer):
        value = layer.QueryTimeSample(path, 3)
        layer.SetTimeSample(path, 3, Gf.Vec3d(value[0], value[1], value[2] + 1e-12))

    assert first_difference(cache, _edited(cache, tmp_path, nudge)) == f"{path}: sample at 3.0 differs"


def test_changed_fields_specs_and_layer_data_are_found(cache, tmp_path):
    from pxr import Sdf

    def extent(layer):
        layer.GetAttributeAtPath("/World/ball/ball.extent").default = [(-1, -1, -1), (1, 1, 1)]

    assert first_difference(cache, _edited(cache, tmp_path, extent)) == "/World/ball/ball.extent: field default differs"

    def extra_prim(layer):
        Sdf.CreatePrimInLayer(layer, "/World/extra")

    assert first_difference(cache, _edited(cache, tmp_path, extra_prim)).startswith("spec paths differ")

    def end(layer):
        layer.endTimeCode = 3

    assert first_difference(cache, _edited(cache, tmp_path, end)) == "layer metadata endTimeCode differs"

    def summary(layer):
        data = dict(layer.customLayerData)
        data["note"] = "added"
        layer.customLayerData = data

    assert first_difference(cache, _edited(cache, tmp_path, summary)) == "customLayerData differs"
