"""--clips N: value-clip layers stitched by the output read back as a single-file cache."""

from __future__ import annotations

import math

import numpy as np
import pytest

from simbake.cli import main

from pxr import Usd, UsdValidation

SCENE = """
[scene]
end_frame = 12
[ground]
[[bodies]]
name = "ball"
shape = { type = "sphere", radius = 0.2 }
position = [0.0, 1.0, 0.0]
angular_velocity = [0.0, 3.0, 1.0]
[[bodies]]
name = "other_ball"
shape = { type = "sphere", radius = 0.2 }
position = [0.5, 1.5, 0.0]
[[bodies]]
name = "slab"
shape = { type = "box", size = [1.0, 0.2, 1.0] }
position = [2.0, 0.1, 0.0]
kinematic = true
[[cloths]]
name = "sheet"
grid = { size = [1.0, 1.0], resolution = [5, 5] }
position = [2.0, 0.5, 0.0]
"""


def _values(stage, time):
    """Every attribute's value at `time`: float arrays where numeric (quaternions as w, x, y, z)."""
    out = {}
    for prim in stage.Traverse():
        for attr in prim.GetAttributes():
            value = attr.Get(time)
            if value is None:
                continue
            if hasattr(value, "GetReal"):
                value = [value.GetReal(), *value.GetImaginary()]
            elif hasattr(value, "__len__") and len(value) and hasattr(value[0], "GetReal"):
                value = [[q.GetReal(), *q.GetImaginary()] for q in value]
            try:
                out[str(attr.GetPath())] = np.array(value, dtype=np.float64)
            except (TypeError, ValueError):
                out[str(attr.GetPath())] = value
    return out


@pytest.mark.parametrize("clip_frames, instancing", [(5, "never"), (1, "always"), (20, "never")])
def test_clips_read_back_as_the_single_file(tmp_path, clip_frames, instancing):
    (tmp_path / "s.toml").write_text(SCENE)
    single, clipped = tmp_path / "single.usdc", tmp_path / "clipped.usda"
    assert main(["bake", str(tmp_path / "s.toml"), "-o", str(single), "--instancing", instancing, "-q"]) == 0
    assert main(["bake", str(tmp_path / "s.toml"), "-o", str(clipped), "--instancing", instancing,
                 "--clips", str(clip_frames), "-q"]) == 0
    clips = sorted((tmp_path / "clipped.clips").glob("clip.*.usdc"))
    assert len(clips) == math.ceil((12 - 1) / clip_frames)  # each shares its last frame with the next
    assert {p.name for p in (tmp_path / "clipped.clips").iterdir()} == \
        {p.name for p in clips} | {"topology.usdc", "manifest.usda"}
    a, b = Usd.Stage.Open(str(single)), Usd.Stage.Open(str(clipped))
    assert (b.GetTimeCodesPerSecond(), b.GetStartTimeCode(), b.GetEndTimeCode()) == (24, 1, 12)
    assert b.GetRootLayer().customLayerData["simbake"]["qa"]["warnings"] == 0
    for time in [f for f in range(1, 13)] + [5.5, 6.25, 11.5]:  # whole frames, and between them
        va, vb = _values(a, time), _values(b, time)
        assert va.keys() == vb.keys()
        for key, value in va.items():
            if isinstance(value, np.ndarray) and value.dtype.kind == "f":
                # the same samples; between frames the same interpolation (to round-off)
                np.testing.assert_allclose(vb[key], value, rtol=0, atol=1e-12, err_msg=f"{key} at {time}")
            else:
                assert vb[key] == value, key
    # the clipped output and every layer it wrote validate clean, and pass simbake check
    context = UsdValidation.ValidationContext(UsdValidation.ValidationRegistry().GetOrLoadAllValidators())
    for path in [clipped, *clips, tmp_path / "clipped.clips" / "topology.usdc"]:
        assert [e.GetMessage() for e in context.Validate(Usd.Stage.Open(str(path)))] == [], path
    assert main(["check", str(clipped)]) == 0


def test_a_second_bake_replaces_the_clips_and_leaves_no_temporaries(tmp_path):
    (tmp_path / "s.toml").write_text(SCENE)
    out = tmp_path / "c.usdc"
    assert main(["bake", str(tmp_path / "s.toml"), "-o", str(out), "--clips", "3", "-q"]) == 0
    assert main(["bake", str(tmp_path / "s.toml"), "-o", str(out), "--clips", "6", "-q"]) == 0
    assert len(list((tmp_path / "c.clips").glob("clip.*.usdc"))) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.clips", "c.qa.json", "c.usdc", "s.toml"]


@pytest.mark.parametrize("value", ["0", "-3"])
def test_bad_clip_lengths_are_one_line_errors(tmp_path, capsys, value):
    (tmp_path / "s.toml").write_text(SCENE)
    assert main(["bake", str(tmp_path / "s.toml"), "-o", str(tmp_path / "c.usdc"), "--clips", value, "-q"]) == 2
    err = capsys.readouterr().err
    assert "--clips: must be a whole number of frames >= 1" in err and err.count("\n") == 1
    assert not (tmp_path / "c.usdc").exists() and not (tmp_path / "c.clips").exists()
