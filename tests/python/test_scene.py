"""Scene file loading and validation (simbake.scene, scene file version 1)."""

from __future__ import annotations

import dataclasses
import math
import os
import textwrap
from pathlib import Path

import pytest

from simbake.errors import SceneError
from simbake import load_scene
from simbake.scene import Body, Cloth, Ground, Scene, Shape

# A tetrahedron: small, closed, enough for "the mesh file exists".
TETRA_OBJ = """\
v 0 0 0
v 1 0 0
v 0 1 0
v 0 0 1
f 1 3 2
f 1 2 4
f 1 4 3
f 2 3 4
"""

FULL_SCENE = """\
[scene]
fps = 30
start_frame = 0
end_frame = 59
gravity = [0.0, -10, 0.0]

[solver]
substeps = 4

[ground]
height = -0.5
friction = 0.8
restitution = 0.25

[[bodies]]
name = "ball"
shape = { type = "sphere", radius = 0.5 }
mass = 2
position = [0.0, 3.0, 0.0]
linear_velocity = [1.0, 0.0, 0.0]
restitution = 0.9

[[bodies]]
name = "crate"
shape = { type = "box", size = [1, 2, 3] }
orientation = [2.0, 0.0, 0.0, 0.0]
angular_velocity = [0.0, 1.5, 0.0]
kinematic = true
friction = 0.0

[[bodies]]
name = "rock"
mesh = "tetra.obj"
density = 2500.0
voxel_size = 0.01
orientation = [1, 1, 0, 0]

[[cloths]]
name = "sheet"
grid = { size = [2.0, 1.5], resolution = [8, 6] }
position = [0.0, 1.5, 0.0]
stretch_stiffness = 500
compression = "enforce"
pinned = [0, 7, 47]
"""


def write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(textwrap.dedent(text))
    return path


@pytest.fixture
def in_tmp(tmp_path, monkeypatch):
    """Work in tmp_path so scenes can be named by a relative path, as users do."""
    monkeypatch.chdir(tmp_path)
    write(tmp_path / "tetra.obj", TETRA_OBJ)
    return tmp_path


# ------------------------------------------------------------------------------------
# (a) a full valid scene, and defaults
# ------------------------------------------------------------------------------------


def test_full_scene_values(in_tmp):
    write(in_tmp / "full.toml", FULL_SCENE)
    scene = load_scene("full.toml")

    assert scene.path == (in_tmp / "full.toml").resolve()
    assert scene.path.is_absolute()
    assert scene.fps == 30.0 and isinstance(scene.fps, float)
    assert (scene.start_frame, scene.end_frame, scene.frame_count) == (0, 59, 60)
    assert scene.gravity == (0.0, -10.0, 0.0)
    assert all(isinstance(g, float) for g in scene.gravity)
    assert scene.substeps == 4
    assert scene.ground == Ground(height=-0.5, friction=0.8, restitution=0.25)

    ball, crate, rock = scene.bodies
    assert ball == Body(
        name="ball",
        shape=Shape(kind="sphere", radius=0.5),
        density=None,
        mass=2.0,
        position=(0.0, 3.0, 0.0),
        orientation=(1.0, 0.0, 0.0, 0.0),
        linear_velocity=(1.0, 0.0, 0.0),
        angular_velocity=(0.0, 0.0, 0.0),
        friction=0.5,
        restitution=0.9,
        kinematic=False,
        voxel_size=0.0,
    )
    assert crate.shape == Shape(kind="box", size=(1.0, 2.0, 3.0))
    assert crate.orientation == (1.0, 0.0, 0.0, 0.0)  # normalized
    assert (crate.density, crate.mass) == (1000.0, None)  # the default density
    assert crate.kinematic is True and crate.friction == 0.0
    assert crate.angular_velocity == (0.0, 1.5, 0.0)

    assert rock.shape.kind == "mesh"
    assert rock.shape.mesh_path == (in_tmp / "tetra.obj").resolve()
    assert (rock.density, rock.mass, rock.voxel_size) == (2500.0, None, 0.01)
    h = 1 / math.sqrt(2)
    assert rock.orientation == pytest.approx((h, h, 0.0, 0.0))

    (sheet,) = scene.cloths
    assert sheet == Cloth(
        name="sheet",
        grid_size=(2.0, 1.5),
        grid_resolution=(8, 6),
        mesh_path=None,
        position=(0.0, 1.5, 0.0),
        orientation=(1.0, 0.0, 0.0, 0.0),
        stretch_stiffness=500.0,
        compression="enforce",
        pinned=(0, 7, 47),
    )
    assert sheet.area_density == 0.1 and sheet.bend_stiffness == 1e-4
    assert sheet.damping == 0.01 and sheet.strain_limit == 0.1
    assert sheet.friction == 0.3 and sheet.thickness == 0.005


def test_minimal_scene_defaults(in_tmp):
    write(in_tmp / "min.toml", "[scene]\nend_frame = 10\n")
    scene = load_scene(in_tmp / "min.toml")  # a Path works too
    assert (scene.fps, scene.start_frame, scene.end_frame) == (24.0, 1, 10)
    assert scene.frame_count == 10
    assert scene.gravity == (0.0, -9.81, 0.0)
    assert scene.substeps == 0
    assert scene.ground is None
    assert scene.bodies == () and scene.cloths == ()


def test_empty_ground_table_means_default_ground(in_tmp):
    write(in_tmp / "g.toml", "[scene]\nend_frame = 1\n[ground]\n")
    assert load_scene("g.toml").ground == Ground()


def test_single_frame_and_cloth_mesh(in_tmp):
    write(
        in_tmp / "c.toml",
        """\
        [scene]
        start_frame = 5
        end_frame = 5
        [[cloths]]
        name = "flag"
        mesh = "tetra.obj"
        pinned = [1000]
        """,
    )
    scene = load_scene("c.toml")
    assert scene.frame_count == 1
    (flag,) = scene.cloths
    assert flag.mesh_path == (in_tmp / "tetra.obj").resolve()
    assert flag.grid_size is None and flag.grid_resolution is None
    assert flag.pinned == (1000,)  # a mesh's vertex count is not known here


def test_cloth_self_collision_is_on_unless_turned_off(in_tmp):
    write(in_tmp / "on.toml", cloth(""))
    write(in_tmp / "off.toml", cloth("self_collision = false"))
    assert load_scene("on.toml").cloths[0].self_collision is True
    assert load_scene("off.toml").cloths[0].self_collision is False


def test_result_is_frozen(in_tmp):
    write(in_tmp / "full.toml", FULL_SCENE)
    scene = load_scene("full.toml")
    with pytest.raises(dataclasses.FrozenInstanceError):
        scene.fps = 12.0  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        scene.bodies[0].mass = 1.0  # type: ignore[misc]


# ------------------------------------------------------------------------------------
# (b) mesh paths are relative to the scene file
# ------------------------------------------------------------------------------------


def test_relative_mesh_path_resolves_against_scene_dir(tmp_path, monkeypatch):
    mesh = write(tmp_path / "assets" / "meshes" / "rock.obj", TETRA_OBJ)
    scene_file = write(
        tmp_path / "assets" / "scenes" / "shot.toml",
        """\
        [scene]
        end_frame = 2
        [[bodies]]
        name = "rock"
        mesh = "../meshes/rock.obj"
        [[cloths]]
        name = "cloth"
        mesh = "../meshes/rock.obj"
        """,
    )
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)  # the working directory must not matter
    scene = load_scene(os.path.relpath(scene_file))
    assert scene.path == scene_file.resolve()
    assert scene.bodies[0].shape.mesh_path == mesh.resolve()
    assert scene.bodies[0].shape.mesh_path.is_absolute()
    assert scene.cloths[0].mesh_path == mesh.resolve()


def test_absolute_mesh_path_is_kept(tmp_path):
    mesh = write(tmp_path / "m" / "rock.obj", TETRA_OBJ)
    scene_file = write(
        tmp_path / "s" / "shot.toml",
        f'[scene]\nend_frame = 2\n[[bodies]]\nname = "rock"\nmesh = "{mesh.as_posix()}"\n',
    )
    assert load_scene(scene_file).bodies[0].shape.mesh_path == mesh.resolve()


# ------------------------------------------------------------------------------------
# (c) bad input: one case per rule
# ------------------------------------------------------------------------------------

HEAD = "[scene]\nend_frame = 10\n"
BALL = '[[bodies]]\nname = "ball"\nshape = { type = "sphere", radius = 0.5 }\n'
SHEET = '[[cloths]]\nname = "sheet"\ngrid = { size = [1, 1], resolution = [8, 8] }\n'


def body(extra: str, shape: str = 'shape = { type = "sphere", radius = 0.5 }') -> str:
    return f'{HEAD}[[bodies]]\nname = "ball"\n{shape}\n{extra}\n'


def cloth(extra: str, grid: str = "grid = { size = [1, 1], resolution = [8, 8] }") -> str:
    return f'{HEAD}[[cloths]]\nname = "sheet"\n{grid}\n{extra}\n'


# (id, scene text, exact key path, a word the problem must contain)
BAD_CASES = [
    # unknown keys, at every level
    ("unknown-table", HEAD + "[physics]\ndt = 0.1\n", "physics", "unknown key"),
    ("unknown-scene-key", HEAD + "fsp = 24\n", "scene.fsp", "unknown key"),
    ("unknown-solver-key", HEAD + "[solver]\niterations = 3\n", "solver.iterations", "unknown"),
    ("unknown-ground-key", HEAD + "[ground]\nheigth = 0\n", "ground.heigth", "unknown"),
    ("unknown-body-key", body("colour = 'red'"), "bodies[0].colour", "unknown"),
    ("unknown-shape-key", body("", 'shape = { type = "sphere", radius = 1, size = [1, 1, 1] }'),
     "bodies[0].shape.size", "unknown"),
    ("unknown-cloth-key", cloth("stiffness = 3"), "cloths[0].stiffness", "unknown"),
    ("unknown-grid-key", cloth("", "grid = { size = [1, 1], resolution = [4, 4], dx = 1 }"),
     "cloths[0].grid.dx", "unknown"),
    # wrong types
    ("bool-is-not-a-number", "[scene]\nend_frame = 10\nfps = true\n", "scene.fps", "number"),
    ("string-is-not-a-number", body("mass = 'heavy'"), "bodies[0].mass", "number"),
    ("float-is-not-an-int", "[scene]\nend_frame = 1.5\n", "scene.end_frame", "integer"),
    ("whole-float-is-not-an-int", HEAD + "[solver]\nsubsteps = 2.0\n", "solver.substeps",
     "integer"),
    ("bool-is-not-an-int", "[scene]\nend_frame = true\n", "scene.end_frame", "integer"),
    ("float-resolution", cloth("", "grid = { size = [1, 1], resolution = [8.0, 8] }"),
     "cloths[0].grid.resolution[0]", "integer"),
    ("float-pinned", cloth("pinned = [0, 1.5]"), "cloths[0].pinned[1]", "integer"),
    ("int-is-not-a-bool", body("kinematic = 1"), "bodies[0].kinematic", "true or false"),
    ("name-not-a-string", HEAD + "[[bodies]]\nname = 3\nshape = { type = 'sphere', radius = 1 }\n",
     "bodies[0].name", "string"),
    ("mesh-not-a-string", body("", "mesh = 3"), "bodies[0].mesh", "string"),
    ("shape-not-a-table", body("", "shape = 'sphere'"), "bodies[0].shape", "table"),
    ("scene-not-a-table", "scene = 3\n", "scene", "table"),
    ("bodies-not-an-array", HEAD + "[bodies]\nname = 'x'\n", "bodies", "array of tables"),
    ("body-not-a-table", "bodies = [1]\n" + HEAD, "bodies[0]", "table"),
    ("vector-not-an-array", body("position = 1.0"), "bodies[0].position", "array"),
    ("vector-element-type", body("position = [0, 'up', 0]"), "bodies[0].position[1]", "number"),
    ("date-is-not-a-number", body("mass = 1979-05-27"), "bodies[0].mass", "number"),
    # NaN / infinity anywhere numeric
    ("nan-in-gravity", "[scene]\nend_frame = 10\ngravity = [0, nan, 0]\n", "scene.gravity[1]",
     "finite"),
    ("inf-friction", body("friction = inf"), "bodies[0].friction", "finite"),
    ("nan-fps", "[scene]\nend_frame = 10\nfps = nan\n", "scene.fps", "finite"),
    ("neg-inf-ground-height", HEAD + "[ground]\nheight = -inf\n", "ground.height", "finite"),
    ("nan-orientation", body("orientation = [nan, 0, 0, 0]"), "bodies[0].orientation[0]",
     "finite"),
    ("inf-mass", body("mass = inf"), "bodies[0].mass", "finite"),
    ("nan-cloth-damping", cloth("damping = nan"), "cloths[0].damping", "finite"),
    # vector lengths
    ("position-too-short", body("position = [0, 1]"), "bodies[0].position", "3 numbers"),
    ("velocity-too-long", body("linear_velocity = [0, 1, 2, 3]"), "bodies[0].linear_velocity",
     "3 numbers"),
    ("orientation-length", body("orientation = [1, 0, 0]"), "bodies[0].orientation", "4 numbers"),
    ("gravity-empty", "[scene]\nend_frame = 10\ngravity = []\n", "scene.gravity", "3 numbers"),
    ("grid-size-length", cloth("", "grid = { size = [1, 1, 1], resolution = [4, 4] }"),
     "cloths[0].grid.size", "2 numbers"),
    ("resolution-length", cloth("", "grid = { size = [1, 1], resolution = [4] }"),
     "cloths[0].grid.resolution", "2 integers"),
    # ranges
    ("fps-zero", "[scene]\nend_frame = 10\nfps = 0\n", "scene.fps", "> 0"),
    ("fps-negative", "[scene]\nend_frame = 10\nfps = -24\n", "scene.fps", "> 0"),
    ("end-before-start", "[scene]\nstart_frame = 10\nend_frame = 9\n", "scene.end_frame",
     ">= start_frame"),
    ("substeps-negative", HEAD + "[solver]\nsubsteps = -1\n", "solver.substeps", ">= 0"),
    ("ground-friction-negative", HEAD + "[ground]\nfriction = -0.1\n", "ground.friction", ">= 0"),
    ("ground-restitution-above-1", HEAD + "[ground]\nrestitution = 1.5\n", "ground.restitution",
     "[0, 1]"),
    ("body-friction-negative", body("friction = -1"), "bodies[0].friction", ">= 0"),
    ("body-restitution-negative", body("restitution = -0.5"), "bodies[0].restitution", "[0, 1]"),
    ("voxel-size-negative", body("voxel_size = -0.01"), "bodies[0].voxel_size", ">= 0"),
    ("mass-negative", body("mass = -1.0"), "bodies[0].mass", "must be > 0, got -1.0"),
    ("mass-zero-kinematic", body("mass = 0\nkinematic = true"), "bodies[0].mass", "> 0"),
    ("density-zero", body("density = 0"), "bodies[0].density", "> 0"),
    ("sphere-radius-zero", body("", 'shape = { type = "sphere", radius = 0 }'),
     "bodies[0].shape.radius", "> 0"),
    ("box-size-zero", body("", 'shape = { type = "box", size = [1, 0, 1] }'),
     "bodies[0].shape.size[1]", "> 0"),
    ("box-size-negative", body("", 'shape = { type = "box", size = [1, 1, -2] }'),
     "bodies[0].shape.size[2]", "> 0"),
    ("orientation-zero", body("orientation = [0, 0, 0, 0]"), "bodies[0].orientation", "non-zero"),
    ("strain-limit-negative", cloth("strain_limit = -0.1"), "cloths[0].strain_limit", ">= 0"),
    ("thickness-negative", cloth("thickness = -0.001"), "cloths[0].thickness", ">= 0"),
    ("area-density-zero", cloth("area_density = 0"), "cloths[0].area_density", "> 0"),
    ("stretch-stiffness-negative", cloth("stretch_stiffness = -1"), "cloths[0].stretch_stiffness",
     ">= 0"),
    ("bend-stiffness-negative", cloth("bend_stiffness = -1e-3"), "cloths[0].bend_stiffness",
     ">= 0"),
    ("damping-negative", cloth("damping = -0.01"), "cloths[0].damping", ">= 0"),
    ("cloth-friction-negative", cloth("friction = -0.3"), "cloths[0].friction", ">= 0"),
    ("grid-size-zero", cloth("", "grid = { size = [0, 1], resolution = [4, 4] }"),
     "cloths[0].grid.size[0]", "> 0"),
    ("resolution-below-2", cloth("", "grid = { size = [1, 1], resolution = [8, 1] }"),
     "cloths[0].grid.resolution[1]", ">= 2"),
    ("pinned-out-of-range", cloth("pinned = [0, 64]"), "cloths[0].pinned[1]", "out of range"),
    ("pinned-negative", cloth("pinned = [-1]"), "cloths[0].pinned[0]", ">= 0"),
    ("compression-unknown", cloth("compression = 'squash'"), "cloths[0].compression",
     "one of: subgrid, enforce, none"),
    # shapes
    ("shape-type-unknown", body("", 'shape = { type = "cone", radius = 1 }'),
     "bodies[0].shape.type", "unknown value 'cone'"),
    ("shape-type-missing", body("", "shape = { radius = 1 }"), "bodies[0].shape.type", "missing"),
    ("sphere-radius-missing", body("", 'shape = { type = "sphere" }'), "bodies[0].shape.radius",
     "missing"),
    ("box-size-missing", body("", 'shape = { type = "box" }'), "bodies[0].shape.size", "missing"),
    ("mesh-and-shape", body('mesh = "tetra.obj"'), "bodies[0].shape", "together with mesh"),
    ("neither-mesh-nor-shape", body("", ""), "bodies[0]", "either mesh"),
    ("density-and-mass", body("density = 1000\nmass = 2"), "bodies[0].mass",
     "together with density"),
    ("grid-and-mesh", cloth('mesh = "tetra.obj"'), "cloths[0].mesh", "together with grid"),
    ("neither-grid-nor-mesh", cloth("", ""), "cloths[0]", "either grid"),
    # required keys
    ("missing-scene-table", "[ground]\n", "scene", "missing required table"),
    ("missing-end-frame", "[scene]\nfps = 24\n", "scene.end_frame", "missing"),
    ("missing-body-name", HEAD + "[[bodies]]\nshape = { type = 'sphere', radius = 1 }\n",
     "bodies[0].name", "missing"),
    ("missing-cloth-name", HEAD + "[[cloths]]\ngrid = { size = [1, 1], resolution = [4, 4] }\n",
     "cloths[0].name", "missing"),
    ("missing-grid-size", cloth("", "grid = { resolution = [4, 4] }"), "cloths[0].grid.size",
     "missing"),
    # names
    ("name-starts-with-digit", body("").replace('"ball"', '"2ball"'), "bodies[0].name",
     "prim name"),
    ("name-with-space", body("").replace('"ball"', '"my ball"'), "bodies[0].name", "prim name"),
    ("name-with-dash", cloth("").replace('"sheet"', '"bed-sheet"'), "cloths[0].name",
     "prim name"),
    ("name-empty", body("").replace('"ball"', '""'), "bodies[0].name", "prim name"),
    ("name-with-newline", body("").replace('"ball"', '"a\\nb"'), "bodies[0].name", "prim name"),
    ("name-world", body("").replace('"ball"', '"World"'), "bodies[0].name", "reserved"),
    ("duplicate-body-names", HEAD + BALL + BALL, "bodies[1].name", "duplicate"),
    ("duplicate-body-cloth-name", HEAD + BALL + SHEET.replace('"sheet"', '"ball"'),
     "cloths[0].name", "duplicate"),
    # files
    ("mesh-missing", body("", 'mesh = "nope/missing.obj"'), "bodies[0].mesh", "not found"),
    ("mesh-is-a-directory", body("", 'mesh = "."'), "bodies[0].mesh", "not a file"),
    ("mesh-empty-string", body("", 'mesh = ""'), "bodies[0].mesh", "empty"),
    ("cloth-mesh-missing", cloth("", 'mesh = "flag.obj"'), "cloths[0].mesh", "not found"),
    ("invalid-toml", "[scene\nend_frame = 10\n", "", "invalid TOML"),
    # cloth models
    ("cloth-unknown-model", cloth('model = "fem"'), "cloths[0].model", "one of"),
    ("cloth-bad-poisson", cloth("poisson_ratio = 0.5"), "cloths[0].poisson_ratio", "[0, 0.5)"),
    ("cloth-unknown-integrator", cloth('integrator = "rk4"'), "cloths[0].integrator", "one of"),
    ("cloth-self-collision-not-bool", cloth('self_collision = "yes"'), "cloths[0].self_collision", "true or false"),
    # keyed kinematic bodies
    ("keys-on-dynamic-body", body("keys = [{ time = 0.0 }]"), "bodies[0].keys", "kinematic"),
    ("keys-not-increasing", body("kinematic = true\nkeys = [{ time = 1.0 }, { time = 1.0 }]"),
     "bodies[0].keys[1].time", "later"),
    ("keys-empty", body("kinematic = true\nkeys = []"), "bodies[0].keys", "at least one"),
    ("key-without-time", body("kinematic = true\nkeys = [{ position = [0, 1, 0] }]"),
     "bodies[0].keys[0].time", "missing"),
    ("key-unknown-field", body("kinematic = true\nkeys = [{ time = 0.0, frame = 3 }]"),
     "bodies[0].keys[0].frame", "unknown"),
    ("key-bad-orientation", body("kinematic = true\nkeys = [{ time = 0.0, orientation = [0, 0, 0, 0] }]"),
     "bodies[0].keys[0].orientation", "non-zero"),
    ("duplicate-toml-key", "[scene]\nend_frame = 10\nend_frame = 11\n", "", "invalid TOML"),
]


@pytest.mark.parametrize(
    "text, key, word", [c[1:] for c in BAD_CASES], ids=[c[0] for c in BAD_CASES]
)
def test_bad_input(in_tmp, text, key, word):
    write(in_tmp / "bad.toml", text)
    with pytest.raises(SceneError) as info:
        load_scene("bad.toml")
    err = info.value
    message = str(err)
    assert "\n" not in message and "\r" not in message, message
    assert err.file == "bad.toml"
    assert err.key == key, message
    assert message.startswith(f"bad.toml: {key}: " if key else "bad.toml: "), message
    assert word in err.problem, message


def test_error_message_format(in_tmp):
    bodies = BALL + BALL.replace('"ball"', '"b1"') + BALL.replace('"ball"', '"b2"')
    write(in_tmp / "demo.toml", HEAD + bodies + "mass = -1.0\n")
    with pytest.raises(SceneError) as info:
        load_scene("demo.toml")
    assert str(info.value) == "demo.toml: bodies[2].mass: must be > 0, got -1.0"


def test_unknown_key_lists_allowed_keys(in_tmp):
    write(in_tmp / "bad.toml", HEAD + "[ground]\nmu = 0.5\n")
    with pytest.raises(SceneError, match=r"allowed: height, friction, restitution"):
        load_scene("bad.toml")


def test_missing_mesh_names_resolved_path(in_tmp):
    write(in_tmp / "scenes" / "bad.toml", body("", 'mesh = "../meshes/gone.obj"'))
    with pytest.raises(SceneError) as info:
        load_scene("scenes/bad.toml")
    assert str((in_tmp / "meshes" / "gone.obj").resolve()) in str(info.value)
    assert info.value.file == "scenes/bad.toml"


def test_unknown_key_with_newline_stays_one_line(in_tmp):
    write(in_tmp / "bad.toml", HEAD + '"evil\\nkey" = 1\n')
    with pytest.raises(SceneError) as info:
        load_scene("bad.toml")
    assert "\n" not in str(info.value)
    assert "unknown key" in str(info.value)


def test_file_not_found(in_tmp):
    with pytest.raises(SceneError) as info:
        load_scene("missing.toml")
    assert str(info.value) == "missing.toml: file not found"


def test_directory_is_not_a_scene(in_tmp):
    (in_tmp / "dir.toml").mkdir()
    with pytest.raises(SceneError, match=r"^dir\.toml: .*directory"):
        load_scene("dir.toml")


def test_not_utf8(in_tmp):
    (in_tmp / "bin.toml").write_bytes(b"[scene]\nend_frame = 10\n# \xff\xfe\n")
    with pytest.raises(SceneError, match=r"^bin\.toml: invalid TOML: not UTF-8"):
        load_scene("bin.toml")


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root reads anything")
def test_unreadable_file(in_tmp):
    path = write(in_tmp / "locked.toml", HEAD)
    path.chmod(0)
    try:
        with pytest.raises(SceneError, match=r"^locked\.toml: cannot read"):
            load_scene("locked.toml")
    finally:
        path.chmod(0o644)


# ------------------------------------------------------------------------------------
# (d) provenance hash
# ------------------------------------------------------------------------------------


def test_hash_stable_and_sensitive(in_tmp):
    scene_file = write(in_tmp / "full.toml", FULL_SCENE)
    first = load_scene("full.toml").hash()
    assert len(first) == 64 and int(first, 16) >= 0
    assert load_scene("full.toml").hash() == first  # reloading changes nothing
    assert load_scene(scene_file).hash() == first  # nor how the file is named

    (in_tmp / "tetra.obj").write_text(TETRA_OBJ + "# edited\n")
    assert load_scene("full.toml").hash() != first  # a referenced mesh changed

    (in_tmp / "tetra.obj").write_text(TETRA_OBJ)
    assert load_scene("full.toml").hash() == first  # and back

    scene_file.write_text(FULL_SCENE + "# a comment\n")
    assert load_scene("full.toml").hash() != first  # the scene file changed


def test_hash_ignores_unreferenced_files(in_tmp):
    write(in_tmp / "full.toml", FULL_SCENE)
    first = load_scene("full.toml").hash()
    write(in_tmp / "other.obj", TETRA_OBJ + "# not used\n")
    assert load_scene("full.toml").hash() == first


def test_hash_same_mesh_twice(in_tmp):
    two = (
        HEAD
        + '[[bodies]]\nname = "a"\nmesh = "tetra.obj"\n'
        + '[[bodies]]\nname = "b"\nmesh = "./tetra.obj"\n'
    )
    write(in_tmp / "two.toml", two)
    scene = load_scene("two.toml")
    assert scene.bodies[0].shape.mesh_path == scene.bodies[1].shape.mesh_path
    assert scene.hash() == scene.hash()


def test_scene_dataclass_is_keyword_only_with_defaults(tmp_path):
    scene = Scene(path=tmp_path / "x.toml", end_frame=3)
    assert (scene.fps, scene.start_frame, scene.frame_count) == (24.0, 1, 3)
    assert scene.ground is None and scene.bodies == () and scene.cloths == ()


def test_keys_default_to_the_body_pose(in_tmp):
    write(in_tmp / "keys.toml", body(
        'kinematic = true\nposition = [1, 2, 3]\norientation = [0, 1, 0, 0]\n'
        'keys = [{ time = 0.5 }, { time = 2.0, position = [4, 2, 3], orientation = [2, 0, 0, 0] }]'))
    keys = load_scene("keys.toml").bodies[0].keys
    assert [k.time for k in keys] == [0.5, 2.0]
    assert keys[0].position == (1.0, 2.0, 3.0) and keys[0].orientation == (0.0, 1.0, 0.0, 0.0)
    assert keys[1].position == (4.0, 2.0, 3.0) and keys[1].orientation == (1.0, 0.0, 0.0, 0.0)
