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

import functools
import hashlib
import json
import math
import os
import random
from dataclasses import dataclass, field
from pathlib import Path

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
    shape: str                 # "box" | "sphere" | "mesh"
    size: tuple                # box: full edge lengths (m); sphere: (r, r, r) diameter/2 each;
                               # mesh: its bounding box's edge lengths (information only)
    position: tuple            # centre, Y up (m); mesh: the mesh's origin
    orientation: tuple = (1.0, 0.0, 0.0, 0.0)  # [w, x, y, z], Y up
    density: float = 1000.0
    mesh: str | None = None    # mesh bodies: the closed .obj, relative to the repository root
    linear_velocity: tuple = (0.0, 0.0, 0.0)   # of the centre of mass, world frame (m/s)
    angular_velocity: tuple = (0.0, 0.0, 0.0)  # world frame (rad/s)

    @property
    def radius(self) -> float:
        return self.size[0]

    @property
    def volume(self) -> float:
        if self.shape == "mesh":
            return mesh_shape(self.mesh).volume
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


# ---------------------------------------------------------------------------------------
# the mesh pile: assets/scenes/pile.toml itself

ROOT = Path(__file__).resolve().parents[2]       # the repository
MESH_PILE = "assets/scenes/pile.toml"
# simbake's defaults for what pile.toml leaves out (pipeline/simbake/scene.py: Body, Ground,
# Scene, DEFAULT_DENSITY); the friction of a pair is the geometric mean of its two bodies'
SIMBAKE_BODY_FRICTION = 0.5
SIMBAKE_GROUND_FRICTION = 0.5
SIMBAKE_DENSITY = 1000.0
_MESH_BODY_KEYS = {"name", "mesh", "position", "orientation", "density", "linear_velocity",
                   "angular_velocity", "friction", "restitution", "voxel_size"}


def _simbake_orientation(q) -> tuple:
    """The quaternion normalized exactly as simbake's scene loader does (_orientation)."""
    scale = max(abs(c) for c in q)
    q = tuple(c / scale for c in q)
    norm = math.hypot(*q)
    return tuple(c / norm for c in q)


def _mesh_pile(seconds, path=MESH_PILE, name="pile_meshes"):
    """The scene file read with tomllib (as simbake reads it): every body's mesh, pose,
    velocities and density, the ground, gravity and duration. Each pair's friction is
    simbake's (geometric mean of the two bodies', the ground's for the ground); the scene
    must give every pair the same friction, which each peer then gets through its own rule."""
    import tomllib
    file = ROOT / path
    with open(file, "rb") as f:
        data = tomllib.load(f)
    settings = data["scene"]
    if float(settings.get("fps", 24)) != FPS:
        raise SystemExit(f"{path}: fps {settings.get('fps')} but the peer benchmark records at {FPS}")
    start, end = int(settings.get("start_frame", 1)), int(settings["end_frame"])
    gravity = tuple(float(v) for v in settings.get("gravity", (0.0, -G, 0.0)))
    ground = data.get("ground")
    if ground is None:
        raise SystemExit(f"{path}: no ground")
    ground_friction = float(ground.get("friction", SIMBAKE_GROUND_FRICTION))
    ground_restitution = float(ground.get("restitution", 0.0))
    bodies, frictions, restitutions = [], [], []
    for t in data["bodies"]:
        unknown = set(t) - _MESH_BODY_KEYS
        if unknown or "mesh" not in t:
            raise SystemExit(f"{path}: body {t.get('name')}: only mesh bodies with keys "
                             f"{sorted(_MESH_BODY_KEYS)} are supported here (got {sorted(unknown) or 'no mesh'})")
        mesh = os.path.relpath((file.parent / t["mesh"]).resolve(), ROOT)
        shape = mesh_shape(mesh)
        bodies.append(Body("mesh", tuple(float(v) for v in shape.extent),
                           tuple(float(v) for v in t.get("position", (0.0, 0.0, 0.0))),
                           _simbake_orientation(tuple(float(v) for v in t.get("orientation", (1.0, 0.0, 0.0, 0.0)))),
                           float(t.get("density", SIMBAKE_DENSITY)), mesh,
                           tuple(float(v) for v in t.get("linear_velocity", (0.0, 0.0, 0.0))),
                           tuple(float(v) for v in t.get("angular_velocity", (0.0, 0.0, 0.0)))))
        frictions.append(float(t.get("friction", SIMBAKE_BODY_FRICTION)))
        restitutions.append(float(t.get("restitution", 0.0)))
    pair_mu = {math.sqrt(a * b) for a in set(frictions) for b in set(frictions)}
    pair_mu |= {math.sqrt(a * ground_friction) for a in set(frictions)}
    pair_e = {max(a, b) for a in set(restitutions) for b in set(restitutions)}
    pair_e |= {max(a, ground_restitution) for a in set(restitutions)}
    if len(pair_mu) != 1 or len(pair_e) != 1:
        raise SystemExit(f"{path}: pairs of different friction {sorted(pair_mu)} or restitution "
                         f"{sorted(pair_e)}: the peer benchmark gives every pair one mu and one e")
    kinds = sorted({Path(b.mesh).stem for b in bodies})
    duration = (end - start) / FPS
    return Scene(name, f"mesh pile: {path}, {len(bodies)} nonconvex meshes ({', '.join(kinds)}), "
                       f"density {bodies[0].density:g}, mu {pair_mu.pop():g}",
                 bodies, seconds or duration, mu=math.sqrt(frictions[0] * ground_friction), e=pair_e.pop(),
                 gravity=gravity, ground_height=float(ground.get("height", 0.0)),
                 notes=[f"built from {path} (frames {start}-{end} at {FPS} fps)"])


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
    "pile_meshes": lambda s=None: _mesh_pile(s),
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
    if any(b.shape == "mesh" for b in scene.bodies):
        data.append([(b.mesh, mesh_shape(b.mesh).sha1 if b.mesh else None, b.linear_velocity,
                      b.angular_velocity) for b in scene.bodies])
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


# ---------------------------------------------------------------------------------------
# mesh bodies: geometry, mass, exact convex decomposition, poses (shared by every engine)


def read_obj(path) -> tuple:
    """(vertices (n, 3) float64, triangles (m, 3) int64) of an .obj (polygons as fans)."""
    vertices, triangles = [], []
    for line in Path(path).read_text().splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            vertices.append([float(v) for v in parts[1:4]])
        elif parts[0] == "f":
            ids = [int(p.split("/")[0]) for p in parts[1:]]
            ids = [i - 1 if i > 0 else len(vertices) + i for i in ids]
            triangles += [(ids[0], ids[k], ids[k + 1]) for k in range(1, len(ids) - 1)]
    return np.array(vertices, dtype=float), np.array(triangles, dtype=np.int64)


def mass_properties(vertices: np.ndarray, triangles: np.ndarray) -> tuple:
    """(volume, centre of mass (3,), inertia about it at unit density (3, 3)) of a closed,
    outward-wound mesh: signed tetrahedra from the origin (divergence theorem)."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    det = np.einsum("ij,ij->i", a, np.cross(b, c))
    volume = det.sum() / 6.0
    s = a + b + c
    centre = (det[:, None] * s).sum(0) / (24.0 * volume)
    # second moment of each tetrahedron (0, a, b, c): det / 120 (a a' + b b' + c c' + s s')
    second = np.einsum("i,ijk->jk", det / 120.0,
                       np.einsum("ij,ik->ijk", a, a) + np.einsum("ij,ik->ijk", b, b)
                       + np.einsum("ij,ik->ijk", c, c) + np.einsum("ij,ik->ijk", s, s))
    second -= volume * np.outer(centre, centre)
    inertia = np.trace(second) * np.eye(3) - second
    return float(volume), centre, inertia


def quat_from_matrix(m: np.ndarray) -> tuple:
    """A rotation matrix -> [w, x, y, z] (w >= 0)."""
    m = np.asarray(m, dtype=float)
    t = np.trace(m)
    if t > 0.0:
        r = math.sqrt(1.0 + t)
        q = (0.5 * r, (m[2, 1] - m[1, 2]) / (2 * r), (m[0, 2] - m[2, 0]) / (2 * r), (m[1, 0] - m[0, 1]) / (2 * r))
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        r = math.sqrt(max(0.0, 1.0 + m[i, i] - m[j, j] - m[k, k]))
        q = [0.0] * 4
        q[0] = (m[k, j] - m[j, k]) / (2 * r)
        q[1 + i] = 0.5 * r
        q[1 + j] = (m[j, i] + m[i, j]) / (2 * r)
        q[1 + k] = (m[k, i] + m[i, k]) / (2 * r)
    q = np.array(q) / np.linalg.norm(q)
    return tuple(float(v) for v in (q if q[0] >= 0 else -q))


def _convex_pieces(stem: str, vertices: np.ndarray) -> list:
    """An exact decomposition of the shipped meshes (assets/meshes/generate.py) into convex
    pieces whose union is the mesh's solid: point sets whose convex hulls are the pieces.
    - torus.obj (32 x 16): the 32 tube segments between neighbouring meridian 16-gons; each
      is the hull of its two 16-gons (their quads are planar trapezoids, mirror-symmetric
      about the bisecting plane), so the pieces tile the tessellated torus exactly;
    - lshape.obj (an extruded L): cut through its one reflex corner into two boxes;
    - sphere.obj: one piece, its convex hull. Not exact: the cube-sphere's quads are split
      along alternating diagonals, so the mesh has shallow dents that the hull fills (its
      volume is 0.17% larger; 108 folded quads, each dent at most the 4.0 mm between the
      quad's two diagonals): a peer's sphere stands up to ~4 mm proud of the true mesh.
    Checked by run_mujoco.py (hull volumes add up to the mesh's volume) and the tests."""
    if stem == "sphere":
        return [vertices.copy()]
    if stem == "torus":
        # meridians by angle about y (the file has 6 decimals; -pi and pi are one meridian)
        angle = np.round(np.mod(np.arctan2(vertices[:, 2], vertices[:, 0]) + 1e-6, 2 * math.pi), 3)
        rings = [vertices[angle == a] for a in np.unique(angle)]
        return [np.vstack([rings[i], rings[(i + 1) % len(rings)]]) for i in range(len(rings))]
    if stem == "lshape":
        z = np.unique(np.round(vertices[:, 2], 12))
        n = len(vertices) // 2
        outline = vertices[:n, :2]                       # the front cap's polygon, in order
        out = np.roll(outline, -1, axis=0) - outline     # edge k -> k + 1
        into = np.roll(out, 1, axis=0)                   # edge k - 1 -> k
        turn = into[:, 0] * out[:, 1] - into[:, 1] * out[:, 0]
        area = (outline[:, 0] * np.roll(outline, -1, axis=0)[:, 1]
                - np.roll(outline, -1, axis=0)[:, 0] * outline[:, 1]).sum()
        reflex = [k for k in range(n) if turn[k] * area < 0]
        if len(reflex) != 1:
            raise ValueError(f"{stem}: expected one reflex corner, found {len(reflex)}")
        cut = outline[reflex[0], 1]                      # a line y = cut through it
        pieces = []
        for side in (-1.0, 1.0):
            # corners strictly on this side, and corners on the cut with a neighbour strictly
            # on this side (a corner on the cut whose edges run along it would add a sliver)
            strictly = [side * (p[1] - cut) > 1e-12 for p in outline]
            pts = [tuple(outline[k]) for k in range(n) if strictly[k]
                   or (abs(outline[k, 1] - cut) <= 1e-12 and (strictly[k - 1] or strictly[(k + 1) % n]))]
            for k in range(n):                           # where the outline crosses the cut
                p, q = outline[k], outline[(k + 1) % n]
                if (p[1] - cut) * (q[1] - cut) < 0:
                    t = (cut - p[1]) / (q[1] - p[1])
                    pts.append((p[0] + t * (q[0] - p[0]), cut))
            pts = np.unique(np.array(pts), axis=0)
            pieces.append(np.array([(x, y, zz) for x, y in pts for zz in (z[0], z[-1])]))
        return pieces
    raise ValueError(f"no exact convex decomposition known for {stem}.obj")


@dataclass
class MeshShape:
    path: str                  # relative to the repository
    vertices: np.ndarray       # (n, 3), the mesh's own frame
    triangles: np.ndarray      # (m, 3)
    sha1: str
    volume: float              # m^3
    centre: np.ndarray         # centre of mass in the mesh frame (m)
    inertia: np.ndarray        # about the centre, mesh frame, unit density (m^5)
    axes: np.ndarray           # principal axes: columns, mesh frame, det +1
    moments: np.ndarray        # principal moments, unit density (m^5)
    radius: float              # largest |vertex| (bounding sphere about the mesh origin)
    extent: np.ndarray         # bounding box edge lengths
    pieces: list               # convex pieces (point sets), mesh frame

    @property
    def axes_quat(self) -> tuple:
        return quat_from_matrix(self.axes)

    def principal(self, points: np.ndarray) -> np.ndarray:
        """Mesh-frame points -> the principal frame (origin at the centre of mass)."""
        return (np.asarray(points) - self.centre) @ self.axes


@functools.lru_cache(maxsize=None)
def mesh_shape(path: str) -> MeshShape:
    file = ROOT / path
    vertices, triangles = read_obj(file)
    volume, centre, inertia = mass_properties(vertices, triangles)
    off = np.abs(inertia - np.diag(np.diag(inertia))).max()
    if off <= 1e-12 * np.trace(inertia):        # already principal (torus, sphere): keep the axes
        axes, moments = np.eye(3), np.diag(inertia).copy()
    else:
        moments, axes = np.linalg.eigh(inertia)
        if np.linalg.det(axes) < 0:
            axes[:, 2] = -axes[:, 2]
    return MeshShape(path, vertices, triangles, hashlib.sha1(file.read_bytes()).hexdigest()[:12],
                     volume, centre, inertia, axes, moments,
                     float(np.linalg.norm(vertices, axis=1).max()), vertices.max(0) - vertices.min(0),
                     _convex_pieces(file.stem, vertices))


def quat_multiply_np(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a, b = np.asarray(a, float), np.asarray(b, float)
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw], axis=-1)


def principal_pose(body: Body) -> tuple:
    """(centre of mass position, principal-frame orientation [w, x, y, z]), Y up, of a mesh
    body: the frame the peers simulate it in (its pieces given by shape.principal)."""
    shape = mesh_shape(body.mesh)
    R = quaternion_matrices(np.array(body.orientation))
    com = np.array(body.position) + R @ shape.centre
    q = quat_multiply_np(np.array(body.orientation), np.array(shape.axes_quat))
    return tuple(float(v) for v in com), tuple(float(v) for v in q)


def mesh_origin_poses(scene: Scene, com: np.ndarray, q: np.ndarray) -> tuple:
    """Principal-frame poses (..., n, 3), (..., n, 4) -> the meshes' origin poses (what
    simbake's World.mesh_poses and every engine hand to analyze)."""
    shapes = [mesh_shape(b.mesh) for b in scene.bodies]
    inverse_axes = np.array([[s.axes_quat[0], -s.axes_quat[1], -s.axes_quat[2], -s.axes_quat[3]] for s in shapes])
    q_mesh = quat_multiply_np(q, inverse_axes)
    centres = np.array([s.centre for s in shapes])
    R = quaternion_matrices(q_mesh)
    origin = np.asarray(com, float) - np.einsum("...ij,...j->...i", R, centres)
    return origin, q_mesh


def origin_pose_readers(scene: Scene, centres, turns) -> tuple:
    """An engine's readers of its bodies' principal-frame centres and turns -> readers of the
    meshes' origins and turns (mesh_origin_poses), as every engine hands them to analyze."""
    return (lambda: mesh_origin_poses(scene, centres(), turns())[0],
            lambda: mesh_origin_poses(scene, centres(), turns())[1])


# ---------------------------------------------------------------------------------------
# penetration of meshes, measured exactly from the true meshes

PEN_SAMPLE_SPACING = 0.01      # m: surface samples of each mesh are at most this far apart
PEN_CELL = 0.02                # m: cells of each mesh's culling grid
PEN_PAIR_FRAME_STRIDE = 3      # body-body penetration on every 3rd frame and the last two


def _closest_on_triangles(p, a, b, c):
    """Closest points of triangles (a, b, c) to points p (broadcast (..., 3)): (squared
    distance, closest point, feature: 0 face, 1/2/3 vertex a/b/c, 4/5/6 edge ab/bc/ca)
    (Ericson, Real-Time Collision Detection 5.1.5, vectorized)."""
    ab, ac = b - a, c - a
    ap, bp, cp = p - a, p - b, p - c
    d1, d2 = (ab * ap).sum(-1), (ac * ap).sum(-1)
    d3, d4 = (ab * bp).sum(-1), (ac * bp).sum(-1)
    d5, d6 = (ab * cp).sum(-1), (ac * cp).sum(-1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        denom = 1.0 / (va + vb + vc)
    conditions = [(d1 <= 0) & (d2 <= 0), (d3 >= 0) & (d4 <= d3), (vc <= 0) & (d1 >= 0) & (d3 <= 0),
                  (d6 >= 0) & (d5 <= d6), (vb <= 0) & (d2 >= 0) & (d6 <= 0),
                  (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)]
    feature = np.select(conditions, [1, 2, 4, 3, 6, 5], 0)
    u = np.select(conditions, [1.0, 0.0, 1.0 - t_ab, 0.0, 1.0 - t_ac, 0.0], 1.0 - (vb + vc) * denom)
    v = np.select(conditions, [0.0, 1.0, t_ab, 0.0, 0.0, 1.0 - t_bc], vb * denom)
    w = 1.0 - u - v
    q = u[..., None] * a + v[..., None] * b + w[..., None] * c
    return ((p - q) ** 2).sum(-1), q, feature


class MeshProbe:
    """Exact signed distance to one closed mesh, for many points: the nearest triangle (exact
    point-triangle distance) and the sign from the angle-weighted pseudo-normal of the nearest
    feature (Baerentzen and Aanaes 2005: exact for closed, consistently wound meshes). A grid
    of PEN_CELL cells with the exact signed distance at each centre culls the points that
    cannot be inside (centre distance >= half the cell's diagonal) and lists, per cell, the
    only triangles that can be nearest to a point in it. Also the mesh's surface samples."""

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, spacing: float = PEN_SAMPLE_SPACING,
                 cell: float = PEN_CELL):
        V, T = np.asarray(vertices, float), np.asarray(triangles, np.int64)
        self.V, self.T = V, T
        self.a, self.b, self.c = V[T[:, 0]], V[T[:, 1]], V[T[:, 2]]
        n = np.cross(self.b - self.a, self.c - self.a)
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        # pseudo-normals per triangle and feature: face, vertices (angle weighted), edges
        vertex_normals = np.zeros_like(V)
        corners = [self.a, self.b, self.c]
        for k in range(3):
            e1 = corners[(k + 1) % 3] - corners[k]
            e2 = corners[(k + 2) % 3] - corners[k]
            cosine = (e1 * e2).sum(1) / (np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1))
            np.add.at(vertex_normals, T[:, k], np.arccos(np.clip(cosine, -1, 1))[:, None] * n)
        vertex_normals /= np.linalg.norm(vertex_normals, axis=1, keepdims=True)
        edge_sum = {}
        for t, tri in enumerate(T):
            for k in range(3):
                key = tuple(sorted((int(tri[k]), int(tri[(k + 1) % 3]))))
                edge_sum[key] = edge_sum.get(key, 0.0) + n[t]
        pn = np.zeros((len(T), 7, 3))
        pn[:, 0] = n
        for k in range(3):
            pn[:, 1 + k] = vertex_normals[T[:, k]]
        for t, tri in enumerate(T):
            for k in range(3):       # 4: ab, 5: bc, 6: ca
                e = edge_sum[tuple(sorted((int(tri[k]), int(tri[(k + 1) % 3]))))]
                pn[t, 4 + k] = e / np.linalg.norm(e)
        self.pn = pn
        self.samples = self._surface_samples(spacing)
        self.spacing = spacing
        # the culling grid
        self.cell = cell
        self.half_diagonal = 0.5 * math.sqrt(3.0) * cell
        lo, hi = V.min(0) - 2 * cell, V.max(0) + 2 * cell
        self.origin = lo
        self.dims = np.ceil((hi - lo) / cell).astype(int)
        ijk = np.stack(np.meshgrid(*[np.arange(d) for d in self.dims], indexing="ij"), -1).reshape(-1, 3)
        centres = lo + (ijk + 0.5) * cell
        sd = np.empty(len(centres))
        starts, items = [0], []
        for s in range(0, len(centres), 128):
            p = centres[s:s + 128]
            d2, q, f = _closest_on_triangles(p[:, None, :], self.a[None], self.b[None], self.c[None])
            best = d2.argmin(1)
            rows = np.arange(len(p))
            side = ((p - q[rows, best]) * pn[best, f[rows, best]]).sum(-1)
            dist = np.sqrt(d2)
            sd[s:s + 128] = np.where(side < 0, -1.0, 1.0) * dist[rows, best]
            for r in range(len(p)):
                if sd[s + r] < self.half_diagonal:
                    near = np.nonzero(dist[r] <= abs(sd[s + r]) + 2.0 * self.half_diagonal + 1e-12)[0]
                    items.append(near)
                    starts.append(starts[-1] + len(near))
                else:
                    starts.append(starts[-1])
        self.grid_sd = sd
        self.list_start = np.array(starts, dtype=np.int64)
        self.list_items = np.concatenate(items) if items else np.zeros(0, np.int64)

    def _surface_samples(self, spacing: float) -> np.ndarray:
        """The vertices and, on every triangle, a barycentric grid whose steps along each edge
        are at most `spacing`."""
        out = [self.V]
        for a, b, c in zip(self.a, self.b, self.c):
            longest = max(np.linalg.norm(b - a), np.linalg.norm(c - b), np.linalg.norm(a - c))
            n = max(1, int(math.ceil(longest / spacing)))
            i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
            keep = (i + j) <= n
            u, v = i[keep] / n, j[keep] / n
            out.append(a + u[:, None] * (b - a) + v[:, None] * (c - a))
        return np.unique(np.round(np.vstack(out), 12), axis=0)

    def depth(self, points: np.ndarray) -> np.ndarray:
        """How deep each point (mesh frame) is inside the mesh (m; 0 outside)."""
        points = np.asarray(points, float).reshape(-1, 3)
        out = np.zeros(len(points))
        ijk = np.floor((points - self.origin) / self.cell).astype(np.int64)
        inside_grid = ((ijk >= 0) & (ijk < self.dims)).all(1)
        idx = np.nonzero(inside_grid)[0]
        flat = (ijk[idx, 0] * self.dims[1] + ijk[idx, 1]) * self.dims[2] + ijk[idx, 2]
        maybe = self.grid_sd[flat] < self.half_diagonal
        idx, flat = idx[maybe], flat[maybe]
        if not len(idx):
            return out
        starts, counts = self.list_start[flat], self.list_start[flat + 1] - self.list_start[flat]
        order = np.argsort(counts, kind="stable")
        for s in range(0, len(order), 2048):
            chunk = order[s:s + 2048]
            width = int(counts[chunk].max())
            cols = np.arange(width)
            valid = cols[None, :] < counts[chunk, None]
            tri = self.list_items[np.where(valid, starts[chunk, None] + cols[None, :], 0)]
            p = points[idx[chunk]]
            d2, q, f = _closest_on_triangles(p[:, None, :], self.a[tri], self.b[tri], self.c[tri])
            d2 = np.where(valid, d2, np.inf)
            best = d2.argmin(1)
            rows = np.arange(len(chunk))
            side = ((p - q[rows, best]) * self.pn[tri[rows, best], f[rows, best]]).sum(-1)
            out[idx[chunk]] = np.where(side < 0, np.sqrt(d2[rows, best]), 0.0)
        return out


_PROBES: dict = {}


_PROBE_FIELDS = ("V", "T", "a", "b", "c", "pn", "samples", "origin", "dims", "grid_sd", "list_start", "list_items")
PROBE_CACHE = Path(__file__).resolve().parent / ".cache"     # gitignored; rebuilt when missing


def mesh_probe(path: str) -> MeshProbe:
    """The probe of a scene's mesh, built once and kept in PROBE_CACHE (keyed by the file's
    hash and the spacings): building one takes seconds, loading it milliseconds."""
    if path not in _PROBES:
        shape = mesh_shape(path)
        file = PROBE_CACHE / f"probe-{Path(path).stem}-{shape.sha1}-{PEN_SAMPLE_SPACING:g}-{PEN_CELL:g}-v1.npz"
        probe = None
        if file.exists():
            try:
                data = np.load(file)
                probe = MeshProbe.__new__(MeshProbe)
                for name in _PROBE_FIELDS:
                    setattr(probe, name, data[name])
                probe.spacing, probe.cell = PEN_SAMPLE_SPACING, PEN_CELL
                probe.half_diagonal = 0.5 * math.sqrt(3.0) * PEN_CELL
            except Exception:
                probe = None
        if probe is None:
            probe = MeshProbe(shape.vertices, shape.triangles)
            try:
                PROBE_CACHE.mkdir(exist_ok=True)
                tmp = file.with_suffix(f".{os.getpid()}.tmp.npz")
                np.savez(tmp, **{name: getattr(probe, name) for name in _PROBE_FIELDS})
                os.replace(tmp, file)
            except OSError:
                pass
        _PROBES[path] = probe
    return _PROBES[path]


CLUSTER_CELL = 0.03           # m: samples are culled in clusters of this cell size first


def _clusters(probe: MeshProbe) -> tuple:
    """The probe's samples grouped by CLUSTER_CELL cells: (centres, radii, order, starts)."""
    if not hasattr(probe, "_cluster_data"):
        key = np.floor(probe.samples / CLUSTER_CELL).astype(np.int64)
        _, label = np.unique(key, axis=0, return_inverse=True)
        label = label.ravel()
        order = np.argsort(label, kind="stable")
        counts = np.bincount(label)
        starts = np.concatenate([[0], np.cumsum(counts)])
        centres = np.array([probe.samples[order[starts[c]:starts[c + 1]]].mean(0) for c in range(len(counts))])
        radii = np.array([np.linalg.norm(probe.samples[order[starts[c]:starts[c + 1]]] - centres[c], axis=1).max()
                          for c in range(len(counts))])
        probe._cluster_data = (centres, radii, order, starts)
    return probe._cluster_data


def _grid_bound(probe: MeshProbe, x: np.ndarray) -> np.ndarray:
    """A lower bound of the signed distance at points x (mesh frame): the cell centre's minus
    half the cell's diagonal; outside the grid, the distance to the grid's box."""
    ijk = np.floor((x - probe.origin) / probe.cell).astype(np.int64)
    inside = ((ijk >= 0) & (ijk < probe.dims)).all(-1)
    ijk = np.clip(ijk, 0, probe.dims - 1)
    flat = (ijk[..., 0] * probe.dims[1] + ijk[..., 1]) * probe.dims[2] + ijk[..., 2]
    lo, hi = probe.origin, probe.origin + probe.dims * probe.cell
    outside = np.linalg.norm(np.maximum(0.0, np.maximum(lo - x, x - hi)), axis=-1)
    return np.where(inside, probe.grid_sd[flat] - probe.half_diagonal, outside)


def pair_penetration(probe_a: MeshProbe, probe_b: MeshProbe, Ra, ta, Rb, tb) -> np.ndarray:
    """Deepest penetration of k pairs of meshes (rotations (k, 3, 3), translations (k, 3) of
    each mesh's frame): the deepest sample of either surface inside the other mesh. Samples
    go in clusters; a cluster whose centre is farther outside the other mesh than its radius
    (by the grid's lower bound) is skipped whole; every other sample's depth is exact."""
    out = np.zeros(len(Ra))
    for (pa, pb, R1, t1, R2, t2) in ((probe_a, probe_b, Ra, ta, Rb, tb), (probe_b, probe_a, Rb, tb, Ra, ta)):
        # the first mesh in the second's frame: x -> R2' (R1 x + t1 - t2)
        R = np.einsum("kji,kjl->kil", R2, R1)
        t = np.einsum("kji,kj->ki", R2, t1 - t2)
        centres, radii, order, starts = _clusters(pa)
        c = np.einsum("kij,nj->kni", R, centres) + t[:, None, :]
        pair, cluster = np.nonzero(_grid_bound(pb, c) < radii[None, :])
        if not len(pair):
            continue
        counts = starts[cluster + 1] - starts[cluster]
        first = np.repeat(starts[cluster] - np.cumsum(counts) + counts, counts)
        sample = order[first + np.arange(counts.sum())]
        owner = np.repeat(pair, counts)
        for s in range(0, len(sample), 1_000_000):
            k, idx = owner[s:s + 1_000_000], sample[s:s + 1_000_000]
            x = np.einsum("mij,mj->mi", R[k], pa.samples[idx]) + t[k]
            np.maximum.at(out, k, pb.depth(x))
    return out


def mesh_penetration(scene: Scene, positions: np.ndarray, orientations: np.ndarray,
                     stride: int = PEN_PAIR_FRAME_STRIDE) -> dict:
    """Deepest penetration of mesh into mesh and into the ground, from the poses of the
    meshes' origins (frames, n, 3) and (frames, n, 4), Y up. Ground: every vertex at every
    frame (exact for polyhedra). Bodies: every `stride`-th recorded frame and the last two;
    pairs whose bounding spheres overlap; each surface sampled (PEN_SAMPLE_SPACING) and
    each sample's depth inside the other mesh computed exactly (MeshProbe)."""
    paths = [b.mesh for b in scene.bodies]
    kinds = sorted(set(paths))
    kind = np.array([kinds.index(p) for p in paths])
    probes = [mesh_probe(p) for p in kinds]
    radius = np.array([mesh_shape(p).radius for p in paths])
    frames = scene.recorded_frames()
    P, Q = np.asarray(positions, float), np.asarray(orientations, float)
    deepest_ground, deepest_pair, pair_frames, pairs_tested = [], {}, [], 0
    measured = sorted(set(range(0, len(frames), stride)) | {len(frames) - 2, len(frames) - 1})
    for f, (p, q) in enumerate(zip(P, Q)):
        R = quaternion_matrices(q)
        lowest = np.inf
        for k, path in enumerate(kinds):
            members = kind == k
            y = np.einsum("nj,bj->bn", mesh_shape(path).vertices, R[members, 1, :]) + p[members, 1:2]
            lowest = min(lowest, float(y.min()))
        deepest_ground.append(max(0.0, scene.ground_height - lowest))
        if f not in measured:
            continue
        pairs = close_pairs(p, 2.0 * radius.max()) if len(p) > 1 else np.zeros((0, 2), int)
        if len(pairs):
            i, j = pairs[:, 0], pairs[:, 1]
            pairs = pairs[np.linalg.norm(p[i] - p[j], axis=1) < radius[i] + radius[j]]
        depth = 0.0
        pairs_tested += len(pairs)
        for ka in range(len(kinds)):
            for kb in range(len(kinds)):
                sel = pairs[(kind[pairs[:, 0]] == ka) & (kind[pairs[:, 1]] == kb)] if len(pairs) else pairs
                if len(sel):
                    i, j = sel[:, 0], sel[:, 1]
                    depth = max(depth, float(pair_penetration(probes[ka], probes[kb], R[i], p[i], R[j], p[j]).max()))
        deepest_pair[f] = depth
    worst_pair = max(deepest_pair, key=deepest_pair.get)
    worst_ground = int(np.argmax(deepest_ground))
    last = len(frames) - 1
    worst = worst_pair if deepest_pair[worst_pair] >= deepest_ground[worst_ground] else worst_ground
    return {"penetration_mm": 1000.0 * max(deepest_pair[worst_pair], deepest_ground[worst_ground]),
            "penetration_bodies_mm": 1000.0 * deepest_pair[worst_pair],
            "penetration_ground_mm": 1000.0 * deepest_ground[worst_ground],
            "penetration_bodies_time": frames[worst_pair] / FPS,
            "penetration_ground_time": frames[worst_ground] / FPS,
            "penetration_time": frames[worst] / FPS,
            "penetration_end_mm": 1000.0 * max(deepest_pair[last], deepest_ground[last]),
            "penetration_bodies_end_mm": 1000.0 * deepest_pair[last],
            "penetration_ground_end_mm": 1000.0 * deepest_ground[last],
            "penetration_method": (f"bodies: samples <= {1000 * PEN_SAMPLE_SPACING:g} mm apart on each "
                                   f"surface, exact depth inside the other mesh, every {stride}th frame "
                                   f"and the last two ({len(measured)} of {len(frames)}); ground: every "
                                   f"vertex, every frame"),
            "penetration_pair_tests": pairs_tested}


def _parabola_vertex(t, y):
    """Vertex height of the parabola through three points."""
    c = np.polyfit(np.asarray(t, float), np.asarray(y, float), 2)
    if c[0] >= 0.0:
        return float(max(y))
    return float(c[2] - c[1] * c[1] / (4.0 * c[0]))


def _pile_end(scene: Scene, last_two: np.ndarray, half: float) -> dict:
    """How a pile ended, from its bodies' centres of mass at the last two recorded frames
    (2, n, 3): speeds over the last frame, centres under the ground (fell through), heights,
    and whether it exploded: nothing may fall faster than from the highest start, nor rise
    above it (`half`: how far a centre sits above the bottom it falls on; 0 for meshes)."""
    speed = np.linalg.norm(last_two[1] - last_two[0], axis=-1) * FPS
    end = last_two[1]
    top = max(b.position[1] for b in scene.bodies)
    out = {"max_speed_end": float(speed.max()), "mean_speed_end": float(speed.mean()),
           "below_ground": int((end[:, 1] < scene.ground_height).sum()),
           "min_height_end": float(end[:, 1].min()), "max_height_end": float(end[:, 1].max()),
           "max_radius_end": float(np.hypot(end[:, 0], end[:, 2]).max()),
           "free_fall_speed_limit": math.sqrt(2.0 * G * (top - half - scene.ground_height))}
    out["exploded"] = bool(out["below_ground"] > 0 or out["max_speed_end"] > out["free_fall_speed_limit"]
                           or out["max_height_end"] > top + half)
    return out


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
    if any(b.shape == "mesh" for b in scene.bodies):
        # positions are the meshes' origins: the centres of mass are origin + R c
        q = np.asarray(orientations, dtype=float)
        out["finite"] = bool(np.isfinite(q).all())
        if not out["finite"]:
            return out
        out.update(mesh_penetration(scene, p, q))
        centres = np.array([mesh_shape(b.mesh).centre for b in scene.bodies])
        com_end = p[-2:] + np.einsum("fnij,nj->fni", quaternion_matrices(q[-2:]), centres)
        out.update(_pile_end(scene, com_end, 0.0))
    elif scene.name in ("tower", "pyramid"):
        out["drift_mm"] = 1000.0 * float(displacement.max())     # largest, any box, any frame
        out["drift_end_mm"] = 1000.0 * float(displacement[-1].max())
        worst = np.unravel_index(int(displacement.argmax()), displacement.shape)
        out["drift_worst_box"] = int(worst[1])
        out["drift_worst_time"] = float(t[worst[0]])
    elif scene.name.startswith("pile"):
        half = 0.5 * scene.bodies[0].size[0]
        out.update(_pile_end(scene, p[-2:], half))
        out["sunk_half"] = int((p[-1, :, 1] < scene.ground_height + 0.5 * half).sum())
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
    if "penetration_bodies_mm" in a:
        flag = "EXPLODED, " if a["exploded"] else ""
        return (f"{flag}vmax {a['max_speed_end']:.2g} m/s, {a['below_ground']} below, pen "
                f"{a['penetration_bodies_mm']:.3g} / {a['penetration_ground_mm']:.3g} mm")
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
