"""The stress run's stiff flag (cloth_stress.py's stiffness axis: a 1 m, 33 x 33 sheet pinned
along one edge, held horizontal and let fall) stepped frame by frame, its kinetic and elastic
energy printed every 6 frames with the solver's mean iterations a step, so that where its
energy comes from can be taken apart: the preconditioner, the solve's tolerance,
self-collision and its friction, the damping.

    .venv/bin/python benchmarks/stress/flag_energy.py [--stiffness 1e6] [--model springs]
        [--preconditioner automatic|multigrid|block_jacobi] [--tolerance 1e-3]
        [--self-collision on|off] [--friction 0.3] [--damping 0.01]

The work of gravity it is judged against in cloth_stress.py is about 1 J (0.1 kg, 1 m).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import cloth_stress  # noqa: E402

from simbake import _core  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--stiffness", type=float, default=1e6)
    parser.add_argument("--model", default="springs", choices=("springs", "membrane"))
    parser.add_argument("--preconditioner", default="automatic", choices=("automatic", "multigrid", "block_jacobi"))
    parser.add_argument("--tolerance", type=float, default=1e-3)
    parser.add_argument("--self-collision", default="on", choices=("on", "off"))
    parser.add_argument("--friction", type=float, default=0.3)
    parser.add_argument("--damping", type=float, default=0.01)
    args = parser.parse_args()
    world = _core.World()
    rest, triangles = cloth_stress.grid(33, 1.0, 1.0)
    world.add_cloth(rest=rest, triangles=triangles, model=args.model, stretch_stiffness=args.stiffness,
                    pinned=list(range(33)), preconditioner=args.preconditioner, tolerance=args.tolerance,
                    self_collision=args.self_collision == "on", friction=args.friction, damping=args.damping)
    for frame in range(1, 49):
        world.step_frame(1.0 / cloth_stress.FPS, 0)
        if frame % 6 == 0:
            s = world.statistics()
            print(f"frame {frame:2d}  kinetic {s['kinetic_energy']:8.3f} J  elastic {s['elastic_energy']:9.3f} J  "
                  f"CG iterations a step {s['cloth_solver_iterations'] / s['cloth_steps']:.0f}", flush=True)


if __name__ == "__main__":
    main()
