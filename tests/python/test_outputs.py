"""A bake's outputs are one commit (README, "Guarantees"; simbake.outputs).

Every output (cache, clips folder, level-set folder, --shot stage, QA sidecar) is checked
against every input and every other output before any work, and all of them are swapped in
together, or none. Each test is a repro of issue 30 and asserts what a user would see: the
exit status, one stderr line, and every byte of every file in the directory tree before and
after.
"""

from __future__ import annotations

import errno
import os
import shutil
import subprocess
import textwrap
from pathlib import Path

import pytest

from simbake.cli import main

from test_cli import assert_one_line_error, listing, simbake
from test_guarantees import BOX_OBJ, SHOT

# a mesh body and a sphere it can touch: the bake writes OUT.vdb/ beside the cache
MESH_SCENE = """
    [scene]
    end_frame = 3
    [ground]
    [[bodies]]
    name = "box"
    mesh = "box.obj"
    position = [0.0, 0.5, 0.0]
    [[bodies]]
    name = "ball"
    shape = { type = "sphere", radius = 0.1 }
    position = [2.0, 0.5, 0.0]
"""


def tree(directory: Path) -> dict[str, bytes | None]:
    """Every file (its bytes) and folder (None) under `directory`, hidden ones included."""
    out: dict[str, bytes | None] = {}
    for root, dirs, files in os.walk(directory):
        for name in dirs:
            out[os.path.relpath(os.path.join(root, name), directory)] = None
        for name in files:
            path = Path(root, name)
            out[os.path.relpath(path, directory)] = path.read_bytes() if not path.is_symlink() else b"->"
    return out


def mesh_scene(directory: Path, name: str = "scene.toml") -> Path:
    (directory / "box.obj").write_text(BOX_OBJ)
    path = directory / name
    path.write_text(textwrap.dedent(MESH_SCENE))
    return path


def short_shot(path: Path, end: int = 4) -> Path:
    """The shipped shot, cut to a few frames (its Capsule is a mesh: a .vdb folder too)."""
    text = SHOT.read_text().replace("endTimeCode = 36", f"endTimeCode = {end}")
    path.write_text(text)
    return path


# --------------------------------------------------------------------------------------------
# 1. a folder a bake replaces never holds one of its inputs
# --------------------------------------------------------------------------------------------

def test_shot_inside_the_clips_folder_is_refused_and_kept(tmp_path):
    """Issue 30, 1: `mkdir out.clips; cp shot.usda out.clips/; simbake bake out.clips/shot.usda
    -o out.usdc --clips 10` deleted the shot (then failed, having written the new cache)."""
    (tmp_path / "out.clips").mkdir()
    short_shot(tmp_path / "out.clips" / "shot.usda")
    before = tree(tmp_path)
    line = assert_one_line_error(simbake("bake", "out.clips/shot.usda", "-o", "out.usdc", "--clips", "10",
                                         "-q", cwd=tmp_path))
    assert "out.clips" in line and "holds the input" in line and "shot.usda" in line
    assert tree(tmp_path) == before


@pytest.mark.parametrize("inside", ["scene", "mesh"])
def test_scene_or_mesh_inside_the_level_set_folder_is_refused_and_kept(tmp_path, inside):
    """Issue 30, 1: the same for a TOML scene, or its mesh, inside OUT.vdb/."""
    folder = tmp_path / "out.vdb"
    folder.mkdir()
    scene = mesh_scene(folder if inside == "scene" else tmp_path)
    if inside == "mesh":
        shutil.move(tmp_path / "box.obj", folder / "box.obj")
        scene.write_text(scene.read_text().replace('"box.obj"', '"out.vdb/box.obj"'))
    before = tree(tmp_path)
    line = assert_one_line_error(simbake("bake", scene, "-o", "out.usdc", "-q", cwd=tmp_path))
    assert "out.vdb" in line and "holds the input" in line
    assert tree(tmp_path) == before


def test_a_users_file_or_folder_of_the_same_name_is_never_renamed_away(tmp_path):
    """Issue 30, 9: a user's regular file named OUT.vdb was renamed to .OUT.vdb.<pid>.old and
    left there; a folder of the user's own files at OUT.vdb would have been deleted."""
    mesh_scene(tmp_path)
    (tmp_path / "out.vdb").write_bytes(b"the user's own file")
    before = tree(tmp_path)
    line = assert_one_line_error(simbake("bake", "scene.toml", "-o", "out.usdc", "-q", cwd=tmp_path))
    assert "out.vdb: is a file, not a folder simbake wrote" in line
    assert tree(tmp_path) == before
    (tmp_path / "out.vdb").unlink()
    (tmp_path / "out.vdb").mkdir()
    (tmp_path / "out.vdb" / "notes.txt").write_text("mine")
    before = tree(tmp_path)
    line = assert_one_line_error(simbake("bake", "scene.toml", "-o", "out.usdc", "-q", cwd=tmp_path))
    assert "holds 'notes.txt', which simbake did not write there" in line
    assert tree(tmp_path) == before


def test_an_earlier_bakes_folders_are_replaced_whole(tmp_path):
    """What a bake wrote there before is replaced by the new bake's, and nothing else is left."""
    mesh_scene(tmp_path)
    for run in range(2):  # frames 1-3 in clips of 1 frame: 1-2, 2-3
        result = simbake("bake", "scene.toml", "-o", "out.usdc", "--clips", "1", "-q", cwd=tmp_path)
        assert result.returncode == 0, result.stderr
        assert listing(tmp_path) == ["box.obj", "out.clips", "out.qa.json", "out.usdc", "out.vdb", "scene.toml"]
        assert listing(tmp_path / "out.clips") == ["clip.0001.usdc", "clip.0002.usdc", "manifest.usda",
                                                   "topology.usdc"]
        assert len(listing(tmp_path / "out.vdb")) == 1


# --------------------------------------------------------------------------------------------
# 2, 3. outputs never write over the input's own layers or each other
# --------------------------------------------------------------------------------------------

def test_a_shot_stage_is_never_rebaked_over_its_own_clip_layers(tmp_path):
    """Issue 30, 2: bake a shot with --clips 10 --shot s.usda, then `simbake bake s.usda -o
    c.usda --clips 7`: exit 0, and c.clips/topology.usdc (a layer s.usda uses), every clip and
    the sidecar were replaced."""
    short_shot(tmp_path / "shot.usda", end=12)
    result = simbake("bake", "shot.usda", "-o", "c.usdc", "--clips", "10", "--shot", "s.usda", "-q", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    before = tree(tmp_path)
    line = assert_one_line_error(simbake("bake", "s.usda", "-o", "c.usda", "--clips", "7", "-q", cwd=tmp_path))
    assert "c.clips" in line and "holds the input" in line
    assert tree(tmp_path) == before


def test_a_stage_that_references_a_level_set_keeps_it(tmp_path):
    """The .vdb files an input names (a cache's level-set Volumes) are inputs too: a bake that
    would replace their folder is refused."""
    mesh_scene(tmp_path)
    assert simbake("bake", "scene.toml", "-o", "c.usda", "-q", cwd=tmp_path).returncode == 0
    (tmp_path / "over.usda").write_text(textwrap.dedent(f"""\
        #usda 1.0
        (
            subLayers = [@./c.usda@, @{SHOT}@]
            metersPerUnit = 1
            upAxis = "Y"
            startTimeCode = 1
            endTimeCode = 3
        )
    """))
    before = tree(tmp_path)
    line = assert_one_line_error(simbake("bake", "over.usda", "-o", "c.usdc", "-q", cwd=tmp_path))
    assert "c.vdb" in line and "holds the input" in line
    assert tree(tmp_path) == before


@pytest.mark.parametrize("args", [
    ["-o", "c.usdc", "--shot", "sub/../c.usdc"],                        # one file, two spellings
    ["-o", "c.usdc", "--shot", "c.clips/topology.usdc", "--clips", "2"],  # into its own clips
    ["-o", "c.usdc", "--shot", "c.vdb/s.usda"],                          # into the level sets
])
def test_outputs_that_alias_each_other_are_refused(tmp_path, args):
    """Issue 30, 3: `--shot sub/../c.usdc` with `-o c.usdc` turned the cache into a 760-byte
    stage that sublayers itself (paths compared un-normalised); `--shot c.clips/topology.usdc`
    likewise."""
    short_shot(tmp_path / "shot.usda")
    for folder in ("sub", "c.clips", "c.vdb"):
        (tmp_path / folder).mkdir()
    before = tree(tmp_path)
    line = assert_one_line_error(simbake("bake", "shot.usda", *args, "-q", cwd=tmp_path))
    assert "must differ from the output" in line
    assert tree(tmp_path) == before


def test_a_newline_in_the_output_name_is_refused_before_the_bake(tmp_path):
    """Issue 30, 14: a newline in -o failed after the whole bake with exit 1."""
    mesh_scene(tmp_path)
    before = tree(tmp_path)
    line = assert_one_line_error(simbake("bake", "scene.toml", "-o", "a\nb.usdc", "-q", cwd=tmp_path))
    assert "a\\nb.usdc" in line and "control character" in line
    assert tree(tmp_path) == before


# --------------------------------------------------------------------------------------------
# 5. all of a bake's outputs, or none
# --------------------------------------------------------------------------------------------

def earlier_outputs(tmp_path: Path) -> dict:
    """A first bake's outputs (cache, clips, level sets, shot stage, sidecar), as bytes."""
    short_shot(tmp_path / "shot.usda")
    result = simbake("bake", "shot.usda", "-o", "c.usdc", "--clips", "2", "--shot", "s.usda", "-q", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert {"c.usdc", "c.clips", "c.vdb", "s.usda", "c.qa.json"} <= set(listing(tmp_path))
    (tmp_path / "shot.usda").write_text((tmp_path / "shot.usda").read_text().replace("radius = 0.25", "radius = 0.3"))
    return tree(tmp_path)


@pytest.mark.parametrize("failing", ["c.qa.json", "s.usda"])
def test_a_full_disk_at_the_last_outputs_keeps_every_earlier_output(tmp_path, monkeypatch, capsys, failing):
    """Issue 30, 5: the disk filling as the QA sidecar was written ended with exit 1 and
    "nothing was replaced", yet the new cache and .vdb/ were in place beside the old sidecar
    (and with --clips, new clips)."""
    import simbake.outputs as outputs

    before = earlier_outputs(tmp_path)
    real = outputs.Outputs.write

    def write(self, final, fn):
        if Path(final).name != failing:
            return real(self, final, fn)

        def full(tmp):
            fn(tmp)
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        return real(self, final, full)

    monkeypatch.setattr(outputs.Outputs, "write", write)
    monkeypatch.chdir(tmp_path)
    status = main(["bake", "shot.usda", "-o", "c.usdc", "--clips", "2", "--shot", "s.usda", "-q"])
    err = capsys.readouterr().err.splitlines()
    assert status == 1 and len(err) == 1 and f"{failing}: cannot write: No space left on device" in err[0], err
    assert tree(tmp_path).keys() == before.keys()
    assert tree(tmp_path) == before


def test_a_failed_rename_in_the_commit_puts_every_earlier_output_back(tmp_path, monkeypatch, capsys):
    """The commit's renames roll back: the third output's rename fails, the two placed before
    it go back and every earlier output is restored."""
    import simbake.outputs as outputs

    before = earlier_outputs(tmp_path)
    real = os.rename
    placed = []

    def rename(src, dst):
        if ".tmp" in Path(src).name:
            placed.append(dst)
            if len(placed) == 3:
                raise OSError(errno.EIO, os.strerror(errno.EIO))
        return real(src, dst)

    monkeypatch.setattr(outputs.os, "rename", rename)
    monkeypatch.chdir(tmp_path)
    status = main(["bake", "shot.usda", "-o", "c.usdc", "--clips", "2", "--shot", "s.usda", "-q"])
    monkeypatch.undo()
    err = capsys.readouterr().err.splitlines()
    assert status == 1 and len(err) == 1 and "Input/output error" in err[0], err
    assert len(placed) == 3
    assert tree(tmp_path) == before


# --------------------------------------------------------------------------------------------
# 9. temps of killed bakes
# --------------------------------------------------------------------------------------------

def test_stale_temp_folders_of_a_killed_bake_are_removed(tmp_path):
    """Issue 30, 9: stale `.OUT.clips.<pid>.tmp/` and `.OUT.vdb.<pid>.tmp/` of a killed bake
    were never removed. A live process's temps are left alone."""
    mesh_scene(tmp_path)
    dead = subprocess.Popen(["true"])
    dead.wait()
    stale = [f".out.clips.{dead.pid}-0a1b2c3d.tmp", f".out.vdb.{dead.pid}-0a1b2c3d.tmp",
             f".out.vdb.{dead.pid}-0a1b2c3e.old"]
    for name in stale:
        (tmp_path / name).mkdir()
        (tmp_path / name / "clip.0001.usdc").write_bytes(b"half")
    live = tmp_path / f".out.vdb.{os.getpid()}-0a1b2c3d.tmp"
    live.mkdir()
    result = simbake("bake", "scene.toml", "-o", "out.usdc", "--clips", "2", "-q", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert [n for n in listing(tmp_path) if n.startswith(".")] == [live.name]


def test_an_earlier_output_a_killed_commit_moved_aside_is_put_back(tmp_path):
    """Killed between moving an earlier output aside and renaming the new one in (SIGKILL in
    the commit's few renames): the next bake of that output puts the earlier one back first."""
    from simbake.outputs import check_outputs

    dead = subprocess.Popen(["true"])
    dead.wait()
    aside = tmp_path / f".out.usdc.{dead.pid}-0a1b2c3d.old"
    aside.write_bytes(b"the earlier cache")
    check_outputs([tmp_path / "out.usdc"], [], [])
    assert listing(tmp_path) == ["out.usdc"]
    assert (tmp_path / "out.usdc").read_bytes() == b"the earlier cache"
