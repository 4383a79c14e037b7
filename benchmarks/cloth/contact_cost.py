"""Cloth with bodies against cloth alone: the cost per vertex and cloth step of
`assets/scenes/cloth_demo.toml` (a 48 x 48 sheet on six bodies and a torus) against the
64 x 64 drape (`assets/scenes/drape.toml`, one kinematic sphere), in the cloth-body contacts
stage and in the whole cloth step.

    .venv/bin/python benchmarks/cloth/contact_cost.py [--frames N] [--rounds R]

Each scene is stepped in this process on one thread (`World(threads=1)`, built by the
pipeline's `simulate.build_world`), the two in turn, R rounds (default 1). A stage's CPU
seconds are its share of the world's stage profile (wall clock) times the stepping's thread
CPU time, so another process taking the CPU does not count. Cost per vertex-step: a stage's
CPU time / (vertices x cloth steps taken). `--frames N` steps each scene's first N frames
only (default: all).
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import simbake
from simbake import assets as sb_assets, simulate

ROOT = Path(__file__).resolve().parents[2]

SCENES = ("drape", "cloth_demo")


def run(name: str, frames: int | None) -> dict:
    """One bake's stepping of scene `name`: CPU seconds, cloth steps, vertices, stage CPU."""
    scene = simbake.load_scene(ROOT / "assets" / "scenes" / f"{name}.toml")
    bodies = sb_assets.load_assets(scene)
    cloths = [sb_assets.load_cloth(scene, i) for i in range(len(scene.cloths))]
    world = simulate.build_world(scene, bodies, cloths, threads=1)
    count = scene.frame_count - 1 if frames is None else min(frames, scene.frame_count - 1)
    wall, cpu = time.perf_counter(), time.thread_time()
    for _ in range(count):
        world.step_frame(1.0 / scene.fps, scene.substeps)
    wall, cpu = time.perf_counter() - wall, time.thread_time() - cpu
    profile = world.profile()
    scale = cpu / wall  # (wall of the profile -> CPU)
    vertices = sum(len(c.vertices) for c in cloths)
    steps = int(world.statistics()["cloth_steps"])
    return {"scene": name, "frames": count, "cpu": cpu, "wall": wall, "vertices": vertices, "cloth_steps": steps,
            "contacts": profile["cloth_contacts"] * scale, "cloth": profile["cloths"] * scale}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=int)
    parser.add_argument("--rounds", type=int, default=1)
    args = parser.parse_args()
    runs: dict[str, list[dict]] = {name: [] for name in SCENES}
    for _ in range(args.rounds):
        for name in SCENES:
            r = run(name, args.frames)
            runs[name].append(r)
            per = 1e6 / (r["vertices"] * r["cloth_steps"])
            print(f"{name}: {r['frames']} frames, {r['cloth_steps']} cloth steps x {r['vertices']} vertices, "
                  f"CPU {r['cpu']:.2f} s (wall {r['wall']:.2f}); contacts {r['contacts']:.2f} s "
                  f"({r['contacts'] * per:.3f} us a vertex-step), cloth step {r['cloth']:.2f} s "
                  f"({r['cloth'] * per:.3f} us)", flush=True)
    ratio = {}
    for key in ("contacts", "cloth"):
        cost = {name: statistics.median(r[key] / (r["vertices"] * r["cloth_steps"]) for r in runs[name])
                for name in SCENES}
        ratio[key] = cost["cloth_demo"] / cost["drape"]
    print(f"cloth_demo / drape per vertex-step: contacts {ratio['contacts']:.2f}x, "
          f"whole cloth step {ratio['cloth']:.2f}x (medians over {args.rounds} round(s))")


if __name__ == "__main__":
    main()
