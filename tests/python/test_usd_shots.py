"""USD shots in, cache layers out (DESIGN.md, cache version 2), checked with pxr on the files.

The shots come from assets/scenes/generate_shots.py (the shipped ones, or variants written
here); the equivalent TOML scene comes from the same description.
"""

from __future__ import annotations

import importlib.util
import math
from dataclasses import replace
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import simbake
from simbake.cli import main

pxr = pytest.importorskip("pxr")
from pxr import Sdf, Usd, UsdGeom, UsdPhysics, UsdValidation  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
SCENES = ROOT / "assets" / "scenes"
_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def _generator():
    spec = importlib.util.spec_from_file_location("generate_shots", SCENES / "generate_shots.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


shots = _generator()


def _world(stage, path, frame) -> np.ndarray:
    """A prim's composed local-to-world matrix (column vectors)."""
    return np.array(UsdGeom.Xformable(stage.GetPrimAtPath(path)).ComputeLocalToWorldTransform(frame)).T


def _quat_matrix(q) -> np.ndarray:
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _validation_errors(path) -> list[str]:
    registry = UsdValidation.ValidationRegistry()
    context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    return [f"{e.GetName()}: {e.GetMessage()}" for e in context.Validate(Usd.Stage.Open(str(path)))]


@pytest.fixture(scope="module")
def shipped(tmp_path_factory):
    """The shipped shots (m/Y-up and cm/Z-up) baked once: cache layers and --shot stages."""
    out = tmp_path_factory.mktemp("shipped")
    result = {}
    for name in ("shot", "shot_cm_zup"):
        cache, shot = out / f"{name}.cache.usdc", out / f"{name}.shot.usda"
        assert main(["bake", str(SCENES / f"{name}.usda"), "-o", str(cache), "--shot", str(shot), "-q"]) == 0
        result[name] = (cache, shot)
    return result


# --------------------------------------------------------------------------------------------
# input
# --------------------------------------------------------------------------------------------

def test_the_schema_is_registered_and_shipped_with_the_package():
    schemas = Path(simbake.__file__).parent / "schemas"
    assert {"plugInfo.json", "schema.usda", "generatedSchema.usda"} <= {p.name for p in schemas.iterdir()}
    definition = Usd.SchemaRegistry().FindAppliedAPIPrimDefinition("SimbakeClothAPI")
    assert definition is not None
    names = set(definition.GetPropertyNames())
    for attr in ("areaDensity", "model", "stretchStiffness", "poissonRatio", "bendStiffness", "damping",
                 "strainLimit", "compression", "integrator", "friction", "thickness", "pinned", "selfCollision"):
        assert f"simbake:cloth:{attr}" in names


def test_shipped_shots_are_what_the_generator_writes(tmp_path):
    for name, units, up in (("shot", "m", "Y"), ("shot_cm_zup", "cm", "Z")):
        shots.write_shot(tmp_path / f"{name}.usda", units, up)
        assert (tmp_path / f"{name}.usda").read_text() == (SCENES / f"{name}.usda").read_text()


def test_a_shot_loads_into_the_same_scene_as_its_toml(tmp_path):
    shot = shots.write_shot(tmp_path / "shot.usda", capsule=False)
    toml = tmp_path / "shot.toml"
    toml.write_text(shots.equivalent_toml())
    a, b = simbake.load_scene(shot), simbake.load_scene(toml)
    assert (a.fps, a.start_frame, a.end_frame, a.ground) == (b.fps, b.start_frame, b.end_frame, b.ground)
    np.testing.assert_allclose(a.gravity, b.gravity, rtol=0, atol=1e-15)
    by_name = {body.name: body for body in b.bodies}
    assert sorted(by_name) == sorted(body.name for body in a.bodies)
    for body in a.bodies:
        other = by_name[body.name]
        assert (body.shape.kind, body.mass, body.density, body.kinematic, body.friction, body.restitution) == \
            (other.shape.kind, other.mass, other.density, other.kinematic, other.friction, other.restitution)
        assert body.shape.size == pytest.approx(other.shape.size, abs=1e-15)
        assert body.shape.radius == other.shape.radius
        # double3 translates; quatf orients (float32) agree to a few float32 ulps
        # the props' quatf orient (float32, ~6e-8) places its children
        np.testing.assert_allclose(body.position, other.position, atol=2e-7)
        np.testing.assert_allclose(body.orientation, other.orientation, atol=3e-7)  # quatf: float32, not quite unit
        np.testing.assert_allclose(body.linear_velocity, other.linear_velocity, atol=1e-7)
        assert len(body.keys) == len(other.keys)
        for k, l in zip(body.keys, other.keys):
            assert k.time == pytest.approx(l.time, abs=1e-15)
            np.testing.assert_allclose(k.position, l.position, atol=1e-12)
    cloth, other = a.cloths[0], b.cloths[0]
    for field in ("area_density", "stretch_stiffness", "bend_stiffness", "thickness", "damping", "strain_limit",
                  "compression", "model", "integrator", "friction", "self_collision", "pinned"):
        assert getattr(cloth, field) == getattr(other, field), field
    from simbake.assets import load_cloth

    rest, grid = load_cloth(a, 0), load_cloth(b, 0)
    np.testing.assert_array_equal(rest.triangles, grid.triangles)
    np.testing.assert_allclose(rest.vertices, grid.vertices, atol=1e-7)  # point3f rest shape
    assert a.warnings == ()


# --------------------------------------------------------------------------------------------
# output, against the TOML path and known answers
# --------------------------------------------------------------------------------------------

def test_the_composed_shot_matches_a_bake_of_its_toml(tmp_path):
    end = 24
    shot = shots.write_shot(tmp_path / "shot.usda", capsule=False, end=end)
    toml = tmp_path / "shot.toml"
    toml.write_text(shots.equivalent_toml(end=end))
    assert main(["bake", str(shot), "-o", str(tmp_path / "cache.usdc"), "--shot", str(tmp_path / "out.usda"), "-q"]) == 0
    # The TOML bake starts from the very numbers the shot was read as (its quatf orients,
    # vector3f velocities and point3f rest shape are float32 round-offs of the TOML's), so that
    # what is compared is the cache layer and its composition, not how contacts amplify 1e-8.
    read = {body.name: body for body in simbake.load_scene(shot).bodies}
    typed = simbake.load_scene(toml)
    same_start = tuple(replace(body, position=read[body.name].position, orientation=read[body.name].orientation,
                               linear_velocity=read[body.name].linear_velocity,
                               angular_velocity=read[body.name].angular_velocity, keys=read[body.name].keys)
                       for body in typed.bodies)
    simbake.bake(replace(typed, bodies=same_start), tmp_path / "toml.usdc", qa=False)
    composed, reference = Usd.Stage.Open(str(tmp_path / "out.usda")), Usd.Stage.Open(str(tmp_path / "toml.usdc"))
    for frame in (1, 6, 12, 18, 24):
        for name, path in (("Crate", "/World/Props/Crate"), ("Ball", "/World/Props/Ball"), ("Pusher", "/World/Pusher")):
            world = _world(composed, path, frame)
            ref = _world(reference, f"/World/{name}", frame)
            # The same start: what is left is the layer's float/double round-off (1e-7 m)
            # and the cloth's float32 rest shape, which touches nothing the bodies touch.
            np.testing.assert_allclose(world[:3, 3], ref[:3, 3], atol=1e-5, err_msg=f"{name} at {frame}")
            np.testing.assert_allclose(world[:3, :3], ref[:3, :3], atol=1e-4, err_msg=f"{name} at {frame}")
        sheet = composed.GetPrimAtPath("/World/Sheet")
        local = np.array(UsdGeom.Mesh(sheet).GetPointsAttr().Get(frame), dtype=np.float64)
        m = _world(composed, "/World/Sheet", frame)
        ref_points = np.array(UsdGeom.Mesh(reference.GetPrimAtPath("/World/Sheet")).GetPointsAttr().Get(frame))
        # point3f in both caches (float32: 1e-7 m at these sizes), rest shapes 1e-8 apart
        np.testing.assert_allclose(local @ m[:3, :3].T + m[:3, 3], ref_points, atol=1e-5)


def _free_fall_shot(path: Path, units: str, up: str, frames: int = 13) -> Path:
    """One sphere, dropped from rest, nothing to hit."""
    mpu = {"m": 1.0, "cm": 0.01}[units]
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, up)
    UsdGeom.SetStageMetersPerUnit(stage, mpu)
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(frames)
    stage.SetTimeCodesPerSecond(24)
    UsdPhysics.Scene.Define(stage, "/PhysicsScene")
    ball = UsdGeom.Sphere.Define(stage, "/World/Ball")
    ball.CreateRadiusAttr(0.1 / mpu)
    start = np.array([0.3, 0.0, 0.2])
    start[1 if up == "Y" else 2] = 5.0
    ball.AddTranslateOp().Set(pxr.Gf.Vec3d(*(start / mpu)))
    UsdPhysics.RigidBodyAPI.Apply(ball.GetPrim())
    UsdPhysics.CollisionAPI.Apply(ball.GetPrim())
    stage.SetDefaultPrim(stage.GetPrimAtPath("/World"))
    stage.GetRootLayer().Save()
    return path


@pytest.mark.parametrize("units, up", [("m", "Y"), ("cm", "Z")])
def test_free_fall_from_a_shot_is_half_g_t_squared(tmp_path, units, up):
    shot = _free_fall_shot(tmp_path / "fall.usda", units, up)
    cache = tmp_path / "fall.cache.usda"
    # a fixed count: automatic substeps grow once the ball travels more than 0.2 of its
    # thickness in a 1/120 s substep (its last frames), and the closed form below needs one step
    stats = simbake.bake(replace(simbake.load_scene(shot), substeps=10), cache, qa=False)
    steps = stats.substeps / 12  # per frame
    assert steps == 10
    stage = Usd.Stage.Open(str(shot))  # the input, with the cache composed over it
    stage.GetSessionLayer().subLayerPaths.append(str(cache))
    mpu = {"m": 1.0, "cm": 0.01}[units]
    axis = 1 if up == "Y" else 2
    for frame in range(1, 14):
        t = (frame - 1) / 24.0
        dt = 1.0 / (24.0 * steps)
        height = _world(stage, "/World/Ball", frame)[axis, 3] * mpu
        # Semi-implicit Euler (velocity, then position) falls 1/2 g t^2 + 1/2 g t dt after
        # t / dt steps: first order in the step, exactly, so round-off is all that may differ
        # from the closed form; and within 1/2 g t dt of the true 1/2 g t^2.
        assert height == pytest.approx(5.0 - 0.5 * 9.81 * t * (t + dt), abs=1e-9), frame
        assert abs(height - (5.0 - 0.5 * 9.81 * t * t)) <= 0.5 * 9.81 * t * dt + 1e-9


def test_the_cm_z_up_shot_moves_as_the_m_y_up_one(shipped):
    metres = Usd.Stage.Open(str(shipped["shot"][1]))
    cms = Usd.Stage.Open(str(shipped["shot_cm_zup"][1]))
    for frame in range(1, shots.END + 1):
        for path in ("/World/Props/Crate", "/World/Props/Ball", "/World/Props/Pill", "/World/Pusher"):
            a, b = _world(metres, path, frame), _world(cms, path, frame)
            # the same physical pose: Z-up centimetres turned to Y-up metres
            # Inputs differ only by float32 round-off (the cm/Z-up quatf orients are other
            # numbers); contacts amplify it to ~0.1 mm by the end of the shot, well under a pixel.
            tol = 1e-7 if frame <= 10 else 1e-3  # before the first contact: round-off only
            np.testing.assert_allclose(a[:3, 3], _Z_UP @ b[:3, 3] * 0.01, atol=tol, err_msg=f"{path} at {frame}")
            np.testing.assert_allclose(a[:3, :3], _Z_UP @ b[:3, :3] @ _Z_UP.T, atol=10 * tol, err_msg=f"{path} at {frame}")
        pa = np.array(UsdGeom.Mesh(metres.GetPrimAtPath("/World/Sheet")).GetPointsAttr().Get(frame))
        pb = np.array(UsdGeom.Mesh(cms.GetPrimAtPath("/World/Sheet")).GetPointsAttr().Get(frame))
        ma, mb = _world(metres, "/World/Sheet", frame), _world(cms, "/World/Sheet", frame)
        np.testing.assert_allclose(pa @ ma[:3, :3].T + ma[:3, 3],
                                   (pb @ mb[:3, :3].T + mb[:3, 3]) @ _Z_UP.T * 0.01, atol=1e-5)


# --------------------------------------------------------------------------------------------
# the layer itself
# --------------------------------------------------------------------------------------------

def test_the_cache_layer_holds_only_overs_at_input_paths(shipped):
    for name, (cache, shot_stage) in shipped.items():
        layer = Sdf.Layer.FindOrOpen(str(cache))
        source = Usd.Stage.Open(str(SCENES / f"{name}.usda"))
        specs = []
        layer.Traverse(Sdf.Path.absoluteRootPath, lambda p: specs.append(p) if p.IsPrimPath() else None)
        assert specs
        for path in specs:
            if "levelset" in path.pathString:  # new prims: the capsule's level set as a guide Volume (beside it: a Gprim)
                assert path.pathString.startswith("/World/Props/Pill_levelset"), path
                assert layer.GetPrimAtPath(path).specifier == Sdf.SpecifierDef, path
                continue
            assert layer.GetPrimAtPath(path).specifier == Sdf.SpecifierOver, path
            assert source.GetPrimAtPath(path).IsValid(), path
        for meta in ("upAxis", "metersPerUnit", "kilogramsPerUnit"):
            assert layer.pseudoRoot.GetInfo(meta) == source.GetRootLayer().pseudoRoot.GetInfo(meta)
        assert (layer.timeCodesPerSecond, layer.startTimeCode, layer.endTimeCode, layer.defaultPrim) == \
            (24, 1, shots.END, "World")
        # dynamic bodies only, with their op order; kinematic and static ones are not repeated
        bodies = {str(p) for p in specs if layer.GetAttributeAtPath(p.AppendProperty("xformOpOrder"))
                  and "levelset" not in p.pathString}
        assert bodies == {"/World/Props/Crate", "/World/Props/Ball", "/World/Props/Pill"}
        for p in bodies:
            order = layer.GetAttributeAtPath(f"{p}.xformOpOrder").default
            assert list(order) == ["xformOp:translate", "xformOp:orient"]
            assert layer.GetNumTimeSamplesForPath(f"{p}.xformOp:translate") == shots.END
        for attr in ("points", "normals", "velocities", "extent"):
            assert layer.GetNumTimeSamplesForPath(f"/World/Sheet.{attr}") == shots.END


def test_openusd_validators_are_clean_on_every_layer_written(shipped):
    for name, (cache, shot_stage) in shipped.items():
        for path in (SCENES / f"{name}.usda", cache, shot_stage):
            assert _validation_errors(path) == [], path


def test_a_scaled_body_keeps_its_scale_under_a_scaled_parent(tmp_path):
    """xformOpOrder = translate, orient, scale: the composed pose is the body's, its scale kept."""
    stage = Usd.Stage.CreateNew(str(tmp_path / "scaled.usda"))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(7)
    stage.SetTimeCodesPerSecond(24)
    group = UsdGeom.Xform.Define(stage, "/World")
    group.AddTranslateOp().Set(pxr.Gf.Vec3d(1, 2, 3))
    group.AddRotateYOp().Set(30.0)
    group.AddScaleOp().Set(pxr.Gf.Vec3f(2, 2, 2))
    box = UsdGeom.Cube.Define(stage, "/World/Box")
    box.AddTranslateOp().Set(pxr.Gf.Vec3d(0, 1, 0))
    box.AddRotateXYZOp().Set(pxr.Gf.Vec3f(10, 20, 30))
    box.AddScaleOp().Set(pxr.Gf.Vec3f(1, 0.5, 2))
    UsdPhysics.RigidBodyAPI.Apply(box.GetPrim())
    UsdPhysics.CollisionAPI.Apply(box.GetPrim())
    stage.GetRootLayer().Save()
    scene = simbake.load_scene(tmp_path / "scaled.usda")
    assert scene.bodies[0].shape.size == pytest.approx((4.0, 2.0, 8.0))  # size 2 x scale x parent 2
    # (a fixed count of substeps: the closed form below needs every step alike)
    simbake.bake(replace(simbake.load_scene(tmp_path / "scaled.usda"), substeps=10), tmp_path / "c.usda",
                 shot=tmp_path / "s.usda")
    composed = Usd.Stage.Open(str(tmp_path / "s.usda"))
    start, fallen = _world(composed, "/World/Box", 1), _world(composed, "/World/Box", 7)
    np.testing.assert_allclose(start, _world(stage, "/World/Box", 1), atol=1e-6)  # frame 1 = input
    np.testing.assert_allclose(fallen[:3, :3], start[:3, :3], atol=1e-6)  # free fall: no turning
    t, dt = 6 / 24, 1 / 240  # semi-implicit Euler at 10 substeps a frame (see the free fall test)
    np.testing.assert_allclose(fallen[:3, 3] - start[:3, 3], [0, -0.5 * 9.81 * t * (t + dt), 0], atol=1e-6)


def test_same_shot_same_bytes(tmp_path):
    shot = SCENES / "shot.usda"
    for run in ("a", "b"):  # one name in two folders: the level set's path is relative to it
        (tmp_path / run).mkdir()
        assert main(["bake", str(shot), "-o", str(tmp_path / run / "c.usdc"), "-q"]) == 0
    assert (tmp_path / "a" / "c.usdc").read_bytes() == (tmp_path / "b" / "c.usdc").read_bytes()


# --------------------------------------------------------------------------------------------
# bad shots: one line, exit 2, nothing written
# --------------------------------------------------------------------------------------------

def _edit(tmp_path, edit, *, capsule=False, cloth=False) -> Path:
    shot = shots.write_shot(tmp_path / "bad.usda", capsule=capsule, cloth=cloth, end=4)
    stage = Usd.Stage.Open(str(shot))
    edit(stage)
    stage.GetRootLayer().Save()
    return shot


@pytest.mark.parametrize("edit, expected", [
    (lambda s: s.GetPrimAtPath("/World/Props/Crate").GetAttribute("physics:mass").Set(-2.0),
     "bad.usda: /World/Props/Crate.physics:mass: must be a finite number >= 0"),
    (lambda s: UsdGeom.Sphere(s.GetPrimAtPath("/World/Props/Ball")).GetRadiusAttr().Set(0.0),
     "bad.usda: /World/Props/Ball.radius: must be a finite number > 0, got 0.0"),
    (lambda s: s.GetPrimAtPath("/World/Looks/Rubber").GetAttribute("physics:restitution").Set(1.5),
     "bad.usda: /World/Looks/Rubber.physics:restitution: must be in [0, 1], got 1.5"),
    (lambda s: s.SetEndTimeCode(0.5),
     "bad.usda: endTimeCode: must be an integer time code, got 0.5"),
    (lambda s: s.GetPrimAtPath("/World/Props/Crate").GetAttribute("physics:velocity").Set(pxr.Gf.Vec3f(float("nan"), 0, 0))
     if s.GetPrimAtPath("/World/Props/Crate").GetAttribute("physics:velocity") else
     UsdPhysics.RigidBodyAPI(s.GetPrimAtPath("/World/Props/Crate")).CreateVelocityAttr(pxr.Gf.Vec3f(float("nan"), 0, 0)),
     "bad.usda: /World/Props/Crate.physics:velocity: must be finite"),
])
def test_bad_values_are_one_line_errors(tmp_path, capsys, edit, expected):
    shot = _edit(tmp_path, edit)
    out = tmp_path / "out.usdc"
    assert main(["bake", str(shot), "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"simbake: error: {tmp_path / 'bad.usda'}"[: len("simbake: error: ")] )
    assert expected in err and "\n" not in err, err
    assert not out.exists() and not list(tmp_path.glob(".*tmp*"))


def test_a_bad_cloth_attribute_names_it(tmp_path, capsys):
    shot = _edit(tmp_path, lambda s: s.GetPrimAtPath("/World/Sheet").GetAttribute(
        "simbake:cloth:compression").Set("squash"), cloth=True)
    assert main(["bake", str(shot), "-o", str(tmp_path / "o.usdc"), "-q"]) == 2
    err = capsys.readouterr().err.strip()
    assert "/World/Sheet.simbake:cloth:compression: unknown value 'squash'" in err and "\n" not in err


def test_unsupported_physics_is_warned_once_per_prim(tmp_path, capsys):
    """A cone collider is left out, warned once; a joint (issue 33) is simulated: no warning
    that it is left out (its frames, 1.4 m apart at the start, are pulled together: the QA's
    joint error names it)."""
    def add_joint_and_cone(stage):
        joint = UsdPhysics.RevoluteJoint.Define(stage, "/World/Hinge")
        joint.CreateBody0Rel().SetTargets(["/World/Props/Crate"])
        joint.CreateBody1Rel().SetTargets(["/World/Props/Ball"])
        joint.CreateAxisAttr("X")
        cone = UsdGeom.Cone.Define(stage, "/World/Cone")
        UsdPhysics.CollisionAPI.Apply(cone.GetPrim())

    shot = _edit(tmp_path, add_joint_and_cone)
    assert main(["bake", str(shot), "-o", str(tmp_path / "o.usdc"), "-q"]) == 0
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if "/World/Cone" in line]
    assert len(lines) == 1 and "cone" in lines[0] and ("not simulated" in lines[0] or "left out" in lines[0]), err
    hinge = [line for line in err.splitlines() if "Hinge" in line]
    assert len(hinge) == 1 and "joint error" in hinge[0] and "left out" not in hinge[0], err


def test_the_cache_never_overwrites_the_input(tmp_path, capsys):
    shot = shots.write_shot(tmp_path / "shot.usda", capsule=False, cloth=False, end=3)
    before = shot.read_bytes()
    for args in (["-o", str(shot)], ["-o", str(tmp_path / "c.usdc"), "--shot", str(shot)],
                 ["-o", str(tmp_path / "c.usdc"), "--shot", str(tmp_path / "c.usdc")]):
        assert main(["bake", str(shot), *args, "-q"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and ("would write over the input" in err or "must differ" in err), err
    assert shot.read_bytes() == before
    assert not (tmp_path / "c.usdc").exists()


def test_the_command_line_bakes_a_shot_with_a_default_name(tmp_path):
    shot = shots.write_shot(tmp_path / "shot.usda", capsule=False, cloth=False, end=3)
    result = subprocess.run([sys.executable, "-m", "simbake", "bake", str(shot), "-q"], cwd=tmp_path,
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "shot.cache.usdc").is_file()


# --------------------------------------------------------------------------------------------
# shapes and mass
# --------------------------------------------------------------------------------------------

def _stage(path: Path, *, units: str = "m", up: str = "Y", end: int = 7, gravity: bool = True):
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, up)
    UsdGeom.SetStageMetersPerUnit(stage, {"m": 1.0, "cm": 0.01}[units])
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(end)
    stage.SetTimeCodesPerSecond(24)
    scene = UsdPhysics.Scene.Define(stage, "/PhysicsScene")
    if not gravity:
        scene.CreateGravityMagnitudeAttr(0.0)
    UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(stage.GetPrimAtPath("/World"))
    return stage


def _body(prim, **mass):
    UsdPhysics.RigidBodyAPI.Apply(prim)
    UsdPhysics.CollisionAPI.Apply(prim)
    api = UsdPhysics.MassAPI.Apply(prim)
    for name, value in mass.items():
        getattr(api, f"Create{name}Attr")(value)
    return prim


def test_an_authored_centre_of_mass_is_what_spins_in_place(tmp_path):
    """No gravity, spinning at pi rad/s about +y: the centre of mass (0.1 m off the origin)
    stays put and the prim's origin circles it."""
    stage = _stage(tmp_path / "com.usda", gravity=False, end=13)
    ball = UsdGeom.Sphere.Define(stage, "/World/Ball")
    ball.CreateRadiusAttr(0.2)
    ball.AddTranslateOp().Set(pxr.Gf.Vec3d(0, 1, 0))
    _body(ball.GetPrim(), Mass=2.0, CenterOfMass=pxr.Gf.Vec3f(0.1, 0, 0))
    UsdPhysics.RigidBodyAPI(ball.GetPrim()).CreateAngularVelocityAttr(pxr.Gf.Vec3f(0, 180, 0))
    stage.GetRootLayer().Save()
    scene = simbake.load_scene(tmp_path / "com.usda")
    assert scene.bodies[0].center_of_mass == pytest.approx((0.1, 0.0, 0.0))
    assert scene.bodies[0].angular_velocity == pytest.approx((0.0, math.pi, 0.0))
    cache = tmp_path / "com.cache.usda"
    simbake.bake(scene, cache, qa=False)
    composed = Usd.Stage.Open(str(tmp_path / "com.usda"))
    composed.GetSessionLayer().subLayerPaths.append(str(cache))
    for frame in (1, 4, 7, 13):
        angle = math.pi * (frame - 1) / 24
        r = np.array([[math.cos(angle), 0, math.sin(angle)], [0, 1, 0], [-math.sin(angle), 0, math.cos(angle)]])
        m = _world(composed, "/World/Ball", frame)
        # torque-free spin about a principal axis is exact in the core: round-off only
        np.testing.assert_allclose(m[:3, :3], r, atol=1e-6)
        np.testing.assert_allclose(m[:3, 3], np.array([0.1, 1.0, 0.0]) - r @ [0.1, 0, 0], atol=1e-6)


def test_authored_inertia_converts_units_and_axes(tmp_path):
    stage = _stage(tmp_path / "inertia.usda", units="cm", up="Z")
    box = UsdGeom.Cube.Define(stage, "/World/Box")
    box.CreateSizeAttr(10.0)
    _body(box.GetPrim(), Mass=3.0, DiagonalInertia=pxr.Gf.Vec3f(1.0, 2.0, 3.0))
    stage.GetRootLayer().Save()
    body = simbake.load_scene(tmp_path / "inertia.usda").bodies[0]
    # kg cm^2 -> kg m^2 (1e-4); the stage's y and z axes become simbake's -z and y
    np.testing.assert_allclose(body.inertia, np.diag([1e-4, 3e-4, 2e-4]), atol=1e-12)
    assert body.mass == 3.0 and body.shape.size == pytest.approx((0.1, 0.1, 0.1))


def _cube_mesh(stage, path, size, *, open_face=False):
    h = size / 2
    points = [(-h, -h, -h), (h, -h, -h), (h, h, -h), (-h, h, -h), (-h, -h, h), (h, -h, h), (h, h, h), (-h, h, h)]
    faces = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (2, 3, 7, 6), (1, 2, 6, 5), (0, 4, 7, 3)]
    if open_face:
        faces = faces[:-1]
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr([pxr.Gf.Vec3f(*p) for p in points])
    mesh.CreateFaceVertexCountsAttr([4] * len(faces))
    mesh.CreateFaceVertexIndicesAttr([i for f in faces for i in f])
    return mesh


def test_mesh_capsule_and_cylinder_colliders_become_closed_meshes(tmp_path):
    import trimesh

    stage = _stage(tmp_path / "shapes.usda", end=3)
    mesh = _cube_mesh(stage, "/World/Brick", 0.5)
    mesh.AddTranslateOp().Set(pxr.Gf.Vec3d(0, 1, 0))
    mesh.AddScaleOp().Set(pxr.Gf.Vec3f(1, 2, 1))
    _body(mesh.GetPrim(), Density=200.0)
    can = UsdGeom.Cylinder.Define(stage, "/World/Can")
    can.CreateRadiusAttr(0.1)
    can.CreateHeightAttr(0.4)
    can.CreateAxisAttr("Z")
    can.AddTranslateOp().Set(pxr.Gf.Vec3d(2, 1, 0))
    _body(can.GetPrim())
    pill = UsdGeom.Capsule.Define(stage, "/World/Pill")
    pill.CreateRadiusAttr(0.1)
    pill.CreateHeightAttr(0.4)
    pill.CreateAxisAttr("Y")
    pill.AddTranslateOp().Set(pxr.Gf.Vec3d(-2, 1, 0))
    _body(pill.GetPrim())
    stage.GetRootLayer().Save()
    scene = simbake.load_scene(tmp_path / "shapes.usda")
    shapes = {b.name: b.shape for b in scene.bodies}
    volumes = {}
    for name, shape in shapes.items():
        assert shape.kind == "mesh", name
        m = trimesh.Trimesh(shape.mesh_vertices, shape.mesh_triangles)
        assert m.is_watertight and m.volume > 0, name
        volumes[name] = (m.volume, m.bounds)
    assert volumes["Brick"][0] == pytest.approx(0.5 * 1.0 * 0.5)  # scaled exactly
    np.testing.assert_allclose(volumes["Brick"][1], [[-0.25, -0.5, -0.25], [0.25, 0.5, 0.25]])
    # tessellated: 32 sides hold 99.4% of a circle's area, 24 x 24 a sphere's volume to ~1%
    assert volumes["Can"][0] == pytest.approx(math.pi * 0.01 * 0.4, rel=0.01)
    np.testing.assert_allclose(volumes["Can"][1][:, 2], [-0.2, 0.2])
    assert volumes["Pill"][0] == pytest.approx(math.pi * 0.01 * 0.4 + 4 / 3 * math.pi * 0.001, rel=0.015)
    np.testing.assert_allclose(volumes["Pill"][1][:, 1], [-0.3, 0.3], atol=1e-9)
    assert scene.bodies[0].density == 200.0
    assert main(["bake", str(tmp_path / "shapes.usda"), "-o", str(tmp_path / "shapes.cache.usdc"), "-q"]) == 0


def test_an_open_collider_mesh_is_an_error(tmp_path, capsys):
    stage = _stage(tmp_path / "open.usda", end=3)
    _body(_cube_mesh(stage, "/World/Box", 0.5, open_face=True).GetPrim())
    stage.GetRootLayer().Save()
    assert main(["bake", str(tmp_path / "open.usda"), "-o", str(tmp_path / "o.usdc"), "-q"]) == 2
    err = capsys.readouterr().err
    assert "/World/Box.faceVertexIndices: a collider mesh must be closed" in err and err.count("\n") == 1


def test_cloth_velocities_carry_each_frame_onto_the_next(shipped):
    """Motion blur: points + velocities / fps is the next frame's points (stage units)."""
    for name, (cache, _) in shipped.items():
        layer_stage = Usd.Stage.Open(str(SCENES / f"{name}.usda"))
        layer_stage.GetSessionLayer().subLayerPaths.append(str(cache))
        mesh = UsdGeom.Mesh(layer_stage.GetPrimAtPath("/World/Sheet"))
        unit = 1.0 / UsdGeom.GetStageMetersPerUnit(layer_stage)  # stage units per metre
        moved = 0.0
        for frame in range(1, shots.END):
            p0 = np.array(mesh.GetPointsAttr().Get(frame), dtype=np.float64)
            p1 = np.array(mesh.GetPointsAttr().Get(frame + 1), dtype=np.float64)
            v = np.array(mesh.GetVelocitiesAttr().Get(frame), dtype=np.float64)
            # float32 points a few metres from the origin: ~5e-7 m each
            np.testing.assert_allclose(p0 + v / 24.0, p1, atol=2e-6 * unit, err_msg=f"{name} {frame}")
            moved = max(moved, np.abs(p1 - p0).max())
        assert moved > 0.01 * unit  # it did fall


def test_toml_cloth_velocities_carry_each_frame_onto_the_next(tmp_path):
    toml = tmp_path / "sheet.toml"
    toml.write_text('[scene]\nend_frame = 8\n\n[[cloths]]\nname = "sheet"\n'
                    'grid = { size = [1.0, 1.0], resolution = [6, 6] }\nposition = [0.0, 1.0, 0.0]\npinned = [0]\n')
    simbake.bake(simbake.load_scene(toml), tmp_path / "sheet.usdc", qa=False)
    stage = Usd.Stage.Open(str(tmp_path / "sheet.usdc"))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/sheet"))
    for frame in range(1, 8):
        p0, p1 = (np.array(mesh.GetPointsAttr().Get(f), dtype=np.float64) for f in (frame, frame + 1))
        v = np.array(mesh.GetVelocitiesAttr().Get(frame), dtype=np.float64)
        np.testing.assert_allclose(p0 + v / 24.0, p1, atol=1e-6)


def test_bodies_under_a_moving_parent_or_another_body_fall_freely(tmp_path):
    """A ball under an animated Xform (the cart moves 2 m in x) and a ball under another
    dynamic body: composed over the input, both fall straight down, whatever their parents do."""
    stage = _stage(tmp_path / "nested.usda", end=7)
    cart = UsdGeom.Xform.Define(stage, "/World/Cart")
    op = cart.AddTranslateOp()
    op.Set(pxr.Gf.Vec3d(0, 0, 0), 1)
    op.Set(pxr.Gf.Vec3d(2, 0, 0), 7)
    cart.AddRotateYOp().Set(30.0)
    ball = UsdGeom.Sphere.Define(stage, "/World/Cart/Ball")
    ball.CreateRadiusAttr(0.1)
    ball.AddTranslateOp().Set(pxr.Gf.Vec3d(0, 2, 0))
    _body(ball.GetPrim())
    crate = UsdGeom.Cube.Define(stage, "/World/Crate")
    crate.CreateSizeAttr(0.2)
    crate.AddTranslateOp().Set(pxr.Gf.Vec3d(5, 3, 0))
    _body(crate.GetPrim())
    rider = UsdGeom.Sphere.Define(stage, "/World/Crate/Rider")
    rider.CreateRadiusAttr(0.05)
    rider.AddTranslateOp().Set(pxr.Gf.Vec3d(0, 1, 0))
    _body(rider.GetPrim())
    stage.GetRootLayer().Save()
    # (a fixed count of substeps: the closed form below needs every step alike; automatic ones
    # grow in the last frame, where the 5 cm rider travels more than 0.2 of its thickness)
    simbake.bake(replace(simbake.load_scene(tmp_path / "nested.usda"), substeps=10), tmp_path / "c.usda",
                 shot=tmp_path / "s.usda")
    composed = Usd.Stage.Open(str(tmp_path / "s.usda"))
    for path, start in (("/World/Cart/Ball", [0, 2, 0]), ("/World/Crate/Rider", [5, 4, 0]), ("/World/Crate", [5, 3, 0])):
        for frame in range(1, 8):
            t, dt = (frame - 1) / 24, 1 / 240  # semi-implicit Euler, 10 substeps a frame
            m = _world(composed, path, frame)
            np.testing.assert_allclose(m[:3, 3], np.array(start) + [0, -0.5 * 9.81 * t * (t + dt), 0], atol=1e-6,
                                       err_msg=f"{path} at {frame}")
    layer = Sdf.Layer.FindOrOpen(str(tmp_path / "c.usda"))
    assert list(layer.GetAttributeAtPath("/World/Crate/Rider.xformOpOrder").default)[0] == "!resetXformStack!"


def test_check_judges_what_simbake_wrote_not_the_inputs_animation(shipped, tmp_path):
    """`simbake check` on a shot's cache and --shot stage (m/Y-up, cm/Z-up, and over clips):
    clean, though the pusher is keyed at two time codes only and the units are the input's;
    a frame missing from what simbake wrote is still caught."""
    from simbake.check import check_cache

    for name, (cache, shot_stage) in shipped.items():
        assert check_cache(cache) == [], name
        assert check_cache(shot_stage) == [], name
    clipped, stage = tmp_path / "clipped.usdc", tmp_path / "clipped_shot.usda"
    assert main(["bake", str(SCENES / "shot.usda"), "-o", str(clipped), "--shot", str(stage),
                 "--clips", "10", "-q"]) == 0
    assert check_cache(stage) == []
    assert main(["check", str(stage)]) == 0
    # one of simbake's own samples gone: reported
    cache, _ = shipped["shot"]
    broken = tmp_path / "broken.usda"
    layer = Sdf.Layer.OpenAsAnonymous(str(cache))
    layer.EraseTimeSample("/World/Props/Ball.xformOp:translate", 5.0)
    layer.Export(str(broken))
    import shutil

    shutil.copytree(cache.with_name("shot.cache.vdb"), tmp_path / "shot.cache.vdb")  # the level set it names
    stage_layer = Sdf.Layer.CreateNew(str(tmp_path / "broken_shot.usda"))
    stage_layer.TransferContent(Sdf.Layer.FindOrOpen(str(shipped["shot"][1])))
    stage_layer.subLayerPaths[0] = "./broken.usda"
    stage_layer.subLayerPaths[1] = str(SCENES / "shot.usda")
    stage_layer.Save()
    problems = check_cache(tmp_path / "broken_shot.usda")
    assert len(problems) == 1 and "/World/Props/Ball.xformOp:translate: 1 frame(s) without a time sample, first 5" in problems[0]
