"""Deepest box-into-box overlap of the jittered 1000-box pile, over several jitters.

    .venv/bin/python benchmarks/rigid/pile_overlap.py [--seconds 3] [--seeds 0 1 2 3]

The peer benchmark's pile (benchmarks/peers/scenes.py "pile": 0.5 m boxes on a 10x10x10 grid
at 0.8 m, each tilted up to 20 degrees) built as benchmarks/peers/run_simbake.py builds it,
one thread, stepped at 60 fps with automatic substeps; the random tilts drawn from each seed
in turn (seed 0 is the benchmark's own, PILE_SEED). At every frame the deepest overlap of any
two boxes is measured from the poses alone by the separating-axis depth (scenes.box_overlap,
the measure every engine gets), independent of simbake's contacts and QA. The worst over the
frames is extreme-value statistics of a chaotic pile: one jitter says little, so the table
gives each seed's worst, their mean and their maximum, and the stepping's CPU seconds.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from benchmarks.peers import scenes
from benchmarks.peers.run_simbake import build_world

FPS = 60


def deepest_overlaps(seed: int, seconds: float) -> tuple[np.ndarray, float]:
    """(frames) the deepest box pair overlap at each frame (m), and the stepping's CPU seconds."""
    saved = scenes.PILE_SEED
    scenes.PILE_SEED = seed if seed else saved
    try:
        scene = scenes.build("pile")
    finally:
        scenes.PILE_SEED = saved
    world = build_world(scene, threads=1)
    half = 0.5 * np.array([b.size for b in scene.bodies], dtype=float)
    reach = 2.0 * float(np.linalg.norm(half, axis=-1).max())
    deepest, cpu = [], 0.0
    for _ in range(int(round(seconds * FPS))):
        start = time.process_time()
        world.step_frame(1.0 / FPS)
        cpu += time.process_time() - start
        state = world.body_states()
        p, R = state["center_of_mass"], scenes.quaternion_matrices(state["orientation"])
        pairs = scenes.close_pairs(p, reach)
        i, j = pairs[:, 0], pairs[:, 1]
        deepest.append(float(scenes.box_overlap(p[i], R[i], half[i], p[j], R[j], half[j]).max()) if len(pairs) else 0.0)
    return np.array(deepest), cpu


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    args = ap.parse_args(argv)
    worst = []
    print("| seed | deepest overlap (mm) | at frame | CPU s |")
    print("| --- | --- | --- | --- |")
    for seed in args.seeds:
        depths, cpu = deepest_overlaps(seed, args.seconds)
        worst.append(depths.max())
        print(f"| {seed or scenes.PILE_SEED} | {1000 * depths.max():.1f} | {int(depths.argmax()) + 1} | {cpu:.2f} |")
    print(f"\nmean of the worst {1000 * np.mean(worst):.1f} mm, maximum {1000 * np.max(worst):.1f} mm "
          f"({args.seconds:g} s at {FPS} fps, one thread)")


if __name__ == "__main__":
    main()
