"""USD shots a user gets wrong, each refused with one line naming the file, the prim and the
attribute (exit 2, nothing written), OpenUSD's own diagnostics turned into simbake's lines
(issue 30, items 7, 11-14, 16, 19). Each test carries the issue's repro.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from pxr import Usd, UsdGeom

from test_cli import assert_one_line_error, listing, simbake

HEADER = """\
#usda 1.0
(
    defaultPrim = "World"
    startTimeCode = 1
    endTimeCode = {end}
    timeCodesPerSecond = 24
    upAxis = "Y"
    metersPerUnit = 1
    {extra}
)
"""

BOX = """
    def Cube "Box" (prepend apiSchemas = ["PhysicsRigidBodyAPI", "PhysicsCollisionAPI", "PhysicsMassAPI"])
    {{
        double size = 0.4
        double3 xformOp:translate = (0, 1, 0)
        uniform token[] xformOpOrder = ["xformOp:translate"]
        {attributes}
    }}
"""


def shot(tmp_path: Path, body: str = "", end: int = 3, extra: str = "", name: str = "shot.usda",
         world: str = "", after: str = "") -> Path:
    """A stage: a ground Plane and `body` under /World (plus `world` text), `after` at the root."""
    text = HEADER.format(end=end, extra=extra) + textwrap.dedent(f"""
        def Xform "World"
        {{
            def Plane "Ground" (prepend apiSchemas = ["PhysicsCollisionAPI"])
            {{
                uniform token axis = "Y"
            }}
        """) + textwrap.indent(textwrap.dedent(body), "    ") + textwrap.indent(textwrap.dedent(world), "    ") \
        + "}\n" + textwrap.dedent(after)
    path = tmp_path / name
    path.write_text(text)
    return path


def box(attributes: str = "") -> str:
    return BOX.format(attributes=attributes)


def in_process(directory: Path, *args: str) -> subprocess.CompletedProcess:
    """`simbake ARGS` run in this process in `directory` (no interpreter start per case), its
    stdout and stderr caught at the file descriptors, so OpenUSD's own C++ output is too."""
    import contextlib
    import os
    import tempfile

    from simbake.cli import main

    streams = [tempfile.TemporaryFile(mode="w+") for _ in range(2)]
    saved = [os.dup(1), os.dup(2)]
    cwd = os.getcwd()
    try:
        for fd, stream in zip((1, 2), streams):
            os.dup2(stream.fileno(), fd)
        os.chdir(directory)
        with contextlib.redirect_stdout(streams[0]), contextlib.redirect_stderr(streams[1]):
            status = main(list(args))
    finally:
        os.chdir(cwd)
        for fd, copy in zip((1, 2), saved):
            os.dup2(copy, fd)
            os.close(copy)
    for stream in streams:
        stream.flush()
        stream.seek(0)
    out, err = (stream.read() for stream in streams)
    return subprocess.CompletedProcess(args, status, out, err)


def refused(tmp_path: Path, path: Path, *words: str) -> str:
    """Bake `path`: one line, exit 2, each of `words` in it, no OpenUSD text, nothing written."""
    before = listing(tmp_path)
    result = in_process(tmp_path, "bake", path.name, "-o", "out.usdc", "-q")
    line = assert_one_line_error(result)
    assert line.startswith(f"simbake: error: {path.name}: ") or "line" in line, line
    for word in words:
        assert word in line, line
    assert "Warning: in" not in result.stderr and "_ReportErrors" not in result.stderr
    assert "np.float64" not in line
    assert listing(tmp_path) == before
    return line


# --------------------------------------------------------------------------------------------
# 7. the frame budget comes before any animation is sampled
# --------------------------------------------------------------------------------------------

def test_a_three_million_frame_shot_is_refused_before_its_animation_is_sampled(tmp_path):
    """Issue 30, 7: a shot with endTimeCode = 3e6 and a keyed body loaded for minutes with
    memory growing 5 MB/s (the loader sampled every time code before the budget)."""
    keyed = box("bool physics:kinematicEnabled = 1\n"
                "double3 xformOp:translate.timeSamples = { 1: (0, 1, 0), 3000000: (0, 9, 0) }")
    path = shot(tmp_path, keyed.replace("double3 xformOp:translate = (0, 1, 0)\n", ""), end=3_000_000)
    start = time.monotonic()
    refused(tmp_path, path, "endTimeCode", "3000000 frames", "budget")
    assert time.monotonic() - start < 20  # ~2 s to start Python and pxr; sampling took minutes


# --------------------------------------------------------------------------------------------
# 11. wrong tokens and types: exit 2, not an internal error
# --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("prim", ["Capsule", "Cylinder", "Plane"])
def test_an_unknown_axis_token_names_the_prim(tmp_path, prim):
    """Issue 30, 11: `axis = "W"` on a Capsule, Cylinder or Plane was a KeyError (exit 1)."""
    if prim == "Plane":
        path = shot(tmp_path, box())
        path.write_text(path.read_text().replace('uniform token axis = "Y"', 'uniform token axis = "W"'))
        refused(tmp_path, path, "/World/Ground.axis", "must be X, Y or Z", "'W'")
        return
    body = f"""
        def {prim} "Pill" (prepend apiSchemas = ["PhysicsRigidBodyAPI", "PhysicsCollisionAPI"])
        {{
            uniform token axis = "W"
            double height = 0.4
            double radius = 0.1
            double3 xformOp:translate = (0, 1, 0)
            uniform token[] xformOpOrder = ["xformOp:translate"]
        }}
    """
    refused(tmp_path, shot(tmp_path, body), "/World/Pill.axis", "must be X, Y or Z")


CLOTH = """
    def Mesh "Sheet" (prepend apiSchemas = ["SimbakeClothAPI"])
    {{
        int[] faceVertexCounts = [3, 3]
        int[] faceVertexIndices = [0, 1, 2, 0, 2, 3]
        point3f[] points = [(-1, 2, -1), (1, 2, -1), (1, 2, 1), (-1, 2, 1)]
        {attribute}
    }}
"""


@pytest.mark.parametrize("attribute, words", [
    ('string simbake:cloth:pinned = "0 7"', ["simbake:cloth:pinned", "must be an int[]", "string"]),   # 11
    ("float[] simbake:cloth:pinned = [1.5]", ["simbake:cloth:pinned", "must be an int[]", "float[]"]),  # 19
    ('token simbake:cloth:selfCollision = "false"', ["simbake:cloth:selfCollision", "must be a bool"]),  # 19
])
def test_cloth_attributes_of_the_wrong_type_are_refused(tmp_path, attribute, words):
    """Issue 30, 11 and 19: `string simbake:cloth:pinned = "0 7"` was a ValueError (exit 1);
    float pin indices were truncated; `token selfCollision = "false"` was read as true."""
    refused(tmp_path, shot(tmp_path, CLOTH.format(attribute=attribute)), "/World/Sheet.", *words)


# --------------------------------------------------------------------------------------------
# 12. composition errors are errors; OpenUSD's diagnostics are simbake's lines
# --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("fault, words", [
    ("subLayers = [@missing.usda@]", ["composition error", "missing.usda"]),
    ("subLayers = [@shot.usda@]", ["composition error", "cycles"]),
])
def test_a_missing_or_cyclic_sublayer_is_an_error(tmp_path, fault, words):
    """Issue 30, 12: missing or cyclic sublayers baked with exit 0 and raw OpenUSD diagnostics
    ("Warning: in _ReportErrors at line 3326 of .../stage.cpp")."""
    refused(tmp_path, shot(tmp_path, box(), extra=fault), *words)


def test_a_missing_reference_is_an_error(tmp_path):
    body = 'def Xform "Props" (references = @props.usda@</Props>)\n{\n}\n'
    refused(tmp_path, shot(tmp_path, body), "composition error", "props.usda")


def test_bodies_in_a_missing_layer_do_not_bake_an_empty_cache(tmp_path):
    """Issue 30, 12: a shot whose bodies live in a missing layer baked an empty cache without
    a word."""
    path = shot(tmp_path, "", extra="subLayers = [@bodies.usda@]")
    refused(tmp_path, path, "composition error", "bodies.usda")


def test_a_syntax_error_names_the_users_line_and_column(tmp_path):
    """Issue 30, 14: USD syntax errors were cut at 160 characters, so `shot.usda:22:28` was
    lost (a long directory makes OpenUSD's message long)."""
    deep = tmp_path / ("d" * 120) / ("e" * 80)
    deep.mkdir(parents=True)
    path = shot(deep, box('double physics:mass = (1, 2'))
    lines = path.read_text().splitlines()
    row = next(k for k, l in enumerate(lines) if "physics:mass" in l) + 1
    result = simbake("bake", path.name, "-o", "out.usdc", "-q", cwd=deep)
    line = assert_one_line_error(result)
    assert line.startswith(f"simbake: error: shot.usda: line {row + 1}, column ") \
        or line.startswith(f"simbake: error: shot.usda: line {row}, column "), line
    assert "pxrInternal" not in line and "Error in" not in line


def test_a_syntax_error_in_a_sublayer_names_that_layer(tmp_path):
    (tmp_path / "sub.usda").write_text('#usda 1.0\ndef Xform "W" {\n  double x = (1,\n}\n')
    line = refused(tmp_path, shot(tmp_path, box(), extra="subLayers = [@sub.usda@]"))
    assert line.startswith("simbake: error: sub.usda: line 4, column 1: "), line


# --------------------------------------------------------------------------------------------
# 13. instanceable bodies move in the --shot stage
# --------------------------------------------------------------------------------------------

def test_a_body_under_an_instance_moves_in_the_shot_stage(tmp_path):
    """Issue 30, 13: rigid bodies under `instanceable = true` were simulated but their overs
    landed on instance proxies, which composition ignores: the --shot stage showed them
    frozen, exit 0. The cache layer now makes the instance an ordinary prim."""
    body = 'def Xform "Holder" (instanceable = true; references = </Proto>)\n{\n}\n'
    proto = 'over "Proto"\n{' + textwrap.indent(box(), "    ").replace("(0, 1, 0)", "(0, 2, 0)") + "}\n"
    path = shot(tmp_path, body, end=12, after=proto)
    for clips in ([], ["--clips", "5"]):
        result = simbake("bake", path.name, "-o", "c.usda", "--shot", "s.usda", "-q", *clips, cwd=tmp_path)
        assert result.returncode == 0, result.stderr
        stage = Usd.Stage.Open(str(tmp_path / "s.usda"))
        prim = stage.GetPrimAtPath("/World/Holder/Box")
        assert not prim.IsInstanceProxy()
        heights = [UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(t).ExtractTranslation()[1] for t in (1, 12)]
        # falling from 2 m for 11/24 s: 2 - g t^2 / 2 = 0.97 m (the ground is far below)
        assert heights[0] == pytest.approx(2.0, abs=1e-6)
        assert heights[1] == pytest.approx(2.0 - 0.5 * 9.81 * (11 / 24) ** 2, abs=0.02)


# --------------------------------------------------------------------------------------------
# 14. messages name the prim and the attribute, in the user's words
# --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("edit, words", [
    (("double size = 0.4", "double size = 1e9"), ["/World/Box.size", "outside simbake's physical range"]),
    (("endTimeCode = 3", "endTimeCode = 3\n    timeCodesPerSecond = 1e9"), ["timeCodesPerSecond", "physical range"]),
])
def test_range_errors_name_the_prim_and_attribute_not_scene_keys(tmp_path, edit, words):
    """Issue 30, 14: range errors in shots named TOML keys (`bodies[0].shape.size[0]`,
    `scene.fps`) instead of the prim and attribute."""
    path = shot(tmp_path, box())
    text = path.read_text().replace(*edit)
    if "timeCodesPerSecond = 1e9" in text:
        text = text.replace("    timeCodesPerSecond = 24\n", "", 1)
    path.write_text(text)
    line = refused(tmp_path, path, *words)
    assert "bodies[" not in line and "scene." not in line


@pytest.mark.parametrize("attributes, words", [
    ("float physics:mass = 2\nfloat3 physics:diagonalInertia = (1, 1, 1)\nquatf physics:principalAxes = (nan, 0, 0, 0)",
     ["/World/Box.physics:principalAxes", "(nan, 0, 0, 0)"]),
    ("float physics:mass = 2\nfloat3 physics:diagonalInertia = (-1, 1, 1)",
     ["/World/Box.physics:diagonalInertia", "(-1, 1, 1)"]),
    ("float3 physics:centerOfMass = (nan, 0, 0)", ["/World/Box.physics:centerOfMass", "finite"]),  # 19
])
def test_mass_attributes_are_named_as_written(tmp_path, attributes, words):
    """Issue 30, 14 and 19: a NaN principalAxes was reported as a flat shape, a negative inertia
    as `np.float64(-1.0)`, a NaN centerOfMass silently dropped."""
    refused(tmp_path, shot(tmp_path, box(attributes)), *words)


def test_a_nan_gravity_direction_is_blamed_on_the_direction(tmp_path):
    """Issue 30, 14: a NaN gravity direction was blamed on gravityMagnitude."""
    scene = 'def PhysicsScene "Physics"\n{\n    vector3f physics:gravityDirection = (0, nan, 0)\n}\n'
    line = refused(tmp_path, shot(tmp_path, box(), world=scene), "/World/Physics.physics:gravityDirection")
    assert "Magnitude" not in line


def test_a_negative_material_density_is_refused(tmp_path):
    """Issue 30, 19: a negative material `physics:density` was silently dropped."""
    material = ('def Material "Rubber" (prepend apiSchemas = ["PhysicsMaterialAPI"])\n{\n'
                "    float physics:density = -5\n}\n")
    body = box().replace('"PhysicsMassAPI"]', '"PhysicsMassAPI", "MaterialBindingAPI"]').replace(
        "double size = 0.4", "double size = 0.4\n        rel material:binding:physics = </World/Rubber>")
    refused(tmp_path, shot(tmp_path, body, world=material), "/World/Rubber.physics:density", "-5")


# --------------------------------------------------------------------------------------------
# 16. physically impossible inertia
# --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("inertia", ["(100, 0.001, 0.001)", "(1, 1, 2.01)"])
def test_inertia_that_breaks_the_triangle_inequality_is_refused(tmp_path, inertia):
    """Issue 30, 16: `diagonalInertia = (100, 0.001, 0.001)`, mass 2, spinning: kinetic energy
    1,371 J to 5.3e7 J in a frame, the box at y = 478 m and 867 m/s; the QA warned only about
    substeps. No body has a principal moment larger than the other two together."""
    attributes = (f"float physics:mass = 2\nfloat3 physics:diagonalInertia = {inertia}\n"
                  "vector3f physics:angularVelocity = (0, 2000, 500)")
    refused(tmp_path, shot(tmp_path, box(attributes)), "/World/Box.physics:diagonalInertia", "triangle inequality")


def test_inertia_at_the_edge_of_the_triangle_inequality_is_accepted(tmp_path):
    """A thin disc: moments (1, 1, 2), equal to the sum exactly, is a real body."""
    attributes = "float physics:mass = 2\nfloat3 physics:diagonalInertia = (1, 1, 2)"
    result = simbake("bake", shot(tmp_path, box(attributes)).name, "-o", "out.usdc", "-q", cwd=tmp_path)
    assert result.returncode == 0, result.stderr


def test_python_scene_with_impossible_inertia_is_refused(tmp_path):
    """The same rule for a Scene made in Python (any inertia tensor: its principal moments)."""
    import simbake
    from dataclasses import replace

    path = tmp_path / "scene.toml"
    path.write_text('[scene]\nend_frame = 2\n[[bodies]]\nname = "b"\nshape = { type = "box", size = [1, 1, 1] }\n')
    scene = simbake.load_scene(path)
    rotation = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    bad = rotation @ np.diag([100.0, 0.001, 0.001]) @ rotation.T
    scene = replace(scene, bodies=(replace(scene.bodies[0], inertia=tuple(map(tuple, bad))),))
    with pytest.raises(simbake.SceneError, match=r"bodies\[0\]\.inertia: principal moments .*triangle inequality"):
        simbake.bake(scene, tmp_path / "out.usdc")
    assert listing(tmp_path) == ["scene.toml"]
