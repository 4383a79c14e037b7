"""Rigid-body stress run: push each axis until something breaks, and record where.

Axes (DESIGN.md, "Fast and accurate": time step, stiffness, mass ratio, speed):

- speed        a 0.2 m box and a 0.2 m sphere shot at a 0.1 m thick kinematic wall
               (no gravity, restitution 0.5 on both, friction 0), automatic substeps and a
               fixed 1 substep per frame. Pass: ends on the near side (no tunnelling, not
               stuck in the wall), no NaN, rebound speed <= impact speed.
- mass_ratio   a light 0.5 m box (1 kg) on the ground under a heavy one (1 ... 10000 kg),
               5 s, automatic substeps. Pass: drift < 5 mm, penetration < 2 mm, no NaN.
- stack        aligned towers of 5 ... 40 unit boxes (1 kg each), 10 s, default settings
               (max_substep 1/240) and max_substep 1/120. Pass: drift < 10 mm, no NaN.
- substeps     the 10-box tower (10 s) and a bouncing sphere (r 0.1 m, e 0.5, dropped
               from 1 m, first apex 0.25 m) at a fixed 1, 2, 4, 8 substeps per frame at
               24 fps. Pass: tower drift < 10 mm; sphere first apex error < 10%.
- body_count   piles of 100 ... 3000 0.5 m boxes (grid, 0.8 m spacing, random tilt up to
               20 degrees, seed 1), 3 s, automatic substeps. Recorded: wall s per simulated
               s, memory (ru_maxrss of the case's process), max penetration, NaN. Pass:
               finishes within the timeout, no NaN, penetration < 5 mm.
- thin         the torus (assets/meshes/torus.obj, density 600, pipeline voxel size and
               samples) dropped over a kinematic post 1 m tall of width 0.06, 0.03, 0.015 m,
               two drops each (nearly centred; off centre with a sideways push so the tube
               strikes the post). Pass: the ring ends threaded on the post, max penetration
               < 5 mm, no NaN.
- overlap      two 0.5 m boxes starting 50% overlapped (side by side on the ground, stacked
               on the ground, and floating without gravity). Pass: separated after 3 s
               (penetration < 2 mm), max speed after 1 s < 2 m/s, no NaN.

Every case runs in its own process with a 60 s timeout: a hang or a crash is a failure, and
the progress the case reported before it (simulated time reached) is kept. All stepping
happens in the C++ core (`World.step_frame`, or `World.step` for the bounce apex).

    .venv/bin/python benchmarks/stress/rigid_stress.py              # all axes
    .venv/bin/python benchmarks/stress/rigid_stress.py speed thin   # some axes

Writes benchmarks/results/stress.json (every number) and stress.md (a table per axis, the
breaking points).
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import resource
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
RESULTS_DIR = ROOT / "benchmarks" / "results"
TORUS = ROOT / "assets" / "meshes" / "torus.obj"

FPS = 24
FRAME_DT = 1.0 / FPS
TIMEOUT = 60.0
THREADS = 1  # the narrow phase's worker threads (results are identical for any count)

# the pipeline's primitive samples (pipeline/simbake/assets.py)
BOX_SUBDIVISIONS = 3
SPHERE_SUBDIVISIONS = 8
# and its automatic choices for a mesh body (torus: 0.8 x 0.2 x 0.8 m)
VOXELS_ACROSS = 64
MIN_VOXELS_THIN = 6
SAMPLES_ACROSS = 4

IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


# =======================================================================================
# the cases (run inside the child process)


def progress(**values) -> None:
    """A line the parent keeps even when the case later hangs or crashes."""
    print("PROGRESS " + json.dumps(values), flush=True)


def maxrss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def world(**settings):
    from simbake import _core
    settings.setdefault("threads", THREADS)
    return _core.World(**settings)


def add_box(w, size, mass, origin, orientation=IDENTITY, **kwargs) -> int:
    from simbake import _core
    size = np.asarray(size, dtype=float)
    return w.add_body(_core.LevelSet.box(size), _core.box_mesh(size, BOX_SUBDIVISIONS)[0],
                      _core.box_mass_properties(size), float(mass), np.asarray(origin, dtype=float),
                      np.asarray(orientation, dtype=float), **kwargs)


def add_sphere(w, radius, mass, origin, **kwargs) -> int:
    from simbake import _core
    return w.add_body(_core.LevelSet.sphere(radius), _core.sphere_mesh(radius, SPHERE_SUBDIVISIONS)[0],
                      _core.sphere_mass_properties(radius), float(mass), np.asarray(origin, dtype=float),
                      IDENTITY, **kwargs)


def positions(w) -> np.ndarray:
    return np.asarray(w.mesh_poses()[0])


def velocities(w, bodies) -> np.ndarray:
    return np.array([w.body_state(i)["linear_velocity"] for i in bodies])


def all_finite(w) -> bool:
    if not w.statistics()["finite"]:
        return False
    t, q = w.mesh_poses()
    return bool(np.isfinite(t).all() and np.isfinite(q).all())


def quat_axis_angle(axis, angle) -> np.ndarray:
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    return np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * axis])


def quat_to_matrix(q) -> np.ndarray:
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


class Stepper:
    """Steps frames, times only the stepping, tracks NaN, penetration and substeps."""

    def __init__(self, w, substeps: int = 0):
        self.w, self.substeps = w, substeps
        self.wall = 0.0
        self.frames = 0
        self.substep_counts: list[int] = []
        self.max_penetration = 0.0
        self.finite = True
        self.last_report = time.perf_counter()

    def frame(self) -> bool:
        start = time.perf_counter()
        n = self.w.step_frame(FRAME_DT, self.substeps)
        self.wall += time.perf_counter() - start
        self.frames += 1
        self.substep_counts.append(int(n))
        stats = self.w.statistics()
        pen = stats["max_penetration"]
        if np.isfinite(pen):
            self.max_penetration = max(self.max_penetration, pen)
        self.finite = self.finite and all_finite(self.w)
        if time.perf_counter() - self.last_report > 2.0:
            self.last_report = time.perf_counter()
            progress(simulated_s=self.frames * FRAME_DT, stepping_wall_s=self.wall,
                     maxrss_mb=maxrss_mb(), max_penetration=self.max_penetration, finite=self.finite)
        return self.finite

    def summary(self) -> dict:
        counts = self.substep_counts or [0]
        return {"simulated_s": self.frames * FRAME_DT, "stepping_wall_s": self.wall,
                "wall_per_simulated_s": self.wall / max(self.frames * FRAME_DT, 1e-12),
                "substeps_per_frame_mean": float(np.mean(counts)), "substeps_per_frame_max": int(max(counts)),
                "max_penetration": self.max_penetration, "finite": self.finite}


# --- speed ------------------------------------------------------------------------------

WALL_THICKNESS = 0.1
PROJECTILE = 0.2   # box edge and sphere diameter (m)
GAP = 1.0          # from the projectile's front face to the wall (m)


PHASES = 5         # impact phases: the gap grows by a fifth of a frame's travel each


def shoot(shape: str, speed: float, substeps: int, gap: float) -> dict:
    w = world(gravity=np.zeros(3))
    add_box(w, [WALL_THICKNESS, 2.0, 2.0], 1.0, [0.0, 0.0, 0.0], kinematic=True, restitution=0.5, friction=0.0)
    x0 = -(WALL_THICKNESS / 2 + gap + PROJECTILE / 2)
    kwargs = dict(linear_velocity=np.array([float(speed), 0.0, 0.0]), restitution=0.5, friction=0.0)
    if shape == "box":
        body = add_box(w, [PROJECTILE] * 3, 1.0, [x0, 0.0, 0.0], **kwargs)
    else:
        body = add_sphere(w, PROJECTILE / 2, 1.0, [x0, 0.0, 0.0], **kwargs)
    frames = int(math.ceil((gap / speed + 0.5) * FPS)) + 1
    s = Stepper(w, substeps)
    for _ in range(frames):
        if not s.frame():
            break
    state = w.body_state(body)
    v = np.asarray(state["linear_velocity"], dtype=float)
    omega = np.asarray(state["angular_velocity"], dtype=float)
    x = float(positions(w)[body][0])
    near_face = -(WALL_THICKNESS / 2 + PROJECTILE / 2)  # centre of a body touching the wall
    if not s.finite:
        outcome = "NaN"
    elif x > 0.0:
        outcome = "tunnelled"
    elif x > near_face + 0.01:
        outcome = "stuck in wall"
    elif v[0] > 1e-9:
        outcome = "still approaching"
    else:
        outcome = "rebounded"
    rebound = float(np.linalg.norm(v)) if s.finite else float("nan")
    # kinetic energy of the unit-mass body with its spin (box: I = m a^2 / 6, sphere: 2/5 m r^2)
    inertia = PROJECTILE ** 2 / 6.0 if shape == "box" else 0.4 * (PROJECTILE / 2) ** 2
    energy = (0.5 * rebound ** 2 + 0.5 * inertia * float(omega @ omega)) / (0.5 * speed ** 2)
    gain = s.finite and (rebound > speed * (1 + 1e-6) or energy > 1 + 1e-6)
    return dict(s.summary(), gap=gap, outcome=outcome, energy_gain=bool(gain), final_x=x, final_vx=float(v[0]),
                rebound_over_impact=rebound / speed, kinetic_energy_ratio=energy,
                final_spin=float(np.linalg.norm(omega)))


def case_speed(shape: str, speed: float, substeps: int) -> dict:
    """The shot at PHASES gaps (GAP plus fifths of a frame's travel): the impact falls at a
    different point of a substep each time; the case passes only if every phase passes."""
    runs = [shoot(shape, speed, substeps, GAP + k / PHASES * speed * FRAME_DT) for k in range(PHASES)]
    bad = [r for r in runs if r["outcome"] != "rebounded" or r["energy_gain"]]
    failures = []
    for outcome in ("NaN", "tunnelled", "stuck in wall", "still approaching"):
        n = sum(r["outcome"] == outcome for r in runs)
        if n:
            failures.append(f"{outcome} ({n}/{PHASES} phases)")
    gains = [r for r in runs if r["energy_gain"]]
    if gains:
        worst = max(gains, key=lambda r: r["kinetic_energy_ratio"])
        failures.append(f"energy gain ({len(gains)}/{PHASES} phases; rebound/impact "
                        f"{worst['rebound_over_impact']:.3g}, KE out/in {worst['kinetic_energy_ratio']:.3g})")
    rebounds = [r for r in runs if r["outcome"] == "rebounded"]
    outcomes = ", ".join(f"{o} {sum(r['outcome'] == o for r in runs)}" for o in dict.fromkeys(r["outcome"] for r in runs))
    return {"passed": not bad, "failure": "; ".join(failures), "outcomes": outcomes, "phases": runs,
            "finite": all(r["finite"] for r in runs),
            "max_penetration": max(r["max_penetration"] for r in runs),
            "rebound_over_impact_range": [min(r["rebound_over_impact"] for r in rebounds),
                                          max(r["rebound_over_impact"] for r in rebounds)] if rebounds else None,
            "kinetic_energy_ratio_max": max(r["kinetic_energy_ratio"] for r in runs),
            "final_spin_max": max(r["final_spin"] for r in rebounds) if rebounds else None,
            "substeps_per_frame_max": max(r["substeps_per_frame_max"] for r in runs),
            "stepping_wall_s": sum(r["stepping_wall_s"] for r in runs),
            "simulated_s": sum(r["simulated_s"] for r in runs),
            "wall_per_simulated_s": sum(r["stepping_wall_s"] for r in runs) / sum(r["simulated_s"] for r in runs)}


# --- mass ratio -------------------------------------------------------------------------


def case_mass_ratio(heavy: float) -> dict:
    w = world()
    w.set_ground(0.0, 0.5, 0.0)
    size = 0.5
    add_box(w, [size] * 3, 1.0, [0.0, size / 2, 0.0])
    add_box(w, [size] * 3, heavy, [0.0, 1.5 * size, 0.0])
    start = positions(w)
    s = Stepper(w)
    drift = np.zeros(2)
    for _ in range(5 * FPS):
        if not s.frame():
            break
        drift = np.maximum(drift, np.linalg.norm(positions(w) - start, axis=1))
    end = positions(w) - start
    failures = []
    if not s.finite:
        failures.append("NaN")
    if drift.max() >= 5e-3:
        failures.append(f"drift {1e3 * drift.max():.3g} mm")
    if s.max_penetration >= 2e-3:
        failures.append(f"penetration {1e3 * s.max_penetration:.3g} mm")
    return dict(s.summary(), passed=not failures, failure="; ".join(failures),
                max_drift=float(drift.max()), max_drift_light=float(drift[0]), max_drift_heavy=float(drift[1]),
                final_sink_light=float(-end[0, 1]), final_sink_heavy=float(-end[1, 1]),
                final_horizontal=float(np.abs(end[:, [0, 2]]).max()),
                final_penetration=float(w.statistics()["max_penetration"]))


# --- towers (stack height and substep size) ----------------------------------------------


def tower(boxes: int, seconds: float, substeps: int = 0, max_substep: float | None = None) -> dict:
    settings = {} if max_substep is None else {"max_substep": max_substep}
    w = world(**settings)
    w.set_ground(0.0, 0.5, 0.0)
    for i in range(boxes):
        add_box(w, [1.0, 1.0, 1.0], 1.0, [0.0, 0.5 + i, 0.0])
    start = positions(w)
    s = Stepper(w, substeps)
    drift = np.zeros(boxes)
    for _ in range(int(round(seconds * FPS))):
        if not s.frame():
            break
        drift = np.maximum(drift, np.linalg.norm(positions(w) - start, axis=1))
    end = positions(w) - start
    failures = []
    if not s.finite:
        failures.append("NaN")
    if drift.max() >= 10e-3:
        top = end[-1]
        failures.append(f"drift {1e3 * drift.max():.3g} mm (top box ends at dx {1e3 * top[0]:.3g}, "
                        f"dy {1e3 * top[1]:.3g}, dz {1e3 * top[2]:.3g} mm)")
    return dict(s.summary(), passed=not failures, failure="; ".join(failures),
                max_drift=float(drift.max()), worst_box=int(np.argmax(drift)),
                top_final_offset=end[-1].tolist(), top_final_sink=float(-end[-1, 1]),
                top_final_horizontal=float(np.hypot(end[-1, 0], end[-1, 2])),
                sleeping_at_end=int(w.sleeping_count),
                final_penetration=float(w.statistics()["max_penetration"]))


def case_stack(boxes: int, max_substep: float | None) -> dict:
    return tower(boxes, 10.0, 0, max_substep)


# --- bouncing sphere ----------------------------------------------------------------------

BOUNCE_R = 0.1
BOUNCE_H0 = 1.0
BOUNCE_E = 0.5
G = 9.81


def case_bounce(substeps: int) -> dict:
    """The ballistic apex (y + v^2 / 2g of the last rising state) after each bounce, stepping
    substep by substep with World.step (the same dt as step_frame(1/24, substeps))."""
    w = world()
    w.set_ground(0.0, 0.0, 0.0)
    body = add_sphere(w, BOUNCE_R, 1.0, [0.0, BOUNCE_R + BOUNCE_H0, 0.0], restitution=BOUNCE_E, friction=0.0)
    dt = FRAME_DT / substeps
    steps = int(round(1.25 / dt))  # past the third apex
    apexes, finite, max_pen, lowest = [], True, 0.0, float("inf")
    prev_vy, prev_apex = 0.0, None
    start = time.perf_counter()
    for k in range(steps):
        w.step(dt)
        st = w.body_state(body)
        y = float(st["center_of_mass"][1]) - BOUNCE_R
        vy = float(st["linear_velocity"][1])
        if not (np.isfinite(y) and np.isfinite(vy)):
            finite = False
            break
        lowest = min(lowest, y)
        if vy > 0.0:
            prev_apex = y + vy * vy / (2 * G)
        elif prev_vy > 0.0 and prev_apex is not None:
            apexes.append(prev_apex)
            prev_apex = None
        prev_vy = vy
    wall = time.perf_counter() - start
    reference = [BOUNCE_H0 * BOUNCE_E ** (2 * k) for k in (1, 2, 3)]
    errors = [(a - r) / r for a, r in zip(apexes, reference)]
    failures = []
    if not finite:
        failures.append("NaN")
    if not errors:
        failures.append("no bounce (stuck in or through the ground)")
    elif abs(errors[0]) >= 0.10:
        failures.append(f"first apex {apexes[0]:.4g} m, error {100 * errors[0]:+.3g}%")
    return dict(passed=not failures, failure="; ".join(failures), apexes=apexes, reference=reference,
                relative_errors=errors, first_apex_error=errors[0] if errors else float("nan"),
                lowest_bottom=lowest, max_penetration=max(0.0, -lowest), finite=finite,
                stepping_wall_s=wall, simulated_s=steps * dt, wall_per_simulated_s=wall / (steps * dt),
                substeps_per_frame_mean=float(substeps))


def case_substeps(problem: str, substeps: int) -> dict:
    if problem == "tower10":
        return tower(10, 10.0, substeps)
    return case_bounce(substeps)


# --- body count ---------------------------------------------------------------------------


def pile_layout(count: int, seed: int = 1):
    side = int(math.ceil(1.3 * count ** (1.0 / 3.0)))
    rng = np.random.default_rng(seed)
    origins, orientations = [], []
    for n in range(count):
        layer, rest = divmod(n, side * side)
        i, j = divmod(rest, side)
        origins.append([(i - (side - 1) / 2) * 0.8, 0.5 + 0.8 * layer, (j - (side - 1) / 2) * 0.8])
        axis = rng.normal(size=3)
        orientations.append(quat_axis_angle(axis, math.radians(20.0) * rng.random()))
    return np.array(origins), np.array(orientations), side


def case_body_count(count: int) -> dict:
    progress(stage="start", maxrss_mb=maxrss_mb())
    base_rss = maxrss_mb()
    w = world()
    w.set_ground(0.0, 0.5, 0.0)
    origins, orientations, side = pile_layout(count)
    for o, q in zip(origins, orientations):
        add_box(w, [0.5] * 3, 125.0, o, q)
    built_rss = maxrss_mb()
    progress(stage="built", maxrss_mb=built_rss)
    s = Stepper(w)
    max_speed_end = 0.0
    for _ in range(3 * FPS):
        if not s.frame():
            break
    if s.finite:
        max_speed_end = float(np.linalg.norm(velocities(w, range(count)), axis=1).max())
    lowest = float(positions(w)[:, 1].min())
    failures = []
    if not s.finite:
        failures.append("NaN")
    if s.max_penetration >= 5e-3:
        failures.append(f"penetration {1e3 * s.max_penetration:.3g} mm")
    if lowest < 0.0:
        failures.append(f"a box centre below the ground ({lowest:.3g} m)")
    return dict(s.summary(), passed=not failures, failure="; ".join(failures), footprint=f"{side}x{side}",
                layers=int(math.ceil(count / side ** 2)), maxrss_before_world_mb=base_rss,
                maxrss_after_build_mb=built_rss, maxrss_end_mb=maxrss_mb(),
                final_penetration=float(w.statistics()["max_penetration"]), lowest_centre=lowest,
                max_speed_at_end=max_speed_end, sleeping_at_end=int(w.sleeping_count),
                impulses=int(w.statistics()["impulses"]))


# --- thin features ------------------------------------------------------------------------

HOLE_RADIUS = 0.2  # torus.obj: tube radius 0.1 around a ring of radius 0.3 about y


def load_torus():
    import trimesh
    from simbake import _core
    mesh = trimesh.load(str(TORUS), force="mesh", process=True)
    v = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
    t = np.ascontiguousarray(mesh.faces, dtype=np.int32)
    extent = v.max(axis=0) - v.min(axis=0)
    voxel = float(min(extent.max() / VOXELS_ACROSS, extent.min() / MIN_VOXELS_THIN))
    samples = _core.surface_samples(v, t, float(extent.min()) / SAMPLES_ACROSS)
    return v, t, voxel, samples, _core.mass_properties(v, t)


def threaded_on_post(translation, orientation, post_xz, post_height) -> tuple[bool, float, float]:
    """Where the post's axis crosses the ring's plane: radial distance from the ring's axis
    in its plane, and the height of the crossing; threaded if inside the hole and on the post."""
    r = quat_to_matrix(orientation)
    c = np.asarray(translation, dtype=float)
    u = r[:, 1]  # the ring's axis in world
    if abs(u[1]) < 1e-6:
        return False, float("inf"), float("nan")
    px, pz = post_xz
    y = c[1] - (u[0] * (px - c[0]) + u[2] * (pz - c[2])) / u[1]
    local = r.T @ (np.array([px, y, pz]) - c)
    rho = float(math.hypot(local[0], local[2]))
    return rho < HOLE_RADIUS and 0.0 <= y <= post_height, rho, float(y)


def case_thin(width: float, drop: str) -> dict:
    from simbake import _core
    v, t, voxel, samples, props = load_torus()
    bake_start = time.perf_counter()
    level_set = _core.LevelSet.bake(v, t, voxel)
    bake_s = time.perf_counter() - bake_start
    w = world()
    w.set_ground(0.0, 0.5, 0.0)
    add_box(w, [width, 1.0, width], 1.0, [0.0, 0.5, 0.0], kinematic=True)
    if drop == "centred":  # like the shipped ring_toss scene: a small tilt and offset
        origin, q, vel = [0.02, 1.4, -0.01], quat_axis_angle([1.0, 0.0, 0.5], math.radians(8.0)), [0.0, 0.0, 0.0]
    else:  # "strike": off centre, tilted and pushed so that the inner side of the tube hits the post
        origin, q, vel = [-0.12, 1.4, 0.03], quat_axis_angle([0.2, 0.0, 1.0], math.radians(15.0)), [0.6, 0.0, 0.0]
    mass = 600.0 * props["volume"]
    ring = w.add_body(level_set, samples, props, mass, np.array(origin), q,
                      linear_velocity=np.array(vel), friction=0.4)
    s = Stepper(w)
    for _ in range(4 * FPS):
        if not s.frame():
            break
    tr, qs = w.mesh_poses()
    on_post, rho, cross_y = threaded_on_post(tr[ring], qs[ring], (0.0, 0.0), 1.0)
    failures = []
    if not s.finite:
        failures.append("NaN")
    elif not on_post:
        failures.append(f"ring not on the post (post axis {rho:.3g} m from the ring axis, crossing at y {cross_y:.3g} m)")
    if s.max_penetration >= 5e-3:
        failures.append(f"penetration {1e3 * s.max_penetration:.3g} mm")
    return dict(s.summary(), passed=not failures, failure="; ".join(failures), voxel_size=voxel,
                torus_samples=int(len(samples)), bake_s=bake_s, ring_mass=mass, post_axis_from_ring_axis=rho,
                crossing_height=cross_y, ring_final=np.asarray(tr[ring]).tolist(),
                final_penetration=float(w.statistics()["max_penetration"]))


# --- deep initial overlap -----------------------------------------------------------------


def case_overlap(layout: str) -> dict:
    size = 0.5
    if layout == "floating":
        w = world(gravity=np.zeros(3))
        a, b = [-size / 4, 1.0, 0.0], [size / 4, 1.0, 0.0]
    else:
        w = world()
        w.set_ground(0.0, 0.5, 0.0)
        if layout == "side":
            a, b = [-size / 4, size / 2, 0.0], [size / 4, size / 2, 0.0]
        else:  # "stacked": the upper box half sunk into the lower one
            a, b = [0.0, size / 2, 0.0], [0.0, size, 0.0]
    add_box(w, [size] * 3, 10.0, a)
    add_box(w, [size] * 3, 10.0, b)
    start = positions(w)
    s = Stepper(w)
    peak_first, peak_after, spin_after = 0.0, 0.0, 0.0
    for _ in range(3 * FPS):
        if not s.frame():
            break
        speed = float(np.linalg.norm(velocities(w, [0, 1]), axis=1).max())
        spin = max(float(np.linalg.norm(w.body_state(i)["angular_velocity"])) for i in (0, 1))
        if s.frames * FRAME_DT <= 1.0 + 1e-9:
            peak_first = max(peak_first, speed)
        else:
            peak_after = max(peak_after, speed)
            spin_after = max(spin_after, spin)
    end = positions(w)
    final_pen = float(w.statistics()["max_penetration"])
    failures = []
    if not s.finite:
        failures.append("NaN")
    else:
        if peak_after >= 2.0:
            failures.append(f"max speed after 1 s {peak_after:.3g} m/s")
        if final_pen >= 2e-3:
            failures.append(f"still overlapped at 3 s ({1e3 * final_pen:.3g} mm)")
    return dict(s.summary(), passed=not failures, failure="; ".join(failures),
                peak_speed_first_s=peak_first, max_speed_after_1s=peak_after, max_spin_after_1s=spin_after,
                final_penetration=final_pen, centre_distance_start=float(np.linalg.norm(start[1] - start[0])),
                centre_distance_end=float(np.linalg.norm(end[1] - end[0])), final_positions=end.tolist())


CASES = {"speed": case_speed, "mass_ratio": case_mass_ratio, "stack": case_stack,
         "substeps": case_substeps, "body_count": case_body_count, "thin": case_thin,
         "overlap": case_overlap}


# =======================================================================================
# the plan (which cases, in which order) and the parent process


def plan() -> dict[str, list[dict]]:
    """axis -> cases; each case: series (the line along which the value is pushed), value,
    and args for its function."""
    p: dict[str, list[dict]] = {}
    p["speed"] = [{"series": f"{shape}, {'auto substeps' if n == 0 else '1 substep/frame'}", "value": v,
                   "args": [shape, v, n]}
                  for shape in ("box", "sphere") for n in (0, 1) for v in (1, 3, 10, 30, 100, 300, 1000, 3000, 10000)]
    p["mass_ratio"] = [{"series": "1 kg under heavy box", "value": m, "args": [m]}
                       for m in (1, 10, 100, 1000, 10000)]
    p["stack"] = [{"series": label, "value": n, "args": [n, ms]}
                  for label, ms in (("default (max_substep 1/240)", None), ("max_substep 1/120", 1.0 / 120.0))
                  for n in (5, 10, 20, 40)]
    p["substeps"] = [{"series": label, "value": n, "args": [problem, n]}
                     for problem, label in (("tower10", "10-box tower, 10 s"), ("bounce", "bouncing sphere"))
                     for n in (8, 4, 2, 1)]
    p["body_count"] = [{"series": "pile of 0.5 m boxes, 3 s", "value": n, "args": [n]} for n in (100, 300, 1000, 3000)]
    p["thin"] = [{"series": f"torus, {drop} drop", "value": width, "args": [width, drop]}
                 for drop in ("centred", "strike") for width in (0.06, 0.03, 0.015)]
    p["overlap"] = [{"series": "two 0.5 m boxes, 50% overlap", "value": layout, "args": [layout]}
                    for layout in ("side", "stacked", "floating")]
    return p


def run_case(axis: str, case: dict) -> dict:
    """The case in a child process with a timeout; its rusage from wait4."""
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        start = time.perf_counter()
        proc = subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "--case", axis,
                                 json.dumps(case["args"])], stdout=out, stderr=err, cwd=str(ROOT))
        status, usage, timed_out = None, None, False
        while True:
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid == proc.pid:
                break
            if time.perf_counter() - start > TIMEOUT:
                timed_out = True
                os.kill(proc.pid, signal.SIGKILL)
                _, status, usage = os.wait4(proc.pid, 0)
                break
            time.sleep(0.02)
        wall = time.perf_counter() - start
        proc.returncode = os.waitstatus_to_exitcode(status)  # reaped here, not by Popen
        out.seek(0)
        err.seek(0)
        lines = out.read().splitlines()
        stderr = err.read()
    record = {"axis": axis, "series": case["series"], "value": case["value"], "args": case["args"],
              "process_wall_s": wall, "maxrss_mb": usage.ru_maxrss / 1024.0,
              "process_cpu_s": usage.ru_utime + usage.ru_stime, "exit_code": proc.returncode}
    results = [json.loads(l[len("RESULT "):]) for l in lines if l.startswith("RESULT ")]
    progress_lines = [json.loads(l[len("PROGRESS "):]) for l in lines if l.startswith("PROGRESS ")]
    if results:
        record.update(results[-1])
    else:
        record["passed"] = False
        if timed_out:
            record["failure"] = f"timeout ({TIMEOUT:g} s)"
        elif proc.returncode < 0:
            record["failure"] = f"crashed ({signal.Signals(-proc.returncode).name})"
        else:
            last = stderr.strip().splitlines()[-1] if stderr.strip() else ""
            record["failure"] = f"error (exit {proc.returncode}): {last}"
        if progress_lines:
            record["last_progress"] = progress_lines[-1]
            last = progress_lines[-1]
            if "simulated_s" in last:
                record["simulated_s"] = last["simulated_s"]
                record["stepping_wall_s"] = last["stepping_wall_s"]
                record["wall_per_simulated_s"] = last["stepping_wall_s"] / max(last["simulated_s"], 1e-12)
                record["max_penetration"] = last.get("max_penetration")
                record["finite"] = last.get("finite")
        record["stderr_tail"] = stderr[-2000:]
    record["timed_out"] = timed_out
    return record


def child(axis: str, args_json: str) -> None:
    result = CASES[axis](*json.loads(args_json))
    print("RESULT " + json.dumps(result, default=float), flush=True)


# =======================================================================================
# reporting


def fmt(value, digits: int = 3) -> str:
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            return str(value)
        if value == 0.0:
            return "0"
        if abs(value) >= 1e5 or abs(value) < 1e-3:
            return f"{value:.{digits}g}"
        return f"{value:.{digits}g}"
    return str(value)


def mm(value) -> str:
    return "-" if value is None else fmt(1e3 * value)


def pct(value) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{100 * value:+.3g}%"


AXIS_TITLES = {
    "speed": "Speed: 0.2 m box / sphere shot at a 0.1 m kinematic wall (e 0.5, no gravity)",
    "mass_ratio": "Mass ratio: 1 kg box under a heavy box, 5 s, automatic substeps",
    "stack": "Stack height: aligned towers of 1 m boxes, 10 s, automatic substeps",
    "substeps": "Substep size: fixed substeps per frame at 24 fps",
    "body_count": "Body count: piles of 0.5 m boxes (0.8 m grid, tilt <= 20 deg, seed 1), 3 s",
    "thin": "Thin features: torus (hole radius 0.2 m, tube 0.2 m) over a 1 m post",
    "overlap": "Deep initial overlap: two 0.5 m boxes, 10 kg each, 50% overlapped, 3 s",
}

VALUE_NAMES = {"speed": "speed (m/s)", "mass_ratio": "heavy mass (kg)", "stack": "boxes",
               "substeps": "substeps/frame", "body_count": "boxes", "thin": "post width (m)",
               "overlap": "layout"}


def columns(axis: str) -> list[tuple[str, callable]]:
    g = lambda key: (lambda r: r.get(key))  # noqa: E731
    if axis == "speed":
        return [("outcomes (5 phases)", lambda r: r.get("outcomes", "-")),
                ("rebound/impact", lambda r: "-" if not r.get("rebound_over_impact_range") else
                 "{} - {}".format(*map(fmt, r["rebound_over_impact_range"]))),
                ("max KE out/in", lambda r: fmt(r.get("kinetic_energy_ratio_max"))),
                ("max spin after (rad/s)", lambda r: fmt(r.get("final_spin_max"))),
                ("max pen (mm)", lambda r: mm(r.get("max_penetration"))),
                ("substeps/frame", lambda r: fmt(r.get("substeps_per_frame_max")))]
    if axis == "mass_ratio":
        return [("max drift (mm)", lambda r: mm(r.get("max_drift"))),
                ("light sink (mm)", lambda r: mm(r.get("final_sink_light"))),
                ("heavy sink (mm)", lambda r: mm(r.get("final_sink_heavy"))),
                ("max pen (mm)", lambda r: mm(r.get("max_penetration"))),
                ("substeps/frame", lambda r: fmt(r.get("substeps_per_frame_mean")))]
    if axis in ("stack", "substeps"):
        return [("max drift (mm)", lambda r: mm(r.get("max_drift"))),
                ("top sink (mm)", lambda r: mm(r.get("top_final_sink"))),
                ("top sideways (mm)", lambda r: mm(r.get("top_final_horizontal"))),
                ("apex 1 / 2 / 3 err", lambda r: " / ".join(pct(e) for e in r["relative_errors"])
                 if r.get("relative_errors") else "-"),
                ("max pen (mm)", lambda r: mm(r.get("max_penetration"))),
                ("asleep", lambda r: fmt(r.get("sleeping_at_end"))),
                ("substeps/frame", lambda r: fmt(r.get("substeps_per_frame_mean")))]
    if axis == "body_count":
        return [("wall s / sim s", lambda r: fmt(r.get("wall_per_simulated_s"))),
                ("sim s reached", lambda r: fmt(r.get("simulated_s"))),
                ("maxrss (MB)", lambda r: fmt(r.get("maxrss_mb"), 4)),
                ("max pen (mm)", lambda r: mm(r.get("max_penetration"))),
                ("finite", lambda r: fmt(r.get("finite"))),
                ("asleep at end", lambda r: fmt(r.get("sleeping_at_end"))),
                ("substeps/frame", lambda r: fmt(r.get("substeps_per_frame_mean")))]
    if axis == "thin":
        return [("post axis from ring axis (m)", lambda r: fmt(r.get("post_axis_from_ring_axis"))),
                ("ring centre y (m)", lambda r: fmt(r["ring_final"][1]) if r.get("ring_final") else "-"),
                ("max pen (mm)", lambda r: mm(r.get("max_penetration"))),
                ("end pen (mm)", lambda r: mm(r.get("final_penetration"))),
                ("substeps/frame", lambda r: fmt(r.get("substeps_per_frame_mean")))]
    if axis == "overlap":
        return [("peak speed 0-1 s (m/s)", lambda r: fmt(r.get("peak_speed_first_s"))),
                ("max speed 1-3 s (m/s)", lambda r: fmt(r.get("max_speed_after_1s"))),
                ("max spin 1-3 s (rad/s)", lambda r: fmt(r.get("max_spin_after_1s"))),
                ("end pen (mm)", lambda r: mm(r.get("final_penetration"))),
                ("centre distance start / end (m)", lambda r: f"{fmt(r.get('centre_distance_start'))} / "
                 f"{fmt(r.get('centre_distance_end'))}" if r.get("centre_distance_end") is not None else "-")]
    return []


def breaking_points(records: list[dict]) -> list[dict]:
    """Per axis and series, in the order values were pushed: the last pass before the first
    failure, the first failure and how it fails."""
    out = []
    seen = []
    for r in records:
        key = (r["axis"], r["series"])
        if key not in seen:
            seen.append(key)
    for axis, series in seen:
        rows = [r for r in records if r["axis"] == axis and r["series"] == series]
        first_fail = next((i for i, r in enumerate(rows) if not r.get("passed")), None)
        entry = {"axis": axis, "series": series, "values": [r["value"] for r in rows],
                 "last_pass": rows[first_fail - 1]["value"] if first_fail else (rows[-1]["value"] if first_fail is None else None),
                 "first_fail": rows[first_fail]["value"] if first_fail is not None else None,
                 "how": rows[first_fail].get("failure") if first_fail is not None else "",
                 "later_passes": [r["value"] for r in rows[(first_fail or len(rows)) + 1:] if r.get("passed")]}
        out.append(entry)
    return out


def markdown(records: list[dict], breaks: list[dict], info: dict, total_s: float) -> str:
    lines = ["# Rigid-body stress run", "",
             f"simbake {info['simbake_version']}, {info['cpu_model']}, {info['date']}, "
             f"narrow phase on {THREADS} thread(s), load average "
             f"{', '.join(f'{v:.2f}' for v in info['load_average_1_5_15_min'])}; the run took "
             f"{total_s:.0f} s. Each case ran in its own process with a {TIMEOUT:g} s timeout; "
             "`wall s` is the case process's wall time (start-up, building and stepping), "
             "`step s / sim s` the stepping alone per simulated second. Frames are 1/24 s. "
             "Written by `benchmarks/stress/rigid_stress.py` (its docstring has every setup and "
             "pass criterion).", ""]
    lines += ["## What breaks", ""]
    for b in breaks:
        if b["first_fail"] is None:
            lines.append(f"- **{b['axis']} / {b['series']}**: no failure up to {b['values'][-1]}")
        else:
            last = "none (fails at the first value)" if b["last_pass"] is None else b["last_pass"]
            later = f"; passes again at {', '.join(map(str, b['later_passes']))}" if b["later_passes"] else ""
            lines.append(f"- **{b['axis']} / {b['series']}**: last pass {last}, first failure "
                         f"{b['first_fail']}: {b['how']}{later}")
    lines.append("")
    for axis in AXIS_TITLES:
        rows = [r for r in records if r["axis"] == axis]
        if not rows:
            continue
        cols = columns(axis)
        if axis not in ("substeps",):
            cols = [c for c in cols if c[0] != "apex 1 / 2 / 3 err"]
        headers = ["series", VALUE_NAMES[axis], "pass"] + [c[0] for c in cols] + ["step s / sim s", "wall s", "failure"]
        lines += [f"## {AXIS_TITLES[axis]}", "", "| " + " | ".join(headers) + " |",
                  "|" + "|".join(["---"] * len(headers)) + "|"]
        for r in rows:
            cells = [r["series"], str(r["value"]), "PASS" if r.get("passed") else "FAIL"]
            for _, get in cols:
                try:
                    cells.append(get(r))
                except (KeyError, TypeError, IndexError):
                    cells.append("-")
            cells += [fmt(r.get("wall_per_simulated_s")), f"{r['process_wall_s']:.1f}",
                      (r.get("failure") or "").replace("|", "/")]
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines).rstrip() + "\n"


def machine_info() -> dict:
    from simbake import _core
    model = platform.processor() or "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"platform": platform.platform(), "cpu_model": model, "logical_cpus": os.cpu_count(),
            "allowed_cpus": sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else [],
            "load_average_1_5_15_min": list(os.getloadavg()), "python": sys.version.split()[0],
            "numpy": np.__version__, "simbake_version": _core.__version__,
            "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("axes", nargs="*", help=f"axes to run (default all): {', '.join(CASES)}")
    parser.add_argument("--case", nargs=2, metavar=("AXIS", "ARGS_JSON"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.case:
        child(*args.case)
        return
    axes = args.axes or list(CASES)
    unknown = set(axes) - set(CASES)
    if unknown:
        parser.error(f"unknown axes: {', '.join(sorted(unknown))}")
    start = time.perf_counter()
    records = []
    for axis, cases in plan().items():
        if axis not in axes:
            continue
        for case in cases:
            r = run_case(axis, case)
            records.append(r)
            print(f"{axis:10s} {r['series']:34s} {str(r['value']):>8s}  {'PASS' if r.get('passed') else 'FAIL'}"
                  f"  {r['process_wall_s']:5.1f} s  {r.get('failure', '')}", flush=True)
    total = time.perf_counter() - start
    breaks = breaking_points(records)
    info = machine_info()
    RESULTS_DIR.mkdir(parents=True, exist_ok=True)
    payload = {"benchmark": "stress", "machine": info, "run_wall_s": total, "timeout_s": TIMEOUT,
               "threads": THREADS, "fps": FPS, "axes": axes, "breaking_points": breaks, "cases": records}
    (RESULTS_DIR / "stress.json").write_text(json.dumps(payload, indent=2, default=float) + "\n")
    (RESULTS_DIR / "stress.md").write_text(markdown(records, breaks, info, total))
    print("\n" + markdown(records, breaks, info, total))
    print(f"-> {RESULTS_DIR / 'stress'}.{{json,md}}")


if __name__ == "__main__":
    main()
