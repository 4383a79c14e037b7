"""The simbake command line, run as a user runs it: a subprocess, `python -m simbake ...`.

The contract under test (DESIGN.md, "Command line and Python" and "Scene file"): a bake writes
its cache and a one-line summary; bad input ends with exactly one line on stderr that names
the file and the key, exit status 2, no traceback, and nothing written: no output file, no
temp file beside it, and an existing file at the output path left byte-for-byte as it was.
"""

from __future__ import annotations

import fcntl
import os
import pty
import re
import select
import struct
import subprocess
import sys
import termios
import time
from pathlib import Path

import numpy as np
import pytest

TIMEOUT = 120  # seconds, per command: generous, a hung bake fails instead of stalling the suite

DROP_SCENE = """
    [scene]
    fps = 24
    start_frame = 1
    end_frame = 12
    [ground]
    [[bodies]]
    name = "ball"
    shape = { type = "sphere", radius = 0.1 }
    position = [0.0, 0.5, 0.0]
    [[bodies]]
    name = "crate"
    shape = { type = "box", size = [0.2, 0.2, 0.2] }
    position = [0.5, 0.1, 0.0]
"""

# five faces of a unit cube (the top is missing): consistently wound but open
OPEN_BOX_OBJ = """\
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
v 1 0 1
v 1 1 1
v 0 1 1
f 1 4 3
f 1 3 2
f 5 6 7
f 5 7 8
f 1 2 6
f 1 6 5
f 2 3 7
f 2 7 6
f 4 1 5
f 4 5 8
"""

SINGLE_TRIANGLE_OBJ = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"


def simbake(*args: str, cwd: Path, **kwargs) -> subprocess.CompletedProcess:
    """Run `python -m simbake ARGS` in `cwd`; stdout and stderr captured (so not a tty)."""
    return subprocess.run([sys.executable, "-m", "simbake", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=TIMEOUT, **kwargs)


def listing(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir()) if directory.is_dir() else []


def assert_one_line_error(result: subprocess.CompletedProcess, status: int = 2) -> str:
    """The error contract: exit status, one line on stderr starting `simbake: error:`."""
    assert result.returncode == status, (result.returncode, result.stdout, result.stderr)
    assert "Traceback" not in result.stderr + result.stdout, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("simbake: error: "), lines[0]
    return lines[0]


# --------------------------------------------------------------------------------------------
# simbake bake: success
# --------------------------------------------------------------------------------------------

def test_bake_writes_cache_and_summary(write_scene, tmp_path):
    write_scene(DROP_SCENE)
    result = simbake("bake", "scene.toml", "-o", "out.usdc", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    out = tmp_path / "out.usdc"
    assert out.read_bytes().startswith(b"PXR-USDC")  # a crate file, not text
    # the summary: frame count (12, the initial state included), substeps, penetration
    summary = result.stdout.strip()
    assert len(summary.splitlines()) == 1, summary
    assert re.search(r"\b12 frames\b", summary), summary
    substeps = int(re.search(r"(\d+) substeps", summary).group(1))
    assert substeps >= 11  # at least one step per frame after the first
    assert re.search(r"penetration [0-9.]+ mm", summary), summary
    assert "out.usdc" in summary
    # stderr is not a terminal here: no progress bar, nothing at all
    assert result.stderr == ""
    # the cache and its QA sidecar, and no temp file left behind
    assert listing(tmp_path) == ["out.qa.json", "out.usdc", "scene.toml"]


def _bake_on_a_tty(args, cwd: Path) -> tuple[int, str]:
    """Run with stderr on a pseudo-terminal; returns (status, what the terminal received)."""
    master, slave = pty.openpty()
    # a real terminal has a size; a fresh pty is 0x0, in which tqdm draws a zero-width bar
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 80, 0, 0))
    try:
        proc = subprocess.Popen([sys.executable, "-m", "simbake", *args], cwd=cwd,
                                stdout=subprocess.DEVNULL, stderr=slave, stdin=subprocess.DEVNULL)
        os.close(slave)
        chunks, deadline = [], time.monotonic() + TIMEOUT
        while time.monotonic() < deadline:
            if not select.select([master], [], [], 1.0)[0]:
                if proc.poll() is not None:
                    break
                continue
            try:
                data = os.read(master, 4096)
            except OSError:  # EIO: the child closed its end
                break
            if not data:
                break
            chunks.append(data)
        status = proc.wait(timeout=max(1.0, deadline - time.monotonic()))
    finally:
        os.close(master)
    return status, b"".join(chunks).decode(errors="replace")


@pytest.mark.parametrize("quiet", [False, True], ids=["tty", "tty-quiet"])
def test_progress_bar_only_on_a_terminal_without_quiet(write_scene, tmp_path, quiet):
    # the counterpart of the test above: on a terminal the bar is there, unless --quiet
    write_scene(DROP_SCENE)
    status, terminal = _bake_on_a_tty(["bake", "scene.toml", "-o", "out.usdc"]
                                      + (["--quiet"] if quiet else []), tmp_path)
    assert status == 0, terminal
    assert (tmp_path / "out.usdc").is_file()
    if quiet:
        assert terminal == ""
    else:
        assert "frame" in terminal  # tqdm's "12/12 [00:00, ...frame/s]"


def test_quiet_bake_prints_only_the_summary(write_scene, tmp_path):
    write_scene(DROP_SCENE)
    result = simbake("bake", "scene.toml", "-o", "out.usdc", "--quiet", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""
    assert result.stdout.startswith("baked 12 frames")


def test_default_output_is_scene_name_in_the_working_directory(write_scene, meshes, tmp_path):
    scenes, work = tmp_path / "scenes", tmp_path / "work"
    scenes.mkdir(), work.mkdir()
    meshes["lshape"].rename(scenes / "lshape.obj")
    # the mesh path is relative to the scene file, not to the working directory
    write_scene(DROP_SCENE + """
        [[bodies]]
        name = "bracket"
        mesh = "lshape.obj"
        position = [0.0, 1.0, 1.0]
    """, "scenes/drop.toml")
    result = simbake("bake", "../scenes/drop.toml", cwd=work)
    assert result.returncode == 0, result.stderr
    # in the cwd, named after the scene (with the bracket's level set beside it)...
    assert listing(work) == ["drop.qa.json", "drop.usdc", "drop.vdb"]
    assert listing(scenes) == ["drop.toml", "lshape.obj"]     # ...not beside the scene file
    assert (work / "drop.usdc").read_bytes().startswith(b"PXR-USDC")
    assert "drop.usdc" in result.stdout


def test_usda_output_is_text(write_scene, tmp_path):
    write_scene(DROP_SCENE)
    result = simbake("bake", "scene.toml", "-o", "out.usda", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    text = (tmp_path / "out.usda").read_text()
    assert text.startswith("#usda 1.0")
    assert 'defaultPrim = "World"' in text and "xformOp:translate.timeSamples" in text
    assert listing(tmp_path) == ["out.qa.json", "out.usda", "scene.toml"]  # the crate temp file is gone too


@pytest.mark.parametrize("suffix", [".usdc", ".usda"])
def test_successful_bake_replaces_an_existing_file(write_scene, tmp_path, suffix):
    write_scene(DROP_SCENE)
    out = tmp_path / f"out{suffix}"
    out.write_bytes(b"an older cache\n")
    result = simbake("bake", "scene.toml", "-o", out.name, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert out.read_bytes().startswith(b"#usda" if suffix == ".usda" else b"PXR-USDC")
    assert listing(tmp_path) == sorted([out.name, "out.qa.json", "scene.toml"])


# --------------------------------------------------------------------------------------------
# simbake demo and simbake check
# --------------------------------------------------------------------------------------------

def test_demo_cache_passes_check(tmp_path):
    result = simbake("demo", "-o", "demo_out.usdc", "--quiet", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "demo_out.usdc").is_file()
    assert re.search(r"\b97 frames\b", result.stdout), result.stdout  # the shipped scene: 1..97
    check = simbake("check", "demo_out.usdc", cwd=tmp_path)
    assert check.returncode == 0, check.stdout + check.stderr
    assert check.stdout.strip() == "demo_out.usdc: ok"


@pytest.mark.parametrize("broken", ["text.usdc", "empty.usdc", "missing.usdc", "a_directory"])
def test_check_rejects_a_broken_file(tmp_path, broken):
    path = tmp_path / broken
    if broken == "text.usdc":
        path.write_text("this is not a USD crate file at all\n" * 20)
    elif broken == "empty.usdc":
        path.write_bytes(b"")
    elif broken == "a_directory":
        path.mkdir()
    result = simbake("check", broken, cwd=tmp_path)
    assert result.returncode == 1, result.stdout + result.stderr
    assert "Traceback" not in result.stdout + result.stderr
    # one line on stderr (the verdict) naming the file; each problem on stdout names it too
    assert result.stderr.splitlines() == [f"{broken}: 1 problem(s)"]
    problems = result.stdout.splitlines()
    assert len(problems) == 1 and problems[0].startswith(f"{broken}: ")
    assert "ok" not in problems[0].split(": ", 1)[1].split()


# --------------------------------------------------------------------------------------------
# simbake levelset
# --------------------------------------------------------------------------------------------

def test_levelset_writes_a_readable_vdb(meshes, tmp_path):
    from simbake import _core

    result = simbake("levelset", "torus.obj", "-o", "t.vdb", "--voxel-size", "0.02", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""
    assert listing(tmp_path) == ["lshape.obj", "t.vdb", "torus.obj"]  # no temp file
    grid = _core.LevelSet.read(str(tmp_path / "t.vdb"))
    assert grid.voxel_size == pytest.approx(0.02)
    # the torus: tube radius 0.1 around a ring of radius 0.3 about the y axis
    phi = grid.phi(np.array([[0.3, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, -0.3]]))
    assert phi[0] < 0 and phi[2] < 0        # inside the tube
    assert phi[0] == pytest.approx(-0.1, abs=0.02)  # its depth, to within a voxel
    assert phi[1] > 0                        # the hole's centre is outside


@pytest.mark.parametrize("case", [
    "zero-voxel", "negative-voxel", "nan-voxel", "inf-voxel", "tiny-voxel", "missing-mesh",
    "wrong-suffix", "open-mesh", "output-is-a-directory"])
def test_levelset_bad_input(meshes, tmp_path, case):
    (tmp_path / "open.obj").write_text(OPEN_BOX_OBJ)
    mesh, out, extra = "torus.obj", "t.vdb", []
    expect = "torus.obj"
    if case == "zero-voxel":
        extra, expect = ["--voxel-size", "0"], "--voxel-size"
    elif case == "negative-voxel":
        extra, expect = ["--voxel-size", "-0.1"], "--voxel-size"
    elif case == "nan-voxel":
        extra, expect = ["--voxel-size", "nan"], "--voxel-size"
    elif case == "inf-voxel":
        extra, expect = ["--voxel-size", "inf"], "--voxel-size"
    elif case == "tiny-voxel":  # 1e-4 m on a 0.8 m torus would fill ~8e9 voxels: refused at once
        extra, expect = ["--voxel-size", "0.0001"], "--voxel-size"
    elif case == "missing-mesh":
        mesh, expect = "nope.obj", "nope.obj"
    elif case == "wrong-suffix":
        out, expect = "t.txt", "t.txt"
    elif case == "open-mesh":
        mesh, expect = "open.obj", "open.obj"
    elif case == "output-is-a-directory":
        (tmp_path / "t.vdb").mkdir()
        expect = "t.vdb"
    before = listing(tmp_path)
    result = simbake("levelset", mesh, "-o", out, *extra, cwd=tmp_path)
    line = assert_one_line_error(result, 2)
    assert expect in line
    assert listing(tmp_path) == before  # no .vdb, no temp file


# --------------------------------------------------------------------------------------------
# simbake bake: bad input
# --------------------------------------------------------------------------------------------

BODY = """
    [scene]
    end_frame = 5
    [ground]
    [[bodies]]
    name = "ball"
    shape = { type = "sphere", radius = 0.1 }
    position = [0.0, 0.5, 0.0]
"""

# case -> (scene text, files to write beside it, output path, words the one line must contain)
BAD_INPUT = {
    "unknown-key": (BODY + 'colour = "red"\n', {}, "out.usdc", ["bodies[0].colour", "unknown key"]),
    "wrong-type": (BODY + 'mass = "heavy"\n', {}, "out.usdc", ["bodies[0].mass", "number"]),
    "missing-mesh": (BODY.replace('shape = { type = "sphere", radius = 0.1 }', 'mesh = "nope.obj"'),
                     {}, "out.usdc", ["bodies[0].mesh", "nope.obj"]),
    "zero-mass": (BODY + "mass = 0\n", {}, "out.usdc", ["bodies[0].mass", "> 0"]),
    "nan-mass": (BODY + "mass = nan\n", {}, "out.usdc", ["bodies[0].mass", "finite"]),
    "duplicate-name": (BODY + BODY.split("[ground]")[1], {}, "out.usdc",
                       ["bodies[1].name", "duplicate", "ball"]),
    "open-box-mesh": (BODY.replace('shape = { type = "sphere", radius = 0.1 }', 'mesh = "open.obj"'),
                      {"open.obj": OPEN_BOX_OBJ}, "out.usdc", ["bodies[0].mesh", "open.obj", "closed"]),
    "single-triangle-mesh": (BODY.replace('shape = { type = "sphere", radius = 0.1 }',
                                          'mesh = "tri.obj"'),
                             {"tri.obj": SINGLE_TRIANGLE_OBJ}, "out.usdc",
                             ["bodies[0].mesh", "tri.obj", "closed"]),
    "not-a-mesh": (BODY.replace('shape = { type = "sphere", radius = 0.1 }', 'mesh = "junk.obj"'),
                   {"junk.obj": "this is not an OBJ file\n"}, "out.usdc",
                   ["bodies[0].mesh", "junk.obj"]),
    "bad-suffix": (BODY, {}, "out.txt", ["out.txt", "output must end in"]),
    "missing-directory": (BODY, {}, "no_such_dir/out.usdc", ["no_such_dir", "does not exist"]),
    "output-is-a-directory": (BODY, {"out.usdc/keep": "a user's file\n"}, "out.usdc",
                              ["out.usdc", "directory"]),
}

@pytest.mark.parametrize("case", list(BAD_INPUT))
def test_bake_bad_input(write_scene, tmp_path, case):
    text, files, output, words = BAD_INPUT[case]
    write_scene(text)
    for name, content in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(content)
    out = tmp_path / output
    out_dir = out.parent
    before = listing(out_dir)

    result = simbake("bake", "scene.toml", "-o", output, cwd=tmp_path)

    line = assert_one_line_error(result, 2)
    if case not in ("bad-suffix", "missing-directory", "output-is-a-directory"):
        assert line.startswith("simbake: error: scene.toml: "), line  # the file, as given
    for word in words:
        assert word in line, (word, line)
    assert result.stdout == ""  # no summary: nothing was baked
    assert not out.is_file()
    assert listing(out_dir) == before  # no output, no temp file beside it
    assert listing(tmp_path / "no_such_dir") == []


def test_bake_bad_input_default_output_not_written(write_scene, tmp_path):
    write_scene(BODY + "mass = nan\n")
    result = simbake("bake", "scene.toml", cwd=tmp_path)
    assert_one_line_error(result, 2)
    assert listing(tmp_path) == ["scene.toml"]  # no scene.usdc, no temp


# --------------------------------------------------------------------------------------------
# a failed bake never destroys what is already at the output path
# --------------------------------------------------------------------------------------------

# failures at each stage: the scene file, the assets, and the solver mid-bake (the state turns
# non-finite after 26 frames, while the writer's temp file is already open and growing; no
# scene within simbake's physical range does that, so the world is made to report it)
FAILURES = {
    "scene": (BODY + "mass = -1.0\n", {}, 2),
    "asset": (BODY.replace('shape = { type = "sphere", radius = 0.1 }', 'mesh = "open.obj"'),
              {"open.obj": OPEN_BOX_OBJ}, 2),
    "solver": ("""
        [scene]
        fps = 24
        end_frame = 40
        [[bodies]]
        name = "bullet"
        shape = { type = "sphere", radius = 0.1 }
        linear_velocity = [10.0, 0.0, 0.0]
    """, {}, 1),
}

# `python -c NON_FINITE_AT_FRAME_26 bake ...`: the CLI with a world whose statistics report a
# non-finite state from the 26th frame on
NON_FINITE_AT_FRAME_26 = """
import sys
import simbake.simulate as simulate

class Failing:
    def __init__(self, world):
        self.world, self.frames = world, 0
    def __getattr__(self, name):
        return getattr(self.world, name)
    def step_frame(self, *args):
        self.frames += 1
        return self.world.step_frame(*args)
    def statistics(self, **kwargs):
        return {**self.world.statistics(**kwargs), "finite": self.frames < 26}

build = simulate.build_world
simulate.build_world = lambda *args, **kwargs: Failing(build(*args, **kwargs))
from simbake.cli import main
sys.exit(main(sys.argv[1:]))
"""


# the suffix matters only once the writer is open (a .usda bake has two temp files)
@pytest.mark.parametrize("stage, suffix", [("scene", ".usdc"), ("asset", ".usdc"),
                                           ("solver", ".usdc"), ("solver", ".usda")])
def test_failed_bake_keeps_an_existing_file(write_scene, tmp_path, stage, suffix):
    text, files, status = FAILURES[stage]
    write_scene(text)
    for name, content in files.items():
        (tmp_path / name).write_text(content)
    out = tmp_path / f"precious{suffix}"
    precious = b"#usda 1.0\n(\n    doc = \"a cache an artist made by hand\"\n)\n" + bytes(range(256))
    out.write_bytes(precious)
    before = listing(tmp_path)

    if stage == "solver":
        result = subprocess.run([sys.executable, "-c", NON_FINITE_AT_FRAME_26, "bake", "scene.toml", "-o", out.name],
                                cwd=tmp_path, capture_output=True, text=True, timeout=TIMEOUT)
    else:
        result = simbake("bake", "scene.toml", "-o", out.name, cwd=tmp_path)

    line = assert_one_line_error(result, status)
    assert "scene.toml" in line
    if stage == "solver":
        assert "non-finite" in line
    assert out.read_bytes() == precious  # byte for byte
    assert listing(tmp_path) == before   # and no temp file left beside it


# --------------------------------------------------------------------------------------------
# files a user gets are readable by the studio, like any file a tool writes
# --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("command", ["bake-usdc", "levelset"])
def test_outputs_respect_the_umask(write_scene, meshes, tmp_path, command):
    write_scene(DROP_SCENE)
    if command == "levelset":
        args, out = ["levelset", "torus.obj", "-o", "t.vdb", "--voxel-size", "0.05"], "t.vdb"
    else:
        out = "out." + command.split("-")[1]
        args = ["bake", "scene.toml", "-o", out]
    result = simbake(*args, cwd=tmp_path, preexec_fn=lambda: os.umask(0o022))
    assert result.returncode == 0, result.stderr
    assert (tmp_path / out).stat().st_mode & 0o777 == 0o644


# --------------------------------------------------------------------------------------------
# simbake bake --threads
# --------------------------------------------------------------------------------------------

def test_threads_option_gives_the_same_cache_at_any_count(write_scene, tmp_path):
    from pxr import Usd

    write_scene(DROP_SCENE)
    for threads in (1, 2):
        result = simbake("bake", "scene.toml", "-o", f"t{threads}.usda", "--threads", threads, cwd=tmp_path)
        assert result.returncode == 0, result.stderr
    samples = []
    for threads in (1, 2):
        stage = Usd.Stage.Open(str(tmp_path / f"t{threads}.usda"))
        attribute = stage.GetPrimAtPath("/World/ball").GetAttribute("xformOp:translate")
        samples.append([tuple(attribute.Get(t)) for t in attribute.GetTimeSamples()])
    assert len(samples[0]) == 12 and samples[0] == samples[1]


def test_more_threads_than_cpus_bake_quietly(write_scene, tmp_path):
    """--threads above the machine's CPU count takes the CPUs there are, with no raw TBB
    warning on stderr (the results are the same bits on any count)."""
    write_scene(DROP_SCENE)
    threads = 4 * (os.cpu_count() or 1)
    result = simbake("bake", "scene.toml", "-o", "t.usda", "--threads", threads, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "TBB" not in result.stderr and "Warning" not in result.stderr, result.stderr


@pytest.mark.parametrize("value", ["-1", "100000"])
def test_threads_option_out_of_range(write_scene, tmp_path, value):
    write_scene(DROP_SCENE)
    line = assert_one_line_error(simbake("bake", "scene.toml", "-o", "out.usdc", "--threads", value, cwd=tmp_path))
    assert "--threads" in line and value in line
    assert listing(tmp_path) == ["scene.toml"]
