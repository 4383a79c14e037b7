"""Helpers shared by the scene-level rigid benchmarks in benchmarks/rigid/.

Everything generic (timing, tables, JSON, plots, machine info, quaternions) lives in
``benchmarks/common.py`` and is reused from there; this module only adds what the
scene-level benchmarks need on top:

- the shipped scenes (``assets/scenes/*.toml``) loaded through the pipeline itself
  (``simbake.load_scene``, ``simbake.assets.load_assets``);
- :func:`make_world`: the pipeline's ``simulate.build_world`` with World settings
  (``build_world`` always builds ``World(gravity=...)`` with the core's defaults, so this
  mirrors its calls one for one; :func:`check_mirror` checks, per run, that both give
  bit-identical poses when the settings are the defaults);
- :func:`run_frames`: steps a world frame by frame (all stepping in C++, ``step_frame``),
  with only the ``step_frame`` calls inside the clock and the poses read between frames;
- :func:`run_child`: runs a script in a fresh Python process and reads back one JSON
  line, for figures that must not share a process (peak memory, bakes pinned to one CPU).
  Peak memory is the child's VmHWM (:func:`peak_rss_mib`, resettable), not ``ru_maxrss``:
  Linux carries the forking parent's peak through exec into a child's ``ru_maxrss``.

Every world here is built with ``threads=1`` unless a benchmark sweeps threads: the
figures are single-thread figures (see /work/shared/PLATFORM.md).
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

RIGID_DIR = Path(__file__).resolve().parent
BENCH_DIR = RIGID_DIR.parent
REPO = BENCH_DIR.parent
SCENES_DIR = REPO / "assets" / "scenes"

import simbake
from benchmarks import common
from simbake import _core, assets as sb_assets, simulate as sb_simulate

THREADS = 1  # single-thread figures unless a benchmark says otherwise


# ---------------------------------------------------------------------------------------
# scenes and worlds


def load(name: str):
    """(scene, assets) of a shipped scene, through the pipeline's own loaders."""
    scene = simbake.load_scene(SCENES_DIR / f"{name}.toml")
    return scene, sb_assets.load_assets(scene)


def make_world(scene, assets, **settings) -> "_core.World":
    """simulate.build_world(scene, assets) with World(**settings) (max_substep, threads, ...);
    threads defaults to 1. Rigid scenes only: a scene with cloth is refused."""
    if getattr(scene, "cloths", ()):
        raise ValueError(f"{scene.path.name}: make_world builds rigid bodies only, this scene has cloth")
    settings.setdefault("threads", THREADS)
    return sb_simulate.build_world(scene, assets, **settings)


def check_mirror(scene, assets, frames: int = 24) -> dict:
    """make_world (one thread) against the pipeline's build_world (all cores) over `frames`
    frames: the poses must be bit-identical (the core's results do not depend on the thread
    count)."""
    a = sb_simulate.build_world(scene, assets)
    b = make_world(scene, assets)
    for _ in range(frames):
        a.step_frame(1.0 / scene.fps, scene.substeps)
        b.step_frame(1.0 / scene.fps, scene.substeps)
    ta, qa = a.mesh_poses()
    tb, qb = b.mesh_poses()
    diff = float(max(np.abs(ta - tb).max(), np.abs(qa - qb).max()))
    return {"frames": frames, "identical": diff == 0.0, "max_abs_difference": diff}


def core_module_info() -> dict:
    """Which build of simbake._core ran (the checkout is edited and rebuilt while we run)."""
    import datetime
    import hashlib
    path = Path(_core.__file__)
    stamp = datetime.datetime.fromtimestamp(path.stat().st_mtime, datetime.timezone.utc)
    head = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True,
                          text=True).stdout.strip()
    return {"path": str(path), "sha1": hashlib.sha1(path.read_bytes()).hexdigest()[:12],
            "mtime": stamp.isoformat(timespec="seconds"), "git_head": head}


def body_index(scene) -> dict:
    return {body.name: i for i, body in enumerate(scene.bodies)}


# ---------------------------------------------------------------------------------------
# stepping


def run_frames(world: "_core.World", frames: int, frame_dt: float, substeps: int = 0,
               record: bool = True) -> dict:
    """Step `frames` frames; only step_frame is inside the clock (wall and process CPU).
    Returns the stepping time, the substeps, bodies asleep and max penetration after every
    frame, and (when `record`) the mesh
    translations at every frame boundary (frames + 1, n, 3) and the deepest penetration
    seen at any frame."""
    t0, q0 = world.mesh_poses()
    translations = [t0.copy()] if record else []
    counts, asleep, penetration, wall, cpu = [], [], [], 0.0, 0.0
    for _ in range(frames):
        start, start_cpu = time.perf_counter(), time.process_time()
        counts.append(world.step_frame(frame_dt, substeps))
        cpu += time.process_time() - start_cpu
        wall += time.perf_counter() - start
        if record:
            translations.append(world.mesh_poses()[0].copy())
        penetration.append(world.statistics()["max_penetration"])
        asleep.append(world.sleeping_count)
    t1, q1 = world.mesh_poses()
    return {"wall": wall, "cpu": cpu, "counts": counts, "asleep": asleep,
            "translations": np.array(translations) if record else None,
            "final_translations": t1, "final_orientations": q1, "initial_orientations": q0,
            "penetration": penetration, "max_penetration_any_frame": max(penetration, default=0.0),
            "deepest_penetration_time": (int(np.argmax(penetration)) + 1) * frame_dt if penetration else None}


def note_wall_over_cpu(wall: float, cpu: float) -> None:
    """Feed common's wall/CPU tally (the .md header's 'wall / CPU time' figure)."""
    if cpu > 0.0:
        common._WALL_OVER_CPU.append(wall / cpu)


def timed_repeats(make, frames: int, frame_dt: float, repeats: int, substeps: int = 0) -> dict:
    """Median over `repeats` fresh worlds of the stepping wall time, per simulated second.
    Every repeat also records poses (outside the clock); the first repeat's run is returned
    as 'run' and the others are checked to end in the same state (the core is deterministic)."""
    walls, cpus, first, same = [], [], None, True
    for _ in range(repeats):
        world = make()
        run = run_frames(world, frames, frame_dt, substeps)
        run["world"] = world
        walls.append(run["wall"])
        cpus.append(run["cpu"])
        note_wall_over_cpu(run["wall"], run["cpu"])
        if first is None:
            first = run
        else:
            same = same and bool(np.array_equal(first["final_translations"], run["final_translations"]))
    seconds = frames * frame_dt
    walls_sorted = sorted(walls)
    median = float(np.median(walls))
    return {"run": first, "repeats": repeats, "all": walls, "cpu_all": cpus,
            "median": median, "min": walls_sorted[0], "max": walls_sorted[-1],
            "per_simulated_second": median / seconds,
            "cpu_per_simulated_second": float(np.median(cpus)) / seconds,
            "simulated_seconds": seconds, "repeats_identical": same}


def profile_per_second(world: "_core.World", simulated_seconds: float) -> dict:
    return {k: float(v) / simulated_seconds for k, v in world.profile().items()}


def drift(translations: np.ndarray, times: np.ndarray) -> dict:
    """Largest displacement of any body from its start, at any recorded frame (m)."""
    d = np.linalg.norm(translations - translations[0], axis=-1)   # (frames, n)
    k, i = np.unravel_index(int(d.argmax()), d.shape)
    return {"max": float(d.max()), "end": float(d[-1].max()), "worst_body": int(i),
            "worst_time": float(times[k])}


def all_asleep_time(asleep: list[int], bodies: int, frame_dt: float) -> float | None:
    """Time (s) after which every body stayed asleep to the end, or None."""
    if not asleep or asleep[-1] < bodies:
        return None
    k = len(asleep)
    while k > 0 and asleep[k - 1] >= bodies:
        k -= 1
    return (k + 1) * frame_dt


def fraction_label(seconds: float) -> str:
    """1/240 for 0.0041666..."""
    return f"1/{round(1.0 / seconds):d}"


# ---------------------------------------------------------------------------------------
# child processes


def maxrss_mib() -> float:
    """ru_maxrss of this process (MiB; Linux reports KiB). Careful in a child process: Linux
    carries the forking parent's peak through exec into it (exec_mmap keeps the old mm's
    high-water mark in signal->maxrss), so a child of a big parent never reads below the
    parent's size. peak_rss_mib() reads the child's own high-water mark instead."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _status_mib(key: str) -> float:
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(key + ":"):
                return float(line.split()[1]) / 1024.0
    except OSError:
        pass
    return float("nan")


def current_rss_mib() -> float:
    return _status_mib("VmRSS")


def peak_rss_mib() -> float:
    """This process's own peak resident set size (VmHWM, MiB) since it started or since
    reset_peak_rss()."""
    return _status_mib("VmHWM")


def reset_peak_rss() -> bool:
    """Reset VmHWM to the current RSS (Linux >= 4.0: write 5 to /proc/self/clear_refs)."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
        return True
    except OSError:
        return False


def run_child(script: Path, args: list[str], timeout: float = 900.0) -> dict:
    """Run `python script args...` in a fresh process; its last stdout line is JSON."""
    cmd = [sys.executable, str(script), *args]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout,
                          env={**os.environ, "PYTHONHASHSEED": "0"})
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
    lines = [line for line in proc.stdout.splitlines() if line.strip()]
    return json.loads(lines[-1])
