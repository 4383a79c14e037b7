"""Cloth stress run: push stiffness, step length, collider speed and triangle quality until
something breaks, and record where.

- stiffness   a 1 m flag (33 x 33, pinned along its top edge, held horizontal and let
              fall) with sheet stiffness 1e3 ... 1e7 N/m, both models, default steps, 2 s.
              Pass: finite; largest strain within 10 % (the limit) + 1 %; the energy
              (kinetic + elastic) never above the gravity work done (no energy from
              nowhere); the CG solve converged (mean iterations below the cap).
- steps       the drape (33 x 33, drape_spec.py) with the cloth's longest step at 1/24 s (one
              cloth step per frame), 1/60, 1/120 (default), 1/240, and with a fixed 1 substep per
              frame for everything. Pass: finite, strain <= 11 %, penetration into the sphere
              or the ground past its surface < 1 mm.
- colliders   a curtain (1 m, 33 x 33, pinned along its top) hit by a keyed kinematic sphere
              (r 0.15 m) crossing it at 1 ... 100 m/s, and a draped cape (as
              assets/scenes/cape_on_mover) on a keyed box spinning at 1 ... 30 rad/s. Pass:
              finite, no vertex inside the collider past its surface at any frame end (1 mm),
              strain <= 11 % (the curtain) / finite (the cape). And a box (0.4 m, a vertical
              edge first, as assets/scenes/box_plow) keyed along the ground through a 1 m sheet
              (21 x 21) lying on it at 0.6 ... 30 m/s. Pass: finite, strain <= 11 %, no cloth
              vertex inside the box past its surface (1 mm), and no edge of the box through a
              cloth triangle at any frame end (crossings.py's segment test, NumPy).
- triangles   a 1 m sheet (17 x 17) draped on the sphere with sliver triangles (one vertex of
              a row pushed to within 1e-3 ... 1e-9 m of its neighbours' line), with tiny
              triangles (a corner refined to 1e-3 ... 1e-5 m edges), and with a zero-area
              triangle. Pass: finite, strain <= 11 %, penetration < 1 mm; the zero-area
              triangle must be refused with a one-line error naming the triangle.

Every case also counts layers through layers at every frame end (benchmarks/cloth/crossings.py,
NumPy, apart from the core): any crossing of two non-adjacent triangles fails the case.

Each case runs in its own process with a 120 s timeout (a hang or crash is a failure).

    .venv/bin/python benchmarks/stress/cloth_stress.py            # all axes (~5 min)
    .venv/bin/python benchmarks/stress/cloth_stress.py steps      # one axis again

Writes benchmarks/results/cloth_stress.{json,md}.
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "benchmarks" / "results"
from benchmarks.cloth import drape_spec as spec
from benchmarks.cloth.crossings import crossing_count, segments_through

FPS = 24
TIMEOUT = 120.0
STRAIN_BOUND = 0.11
PENETRATION_BOUND = 1e-3
IDENTITY = [1.0, 0.0, 0.0, 0.0]


def grid(n: int, size: float, y: float = 0.0):
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="xy")
    x = (i / (n - 1) - 0.5) * size
    z = (j / (n - 1) - 0.5) * size
    v = np.stack([x, np.full_like(x, y, dtype=float), z], -1).reshape(-1, 3).astype(float)
    p00 = (j[:-1, :-1] * n + i[:-1, :-1]).ravel()
    t = np.concatenate([np.stack([p00, p00 + n, p00 + n + 1], -1), np.stack([p00, p00 + n + 1, p00 + 1], -1)])
    return v, t.astype(np.int32)


def add_sphere(world, radius, center, kinematic=True):
    from simbake import _core
    return world.add_body(shape=_core.LevelSet.sphere(radius), samples=_core.sphere_mesh(radius, 4)[0],
                          mass_properties=_core.sphere_mass_properties(radius), mass=1.0,
                          origin=np.array(center, float), orientation=np.array(IDENTITY), friction=0.5,
                          kinematic=kinematic)


def run_frames(world, frames: int, triangles, check=None, substeps: int = 0) -> dict:
    """Steps frame by frame (automatic substeps, or `substeps` a frame); the worst strain,
    penetration and layer crossings (of cloth 0, with these triangles) at frame ends."""
    strain = penetration = 0.0
    crossings, crossing_frame = 0, None
    for frame in range(1, frames + 1):
        world.step_frame(1.0 / FPS, substeps)
        s = world.statistics()
        if not s["finite"]:
            return {"finite": False}
        strain = max(strain, s["max_cloth_strain"])
        penetration = max(penetration, s["cloth_penetration"])
        count = crossing_count(world.cloth_state(0)[0], triangles)
        if count > crossings:
            crossings, crossing_frame = count, frame
        if check:
            check(world)
    s = world.statistics()
    return {"finite": True, "max_strain": strain, "max_penetration": penetration,
            "self_crossings": crossings, "self_crossings_frame": crossing_frame,
            "cloth_steps": s["cloth_steps"], "cg_iterations": s["cloth_solver_iterations"]}


# ---- the cases

def case_stiffness(stiffness: float, model: str) -> dict:
    from simbake import _core
    w = _core.World()
    v, t = grid(33, 1.0, 1.0)
    pinned = list(range(33))  # the row j = 0 (the -z edge)
    w.add_cloth(rest=v, triangles=t, model=model, stretch_stiffness=stiffness, pinned=pinned)
    mass = 0.1 * 1.0
    worst_energy = [0.0]

    def energy(world):
        s = world.statistics()
        drop_work = mass * 9.81 * 1.0  # no vertex falls more than 1 m below its start
        worst_energy[0] = max(worst_energy[0], (s["kinetic_energy"] + s["elastic_energy"]) / drop_work)
    out = run_frames(w, 48, t, energy)
    out["energy_over_work"] = worst_energy[0]
    if not out["finite"]:
        return dict(out, passed=False, failure="NaN")
    mean_iterations = out["cg_iterations"] / max(out["cloth_steps"], 1)
    out["mean_cg_iterations"] = mean_iterations
    failures = []
    if out["max_strain"] > STRAIN_BOUND:
        failures.append(f"strain {out['max_strain']:.3f}")
    if worst_energy[0] > 1.0:
        failures.append(f"energy {worst_energy[0]:.2f} x the work of gravity")
    if mean_iterations > 1900:
        failures.append(f"CG at its cap ({mean_iterations:.0f} iterations a step)")
    if out["self_crossings"]:
        failures.append(f"{out['self_crossings']} layer crossings (frame {out['self_crossings_frame']})")
    return dict(out, passed=not failures, failure="; ".join(failures))


def drape_world(n: int, **settings):
    from simbake import _core
    w = _core.World(**settings)
    w.set_ground(height=0.0, friction=0.5, restitution=0.0)
    add_sphere(w, spec.SPHERE_RADIUS, spec.SPHERE_CENTER)
    v, t = spec.grid(n)
    w.add_cloth(rest=v, triangles=t, stretch_stiffness=spec.STRETCH, friction=spec.FRICTION,
                thickness=spec.THICKNESS)
    return w, t


def case_steps(cloth_step: float, fixed_substeps: int) -> dict:
    w, t = drape_world(33, cloth_max_substep=cloth_step)
    return judge(run_frames(w, 72, t, substeps=fixed_substeps))


def judge(out: dict, strain: bool = True) -> dict:
    if not out["finite"]:
        return dict(out, passed=False, failure="NaN")
    failures = []
    if strain and out["max_strain"] > STRAIN_BOUND:
        failures.append(f"strain {out['max_strain']:.3f}")
    if out["max_penetration"] > PENETRATION_BOUND:
        failures.append(f"penetration {1000 * out['max_penetration']:.1f} mm")
    if out["self_crossings"]:
        failures.append(f"{out['self_crossings']} layer crossings (frame {out['self_crossings_frame']})")
    return dict(out, passed=not failures, failure="; ".join(failures))


def case_curtain(speed: float) -> dict:
    from simbake import _core
    w = _core.World()
    # a curtain in the XY plane at z = 0, top edge pinned at y = 1.5
    n = 33
    v, t = grid(n, 1.0)
    v = np.stack([v[:, 0], 1.0 - v[:, 2], np.zeros(len(v))], -1)
    pinned = [k for k in range(len(v)) if v[k, 1] > 1.5 - 1e-9]
    w.add_cloth(rest=v, triangles=t, pinned=pinned)
    ball = add_sphere(w, 0.15, (0.0, 1.0, -1.0))
    travel = 2.0
    duration = travel / speed
    w.set_kinematic_track(ball, [0.0, duration], np.array([[0.0, 1.0, -1.0], [0.0, 1.0, 1.0]]),
                          np.array([IDENTITY, IDENTITY]))
    frames = max(int(math.ceil(duration * FPS)) + 12, 24)
    return judge(run_frames(w, frames, t))


def case_spinner(spin: float) -> dict:
    from simbake import _core
    w = _core.World()
    w.set_ground(height=0.0, friction=0.5, restitution=0.0)
    size = np.array([0.6, 0.6, 0.6])
    box = w.add_body(shape=_core.LevelSet.box(size), samples=_core.box_mesh(size, 3)[0],
                     mass_properties=_core.box_mass_properties(size), mass=1.0,
                     origin=np.array([0.0, 0.6, 0.0]), orientation=np.array(IDENTITY), friction=0.8,
                     kinematic=True)
    times = np.linspace(0.0, 2.0, 65)
    angles = spin * times
    q = np.stack([np.cos(angles / 2), 0 * angles, np.sin(angles / 2), 0 * angles], -1)
    w.set_kinematic_track(box, list(times), np.tile([0.0, 0.6, 0.0], (len(times), 1)), q)
    v, t = grid(33, 1.4, 1.0)
    w.add_cloth(rest=v, triangles=t, friction=0.8)
    return judge(run_frames(w, 48, t), strain=False)


def box_edges_through(world, box: int, size, points, triangles) -> int:
    """(box edge, cloth triangle) pairs that cross, the box's 12 edges at its pose now."""
    translations, orientations = world.mesh_poses()
    w, x, y, z = orientations[box]
    rotation = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                         [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                         [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    corners = np.array([[a, b, c] for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)]) * 0.5 * np.asarray(size)
    corners = corners @ rotation.T + translations[box]
    pairs = [(i, j) for i in range(8) for j in range(i + 1, 8) if bin(i ^ j).count("1") == 1]
    B = points[triangles]
    count = 0
    for i, j in pairs:
        p, q = np.tile(corners[i], (len(B), 1)), np.tile(corners[j], (len(B), 1))
        count += int(segments_through(p, q, B, np.full(len(B), np.linalg.norm(corners[j] - corners[i]))).sum())
    return count


def case_plow(speed: float) -> dict:
    from simbake import _core
    w = _core.World()
    w.set_ground(height=0.0, friction=0.5, restitution=0.0)
    size = np.array([0.4, 0.4, 0.4])
    turn = [math.cos(math.pi / 8), 0.0, math.sin(math.pi / 8), 0.0]  # 45 degrees about y: an edge first
    box = w.add_body(shape=_core.LevelSet.box(size), samples=_core.box_mesh(size, 3)[0],
                     mass_properties=_core.box_mass_properties(size), mass=1.0,
                     origin=np.array([-0.9, 0.2, 0.0]), orientation=np.array(turn), friction=0.5,
                     kinematic=True)
    duration = 1.8 / speed
    w.set_kinematic_track(box, [0.0, duration], np.array([[-0.9, 0.2, 0.0], [0.9, 0.2, 0.0]]), np.array([turn, turn]))
    v, t = grid(21, 1.0, 0.02)
    w.add_cloth(rest=v, triangles=t, friction=0.5)
    through = [0, None]

    def edges(world):
        count = box_edges_through(world, box, size, world.cloth_state(0)[0], t)
        if count > through[0]:
            through[0] = count
            through[1] = world.time
    out = judge(run_frames(w, int(math.ceil(duration * FPS)) + 12, t, edges))
    out["box_edges_through"] = through[0]
    if through[0]:
        out["passed"] = False
        out["failure"] = "; ".join(filter(None, [out["failure"], f"{through[0]} box edge crossings (t {through[1]:.2f} s)"]))
    return out


def sheet(n: int = 17):
    v, t = grid(n, 1.0, 1.2)
    return v, t


def case_triangles(kind: str, size: float) -> dict:
    from simbake import _core
    v, t = sheet()
    n = 17
    if kind == "sliver":
        # vertex (8, 8) pushed onto the line of (7, 9)-(9, 7) to within `size`: its triangles
        # around that diagonal become slivers
        k = 8 * n + 8
        a, b = v[7 * n + 9], v[9 * n + 7]
        mid = 0.5 * (a + b)
        direction = np.array([1.0, 0.0, 1.0]) / math.sqrt(2.0)
        v[k] = mid + size * direction
    elif kind == "tiny":
        # the corner cell refined: a fan of triangles with edges of `size` around vertex 0
        extra = np.array([[v[0, 0] + size, 1.2, v[0, 2]], [v[0, 0], 1.2, v[0, 2] + size],
                          [v[0, 0] + size, 1.2, v[0, 2] + size]])
        base = len(v)
        v = np.concatenate([v, extra])
        keep = [tri for tri in t.tolist() if 0 not in tri]
        c, r, d, e = 0, 1, n, n + 1   # the corner cell's vertices (0,0), (1,0), (0,1), (1,1)
        x1, x2, x3 = base, base + 1, base + 2
        keep += [[c, x2, x3], [c, x3, x1], [x1, x3, r], [x3, e, r], [x2, d, x3], [x3, d, e]]
        t = np.array(keep, dtype=np.int32)
    elif kind == "zero":
        t = np.concatenate([t, np.array([[0, 1, 2]], dtype=np.int32)])  # collinear along the first row
    w = _core.World()
    w.set_ground(height=0.0, friction=0.5, restitution=0.0)
    add_sphere(w, 0.3, (0.0, 0.3, 0.0))
    try:
        w.add_cloth(rest=v, triangles=t.astype(np.int32))
    except ValueError as error:
        message = str(error)
        one_line = "\n" not in message and "triangle" in message
        return {"finite": True, "refused": message, "passed": kind == "zero" and one_line,
                "failure": "" if kind == "zero" and one_line else f"refused: {message}"}
    if kind == "zero":
        return {"finite": True, "passed": False, "failure": "a zero-area triangle was accepted"}
    return judge(run_frames(w, 48, t))


AXES = {
    "stiffness": [(f"{model}, Y {y:g} N/m", case_stiffness, (y, model))
                  for model in ("springs", "membrane") for y in (1e3, 1e4, 1e5, 1e6, 1e7)],
    "steps": [("cloth step 1/240 s", case_steps, (1 / 240, 0)), ("cloth step 1/120 s (default)", case_steps, (1 / 120, 0)),
              ("cloth step 1/60 s", case_steps, (1 / 60, 0)),
              ("cloth step 1/24 s (one a frame)", case_steps, (1 / 24, 0)),
              ("1 substep a frame, everything", case_steps, (1 / 120, 1))],
    "colliders": [(f"sphere through a curtain at {s:g} m/s", case_curtain, (s,)) for s in (1, 5, 20, 100)]
                 + [(f"cape on a box spinning at {s:g} rad/s", case_spinner, (s,)) for s in (1, 5, 10, 30)]
                 + [(f"box ploughing a sheet at {s:g} m/s", case_plow, (s,)) for s in (0.6, 3, 10, 15, 30)],
    "triangles": [(f"sliver, vertex {d:g} m off the line", case_triangles, ("sliver", d)) for d in (1e-3, 1e-6, 1e-9)]
                 + [(f"tiny triangles, {d:g} m edges", case_triangles, ("tiny", d)) for d in (1e-3, 1e-4, 1e-5)]
                 + [("zero-area triangle", case_triangles, ("zero", 0.0))],
}


def _child(queue, function, args):
    try:
        queue.put(function(*args))
    except Exception as error:  # reported as the case's failure
        queue.put({"passed": False, "failure": f"{type(error).__name__}: {error}"})


def run_case(function, args) -> dict:
    queue = mp.Queue()
    process = mp.Process(target=_child, args=(queue, function, args))
    start = time.perf_counter()
    process.start()
    process.join(TIMEOUT)
    if process.is_alive():
        process.terminate()
        return {"passed": False, "failure": f"timeout ({TIMEOUT:g} s)"}
    out = queue.get() if not queue.empty() else {"passed": False, "failure": f"crashed (exit {process.exitcode})"}
    out["wall_seconds"] = time.perf_counter() - start
    return out


def fmt(value, digits=3):
    return "-" if value is None else f"{value:.{digits}g}"


def write_markdown(results: dict, path: Path) -> None:
    lines = ["# Cloth stress run (`benchmarks/stress/cloth_stress.py`)", "",
             "Cases and pass criteria: the script's docstring. Strain and penetration are the worst",
             "at any frame end.", ""]
    for axis, cases in results.items():
        lines += [f"## {axis}", "", "| case | passed | max strain | max penetration (mm) | layer crossings | CG iterations / step | wall s | failure |",
                  "| --- | --- | --- | --- | --- | --- | --- | --- |"]
        for name, r in cases.items():
            pen = r.get("max_penetration")
            lines.append(f"| {name} | {'yes' if r['passed'] else '**no**'} | {fmt(r.get('max_strain'))} | "
                         f"{fmt(None if pen is None else 1000 * pen)} | {r.get('self_crossings', '-')} | "
                         f"{fmt(r.get('mean_cg_iterations'))} | "
                         f"{fmt(r.get('wall_seconds'), 2)} | {r.get('failure') or r.get('refused', '')} |")
        lines.append("")
    path.write_text("\n".join(lines))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("axes", nargs="*", help=f"some of {', '.join(AXES)} (default: all)")
    args = parser.parse_args()
    unknown = [a for a in args.axes if a not in AXES]
    if unknown:
        parser.error(f"unknown axes {unknown}; choose from {list(AXES)}")
    args.axes = args.axes or list(AXES)
    path = RESULTS / "cloth_stress.json"
    results = json.loads(path.read_text()) if path.exists() else {}
    for axis in args.axes:
        results[axis] = {}
        for name, function, case_args in AXES[axis]:
            r = run_case(function, case_args)
            results[axis][name] = r
            print(f"{axis:10s} {name:45s} {'pass' if r['passed'] else 'FAIL'} {r.get('failure', '')}", flush=True)
            path.write_text(json.dumps(results, indent=1))
    write_markdown(results, RESULTS / "cloth_stress.md")
    print(f"wrote {RESULTS / 'cloth_stress.md'}")


if __name__ == "__main__":
    main()
