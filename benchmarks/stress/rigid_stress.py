"""Rigid-body stress run: push each axis until something breaks, and record where.

DESIGN.md ("Fast and accurate"): a stress run that pushes time step, stiffness, mass ratio and
speed until it breaks, recording where. Each axis is a list of series; each series pushes one
value (the brief's values first, then further ones where it still held) and the report gives,
per series, the last passing and the first failing value and how it fails.

- speed        a 0.2 m box and a 0.2 m sphere (1 kg) shot at a 0.1 m thick kinematic wall
               (no gravity, restitution 0.5 on both, friction 0), automatic substeps and a
               fixed 1 substep per frame, 1 ... 30000 m/s. Each speed is shot from 5 distances
               (1 m plus fifths of a frame's travel) so the impact falls at 5 phases of a step.
               Pass (all 5): ends on the near side, moving away (not tunnelled, not stuck in
               the wall), no NaN, rebound speed <= impact speed and kinetic energy (with spin)
               out <= in.
- mass_ratio   1 kg 0.5 m boxes under heavy ones (1 ... 1e6 kg), 5 s, automatic substeps:
               resting aligned (the brief's case); offset 0.1 m and turned 15 degrees; dropped
               0.2 m (judged after 1 s); a column of six alternating 1 kg / heavy. Pass: drift
               from the resting positions < 5 mm, penetration < 2 mm (the engine's, and
               measured geometrically at the end), no NaN.
- stack        aligned towers of 5 ... 40 unit boxes (1 m, 1 kg), 10 s, automatic substeps at
               the default max_substep 1/240, at 1/120 (the brief's two), at 1/480, and at
               the default with every box pre-loaded (sunk 0.1 mm, within the 0.2 mm slop,
               into the one below: already in contact at the start). Pass: no box ever
               drifts 10 mm from its start, no NaN.
- substeps     fixed 8, 4, 2, 1 substeps per frame at 24 fps: the 10-box tower (10 s, as
               above) and a bouncing sphere (r 0.1 m, e 0.5, 1 kg, dropped from 1 m; apexes
               0.25, 0.0625, 0.015625 m; ballistic apex of the last rising substep). Pass:
               apex 1 error < 10% (the brief), and a stricter series with apexes 1-3.
- body_count   piles of 100 ... 3000 0.5 m boxes (125 kg) in layers of side x side on a 0.8 m
               grid (side = ceil(1.3 n^(1/3))), each tilted about a random axis by up to 20
               degrees (seed 1), 3 s, automatic substeps, on 1 thread and on all cores.
               Recorded: stepping wall s per simulated s, ru_maxrss of the case's process
               (after stepping) and its growth over the process before the world was built,
               max penetration (the engine's, per frame; geometric at the end), NaN. Pass: no
               NaN and done within the timeout.
- thin         the torus (assets/meshes/torus.obj, density 600, the pipeline's automatic voxel
               size 12.5 mm and samples) over a kinematic post 1 m tall and 0.06, 0.03,
               0.015 m wide, 4 s: "centred" (small tilt and offset, like
               assets/scenes/ring_toss), "slide" (off centre, pushed 0.6 m/s: comes to lean on
               the post) and "strike" (pushed 1.5 m/s: the tube hits the post's side). Pass: the
               ring ends threaded on the post (the post's axis crosses the ring's plane inside
               the hole, below the top), penetration < 5 mm, no NaN.
- overlap      two 0.5 m boxes (10 kg) starting overlapped by 10, 25, 40, 50% of their size:
               side by side on the ground, one sunk into the other on the ground, floating
               without gravity. Pass: separated at 3 s (geometric penetration < 2 mm), max
               speed after 1 s < 2 m/s, no NaN.

Penetration is reported two ways. "engine" is statistics()["max_penetration"]: the engine's
own samples inside another body's level set, over the pairs of the last broad phase (so it
reads 0 for bodies that are asleep). "geometric" is measured here from the poses alone, at
points denser than the engine's samples (box_mesh(size, 6) for boxes; points 2.5 mm apart on
the post's surface against the ring's level set, and the ring's vertices against the post),
for every pair, asleep or not: it is what a viewer of the cache would see.

Every case runs in its own process with a 60 s timeout: a hang or a crash is a failure, and
the progress the case reported before it (simulated time reached) is kept. All stepping
happens in the C++ core (`World.step_frame`, or `World.step` for the bounce apexes); the
narrow phase runs on one thread except in the "all cores" body-count series.

    .venv/bin/python benchmarks/stress/rigid_stress.py              # all axes (~4 min)
    .venv/bin/python benchmarks/stress/rigid_stress.py speed thin   # some axes again: they
                                      # replace those axes in stress.json, the others are kept

Writes benchmarks/results/stress.json (every number, per case and per phase) and stress.md
(the breaking points and a table per axis).
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import resource
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import common  # machine info

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
    return w.add_body(shape=_core.LevelSet.box(size), samples=_core.box_mesh(size, BOX_SUBDIVISIONS)[0],
                      mass_properties=_core.box_mass_properties(size), mass=float(mass),
                      origin=np.asarray(origin, dtype=float), orientation=np.asarray(orientation, dtype=float),
                      **kwargs)


def add_sphere(w, radius, mass, origin, **kwargs) -> int:
    from simbake import _core
    return w.add_body(shape=_core.LevelSet.sphere(radius),
                      samples=_core.sphere_mesh(radius, SPHERE_SUBDIVISIONS)[0],
                      mass_properties=_core.sphere_mass_properties(radius), mass=float(mass),
                      origin=np.asarray(origin, dtype=float), orientation=IDENTITY, **kwargs)


def positions(w) -> np.ndarray:
    return np.asarray(w.mesh_poses()[0])


def velocities(w, bodies) -> np.ndarray:
    return w.body_states()["linear_velocity"][list(bodies)]


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


def box_penetration(w, size: float, bodies=None, ground: float | None = 0.0, subdivisions: int = 6,
                    chunk: int = 2000) -> float:
    """Deepest point of any box inside another box (or below the ground), measured here from
    the poses alone: every pair whose bounding spheres overlap, both ways, at points of a
    box_mesh(size, 6) (denser than the engine's samples, so a corner between samples counts).
    Unlike statistics()["max_penetration"] it also sees bodies that are asleep."""
    from simbake import _core
    pts = _core.box_mesh(np.array([size] * 3), subdivisions)[0]
    shape = _core.LevelSet.box(np.array([size] * 3))
    t, q = w.mesh_poses()
    bodies = np.arange(len(t)) if bodies is None else np.asarray(bodies)
    t = np.asarray(t)[bodies]
    r = np.array([quat_to_matrix(x) for x in np.asarray(q)[bodies]])
    world_pts = np.einsum("kj,pij->pki", pts, r) + t[:, None, :]  # (bodies, k, 3)
    deepest = 0.0
    if ground is not None:
        deepest = max(deepest, float(ground - world_pts[..., 1].min()))
    reach = math.sqrt(3.0) * size
    # candidate pairs by a uniform grid of cell `reach`
    cells: dict = {}
    for i, c in enumerate(np.floor(t / reach).astype(int)):
        cells.setdefault(tuple(c), []).append(i)
    pairs = []
    for c, members in cells.items():
        near = [j for dx in (-1, 0, 1) for dy in (-1, 0, 1) for dz in (-1, 0, 1)
                for j in cells.get((c[0] + dx, c[1] + dy, c[2] + dz), [])]
        for i in members:
            pairs += [(i, j) for j in near if j != i and np.linalg.norm(t[i] - t[j]) < reach]
    pairs = np.array(pairs, dtype=int).reshape(-1, 2)
    for start in range(0, len(pairs), chunk):
        a, b = pairs[start:start + chunk, 0], pairs[start:start + chunk, 1]
        local = np.einsum("pki,pij->pkj", world_pts[a] - t[b][:, None, :], r[b])
        deepest = max(deepest, float(-shape.phi(local.reshape(-1, 3)).min()))
    return max(deepest, 0.0)


class Stepper:
    """Steps frames, times only the stepping, tracks NaN, penetration and substeps."""

    def __init__(self, w, substeps: int = 0):
        self.w, self.substeps = w, substeps
        self.wall = 0.0
        self.cpu = 0.0  # process CPU time of the stepping (all threads)
        self.frames = 0
        self.substep_counts: list[int] = []
        self.max_penetration = 0.0
        self.finite = True
        self.last_report = time.perf_counter()

    def frame(self) -> bool:
        start, start_cpu = time.perf_counter(), time.process_time()
        n = self.w.step_frame(FRAME_DT, self.substeps)
        self.wall += time.perf_counter() - start
        self.cpu += time.process_time() - start_cpu
        self.frames += 1
        self.substep_counts.append(int(n))
        stats = self.w.statistics()
        pen = stats["max_penetration"]
        if np.isfinite(pen):
            self.max_penetration = max(self.max_penetration, pen)
        self.finite = self.finite and all_finite(self.w)
        if time.perf_counter() - self.last_report > 2.0:
            self.last_report = time.perf_counter()
            progress(simulated_s=self.frames * FRAME_DT, stepping_wall_s=self.wall, stepping_cpu_s=self.cpu,
                     maxrss_mb=maxrss_mb(), max_penetration=self.max_penetration, finite=self.finite)
        return self.finite

    def summary(self) -> dict:
        counts = self.substep_counts or [0]
        return {"simulated_s": self.frames * FRAME_DT, "stepping_wall_s": self.wall,
                "wall_per_simulated_s": self.wall / max(self.frames * FRAME_DT, 1e-12),
                "stepping_cpu_s": self.cpu, "cpu_per_simulated_s": self.cpu / max(self.frames * FRAME_DT, 1e-12),
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
    state = common.body_state(w, body)
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


def case_mass_ratio(heavy: float, layout: str) -> dict:
    """1 kg 0.5 m boxes under heavy ones. Layouts: "aligned" (the heavy box resting exactly on
    the light one), "offset" (shifted 0.1 m and turned 15 degrees about y), "dropped" (falls
    0.2 m onto it), "alternating" (a column of six: 1 kg, heavy, 1 kg, ...). Drift is measured
    from the resting positions: over the whole run, and for "dropped" at the end."""
    w = world()
    w.set_ground(height=0.0, friction=0.5, restitution=0.0)
    size = 0.5
    turn = quat_axis_angle([0.0, 1.0, 0.0], math.radians(15.0))
    if layout == "alternating":
        rest = np.array([[0.0, size / 2 + size * i, 0.0] for i in range(6)])
        for i, o in enumerate(rest):
            add_box(w, [size] * 3, 1.0 if i % 2 == 0 else heavy, o)
    else:
        dx = 0.1 if layout == "offset" else 0.0
        rest = np.array([[0.0, size / 2, 0.0], [dx, 1.5 * size, 0.0]])
        add_box(w, [size] * 3, 1.0, rest[0])
        add_box(w, [size] * 3, heavy, rest[1] + [0.0, 0.2 if layout == "dropped" else 0.0, 0.0],
                turn if layout == "offset" else IDENTITY)
    s = Stepper(w)
    drift = np.zeros(len(rest))
    settled_penetration = 0.0
    for _ in range(5 * FPS):
        if not s.frame():
            break
        if layout != "dropped" or s.frames * FRAME_DT > 1.0:
            drift = np.maximum(drift, np.linalg.norm(positions(w) - rest, axis=1))
            settled_penetration = max(settled_penetration, w.statistics()["max_penetration"])
    end = positions(w) - rest
    geometric = box_penetration(w, size)
    penetration = max(settled_penetration, geometric)
    failures = []
    if not s.finite:
        failures.append("NaN")
    if drift.max() >= 5e-3:
        failures.append(f"drift {1e3 * drift.max():.3g} mm")
    if penetration >= 2e-3:
        failures.append(f"penetration {1e3 * penetration:.3g} mm")
    return dict(s.summary(), passed=not failures, failure="; ".join(failures),
                max_drift=float(drift.max()), drift_per_box=drift.tolist(),
                final_sink_light=float(-end[0, 1]), final_sink_heavy=float(-end[1, 1]),
                final_horizontal=float(np.abs(end[:, [0, 2]]).max()),
                settled_penetration=settled_penetration, geometric_penetration_end=geometric,
                sleeping_at_end=int(w.sleeping_count))


# --- towers (stack height and substep size) ----------------------------------------------

DRIFT_LIMIT_TOWER = 10e-3


def tower(boxes: int, seconds: float, substeps: int = 0, max_substep: float | None = None,
          preload: float = 0.0) -> dict:
    """A column of 1 m boxes, each resting exactly on the one below (or sunk `preload` m into
    it: already in contact, within the engine's 0.2 mm penetration slop)."""
    settings = {} if max_substep is None else {"max_substep": max_substep}
    w = world(**settings)
    w.set_ground(height=0.0, friction=0.5, restitution=0.0)
    for i in range(boxes):
        add_box(w, [1.0, 1.0, 1.0], 1.0, [0.0, 0.5 + i * (1.0 - preload) - preload, 0.0])
    start = positions(w)
    s = Stepper(w, substeps)
    drift = np.zeros(boxes)
    first_frame, fail_time, peak_rise, peak_tilt = None, None, 0.0, 0.0
    for _ in range(int(round(seconds * FPS))):
        if not s.frame():
            break
        d = positions(w) - start
        drift = np.maximum(drift, np.linalg.norm(d, axis=1))
        peak_rise = max(peak_rise, float(d[:, 1].max()))
        q = np.asarray(w.mesh_poses()[1])
        peak_tilt = max(peak_tilt, float(np.degrees(2 * np.arccos(np.clip(np.abs(q[:, 0]), 0, 1))).max()))
        if first_frame is None:
            first_frame = {"top_sink": float(-d[-1, 1]), "max_penetration": w.statistics()["max_penetration"]}
        if fail_time is None and drift.max() >= DRIFT_LIMIT_TOWER:
            fail_time = s.frames * FRAME_DT
    end = positions(w) - start
    geometric = box_penetration(w, 1.0)
    failures = []
    if not s.finite:
        failures.append("NaN")
    if drift.max() >= DRIFT_LIMIT_TOWER:
        top = end[-1]
        collapsed = float(np.hypot(top[0], top[2])) > 0.5 or top[1] < -0.5
        failures.append(f"{'collapsed' if collapsed else 'drift'} {1e3 * drift.max():.3g} mm, from t = {fail_time:.3g} s "
                        f"(top box ends at dx {1e3 * top[0]:.3g}, dy {1e3 * top[1]:.3g}, dz {1e3 * top[2]:.3g} mm)")
    return dict(s.summary(), passed=not failures, failure="; ".join(failures),
                max_drift=float(drift.max()), worst_box=int(np.argmax(drift)), drift_exceeded_at_s=fail_time,
                first_frame=first_frame, peak_rise=peak_rise, peak_tilt_deg=peak_tilt,
                top_final_offset=end[-1].tolist(), top_final_sink=float(-end[-1, 1]),
                top_final_horizontal=float(np.hypot(end[-1, 0], end[-1, 2])),
                sleeping_at_end=int(w.sleeping_count), geometric_penetration_end=geometric,
                final_penetration=float(w.statistics()["max_penetration"]))


def case_stack(boxes: int, max_substep: float | None, preload: float = 0.0) -> dict:
    return tower(boxes, 10.0, 0, max_substep, preload)


# --- bouncing sphere ----------------------------------------------------------------------

BOUNCE_R = 0.1
BOUNCE_H0 = 1.0
BOUNCE_E = 0.5
G = 9.81


def case_bounce(substeps: int, apexes_judged: int = 1) -> dict:
    """The ballistic apex (y + v^2 / 2g of the last rising state) after each bounce, stepping
    substep by substep with World.step (the same dt as step_frame(1/24, substeps))."""
    w = world()
    w.set_ground(height=0.0, friction=0.0, restitution=0.0)
    body = add_sphere(w, BOUNCE_R, 1.0, [0.0, BOUNCE_R + BOUNCE_H0, 0.0], restitution=BOUNCE_E, friction=0.0)
    dt = FRAME_DT / substeps
    steps = int(round(1.25 / dt))  # past the third apex
    apexes, finite, max_pen, lowest = [], True, 0.0, float("inf")
    prev_vy, prev_apex = 0.0, None
    start = time.perf_counter()
    for k in range(steps):
        w.step(dt)
        st = common.body_state(w, body)
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
    else:
        for k, (apex, err) in enumerate(list(zip(apexes, errors))[:apexes_judged]):
            if abs(err) >= 0.10:
                failures.append(f"apex {k + 1} {apex:.4g} m, error {100 * err:+.3g}%")
        if len(errors) < apexes_judged:
            failures.append(f"only {len(errors)} apexes")
    return dict(passed=not failures, failure="; ".join(failures), apexes=apexes, reference=reference,
                relative_errors=errors, first_apex_error=errors[0] if errors else float("nan"),
                lowest_bottom=lowest, max_penetration=max(0.0, -lowest), finite=finite,
                stepping_wall_s=wall, simulated_s=steps * dt, wall_per_simulated_s=wall / (steps * dt),
                substeps_per_frame_mean=float(substeps))


def case_substeps(problem: str, substeps: int) -> dict:
    if problem == "tower10":
        return tower(10, 10.0, substeps)
    return case_bounce(substeps, 3 if problem == "bounce3" else 1)


# --- body count ---------------------------------------------------------------------------


def pile_layout(count: int, seed: int = 1):
    """Layers of side x side boxes on a 0.8 m grid, side = ceil(1.3 count^(1/3)); each box
    tilted about a random axis by up to 20 degrees."""
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


def case_body_count(count: int, threads: int = THREADS) -> dict:
    from simbake import _core  # noqa: F401  (loaded before the baseline: the world's own growth is what counts)
    base_rss = maxrss_mb()
    progress(stage="start", maxrss_mb=base_rss)
    w = world(threads=threads)
    w.set_ground(height=0.0, friction=0.5, restitution=0.0)
    origins, orientations, side = pile_layout(count)
    for o, q in zip(origins, orientations):
        add_box(w, [0.5] * 3, 125.0, o, q)
    initial = box_penetration(w, 0.5)
    built_rss = maxrss_mb()
    progress(stage="built", maxrss_mb=built_rss)
    s = Stepper(w)
    for _ in range(3 * FPS):
        if not s.frame():
            break
    stepped_rss = maxrss_mb()  # before the measurements below allocate anything
    max_speed_end = float(np.linalg.norm(velocities(w, range(count)), axis=1).max()) if s.finite else float("nan")
    geometric = box_penetration(w, 0.5) if s.finite else float("nan")
    failures = []
    if not s.finite:
        failures.append("NaN")
    return dict(s.summary(), passed=not failures, failure="; ".join(failures), threads=threads,
                footprint=f"{side}x{side}", layers=int(math.ceil(count / side ** 2)),
                initial_overlap=initial, maxrss_before_world_mb=base_rss, maxrss_after_build_mb=built_rss,
                maxrss_after_stepping_mb=stepped_rss,
                world_memory_mb=stepped_rss - base_rss, geometric_penetration_end=geometric,
                final_penetration=float(w.statistics()["max_penetration"]),
                max_speed_at_end=max_speed_end, sleeping_at_end=int(w.sleeping_count),
                impulses=int(w.statistics()["impulses"]), profile=w.profile())


# --- thin features ------------------------------------------------------------------------

HOLE_RADIUS = 0.2  # torus.obj: tube radius 0.1 around a ring of radius 0.3 about y
POST_HEIGHT = 1.0


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


def post_surface_points(width: float, spacing: float = 0.0025) -> np.ndarray:
    """Points on the post's four sides and top, `spacing` apart vertically, 9 across a side."""
    across = np.linspace(-width / 2, width / 2, 9)
    pts = []
    for y in np.arange(0.0, POST_HEIGHT + 1e-9, spacing):
        for a in across:
            pts += [[a, y, -width / 2], [a, y, width / 2], [-width / 2, y, a], [width / 2, y, a]]
    pts += [[a, POST_HEIGHT, b] for a in across for b in across]
    return np.array(pts)


DROPS = {  # origin of the ring, its tilt (axis, degrees) and its push
    "centred": ([0.02, 1.4, -0.01], [1.0, 0.0, 0.5], 8.0, [0.0, 0.0, 0.0]),   # like assets/scenes/ring_toss
    "slide": ([-0.12, 1.4, 0.03], [0.2, 0.0, 1.0], 15.0, [0.6, 0.0, 0.0]),   # ends leaning on the post
    "strike": ([-0.12, 1.25, 0.03], [0.2, 0.0, 1.0], 15.0, [1.5, 0.0, 0.0]),  # tube hits the post's side
}


def case_thin(width: float, drop: str) -> dict:
    """The ring over a kinematic post. Penetration is measured two ways: the engine's (its
    samples inside the other body's level set) and geometrically here (points 2.5 mm apart
    on the post's surface inside the ring's level set, and the ring's vertices inside the post)."""
    from simbake import _core
    v, t, voxel, samples, props = load_torus()
    bake_start = time.perf_counter()
    level_set = _core.LevelSet.bake(v, t, voxel)
    bake_s = time.perf_counter() - bake_start
    w = world()
    w.set_ground(height=0.0, friction=0.5, restitution=0.0)
    add_box(w, [width, POST_HEIGHT, width], 1.0, [0.0, POST_HEIGHT / 2, 0.0], kinematic=True)
    origin, axis, degrees, vel = DROPS[drop]
    mass = 600.0 * props["volume"]
    ring = w.add_body(shape=level_set, samples=samples, mass_properties=props, mass=mass,
                      origin=np.array(origin), orientation=quat_axis_angle(axis, math.radians(degrees)),
                      linear_velocity=np.array(vel, dtype=float), friction=0.4)
    post_pts = post_surface_points(width)
    post_shape = _core.LevelSet.box(np.array([width, POST_HEIGHT, width]))
    s = Stepper(w)
    geometric, geometric_at, threaded_frames, missed_at = 0.0, None, 0, None
    for _ in range(4 * FPS):
        if not s.frame():
            break
        tr, qs = w.mesh_poses()
        r, c = quat_to_matrix(qs[ring]), np.asarray(tr[ring])
        post_in_ring = -float(level_set.phi((post_pts - c) @ r).min())
        ring_in_post = -float(post_shape.phi(v @ r.T + c - [0.0, POST_HEIGHT / 2, 0.0]).min())
        depth = max(post_in_ring, ring_in_post, 0.0)
        if depth > geometric:
            geometric, geometric_at = depth, s.frames * FRAME_DT
    tr, qs = w.mesh_poses()
    on_post, rho, cross_y = threaded_on_post(tr[ring], qs[ring], (0.0, 0.0), POST_HEIGHT)
    penetration = max(s.max_penetration, geometric)
    failures = []
    if not s.finite:
        failures.append("NaN")
    elif not on_post:
        failures.append(f"ring off the post (post axis {rho:.3g} m from the ring axis, crossing at y {cross_y:.3g} m)")
    if penetration >= 5e-3:
        failures.append(f"penetration {1e3 * penetration:.3g} mm at t {geometric_at:.3g} s (engine saw "
                        f"{1e3 * s.max_penetration:.3g} mm)")
    return dict(s.summary(), passed=not failures, failure="; ".join(failures), voxel_size=voxel,
                torus_samples=int(len(samples)), bake_s=bake_s, ring_mass=mass, post_axis_from_ring_axis=rho,
                crossing_height=cross_y, ring_final=np.asarray(tr[ring]).tolist(),
                geometric_penetration=geometric, geometric_penetration_at_s=geometric_at,
                engine_max_penetration=s.max_penetration,
                final_penetration=float(w.statistics()["max_penetration"]))


# --- deep initial overlap -----------------------------------------------------------------


def case_overlap(layout: str, fraction: float) -> dict:
    """Two 0.5 m boxes, 10 kg each, starting overlapped by `fraction` of their size:
    side by side on the ground, one sunk into the other on the ground, or floating (no
    gravity). Separation is checked geometrically (box_penetration), since the engine's
    statistic skips sleeping bodies."""
    size = 0.5
    depth = fraction * size
    if layout == "floating":
        w = world(gravity=np.zeros(3))
        a, b = [-(size - depth) / 2, 1.0, 0.0], [(size - depth) / 2, 1.0, 0.0]
    else:
        w = world()
        w.set_ground(height=0.0, friction=0.5, restitution=0.0)
        if layout == "side":
            a, b = [-(size - depth) / 2, size / 2, 0.0], [(size - depth) / 2, size / 2, 0.0]
        else:  # "stacked": the upper box sunk into the lower one
            a, b = [0.0, size / 2, 0.0], [0.0, 1.5 * size - depth, 0.0]
    add_box(w, [size] * 3, 10.0, a)
    add_box(w, [size] * 3, 10.0, b)
    initial = box_penetration(w, size, ground=None)
    start = positions(w)
    s = Stepper(w)
    peak_first, peak_after, spin_after, separated_at = 0.0, 0.0, 0.0, None
    for _ in range(3 * FPS):
        if not s.frame():
            break
        speed = float(np.linalg.norm(velocities(w, [0, 1]), axis=1).max())
        spin = max(float(np.linalg.norm(common.body_state(w, i)["angular_velocity"])) for i in (0, 1))
        if s.frames * FRAME_DT <= 1.0 + 1e-9:
            peak_first = max(peak_first, speed)
        else:
            peak_after = max(peak_after, speed)
            spin_after = max(spin_after, spin)
        if separated_at is None and s.finite and box_penetration(w, size, ground=None) < 2e-3:
            separated_at = s.frames * FRAME_DT
    end = positions(w)
    final = box_penetration(w, size, ground=None) if s.finite else float("nan")
    failures = []
    if not s.finite:
        failures.append("NaN")
    else:
        if peak_after >= 2.0:
            failures.append(f"max speed after 1 s {peak_after:.3g} m/s")
        if final >= 2e-3:
            failures.append(f"still overlapped at 3 s by {1e3 * final:.3g} mm (engine reports "
                            f"{1e3 * w.statistics()['max_penetration']:.3g} mm; {w.sleeping_count} asleep)")
    return dict(s.summary(), passed=not failures, failure="; ".join(failures), initial_overlap=initial,
                peak_speed_first_s=peak_first, max_speed_after_1s=peak_after, max_spin_after_1s=spin_after,
                separated_at_s=separated_at, geometric_penetration_end=final,
                final_penetration=float(w.statistics()["max_penetration"]), sleeping_at_end=int(w.sleeping_count),
                centre_distance_start=float(np.linalg.norm(start[1] - start[0])),
                centre_distance_end=float(np.linalg.norm(end[1] - end[0])), final_positions=end.tolist())


CASES = {"speed": case_speed, "mass_ratio": case_mass_ratio, "stack": case_stack,
         "substeps": case_substeps, "body_count": case_body_count, "thin": case_thin,
         "overlap": case_overlap}


# =======================================================================================
# the plan (which cases, in which order) and the parent process


def plan() -> dict[str, list[dict]]:
    """axis -> cases; each case: series (the line along which the value is pushed), value,
    and args for its function. The brief's values first, then further ones where it held."""
    p: dict[str, list[dict]] = {}
    p["speed"] = [{"series": f"{shape}, {'auto substeps' if n == 0 else '1 substep/frame'}", "value": v,
                   "args": [shape, v, n]}
                  for shape in ("box", "sphere") for n in (0, 1)
                  for v in (1, 3, 10, 30, 100, 300, 1000, 3000, 10000, 30000)]
    p["mass_ratio"] = [{"series": label, "value": m, "args": [m, layout]}
                       for layout, label in (("aligned", "1 kg under heavy, aligned"),
                                             ("offset", "1 kg under heavy, offset 0.1 m, turned 15 deg"),
                                             ("dropped", "heavy dropped 0.2 m onto 1 kg"),
                                             ("alternating", "column of 6, 1 kg / heavy alternating"))
                       for m in (1, 10, 100, 1000, 10000, 100000, 1000000)]
    p["stack"] = [{"series": label, "value": n, "args": [n, ms, preload]}
                  for label, ms, preload in (("default (max_substep 1/240)", None, 0.0),
                                             ("max_substep 1/120", 1.0 / 120.0, 0.0),
                                             ("max_substep 1/480", 1.0 / 480.0, 0.0),
                                             ("default, pre-loaded: each box sunk 0.1 mm", None, 1e-4))
                  for n in (5, 10, 15, 20, 30, 40)]
    p["substeps"] = [{"series": label, "value": n, "args": [problem, n]}
                     for problem, label in (("tower10", "10-box tower, 10 s"), ("bounce", "bouncing sphere, apex 1"),
                                            ("bounce3", "bouncing sphere, apexes 1-3"))
                     for n in (8, 4, 2, 1)]
    p["body_count"] = [{"series": f"pile of 0.5 m boxes, 3 s, {label}", "value": n, "args": [n, threads]}
                       for threads, label in ((1, "1 thread"), (0, "all cores"))
                       for n in (100, 300, 1000, 3000)]
    p["thin"] = [{"series": f"torus, {drop} drop", "value": width, "args": [width, drop]}
                 for drop in DROPS for width in (0.06, 0.03, 0.015)]
    p["overlap"] = [{"series": f"{layout}", "value": f"{round(100 * f)}%", "args": [layout, f]}
                    for layout in ("side", "stacked", "floating") for f in (0.1, 0.25, 0.4, 0.5)]
    return p


def run_case(axis: str, case: dict) -> dict:
    """The case in a child process with a timeout; its rusage from wait4."""
    load_before = list(os.getloadavg())
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
              "process_cpu_s": usage.ru_utime + usage.ru_stime, "exit_code": proc.returncode,
              "load_average_before": load_before,
              "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}
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
                if "stepping_cpu_s" in last:
                    record["cpu_per_simulated_s"] = last["stepping_cpu_s"] / max(last["simulated_s"], 1e-12)
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
    "speed": "Speed: 0.2 m box / sphere shot at a 0.1 m kinematic wall (e 0.5, no gravity), 5 impact phases",
    "mass_ratio": "Mass ratio: 1 kg 0.5 m boxes under heavy ones, 5 s, automatic substeps",
    "stack": "Stack height: aligned towers of 1 m boxes (1 kg), 10 s, automatic substeps",
    "substeps": "Substep size: fixed substeps per frame at 24 fps",
    "body_count": "Body count: piles of 0.5 m boxes (0.8 m grid, tilt <= 20 deg, seed 1), 3 s, automatic substeps",
    "thin": "Thin features: torus (hole radius 0.2 m, tube 0.2 m, 34 kg) over a 1 m kinematic post, 4 s",
    "overlap": "Deep initial overlap: two 0.5 m boxes, 10 kg each, 3 s",
}

VALUE_NAMES = {"speed": "speed (m/s)", "mass_ratio": "heavy mass (kg)", "stack": "boxes",
               "substeps": "substeps/frame", "body_count": "boxes", "thin": "post width (m)",
               "overlap": "overlap"}


def columns(axis: str) -> list[tuple[str, callable]]:
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
                ("engine pen (mm)", lambda r: mm(r.get("settled_penetration"))),
                ("end pen, geometric (mm)", lambda r: mm(r.get("geometric_penetration_end"))),
                ("substeps/frame", lambda r: fmt(r.get("substeps_per_frame_mean")))]
    if axis == "stack" or axis == "substeps":
        cols = [("max drift (mm)", lambda r: mm(r.get("max_drift"))),
                ("exceeded at (s)", lambda r: fmt(r.get("drift_exceeded_at_s"))),
                ("frame 1 top sink (mm)", lambda r: mm(r["first_frame"]["top_sink"]) if r.get("first_frame") else "-"),
                ("peak rise (mm)", lambda r: mm(r.get("peak_rise"))),
                ("peak tilt (deg)", lambda r: fmt(r.get("peak_tilt_deg"))),
                ("top end dx/dy/dz (mm)", lambda r: "/".join(f"{1e3 * x:.3g}" for x in r["top_final_offset"])
                 if r.get("top_final_offset") else "-"),
                ("engine max pen (mm)", lambda r: mm(r.get("max_penetration"))),
                ("substeps/frame", lambda r: fmt(r.get("substeps_per_frame_mean")))]
        if axis == "substeps":
            cols.insert(0, ("apex 1 / 2 / 3 err", lambda r: " / ".join(pct(e) for e in r["relative_errors"][:3])
                            if r.get("relative_errors") else "-"))
        return cols
    if axis == "body_count":
        return [("sim s reached", lambda r: fmt(r.get("simulated_s"))),
                ("step CPU s / sim s", lambda r: fmt(r.get("cpu_per_simulated_s"))),
                ("maxrss: process / world (MB)", lambda r: f"{fmt(r.get('maxrss_after_stepping_mb', r.get('maxrss_mb')), 4)}"
                 f" / {fmt(r.get('world_memory_mb'), 3)}"),
                ("engine max pen (mm)", lambda r: mm(r.get("max_penetration"))),
                ("end pen, geometric (mm)", lambda r: mm(r.get("geometric_penetration_end"))),
                ("NaN", lambda r: "-" if r.get("finite") is None else fmt(not r.get("finite"))),
                ("asleep at end", lambda r: fmt(r.get("sleeping_at_end"))),
                ("max speed at end (m/s)", lambda r: fmt(r.get("max_speed_at_end"))),
                ("CPU s / wall s of the process", lambda r: f"{r['process_cpu_s']:.1f} / {r['process_wall_s']:.1f}"),
                ("load avg before", lambda r: fmt(r["load_average_before"][0]) if r.get("load_average_before") else "-")]
    if axis == "thin":
        return [("post axis from ring axis (m)", lambda r: fmt(r.get("post_axis_from_ring_axis"))),
                ("ring centre y (m)", lambda r: fmt(r["ring_final"][1]) if r.get("ring_final") else "-"),
                ("engine max pen (mm)", lambda r: mm(r.get("engine_max_penetration"))),
                ("geometric max pen (mm)", lambda r: mm(r.get("geometric_penetration"))),
                ("substeps/frame mean/max", lambda r: f"{fmt(r.get('substeps_per_frame_mean'))}/"
                 f"{fmt(r.get('substeps_per_frame_max'))}")]
    if axis == "overlap":
        return [("initial depth (mm)", lambda r: mm(r.get("initial_overlap"))),
                ("peak speed 0-1 s (m/s)", lambda r: fmt(r.get("peak_speed_first_s"))),
                ("max speed 1-3 s (m/s)", lambda r: fmt(r.get("max_speed_after_1s"))),
                ("separated at (s)", lambda r: fmt(r.get("separated_at_s"))),
                ("end pen geometric / engine (mm)", lambda r: f"{mm(r.get('geometric_penetration_end'))} / "
                 f"{mm(r.get('final_penetration'))}"),
                ("asleep", lambda r: fmt(r.get("sleeping_at_end")))]
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
             f"narrow phase on {THREADS} thread (all cores in the body-count series so marked), "
             f"load average {', '.join(f'{v:.2f}' for v in info.get('load_average_at_start', []))} at the start and "
             f"{', '.join(f'{v:.2f}' for v in info['load_average_1_5_15_min'])} at the end (2 vCPU, shared: wall "
             "times above the machine's idle figures mean another process had the CPU); the run took "
             f"{total_s:.0f} s (a partial rerun replaces its axes and keeps the others: each case's date and "
             "load average are in the JSON). Each case ran in its own process with a {TIMEOUT:g} s timeout; "
             "`wall s` is the case process's wall time (start-up, building and stepping), "
             "`step s / sim s` the stepping alone per simulated second. Frames are 1/24 s. "
             "Written by `benchmarks/stress/rigid_stress.py` (its docstring has every setup and "
             "pass criterion).", ""]
    library = info.get("core_library")
    if library:
        lines[-2] += (f" Core library `{Path(library['at_end']['path']).name}` built "
                      f"{library['at_end']['modified']} (sha256 {library['at_end']['sha256'][:12]}).")
        if library["changed_during_run"]:
            lines += ["**Warning: the core library was replaced during the run; cases may mix two builds.**", ""]
    lines += ["Penetration: \"engine\" is `statistics()[\"max_penetration\"]` (its own samples, pairs of "
              "the last broad phase, so 0 once bodies sleep); \"geometric\" is measured by the script from "
              "the poses at points denser than the engine's samples, for every pair, asleep or not.", ""]
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


def core_library() -> dict:
    """Which build of simbake._core the cases load (the run notes it if it changed midway)."""
    import hashlib
    from simbake import _core
    path = Path(_core.__file__)
    return {"path": str(path), "sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
            "modified": datetime.datetime.fromtimestamp(path.stat().st_mtime, datetime.timezone.utc)
            .isoformat(timespec="seconds")}


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
    load_at_start = list(os.getloadavg())
    library_at_start = core_library()
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
    json_path = RESULTS_DIR / "stress.json"
    if set(axes) != set(CASES) and json_path.is_file():
        # a partial run replaces its axes in the last full results and keeps the others
        try:
            previous = json.loads(json_path.read_text()).get("cases", [])
        except (OSError, ValueError):
            previous = []
        kept = [r for r in previous if r["axis"] not in axes]
        order = list(CASES)
        records = sorted(kept + records, key=lambda r: order.index(r["axis"]))  # stable within an axis
        axes = sorted({r["axis"] for r in records}, key=order.index)
    breaks = breaking_points(records)
    info = common.machine_info()
    RESULTS_DIR.mkdir(parents=True, exist_ok=True)
    library = {"at_start": library_at_start, "at_end": core_library()}
    library["changed_during_run"] = library["at_start"]["sha256"] != library["at_end"]["sha256"]
    info["core_library"] = library
    info["load_average_at_start"] = load_at_start
    payload = {"benchmark": "stress", "machine": info, "load_average_at_start": load_at_start, "run_wall_s": total, "timeout_s": TIMEOUT,
               "threads": THREADS, "fps": FPS, "axes": axes, "breaking_points": breaks, "cases": records}
    (RESULTS_DIR / "stress.json").write_text(json.dumps(payload, indent=2, default=float) + "\n")
    (RESULTS_DIR / "stress.md").write_text(markdown(records, breaks, info, total))
    print("\n" + markdown(records, breaks, info, total))
    print(f"-> {RESULTS_DIR / 'stress'}.{{json,md}}")


if __name__ == "__main__":
    main()
