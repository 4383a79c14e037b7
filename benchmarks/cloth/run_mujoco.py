"""MuJoCo's flex cloth on the drape problem (drape_spec.py); prints one JSON line.

    benchmarks/peers/.venv-peers/bin/python benchmarks/cloth/run_mujoco.py N \
        [--steps-per-frame K] [--seconds S] [--free-fall]

N is the vertex count a side (17, 33, 65, 129, 257). The comparison driver pins the process
to one CPU (taskset -c 0); MuJoCo's mj_step is single-threaded.

Settings (MuJoCo 4.0.0, Z up: Y-up (x, y, z) -> MuJoCo (x, -z, y) and back):
- the cloth: one flexcomp type="grid", dim=2, count="n n 1", spacing 2/(n-1), at height 1.2,
  dof="full" (the default: each vertex is a body with 3 slide joints along the world axes, a
  degree of freedom of its own; the reduced trilinear/quadratic models are not used). Its
  vertex k is point (a, b) = (k // n, k % n) of the grid, a along +x and b along +y (Z up),
  i.e. drape point (i, j) = (a, n - 1 - b); the permutation is built from the positions and
  checked against drape_spec.grid(n) at t = 0. MuJoCo triangulates each cell along the other
  diagonal than drape_spec (which only changes the stiffness/bending stencils);
- mass: flexcomp gives every vertex mass/npoints, so the border would carry ~2x its share;
  instead each vertex body gets simbake's lumping, area density 0.1 kg/m^2 x a third of each
  of its drape_spec triangles' area (set through MjSpec before compiling; 0.4 kg in all);
- stretch: MuJoCo's 2D flex elasticity is a Saint Venant-Kirchhoff membrane (linear
  triangles, Green strain) of energy per area t (mu tr(E^2) + lambda*/2 tr(E)^2), Lame mu =
  young / (2 (1 + nu)), plane-stress lambda* = young nu / (1 - nu^2) (4.0.0 changelog: these
  constants are now as documented). simbake's stretch_stiffness is the sheet's Y = young x
  thickness = 2000 N/m, Poisson 0.3, so young x thickness = 2000 N/m. (simbake's default
  "springs" model of the same Y: a right-triangle grid pulled along an axis resists with Y,
  core/cloth/cloth.cpp; the drape's tensions are ~1 N/m, strains < 0.1 %);
- bending: elastic2d="both". MuJoCo's 2D bending is a discrete hinge model normalised so that
  a cylinder of curvature k stores the plate energy D k^2 / 2 per area, D = young t^3 /
  (12 (1 - nu^2)): simbake's 1/2 B (1/R1 + 1/R2)^2 with B = 1e-4 N m gives D = B. young and
  thickness are then both fixed: t = sqrt(12 (1 - nu^2) B / Y) = 7.389e-4 m and young = Y / t
  = 2.707e6 Pa (the thickness is not the collision distance, which is the flex radius);
- damping: simbake's default Rayleigh (stiffness-proportional) damping of 0.01 s; MuJoCo's
  elasticity damping is the same Rayleigh coefficient (s) scaling the elastic stiffness. No
  edge damping (not allowed with the discrete integrator), no air drag;
- integrator "discrete" with the Newton solver (defaults: 100 iterations, tolerance 1e-8):
  in MuJoCo 4.0.0 flex elasticity is rejected under implicit and implicitfast ("set
  integrator='discrete', or 'Euler' with a small timestep"), and discrete, the only one
  implicit in position (metric M + hD + h^2 K), needs CG or Newton (not PGS). Euler is
  explicit: it blows up within 0.01 s at 40 steps a frame at n = 33 (the membrane's highest
  frequency, ~c/dx with c = sqrt(Y / rho) = 141 m/s, and worse with the Rayleigh damping,
  needs microsecond steps at n = 257). Newton converges in a few iterations; CG often
  stops at its 100-iteration cap here (measured at n = 33), so Newton is kept;
- time step: 1/96 s (4 steps per 1/24 s frame; see STEPS_PER_FRAME below for the check).
  At n = 129 and this step MuJoCo warns that the flex stiffness is too ill-conditioned for its
  effective-metric preconditioner (the M + h^2 K solve stops under-converged, mjWARN_INERTIA,
  every step: tiny vertex masses against the membrane's stiffness); the run goes on and the
  count is in "mujoco_warnings". At 8 steps a frame (h^2 K four times smaller) the warning is
  gone (checked over the free fall only): use --steps-per-frame 8 from n = 129 up;
- each frame the vertices' positions are read from qpos (see Vertices: flexvert_xpos lags
  one step after mj_step), converted to Y up and permuted to drape order;
- contacts: the sphere (static geom of the world body, radius 0.5 at (0, 0, 0.5) Z up) and
  the ground (an infinite plane at 0); the flex radius 5 mm is the collision distance (the
  triangles are 5 mm thick half-way each side), margin and gap 0; condim 3 (sliding friction),
  pyramidal cones, default solimp (0.9 0.95 0.001 0.5 2). solref "0.001 1" on the flex and
  both geoms: under the discrete integrator the "refsafe" flag (on by default) replaces a
  contact spring stiffer than the step can resolve (timeconst x dampratio < h) by the stiffest
  zero-restitution one it can, so this asks for the hardest stable contact at any step.
  MuJoCo's default 0.02 s contact spring is soft for cloth: the corners, whipping onto the
  ground at ~3 m/s, sank 2 cm into it (n = 33, 16 steps a frame). No contact is found before
  the cloth is within the radius (margin 0), so the first impact on the sphere, at ~2 m/s,
  sinks up to ~2 m/s x h - 5 mm (1.5 cm at h = 1/96 s) for a step;
- friction: MuJoCo takes the max of the two friction coefficients of a pair, so the flex, the
  sphere and the ground all get sqrt(0.4 x 0.5) = 0.447, simbake's geometric mean of the cloth
  (drape_spec.FRICTION) and the sphere/ground (0.5, assets/scenes/drape.toml);
- self-collision off (selfcollide="none") unless --self-collision on (selfcollide="auto",
  MuJoCo's choice of broad phase for the flex against itself). Gravity 9.81 along -Z.
Only mj_step is timed (perf_counter; the model is compiled and mj_forward run before the
clock starts); reading the positions and measuring each frame are not. The process CPU time of
the stepping is reported too ("cpu_seconds"), as the wall time suffers on a busy machine.

Checked: --free-fall (no sphere, no ground, 0.3 s) prints the drop against 1/2 g t^2.
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

import mujoco  # noqa: E402

# Time step: 1/96 s, the largest that gives a sane drape at n = 65 (checked at 2, 4, 8 steps a
# frame). The discrete integrator does not blow up even at 1 step a frame, but the cloth moves
# ~2 cm a step when it meets the sphere (contacts are only found once it is within the radius)
# and the impact then sinks and stretches it: at 2 steps a frame 3.4 cm deep and 36 % strain,
# at 4 steps 0.9 cm and 7.3 %, at 8 steps 0.5 cm and 3.3 % (transients: the settled cloth's
# strains are < 0.5 %). The shape has not converged in the step: 4 vs 8 steps a frame differ
# by 3-4 cm on average (up to 15-23 cm where the folds fall differently).
STEPS_PER_FRAME = 4
POISSON = 0.3
THICKNESS = (12.0 * (1.0 - POISSON ** 2) * spec.BEND / spec.STRETCH) ** 0.5   # 7.389e-4 m
YOUNG = spec.STRETCH / THICKNESS                                              # 2.707e6 Pa
DAMPING = 0.01                        # s, Rayleigh (simbake's default)
RADIUS = spec.THICKNESS               # 5 mm collision distance
MU = (spec.FRICTION * 0.5) ** 0.5     # 0.447, the pair's friction in simbake (geometric mean)
SOLREF = "0.001 1"                    # the stiffest contact the step resolves (refsafe), see above


def to_zup(p):
    p = np.asarray(p, dtype=np.float64)
    return np.stack([p[..., 0], -p[..., 2], p[..., 1]], -1)


def from_zup(p):
    p = np.asarray(p, dtype=np.float64)
    return np.stack([p[..., 0], p[..., 2], -p[..., 1]], -1)


def lumped_masses(n: int) -> np.ndarray:
    """simbake's vertex masses: a third of each triangle's area x the area density."""
    x, tri = spec.grid(n)
    a = x[tri[:, 1]] - x[tri[:, 0]]
    b = x[tri[:, 2]] - x[tri[:, 0]]
    area = 0.5 * np.linalg.norm(np.cross(a, b), axis=1)
    mass = np.zeros(n * n)
    for c in range(3):
        np.add.at(mass, tri[:, c], spec.AREA_DENSITY * area / 3.0)
    return mass


def model_xml(n: int, time_step: float, colliders: bool, selfcollide: str = "none") -> str:
    h = spec.SIZE / (n - 1)
    cx, cy, cz = (float(v) for v in to_zup(spec.SPHERE_CENTER))
    lines = [
        '<mujoco model="drape">',
        f'  <option timestep="{time_step!r}" gravity="0 0 {-spec.GRAVITY!r}" integrator="discrete"'
        ' solver="Newton" cone="pyramidal"/>',
        f'  <size memory="{64 + n * n // 16}M"/>',   # arena: n = 129 needed > 584 MB
        '  <worldbody>',
    ]
    if colliders:
        lines += [
            f'    <geom name="ground" type="plane" size="0 0 1" pos="0 0 {spec.GROUND!r}"'
            f' friction="{MU!r} 0.005 0.0001" condim="3" solref="{SOLREF}"/>',
            f'    <geom name="ball" type="sphere" size="{spec.SPHERE_RADIUS!r}" pos="{cx!r} {cy!r} {cz!r}"'
            f' friction="{MU!r} 0.005 0.0001" condim="3" solref="{SOLREF}"/>',
        ]
    lines += [
        f'    <flexcomp name="cloth" type="grid" dim="2" dof="full" count="{n} {n} 1"'
        f' spacing="{h!r} {h!r} {h!r}" pos="0 0 {spec.HEIGHT!r}" radius="{RADIUS!r}"'
        f' mass="{spec.AREA_DENSITY * spec.SIZE ** 2!r}">',
        f'      <contact condim="3" friction="{MU!r} 0.005 0.0001" solref="{SOLREF}" selfcollide="{selfcollide}"'
        ' margin="0" gap="0"/>',
        f'      <elasticity young="{YOUNG!r}" poisson="{POISSON!r}" thickness="{THICKNESS!r}"'
        f' damping="{DAMPING!r}" elastic2d="both"/>',
        '    </flexcomp>',
        '  </worldbody>',
        '</mujoco>',
    ]
    return "\n".join(lines)


def build(n: int, time_step: float, colliders: bool = True, selfcollide: str = "none"):
    """The compiled model and data, and perm: drape vertex p is MuJoCo flex vertex perm[p]."""
    mjspec = mujoco.MjSpec.from_string(model_xml(n, time_step, colliders, selfcollide))
    # vertex k of the flexcomp is body cloth_k at the grid point: from its position to (i, j)
    mass = lumped_masses(n)
    perm = np.full(n * n, -1)
    for body in mjspec.bodies:
        if not body.name.startswith("cloth_"):
            continue
        k = int(body.name[len("cloth_"):])
        x = from_zup(np.array(body.pos))
        i = int(round((x[0] / spec.SIZE + 0.5) * (n - 1)))
        j = int(round((x[2] / spec.SIZE + 0.5) * (n - 1)))
        perm[j * n + i] = k
        body.mass = float(mass[j * n + i])
    model = mjspec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    # check: every vertex mapped once, and the permuted positions are drape_spec's grid
    if sorted(perm.tolist()) != list(range(n * n)) or model.nflex != 1 or model.flex_vertnum[0] != n * n:
        raise RuntimeError("flex vertices do not map one to one onto the n x n grid")
    x0 = from_zup(data.flexvert_xpos)[perm]
    err = float(np.abs(x0 - spec.grid(n)[0]).max())
    if err > 1e-9:
        raise RuntimeError(f"flex vertex order check failed: {err:g} m off drape_spec.grid")
    body_of_vertex = model.flex_vertbodyid[perm]
    if abs(model.body_mass[body_of_vertex].sum() - spec.AREA_DENSITY * spec.SIZE ** 2) > 1e-9:
        raise RuntimeError("cloth mass is not 0.4 kg")
    return model, data, perm


class Vertices:
    """The flex vertices' Y-up positions in drape order, of the current state.

    data.flexvert_xpos is computed by mj_forward at the start of mj_step, before the state is
    advanced, so after mj_step it lags one step behind qpos (in free fall the drop then reads
    1/2 g t (t - h)). Each vertex is a body of the world with 3 slide joints along x, y, z, so
    its position is its body's position plus those 3 qpos: what mj_kinematics + mj_flex
    would write into flexvert_xpos (checked at t = 0 against flexvert_xpos)."""

    def __init__(self, model, data, perm):
        body = model.flex_vertbodyid[perm]
        jnt = model.body_jntadr[body]
        if ((model.body_jntnum[body] != 3).any() or (model.body_parentid[body] != 0).any()
                or (model.jnt_type[jnt[:, None] + np.arange(3)] != mujoco.mjtJoint.mjJNT_SLIDE).any()
                or not np.allclose(model.jnt_axis[jnt[:, None] + np.arange(3)], np.eye(3))):
            raise RuntimeError("flex vertex bodies are not 3-slide bodies of the world")
        self.data = data
        self.base = model.body_pos[body].copy()
        self.qadr = model.jnt_qposadr[jnt][:, None] + np.arange(3)
        if np.abs(self.zup() - data.flexvert_xpos[perm]).max() > 1e-12:
            raise RuntimeError("vertex positions from qpos disagree with flexvert_xpos")

    def zup(self) -> np.ndarray:
        return self.base + self.data.qpos[self.qadr]

    def __call__(self) -> np.ndarray:
        return from_zup(self.zup())


def warnings_of(data) -> dict:
    return {str(mujoco.mjtWarning(i)).split(".")[-1]: int(w.number)
            for i, w in enumerate(data.warning) if w.number}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("n", type=int, help="vertices a side (16 k + 1)")
    parser.add_argument("--steps-per-frame", type=int, default=STEPS_PER_FRAME,
                        help="mj_step calls per 1/24 s frame")
    parser.add_argument("--seconds", type=float, default=spec.SECONDS, help="simulated time")
    parser.add_argument("--free-fall", action="store_true",
                        help="no colliders, 0.3 s: print the drop against 1/2 g t^2 instead")
    parser.add_argument("--self-collision", choices=("on", "off"), default="off",
                        help='the flex against itself (selfcollide="auto")')
    args = parser.parse_args()
    n, k = args.n, args.steps_per_frame
    selfcollide = "auto" if args.self_collision == "on" else "none"
    time_step = 1.0 / (spec.FPS * k)

    if args.free_fall:
        model, data, perm = build(n, time_step, colliders=False)
        vertices = Vertices(model, data, perm)
        y0 = vertices()[:, 1].mean()
        steps = int(round(0.3 / time_step))
        mujoco.mj_step(model, data, nstep=steps)
        t = steps * time_step
        x = vertices()
        drop = y0 - x[:, 1].mean()
        print(json.dumps({"engine": "mujoco", "check": "free_fall", "resolution": n,
                          "steps_per_frame": k, "t": t, "drop": drop,
                          "half_g_t2": 0.5 * spec.GRAVITY * t * t,
                          "ratio": drop / (0.5 * spec.GRAVITY * t * t),
                          "spread_of_heights": float(x[:, 1].max() - x[:, 1].min()),
                          "mujoco_warnings": warnings_of(data)}))
        return

    spec.SECONDS = args.seconds            # report() divides the wall time by it
    frames = int(round(args.seconds * spec.FPS))
    model, data, perm = build(n, time_step, selfcollide=selfcollide)
    vertices = Vertices(model, data, perm)
    meter = spec.Meter(n)
    meter.frame(0.0, vertices())
    wall = cpu = 0.0
    max_contacts = 0
    iterations = []
    for frame in range(1, frames + 1):
        for _ in range(k):
            w0, c0 = time.perf_counter(), time.process_time()
            mujoco.mj_step(model, data)
            wall += time.perf_counter() - w0
            cpu += time.process_time() - c0
            iterations.append(int(data.solver_niter[0]))
        max_contacts = max(max_contacts, int(data.ncon))
        meter.frame(frame / spec.FPS, vertices())

    x = vertices()
    corners = [0, n - 1, n * (n - 1), n * n - 1]
    settings = {
        "mujoco": mujoco.__version__, "time_step": time_step, "steps_per_frame": k,
        "integrator": "discrete (implicit in position; implicit/implicitfast reject flex elasticity)",
        "solver": "Newton (default: 100 iterations, tolerance 1e-8)", "cone": "pyramidal (default)",
        "flexcomp": f'grid dim=2 dof=full count="{n} {n} 1" (one 3-slide body per vertex)',
        "vertex_mass": "area density 0.1 x a third of each drape_spec triangle (simbake's lumping)",
        "membrane": "StVK, young x thickness = 2000 N/m, poisson 0.3 (plane stress)",
        "young": YOUNG, "poisson": POISSON, "thickness": THICKNESS,
        "bending": "elastic2d=both, D = young t^3 / (12 (1 - nu^2)) = 1e-4 N m",
        "rayleigh_damping": DAMPING, "flex_radius": RADIUS, "margin": 0.0, "gap": 0.0,
        "friction_per_geom_and_flex": MU, "combine": "max (MuJoCo)", "condim": 3,
        "solref": f"{SOLREF} (refsafe: the stiffest the step resolves)", "solimp": "default (0.9 0.95 0.001 0.5 2)",
        "selfcollide": selfcollide,
    }
    spec.report("mujoco", n, settings, wall, meter, version=mujoco.__version__, cpu_seconds=cpu,
                steps=len(iterations), solver_iterations_mean=float(np.mean(iterations)),
                solver_iterations_max=int(max(iterations)), max_contacts_at_frame_ends=max_contacts,
                final_center_y=float(x[(n * n) // 2, 1]), final_corner_y=float(x[corners, 1].max()),
                mujoco_warnings=warnings_of(data))


if __name__ == "__main__":
    main()
