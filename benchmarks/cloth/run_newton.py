"""Newton's VBD cloth solver on the drape problem (drape_spec.py); prints one JSON line.

    benchmarks/peers/.venv-newton/bin/python benchmarks/cloth/run_newton.py N \
        [--substeps S] [--iterations K] [--seconds T] [--no-capture] [--free-fall]

N is the vertex count a side (17, 33, 65, 129, 257). The comparison driver pins the process
to one CPU (taskset -c 0); Warp's CPU backend runs every kernel on the calling thread anyway.

Settings (newton 1.8.0, warp-lang 1.19.0, device "cpu", Y up through ModelBuilder(up_axis=Y)
so positions need no conversion):
- the cloth: add_cloth_mesh with drape_spec.grid(n) as is (vertex j * n + i, the spec's
  triangles), area density 0.1 kg/m^2 lumped to the vertices (a third of each triangle's
  mass, as add_cloth_mesh does);
- stretch: VBD's triangles are a stable Neo-Hookean membrane with tri_ke = mu and
  tri_ka = lambda, Lame parameters per unit rest area (N/m), lambda_NH = lambda + mu
  (Smith et al. 2018), which linearises to the membrane of those Lame constants.
  simbake's stretch_stiffness is the sheet's Y = Young's modulus x thickness (N/m) and its
  membrane's Poisson ratio defaults to 0.3, so a plane-stress sheet:
  mu = Y / (2 (1 + nu)) = 769.2 N/m, lambda = Y nu / (1 - nu^2) = 659.3 N/m
  (uniaxial-strain modulus lambda + 2 mu = Y / (1 - nu^2)). simbake's default "springs"
  model of the same Y: a right-triangle grid pulled along an axis resists with Y
  (core/cloth/cloth.cpp); at the drape's tensions (~1 N/m) both strain < 0.1 %;
- bending: Newton's hinge energy is 1/2 edge_ke L (theta - theta0)^2 per interior edge of
  rest length L (dihedral angle theta, rest 0). A cylinder of curvature k bending a grid of
  spacing h along an axis folds only the edges across it, each by theta = k h, one per
  h^2 of area: energy density 1/2 edge_ke h k^2, which is simbake's 1/2 B k^2 with
  edge_ke = B / h, h = 2 m / (n - 1) (so edge_ke depends on the resolution; 3.2e-3 N at
  n = 65); the grid's response to other bending directions is anisotropic, as any hinge model;
- damping: simbake's default Rayleigh (stiffness-proportional) damping beta = 0.01 s.
  Newton damps the membrane through the rate of C = F^T F: 2nd Piola stress 4 tri_kd dE/dt
  against the elastic 2 mu E, so tri_kd = beta mu / 2 = 3.85 N s/m matches the deviatoric
  part; the hinge's damping is edge_kd L dtheta/dt, so edge_kd = beta edge_ke. No drag/lift;
- contacts: the sphere (static shape, body -1) and the ground plane (infinite, height 0),
  particle radius = the 5 mm collision distance, shape margin 0; a CollisionPipeline finds
  particle-shape contacts before every substep (soft_contact_gap 0.01 m, Newton's default
  detection slack; a particle falls at most ~5 mm a substep). VBD's particle-shape contact is
  a quadratic penalty on the depth inside radius + margin (ke = 1e3 N/m per particle, the
  Model's default, averaged with the shape's which we set equal) with a damping kd = 10
  N s/m that acts only on approach (the Model's default; it makes the impact inelastic), and an IPC-style smoothed Coulomb friction (friction_epsilon 0.01 m/s, default);
- friction: Newton combines mu by the geometric mean sqrt(mu_particle mu_shape), the same as
  simbake: the cloth gets drape_spec.FRICTION (0.4) and the sphere and the ground 0.5 (as in
  assets/scenes/drape.toml), so mu = sqrt(0.4 x 0.5) = 0.447 for every contact;
- self-contact off (SolverVBD's default) unless --self-contact on: VBD's vertex-triangle and
  edge-edge self-contact with the interaction distance at the spec's thickness
  (particle_self_contact_margin) and as much again of detection slack (..._gap, as the
  docstring advises). gravity 9.81 along -Y;
- time stepping: 24 fps, 3 s; substeps per frame and VBD iterations per substep default to
  25 and 10: Newton's VBD cloth examples use 10 substeps of a 60 fps frame (dt = 1/600 s)
  and 10 iterations; 25 substeps of 1/24 s give the same dt;
- the substep (clear_forces, collide, solver.step) is captured into Warp graphs, one for
  each direction between the two states, and replayed in turn, as the examples capture
  their frame (Warp 1.19 records and replays launches on the CPU too, without Python's
  per-launch cost: about half the time at n = 17; positions identical to --no-capture's,
  which steps in Python).
Kernels are compiled before the clock starts: a throwaway 17 x 17 model with the same
settings is built and stepped one frame first. Only the stepping is timed (perf_counter,
wp.synchronize_device); reading particle_q and measuring each frame are not. The process's
CPU time over the same stepping is reported too (cpu_seconds): on a shared machine wall time
includes waiting for the CPU.

Checked: in free fall (--free-fall: no sphere, no ground, 0.3 s = 180 substeps) the cloth
drops 0.4446 m against 1/2 g t^2 = 0.4415 m (+0.7 %: VBD is backward Euler, whose drop after
k steps is 1/2 g t^2 (1 + 1/k), +0.56 % here). The drape ends with the centre at y = 1.004
(sphere top + radius) and the corners on the ground (y = 0.005) from n = 33 on; at n = 17
two corners stay 5-7 cm up. Peak edge strain grows with n at a fixed iteration count
(1.8 % at 17, 6.5 % at 33, 12 % at 65 with 25 x 10) and stays (5.4 % in the last frame at
65 with 50 x 5), though this sheet's static strain is < 0.1 %: VBD's Gauss-Seidel iterations
do not converge at fine resolutions (the per-vertex stiffness, ~ mu, against the vertex's
m / dt^2 ~ h^2 grows as 1 / h^2), so the sheet behaves softer than its tri_ke / tri_ka.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import drape_spec as spec  # noqa: E402

import warp as wp  # noqa: E402

wp.config.log_level = wp.LOG_WARNING  # Warp's banner and module-load lines would go to stdout

import newton  # noqa: E402

DEVICE = "cpu"
SUBSTEPS = 25                 # per 1/24 s frame: dt = 1/600 s, Newton's cloth examples' substep
ITERATIONS = 10               # VBD iterations per substep (Newton's examples)
POISSON = 0.3                 # simbake's membrane default
DAMPING = 0.01                # simbake's default Rayleigh stiffness-proportional coefficient (s)
COLLIDER_FRICTION = 0.5       # sphere and ground (assets/scenes/drape.toml); cloth: spec.FRICTION
CONTACT_KE = 1.0e3            # N/m per particle (Newton's Model default)
CONTACT_KD = 10.0             # N s/m per particle, on approach only (Newton's Model default)
CONTACT_GAP = 0.01            # m, detection slack beyond the radius (CollisionPipeline default)
FRICTION_EPSILON = 1.0e-2     # m/s, friction smoothing velocity (SolverVBD default)


def materials(n: int) -> dict:
    y, nu = spec.STRETCH, POISSON
    mu = y / (2.0 * (1.0 + nu))
    lam = y * nu / (1.0 - nu * nu)
    h = spec.SIZE / (n - 1)
    edge_ke = spec.BEND / h
    return {"tri_ke": mu, "tri_ka": lam, "tri_kd": DAMPING * mu / 2.0,
            "edge_ke": edge_ke, "edge_kd": DAMPING * edge_ke}


def build(n: int, substeps: int, iterations: int, colliders: bool = True, self_contact: bool = False):
    builder = newton.ModelBuilder(up_axis=newton.Axis.Y, gravity=(0.0, -spec.GRAVITY, 0.0))
    if colliders:
        cfg = newton.ModelBuilder.ShapeConfig(ke=CONTACT_KE, kd=CONTACT_KD, mu=COLLIDER_FRICTION, margin=0.0)
        builder.add_ground_plane(height=spec.GROUND, cfg=cfg)
        builder.add_shape_sphere(-1, xform=wp.transform(wp.vec3(*spec.SPHERE_CENTER), wp.quat_identity()),
                                 radius=spec.SPHERE_RADIUS, cfg=cfg)
    vertices, triangles = spec.grid(n)
    m = materials(n)
    builder.add_cloth_mesh(
        pos=wp.vec3(0.0, 0.0, 0.0), rot=wp.quat_identity(), scale=1.0, vel=wp.vec3(0.0, 0.0, 0.0),
        vertices=[wp.vec3(*v) for v in vertices], indices=triangles.ravel().tolist(),
        density=spec.AREA_DENSITY, tri_ke=m["tri_ke"], tri_ka=m["tri_ka"], tri_kd=m["tri_kd"],
        tri_drag=0.0, tri_lift=0.0, edge_ke=m["edge_ke"], edge_kd=m["edge_kd"],
        particle_radius=spec.THICKNESS,
    )
    builder.color(include_bending=True)
    model = builder.finalize(device=DEVICE)
    model.soft_contact_ke = CONTACT_KE
    model.soft_contact_kd = CONTACT_KD
    model.soft_contact_mu = spec.FRICTION
    contact = ({"particle_enable_self_contact": True, "particle_self_contact_margin": spec.THICKNESS,
                "particle_self_contact_gap": spec.THICKNESS} if self_contact else {})
    solver = newton.solvers.SolverVBD(model, iterations=iterations, friction_epsilon=FRICTION_EPSILON, **contact)
    pipeline = newton.CollisionPipeline(model, soft_contact_gap=CONTACT_GAP)
    return Sim(model, solver, pipeline, substeps)


class Sim:
    def __init__(self, model, solver, pipeline, substeps: int):
        self.model, self.solver, self.pipeline = model, solver, pipeline
        self.states = (model.state(), model.state())
        self.current = 0                      # index of the state holding the latest positions
        self.control = model.control()
        self.contacts = pipeline.contacts()
        self.substeps = substeps
        self.dt = 1.0 / (spec.FPS * substeps)
        self.graphs = None

    def substep(self, src: int) -> None:
        state_in, state_out = self.states[src], self.states[1 - src]
        state_in.clear_forces()
        self.pipeline.collide(state_in, self.contacts)
        self.solver.step(state_in, state_out, self.control, self.contacts, self.dt)

    def capture(self) -> None:
        # One graph per direction of the substep (state 0 -> 1 and 1 -> 0), replayed in turn,
        # so any substep count works. On the CPU, Warp records the launches without running them.
        self.graphs = []
        for src in (0, 1):
            with wp.ScopedCapture(device=DEVICE) as capture:
                self.substep(src)
            self.graphs.append(capture.graph)

    def frame(self) -> None:
        for _ in range(self.substeps):
            if self.graphs is not None:
                wp.capture_launch(self.graphs[self.current])
            else:
                self.substep(self.current)
            self.current = 1 - self.current

    def positions(self) -> np.ndarray:
        return self.states[self.current].particle_q.numpy().astype(np.float64)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("n", type=int, help="vertices a side (16 k + 1)")
    parser.add_argument("--substeps", type=int, default=SUBSTEPS, help="substeps per 1/24 s frame")
    parser.add_argument("--iterations", type=int, default=ITERATIONS, help="VBD iterations per substep")
    parser.add_argument("--seconds", type=float, default=spec.SECONDS, help="simulated time")
    parser.add_argument("--no-capture", action="store_true", help="step in Python, no Warp graph")
    parser.add_argument("--self-collision", choices=("on", "off"), default="off",
                        help="VBD self-contact at the spec's thickness")
    parser.add_argument("--free-fall", action="store_true",
                        help="no colliders, 0.3 s: print the drop against 1/2 g t^2 instead")
    args = parser.parse_args()
    n = args.n
    wp.init()
    capture = not args.no_capture

    if args.free_fall:
        sim = build(n, args.substeps, args.iterations, colliders=False)
        y0 = sim.positions()[:, 1].mean()
        steps = int(round(0.3 / sim.dt))
        sim.substeps = 1
        for _ in range(steps):
            sim.frame()
        t = steps * sim.dt
        drop = y0 - sim.positions()[:, 1].mean()
        print(json.dumps({"engine": "newton", "check": "free_fall", "resolution": n, "t": t, "drop": drop,
                          "half_g_t2": 0.5 * spec.GRAVITY * t * t,
                          "ratio": drop / (0.5 * spec.GRAVITY * t * t)}))
        return

    # warm-up: compile every kernel (and the graph path) on a throwaway model
    self_contact = args.self_collision == "on"
    warm = build(spec.COMMON, args.substeps, args.iterations, self_contact=self_contact)
    if capture:
        warm.capture()
    warm.frame()
    wp.synchronize_device(DEVICE)
    del warm

    build_start = time.perf_counter()
    sim = build(n, args.substeps, args.iterations, self_contact=self_contact)
    if capture:
        sim.capture()   # records the substep loop without running it
    build_seconds = time.perf_counter() - build_start

    meter = spec.Meter(n)
    frames = int(round(args.seconds * spec.FPS))
    meter.frame(0.0, sim.positions())
    frame_walls, cpu = [], 0.0
    for f in range(1, frames + 1):
        start, cpu_start = time.perf_counter(), time.process_time()
        sim.frame()
        wp.synchronize_device(DEVICE)
        frame_walls.append(time.perf_counter() - start)
        cpu += time.process_time() - cpu_start
        meter.frame(f / spec.FPS, sim.positions())
    wall = float(sum(frame_walls))

    x = sim.positions()
    lengths = np.linalg.norm(x[meter.edges[:, 1]] - x[meter.edges[:, 0]], axis=1)
    corners = [0, n - 1, n * (n - 1), n * n - 1]
    settings = {
        "device": DEVICE, "solver": "SolverVBD", "up_axis": "Y",
        "substeps_per_frame": args.substeps, "time_step": 1.0 / (spec.FPS * args.substeps),
        "iterations": args.iterations, "graph_capture": capture,
        "membrane": "stable Neo-Hookean (VBD triangles)", "poisson_ratio": POISSON,
        **{k: float(v) for k, v in materials(n).items()},
        "particle_radius": spec.THICKNESS, "shape_margin": 0.0, "soft_contact_gap": CONTACT_GAP,
        "soft_contact_ke": CONTACT_KE, "soft_contact_kd": CONTACT_KD,
        "friction_cloth": spec.FRICTION, "friction_colliders": COLLIDER_FRICTION,
        "friction_combined": float(np.sqrt(spec.FRICTION * COLLIDER_FRICTION)),
        "friction_epsilon": FRICTION_EPSILON, "self_contact": self_contact,
        "self_contact_margin": spec.THICKNESS if self_contact else None,
        "mass_lumping": "density x area / 3 per triangle corner",
    }
    spec.report("newton", n, settings, wall, meter,
                wall_per_sim_second=wall / (frames / spec.FPS), seconds=frames / spec.FPS,
                newton_version=newton.__version__, warp_version=wp.__version__,
                cpu_seconds=cpu, build_seconds=build_seconds, first_frame_wall=frame_walls[0],
                max_frame_wall=max(frame_walls),
                final_strain=float((lengths / meter.rest - 1.0).max()),
                final_center_y=float(x[(n // 2) * n + n // 2, 1]),
                final_corner_y=[float(x[c, 1]) for c in corners])


if __name__ == "__main__":
    main()
