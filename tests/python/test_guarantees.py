"""README "Guarantees" (issue 10): inputs are never written, outputs appear whole or not at
all (a full disk included), level-set cache entries are checked before use, signals end a
bake like Ctrl-C, and temps a killed bake left are cleaned up.

Each test asserts what a user would see: exit status, the number of stderr lines, the bytes
of every file before and after, the listing of the directory.
"""

from __future__ import annotations

import errno
import hashlib
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from pxr import Usd

from simbake import _core
from simbake.assets import CACHE_KEY, bake_level_set, write_level_set
from simbake.errors import OutputError, SceneError
from simbake.files import check_output_path, remove_stale_temps, write_atomically

from test_cli import DROP_SCENE, OPEN_BOX_OBJ, assert_one_line_error, listing, simbake

BOX_OBJ = OPEN_BOX_OBJ + "f 3 4 8\nf 3 8 7\n"  # the cube closed by its top


def snapshot(directory: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir()) if p.is_file() and not p.is_symlink()}


# --------------------------------------------------------------------------------------------
# inputs are never written
# --------------------------------------------------------------------------------------------

SHOT = Path(__file__).resolve().parents[2] / "assets" / "scenes" / "shot.usda"


@pytest.mark.parametrize("name, args", [
    ("scene.usda", ["-o", "scene.usda"]),           # a USD shot baked onto itself
    ("shot.usdc", ["-o", "./shot.usdc"]),           # the same file by another spelling
    ("take.qa.json", ["-o", "take.usdc"]),           # the QA sidecar would be the scene
])
def test_bake_never_writes_over_its_scene(tmp_path, name, args):
    if name.endswith((".usda", ".usdc")):
        Usd.Stage.Open(str(SHOT)).Export(str(tmp_path / name))
    else:
        (tmp_path / name).write_text(textwrap.dedent(DROP_SCENE))
    before = snapshot(tmp_path)
    line = assert_one_line_error(simbake("bake", name, *args, cwd=tmp_path))
    assert "would write over the input" in line and name in line
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("name", ["scene.usda", "shot.usdc"])
def test_a_toml_scene_with_a_usd_suffix_is_refused_whole(tmp_path, name):
    (tmp_path / name).write_text(textwrap.dedent(DROP_SCENE))
    before = snapshot(tmp_path)
    line = assert_one_line_error(simbake("bake", name, cwd=tmp_path))
    assert name in line
    assert snapshot(tmp_path) == before


def test_bake_never_writes_over_a_mesh_through_a_link(tmp_path):
    (tmp_path / "box.obj").write_text(BOX_OBJ)
    (tmp_path / "scene.toml").write_text(textwrap.dedent("""
        [scene]
        end_frame = 2
        [[bodies]]
        name = "b"
        mesh = "box.obj"
    """))
    os.link(tmp_path / "box.obj", tmp_path / "hard.usdc")
    (tmp_path / "soft.usdc").symlink_to("box.obj")
    before = snapshot(tmp_path)
    for out in ("hard.usdc", "soft.usdc"):
        line = assert_one_line_error(simbake("bake", "scene.toml", "-o", out, cwd=tmp_path))
        assert "would write over the input" in line and "box.obj" in line
    assert snapshot(tmp_path) == before


def test_levelset_never_writes_over_its_mesh(tmp_path):
    (tmp_path / "box.obj").write_text(BOX_OBJ)
    (tmp_path / "box.vdb").symlink_to("box.obj")
    line = assert_one_line_error(simbake("levelset", "box.obj", "-o", "box.vdb", cwd=tmp_path))
    assert "would write over the input box.obj" in line
    assert (tmp_path / "box.obj").read_text() == BOX_OBJ


def test_report_and_preview_never_write_over_what_they_read(tmp_path):
    cache = tmp_path / "c.usdc"
    cache.write_bytes(b"not really a cache")
    for out, suffixes in ((tmp_path / "c.png", (".png",)), (tmp_path / "c.html", (".html",))):
        os.link(cache, out)
        with pytest.raises(SceneError, match="would write over the input"):
            check_output_path(out, suffixes, inputs=[cache])


@pytest.mark.parametrize("where", ["/proc/simbake-out.usdc", "readonly/out.usdc"])
def test_unwritable_output_directory_is_refused_up_front(write_scene, tmp_path, where):
    write_scene(DROP_SCENE)
    if where.startswith("readonly"):
        ro = tmp_path / "readonly"
        ro.mkdir()
        if subprocess.run(["mount", "--bind", "-o", "ro", str(ro), str(ro)], capture_output=True).returncode:
            ro.chmod(0o500)  # not root: a directory without write permission
            if os.access(ro, os.W_OK):
                pytest.skip("cannot make a read-only directory here")
    try:
        start = time.monotonic()
        line = assert_one_line_error(simbake("bake", "scene.toml", "-o", where, cwd=tmp_path))
        assert "cannot write in" in line
        assert time.monotonic() - start < 30
    finally:
        subprocess.run(["umount", str(tmp_path / "readonly")], capture_output=True)


# --------------------------------------------------------------------------------------------
# whole or not at all
# --------------------------------------------------------------------------------------------

def test_write_atomically_on_a_full_disk_keeps_the_old_file(tmp_path):
    target = tmp_path / "out.qa.json"
    target.write_text("old\n")

    def full(tmp: str) -> None:
        Path(tmp).write_text("half")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    with pytest.raises(OutputError, match="out.qa.json: cannot write: No space left on device"):
        write_atomically(target, full)
    assert target.read_text() == "old\n"
    assert listing(tmp_path) == ["out.qa.json"]


def run_on_full_disk(tmp_path: Path, out: str, command: list[str], leave_kb: int) -> subprocess.CompletedProcess:
    """Run `command` in a private mount namespace, in a small tmpfs (tmp_path/full) that
    holds `out` (the bytes b"precious") and is otherwise filled up but for `leave_kb`; its
    stderr ends with `status=N`. Skips when no namespace can be made."""
    if shutil.which("unshare") is None or subprocess.run(["unshare", "-rm", "true"]).returncode:
        pytest.skip("no user mount namespace for a small tmpfs")
    full = tmp_path / "full"
    full.mkdir()
    script = (f"mount -t tmpfs -o size=256k none {full} && cd {full} && printf precious > {out} && "
              f"(dd if=/dev/zero of=filler bs=4k 2>/dev/null; truncate -s -{leave_kb}K filler; {' '.join(command)}; echo status=$? >&2; "
              f"echo LS: $(ls -A); sha256sum {out})")
    return subprocess.run(["unshare", "-rm", "sh", "-c", script], capture_output=True, text=True,
                          timeout=120, cwd=tmp_path, env={**os.environ, "SIMBAKE_CACHE_DIR": str(full / "cache")})


@pytest.mark.parametrize("what, leave_kb, status, words", [
    ("levelset", 0, 1, "No space left on device"),
    # the bake's estimate (2 kB of samples) fits in 8 kB, the file (13 kB) does not
    ("bake", 8, 1, "No space left on device"),
    ("bake", 0, 2, "scene.end_frame: the cache needs"),  # refused up front by the estimate
])
def test_real_full_disk_keeps_the_old_output(tmp_path, what, leave_kb, status, words):
    (tmp_path / "box.obj").write_text(BOX_OBJ)
    (tmp_path / "scene.toml").write_text(textwrap.dedent(DROP_SCENE))
    out = "old.vdb" if what == "levelset" else "old.usdc"
    py = [sys.executable, "-m", "simbake"]
    command = ([*py, "levelset", str(tmp_path / "box.obj"), "-o", out, "--voxel-size", "0.02"]
               if what == "levelset" else [*py, "bake", str(tmp_path / "scene.toml"), "-o", out, "-q"])
    result = run_on_full_disk(tmp_path, out, command, leave_kb)
    lines = result.stderr.splitlines()
    assert lines[-1] == f"status={status}", result.stderr
    assert len(lines) == 2 and lines[0].startswith("simbake: error: "), result.stderr
    assert words in lines[0] and (out in lines[0] or status == 2), lines[0]
    listed = next(l for l in result.stdout.splitlines() if l.startswith("LS:")).split()[1:]
    assert sorted(listed) == ["filler", out]  # no temp left on the full disk
    assert result.stdout.splitlines()[-1].split()[0] == hashlib.sha256(b"precious").hexdigest()


# --------------------------------------------------------------------------------------------
# level-set cache entries are what they claim
# --------------------------------------------------------------------------------------------

def test_cache_entry_of_another_mesh_is_not_trusted(tmp_path):
    small = _core.sphere_mesh(0.3, 6)
    big = _core.sphere_mesh(0.5, 6)
    cache = tmp_path / "cache"
    bake_level_set(*small, 0.05, cache=cache)
    bake_level_set(*big, 0.05, cache=cache)
    entries = sorted((cache / "levelsets").glob("*.vdb"))
    assert len(entries) == 2
    assert all(CACHE_KEY in _core.LevelSet.read(str(e)).metadata for e in entries)
    # every entry now holds the small sphere: a valid .vdb, but not of the big one's mesh
    small_entry = next(e for e in entries if _core.LevelSet.read(str(e)).bounds[1][0] < 0.4)
    shutil.copyfile(small_entry, next(e for e in entries if e != small_entry))
    grid = bake_level_set(*big, 0.05, cache=cache)
    assert abs(grid.phi(np.array([[0.5, 0.0, 0.0]]))[0]) < 0.02  # the big sphere's surface
    grid = bake_level_set(*small, 0.05, cache=cache)
    assert abs(grid.phi(np.array([[0.3, 0.0, 0.0]]))[0]) < 0.02


def test_truncated_or_foreign_cache_entry_is_baked_again(tmp_path):
    vertices, triangles = _core.sphere_mesh(0.4, 6)
    cache = tmp_path / "cache"
    bake_level_set(vertices, triangles, 0.05, cache=cache)
    (entry,) = (cache / "levelsets").glob("*.vdb")
    whole = entry.read_bytes()
    entry.write_bytes(whole[: len(whole) // 2])
    grid = bake_level_set(vertices, triangles, 0.05, cache=cache)
    assert abs(grid.phi(np.array([[0.4, 0.0, 0.0]]))[0]) < 0.02
    assert CACHE_KEY in _core.LevelSet.read(str(entry)).metadata  # replaced whole
    # a grid without our metadata (another tool's, or an older simbake's) is not trusted
    grid.write(str(entry))
    assert CACHE_KEY not in _core.LevelSet.read(str(entry)).metadata
    bake_level_set(vertices, triangles, 0.05, cache=cache)
    assert CACHE_KEY in _core.LevelSet.read(str(entry)).metadata


def test_level_set_that_does_not_read_back_is_not_committed(tmp_path, monkeypatch):
    vertices, triangles = _core.sphere_mesh(0.4, 6)
    grid = _core.LevelSet.bake(vertices, triangles, 0.05)
    out = tmp_path / "out.vdb"
    out.write_bytes(b"old")

    class Truncating:  # a writer that silently stops half way, as OpenVDB's does on a full disk
        active_voxel_count = grid.active_voxel_count

        def write(self, path, metadata):
            grid.write(path, metadata)
            data = Path(path).read_bytes()
            Path(path).write_bytes(data[: len(data) // 2])

    with pytest.raises(OutputError, match="out.vdb: cannot write"):
        write_level_set(Truncating(), out)
    assert out.read_bytes() == b"old"
    assert listing(tmp_path) == ["out.vdb"]


# --------------------------------------------------------------------------------------------
# signals and stale temps
# --------------------------------------------------------------------------------------------

LONG_SCENE = """
    [scene]
    end_frame = 100000
    [ground]
    [[bodies]]
    name = "ball"
    shape = { type = "sphere", radius = 0.1 }
    position = [0.0, 0.5, 0.0]
    linear_velocity = [0.3, 0.0, 0.0]
    [[bodies]]
    name = "crate"
    shape = { type = "box", size = [0.2, 0.2, 0.2] }
    position = [0.5, 0.1, 0.0]
    angular_velocity = [0.0, 1.0, 0.0]
"""


def temps(directory: Path) -> list[str]:
    return [n for n in listing(directory) if n.startswith(".") and ".tmp" in n]


def start_long_bake(tmp_path: Path) -> subprocess.Popen:
    (tmp_path / "long.toml").write_text(textwrap.dedent(LONG_SCENE))
    # Ctrl-C's default action in the bake, as in a terminal: a shell that starts a test run in
    # the background hands its children SIGINT ignored, which Python then keeps ignoring
    proc = subprocess.Popen([sys.executable, "-m", "simbake", "bake", "long.toml", "-o", "out.usdc", "-q"],
                            cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 60
    while not temps(tmp_path):  # the bake has started writing
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.05)
    time.sleep(0.3)
    return proc


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT])
def test_signal_ends_a_bake_like_ctrl_c(tmp_path, signum):
    (tmp_path / "out.usdc").write_bytes(b"the earlier cache")
    proc = start_long_bake(tmp_path)
    proc.send_signal(signum)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signum, stderr
    lines = stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("simbake: "), stderr
    assert "Traceback" not in stderr
    assert temps(tmp_path) == []
    assert (tmp_path / "out.usdc").read_bytes() == b"the earlier cache"
    assert "out.qa.json" not in listing(tmp_path)


def test_temps_of_a_killed_bake_are_removed_by_the_next_bake(tmp_path):
    proc = start_long_bake(tmp_path)
    proc.kill()
    proc.communicate(timeout=60)
    left = temps(tmp_path)
    assert left and all(f".{proc.pid}-" in n for n in left)  # SIGKILL: nothing can clean up
    # a temp of a live process (this one) beside the same output is left alone
    live = tmp_path / f".out.usdc.{os.getpid()}-0-deadbeef.tmp.usdc"
    live.write_bytes(b"someone else's bake in progress")
    (tmp_path / "short.toml").write_text(textwrap.dedent(DROP_SCENE))
    result = simbake("bake", "short.toml", "-o", "out.usdc", "-q", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert temps(tmp_path) == [live.name]


def test_remove_stale_temps_judges_by_pid_and_name(tmp_path):
    dead = subprocess.Popen(["true"])
    dead.wait()
    names = [f".a.vdb.{dead.pid}-0a1b2c3d.tmp.vdb",       # dead pid, this output: removed
             f".a.vdb.{os.getpid()}-0a1b2c3d.tmp.vdb",    # live pid: kept
             f".b.vdb.{dead.pid}-0a1b2c3d.tmp.vdb",       # another output: kept
             "a.vdb"]
    for n in names:
        (tmp_path / n).write_bytes(b"x")
    assert [p.name for p in remove_stale_temps(tmp_path / "a.vdb")] == [names[0]]
    assert listing(tmp_path) == sorted(names[1:])
