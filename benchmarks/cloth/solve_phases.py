"""The cloth solve's conjugate-gradient iterations per step on the drape (drape_spec.py), in
the fall (t <= 0.5 s, before and at the first contact) and at rest (2 s < t <= 3 s, draped
over the sphere and the ground), for one resolution and preconditioner; prints one JSON line.

    .venv/bin/python benchmarks/cloth/solve_phases.py N [--preconditioner automatic|block_jacobi|multigrid]
        [--seconds S] [--self-collision on|off]

Also the run's CPU seconds per simulated second (the whole step) and the solver's
(preconditioner update and conjugate gradients, the core's own thread-CPU count).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import drape_spec as spec  # noqa: E402
import run_simbake  # noqa: E402

PHASES = {"fall": (0.0, 0.5), "settling": (0.5, 2.0), "rest": (2.0, 3.0)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("n", type=int)
    parser.add_argument("--preconditioner", choices=("automatic", "block_jacobi", "multigrid"), default="automatic")
    parser.add_argument("--seconds", type=float, default=spec.SECONDS)
    parser.add_argument("--self-collision", choices=("on", "off"), default="on")
    args = parser.parse_args()
    world = run_simbake.build(args.n, 1.0 / 120.0, 1e-3, "implicit", "springs", args.preconditioner,
                              args.self_collision == "on")
    per_frame = []  # (end time, iterations, cloth steps) of each frame
    iterations = steps = 0
    cpu = 0.0
    for f in range(1, int(round(args.seconds * spec.FPS)) + 1):
        c0 = time.process_time()
        world.step_frame(1.0 / spec.FPS)
        cpu += time.process_time() - c0
        stats = world.statistics()
        per_frame.append((f / spec.FPS, stats["cloth_solver_iterations"] - iterations, stats["cloth_steps"] - steps))
        iterations, steps = stats["cloth_solver_iterations"], stats["cloth_steps"]
    phases = {}
    for name, (lo, hi) in PHASES.items():
        inside = [(i, s) for t, i, s in per_frame if lo < t <= hi + 1e-9]
        if inside:
            phases[name] = round(sum(i for i, _ in inside) / max(1, sum(s for _, s in inside)), 1)
    print(json.dumps({"n": args.n, "preconditioner": args.preconditioner, "self_collision": args.self_collision,
                      "seconds": args.seconds, "iterations_per_step": phases,
                      "all": round(iterations / max(1, steps), 1),
                      "cpu_per_sim_second": round(cpu / args.seconds, 3),
                      "solver_cpu_per_sim_second": round(world.statistics()["cloth_solver_seconds"] / args.seconds, 3),
                      "profile_per_sim_second": {k: round(v / args.seconds, 3) for k, v in world.profile().items()
                                                 if k.startswith("cloth")}}))


if __name__ == "__main__":
    main()
