"""The drape (drape_spec.py, built as run_simbake.py builds it) stepped frame by frame, two
lines a frame: the CPU seconds it took, the largest edge strain, the fastest vertex, the lowest
point, the deepest point into the sphere; then where the CPU went (the cloth sub-stages of
World.profile, the solver's iterations) and what self-collision did in the frame (repulsions,
collision impulses, impact zones, full searches for candidate pairs and the pairs they found,
updates around vertices that left their boxes, pairs put through the continuous test). It
stops after the frame where the strain first passes 50% (a blow-up) and prints that vertex.

    .venv/bin/python benchmarks/cloth/frame_trace.py [N] [FRAMES]

N vertices a side (default 257), FRAMES frames of 1/24 s (default 72, the benchmark's 3 s).
For finding where a run goes wrong; the benchmark itself is compare.py.
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import drape_spec as spec  # noqa: E402
import run_simbake  # noqa: E402

COUNTS = ("self_repulsions", "self_collision_impulses", "impact_zone_rounds", "impact_zone_vertices",
          "cloth_held_still", "self_collision_searches", "self_collision_candidates", "self_collision_updates",
          "self_collision_tests", "cloth_solver_iterations")
STAGES = ("cloth_forces", "cloth_contacts", "cloth_strain", "cloth_self_collision")


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 257
    frames = int(sys.argv[2]) if len(sys.argv) > 2 else spec.FRAMES
    world = run_simbake.build(n, 1.0 / 120.0, 1e-3, "implicit", "springs")
    before = dict.fromkeys(COUNTS, 0)
    spent = dict.fromkeys(STAGES, 0.0)
    for frame in range(1, frames + 1):
        start = time.process_time()
        world.step_frame(1.0 / spec.FPS)
        x, v = world.cloth_state(0)[:2]
        stats = world.statistics()
        strain = world.cloth_max_strain(0)
        speed = np.linalg.norm(v, axis=1)
        depth = np.linalg.norm(x - np.array(spec.SPHERE_CENTER), axis=1) - spec.SPHERE_RADIUS
        done = {k: stats[k] - before[k] for k in COUNTS}
        before = {k: stats[k] for k in COUNTS}
        profile = world.profile()
        stages = "  ".join(f"{k.removeprefix('cloth_')} {profile[k] - spent[k]:.2f} s" for k in STAGES)
        spent = {k: profile[k] for k in STAGES}
        print(f"{frame:3d} {time.process_time() - start:7.2f} s  strain {strain:.3f}  fastest {speed.max():.2f} m/s "
              f"(vertex {speed.argmax()})  lowest {1e3 * x[:, 1].min():.2f} mm  sphere {1e3 * depth.min():.2f} mm\n"
              f"    {stages}  {done}", flush=True)
        if strain > 0.5:
            k = int(speed.argmax())
            print(f"blow-up: vertex {k} at {x[k]} moving {v[k]}")
            break


if __name__ == "__main__":
    main()
