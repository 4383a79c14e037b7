"""Scenes of the peer benchmark, shared by every engine script (and compare.py).

Everything here is plain Python plus NumPy (each engine runs in its own venv, with its own
NumPy), and the scenes are built from ``random.Random`` so the pile is bit-identical in every
venv. Conventions:

- SI units, Y up (simbake's frame), gravity 9.81, quaternions [w, x, y, z].
- One material for every pair of a scene: the *pair* friction ``mu`` and restitution ``e``.
  Engines combine the two coefficients of a pair differently (simbake: geometric mean of the
  friction, max of the restitution; PyBullet and Blender: product of both; MuJoCo: max of the
  friction, no restitution coefficient), so each engine script asks :func:`per_object` for
  the coefficient that gives each pair exactly ``mu`` (``e``).
- Z-up engines (PyBullet, MuJoCo, Blender) convert with :func:`to_zup` / :func:`from_zup`:
  a +90 degree rotation about x, (x, y, z)_Y-up -> (x, -z, y)_Z-up.
- Engines only record poses at frame boundaries (outside the clock) and hand them to
  :func:`analyze`, so every engine is measured by the same code.

A scene script prints one JSON line: ``result(...)`` below builds it.
"""

from __future__ import annotations

import hashlib
import json
import math
import random
from dataclasses import dataclass, field

import numpy as np

G = 9.81
FPS = 24                       # frames per second: poses are recorded at frame boundaries
PILE_SEED = 20240601           # the pile's random tilts
PILE_MAX_TILT_DEG = 20.0
INCLINE_DEG = 30.0
DROP_HEIGHT = 1.5              # bottom of the sphere above the ground (m)
DROP_RADIUS = 0.1


@dataclass
class Body:
    shape: str                 # "box" | "sphere"
    size: tuple                # box: full edge lengths (m); sphere: (r, r, r) diameter/2 each
    position: tuple            # centre, Y up (m)
    orientation: tuple = (1.0, 0.0, 0.0, 0.0)  # [w, x, y, z], Y up
    density: float = 1000.0

    @property
    def radius(self) -> float:
        return self.size[0]

    @property
    def volume(self) -> float:
        if self.shape == "sphere":
            return 4.0 / 3.0 * math.pi * self.radius ** 3
        return self.size[0] * self.size[1] * self.size[2]

    @property
    def mass(self) -> float:
        return self.density * self.volume


@dataclass
class Scene:
    name: str
    title: str
    bodies: list
    seconds: float             # simulated time (s)
    mu: float                  # friction of every pair (body-body and body-ground)
    e: float = 0.0             # restitution of every pair
    gravity: tuple = (0.0, -G, 0.0)   # Y up
    ground_height: float = 0.0
    record: str = "all"        # "all" frames, or "ends" (first frame and the last two)
    notes: list = field(default_factory=list)

    @property
    def frames(self) -> int:
        return int(round(self.seconds * FPS))

    def recorded_frames(self) -> list:
        """Frame indices (0 = initial state) whose poses the engine must record."""
        if self.record == "all":
            return list(range(self.frames + 1))
        return sorted({0, max(self.frames - 1, 0), self.frames})


# ---------------------------------------------------------------------------------------
# scene builders


def _tower(seconds):
    bodies = [Body("box", (1.0, 1.0, 1.0), (0.0, 0.5 + i, 0.0)) for i in range(10)]
    return Scene("tower", "tower: 10 unit boxes stacked exactly, mu 0.5", bodies,
                 seconds or 10.0, mu=0.5)


def _quat_axis_angle(axis, angle):
    s = math.sin(0.5 * angle)
    return (math.cos(0.5 * angle), axis[0] * s, axis[1] * s, axis[2] * s)


def _pile(nx, ny, nz, seconds, name, max_tilt_deg=PILE_MAX_TILT_DEG):
    rng = random.Random(PILE_SEED)
    size, spacing, bottom = 0.5, 0.8, 0.5   # the lowest boxes' bottoms start 0.5 m up
    bodies = []
    for j in range(ny):            # layers, bottom up
        for i in range(nx):
            for k in range(nz):
                # uniform random axis, angle uniform in [0, 20] degrees
                z = rng.uniform(-1.0, 1.0)
                phi = rng.uniform(0.0, 2.0 * math.pi)
                r = math.sqrt(max(0.0, 1.0 - z * z))
                axis = (r * math.cos(phi), r * math.sin(phi), z)
                angle = math.radians(rng.uniform(0.0, max_tilt_deg))
                position = ((i - 0.5 * (nx - 1)) * spacing,
                            bottom + 0.5 * size + j * spacing,
                            (k - 0.5 * (nz - 1)) * spacing)
                bodies.append(Body("box", (size, size, size), position, _quat_axis_angle(axis, angle)))
    n = nx * ny * nz
    tilt = f"tilted <= {max_tilt_deg:g} deg" if max_tilt_deg > 0.0 else "aligned"
    return Scene(name, f"pile: {n} boxes 0.5 m, {nx}x{ny}x{nz} grid (0.8 m), {tilt}, mu 0.5",
                 bodies, seconds or 5.0, mu=0.5)


def _pyramid(seconds, rows=15):
    bodies = []
    for r in range(rows):
        count = rows - r
        for c in range(count):
            bodies.append(Body("box", (1.0, 1.0, 1.0), (c - 0.5 * (count - 1), 0.5 + r, 0.0)))
    return Scene("pyramid", f"pyramid: 2D, {rows} rows, {len(bodies)} unit boxes touching, mu 0.5",
                 bodies, seconds or 10.0, mu=0.5)


def _drop(seconds):
    r = DROP_RADIUS
    return Scene("drop", f"sphere drop: r {r}, bottom {DROP_HEIGHT} m up, e 0.5",
                 [Body("sphere", (r, r, r), (0.0, DROP_HEIGHT + r, 0.0))],
                 seconds or 1.5, mu=0.5, e=0.5)


def _incline(mu, seconds, name):
    a = math.radians(INCLINE_DEG)
    return Scene(name, f"incline: 0.5 m box, gravity tilted {INCLINE_DEG:g} deg, mu {mu}",
                 [Body("box", (0.5, 0.5, 0.5), (0.0, 0.25, 0.0))],
                 seconds or (2.0 if mu < math.tan(a) else 3.0), mu=mu,
                 gravity=(G * math.sin(a), -G * math.cos(a), 0.0))


SCENES = {
    "tower": lambda s=None: _tower(s),
    "pile": lambda s=None: _pile(10, 10, 10, s, "pile"),
    "pile216": lambda s=None: _pile(6, 6, 6, s, "pile216"),
    "pile_aligned": lambda s=None: _pile(10, 10, 10, s, "pile_aligned", max_tilt_deg=0.0),
    # the scaling series: the same boxes and spacing on wider grids
    "pile4000": lambda s=None: _pile(20, 10, 20, s, "pile4000"),
    "pile10000": lambda s=None: _pile(25, 10, 40, s, "pile10000"),
    "pyramid": lambda s=None: _pyramid(s),
    "drop": lambda s=None: _drop(s),
    "incline_slide": lambda s=None: _incline(0.5, s, "incline_slide"),
    "incline_stick": lambda s=None: _incline(0.7, s, "incline_stick"),
}


def build(name: str, seconds: float | None = None) -> Scene:
    if name not in SCENES:
        raise SystemExit(f"unknown scene {name!r}; one of {', '.join(SCENES)}")
    return SCENES[name](seconds)


def digest(scene: Scene) -> str:
    """A short hash of the scene's bodies and settings (not its duration): equal in every
    engine's venv, so compare.py can check that every engine ran the same scene."""
    data = [scene.name, scene.mu, scene.e, scene.gravity, scene.ground_height,
            [(b.shape, b.size, b.position, b.orientation, b.density) for b in scene.bodies]]
    return hashlib.sha1(json.dumps(data).encode()).hexdigest()[:12]


# ---------------------------------------------------------------------------------------
# materials and axes


def per_object(pair_value: float, rule: str) -> float:
    """The coefficient to give both objects so their pair gets `pair_value` under `rule`."""
    if rule == "product":
        return math.sqrt(pair_value)
    if rule in ("geometric", "max", "average"):
        return pair_value
    raise ValueError(rule)


_Q_YUP_TO_ZUP = (math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0)   # +90 deg about x


def quat_multiply(a, b):
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw)


def vec_to_zup(v):
    return (v[0], -v[2], v[1])


def vec_from_zup(v):
    return (v[0], v[2], -v[1])


def quat_to_zup(q):
    return quat_multiply(_Q_YUP_TO_ZUP, q)


def quat_from_zup(q):
    w, x, y, z = _Q_YUP_TO_ZUP
    return quat_multiply((w, -x, -y, -z), q)


def orientations_from_zup(q: np.ndarray) -> np.ndarray:
    """(..., 4) Z-up orientations [w, x, y, z] -> Y up (quat_from_zup on each)."""
    q = np.asarray(q, dtype=float)
    s = math.sqrt(0.5)   # conj(_Q_YUP_TO_ZUP) (x) q, written out
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([s * (w + x), s * (x - w), s * (y + z), s * (z - y)], axis=-1)


def positions_from_zup(p: np.ndarray) -> np.ndarray:
    """(..., 3) Z-up positions -> Y up."""
    p = np.asarray(p, dtype=float)
    return np.stack([p[..., 0], p[..., 2], -p[..., 1]], axis=-1)


# ---------------------------------------------------------------------------------------
# measurements (shared by every engine)


def quaternion_matrices(q: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions [w, x, y, z] -> (..., 3, 3) rotation matrices."""
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1)], axis=-2)


def close_pairs(centres: np.ndarray, reach: float) -> np.ndarray:
    """(k, 2) pairs i < j of points closer than `reach`, found through a grid of cells of
    that size (each cell against itself and its 13 forward neighbours), so 10,000 bodies
    cost a few thousand pair tests, not 5e7."""
    cells = np.floor(np.asarray(centres) / reach).astype(np.int64)
    cells -= cells.min(axis=0)
    span = cells.max(axis=0) + 3
    keys = (cells[:, 0] * span[1] + cells[:, 1]) * span[2] + cells[:, 2]
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    offsets = [(dx, dy, dz) for dx in (-1, 0, 1) for dy in (-1, 0, 1) for dz in (-1, 0, 1)
               if (dx, dy, dz) > (0, 0, 0)]
    firsts, seconds = [], []
    for dx, dy, dz in [(0, 0, 0)] + offsets:
        target = keys + (dx * span[1] + dy) * span[2] + dz
        lo = np.searchsorted(sorted_keys, target, side="left")
        hi = np.searchsorted(sorted_keys, target, side="right")
        counts = hi - lo
        i = np.repeat(np.arange(len(keys)), counts)
        j = order[np.repeat(lo, counts) + np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)]
        keep = i < j if (dx, dy, dz) == (0, 0, 0) else np.ones(len(i), bool)
        firsts.append(i[keep])
        seconds.append(j[keep])
    i, j = np.concatenate(firsts), np.concatenate(seconds)
    near = np.linalg.norm(centres[i] - centres[j], axis=-1) < reach
    pairs = np.stack([np.minimum(i, j), np.maximum(i, j)], axis=-1)[near]
    return pairs


def box_overlap(ca, Ra, ha, cb, Rb, hb) -> np.ndarray:
    """Penetration depth of pairs of boxes (centres (k, 3), rotations (k, 3, 3) whose columns
    are the box axes, half sizes (k, 3)): the smallest overlap of their projections on the
    15 separating axes (3 face normals each, 9 edge-edge cross products), which for convex
    polyhedra is the shortest translation that separates them; 0 when apart."""
    axes = [Ra[:, :, i] for i in range(3)] + [Rb[:, :, i] for i in range(3)]
    for i in range(3):
        for j in range(3):
            axes.append(np.cross(Ra[:, :, i], Rb[:, :, j]))
    L = np.stack(axes, axis=1)                                     # (k, 15, 3)
    length = np.linalg.norm(L, axis=-1)
    valid = length > 1e-6                                          # parallel edges: no axis
    L = L / np.where(valid, length, 1.0)[..., None]
    ra = (np.abs(np.einsum("kaj,kji->kai", L, Ra)) * ha[:, None, :]).sum(-1)
    rb = (np.abs(np.einsum("kaj,kji->kai", L, Rb)) * hb[:, None, :]).sum(-1)
    distance = np.abs(np.einsum("kaj,kj->ka", L, cb - ca))
    overlap = np.where(valid, ra + rb - distance, np.inf)
    return np.maximum(overlap.min(axis=1), 0.0)


def box_penetration(scene: Scene, positions: np.ndarray, orientations: np.ndarray) -> dict:
    """Deepest penetration of box into box and of a box corner into the ground, at every
    recorded frame, measured from the poses alone (the same code for every engine)."""
    half = 0.5 * np.array([b.size for b in scene.bodies], dtype=float)     # (n, 3)
    reach = 2.0 * float(np.linalg.norm(half, axis=-1).max())
    deepest_pair, deepest_ground, deepest_frame = [], [], []
    for p, q in zip(np.asarray(positions, float), np.asarray(orientations, float)):
        R = quaternion_matrices(q)
        lowest = p[:, 1] - (np.abs(R[:, 1, :]) * half).sum(-1)
        deepest_ground.append(float(max(0.0, (scene.ground_height - lowest).max())))
        pairs = close_pairs(p, reach) if len(p) > 1 else np.zeros((0, 2), int)
        depth = 0.0
        if len(pairs):
            i, j = pairs[:, 0], pairs[:, 1]
            depth = float(box_overlap(p[i], R[i], half[i], p[j], R[j], half[j]).max())
        deepest_pair.append(depth)
    frames = scene.recorded_frames()
    worst = int(np.argmax(np.maximum(deepest_pair, deepest_ground)))
    return {"penetration_mm": 1000.0 * max(max(deepest_pair), max(deepest_ground)),
            "penetration_boxes_mm": 1000.0 * max(deepest_pair),
            "penetration_ground_mm": 1000.0 * max(deepest_ground),
            "penetration_time": frames[worst] / FPS,
            "penetration_end_mm": 1000.0 * max(deepest_pair[-1], deepest_ground[-1])}


def _parabola_vertex(t, y):
    """Vertex height of the parabola through three points."""
    c = np.polyfit(np.asarray(t, float), np.asarray(y, float), 2)
    if c[0] >= 0.0:
        return float(max(y))
    return float(c[2] - c[1] * c[1] / (4.0 * c[0]))


def analyze(scene: Scene, positions: np.ndarray, orientations: np.ndarray | None = None) -> dict:
    """Accuracy of a run from the recorded centres (len(recorded_frames()), n, 3), Y up, and
    for scenes of boxes from the orientations too ((frames, n, 4), [w, x, y, z], Y up): the
    deepest penetration at any recorded frame."""
    p = np.asarray(positions, dtype=float)
    frames = scene.recorded_frames()
    t = np.array(frames, dtype=float) / FPS
    out = {"finite": bool(np.isfinite(p).all())}
    if not out["finite"]:
        return out
    if orientations is not None and all(b.shape == "box" for b in scene.bodies):
        out.update(box_penetration(scene, p, orientations))
    displacement = np.linalg.norm(p - p[0], axis=-1)            # (frames, n)
    if scene.name in ("tower", "pyramid"):
        out["drift_mm"] = 1000.0 * float(displacement.max())     # largest, any box, any frame
        out["drift_end_mm"] = 1000.0 * float(displacement[-1].max())
        worst = np.unravel_index(int(displacement.argmax()), displacement.shape)
        out["drift_worst_box"] = int(worst[1])
        out["drift_worst_time"] = float(t[worst[0]])
    elif scene.name.startswith("pile"):
        speed = np.linalg.norm(p[-1] - p[-2], axis=-1) * FPS     # over the last frame
        half = 0.5 * scene.bodies[0].size[0]
        out["max_speed_end"] = float(speed.max())
        out["mean_speed_end"] = float(speed.mean())
        out["below_ground"] = int((p[-1, :, 1] < scene.ground_height).sum())   # centre under the plane
        out["sunk_half"] = int((p[-1, :, 1] < scene.ground_height + 0.5 * half).sum())
        out["min_height_end"] = float(p[-1, :, 1].min())
        out["max_height_end"] = float(p[-1, :, 1].max())
        out["max_radius_end"] = float(np.hypot(p[-1, :, 0], p[-1, :, 2]).max())
        # nothing may fall faster than from the highest start, nor rise above it
        top = max(b.position[1] for b in scene.bodies)
        out["free_fall_speed_limit"] = math.sqrt(2.0 * G * (top - half - scene.ground_height))
        out["exploded"] = bool(out["below_ground"] > 0 or out["max_speed_end"] > out["free_fall_speed_limit"]
                               or out["max_height_end"] > top + half)
    elif scene.name == "drop":
        r = scene.bodies[0].radius
        h = p[:, 0, 1] - r - scene.ground_height                 # bottom height
        expected = scene.e ** 2 * DROP_HEIGHT
        out["expected_apex_m"] = expected
        dh = np.diff(h)
        # first impact: the first frame after which the sphere no longer falls
        impact = next((k for k in range(1, len(dh)) if dh[k - 1] < 0.0 and dh[k] >= 0.0), None)
        apex_k = None
        if impact is not None:
            apex_k = next((k for k in range(impact + 1, len(dh)) if dh[k - 1] > 0.0 and dh[k] <= 0.0), None)
        if apex_k is None:
            apex = float(h[impact:].max()) if impact is not None else float("nan")
            out["apex_method"] = "no rebound apex found: highest bottom after the first impact"
        elif min(h[apex_k - 1], h[apex_k], h[apex_k + 1]) > 0.01:
            apex = _parabola_vertex(t[apex_k - 1:apex_k + 2], h[apex_k - 1:apex_k + 2])
            out["apex_method"] = "parabola through the 3 frames around the apex (ballistic)"
        else:
            apex = float(h[apex_k])
            out["apex_method"] = "highest frame (too close to the ground for a parabola)"
        out["apex_m"] = apex
        out["apex_error_pct"] = 100.0 * (apex - expected) / expected
        out["first_impact_time"] = float(t[impact]) if impact is not None else None
    elif scene.name.startswith("incline"):
        a = math.radians(INCLINE_DEG)
        x = p[:, 0, 0] - p[0, 0, 0]                              # along the slope (downhill +x)
        out["sideways_drift_mm"] = 1000.0 * float(abs(p[-1, 0, 2] - p[0, 0, 2]))
        out["lift_mm"] = 1000.0 * float(p[:, 0, 1].max() - p[0, 0, 1])
        if scene.mu < math.tan(a):
            expected = G * (math.sin(a) - scene.mu * math.cos(a))
            fit = t >= 0.25                                      # after any start-up transient
            c = np.polyfit(t[fit], x[fit], 2)
            out["expected_acceleration"] = expected
            out["acceleration"] = float(2.0 * c[0])
            out["acceleration_error_pct"] = 100.0 * (2.0 * c[0] - expected) / expected
            out["distance_m"] = float(x[-1])
        else:
            last = t >= t[-1] - 1.0 - 1e-9
            out["creep_mm_per_s"] = 1000.0 * float((x[last][-1] - x[last][0]) / (t[last][-1] - t[last][0]))
            out["creep_total_mm"] = 1000.0 * float(x[-1])
    return out


def _penetration(accuracy: dict) -> str:
    if "penetration_mm" not in accuracy:
        return ""
    return f", pen {accuracy['penetration_mm']:.3g} mm"


def summary(scene_name: str, accuracy: dict) -> str:
    """One short accuracy string for tables and the chart."""
    a = accuracy
    if not a or not a.get("finite", False):
        return "non-finite" if a else "-"
    if scene_name in ("tower", "pyramid"):
        return f"drift {a['drift_mm']:.3g} mm" + _penetration(a)
    if scene_name.startswith("pile"):
        flag = "EXPLODED, " if a["exploded"] else ""
        return f"{flag}vmax {a['max_speed_end']:.2g} m/s, {a['below_ground']} below" + _penetration(a)
    if scene_name == "drop":
        return f"apex {a['apex_error_pct']:+.1f}%"
    if scene_name == "incline_slide":
        return f"accel {a['acceleration_error_pct']:+.2f}%"
    if scene_name == "incline_stick":
        return f"creep {a['creep_mm_per_s']:.3g} mm/s"
    return ""


def result(engine: str, version: str, scene: Scene, clock: "StepClock",
           positions: np.ndarray, settings: dict, extra: dict | None = None,
           orientations: np.ndarray | None = None) -> dict:
    """The JSON line an engine script prints."""
    sim = scene.frames / FPS
    out = {
        "engine": engine, "version": version, "scene": scene.name, "scene_digest": digest(scene),
        "bodies": len(scene.bodies), "simulated_seconds": sim,
        "step_wall_seconds": clock.total,
        "step_cpu_seconds": clock.cpu,     # process CPU time: above wall = more than one thread
        "wall_per_simulated_second": clock.total / sim if sim > 0 else None,
        "wall_per_simulated_second_by_second": clock.by_second(),
        "accuracy": analyze(scene, positions, orientations),
        "settings": settings,
    }
    out["summary"] = summary(scene.name, out["accuracy"])
    if extra:
        out.update(extra)
    return out


class StepClock:
    """Wall time of the stepping alone, also per simulated second (frames are 1/FPS)."""

    def __init__(self):
        import time
        self._now = time.perf_counter
        self._cpu = time.process_time
        self.total = 0.0
        self.cpu = 0.0
        self.segments = [0.0]
        self._frame = 0
        self._start = None

    def __enter__(self):
        self._start, self._start_cpu = self._now(), self._cpu()
        return self

    def __exit__(self, *exc):
        dt = self._now() - self._start
        self.cpu += self._cpu() - self._start_cpu
        self.total += dt
        self.segments[-1] += dt
        self._frame += 1
        if self._frame % FPS == 0:
            self.segments.append(0.0)
        return False

    def by_second(self) -> list:
        """Stepping wall seconds of each simulated second (the last may be partial)."""
        return [s for s in self.segments if s > 0.0]


def common_args(argv=None):
    """scene [--seconds S] for every engine script."""
    import argparse
    ap = argparse.ArgumentParser()
    ap.add_argument("scene", choices=list(SCENES))
    ap.add_argument("--seconds", type=float, default=None, help="simulated seconds (default: the scene's)")
    return ap.parse_args(argv)
