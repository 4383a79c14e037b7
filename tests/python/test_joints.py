"""Joints through the pipeline: TOML [[joints]] (errors naming the key), a bake recording its
breaks, the QA's joint error, a USD shot with a joint of every type (nothing left out, a
broken joint's physics:jointEnabled written false from the frame it broke), and the shipped
wrecking ball (the wall standing breaks nothing; the ball breaks it)."""

from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import simbake
from simbake.assets import load_assets
from simbake.errors import SceneError
from simbake.simulate import build_world

REPO = Path(__file__).resolve().parents[2]
SCENES = REPO / "assets" / "scenes"
SHOT = REPO / "tests" / "data" / "shots" / "joints.usda"

HANGING = """
[scene]
fps = 24
end_frame = 24
[[bodies]]
name = "block"
shape = { type = "box", size = [0.2, 0.2, 0.2] }
mass = 2.0
position = [0.0, -0.5, 0.0]
[[joints]]
name = "glue"
type = "fixed"
body1 = "block"
local_position1 = [0.0, 0.5, 0.0]
"""


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "scene.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("extra, key, problem", [
    ('type = "hinge"', "joints[0].type", "unknown value"),
    ('body0 = "nobody"', "joints[0].body0", "no body named"),
    ('cone_angle0 = 0.5', "joints[0].cone_angle0", "does not apply to a fixed joint"),
    ('break_force = -1.0', "joints[0].break_force", "must be > 0"),
    ('wobble = 1', "joints[0].wobble", "unknown key"),
])
def test_bad_joint_keys_name_the_key(tmp_path, extra, key, problem):
    text = HANGING.replace('type = "fixed"', extra) if extra.startswith("type") else HANGING + extra + "\n"
    with pytest.raises(SceneError) as error:
        simbake.load_scene(_write(tmp_path, text))
    message = str(error.value)
    assert key in message and problem in message and "\n" not in message


def test_bad_joint_exits_2_with_one_line(tmp_path):
    scene = _write(tmp_path, HANGING + 'axis = "w"\n')
    run = subprocess.run([sys.executable, "-m", "simbake", "bake", str(scene), "-o", str(tmp_path / "out.usdc")],
                         capture_output=True, text=True)
    assert run.returncode == 2
    assert run.stderr.strip().count("\n") == 0 and "joints[0].axis" in run.stderr
    assert not (tmp_path / "out.usdc").exists()


@pytest.mark.parametrize("factor, broken", [(1.05, False), (0.95, True)])
def test_break_recorded_in_custom_layer_data(tmp_path, factor, broken):
    """2 kg hanging: the glue carries m g = 19.62 N; 5% above holds, 5% below breaks at frame 2
    (the first stepped frame) and is recorded there."""
    text = HANGING + f"break_force = {factor * 2.0 * 9.81}\n"
    stats = simbake.bake(simbake.load_scene(_write(tmp_path, text)), tmp_path / "out.usdc", threads=1)
    from pxr import Usd

    stage = Usd.Stage.Open(str(stats.output))
    data = dict(stage.GetRootLayer().customLayerData)["simbake"]
    assert data.get("joints_broken", {}) == ({"glue": 2} if broken else {})
    qa = json.loads(stats.qa.read_text())
    assert "joint_error" in qa["summary"]
    assert qa["summary"]["joint_error"]["worst"] < 1e-6  # (a broken joint counts for nothing)


def test_shot_with_every_joint_type(tmp_path):
    scene = simbake.load_scene(SHOT)
    assert not [w for w in scene.warnings if "left out" in w]
    assert sorted(j.type for j in scene.joints) == ["d6", "distance", "fixed", "fixed", "prismatic", "revolute",
                                                    "spherical"]
    hinge = next(j for j in scene.joints if j.type == "revolute")
    assert hinge.axis == "y" and math.isclose(hinge.upper_limit, math.pi / 2)
    assert dict(hinge.drives)["angular"].target_velocity == pytest.approx(math.radians(45.0))
    assert scene.filtered_pairs == (("door", "slider"),)
    assert scene.group_filters == ((0,),) and {b for b, _ in scene.collision_groups} == {"bob", "bob2"}
    stats = simbake.bake(scene, tmp_path / "shot.cache.usda", threads=1, shot=tmp_path / "shot.sim.usda")
    from pxr import Usd

    stage = Usd.Stage.Open(str(tmp_path / "shot.sim.usda"))
    enabled = stage.GetPrimAtPath("/World/joints/weak").GetAttribute("physics:jointEnabled")
    assert enabled.Get(1) is True and enabled.Get(2) is False and enabled.Get(48) is False
    from simbake.cli import main

    assert main(["check", str(tmp_path / "shot.sim.usda")]) == 0  # (a sample at every frame)
    assert stage.GetPrimAtPath("/World/joints/glue").GetAttribute("physics:jointEnabled").Get(48) is True
    qa = json.loads(stats.qa.read_text())
    assert qa["summary"]["joint_error"]["worst"] < 1e-3
    # the limited hinge, driven at 45 deg/s, stops at its 90 degree limit (half a degree)
    door = stage.GetPrimAtPath("/World/door")
    from pxr import UsdGeom

    r = UsdGeom.Xformable(door).ComputeLocalToWorldTransform(48).ExtractRotationQuat()
    turned = math.degrees(2 * math.atan2(r.GetImaginary()[1], r.GetReal()))
    assert abs(turned) < 90.5


def test_wrecking_ball_wall_stands_then_breaks():
    scene = simbake.load_scene(SCENES / "wrecking_ball.toml")
    # the wall alone, 2 s: no glue breaks
    wall = [b for b in scene.bodies if b.name.startswith("brick")]
    alone = dataclasses.replace(scene, bodies=tuple(wall),
                                joints=tuple(j for j in scene.joints if j.name.startswith("glue")))
    world = build_world(alone, load_assets(alone), threads=1)
    for _ in range(48):
        world.step_frame(1 / 24)
    assert world.joint_states()["enabled"].all()
    # with the ball: it breaks glue when it hits (frame 27 of the shipped bake), not before
    world = build_world(scene, load_assets(scene), threads=1)
    broken_at = []
    for frame in range(2, 40):
        world.step_frame(1 / 24)
        broken_at.append(int((~world.joint_states()["enabled"]).sum()))
    assert broken_at[20] == 0 and broken_at[-1] >= 10


def test_same_bits_at_any_thread_count(tmp_path):
    """The shot with every joint type, baked on one thread and on two: the same cache content."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("same_bits", REPO / "benchmarks" / "same_bits.py")
    same_bits = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(same_bits)
    scene = simbake.load_scene(SHOT)
    for threads in (1, 2):
        (tmp_path / str(threads)).mkdir()
        simbake.bake(scene, tmp_path / str(threads) / "joints.usdc", threads=threads, qa=False)
    assert same_bits.first_difference(tmp_path / "1" / "joints.usdc", tmp_path / "2" / "joints.usdc") is None


def test_shot_clips_write_breaks_per_joint(tmp_path):
    """--clips on a shot: each broken joint's physics:jointEnabled reads, composed over the
    input, the same at every frame as in the single-file shot cache (the weak joint breaks)."""
    from pxr import Usd

    scene = simbake.load_scene(SHOT)
    simbake.bake(scene, tmp_path / "one.usda", threads=1, qa=False, shot=tmp_path / "one.sim.usda")
    simbake.bake(scene, tmp_path / "clips.usda", threads=1, qa=False, clips=10, shot=tmp_path / "clips.sim.usda")
    one, clipped = (Usd.Stage.Open(str(tmp_path / f"{n}.sim.usda")) for n in ("one", "clips"))
    joints = [j.prim_path for j in scene.joints]
    breaks = 0
    for path in joints:
        a, b = (s.GetPrimAtPath(path).GetAttribute("physics:jointEnabled") for s in (one, clipped))
        values = [a.Get(f) for f in range(scene.start_frame, scene.end_frame + 1)]
        assert values == [b.Get(f) for f in range(scene.start_frame, scene.end_frame + 1)], path
        breaks += values[-1] is False
    assert breaks == 1


def test_revolute_without_limits_is_free(tmp_path):
    """A revolute joint with no limits given turns freely (its limits are infinite); a finite
    limit outside [-pi, pi] is still an error naming the key."""
    free = HANGING.replace('type = "fixed"', 'type = "revolute"\naxis = "z"')
    joint = simbake.load_scene(_write(tmp_path, free)).joints[0]
    assert joint.lower_limit == -math.inf and joint.upper_limit == math.inf
    with pytest.raises(SceneError, match=r"joints\[0\]\.lower_limit: must be within \[-pi, pi\] rad"):
        simbake.load_scene(_write(tmp_path, free + "lower_limit = -4.0\n"))
