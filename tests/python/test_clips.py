"""--clips N: value-clip layers stitched by the output read back as a single-file cache."""

from __future__ import annotations

import math
from pathlib import Path

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


# --------------------------------------------------------------------------------------------
# a USD shot's cache layer as clips
# --------------------------------------------------------------------------------------------

SHOTS = Path(__file__).resolve().parents[2] / "assets" / "scenes"


def _composed(stage, frame):
    """Every Xformable's composed world transform and every Mesh's points at `frame`."""
    from pxr import UsdGeom

    out = {}
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.Xformable):
            out[f"{prim.GetPath()} world"] = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(frame))
        if prim.IsA(UsdGeom.Mesh):
            for name in ("points", "normals", "velocities", "extent"):
                value = prim.GetAttribute(name).Get(frame)
                if value is not None:
                    out[f"{prim.GetPath()}.{name}"] = np.array(value, dtype=np.float64)
    return out


@pytest.mark.parametrize("shot, clip_frames", [("shot.usda", 10), ("shot_cm_zup.usda", 1)])
def test_a_shots_clips_read_back_as_its_single_file_cache(tmp_path, shot, clip_frames):
    """The --shot stage over clips: the same world transforms (bodies, the pusher, the level-set
    Volume) and cloth points as over the single-file shot cache, at every frame."""
    from pxr import Sdf

    single, clipped = tmp_path / "single.usdc", tmp_path / "clipped.usdc"
    assert main(["bake", str(SHOTS / shot), "-o", str(single), "--shot", str(tmp_path / "single_shot.usda"), "-q"]) == 0
    assert main(["bake", str(SHOTS / shot), "-o", str(clipped), "--shot", str(tmp_path / "clipped_shot.usda"),
                 "--clips", str(clip_frames), "-q"]) == 0
    folder = tmp_path / "clipped.clips"
    clips = sorted(folder.glob("clip.*.usdc"))
    a = Usd.Stage.Open(str(tmp_path / "single_shot.usda"))
    b = Usd.Stage.Open(str(tmp_path / "clipped_shot.usda"))
    start, end = int(a.GetStartTimeCode()), int(a.GetEndTimeCode())
    assert len(clips) == math.ceil((end - start) / clip_frames)
    assert {p.name for p in folder.iterdir()} == {p.name for p in clips} | {"topology.usdc", "manifest.usda"}
    assert (b.GetStartTimeCode(), b.GetEndTimeCode()) == (start, end)
    for frame in range(start, end + 1):
        va, vb = _composed(a, frame), _composed(b, frame)
        assert va.keys() == vb.keys()
        assert any(k.endswith("Sheet.points") for k in va)
        for key in va:
            np.testing.assert_array_equal(va[key], vb[key], err_msg=f"{key} at {frame}")
    # the output and every clip hold only overs at the input's prims (the level-set Volume is new)
    source = Usd.Stage.Open(str(SHOTS / shot))
    for path in [clipped, *clips, folder / "topology.usdc"]:
        layer = Sdf.Layer.FindOrOpen(str(path))
        specs = []
        layer.Traverse(Sdf.Path.absoluteRootPath, lambda p: specs.append(p) if p.IsPrimPath() else None)
        for p in specs:
            if "levelset" not in p.pathString:
                assert layer.GetPrimAtPath(p).specifier == Sdf.SpecifierOver and source.GetPrimAtPath(p), (path, p)
    assert Sdf.Layer.FindOrOpen(str(clipped)).pseudoRoot.GetInfo("upAxis") == source.GetRootLayer().pseudoRoot.GetInfo("upAxis")
    context = UsdValidation.ValidationContext(UsdValidation.ValidationRegistry().GetOrLoadAllValidators())
    assert [e.GetMessage() for e in context.Validate(b)] == []
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_the_same_clips_bake_gives_the_same_bytes(tmp_path):
    """Issue 30, 19: one of three identical --clips bakes wrote a topology.usdc with different
    bytes (same content): UsdUtils stitches clips in a parallel reduction whose order set the
    bytes. Many small clips (29 here) give it room to split differently from run to run (on
    main, two different topologies in four runs)."""
    import hashlib

    from test_cli import simbake

    text = (Path(__file__).resolve().parents[2] / "assets" / "scenes" / "tower.toml").read_text()
    (tmp_path / "tower.toml").write_text(text.replace("end_frame = 241", "end_frame = 30"))
    digests = set()
    for run in range(6):
        result = simbake("bake", "tower.toml", "-o", "t.usdc", "--clips", "1", "-q", cwd=tmp_path)
        assert result.returncode == 0, result.stderr
        files = [tmp_path / "t.usdc"] + [tmp_path / "t.clips" / n for n in ("topology.usdc", "manifest.usda")]
        digests.add(tuple(hashlib.sha256(f.read_bytes()).hexdigest() for f in files))
    assert len(digests) == 1
