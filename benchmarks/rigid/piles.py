"""Piles: wall time, threads, memory and stage profile of two big piles.

Scenes:
- pile.toml: the shipped scene, 200 mixed nonconvex meshes (tori, L-shapes, spheres, baked
  level sets) poured onto the ground, 6 s; loaded through the pipeline, built with
  common_rigid.make_world.
- box1000: 1000 boxes (0.5 m, 1000 kg/m^3) on a 10x10x10 grid, 0.8 m spacing, lowest
  bottoms 0.5 m above the ground, each tilted randomly up to 20 degrees (fixed seed), mu 0.5,
  5 s: the scene of the peer benchmark (benchmarks/peers/scenes.py, "pile"), built the way
  benchmarks/peers/run_simbake.py builds it (analytic LevelSet.box, box_mesh(size, 4)
  samples) but with the World settings below.

Each at max_substep 1/240 s (the default) and 1/120 s (automatic substeps otherwise), each
with threads=1 and threads=2, one run each, every run in its own child process (so that its
peak memory is that run's own and the thread pools start fresh). threads=1 and threads=2 run
back to back; the ratio of their wall times is the measured parallel speed-up on this machine
at that moment (the second vCPU is not always there, see /work/shared/PLATFORM.md). The
core's results do not depend on the thread count: the child reports a hash of the final poses
and the table says whether both thread counts agree.

Known answer: none exact; a pile must not explode (no centre below the ground, nothing
faster than free fall from the highest start) and should come to rest. Measured: wall and
CPU seconds per simulated second of the stepping alone, the per-stage breakdown
(world.profile()), the child's peak memory while building and stepping (VmHWM reset after
the imports; ru_maxrss of a child is polluted by its parent, see the notes in the results),
bodies asleep at the end, max penetration at the end and the deepest at any frame, the
largest speed over the last frame.
"""

from __future__ import annotations

import hashlib
import json
import math
import sys

import numpy as np

import common_rigid as cr
from common_rigid import _core, common
from benchmarks.common import Result, Series

from benchmarks.peers import run_simbake  # benchmarks/peers/run_simbake.py: how it samples a box
from benchmarks.peers import scenes as peer_scenes  # benchmarks/peers/scenes.py: the 1000-box pile

NAME = "rigid_piles"
SCENES = ["pile", "box1000"]
MAX_SUBSTEPS = [1 / 240, 1 / 120]
THREADS = [1, 2]
STAGES = ["broad_phase", "collisions", "contacts", "shock_propagation"]


# ---------------------------------------------------------------------------------------
# the child: one run


def build(scene_name: str, **settings):
    """(world, frames, frame_dt, body names, peers scene or None)"""
    if scene_name == "pile":
        scene, assets = cr.load("pile")
        return cr.make_world(scene, assets, **settings), scene.end_frame - scene.start_frame, 1.0 / scene.fps, None
    peer = peer_scenes.build("pile")
    world = _core.World(gravity=np.array(peer.gravity, dtype=float), **settings)
    mu = peer_scenes.per_object(peer.mu, "geometric")
    world.set_ground(height=peer.ground_height, friction=mu, restitution=0.0)
    size = np.array(peer.bodies[0].size, dtype=float)
    level_set = _core.LevelSet.box(size)
    samples = _core.box_mesh(size, run_simbake.BOX_SUBDIVISIONS)[0]
    mass_properties = _core.box_mass_properties(size)
    for b in peer.bodies:
        assert b.shape == "box" and tuple(b.size) == tuple(size)
        world.add_body(shape=level_set, samples=samples, mass_properties=mass_properties, mass=b.mass,
                       origin=np.array(b.position, dtype=float),
                       orientation=np.array(b.orientation, dtype=float), linear_velocity=np.zeros(3),
                       angular_velocity=np.zeros(3), friction=mu, restitution=peer.e, kinematic=False)
    return world, peer.frames, 1.0 / peer_scenes.FPS, peer


def child(scene_name: str, threads: int, max_substep: float) -> None:
    peak_imports, rss_imports = cr.peak_rss_mib(), cr.current_rss_mib()
    reset = cr.reset_peak_rss()   # from here VmHWM is the peak of building and stepping
    world, frames, frame_dt, peer = build(scene_name, threads=threads, max_substep=max_substep)
    peak_built, rss_built = cr.peak_rss_mib(), cr.current_rss_mib()
    run = cr.run_frames(world, frames, frame_dt)
    peak_end, rss_end = cr.peak_rss_mib(), cr.current_rss_mib()
    seconds = frames * frame_dt
    p = run["translations"]
    speed_end = np.linalg.norm(p[-1] - p[-2], axis=-1) / frame_dt
    out = {
        "scene": scene_name, "threads": threads, "max_substep": max_substep, "bodies": world.body_count,
        "simulated_seconds": seconds, "wall": run["wall"], "cpu": run["cpu"],
        "wall_per_simulated_second": run["wall"] / seconds, "cpu_per_simulated_second": run["cpu"] / seconds,
        "substeps_per_frame": {"mean": float(np.mean(run["counts"])), "max": int(max(run["counts"]))},
        "asleep_end": world.sleeping_count, "asleep_by_frame": run["asleep"],
        "max_penetration_end": world.statistics()["max_penetration"],
        "max_penetration_any_frame": run["max_penetration_any_frame"],
        "deepest_penetration_time": run["deepest_penetration_time"],
        "max_speed_end": float(speed_end.max()), "mean_speed_end": float(speed_end.mean()),
        "centres_below_ground": int((p[-1, :, 1] < 0.0).sum()),
        "min_height_end": float(p[-1, :, 1].min()), "max_height_end": float(p[-1, :, 1].max()),
        "statistics_end": world.statistics(),
        "profile_seconds": world.profile(),
        "profile_per_simulated_second": cr.profile_per_second(world, seconds),
        "rss_mib": {"peak_of_imports": peak_imports, "after_imports": rss_imports, "peak_reset_after_imports": reset,
                    "peak_build": peak_built, "after_build": rss_built, "peak_end": peak_end, "end": rss_end,
                    "peak_end_over_imports": peak_end - rss_imports,
                    "ru_maxrss_end": cr.maxrss_mib()},
        "final_pose_sha1": hashlib.sha1(np.ascontiguousarray(run["final_translations"]).tobytes()
                                        + np.ascontiguousarray(run["final_orientations"]).tobytes()).hexdigest()[:16],
        "allowed_cpus": common.allowed_cpus(), "load_average": common.load_average(),
    }
    if peer is not None:   # the peer benchmark's own accuracy measures, on its recorded frames
        out["peer_analysis"] = peer_scenes.analyze(peer, p[peer.recorded_frames()])
    print(json.dumps(common._jsonable(out)))


# ---------------------------------------------------------------------------------------
# the parent


def run() -> Result:
    data, rows = [], []
    for scene_name in SCENES:
        for max_substep in MAX_SUBSTEPS:
            pair = []
            for threads in THREADS:
                r = cr.run_child(cr.RIGID_DIR / "piles.py", ["--child", scene_name, str(threads), repr(max_substep)])
                if threads == 1:
                    cr.note_wall_over_cpu(r["wall"], r["cpu"])
                pair.append(r)
                print(f"  {scene_name} max_substep {cr.fraction_label(max_substep)} threads {threads}: "
                      f"{r['wall_per_simulated_second']:.3g} wall s / sim s, peak {r['rss_mib']['peak_end']:.0f} MiB, "
                      f"asleep {r['asleep_end']}/{r['bodies']}", flush=True)
            one, two = pair
            ratio = one["wall"] / two["wall"]
            same = one["final_pose_sha1"] == two["final_pose_sha1"]
            for r in pair:
                r["speedup_threads_2_over_1"] = ratio
                r["same_result_both_thread_counts"] = same
                data.append(r)
                prof = r["profile_per_simulated_second"]
                other = sum(prof.values()) - sum(prof[s] for s in STAGES)
                rows.append([r["scene"], cr.fraction_label(r["max_substep"]), r["threads"],
                             r["substeps_per_frame"]["mean"], r["wall_per_simulated_second"],
                             r["cpu_per_simulated_second"], ratio if r["threads"] == 2 else "",
                             "yes" if same else "NO",
                             r["rss_mib"]["peak_end"], r["rss_mib"]["peak_end_over_imports"],
                             f"{r['asleep_end']}/{r['bodies']}", 1000.0 * r["max_penetration_end"],
                             1000.0 * r["max_penetration_any_frame"], r["max_speed_end"],
                             *[prof[s] for s in STAGES], other])
    series = []
    for scene_name in SCENES:
        for threads in THREADS:
            runs = [r for r in data if r["scene"] == scene_name and r["threads"] == threads]
            series.append(Series(f"{scene_name}, threads={threads}", [r["wall_per_simulated_second"] for r in runs],
                                 [r["max_penetration_any_frame"] for r in runs],
                                 [cr.fraction_label(r["max_substep"]) for r in runs], "o" if threads == 1 else "s"))
    return Result(
        name=NAME,
        title="Piles: pile.toml (200 meshes, 6 s), 1000 boxes (5 s); threads 1, 2; max_substep 1/240, 1/120",
        data={"core_module": cr.core_module_info(), "scenes": SCENES, "max_substeps": MAX_SUBSTEPS,
              "threads": THREADS, "runs": data},
        table_headers=["scene", "max_substep", "threads", "substeps/frame", "wall s / sim s", "CPU s / sim s",
                       "speed-up 2 vs 1 thread", "same poses 1 & 2 threads", "peak RSS MiB", "peak over imports MiB",
                       "asleep at end", "max penetration at end mm", "deepest penetration mm", "max speed at end m/s",
                       *[f"{s} s/sim s" for s in STAGES], "other stages s/sim s"],
        table_rows=rows,
        series=series,
        xlabel="wall seconds per simulated second (one run each)",
        ylabel="deepest penetration at any frame (m)",
        notes=["every run in its own child process, one run each (too long to repeat inside the time budget); "
               "threads=1 and threads=2 back to back; the speed-up is their wall-time ratio in that run and "
               "changes with the load on the shared 2-vCPU machine (CPU s / sim s of a threads=1 run well below "
               "its wall s / sim s means another process had our CPU)",
               "peak RSS: the child's VmHWM, reset (clear_refs) right after its imports, so it is the peak while "
               "loading the scene's assets, building the world and stepping, on top of the ~150 MiB of Python, "
               "NumPy, simbake and usd-core; peak over imports: that minus the RSS right after the imports. "
               "Not ru_maxrss: Linux carries the forking parent's peak through exec into the child's ru_maxrss "
               "(inside run_all that was the parent's 235 MiB for every run); it is kept in the JSON",
               "stage columns: world.profile() per simulated second (wall time inside each stage; with 2 threads "
               "the stages run in parallel inside); 'other' = velocities + positions + sleeping + statistics",
               "same poses: a hash of every body's final pose agrees between threads=1 and threads=2",
               "box1000 is the peer benchmark's pile (benchmarks/peers/scenes.py) with its box samples "
               "(box_mesh(size, 4)); pile.toml uses the pipeline's assets (automatic voxel sizes, cached grids)",
               "the box1000 child also runs the peer benchmark's analyze() (speeds, heights, explosion check): "
               "peer_analysis in the JSON"],
    )


if __name__ == "__main__":
    if len(sys.argv) == 5 and sys.argv[1] == "--child":
        child(sys.argv[2], int(sys.argv[3]), float(sys.argv[4]))
    else:
        common.main(run)
