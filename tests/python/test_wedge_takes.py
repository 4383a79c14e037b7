"""The takes of a wedge without a cluster (simbake.wedge_takes): values, key paths applied
through the scene file's own validation, the cartesian product, seeds, USD override layers."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import pytest

from simbake.errors import SceneError
from simbake import load_scene
from simbake.wedge_takes import (POSITION_JITTER, YAW_JITTER, Take, check_keys, parse_set, perturb, plan_takes,
                                 take_scene, toml_scene)

REPO = Path(__file__).resolve().parents[2]

SCENE = """
[scene]
end_frame = 5
[ground]
[[bodies]]
name = "ball"
shape = { type = "sphere", radius = 0.2 }
position = [0.0, 1.0, 0.0]
[[bodies]]
name = "post"
shape = { type = "box", size = [0.1, 1.0, 0.1] }
position = [1.0, 0.5, 0.0]
kinematic = true
[[cloths]]
name = "sheet"
grid = { size = [1.0, 1.0], resolution = [4, 4] }
position = [0.0, 2.0, 0.0]
"""


@pytest.fixture
def scene(write_scene) -> str:
    return str(write_scene(SCENE))


@pytest.mark.parametrize("text, key, values", [
    ("bodies.ball.restitution=0.2,0.5", "bodies.ball.restitution", [0.2, 0.5]),
    ("cloths.sheet.compression=enforce,none", "cloths.sheet.compression", ["enforce", "none"]),
    ('cloths.sheet.compression="subgrid"', "cloths.sheet.compression", ["subgrid"]),
    ("bodies.ball.position=[0, 1, 0], [1.5, 2, 0]", "bodies.ball.position", [[0, 1, 0], [1.5, 2, 0]]),
    ("cloths.sheet.self_collision=true,false", "cloths.sheet.self_collision", [True, False]),
    ("scene.end_frame=12", "scene.end_frame", [12]),
])
def test_values_are_toml_split_at_top_level_commas(text, key, values):
    assert parse_set(text, "s.toml") == (key, values)


def test_takes_are_the_cartesian_product_in_order_last_key_fastest():
    takes = plan_takes({"a.x.y": [1, 2], "b.x.y": ["p", "q", "r"]}, 2, "s.toml")
    assert len(takes) == 12 and takes[0].name == "take_00" and takes[-1].name == "take_11"
    assert [(dict(t.settings)["a.x.y"], dict(t.settings)["b.x.y"], t.seed) for t in takes[:4]] == \
        [(1, "p", 0), (1, "p", 1), (1, "q", 0), (1, "q", 1)]
    assert takes[3].label() == "a.x.y=1 b.x.y=q seed=1"
    assert [t.name for t in plan_takes({"a.b.c": list(range(101))}, 1, "s")][-1] == "take_100"


def test_a_take_is_the_scene_file_with_its_values_validated_as_the_file_is(scene):
    varied = toml_scene(scene, [("bodies.ball.restitution", 0.7), ("cloths.sheet.grid.resolution", [6, 5]),
                                ("bodies.ball.shape.radius", 0.3), ("scene.end_frame", 9), ("solver.substeps", 4)])
    assert varied.bodies[0].restitution == 0.7 and varied.bodies[0].shape.radius == 0.3
    assert varied.cloths[0].grid_resolution == (6, 5) and varied.end_frame == 9 and varied.substeps == 4
    assert load_scene(scene).bodies[0].restitution == 0.0  # the file is not changed
    with pytest.raises(SceneError, match=r"bodies\[0\]\.restitution: must be in \[0, 1\], got 1.5"):
        toml_scene(scene, [("bodies.ball.restitution", 1.5)])
    with pytest.raises(SceneError, match=r"cloths\[0\]\.compression: unknown value 'crumple'"):
        toml_scene(scene, [("cloths.sheet.compression", "crumple")])
    with pytest.raises(SceneError, match=r"bodies\[1\]\.mass: must be a number, got string 'heavy'"):
        toml_scene(scene, [("bodies.post.mass", "heavy")])


@pytest.mark.parametrize("key, problem", [
    ("bodies.ghost.mass", "no body named 'ghost' (bodies: ball, post)"),
    ("cloths.cape.damping", "no cloth named 'cape' (cloths: sheet)"),
    ("bodies.ball.name", "unknown key 'name'"),
    ("bodies.ball.grid.size", "'grid' is not a table (tables: shape)"),
    ("bodies.post.shape.height", "unknown key 'height' (allowed: type, radius, size)"),
    ("world.gravity", "must be scene.KEY, solver.KEY"),
    ("scene.fps.x", "must be scene.KEY, solver.KEY"),
])
def test_keys_that_name_nothing_are_refused_before_any_bake(scene, key, problem):
    with pytest.raises(SceneError) as error:
        check_keys(scene, [key])
    assert str(error.value) == f"{scene}: --set {key}: {error.value.problem}" and problem in error.value.problem


def test_a_ground_key_needs_a_ground(write_scene):
    path = str(write_scene(SCENE.replace("[ground]\n", ""), "no_ground.toml"))
    with pytest.raises(SceneError, match="the scene has no \\[ground\\]"):
        check_keys(path, ["ground.friction"])


def test_seed_zero_is_the_scene_and_others_move_dynamic_things_a_little(scene):
    base = load_scene(scene)
    assert perturb(base, 0) is base
    one, again, two = perturb(base, 1), perturb(base, 1), perturb(base, 2)
    assert one == again and one != two  # the same seed, the same take
    ball, post, sheet = one.bodies[0], one.bodies[1], one.cloths[0]
    assert post == base.bodies[1]  # kinematic: left alone
    for moved, original in ((ball, base.bodies[0]), (sheet, base.cloths[0])):
        offset = [a - b for a, b in zip(moved.position, original.position)]
        assert offset[1] == 0 and 0 < max(abs(offset[0]), abs(offset[2])) <= POSITION_JITTER
        w, x, y, z = moved.orientation  # a turn about the vertical alone, within YAW_JITTER
        assert x == z == 0 and 0 < 2 * math.atan2(abs(y), w) <= YAW_JITTER


def test_a_shots_take_loads_its_override_layer(tmp_path):
    shot = Path(shutil.copy(REPO / "assets" / "scenes" / "shot.usda", tmp_path / "shot.usda"))
    types = check_keys(str(shot), ["/World/Props/Crate.physics:mass"])
    assert types == {"/World/Props/Crate.physics:mass": "float"}
    folder = tmp_path / "takes"
    folder.mkdir()
    take = Take("take_00", (("/World/Props/Crate.physics:mass", 20.0),), 0)
    varied = take_scene(str(shot), take, folder, types)
    def crate(scene):
        return next(b for b in scene.bodies if b.prim_path == "/World/Props/Crate")

    assert crate(varied).mass == 20.0 and crate(load_scene(shot)).mass == 8.0
    assert (folder / "take_00.over.usda").read_text().count("@../shot.usda@") == 1
    bad = Take("take_01", (("/World/Props/Crate.physics:mass", -1.0),), 0)
    with pytest.raises(SceneError, match=r"/World/Props/Crate.physics:mass: must be a finite number >= 0"):
        take_scene(str(shot), bad, folder, types)
    wrong = Take("take_02", (("/World/Props/Crate.physics:mass", "heavy"),), 0)
    with pytest.raises(SceneError, match=r"/World/Props/Crate.physics:mass: cannot be set to heavy \(a float\)"):
        take_scene(str(shot), wrong, folder, types)


def test_seeds_need_something_to_move(write_scene, tmp_path):
    from simbake.wedge_run import plan_wedge

    still = write_scene("""
        [scene]
        end_frame = 3
        [[bodies]]
        name = "post"
        shape = { type = "box", size = [0.1, 1.0, 0.1] }
        kinematic = true
    """, "still.toml")
    with pytest.raises(SceneError, match="--seeds: the scene has no dynamic body or cloth for a seed to move"):
        plan_wedge(still, {"bodies.post.friction": [0.1, 0.2]}, tmp_path / "w.usda", seeds=2)
    assert plan_wedge(still, {"bodies.post.friction": [0.1, 0.2]}, tmp_path / "w.usda").takes[1].seed == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["still.toml"]  # planning writes nothing
