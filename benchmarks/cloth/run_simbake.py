"""simbake's cloth on the drape problem (drape_spec.py); prints one JSON line.

    .venv/bin/python benchmarks/cloth/run_simbake.py N [--cloth-step S] [--tolerance T]
        [--integrator implicit|explicit] [--model springs|membrane] [--seconds T]
        [--preconditioner automatic|block_jacobi|multigrid] [--self-collision on|off]

N is the vertex count a side (17, 33, 65, 129, 257). The world is built with the core API
exactly as `simbake bake assets/scenes/drape.toml` builds it (a kinematic analytic sphere,
the ground, one grid cloth with the scene's material), on one thread.

Settings: the drape scene's material (stretch_stiffness 2000 N/m springs, bend_stiffness
1e-4 N m, Rayleigh damping 0.01 s, strain limit 10 %, subgrid compression, thickness 5 mm,
friction 0.4 against the sphere's and the ground's 0.5: sqrt(0.4 x 0.5) = 0.447);
--cloth-step is the world's cloth_max_substep (the longest implicit step; the explicit
integrator takes its speed-of-sound step whatever it is), --tolerance the conjugate-gradient
solve's relative residual, --preconditioner its preconditioner (automatic, the core's
default: multigrid from 1,000 free vertices when none is pinned, block-Jacobi otherwise), --self-collision off the cloth's self-collision
(on, the default, as the scene's). Only World.step_frame is timed; CPU time is reported beside wall
time (cpu_seconds), as the peers' runners do.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import drape_spec as spec  # noqa: E402

from simbake import _core  # noqa: E402


def build(n: int, cloth_step: float, tolerance: float, integrator: str, model: str,
          preconditioner: str = "automatic", self_collision: bool = True,
          contacts_in_solve: bool = True, stretch: float = spec.STRETCH,
          strain_limit: float = 0.1) -> "_core.World":
    world = _core.World(gravity=np.array([0.0, -spec.GRAVITY, 0.0]), threads=1, cloth_max_substep=cloth_step,
                        cloth_contacts_in_solve=contacts_in_solve)
    world.set_ground(height=spec.GROUND, friction=0.5, restitution=0.0)
    radius = spec.SPHERE_RADIUS
    samples = _core.sphere_mesh(radius, 4)[0]
    world.add_body(shape=_core.LevelSet.sphere(radius), samples=samples,
                   mass_properties=_core.sphere_mass_properties(radius), mass=1.0,
                   origin=np.array(spec.SPHERE_CENTER), orientation=np.array([1.0, 0.0, 0.0, 0.0]),
                   friction=0.5, kinematic=True)
    vertices, triangles = spec.grid(n)
    world.add_cloth(rest=vertices, triangles=triangles, area_density=spec.AREA_DENSITY, model=model,
                    stretch_stiffness=stretch, bend_stiffness=spec.BEND, damping=0.01,
                    strain_limit=strain_limit, integrator=integrator, friction=spec.FRICTION,
                    thickness=spec.THICKNESS, tolerance=tolerance, preconditioner=preconditioner,
                    self_collision=self_collision)
    return world


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("n", type=int, help="vertices a side (16 k + 1)")
    parser.add_argument("--cloth-step", type=float, default=1.0 / 120.0, help="cloth_max_substep (s)")
    parser.add_argument("--tolerance", type=float, default=1e-3, help="CG relative residual")
    parser.add_argument("--integrator", choices=("implicit", "explicit"), default="implicit")
    parser.add_argument("--model", choices=("springs", "membrane"), default="springs")
    parser.add_argument("--seconds", type=float, default=spec.SECONDS)
    parser.add_argument("--preconditioner", choices=("automatic", "block_jacobi", "multigrid"), default="automatic")
    parser.add_argument("--self-collision", choices=("on", "off"), default="on")
    parser.add_argument("--contacts-in-solve", choices=("on", "off"), default="on")
    args = parser.parse_args()
    spec.SECONDS = args.seconds
    world = build(args.n, args.cloth_step, args.tolerance, args.integrator, args.model, args.preconditioner,
                  args.self_collision == "on", args.contacts_in_solve == "on")
    meter = spec.Meter(args.n)
    meter.frame(0.0, world.cloth_state(0)[0])
    frames = int(round(args.seconds * spec.FPS))
    wall = cpu = 0.0
    for f in range(1, frames + 1):
        w0, c0 = time.perf_counter(), time.process_time()
        world.step_frame(1.0 / spec.FPS)
        wall += time.perf_counter() - w0
        cpu += time.process_time() - c0
        meter.frame(f / spec.FPS, world.cloth_state(0)[0])
    stats = world.statistics()
    settings = {"cloth_max_substep": args.cloth_step, "tolerance": args.tolerance,
                "integrator": args.integrator, "model": args.model, "threads": 1}
    if args.preconditioner != "automatic":
        settings["preconditioner"] = args.preconditioner
    if args.self_collision == "off":
        settings["self_collision"] = False
    if args.contacts_in_solve == "off":
        settings["contacts_in_solve"] = False
    spec.report("simbake", args.n, settings, wall, meter, cpu_seconds=cpu,
                cloth_steps=stats["cloth_steps"], substeps=stats["substeps"],
                solver_iterations=stats["cloth_solver_iterations"], solver_cpu_seconds=stats["cloth_solver_seconds"],
                profile=world.profile(),
                self_collision={k: v for k, v in stats.items() if k.startswith(("self_", "impact_"))})


if __name__ == "__main__":
    main()
