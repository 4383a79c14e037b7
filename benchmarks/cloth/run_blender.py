"""Blender's cloth modifier (bpy, Baraff-Witkin mass-spring, implicit) on the drape problem
(drape_spec.py); one JSON line.

    benchmarks/peers/.venv-bpy/bin/python benchmarks/cloth/run_blender.py N [--quality Q]
        [--collision-quality C] [--seconds S] [--compression-scale K] [--time-scale T]
    benchmarks/peers/.venv-bpy/bin/python benchmarks/cloth/run_blender.py N --free-fall
        [--time-scale T]      # the time check below (no colliders); prints its own JSON line

bpy 5.0.1 from PyPI, factory settings, empty scene, Z up: the Y-up spec is converted at the
boundary, (x, y, z) -> (x, -z, y) and back. Settings, and why:

- Mesh: the spec's n x n grid built vertex by vertex (index j n + i, i along x, j along z)
  with (n-1)^2 QUADS (Blender's natural cloth mesh: structural springs on the quad sides,
  shear springs on both quad diagonals, angular bending across every interior side),
  wound so the normals point up. The evaluated mesh keeps this vertex order (checked at the
  first frame against the construction: the run aborts otherwise). Object at the origin,
  identity transform; positions are read from the depsgraph-evaluated object, mapped by
  its world matrix.
- Units of Blender's cloth solver (read in source/blender/simulation/intern/
  SIM_mass_spring.cc, implicit_blender.cc, blenkernel/intern/cloth.cc, collision.cc):
  lengths m, masses kg (settings.mass is the mass of EVERY vertex), but time counts in frames:
  each frame advances the solver by time_scale internal units in `quality` steps, and gravity
  enters as 0.001 g. Gravity is right when one internal unit is u = sqrt(0.001) s = 31.6 ms,
  i.e. time_scale = (1/fps) / u = 31.62 / fps: 1.3176 at 24 fps. Blender's default
  time_scale 1 would be right at 31.6 fps only; at 24 fps the cloth would fall with an
  effective g = 9.81 x 0.001 x 24^2 = 5.65 m/s^2 (0.58 g), in slow motion.
  Forces then count in kg m / u^2 = 1000 N, spring constants (force / length) in 1000 N/m,
  damping coefficients (force / velocity) in kg / u = 31.6 kg/s.
- TIME CHECK (--free-fall: no colliders, no air damping, mean height of the sheet; drop
  after 7 frames, t = 0.2917 s, against 1/2 g t^2 = 0.4173 m), n = 65:
    time_scale 1.3176, quality 20: 0.4202 m, 1.007 x 1/2 g t^2 (quality 5, n = 17: 1.029 x);
    time_scale 1,      quality 20: 0.2421 m, 0.580 x.
  The excess is backward Euler's own: with N steps of gravity alone x = 1/2 g t^2 (1 + 1/N)
  exactly, and the measured drop divided by that is 1.0000 at every frame with the
  corrected time scale, 0.5760 = 24^2 / 1000 with time scale 1 (up to 0.5 s).
- Mass: 0.1 kg/m^2 x 4 m^2 = 0.4 kg spread evenly over the n^2 vertices, settings.mass =
  0.4 / n^2 (Blender has one mass for every vertex, so border and corner vertices are as
  heavy as interior ones, where simbake lumps by area: half for a border vertex, a quarter
  for a corner; same total 0.4 kg).
- Stretch (simbake: Y = 2000 N/m, springs along the triangle sides, each E = 12/5 Y a / L,
  spring constant E / L: 0.8 Y for an interior grid side, 0.4 Y for a diagonal, tension
  full, compression x 0.01 (subgrid); a right-triangle grid pulled along an axis resists
  with exactly Y, 4/5 from the sides and 1/5 from the diagonals). Blender's spring constant
  is stiffness / avg_spring_len (avg over structural springs = h, the grid spacing) in
  1000 N/m, so k = 1000 x stiffness / h (N/m). Mapping that keeps the pull along an axis at Y:
    tension_stiffness = Y h / 1250 (a side spring of 0.8 Y, as simbake's interior sides);
    shear_stiffness   = Y h / 5000 (each of the TWO quad diagonals 0.2 Y, together
                        0.4 Y like simbake's one diagonal; a diagonal pulled along an axis
                        gives k/2 per cell, two of them Y/5);
    compression_stiffness = tension_stiffness (Blender's own default relation; linear
                        springs symmetric in tension and compression).
  simbake's subgrid compression (springs at 1 % under compression) taken literally
  (--compression-scale 0.01) wrecks Blender's run: with no strain limit, tension-only shear
  springs and velocity-impulse collisions the sheet crumples on the cap and stays stretched
  there (n = 65, quality 5: max strain 0.51, steady 0.35-0.4; quality 40 still 0.07;
  penetration 2-3 cm), so the default resists compression like tension (n = 65, quality 5:
  steady strain 1-3 %, penetration 1 mm). With the angular bending model (Blender's
  default, kept) structural springs resist compression with the separate compression
  spring (Choi-Ko curve, linear for any realistic compression: the buckling branch only
  takes over beyond ~3 m of shortening), and shear springs act in tension only.
  Uncertainty: the in-plane responses agree along the grid axes in tension only (pure
  shear: Blender has one stretched diagonal per cell of 0.2 Y, simbake one of 0.4 Y; border
  sides: Blender 0.8 Y, simbake 0.4 Y); no strain limit in Blender (simbake's 10 %).
  Checked statically (with the earlier 5/12 calibration, both sides scaled alike): a sheet
  hanging from its top row (n = 17 and 33) stretched at the top by 0.21-0.23 %, against
  0.23 % predicted under the weight below.
  *_max values are set equal (they are vertex-group maxima; no vertex groups here).
- Bending (simbake: B = 1e-4 N m, hinge energy 1/2 B theta^2 |e|^2/(A1+A2), the continuum
  1/2 B kappa^2 per area). Blender's angular spring pushes each quad with force
  k theta, k = bending_stiffness x h x 0.1 (internal units), spread over the quad's 4
  vertices: a torque k theta h / 2 about the hinge, so a hinge stiffness 0.05 bending h^2
  (x 1000 N m). On a quad grid the continuum needs B per hinge, hence
  bending_stiffness = B / (50 h^2) (uncertain by a factor of order 1: the lever arm and the
  dihedral angle's discretisation are read off the code, not measured; bending barely
  matters here, the bending length (B / rho g)^(1/3) = 4.7 cm being ~h at n = 33).
- Damping: simbake's default Rayleigh beta = 0.01 s (stiffness-proportional, drape.toml
  keeps it). A Blender spring damps along its direction with c (kg/u), so c = beta k in
  internal units: tension_damping = (beta / u) x tension / h = 0.211, shear_damping =
  0.053, compression_damping = tension_damping (x the compression scale), bending_damping (angular model:
  force c x the faces' normal velocities, ~ c h/2 dtheta/dt) = 0.2 (beta / u) x bending.
  (Blender's defaults, 5 / 5 / 5 / 0.5, on these 1e-4 kg vertices would be hundreds of
  times overdamped.) air_damping 0 (default 1).
- Collisions: sphere (UV sphere 64 x 32, radius 0.5, vertices on the sphere: flat faces
  sag inside it by <= 1.2 mm, smooth shading) and ground (a 10 x 10 m quad at height 0),
  both with a collision modifier. Cloth-object distance = (cloth distance_min + collider
  thickness_outer) x 8/9 (collision.cc pushes to 8/9 of the detection distance), so
  thickness_outer = 0.001 (its minimum) and distance_min = 9/8 x 0.005 - 0.001 = 0.004625
  give the spec's 5 mm. Friction: Blender's object-collision friction is the COLLIDER's
  cloth_friction / 100 (a Coulomb velocity impulse: tangential speed cut by mu x the
  normal speed removed; no friction for resting contact that is not approaching), the cloth's
  own collision friction is not read there. simbake combines sqrt(mu_cloth mu_collider) =
  sqrt(0.4 x 0.5) = 0.447 (drape.toml: ball and ground 0.5), so cloth_friction = 44.7 on
  both colliders (and the cloth's friction, unused, also 44.7). Self-collision off,
  use_culling on (default; one-sided against outward normals), impulse clamp 0 (none).
- Steps: quality = solver steps per frame, default 20 (480 Hz; Blender's default is 5).
  Blender has no strain limit and its collisions are velocity impulses, so the hem hitting
  the ground and the cap under the falling sheet stretch edges transiently (a few frames,
  around t = 0.5-0.9 s; steady-state strain is 1-3 % at every quality), and how far
  depends on the step: n = 65 gave max strain 1.11 at quality 5 (penetration 7 cm),
  0.51 at 10, 0.10 at 20 (no penetration), the max strain being erratic from run to run
  (collision order is threaded). 20 is the lowest quality that keeps the cloth from going
  visibly rubbery at n = 65 (n = 17: 0.04, 33: 0.07); --quality 5 gives Blender's
  out-of-the-box behaviour. The transient grows as the edges shorten at a fixed step
  (n = 129: 0.28 at quality 20, 0.57 at 10; n = 257: 2.3 at 10), so finer grids would need
  proportionally more steps.
  collision_quality = collision passes per step (Blender's default 2, kept;
  --collision-quality: 5 changed nothing at n = 33).
- Threads: scene.render.threads_mode = 'FIXED', threads = 1 (only the renderer reads it:
  cloth uses Blender's task scheduler (TBB), which follows the process's CPU affinity, so
  the driver's `taskset -c 0` and OMP/TBB variables are what make the run single-threaded;
  step_cpu_seconds / wall_seconds tells).
- 24 fps, 72 frames after the first (3 s); point cache frames 1 .. 73 (in memory).
Only scene.frame_set (which steps the cloth and evaluates the depsgraph, as Blender always
does) is timed; reading the positions is not.
"""

from __future__ import annotations

import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import drape_spec as spec  # noqa: E402

import bpy  # noqa: E402  (first: bmesh comes with it)
import bmesh  # noqa: E402

DEFAULT_QUALITY = 20            # steps per frame (Blender's default is 5; see the docstring)
DEFAULT_COLLISION_QUALITY = 2   # Blender's default
COLLIDER_FRICTION = 0.5         # ball and ground in assets/scenes/drape.toml
RAYLEIGH_BETA = 0.01            # simbake's default cloth damping (s)
COMPRESSION_SCALE = 1.0         # compression stiffness / tension stiffness (simbake's subgrid: 0.01)
INTERNAL_UNIT = math.sqrt(0.001)                  # s: Blender cloth gravity is 0.001 g per unit^2
TIME_SCALE = 1.0 / (spec.FPS * INTERNAL_UNIT)     # 1.3176 at 24 fps
SPHERE_SEGMENTS = (64, 32)
GROUND_SIZE = 10.0


def to_zup(p: np.ndarray) -> np.ndarray:
    p = np.asarray(p, dtype=float)
    return np.stack([p[..., 0], -p[..., 2], p[..., 1]], axis=-1)


def from_zup(p: np.ndarray) -> np.ndarray:
    p = np.asarray(p, dtype=float)
    return np.stack([p[..., 0], p[..., 2], -p[..., 1]], axis=-1)


def grid_quads(n: int) -> np.ndarray:
    """(n-1)^2 quads (p00, p01, p11, p10): counter-clockwise seen from +y (spec), +z (Blender)."""
    j, i = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    p00 = (j * n + i).ravel()
    return np.stack([p00, p00 + n, p00 + n + 1, p00 + 1], -1)


def cloth_parameters(n: int, compression_scale: float = COMPRESSION_SCALE) -> dict:
    """The cloth settings for an n x n grid (see the docstring for the mapping)."""
    h = spec.SIZE / (n - 1)
    y = spec.STRETCH
    beta = RAYLEIGH_BETA / INTERNAL_UNIT          # in internal time units
    tension = y * h / 1250.0
    shear = y * h / 5000.0
    compression = compression_scale * tension
    bending = spec.BEND / (50.0 * h * h)
    return {
        "mass": spec.AREA_DENSITY * spec.SIZE ** 2 / (n * n),
        "tension_stiffness": tension, "shear_stiffness": shear,
        "compression_stiffness": compression, "bending_stiffness": bending,
        "tension_damping": beta * tension / h, "shear_damping": beta * shear / h,
        "compression_damping": beta * compression / h, "bending_damping": 0.2 * beta * bending,
        "air_damping": 0.0,
    }


def build(n: int, quality: int, collision_quality: int, time_scale: float, colliders: bool,
          frames: int, compression_scale: float = COMPRESSION_SCALE, self_collision: bool = False):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = spec.FPS, 1.0
    sc.render.threads_mode, sc.render.threads = "FIXED", 1
    sc.use_gravity = True
    sc.gravity = (0.0, 0.0, -spec.GRAVITY)
    sc.frame_start, sc.frame_end = 1, frames + 1

    vertices = to_zup(spec.grid(n)[0])
    me = bpy.data.meshes.new("sheet")
    me.from_pydata(vertices.tolist(), [], grid_quads(n).tolist())
    me.validate()
    cloth = bpy.data.objects.new("sheet", me)
    sc.collection.objects.link(cloth)
    if len(me.vertices) != n * n or len(me.polygons) != (n - 1) ** 2:
        raise RuntimeError("grid mesh has the wrong size")

    md = cloth.modifiers.new("cloth", "CLOTH")
    s, c = md.settings, md.collision_settings
    params = cloth_parameters(n, compression_scale)
    s.quality = quality
    s.time_scale = time_scale
    s.mass = params["mass"]
    s.air_damping = params["air_damping"]
    s.bending_model = "ANGULAR"
    for key in ("tension", "compression", "shear", "bending"):
        setattr(s, f"{key}_stiffness", params[f"{key}_stiffness"])
        setattr(s, f"{key}_stiffness_max", params[f"{key}_stiffness"])
        setattr(s, f"{key}_damping", params[f"{key}_damping"])
    s.use_internal_springs = s.use_pressure = s.use_sewing_springs = s.use_dynamic_mesh = False
    s.shrink_min = s.shrink_max = 0.0
    s.effector_weights.gravity = 1.0
    s.gravity = (0.0, 0.0, -spec.GRAVITY)
    c.use_collision = colliders
    c.use_self_collision = self_collision
    c.self_distance_min = spec.THICKNESS          # the sheet keeps the spec's thickness from itself
    c.collision_quality = collision_quality
    c.distance_min = spec.THICKNESS * 9.0 / 8.0 - 0.001
    mu = math.sqrt(spec.FRICTION * COLLIDER_FRICTION)
    c.friction = 100.0 * mu                       # not read for object collisions (collision.cc)
    c.impulse_clamp = 0.0
    md.point_cache.frame_start, md.point_cache.frame_end = 1, frames + 1

    if colliders:
        bm = bmesh.new()
        bmesh.ops.create_uvsphere(bm, u_segments=SPHERE_SEGMENTS[0], v_segments=SPHERE_SEGMENTS[1],
                                  radius=spec.SPHERE_RADIUS)
        sphere_mesh = bpy.data.meshes.new("ball")
        bm.to_mesh(sphere_mesh)
        bm.free()
        sphere_mesh.shade_smooth()
        ball = bpy.data.objects.new("ball", sphere_mesh)
        ball.location = tuple(to_zup(np.array(spec.SPHERE_CENTER)))
        ground_mesh = bpy.data.meshes.new("ground")
        g = GROUND_SIZE / 2
        ground_mesh.from_pydata([(-g, -g, 0.0), (g, -g, 0.0), (g, g, 0.0), (-g, g, 0.0)], [], [(0, 1, 2, 3)])
        ground = bpy.data.objects.new("ground", ground_mesh)
        ground.location = (0.0, 0.0, spec.GROUND)
        for obj in (ball, ground):
            sc.collection.objects.link(obj)
            obj.modifiers.new("collision", "COLLISION")
            col = obj.collision
            col.use = True
            col.thickness_outer = 0.001
            col.cloth_friction = 100.0 * mu
            col.use_culling = True
            col.use_normal = False

    settings = {
        "fps": spec.FPS, "quality_steps_per_frame": quality, "collision_quality": collision_quality,
        "time_scale": time_scale, "mesh": "quads", "vertex_mass": s.mass, "total_mass": s.mass * n * n,
        "tension_stiffness": s.tension_stiffness, "compression_stiffness": s.compression_stiffness,
        "shear_stiffness": s.shear_stiffness, "bending_stiffness": s.bending_stiffness,
        "bending_model": s.bending_model,
        "tension_damping": s.tension_damping, "compression_damping": s.compression_damping,
        "shear_damping": s.shear_damping, "bending_damping": s.bending_damping,
        "air_damping": s.air_damping,
        "stiffness_si": "spring k = 1000 x stiffness / h N/m: sides Y/3, each diagonal Y/12, "
                        f"compression {compression_scale:g} x tension; bending B / (50 h^2); damping Rayleigh 0.01 s",
        "distance_min": c.distance_min, "collider_thickness_outer": 0.001 if colliders else None,
        "collision_distance": (c.distance_min + 0.001) * 8.0 / 9.0,
        "friction": mu, "cloth_friction": 100.0 * mu, "self_collision": self_collision,
        "self_distance_min": c.self_distance_min if self_collision else None,
        "sphere": f"UV sphere {SPHERE_SEGMENTS[0]} x {SPHERE_SEGMENTS[1]}, r = {spec.SPHERE_RADIUS}",
        "ground": f"{GROUND_SIZE:g} m quad",
        "render_threads": "FIXED 1",
        "threads": "process pinned to one CPU" if len(os.sched_getaffinity(0)) == 1
                   else f"{len(os.sched_getaffinity(0))} CPUs allowed",
    }
    return sc, cloth, vertices, settings


def reader(cloth, n: int):
    buf = np.empty(3 * n * n, dtype=np.float32)

    def positions() -> np.ndarray:
        depsgraph = bpy.context.evaluated_depsgraph_get()
        ev = cloth.evaluated_get(depsgraph)
        me = ev.data
        if len(me.vertices) != n * n:
            raise RuntimeError(f"evaluated mesh has {len(me.vertices)} vertices, expected {n * n}")
        me.vertices.foreach_get("co", buf)
        local = buf.reshape(-1, 3).astype(np.float64)
        m = np.array(ev.matrix_world)
        return local @ m[:3, :3].T + m[:3, 3]

    return positions


def free_fall(n: int, quality: int, time_scale: float) -> dict:
    """Drop the sheet with no colliders: its drop against 1/2 g t^2."""
    frames = 12
    sc, cloth, start, settings = build(n, quality, DEFAULT_COLLISION_QUALITY, time_scale, False, frames)
    positions = reader(cloth, n)
    sc.frame_set(1)
    z0 = positions()[:, 2].mean()
    rows = []
    for f in range(2, frames + 2):
        sc.frame_set(f)
        t = (f - 1) / spec.FPS
        drop = z0 - positions()[:, 2].mean()
        exact = 0.5 * spec.GRAVITY * t * t
        steps = quality * (f - 1)
        rows.append({"t": round(t, 4), "drop": round(float(drop), 5), "ratio": round(float(drop / exact), 4),
                     "ratio_over_backward_euler": round(float(drop / (exact * (1 + 1 / steps))), 4)})
    at = min(rows, key=lambda r: abs(r["t"] - 0.3))
    return {"engine": "blender", "check": "free fall", "resolution": n, "quality": quality,
            "time_scale": time_scale, "at_0.3s": at, "frames": rows}


def main() -> None:
    import argparse
    ap = argparse.ArgumentParser()
    ap.add_argument("n", type=int, help="vertices per side (16 k + 1)")
    ap.add_argument("--quality", type=int, default=DEFAULT_QUALITY, help="solver steps per frame")
    ap.add_argument("--collision-quality", type=int, default=DEFAULT_COLLISION_QUALITY)
    ap.add_argument("--seconds", type=float, default=spec.SECONDS)
    ap.add_argument("--time-scale", type=float, default=TIME_SCALE)
    ap.add_argument("--compression-scale", type=float, default=COMPRESSION_SCALE,
                    help="compression / tension stiffness (simbake's subgrid 0.01)")
    ap.add_argument("--free-fall", action="store_true", help="the time check: no colliders")
    ap.add_argument("--self-collision", choices=("on", "off"), default="off",
                    help="Blender's self collision (distance = the spec's thickness)")
    args = ap.parse_args()
    if args.free_fall:
        import json
        print(json.dumps(free_fall(args.n, args.quality, args.time_scale)))
        return

    spec.SECONDS = args.seconds        # report() divides the wall time by it
    frames = int(round(args.seconds * spec.FPS))
    n = args.n
    sc, cloth, start, settings = build(n, args.quality, args.collision_quality, args.time_scale, True, frames,
                                       args.compression_scale, args.self_collision == "on")
    positions = reader(cloth, n)
    meter = spec.Meter(n)

    sc.frame_set(1)                    # the initial state (builds the cloth)
    x = positions()
    if np.abs(x - start).max() > 1e-6:
        raise RuntimeError("the evaluated mesh's vertex order differs from the construction's")
    meter.frame(0.0, from_zup(x))

    wall = cpu = 0.0
    for f in range(2, frames + 2):
        t0, c0 = time.perf_counter(), time.process_time()
        sc.frame_set(f)
        wall += time.perf_counter() - t0
        cpu += time.process_time() - c0
        meter.frame((f - 1) / spec.FPS, from_zup(positions()))

    final = from_zup(positions())
    k = np.arange(n * n).reshape(n, n)
    corners = [k[0, 0], k[0, -1], k[-1, 0], k[-1, -1]]
    spec.report("blender", n, settings, wall, meter, version=bpy.app.version_string,
                step_cpu_seconds=cpu, frames=frames,
                final_center_y=float(final[k[n // 2, n // 2], 1]),
                final_corner_y_max=float(final[corners, 1].max()),
                final_min_y=float(final[:, 1].min()))


if __name__ == "__main__":
    main()
