"""Wedges and batches on real Dask clusters (simbake.wedge_run, simbake.farm).

* a LocalCluster of 2 worker processes (shared by this module): a 2 x 3 wedge gives the same
  caches (by content: every spec, field and time sample) as 6 sequential bakes of scene files
  written with those values, and the variant set composes each take; a bad value fails its
  take alone; a USD shot's wedge composes each take's attribute value; a batch;
* a LocalCluster whose worker is SIGKILLed mid-bake: every take baked once, complete, no temp;
* the farm path: `dask scheduler` and two `dask worker` processes on localhost, the same
  wedge through `simbake wedge --scheduler`;
* the command line: bad input (exit 2, one line, nothing written), a failed take (exit 1),
  and that `simbake bake` never imports Dask.
"""

from __future__ import annotations

import json
import logging
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

import simbake
from simbake.cache_compare import first_difference

REPO = Path(__file__).resolve().parents[2]

SIMBAKE = str(Path(sys.executable).with_name("simbake"))
DASK = str(Path(sys.executable).with_name("dask"))
TIMEOUT = 240  # s: any one command or cluster start here

# a ball thrown at a crate; the wedge varies the ball's restitution and the crate's mass
BALLS = """
[scene]
end_frame = 10
[ground]
[[bodies]]
name = "ball"
shape = {{ type = "sphere", radius = 0.2 }}
position = [0.0, 0.6, 0.0]
linear_velocity = [2.0, 0.0, 0.0]
restitution = {restitution}
[[bodies]]
name = "crate"
shape = {{ type = "box", size = [0.3, 0.3, 0.3] }}
position = [0.5, 0.15, 0.0]
mass = {mass}
"""
RESTITUTIONS = [0.2, 0.8]
MASSES = [1.0, 3.0, 6.0]
VARIATIONS = {"bodies.ball.restitution": RESTITUTIONS, "bodies.crate.mass": MASSES}

# a sheet dropped on a sphere: a second or two a bake, long enough to be killed in
SHEET = """
[scene]
end_frame = {frames}
[ground]
[[bodies]]
name = "ball"
shape = {{ type = "sphere", radius = 0.3 }}
position = [0.0, 0.3, 0.0]
kinematic = true
[[cloths]]
name = "sheet"
grid = {{ size = [1.0, 1.0], resolution = [24, 24] }}
position = [0.0, 0.8, 0.0]
stretch_stiffness = {stiffness}
"""


def _local_cluster(workers: int = 2, allowed_failures: int = 2):
    import dask
    from distributed import LocalCluster

    with dask.config.set({"distributed.scheduler.allowed-failures": allowed_failures}):
        return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                            dashboard_address=":0", silence_logs=logging.ERROR)


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    """A real LocalCluster of 2 worker processes, closed at the end even on failure. Its
    workers get a level-set cache of their own (they inherit the environment at start)."""
    from distributed import Client

    saved = os.environ.get("SIMBAKE_CACHE_DIR")
    os.environ["SIMBAKE_CACHE_DIR"] = str(tmp_path_factory.mktemp("cluster-cache"))
    cluster = _local_cluster()
    try:
        with Client(cluster) as c:
            yield c
    finally:
        cluster.close(timeout=30)
        if saved is None:
            os.environ.pop("SIMBAKE_CACHE_DIR", None)
        else:
            os.environ["SIMBAKE_CACHE_DIR"] = saved


@pytest.fixture(scope="module")
def references(tmp_path_factory) -> dict:
    """(restitution, mass) -> the cache of a sequential bake of a scene file with those values."""
    folder = tmp_path_factory.mktemp("sequential")
    out = {}
    for r in RESTITUTIONS:
        for m in MASSES:
            scene = folder / f"balls_{r}_{m}.toml"
            scene.write_text(BALLS.format(restitution=r, mass=m))
            out[(r, m)] = simbake.bake(simbake.load_scene(scene), folder / f"balls_{r}_{m}.usdc").output
    return out


def _balls(folder: Path) -> Path:
    scene = folder / "balls.toml"
    scene.write_text(BALLS.format(restitution=0.5, mass=2.0))
    return scene


def _copy(source: Path, folder: Path) -> Path:
    import shutil

    return Path(shutil.copy(source, folder / source.name))


def _temps(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if ".tmp" in p.name]


def _assert_matches_references(output: Path, references: dict) -> None:
    """Each variant of the wedge stage is its take's cache, the same as the sequential bake
    of its values; selecting it composes that take's poses."""
    from pxr import Usd

    stage = Usd.Stage.Open(str(output))
    variants = stage.GetPrimAtPath("/World").GetVariantSet("wedge")
    assert variants.GetVariantNames() == [f"take_0{i}" for i in range(6)]
    finals = set()
    for name in variants.GetVariantNames():
        variants.SetVariantSelection(name)
        data = stage.GetPrimAtPath("/World").GetPrimStack()[0].layer.GetPrimAtPath(
            f"/World{{wedge={name}}}").customData["simbake"]
        settings = dict(data["settings"])
        reference = references[(settings["bodies.ball.restitution"], settings["bodies.crate.mass"])]
        cache = output.parent / data["stage"]
        assert first_difference(cache, reference) is None, name
        expected = Usd.Stage.Open(str(reference))
        for path in ("/World/ball", "/World/crate"):
            for t in (1, 5, 10):
                got = stage.GetPrimAtPath(path).GetAttribute("xformOp:translate").Get(t)
                assert got == expected.GetPrimAtPath(path).GetAttribute("xformOp:translate").Get(t), (name, path, t)
        finals.add(tuple(stage.GetPrimAtPath("/World/crate").GetAttribute("xformOp:translate").Get(10)))
    assert len(finals) == 6  # six different takes, not one repeated


def test_a_2x3_wedge_gives_the_sequential_bakes_caches_and_composes_each(client, references, tmp_path):
    output = tmp_path / "w.usda"
    seen = []
    results = simbake.wedge(_balls(tmp_path), VARIATIONS, client, output=output,
                            on_take=lambda r, done, total: seen.append((r.name, done, total)))
    assert [r.name for r in results] == [f"take_0{i}" for i in range(6)]
    assert all(r.baked and r.stats.frames == 10 for r in results)
    assert sorted(done for _, done, _ in seen) == list(range(1, 7)) and {t for *_, t in seen} == {6}
    assert [(r.settings["bodies.ball.restitution"], r.settings["bodies.crate.mass"]) for r in results] == \
        [(r, m) for r in RESTITUTIONS for m in MASSES]
    _assert_matches_references(output, references)
    takes = sorted(p.name for p in (tmp_path / "w.takes").iterdir())
    assert takes == sorted(["wedge.json"] + [f"take_0{i}{s}" for i in range(6) for s in (".usdc", ".qa.json")])
    assert not _temps(tmp_path)


def test_a_bad_value_fails_its_take_alone(client, tmp_path):
    scene = _balls(tmp_path)
    results = simbake.wedge(scene, {"bodies.crate.mass": [1.0, -3.0, 2.0]}, client, output=tmp_path / "w.usda")
    assert [r.baked for r in results] == [True, False, True]
    assert results[1].error == f"{scene}: bodies[1].mass: must be > 0, got -3.0"
    assert results[1].label == "bodies.crate.mass=-3.0 seed=0"
    from pxr import Usd

    stage = Usd.Stage.Open(str(tmp_path / "w.usda"))
    assert stage.GetPrimAtPath("/World").GetVariantSet("wedge").GetVariantNames() == ["take_00", "take_02"]
    failed = stage.GetRootLayer().customLayerData["simbake"]["wedge"]["failed"]
    assert failed["take_01"]["error"] == results[1].error
    assert not (tmp_path / "w.takes" / "take_01.usdc").exists()
    report = subprocess.run([SIMBAKE, "report", str(tmp_path / "w.usda")], capture_output=True, text=True,
                            timeout=TIMEOUT)
    assert report.returncode == 0, report.stderr
    assert f"FAILED: {scene}: bodies[1].mass: must be > 0, got -3.0" in report.stdout
    page = (tmp_path / "w.report.html").read_text()
    assert "take_01" in page and "must be &gt; 0, got -3.0" in page and page.count("<tr>") == 4


def test_a_shots_wedge_composes_each_takes_attribute_value(client, tmp_path):
    from pxr import Usd

    shot = Path(_copy(REPO / "assets" / "scenes" / "shot.usda", tmp_path))
    results = simbake.wedge(shot, {"/World/Props/Crate.physics:mass": [2.0, 30.0]}, client,
                            output=tmp_path / "w.usda", seeds=2)
    assert all(r.baked for r in results), [r.error for r in results]
    assert [(r.settings["/World/Props/Crate.physics:mass"], r.seed) for r in results] == \
        [(2.0, 0), (2.0, 1), (30.0, 0), (30.0, 1)]
    stage = Usd.Stage.Open(str(tmp_path / "w.usda"))
    variants = stage.GetPrimAtPath("/World").GetVariantSet("wedge")
    balls = {}
    for result in results:
        variants.SetVariantSelection(result.name)
        crate = stage.GetPrimAtPath("/World/Props/Crate")
        assert crate.GetAttribute("physics:mass").Get() == result.settings["/World/Props/Crate.physics:mass"]
        own = Usd.Stage.Open(str(result.stage))  # the take's shot stage: its cache over its override
        ball = stage.GetPrimAtPath("/World/Props/Ball").GetAttribute("xformOp:translate")
        assert ball.Get(36) == own.GetPrimAtPath("/World/Props/Ball").GetAttribute("xformOp:translate").Get(36)
        balls[(result.settings["/World/Props/Crate.physics:mass"], result.seed)] = ball.Get(1)
    # seed 1 moves the ball's start horizontally by at most 1 mm; seed 0 is the shot's own
    assert balls[(2.0, 0)] == balls[(30.0, 0)] != balls[(2.0, 1)] == balls[(30.0, 1)]
    moved = [a - b for a, b in zip(balls[(2.0, 1)], balls[(2.0, 0)])]
    assert 0 < max(abs(v) for v in moved) <= 1e-3 + 1e-12 and abs(moved[1]) < 1e-12


def test_a_batch_bakes_each_scene_as_bake_would_and_a_bad_one_fails_alone(client, tmp_path):
    a, b = tmp_path / "a.toml", tmp_path / "b.toml"
    a.write_text(BALLS.format(restitution=0.3, mass=1.0))
    b.write_text(BALLS.format(restitution=0.9, mass=4.0))
    bad = tmp_path / "bad.toml"
    bad.write_text(BALLS.format(restitution=2.0, mass=1.0))
    out = tmp_path / "out"
    out.mkdir()
    results = simbake.batch([a, bad, b], client, output_dir=out)
    assert [r.baked for r in results] == [True, False, True]
    assert results[1].error == f"{bad}: bodies[0].restitution: must be in [0, 1], got 2.0"
    assert sorted(p.name for p in out.iterdir()) == ["a.qa.json", "a.usdc", "b.qa.json", "b.usdc"]
    for scene in (a, b):
        reference = simbake.bake(simbake.load_scene(scene), tmp_path / f"{scene.stem}.ref.usdc").output
        assert first_difference(out / f"{scene.stem}.usdc", reference) is None


def test_preview_wedges_draws_one_row_per_take(client, tmp_path):
    from PIL import Image

    results = simbake.wedge(_balls(tmp_path), {"bodies.crate.mass": [1.0, -1.0, 6.0]}, client,
                            output=tmp_path / "w.usda")
    assert [r.baked for r in results] == [True, False, True]
    run = subprocess.run([SIMBAKE, "preview", str(tmp_path / "w.usda"), "--wedges", "-o", str(tmp_path / "s.png"),
                          "--frames", "1:10:3", "--size", "160x90"], capture_output=True, text=True, timeout=TIMEOUT)
    assert run.returncode == 0, run.stderr
    sheet = Image.open(tmp_path / "s.png")
    # two rows of a band (26) and 4 frames (90 + 2 gaps of 4), one failed band; 4 below each row
    assert sheet.size == (4 * 164 + 4, 2 * (26 + 98 + 4) + 26 + 4)
    pixels = sheet.convert("RGB")
    assert pixels.getpixel((2, 26 + 98 + 4 + 10))[0] > 150  # the failed take's band is red


# --------------------------------------------------------------------------------------
# A worker killed mid-bake
# --------------------------------------------------------------------------------------

def _kill_first_bake(parent: Path, stop: threading.Event, killed: list) -> None:
    """SIGKILL the process writing the first take's temp cache that appears under `parent`."""
    pattern = re.compile(r"\.(take_\d+)\.usdc\.(\d+)-.*\.tmp\.usdc")
    while not stop.is_set():
        for temp in parent.glob(".w.takes.*.tmp/.take_*.usdc.*.tmp.usdc"):
            match = pattern.fullmatch(temp.name)
            if match and int(match[2]) != os.getpid():
                os.kill(int(match[2]), signal.SIGKILL)
                killed.append((match[1], int(match[2])))
                return
        time.sleep(0.005)


def test_a_worker_killed_mid_bake_loses_nothing(tmp_path):
    from distributed import Client

    scene = tmp_path / "sheet.toml"
    scene.write_text(SHEET.format(frames=36, stiffness=1000.0))
    stiffnesses = [500.0, 1000.0, 2000.0, 4000.0]
    cluster = _local_cluster(allowed_failures=2)
    stop, killed = threading.Event(), []
    watcher = threading.Thread(target=_kill_first_bake, args=(tmp_path, stop, killed), daemon=True)
    try:
        with Client(cluster) as client:
            watcher.start()
            results = simbake.wedge(scene, {"cloths.sheet.stretch_stiffness": stiffnesses}, client,
                                    output=tmp_path / "w.usda")
    finally:
        stop.set()
        cluster.close(timeout=30)
    assert killed, "no bake was caught running"
    take, pid = killed[0]
    assert all(r.baked for r in results), [r.error for r in results]
    again = next(r for r in results if r.name == take)
    assert not again.worker.endswith(f":{pid}")  # baked again by a live worker
    assert not _temps(tmp_path)
    names = sorted(p.name for p in (tmp_path / "w.takes").iterdir())
    assert names == sorted(["wedge.json"] + [f"take_0{i}{s}" for i in range(4) for s in (".usdc", ".qa.json")])
    # the killed take's cache is whole: the same as a sequential bake of its values
    reference = tmp_path / "ref.toml"
    reference.write_text(SHEET.format(frames=36, stiffness=again.settings["cloths.sheet.stretch_stiffness"]))
    expected = simbake.bake(simbake.load_scene(reference), tmp_path / "ref.usdc").output
    assert first_difference(again.cache, expected) is None


def test_retries_are_bounded_a_take_whose_worker_keeps_dying_fails_alone(tmp_path):
    from distributed import Client

    scene = tmp_path / "sheet.toml"
    scene.write_text(SHEET.format(frames=36, stiffness=1000.0))
    cluster = _local_cluster(allowed_failures=0)  # no second run: one death fails the take
    stop, killed = threading.Event(), []
    watcher = threading.Thread(target=_kill_first_bake, args=(tmp_path, stop, killed), daemon=True)
    try:
        with Client(cluster) as client:
            watcher.start()
            results = simbake.wedge(scene, {"cloths.sheet.stretch_stiffness": [500.0, 1000.0, 2000.0]}, client,
                                    output=tmp_path / "w.usda")
    finally:
        stop.set()
        cluster.close(timeout=30)
    assert killed, "no bake was caught running"
    dead = next(r for r in results if r.name == killed[0][0])
    assert dead.error == "its worker died 1 time(s) baking it (killed or out of memory); not tried again"
    assert [r.baked for r in results].count(True) == 2 and not _temps(tmp_path)
    assert not (tmp_path / "w.takes" / f"{dead.name}.usdc").exists()
    from pxr import Sdf

    failed = Sdf.Layer.FindOrOpen(str(tmp_path / "w.usda")).customLayerData["simbake"]["wedge"]["failed"]
    assert failed[dead.name]["error"] == dead.error


# --------------------------------------------------------------------------------------
# The farm path: dask scheduler and dask worker on localhost
# --------------------------------------------------------------------------------------

def _stop(processes: list[subprocess.Popen]) -> None:
    """SIGTERM each (a dask worker closes its own worker process), then SIGKILL what is left."""
    for p in processes:
        if p.poll() is None:
            p.terminate()
        try:
            p.wait(timeout=20)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(timeout=20)


@pytest.fixture
def farm(tmp_path):
    """`dask scheduler` and two `dask worker` processes on localhost; their address. Stopped
    at the end, even on failure."""
    from distributed import Client

    info = tmp_path / "scheduler.json"
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    processes = [subprocess.Popen([DASK, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                                   "--scheduler-file", str(info)], **quiet)]
    try:
        deadline = time.monotonic() + TIMEOUT
        while not info.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        address = json.loads(info.read_text())["address"]
        for _ in range(2):
            processes.append(subprocess.Popen([DASK, "worker", address, "--nthreads", "1", "--no-dashboard",
                                               "--host", "127.0.0.1"], **quiet))
        with Client(address, timeout="60s") as client:
            client.wait_for_workers(2, timeout=TIMEOUT)
        yield address
    finally:
        _stop(processes[1:] + processes[:1])  # the workers first


def test_the_same_wedge_through_a_farm_scheduler(farm, references, tmp_path):
    scene = _balls(tmp_path)
    run = subprocess.run([SIMBAKE, "wedge", str(scene), "--set", "bodies.ball.restitution=0.2,0.8",
                          "--set", "bodies.crate.mass=1.0,3.0,6.0", "-o", str(tmp_path / "w.usda"),
                          "--scheduler", farm], capture_output=True, text=True, timeout=TIMEOUT)
    assert run.returncode == 0, run.stderr
    assert f"at {farm}" in run.stdout and "2 Dask worker(s)" in run.stdout
    assert run.stdout.count(" baked: 10 frames") == 6
    _assert_matches_references(tmp_path / "w.usda", references)
    assert not _temps(tmp_path)


# --------------------------------------------------------------------------------------
# The command line
# --------------------------------------------------------------------------------------

def test_wedge_command_with_a_failed_take_exits_1_and_writes_the_others(tmp_path):
    scene = _balls(tmp_path)
    run = subprocess.run([SIMBAKE, "wedge", str(scene), "--set", "bodies.ball.restitution=0.4,1.5",
                          "-o", str(tmp_path / "w.usda"), "--workers", "1"],
                         capture_output=True, text=True, timeout=TIMEOUT, cwd=tmp_path)
    assert run.returncode == 1
    assert "dashboard http://" in run.stdout
    assert "[2/2]" in run.stdout and "wedged 1 of 2 take(s)" in run.stdout
    assert run.stderr.strip() == (f"simbake: error: take_01 (bodies.ball.restitution=1.5 seed=0): {scene}: "
                                  "bodies[0].restitution: must be in [0, 1], got 1.5")
    assert (tmp_path / "w.takes" / "take_00.usdc").is_file() and (tmp_path / "w.usda").is_file()


def test_batch_command_bakes_each_scene_and_exits_1_when_one_fails(tmp_path):
    good, bad = tmp_path / "good.toml", tmp_path / "bad.toml"
    good.write_text(BALLS.format(restitution=0.3, mass=1.0))
    bad.write_text(BALLS.format(restitution=0.3, mass=0.0))
    (tmp_path / "out").mkdir()
    run = subprocess.run([SIMBAKE, "batch", "good.toml", "bad.toml", "-o", "out", "--workers", "1"],
                         capture_output=True, text=True, timeout=TIMEOUT, cwd=tmp_path)
    assert run.returncode == 1
    assert "good.toml baked: 10 frames" in run.stdout and "-> out/good.usdc" in run.stdout
    assert run.stderr.strip() == "simbake: error: bad.toml: bodies[1].mass: must be > 0, got 0.0"
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["good.qa.json", "good.usdc"]


@pytest.mark.parametrize("arguments, message", [
    (["--set", "bodies.nope.mass=1,2"], "--set bodies.nope.mass: no body named 'nope' (bodies: ball, crate)"),
    (["--set", "bodies.ball.colour=1,2"], "--set bodies.ball.colour: unknown key 'colour' (allowed: "),
    (["--set", "bodies.ball.restitution"], "--set: must be KEY=V1,V2,..."),
    (["--set", "bodies.ball.restitution=0.1,,0.2"], "--set bodies.ball.restitution: an empty value"),
    (["--set", "bodies.ball.mass=1", "--seeds", "0"], "--seeds: must be a whole number >= 1, got 0"),
    (["--set", "bodies.ball.mass=1", "--set", "bodies.ball.mass=2"], "--set bodies.ball.mass: given twice"),
    (["--set", "cloths.sheet.damping=1"], "--set cloths.sheet.damping: no cloth named 'sheet' (cloths: none)"),
    (["--set", "bodies.ball.mass=1", "--threads", "-1"], "--threads: must be a whole number in [0, 1024]"),
    (["--set", "bodies.ball.mass=1", "--workers", "0"], "--workers: must be a whole number in [1, 1024], got 0"),
    (["--set", "bodies.ball.mass=1", "--retries", "-1"], "--retries: must be a whole number in [0, 100], got -1"),
    (["--set", "bodies.ball.mass=1", "--scheduler", "tcp://127.0.0.1:9", "--workers", "2"],
     "--workers: sets a local cluster's size"),
])
def test_wedge_bad_input_exits_2_with_one_line_and_writes_nothing(tmp_path, arguments, message):
    scene = _balls(tmp_path)
    run = subprocess.run([SIMBAKE, "wedge", str(scene), *arguments, "-o", str(tmp_path / "w.usda")],
                         capture_output=True, text=True, timeout=TIMEOUT, cwd=tmp_path)
    assert run.returncode == 2, run.stderr
    assert run.stderr.startswith("simbake: error: ") and message in run.stderr, run.stderr
    assert len(run.stderr.strip().splitlines()) == 1 and "Traceback" not in run.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["balls.toml"]


def test_wedge_never_replaces_a_folder_it_did_not_write(tmp_path):
    scene = _balls(tmp_path)
    mine = tmp_path / "w.takes"
    mine.mkdir()
    (mine / "notes.txt").write_text("a user's file")
    run = subprocess.run([SIMBAKE, "wedge", str(scene), "--set", "bodies.ball.mass=1,2", "-o", str(tmp_path / "w.usda")],
                         capture_output=True, text=True, timeout=TIMEOUT)
    assert run.returncode == 2
    assert "w.takes: exists and was not written by simbake wedge" in run.stderr
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["balls.toml", "notes.txt", "w.takes"]


def test_usd_keys_are_checked_before_any_bake(tmp_path):
    shot = _copy(REPO / "assets" / "scenes" / "shot.usda", tmp_path)
    for key, message in [("/World/Nope.physics:mass", "no prim at /World/Nope in the shot"),
                         ("/World/Props/Crate.physics:mas", "/World/Props/Crate has no attribute physics:mas"),
                         ("World.mass", "must be a USD attribute /PRIM/PATH.ATTRIBUTE")]:
        run = subprocess.run([SIMBAKE, "wedge", str(shot), "--set", f"{key}=1,2", "-o", str(tmp_path / "w.usda")],
                             capture_output=True, text=True, timeout=TIMEOUT)
        assert run.returncode == 2 and message in run.stderr, run.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["shot.usda"]


def test_bake_does_not_import_dask(tmp_path):
    scene = _balls(tmp_path)
    code = ("import sys; from simbake.cli import main; status = main(['bake', sys.argv[1], '-o', sys.argv[2], '-q']); "
            "print(status, 'dask' in sys.modules, 'distributed' in sys.modules)")
    run = subprocess.run([sys.executable, "-c", code, str(scene), str(tmp_path / "b.usdc")],
                         capture_output=True, text=True, timeout=TIMEOUT)
    assert run.stdout.splitlines()[-1] == "0 False False", run.stderr
