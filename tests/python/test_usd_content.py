"""USD shots as studios and Kit write them (issue 32): the frame range on the command line,
no silent loss of authored physics, body meshes under their own name, open and mirrored
static colliders, scaled parents, collision approximations, `simbake check` of what simbake
wrote. Every number is checked against an analytic answer or pxr's reading of the composed
stage.
"""

from __future__ import annotations

import textwrap
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import simbake
from simbake.cli import main

pxr = pytest.importorskip("pxr")
from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics  # noqa: E402

G = 9.81


def _write(path: Path, text: str) -> Path:
    path.write_text(textwrap.dedent(text).lstrip())
    return path


def _composed(shot: Path, cache: Path) -> Usd.Stage:
    """The input with the cache layer composed over it, as a --shot stage does."""
    stage = Usd.Stage.Open(str(shot))
    stage.GetSessionLayer().subLayerPaths.append(str(cache))
    return stage


def _world(stage, path, frame) -> np.ndarray:
    return np.array(UsdGeom.Xformable(stage.GetPrimAtPath(path)).ComputeLocalToWorldTransform(frame)).T


def _one_line_error(capsys, *words) -> str:
    err = capsys.readouterr().err.strip()
    assert err.startswith("simbake: error: ") and "\n" not in err and "Traceback" not in err, err
    for word in words:
        assert word in err, err
    return err


# a ball dropped in a Y-up metre stage; {range} is the layer's time metadata (or nothing)
FALL = """\
    #usda 1.0
    (
        defaultPrim = "World"
        {range}
        timeCodesPerSecond = 24
        upAxis = "Y"
        metersPerUnit = 1
    )
    def PhysicsScene "physicsScene"
    {{
    }}
    def Xform "World"
    {{
        def Sphere "ball" (prepend apiSchemas = ["PhysicsRigidBodyAPI", "PhysicsCollisionAPI"])
        {{
            double radius = 0.1
            {translate}
            uniform token[] xformOpOrder = ["xformOp:translate"]
        }}
    }}
"""


def _fall(path: Path, range_: str = "", translate: str = "double3 xformOp:translate = (0, 5, 0)") -> Path:
    return _write(path, FALL.format(range=range_, translate=translate))


def _height(stage, frame) -> float:
    return float(_world(stage, "/World/ball", frame)[1, 3])


# --------------------------------------------------------------------------------------------
# 1. --frames START:END
# --------------------------------------------------------------------------------------------

def test_a_stage_without_a_range_is_refused_naming_frames_and_bakes_with_it(tmp_path, capsys):
    """Kit writes no startTimeCode/endTimeCode (4 of PhysX's 7 test scenes): refused with a
    line naming --frames; with --frames the range is baked and the layer says so."""
    shot = _fall(tmp_path / "norange.usda")
    out = tmp_path / "c.usdc"
    assert main(["bake", str(shot), "-o", str(out), "-q"]) == 2
    _one_line_error(capsys, "norange.usda", "startTimeCode", "--frames START:END")
    assert not out.exists()
    assert main(["bake", str(shot), "-o", str(out), "-q", "--frames", "0:6"]) == 0
    layer = Sdf.Layer.FindOrOpen(str(out))
    assert (layer.startTimeCode, layer.endTimeCode) == (0.0, 6.0)
    stage = _composed(shot, out)
    assert _height(stage, 0) == 5.0  # the initial state at START
    # falling freely: below the start by at least 1/2 g t^2 (semi-implicit Euler falls
    # 1/2 g t (t + dt), dt <= 1/24 s) and at most 1/2 g t (t + 1/24)
    t = 6 / 24
    assert 0.5 * G * t * t - 1e-9 <= 5.0 - _height(stage, 6) <= 0.5 * G * t * (t + 1 / 24) + 1e-9


def test_kits_million_frame_default_is_refused_naming_frames_and_a_part_bakes(tmp_path, capsys):
    shot = _fall(tmp_path / "kit.usda", "startTimeCode = 0\n    endTimeCode = 1000000")
    out = tmp_path / "c.usdc"
    assert main(["bake", str(shot), "-o", str(out), "-q"]) == 2
    _one_line_error(capsys, "kit.usda", "endTimeCode", "1000001 frames", "budget", "--frames START:END")
    assert main(["bake", str(shot), "-o", str(out), "-q", "--frames", "10:13"]) == 0
    layer = Sdf.Layer.FindOrOpen(str(out))
    assert (layer.startTimeCode, layer.endTimeCode) == (10.0, 13.0)
    assert sorted(layer.ListAllTimeSamples()) == [10.0, 11.0, 12.0, 13.0]


def test_frames_start_at_the_stages_state_at_that_time_code(tmp_path):
    """An animated start pose (time samples on a dynamic body's translate, as Kit records a
    take): --frames 6:10 starts from the stage's value at time code 6, read by pxr."""
    shot = _fall(tmp_path / "anim.usda", "startTimeCode = 1\n    endTimeCode = 11",
                 "double3 xformOp:translate.timeSamples = { 1: (0, 5, 0), 11: (0, 10, 0) }")
    alone = Usd.Stage.Open(str(shot))
    start = float(_world(alone, "/World/ball", 6)[1, 3])
    assert start == pytest.approx(7.5, abs=1e-12)  # linear interpolation of the samples
    scene = simbake.load_scene(shot, start_frame=6, end_frame=10)
    assert (scene.start_frame, scene.end_frame, scene.bodies[0].position[1]) == (6, 10, start)
    out = tmp_path / "c.usda"
    stats = simbake.bake(replace(scene, substeps=10), out, qa=False)
    assert stats.frames == 5
    stage = _composed(shot, out)
    dt = 1 / 240
    for frame in range(6, 11):
        t = (frame - 6) / 24
        # semi-implicit Euler with a fixed step: exactly 1/2 g t (t + dt), round-off aside
        assert _height(stage, frame) == pytest.approx(start - 0.5 * G * t * (t + dt), abs=1e-9), frame


def test_python_bake_takes_start_and_end_frame(tmp_path):
    """simbake.bake(scene, out, start_frame=, end_frame=) overrides the scene's own range
    (a TOML scene: the initial state is written at the new start)."""
    toml = _write(tmp_path / "s.toml", """
        [scene]
        fps = 24
        end_frame = 100
        [[bodies]]
        name = "ball"
        shape = { type = "sphere", radius = 0.1 }
        position = [0.0, 5.0, 0.0]
        """)
    out = tmp_path / "c.usda"
    stats = simbake.bake(simbake.load_scene(toml), out, start_frame=20, end_frame=23, qa=False)
    assert stats.frames == 4
    layer = Sdf.Layer.FindOrOpen(str(out))
    assert (layer.startTimeCode, layer.endTimeCode) == (20.0, 23.0)
    stage = Usd.Stage.Open(str(out))
    assert _height(stage, 20) == 5.0
    t = 3 / 24  # semi-implicit Euler falls 1/2 g t (t + dt), dt <= 1/24 s
    assert 0.5 * G * t * t - 1e-9 <= 5.0 - _height(stage, 23) <= 0.5 * G * t * (t + 1 / 24) + 1e-9


@pytest.mark.parametrize("frames, words", [("a:b", "two whole frame numbers"), ("9:3", "END must be >= START"),
                                           ("5", "START:END")])
def test_bad_frames_are_one_line_errors(tmp_path, capsys, frames, words):
    shot = _fall(tmp_path / "f.usda")
    assert main(["bake", str(shot), "-o", str(tmp_path / "c.usdc"), "-q", "--frames", frames]) == 2
    _one_line_error(capsys, "f.usda", "--frames", words)
    assert not (tmp_path / "c.usdc").exists()


# --------------------------------------------------------------------------------------------
# 2. no silent loss: bindings without the API, unhonoured opinions once per name, Physx*
# --------------------------------------------------------------------------------------------

# OpenUSD's usdPhysicsSpheresWithMaterial.usda binds its material this way: a
# material:binding:physics relationship on prims without MaterialBindingAPI applied
BOUNCE = """\
    #usda 1.0
    (
        defaultPrim = "World"
        startTimeCode = 0
        endTimeCode = 30
        timeCodesPerSecond = 24
        upAxis = "Y"
        metersPerUnit = 1
    )
    def Xform "World"
    {
        def PhysicsScene "physicsScene"
        {
            vector3f physics:gravityDirection = (0, -1, 0)
            float physics:gravityMagnitude = 9.81
        }
        def Material "rubber" (prepend apiSchemas = ["PhysicsMaterialAPI"])
        {
            float physics:dynamicFriction = 0.5
            float physics:staticFriction = 0.5
            float physics:restitution = 0.8
        }
        def Plane "ground" (prepend apiSchemas = ["PhysicsCollisionAPI"])
        {
            uniform token axis = "Y"
            rel material:binding:physics = </World/rubber>
        }
        def Sphere "ball" (prepend apiSchemas = ["PhysicsRigidBodyAPI", "PhysicsCollisionAPI"])
        {
            double radius = 0.1
            rel material:binding:physics = </World/rubber>
            double3 xformOp:translate = (0, 1.1, 0)
            uniform token[] xformOpOrder = ["xformOp:translate"]
        }
    }
"""


def test_a_material_bound_without_the_api_is_read_with_one_warning(tmp_path, capsys):
    """e = 0.8 on both: the ball dropped from 1 m (its bottom) rebounds to e^2 h = 0.64 m. Had
    the binding been dropped (simbake's default restitution 0) it would land dead."""
    shot = _write(tmp_path / "bounce.usda", BOUNCE)
    out = tmp_path / "c.usdc"
    assert main(["bake", str(shot), "-o", str(out), "-q"]) == 0
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if "MaterialBindingAPI" in line]
    # one line for the two prims that bind without the API
    assert len(lines) == 1 and "material:binding:physics" in lines[0] and "(and 1 more prim)" in lines[0], err
    stage = _composed(shot, out)
    heights = np.array([_height(stage, f) - 0.1 for f in range(0, 31)])
    bounce = int(np.flatnonzero(np.diff(heights) > 0)[0])  # the first frame it rises after
    assert heights[bounce] < 0.1 and bounce < 14  # the ground, ~0.45 s after the drop
    # the apex is sampled at 24 fps: within 1/48 s of the top, 1/2 g (1/48)^2 = 2.1 mm low;
    # the impact resolved within a substep: 3% of the rebound height in all
    assert heights[bounce:24].max() == pytest.approx(0.8 ** 2 * 1.0, abs=0.02)  # apex ~0.81 s


def _kit_stage(path: Path) -> Path:
    """Kit-style: PhysX attributes on the scene and on three bodies, a joint, a trigger."""
    bodies = "".join(f"""
        def Cube "box{i}" (prepend apiSchemas = ["PhysicsRigidBodyAPI", "PhysicsCollisionAPI", "PhysxRigidBodyAPI"])
        {{
            double size = 0.2
            float physxRigidBody:linearDamping = 0.1
            float physxRigidBody:angularDamping = 0
            int physxRigidBody:solverPositionIterationCount = 16
            double3 xformOp:translate = ({i}, 5, 0)
            uniform token[] xformOpOrder = ["xformOp:translate"]
        }}""" for i in range(3))
    return _write(path, f"""
        #usda 1.0
        (
            defaultPrim = "World"
            startTimeCode = 0
            endTimeCode = 12
            timeCodesPerSecond = 24
            upAxis = "Y"
            metersPerUnit = 1
        )
        def Xform "World"
        {{
            def PhysicsScene "physicsScene" (prepend apiSchemas = ["PhysxSceneAPI"])
            {{
                uint physxScene:timeStepsPerSecond = 240
                bool physxScene:enableGPUDynamics = 0
            }}
            def PhysicsRevoluteJoint "hinge0"
            {{
                rel physics:body0 = </World/box0>
                rel physics:body1 = </World/box1>
            }}
            def PhysicsRevoluteJoint "hinge1"
            {{
                rel physics:body0 = </World/box1>
                rel physics:body1 = </World/box2>
            }}
            def Cube "sensor" (prepend apiSchemas = ["PhysicsCollisionAPI", "PhysxTriggerAPI"])
            {{
                double size = 0.5
                double3 xformOp:translate = (10, 0, 0)
                uniform token[] xformOpOrder = ["xformOp:translate"]
            }}
            {textwrap.indent(bodies, "    ").strip()}
        }}
        """)


def test_physx_attributes_map_or_are_warned_once_per_name(tmp_path, capsys):
    shot = _kit_stage(tmp_path / "kit.usda")
    scene = simbake.load_scene(shot)
    assert scene.substeps == 10  # physxScene:timeStepsPerSecond 240 at 24 time codes per second
    out = tmp_path / "c.usdc"
    assert main(["bake", str(shot), "-o", str(out), "-q"]) == 0
    err = capsys.readouterr().err.splitlines()

    def about(word):
        return [line for line in err if word in line]

    assert len(about("physxRigidBody:linearDamping")) == 1 and "(and 2 more prims)" in about("linearDamping")[0]
    assert len(about("physxRigidBody:solverPositionIterationCount")) == 1
    assert about("angularDamping") == [] and about("enableGPUDynamics") == []  # what simbake does anyway
    assert about("timeStepsPerSecond") == []  # read
    assert not [line for line in about("RevoluteJoint") if "left out" in line]  # simulated (issue 33)
    assert len(about("PhysxTriggerAPI")) == 1 and "/World/sensor" in about("PhysxTriggerAPI")[0]
    # ten fixed substeps a frame: semi-implicit Euler falls exactly 1/2 g t (t + 1/240)
    stage = _composed(shot, out)
    for frame in (6, 12):
        t = frame / 24
        y = float(_world(stage, "/World/box1", frame)[1, 3])
        assert y == pytest.approx(5.0 - 0.5 * G * t * (t + 1 / 240), abs=1e-9)


# --------------------------------------------------------------------------------------------
# 3. body meshes under the body's own name
# --------------------------------------------------------------------------------------------

def test_a_bodys_mesh_is_named_as_the_body(tmp_path):
    """Blender merges an Xform with its single child and names the object after the child:
    /World/ball/ball keeps the name 'ball' (it was 'mesh', 'mesh.001', ...). A body called
    'levelset' does not meet its level-set Volume."""
    toml = _write(tmp_path / "s.toml", """
        [scene]
        end_frame = 2
        [[bodies]]
        name = "ball"
        shape = { type = "sphere", radius = 0.25 }
        position = [0.0, 3.0, 0.0]
        [[bodies]]
        name = "levelset"
        shape = { type = "box", size = [1.0, 1.0, 1.0] }
        kinematic = true
        """)
    out = tmp_path / "c.usda"
    simbake.bake(simbake.load_scene(toml), out, qa=False)
    stage = Usd.Stage.Open(str(out))
    ball = stage.GetPrimAtPath("/World/ball")
    assert [c.GetName() for c in ball.GetChildren()] == ["ball"]
    points = np.array(UsdGeom.Mesh(ball.GetChild("ball")).GetPointsAttr().Get(), dtype=np.float64)
    # the cube-projected sphere's points lie on the sphere (float32 points: 1e-7 relative)
    np.testing.assert_allclose(np.linalg.norm(points, axis=1), 0.25, rtol=1e-6)
    box = UsdGeom.Mesh(stage.GetPrimAtPath("/World/levelset/levelset_mesh"))
    points = np.array(box.GetPointsAttr().Get(), dtype=np.float64)
    np.testing.assert_allclose(np.abs(points).max(axis=0), 0.5, rtol=1e-7)


# --------------------------------------------------------------------------------------------
# 4. static colliders as PhysX reads them; scaled parents of dynamic bodies
# --------------------------------------------------------------------------------------------

SHOTS = Path(__file__).resolve().parents[1] / "data" / "shots"

QUAD = """\
    #usda 1.0
    (
        defaultPrim = "World"
        startTimeCode = 1
        endTimeCode = {end}
        timeCodesPerSecond = 24
        metersPerUnit = 1
        upAxis = "Y"
    )
    def Xform "World"
    {{
        def PhysicsScene "physicsScene"
        {{
            float physics:gravityMagnitude = {gravity}
        }}
        def Mesh "quad" (prepend apiSchemas = ["PhysicsCollisionAPI"{offset_api}])
        {{
            int[] faceVertexCounts = [4]
            int[] faceVertexIndices = [0, 1, 2, 3]
            point3f[] points = [(-1, 0, -1), (1, 0, -1), (1, 0, 1), (-1, 0, 1)]
            {offset}
        }}
        def Sphere "ball" (prepend apiSchemas = ["PhysicsRigidBodyAPI", "PhysicsCollisionAPI"])
        {{
            double radius = 0.1
            vector3f physics:velocity = (0, {speed}, 0)
            double3 xformOp:translate = (0.2, {height}, 0.1)
            uniform token[] xformOpOrder = ["xformOp:translate"]
        }}
    }}
"""


def _quad(path, *, end=36, gravity=9.81, height=0.4, speed=0.0, rest_offset=None):
    offset = f"float physxCollision:restOffset = {rest_offset}" if rest_offset is not None else ""
    return _write(path, QUAD.format(end=end, gravity=gravity, height=height, speed=speed, offset=offset,
                                    offset_api=', "PhysxCollisionAPI"' if rest_offset is not None else ""))


@pytest.mark.parametrize("rest_offset, thickness", [(None, 0.01), (0.03, 0.03)])
def test_a_ball_rests_on_a_single_quad_ground_at_its_thickness(tmp_path, rest_offset, thickness):
    """An open quad is a two-sided surface of half-thickness t (1 cm, or PhysX's restOffset):
    the ball comes to rest with its centre r + t above it (the quad's grid: voxel t, its
    interpolated |d| within ~h/4 of the truth by the surface: 3 mm)."""
    shot = _quad(tmp_path / "quad.usda", rest_offset=rest_offset)
    scene = simbake.load_scene(shot)
    quad = next(b for b in scene.bodies if b.name == "quad")
    assert quad.kinematic and quad.shape.thickness == pytest.approx(thickness)
    out = tmp_path / "c.usdc"
    simbake.bake(scene, out, qa=False)
    stage = _composed(shot, out)
    assert _height(stage, 36) == pytest.approx(0.1 + thickness, abs=0.003)


def test_the_quad_is_two_sided(tmp_path):
    """No gravity; the ball starts under the quad moving up at 2 m/s: it must stop at the
    underside (centre -(r + t)) and never come through."""
    shot = _quad(tmp_path / "under.usda", gravity=0.0, height=-0.5, speed=2.0, end=24)
    out = tmp_path / "c.usdc"
    simbake.bake(simbake.load_scene(shot), out, qa=False)
    stage = _composed(shot, out)
    heights = [_height(stage, f) for f in range(1, 25)]
    assert max(heights) <= -(0.1 + 0.01) + 0.003
    assert max(heights) >= -(0.1 + 0.01) - 0.02  # it got there (0.39 m in 0.2 s)


def test_a_mirrored_kit_ground_cube_holds_the_ball(tmp_path, capsys):
    """Kit's ground: a Cube scaled (-500, 500, 10) cm, Z up, endTimeCode 1e6 (baked with
    --frames). Its top is z = 0: the 10 cm ball rests at z = 10 cm. The mirror is no
    refusal: a mirrored box is the same box."""
    shot = SHOTS / "kit_mirrored_ground.usda"
    out = tmp_path / "kit.usdc"
    assert main(["bake", str(shot), "-o", str(out), "-q", "--frames", "0:60"]) == 0
    stage = _composed(shot, out)
    z = float(_world(stage, "/World/Sphere", 60)[2, 3])  # centimetres
    assert z == pytest.approx(10.0, abs=0.3)
    ground = UsdGeom.Xformable(stage.GetPrimAtPath("/World/GroundCube")).ComputeLocalToWorldTransform(0)
    assert ground.GetDeterminant() < 0  # it is mirrored, as authored


def test_a_sheared_parent_is_baked_into_the_body_shape(tmp_path):
    """A Cube under a parent [scale (2, 1, 1), rotateZ 30]: its world transform is sheared.
    It falls rigidly (the composed linear part stays the authored one until it lands) and
    comes to rest with its visual corners, as pxr composes them, on the ground."""
    shot = SHOTS / "sheared_parent.usda"
    out = tmp_path / "c.usda"
    simbake.bake(replace(simbake.load_scene(shot), substeps=10), out, qa=False)
    alone = Usd.Stage.Open(str(shot))
    stage = _composed(shot, out)
    start = _world(alone, "/World/stretched/crate", 1)
    for frame in (1, 3):
        now = _world(stage, "/World/stretched/crate", frame)
        np.testing.assert_allclose(now[:3, :3], start[:3, :3], atol=1e-6)  # float64 matrices
        t = (frame - 1) / 24
        assert now[1, 3] == pytest.approx(start[1, 3] - 0.5 * G * t * (t + 1 / 240), abs=1e-9)
    corners = np.array([[x, y, z, 1.0] for x in (-0.1, 0.1) for y in (-0.1, 0.1) for z in (-0.1, 0.1)])
    end = _world(stage, "/World/stretched/crate", 24)
    lowest = (corners @ end.T)[:, 1].min()
    # on the ground: the contact tolerance and the QA's penetration threshold, a few mm
    assert -0.003 <= lowest <= 0.003
    # and it moved rigidly: the composed shape is the authored one, turned
    m = end[:3, :3] @ np.linalg.inv(start[:3, :3])
    np.testing.assert_allclose(m @ m.T, np.eye(3), atol=1e-6)


# --------------------------------------------------------------------------------------------
# 5. physics:approximation
# --------------------------------------------------------------------------------------------

def _notched_block():
    """A block 1 x 0.4 x 1 m (x, y, z) on y = 0 with a notch 0.4 wide and 0.3 deep down the
    middle of its top: closed, concave. Its hull and its box both have their top at y = 0.4;
    the notch's floor is at y = 0.1; its smallest enclosing sphere is centred at (0, 0.2, 0)
    with radius sqrt(0.5^2 + 0.2^2 + 0.5^2) (the block's corners)."""
    import trimesh

    outline = np.array([[-0.5, 0], [-0.2, 0], [0.2, 0], [0.5, 0], [0.5, 0.4], [0.2, 0.4], [0.2, 0.1],
                        [-0.2, 0.1], [-0.2, 0.4], [-0.5, 0.4]])
    caps = np.array([[0, 1, 7], [0, 7, 8], [0, 8, 9], [1, 2, 6], [1, 6, 7], [3, 4, 5], [3, 5, 6], [3, 6, 2]])
    mesh = trimesh.creation.extrude_triangulation(outline, caps, 1.0)
    v = np.asarray(mesh.vertices) - [0.0, 0.0, 0.5]
    assert mesh.is_watertight and mesh.volume == pytest.approx(0.4 - 0.12)
    return v, np.asarray(mesh.faces)


def _notch_shot(path: Path, approximation: str, drop: float) -> Path:
    v, f = _notched_block()
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, "Y")
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(30)
    stage.SetTimeCodesPerSecond(24)
    UsdPhysics.Scene.Define(stage, "/World/physicsScene")
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/World").GetPrim())
    block = UsdGeom.Mesh.Define(stage, "/World/block")
    block.CreatePointsAttr([Gf.Vec3f(*p) for p in v])
    block.CreateFaceVertexCountsAttr([3] * len(f))
    block.CreateFaceVertexIndicesAttr([int(i) for i in f.reshape(-1)])
    UsdPhysics.CollisionAPI.Apply(block.GetPrim())
    UsdPhysics.MeshCollisionAPI.Apply(block.GetPrim()).CreateApproximationAttr(approximation)
    ball = UsdGeom.Sphere.Define(stage, "/World/ball")
    ball.CreateRadiusAttr(0.1)
    ball.AddTranslateOp().Set(Gf.Vec3d(0, drop, 0))
    UsdPhysics.RigidBodyAPI.Apply(ball.GetPrim())
    UsdPhysics.CollisionAPI.Apply(ball.GetPrim())
    stage.GetRootLayer().Save()
    return path


SPHERE_TOP = 0.2 + float(np.sqrt(0.5 ** 2 + 0.2 ** 2 + 0.5 ** 2))


@pytest.mark.parametrize("approximation, rest", [
    ("convexHull", 0.4 + 0.1),           # on the hull, over the notch: not in it
    ("boundingCube", 0.4 + 0.1),
    ("boundingSphere", SPHERE_TOP + 0.1),
    ("none", 0.1 + 0.1),                 # the mesh itself: down in the notch
    ("meshSimplification", 0.1 + 0.1),
    ("convexDecomposition", 0.1 + 0.1),
    ("sdf", 0.1 + 0.1),
])
def test_each_approximation_is_the_shape_the_ball_rests_on(tmp_path, approximation, rest):
    """A ball dropped over the notch of a concave block: it rests on the hull (or box, or
    sphere) when the block is approximated so, in the notch when it is the mesh. Rest
    heights are the analytic tops plus the radius; 5 mm covers the block's level set
    (voxel 1/64 of a metre, ~0.2 voxel error at flat faces) and the resting contact."""
    shot = _notch_shot(tmp_path / "notch.usda", approximation, drop=rest + 0.15)
    out = tmp_path / "c.usdc"
    simbake.bake(simbake.load_scene(shot), out, qa=False)
    stage = _composed(shot, out)
    assert _height(stage, 30) == pytest.approx(rest, abs=0.005)
    assert abs(_world(stage, "/World/ball", 30)[0, 3]) < 0.01  # it stayed over the notch


# --------------------------------------------------------------------------------------------
# 6. simbake check judges what simbake authored; --strict adds the input's findings
# --------------------------------------------------------------------------------------------

def test_check_passes_a_kit_shot_and_strict_adds_the_inputs_findings(tmp_path, capsys):
    """The Kit-style input has an MDL asset that does not resolve here and a Mesh without an
    authored extent: OpenUSD's validators on the input alone find the first, our extent rule
    the second. Neither is simbake's: `check` passes the --shot stage; `--strict` fails it with
    exactly what pxr's validators say of the input, plus the extent."""
    shot_in = SHOTS / "kit_mirrored_ground.usda"
    cache, shot = tmp_path / "kit.usdc", tmp_path / "kit.shot.usda"
    assert main(["bake", str(shot_in), "-o", str(cache), "--shot", str(shot), "-q", "--frames", "0:6"]) == 0
    capsys.readouterr()
    assert main(["check", str(shot)]) == 0
    assert capsys.readouterr().out.strip() == f"{shot}: ok"
    assert main(["check", "--strict", str(shot)]) == 1
    out = capsys.readouterr().out
    from pxr import UsdValidation

    registry = UsdValidation.ValidationRegistry()
    alone = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators()).Validate(Usd.Stage.Open(str(shot_in)))
    errors = {e.GetIdentifier() for e in alone if e.GetType() == UsdValidation.ValidationErrorType.Error}
    assert any("UnresolvableDependency" in str(i) for i in errors)
    reported = {line.split("usd error: ")[1].split(" ")[0].rstrip(":") for line in out.splitlines() if "usd error: " in line}
    assert reported == {str(i) for i in errors}, (reported, errors)
    assert "/World/Decor/Cone: points without an authored extent" in out


# --------------------------------------------------------------------------------------------
# 7. the corpus: every scene under tests/data/shots bakes cleanly
# --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("shot", sorted(p.name for p in SHOTS.glob("*.usd*")))
def test_every_corpus_shot_bakes_without_refusal_or_loss(tmp_path, capsys, shot):
    """No refusal, no "left out" warning, nothing under the ground by more than the QA
    threshold, nothing NaN: 24 frames from each stage's start (or 0 when it has none)."""
    from simbake.qa import BODY_PENETRATION

    path = SHOTS / shot
    stage = Usd.Stage.Open(str(path))
    start = int(stage.GetStartTimeCode()) if stage.HasAuthoredTimeCodeRange() else 0
    cache = tmp_path / "c.usdc"
    assert main(["bake", str(path), "-o", str(cache), "-q", "--frames", f"{start}:{start + 24}"]) == 0
    err = capsys.readouterr().err
    assert "left out" not in err and "error" not in err, err
    composed = _composed(path, cache)
    mpu = UsdGeom.GetStageMetersPerUnit(composed)
    axis = 1 if UsdGeom.GetStageUpAxis(composed) == "Y" else 2
    for prim in composed.Traverse():
        if not prim.HasAPI(UsdPhysics.RigidBodyAPI) or not prim.IsA(UsdGeom.Gprim):
            continue
        for frame in range(start, start + 25):
            world = _world(composed, prim.GetPath(), frame)
            assert np.isfinite(world).all(), (prim.GetPath(), frame)
            # the lowest point of the body's bound (world, metres) is above the ground (z or y = 0)
            bound = UsdGeom.Imageable(prim).ComputeWorldBound(frame, "default").ComputeAlignedRange()
            assert bound.GetMin()[axis] * mpu >= -BODY_PENETRATION, (prim.GetPath(), frame, bound)


def test_same_open_collider_shot_same_bytes(tmp_path):
    """Same scene in, same bytes out: the open quad's shell grid (baked, not disk-cached) and
    the cache written beside it."""
    shot = SHOTS / "box_on_quad.usda"
    for run in ("a", "b"):  # one name in two folders: the level set's path is relative to it
        (tmp_path / run).mkdir()
        assert main(["bake", str(shot), "-o", str(tmp_path / run / "c.usdc"), "-q", "--frames", "1:6"]) == 0
    assert (tmp_path / "a" / "c.usdc").read_bytes() == (tmp_path / "b" / "c.usdc").read_bytes()
    vdbs = [sorted((tmp_path / run / "c.vdb").iterdir()) for run in ("a", "b")]
    assert [p.name for p in vdbs[0]] == [p.name for p in vdbs[1]] and vdbs[0]
    assert all(x.read_bytes() == y.read_bytes() for x, y in zip(*vdbs))
