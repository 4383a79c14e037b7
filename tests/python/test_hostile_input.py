"""Hostile and careless input (issue 10): every case ends with one line on stderr that blames
the right file and key, the documented exit status, no traceback, and no file written.

Most cases call the CLI's main() in this process (the same code path as the command, without
an interpreter start per case); a sample runs as a subprocess.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

import simbake
from simbake import limits
from simbake.cli import main

from test_cli import assert_one_line_error, listing, simbake as run_simbake

HEAD = """
    [scene]
    end_frame = 3
"""
SPHERE = """
    [[bodies]]
    name = "ball"
    shape = { type = "sphere", radius = 0.5 }
"""
CLOTH = """
    [[cloths]]
    name = "sheet"
    grid = { size = [1.0, 1.0], resolution = [4, 4] }
"""
TETRA = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n"


def cli(capsys, *args) -> tuple[int, list[str], str]:
    """main(args) in this process: (status, stderr lines, stdout)."""
    status = main([str(a) for a in args])
    captured = capsys.readouterr()
    return status, captured.err.splitlines(), captured.out


def scene_text(*parts: str) -> str:
    return "".join(textwrap.dedent(p) for p in parts)


# (name, scene text, expected key in the message, expected words)
BAD_SCENES = [
    ("fps_subnormal", scene_text("[scene]\nend_frame = 3\nfps = 1e-309\n", SPHERE), "scene.fps", "below"),
    ("fps_huge", scene_text("[scene]\nend_frame = 3\nfps = 1e300\n", SPHERE), "scene.fps", "outside"),
    ("substeps_3e9", scene_text(HEAD, "[solver]\nsubsteps = 3000000000\n", SPHERE), "solver.substeps", "at most 4096"),
    ("gravity_1e300", scene_text("[scene]\nend_frame = 3\ngravity = [0.0, -1e300, 0.0]\n", SPHERE),
     "scene.gravity[1]", "physical range"),
    ("thickness_1e300", scene_text(HEAD, CLOTH, "thickness = 1e300\n"), "cloths[0].thickness", "physical range"),
    ("thickness_1e6", scene_text(HEAD, CLOTH, "thickness = 1e6\n"), "cloths[0].thickness", "at most 1 m"),
    ("grid_1e300_m", scene_text(HEAD, CLOTH.replace("[1.0, 1.0]", "[1e300, 1.0]")), "cloths[0].grid.size[0]",
     "physical range"),
    ("grid_resolution_huge", scene_text(HEAD, CLOTH.replace("[4, 4]", "[100000, 100000]")),
     "cloths[0].grid.resolution", "memory"),
    ("radius_tiny", scene_text(HEAD, SPHERE.replace("0.5", "1e-300")), "bodies[0].shape.radius", "below"),
    ("speed_1e300", scene_text(HEAD, SPHERE, "linear_velocity = [1e300, 0.0, 0.0]\n"),
     "bodies[0].linear_velocity[0]", "m/s"),
    ("position_far", scene_text(HEAD, SPHERE, "position = [0.0, 1e12, 0.0]\n"), "bodies[0].position[1]", "m"),
    ("mass_huge", scene_text(HEAD, SPHERE, "mass = 1e40\n"), "bodies[0].mass", "kg"),
    ("start_beyond_2_53", "[scene]\nstart_frame = 9007199254740993\nend_frame = 9007199254740995\n",
     "scene.start_frame", "2^53"),
    ("end_frame_1e9", scene_text("[scene]\nend_frame = 1000000000\n", SPHERE), "scene.end_frame", "budget"),
]


@pytest.mark.parametrize("name, text, key, words", BAD_SCENES, ids=[c[0] for c in BAD_SCENES])
def test_absurd_scene_is_bad_input_naming_the_key(capsys, tmp_path, monkeypatch, name, text, key, words):
    monkeypatch.chdir(tmp_path)
    Path("s.toml").write_text(text)
    start = time.monotonic()
    status, err, out = cli(capsys, "bake", "s.toml", "-o", "out.usdc", "-q")
    assert status == 2, err
    assert len(err) == 1 and err[0].startswith("simbake: error: s.toml: "), err
    assert f": {key}: " in err[0] and words in err[0], err[0]
    assert "Traceback" not in "".join(err)
    assert time.monotonic() - start < 10  # refused up front, not after trying
    assert listing(tmp_path) == ["s.toml"]
    with pytest.raises(simbake.SceneError):  # the Python API refuses it the same way
        simbake.load_scene("s.toml")


def test_time_codes_up_to_2_53_are_accepted(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(f"[scene]\nstart_frame = {2**53 - 2}\nend_frame = {2**53}\n")
    scene = simbake.load_scene(path)
    assert scene.frame_count == 3
    assert float(scene.end_frame) - float(scene.start_frame) == 2  # every frame distinct


def test_budget_refuses_a_rigid_cache_that_would_not_fit_in_memory(capsys, tmp_path, monkeypatch):
    """The writer holds ~120 B per moving body and frame: refused up front, not after hours."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SIMBAKE_MEMORY_BUDGET", "1M")
    Path("s.toml").write_text(scene_text("[scene]\nend_frame = 20000\n", SPHERE))
    start = time.monotonic()
    status, err, _ = cli(capsys, "bake", "s.toml", "-o", "out.usdc", "-q")
    assert status == 2 and len(err) == 1, err
    assert "scene.end_frame" in err[0] and "memory" in err[0] and "SIMBAKE_MEMORY_BUDGET" in err[0]
    assert time.monotonic() - start < 10
    assert listing(tmp_path) == ["s.toml"]


def test_budget_refuses_substeps_naming_the_fixed_count(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    Path("s.toml").write_text(scene_text("[scene]\nend_frame = 900000\n[solver]\nsubsteps = 4000\n"))
    status, err, _ = cli(capsys, "bake", "s.toml", "-o", "out.usdc", "-q")
    assert status == 2 and len(err) == 1 and ": solver.substeps: " in err[0] and "budget" in err[0], err


def test_budget_refuses_a_cache_larger_than_the_free_disk(capsys, tmp_path, monkeypatch):
    import shutil

    monkeypatch.chdir(tmp_path)
    Path("s.toml").write_text(scene_text("[scene]\nend_frame = 1000\n", CLOTH.replace("[4, 4]", "[64, 64]")))
    usage = shutil.disk_usage(tmp_path)
    monkeypatch.setattr(limits.shutil, "disk_usage", lambda p: usage._replace(free=10 ** 6))
    status, err, _ = cli(capsys, "bake", "s.toml", "-o", "out.usdc", "-q")
    assert status == 2 and len(err) == 1 and ": scene.end_frame: " in err[0] and "on disk" in err[0], err
    assert listing(tmp_path) == ["s.toml"]


# --------------------------------------------------------------------------------------------
# paths and meshes: the message blames the right thing
# --------------------------------------------------------------------------------------------

def test_symlink_loops_in_scene_and_mesh_paths(tmp_path):
    (tmp_path / "a.toml").symlink_to("b.toml")
    (tmp_path / "b.toml").symlink_to("a.toml")
    (tmp_path / "a.obj").symlink_to("b.obj")
    (tmp_path / "b.obj").symlink_to("a.obj")
    (tmp_path / "mesh.toml").write_text(scene_text(HEAD, '[[bodies]]\nname = "m"\nmesh = "a.obj"\n'))
    line = assert_one_line_error(run_simbake("bake", "a.toml", "-o", "o.usdc", cwd=tmp_path))
    assert "a.toml" in line and "symbolic links" in line
    line = assert_one_line_error(run_simbake("bake", "mesh.toml", "-o", "o.usdc", cwd=tmp_path))
    assert "bodies[0].mesh" in line and "a.obj" in line
    line = assert_one_line_error(run_simbake("levelset", "a.obj", "-o", "o.vdb", cwd=tmp_path))
    assert "a.obj" in line and "symbolic links" in line
    assert not {"o.usdc", "o.vdb", "o.qa.json"} & set(listing(tmp_path))


@pytest.mark.parametrize("mesh, words, not_words", [
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv nan 0 1\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n", "non-finite", "not a closed"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1e200 1e200 1e200\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n", "physical range",
     "Warning"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 1 3 2\n", "is flat", "voxel"),  # closed, but no inside
])
def test_mesh_messages_blame_the_right_thing(tmp_path, mesh, words, not_words):
    (tmp_path / "m.obj").write_text(mesh)
    line = assert_one_line_error(run_simbake("levelset", "m.obj", "-o", "o.vdb", cwd=tmp_path))
    assert words in line and not_words not in line, line
    assert listing(tmp_path) == ["m.obj"]


def test_missing_optional_reader_is_cannot_read_mesh(capsys, tmp_path, monkeypatch):
    import trimesh

    monkeypatch.chdir(tmp_path)
    Path("m.3mf").write_text("not a mesh")

    def no_module(*args, **kwargs):
        raise ModuleNotFoundError("No module named 'networkx'", name="networkx")

    monkeypatch.setattr(trimesh, "load", no_module)
    status, err, _ = cli(capsys, "levelset", "m.3mf", "-o", "o.vdb")
    assert status == 2 and len(err) == 1, err
    assert "cannot read mesh m.3mf" in err[0] and "no reader for .3mf files" in err[0], err[0]


def test_voxel_size_is_blamed_only_when_given(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    # a needle: the automatic voxel size (6 across its thinnest extent) needs too many voxels
    Path("needle.obj").write_text(TETRA.replace("v 1 0 0", "v 100 0 0").replace("v 0 0 1", "v 0 0 0.0001"))
    status, err, _ = cli(capsys, "levelset", "needle.obj", "-o", "o.vdb")
    assert status == 2 and len(err) == 1, err
    assert "--voxel-size" not in err[0] and "voxel size" in err[0], err[0]
    status, err, _ = cli(capsys, "levelset", "needle.obj", "-o", "o.vdb", "--voxel-size", "1e-5")
    assert status == 2 and "--voxel-size" in err[0], err
    assert listing(tmp_path) == ["needle.obj"]


def test_voxel_errors_name_the_body_key(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    Path("m.obj").write_text(TETRA)
    Path("s.toml").write_text(scene_text(HEAD, SPHERE, '[[bodies]]\nname = "m"\nmesh = "m.obj"\nvoxel_size = 1e-6\n'))
    status, err, _ = cli(capsys, "bake", "s.toml", "-o", "o.usdc")
    assert status == 2 and len(err) == 1 and ": bodies[1].voxel_size: " in err[0], err


def test_broken_stdout_pipe_is_quiet_and_the_cache_is_whole(tmp_path):
    (tmp_path / "s.toml").write_text(scene_text(HEAD, SPHERE))
    read, write = os.pipe()
    os.close(read)  # the reader is gone before simbake prints (`| head -c0`)
    try:
        result = subprocess.run([sys.executable, "-m", "simbake", "bake", "s.toml", "-o", "o.usdc"], cwd=tmp_path,
                                stdout=write, stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(write)
    assert result.returncode == 128 + signal.SIGPIPE
    assert result.stderr == ""
    assert (tmp_path / "o.usdc").read_bytes().startswith(b"PXR-USDC")


# --------------------------------------------------------------------------------------------
# issue 30, 14 and 19
# --------------------------------------------------------------------------------------------

def test_a_binary_obj_says_it_is_not_text(tmp_path):
    """Issue 30, 14: a garbage `.obj` said "No module named 'charset_normalizer'"."""
    (tmp_path / "junk.obj").write_bytes(bytes(range(256)) * 8)
    line = assert_one_line_error(run_simbake("levelset", "junk.obj", "-o", "junk.vdb", cwd=tmp_path))
    assert "junk.obj" in line and "not UTF-8 text" in line and "charset" not in line
    assert listing(tmp_path) == ["junk.obj"]


def test_a_voxel_larger_than_the_mesh_is_refused(tmp_path):
    """Issue 30, 19: `levelset --voxel-size 1e9` baked a grid of 1e9 m voxels of a 1 m mesh."""
    (tmp_path / "tetra.obj").write_text(TETRA)
    line = assert_one_line_error(run_simbake("levelset", "tetra.obj", "-o", "t.vdb", "--voxel-size", "1e9",
                                             cwd=tmp_path))
    assert "--voxel-size" in line and "larger than the mesh (1 m across)" in line
    assert listing(tmp_path) == ["tetra.obj"]


def test_an_empty_cache_dir_variable_is_unset(tmp_path, monkeypatch):
    """Issue 30, 19: `SIMBAKE_CACHE_DIR=""` wrote `./levelsets` into the working directory."""
    from simbake.assets import cache_dir

    monkeypatch.setenv("SIMBAKE_CACHE_DIR", "")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_dir() == tmp_path / "xdg" / "simbake"
    work = tmp_path / "work"
    work.mkdir()
    (work / "tetra.obj").write_text(TETRA)
    (work / "scene.toml").write_text(textwrap.dedent(HEAD + SPHERE + """
        [[bodies]]
        name = "tet"
        mesh = "tetra.obj"
        position = [2.0, 0.0, 0.0]
    """))
    result = run_simbake("bake", "scene.toml", "-o", "out.usdc", "-q", cwd=work,
                         env={**os.environ, "SIMBAKE_CACHE_DIR": "", "XDG_CACHE_HOME": str(tmp_path / "xdg")})
    assert result.returncode == 0, result.stderr
    assert "levelsets" not in listing(work)
    assert list((tmp_path / "xdg" / "simbake" / "levelsets").glob("*.vdb"))


def test_memory_outgrowing_the_budget_mid_bake_stops_it_cleanly(capsys, tmp_path, monkeypatch):
    """Issue 30, 8: the estimate cannot foresee everything (a folding cloth's self-collision
    keeps more as it folds): the bake watches its resident memory every frame and stops once
    it is over the budget, one line, exit 1, nothing written, instead of swapping or being
    killed. Here the memory the process holds is made to grow past the budget at frame 3."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SIMBAKE_MEMORY_BUDGET", "4G")
    Path("s.toml").write_text(scene_text(HEAD.replace("end_frame = 3", "end_frame = 6"), CLOTH))
    (tmp_path / "out.usdc").write_bytes(b"an earlier cache")
    frames = []

    def held() -> int:
        frames.append(1)
        return (1 if len(frames) < 2 else 5) * 2 ** 30

    monkeypatch.setattr(limits, "resident_bytes", held)
    status, err, _ = cli(capsys, "bake", "s.toml", "-o", "out.usdc", "-q")
    assert status == 1 and len(err) == 1, err
    assert "frame 3: the bake holds 5 GiB of memory, over the budget of 4 GiB" in err[0], err
    assert listing(tmp_path) == ["out.usdc", "s.toml"] and (tmp_path / "out.usdc").read_bytes() == b"an earlier cache"
