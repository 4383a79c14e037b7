"""Fuzz (issue 10): generated scene files thrown at load_scene and at the CLI.

A fixed-seed generator (no new dependency) mutates a small valid scene: keys set to values of
every TOML type (NaN, infinities, huge and tiny numbers, huge integers, empty and multi-line
strings, arrays of the wrong length, tables, dates), keys removed, unknown keys added, mesh
paths pointing at nothing, a directory, a symlink loop, /dev/null or a text file, and the text
itself truncated or scribbled on. The contract for every case:

* load_scene returns a Scene or raises SceneError whose message is one line naming the file;
* the CLI exits 0 or 2; on 2, exactly one stderr line `simbake: error: FILE...`, no traceback,
  and no output written; in every case no earlier file changes (scene, meshes, a cache made
  before).

Bounded: CASES load_scene cases and CLI_CASES bakes of at most 3 frames (a few seconds).
"""

from __future__ import annotations

import datetime
import json
import math
import random
from pathlib import Path

import pytest

import simbake
from simbake.cli import main

SEED = 20261124
CASES = 400
CLI_CASES = 24

TETRA = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n"


def base_scene() -> dict:
    return {
        "scene": {"fps": 24, "start_frame": 1, "end_frame": 3, "gravity": [0.0, -9.81, 0.0]},
        "solver": {"substeps": 0},
        "ground": {"height": 0.0, "friction": 0.5, "restitution": 0.0},
        "bodies": [
            {"name": "ball", "shape": {"type": "sphere", "radius": 0.2}, "position": [0.0, 1.0, 0.0],
             "linear_velocity": [1.0, 0.0, 0.0], "density": 500.0},
            {"name": "crate", "shape": {"type": "box", "size": [0.3, 0.3, 0.3]}, "position": [0.6, 0.2, 0.0],
             "friction": 0.4, "restitution": 0.1},
            {"name": "tet", "mesh": "tetra.obj", "position": [-0.6, 0.5, 0.0], "mass": 2.0},
        ],
        "cloths": [
            {"name": "sheet", "grid": {"size": [1.0, 1.0], "resolution": [5, 5]}, "position": [0.0, 2.0, 0.0],
             "pinned": [0, 4], "thickness": 0.01},
        ],
    }


NUMBERS = [0, -1, 1, 2, 7, 4096, 4097, 2 ** 31, 3_000_000_000, 2 ** 53 + 1, 2 ** 63 - 1, -(2 ** 63),
           0.0, -0.0, 0.5, -2.5, 1e-309, 5e-324, 1e-300, 1e6, 1e300, -1e300, 1.7e308,
           math.nan, math.inf, -math.inf]
STRINGS = ["", "x", "sphere", "box", "membrane", "none", "World", "a b", "é", "line\nbreak", "x" * 300,
           "missing.obj", "../../../../etc/passwd", "/dev/null", "/proc/self/mem", "loop.obj", "adir",
           "notes.txt", "tetra.obj"]
PATHS = ["missing.obj", "adir", "loop.obj", "/dev/null", "notes.txt", "", "tetra.obj", "/proc/self/status"]
KEYS = ["fps", "start_frame", "end_frame", "gravity", "substeps", "height", "friction", "restitution", "name",
        "mesh", "shape", "density", "mass", "position", "orientation", "linear_velocity", "angular_velocity",
        "kinematic", "voxel_size", "keys", "grid", "area_density", "stretch_stiffness", "bend_stiffness",
        "damping", "strain_limit", "compression", "thickness", "pinned", "model", "poisson_ratio",
        "integrator", "self_collision", "radius", "size", "type", "resolution", "time", "bogus"]


def random_value(rng: random.Random, depth: int = 0):
    kind = rng.random()
    if kind < 0.45:
        return rng.choice(NUMBERS)
    if kind < 0.6:
        return rng.choice(STRINGS)
    if kind < 0.65:
        return rng.choice([True, False])
    if kind < 0.9 and depth < 2:
        return [random_value(rng, depth + 1) for _ in range(rng.choice([0, 1, 2, 3, 3, 4, 5]))]
    if kind < 0.97 and depth < 2:
        return {rng.choice(KEYS): random_value(rng, depth + 1) for _ in range(rng.randint(0, 3))}
    return datetime.date(2026, 11, 24)


def tables(scene: dict) -> list[dict]:
    """Every table a mutation may touch, nested ones included."""
    out = []

    def walk(value):
        if isinstance(value, dict):
            out.append(value)
            for v in value.values():
                walk(v)
        elif isinstance(value, list):
            for v in value:
                walk(v)

    walk(scene)
    return out


def mutate(rng: random.Random, scene: dict) -> None:
    table = rng.choice(tables(scene))
    what = rng.random()
    if what < 0.5:
        table[rng.choice(list(table) or KEYS) if rng.random() < 0.8 else rng.choice(KEYS)] = random_value(rng)
    elif what < 0.7 and table:
        del table[rng.choice(list(table))]
    elif what < 0.85:
        bodies = scene.get("bodies")
        body = rng.choice(bodies) if isinstance(bodies, list) and bodies else {}
        if isinstance(body, dict):
            body["mesh"] = rng.choice(PATHS)
            body.pop("shape", None)
    else:
        key = rng.choice(list(table) or ["x"])
        if isinstance(table.get(key), list) and table[key]:
            table[key][rng.randrange(len(table[key]))] = random_value(rng)
        else:
            table[key] = random_value(rng)


def toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf") if math.isinf(value) else repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {toml_value(v)}" for k, v in value.items()) + "}"
    return value.isoformat()


def to_toml(scene: dict) -> str:
    lines = []
    for name, value in scene.items():
        if isinstance(value, dict):
            lines.append(f"[{name}]")
            lines += [f"{json.dumps(k)} = {toml_value(v)}" for k, v in value.items()]
        elif isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            for item in value:
                lines.append(f"[[{name}]]")
                lines += [f"{json.dumps(k)} = {toml_value(v)}" for k, v in item.items()]
        else:
            lines.insert(0, f"{json.dumps(name)} = {toml_value(value)}")
    return "\n".join(lines) + "\n"


def generate(rng: random.Random) -> str:
    scene = base_scene()
    for _ in range(rng.choice([1, 1, 2, 3])):
        mutate(rng, scene)
    text = to_toml(scene)
    if rng.random() < 0.08:  # scribble on the text itself
        cut = rng.randrange(len(text))
        text = text[:cut] + rng.choice(["", "\x00", "[[", "=", '"', "\ufeff", "]]\n[scene]\n"]) + text[cut + 1:]
    return text


@pytest.fixture
def playground(tmp_path) -> Path:
    """A directory with everything the generated paths name, and an earlier cache."""
    (tmp_path / "tetra.obj").write_text(TETRA)
    (tmp_path / "notes.txt").write_text("not a mesh\n")
    (tmp_path / "adir").mkdir()
    (tmp_path / "loop.obj").symlink_to("loop2.obj")
    (tmp_path / "loop2.obj").symlink_to("loop.obj")
    (tmp_path / "earlier.usdc").write_bytes(b"an earlier cache, by hand")
    return tmp_path


def snapshot(directory: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in directory.iterdir() if p.is_file()}


def test_generator_covers_both_outcomes(playground):
    """The fuzz is only worth something if it reaches valid scenes and each kind of error."""
    rng = random.Random(SEED)
    valid, messages = 0, set()
    for k in range(CASES):
        path = playground / "fuzz.toml"
        path.write_text(generate(rng))
        try:
            simbake.load_scene(path)
            valid += 1
        except simbake.SceneError as error:
            messages.add(error.problem.split(" ")[0])
    assert valid >= CASES // 10
    assert len(messages) >= 10


def test_load_scene_raises_only_one_line_scene_errors(playground):
    rng = random.Random(SEED)
    before = snapshot(playground)
    for k in range(CASES):
        text = generate(rng)
        path = playground / "fuzz.toml"
        path.write_text(text)
        try:
            simbake.load_scene(path)
        except simbake.SceneError as error:
            message = str(error)
            assert "\n" not in message and message.startswith(str(path)), (text, message)
        except Exception as error:  # anything else is a bug the user would see as a traceback
            pytest.fail(f"case {k}: {type(error).__name__}: {error}\n{text}")
        assert snapshot(playground) == {**before, "fuzz.toml": text.encode()}


def test_cli_exits_0_or_2_with_one_line_and_writes_nothing_on_failure(playground, capsys, monkeypatch):
    monkeypatch.chdir(playground)
    rng = random.Random(SEED + 1)
    outcomes = []
    for k in range(CLI_CASES):
        text = generate(rng)
        Path("fuzz.toml").write_text(text)
        before = snapshot(playground)
        status = main(["bake", "fuzz.toml", "-o", "out.usdc", "-q"])
        err = capsys.readouterr().err.splitlines()
        outcomes.append(status)
        assert status in (0, 2), (k, status, err, text)
        after = snapshot(playground)
        if status == 2:
            assert len(err) == 1 and err[0].startswith("simbake: error: fuzz.toml"), (err, text)
            assert after == before, text
        else:
            assert all(line.startswith("simbake: warning: QA: ") for line in err), (err, text)
            assert set(after) - set(before) == {"out.usdc", "out.qa.json"}, text
            assert {k: v for k, v in after.items() if k in before} == before
            for name in ("out.usdc", "out.qa.json"):
                Path(name).unlink()
    assert 0 in outcomes and 2 in outcomes


# --------------------------------------------------------------------------------------------
# issue 30: output layouts against the inputs, USD faults, absurd inertia
# --------------------------------------------------------------------------------------------

LAYOUT_CASES = 24
SHOT_CASES = 160
SHOT_CLI_CASES = 12

SHOT_TEXT = """#usda 1.0
(
    defaultPrim = "World"
    startTimeCode = 1
    endTimeCode = 3
    metersPerUnit = 1
    upAxis = "Y"
    {layer_metadata}
)
def Xform "World" ({world_metadata})
{{
    def Plane "Ground" (prepend apiSchemas = ["PhysicsCollisionAPI"])
    {{
        uniform token axis = "{axis}"
    }}
    def Cube "Box" (prepend apiSchemas = ["PhysicsRigidBodyAPI", "PhysicsCollisionAPI", "PhysicsMassAPI"])
    {{
        double size = 0.4
        double3 xformOp:translate = (0, 1, 0)
        uniform token[] xformOpOrder = ["xformOp:translate"]
        {mass}
    }}
    def Mesh "Sheet" (prepend apiSchemas = ["SimbakeClothAPI"])
    {{
        int[] faceVertexCounts = [3, 3]
        int[] faceVertexIndices = [0, 1, 2, 0, 2, 3]
        point3f[] points = [(-1, 2, -1), (1, 2, -1), (1, 2, 1), (-1, 2, 1)]
        {cloth}
    }}
}}
"""
FLOATS = ["0", "1", "2", "0.001", "100", "-1", "nan", "inf", "-inf", "1e30", "1e-30"]


def inertia_case(rng: random.Random) -> tuple[str, bool | None]:
    """Mass attributes and whether they must be refused (None: either is fine)."""
    if rng.random() < 0.15:
        return f"float3 physics:centerOfMass = ({rng.choice(FLOATS)}, 0, 0)", None
    d = sorted(float(rng.choice(FLOATS[1:6] + ["3", "0.5"])) for _ in range(3))
    d = rng.sample(d, 3)
    impossible = max(d) > (sum(d) - max(d)) * (1 + 1e-6) or min(d) <= 0
    axes = rng.choice(["", "quatf physics:principalAxes = (1, 0, 0, 0)", "quatf physics:principalAxes = (0, 0, 0, 0)",
                       "quatf physics:principalAxes = (nan, 0, 0, 0)", "quatf physics:principalAxes = (0.7, 0.7, 0, 0)"])
    text = f"float physics:mass = 2\nfloat3 physics:diagonalInertia = ({d[0]:g}, {d[1]:g}, {d[2]:g})\n{axes}"
    return text, (True if impossible or "nan" in axes else None)


def shot_case(rng: random.Random) -> tuple[str, bool | None]:
    """A generated shot (text) and whether it must be refused (None: either outcome)."""
    mass, refuse = inertia_case(rng) if rng.random() < 0.5 else ("", None)
    faults = {"layer_metadata": "", "world_metadata": "", "axis": "Y", "mass": mass, "cloth": ""}
    what = rng.random()
    if what < 0.12:
        faults["layer_metadata"], refuse = rng.choice(['subLayers = [@missing.usda@]', 'subLayers = [@fuzz.usda@]',
                                                      'subLayers = [@broken.usda@]']), True
    elif what < 0.22:
        faults["world_metadata"], refuse = rng.choice(['references = @missing.usda@</X>',
                                                      'payload = @missing.usda@</X>', 'references = </Nowhere>']), True
    elif what < 0.3:
        faults["axis"], refuse = rng.choice(["W", "", "y"]), True
    elif what < 0.42:
        faults["cloth"], refuse = rng.choice(['string simbake:cloth:pinned = "0 7"', "float[] simbake:cloth:pinned = [1.5]",
                                             'token simbake:cloth:selfCollision = "false"', "int[] simbake:cloth:pinned = [9]",
                                             "float simbake:cloth:thickness = nan"]), True
    elif what < 0.5:
        faults["world_metadata"] = "instanceable = true"
    text = SHOT_TEXT.format(**faults)
    if rng.random() < 0.1:  # scribbled on
        cut = rng.randrange(len(text))
        text, refuse = text[:cut] + rng.choice(["", "(", '"', "{", "\x00", "@"]) + text[cut + 1:], None
    return text, refuse


@pytest.fixture
def usd_playground(tmp_path) -> Path:
    (tmp_path / "broken.usda").write_text('#usda 1.0\ndef Xform "W" {\n  double x = (1,\n}\n')
    (tmp_path / "earlier.usdc").write_bytes(b"an earlier cache, by hand")
    return tmp_path


def test_generated_shots_load_or_fail_in_one_line(usd_playground, capfd):
    """USD composition faults, syntax scribbles, absurd inertia and wrong attribute types: a
    Scene or one SceneError line naming the file; never OpenUSD's raw text on stderr; every
    case that must be refused (an impossible inertia, a missing layer) is."""
    rng = random.Random(SEED + 2)
    outcomes = {True: 0, False: 0}
    for k in range(SHOT_CASES):
        text, refuse = shot_case(rng)
        path = usd_playground / "fuzz.usda"
        path.write_text(text)
        try:
            simbake.load_scene(path)
            refused = False
        except simbake.SceneError as error:
            refused = True
            assert "\n" not in str(error) and str(error).split(": ")[0].endswith((".usda", "usda")), (text, str(error))
        except Exception as error:
            pytest.fail(f"case {k}: {type(error).__name__}: {error}\n{text}")
        assert refuse is None or refused == refuse, (k, refuse, text)
        outcomes[refused] += 1
        err = capfd.readouterr().err
        assert "Warning: in" not in err and "Error in" not in err and "Traceback" not in err, (text, err)
    assert outcomes[True] >= SHOT_CASES // 5 and outcomes[False] >= SHOT_CASES // 10


def test_generated_shots_through_the_cli(usd_playground, capsys, monkeypatch):
    monkeypatch.chdir(usd_playground)
    rng = random.Random(SEED + 3)
    for k in range(SHOT_CLI_CASES):
        text, refuse = shot_case(rng)
        Path("fuzz.usda").write_text(text)
        before = snapshot(usd_playground)
        status = main(["bake", "fuzz.usda", "-o", "out.usdc", "-q"])
        err = capsys.readouterr().err.splitlines()
        assert status in (0, 2) and (refuse is None or (status == 2) == refuse), (k, status, err, text)
        after = snapshot(usd_playground)
        if status == 2:
            assert len(err) == 1 and err[0].startswith("simbake: error: "), (err, text)
            assert after == before, text
        else:
            assert {k: v for k, v in after.items() if k in before} == before
            for name in ("out.usdc", "out.qa.json"):
                Path(name).unlink()


def layout_case(rng: random.Random, root: Path) -> tuple[list[str], set[str]]:
    """Inputs placed somewhere (a folder a bake replaces among them), outputs named every which
    way, or a shot stage an earlier bake wrote baked again: (argv, the input files)."""
    from test_outputs import mesh_scene, short_shot

    for folder in ("sub", "out.clips", "out.vdb"):
        (root / folder).mkdir(exist_ok=True)
    if rng.random() < 0.3:
        return _rebake_case(rng, root, short_shot)
    home = rng.choice([".", "out.clips", "out.vdb", "sub"])
    shot = rng.random() < 0.5
    scene = short_shot(root / home / "shot.usda") if shot else mesh_scene(root / home)
    inputs = {str(scene.relative_to(root))} | (set() if shot else {str(Path(home, "box.obj"))})
    first = sorted(inputs)[0]
    out = rng.choice(["out.usdc", "out.usda", "sub/../out.usdc", "./out.usdc", first, "sub/out.usdc",
                      "out.clips/x.usdc", f"{home}/out.usdc"])
    argv = ["bake", str(scene.relative_to(root)), "-o", out, "-q"]
    if rng.random() < (0.8 if home == "out.clips" else 0.4):
        argv += ["--clips", rng.choice(["1", "2"])]
    if shot and rng.random() < 0.5:
        argv += ["--shot", rng.choice(["s.usda", "sub/../" + out, "out.clips/topology.usdc", "out.vdb/s.usda", first])]
    return argv, inputs


def _rebake_case(rng: random.Random, root: Path, short_shot) -> tuple[list[str], set[str]]:
    """A first bake writes c.usdc (clips, level sets) and the stage s.usda over the shot; the
    case bakes s.usda again: the shot, s.usda, c.usdc and every clip and .vdb are its inputs."""
    short_shot(root / "shot.usda")
    assert main(["bake", "shot.usda", "-o", "c.usdc", "--clips", "1", "--shot", "s.usda", "-q"]) == 0
    inputs = {"shot.usda", "s.usda", "c.usdc"} | {str(p.relative_to(root)) for folder in ("c.clips", "c.vdb")
                                                  for p in (root / folder).iterdir()}
    out = rng.choice(["c.usdc", "c.usda", "d.usdc", "c.clips/x.usdc", "sub/../c.usdc", "c.vdb/x.usdc"])
    argv = ["bake", "s.usda", "-o", out, "-q"] + rng.choice([[], ["--clips", "1"], ["--clips", "2"]])
    return argv + rng.choice([[], ["--shot", "s.usda"], ["--shot", "s2.usda"], ["--shot", "c.clips/topology.usdc"]]), inputs


def test_generated_output_layouts_never_touch_an_input(tmp_path, capsys, monkeypatch):
    """Outputs inside the inputs' folders, inputs inside output folders, aliases of one file,
    an input as an output: exit 0 or 2 with one line; on 2 nothing changed; on 0 every input
    is byte for byte as it was, and every output is written."""
    from test_outputs import tree

    rng = random.Random(SEED + 4)
    outcomes = []
    for k in range(LAYOUT_CASES):
        root = tmp_path / f"case{k}"
        root.mkdir()
        monkeypatch.chdir(root)
        argv, inputs = layout_case(rng, root)
        capsys.readouterr()
        before = tree(root)
        status = main(argv)
        err = capsys.readouterr().err.splitlines()
        outcomes.append(status)
        after = tree(root)
        assert status in (0, 2), (k, argv, err)
        if status == 2:
            assert len(err) == 1 and err[0].startswith("simbake: error: "), (argv, err)
            assert after == before, argv
        else:
            assert all(after.get(name) == before[name] for name in inputs), argv
            assert Path(argv[argv.index("-o") + 1]).is_file(), argv
            assert not [n for n in after if Path(n).name.startswith(".")], argv
    assert 0 in outcomes and 2 in outcomes
