"""Writes the shipped character shots (metres, Y up, 24 fps), checked in beside this file:

* ``character.usda``: a procedurally built figure walking forward (+Z) for 5 s, as a UsdSkel
  asset: a ``SkelRoot`` with a 17-joint ``Skeleton`` (hips, spine, chest, neck, head; shoulders,
  elbows, wrists; upper legs, knees, ankles), a ``SkelAnimation`` of the walk, and a closed
  body ``Mesh`` (``PhysicsCollisionAPI``) bound to it with linear blend skinning; a costume
  (one SimbakeClothAPI mesh, so that its self-collision keeps its two garments apart: two cloths
  do not collide with each other) of a skirt (a flared tube) attached along its waistband and a
  cape hung behind the shoulders over the skirt, attached along its top edge, the garments
  named by ``GeomSubset`` s ``skirt`` and ``cape``; a ground ``Plane``.
* ``flag_carried.usda``: a keyed arm (a kinematic rigid body: forearm, fist and a pole) that
  raises a flag and waves it while walking forward; the flag (SimbakeClothAPI) is attached
  along its pole edge to the arm.

Run it from anywhere: ``python generate_character.py`` (numpy and usd-core). It is
deterministic: the same bytes every run.

The body. Its rest (bind) shape is the zero level of a field (negative inside), the smooth
union of tapered capsules and ellipsoids (one per limb segment, the torso's parts, the head,
the feet), so the limbs blend into the torso at the joints. The surface is extracted by
marching tetrahedra on a grid (each cube cut into the six tetrahedra about its main diagonal,
a cut that neighbouring cubes share, so the surface is closed and manifold), wound outwards,
then relaxed: each vertex moved towards its neighbours' mean and put back on the field's zero
level by Newton steps, which evens the triangles without moving the surface.

The weights. A vertex's bones are the nearest one (its distance to the bone's segment over
the bone's radius) and that bone's neighbours in the skeleton (parent, children), so a thigh
never takes weight from the other thigh; each weighs the inverse fourth power of that measure,
the four largest are kept and normalised.

The walk. The feet are placed (a foot stays planted through its stance and swings to a
landing spot ahead of the pelvis by 0.3 of a stride), the pelvis moves forward at a speed
that ramps up from standing (the first STAND s are still, so that the cloth settles), bobs
as high as the stance legs reach and sways over the stance foot; hips and knees follow by
two-bone inverse kinematics in the leg's plane, the feet stay level, the arms swing against
the legs with the elbows bending, the pelvis and chest turn against each other.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
FPS, START = 24, 1
SECONDS = 5.0
END = START + int(round(SECONDS * FPS))           # 121: frames 1 .. 121

# -- the skeleton (bind pose: every joint unrotated, the figure facing +Z, its left at +X) ----
ARM_SPREAD = math.radians(18.0)      # the arms' angle out from the body in the bind pose
UPPER_ARM, FOREARM, HAND = 0.28, 0.25, 0.15
THIGH, SHIN = 0.42, 0.42
_ARM = np.array([math.sin(ARM_SPREAD), -math.cos(ARM_SPREAD), 0.0])


def _joints():
    """(name, parent index, bind position (m)) of every joint, parents first."""
    j = [("hips", -1, (0.0, 0.95, 0.0)),
         ("spine", 0, (0.0, 1.07, 0.0)),
         ("chest", 1, (0.0, 1.25, 0.0)),
         ("neck", 2, (0.0, 1.45, 0.0)),
         ("head", 3, (0.0, 1.56, 0.0))]
    for side, s in (("l", 1.0), ("r", -1.0)):
        arm = _ARM * np.array([s, 1.0, 1.0])
        shoulder = np.array([0.18 * s, 1.42, 0.0])
        elbow = shoulder + UPPER_ARM * arm
        wrist = elbow + FOREARM * arm
        base = len(j)
        j += [(f"{side}_shoulder", 2, tuple(shoulder)), (f"{side}_elbow", base, tuple(elbow)),
              (f"{side}_wrist", base + 1, tuple(wrist))]
    for side, s in (("l", 1.0), ("r", -1.0)):
        base = len(j)
        j += [(f"{side}_upleg", 0, (0.10 * s, 0.92, 0.0)), (f"{side}_knee", base, (0.10 * s, 0.50, 0.0)),
              (f"{side}_ankle", base + 1, (0.10 * s, 0.08, 0.0))]
    return j


JOINTS = _joints()
NAMES = [name for name, _, _ in JOINTS]
PARENT = np.array([p for _, p, _ in JOINTS])
BIND = np.array([pos for _, _, pos in JOINTS])
INDEX = {name: k for k, name in enumerate(NAMES)}


def joint_paths() -> list[str]:
    """UsdSkel joint paths: each joint's ancestors' names and its own, joined by '/'."""
    paths = []
    for k, (name, parent, _) in enumerate(JOINTS):
        paths.append(name if parent < 0 else f"{paths[parent]}/{name}")
    return paths


# -- the body's rest shape: a field, negative inside ---------------------------------------------

def _segment_distance(p, a, b):
    """Distance of points p (n, 3) to the segment a-b, and the parameter t in [0, 1] nearest."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    ab = b - a
    t = np.clip((p - a) @ ab / (ab @ ab), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1), t


def _capsule(p, a, b, r0, r1):
    """A capsule from a to b whose radius goes from r0 to r1 (a field, not exactly a distance)."""
    d, t = _segment_distance(p, a, b)
    return d - (r0 + (r1 - r0) * t)


def _ellipsoid(p, centre, radii):
    """An ellipsoid's field, scaled to be a distance near its surface."""
    radii = np.asarray(radii, float)
    q = (p - np.asarray(centre, float)) / radii
    return (np.linalg.norm(q, axis=1) - 1.0) * radii.min()


def _smooth_union(a, b, k):
    """Polynomial smooth minimum (blend width k, m): the union, rounded where the two meet."""
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b + (a - b) * h - k * h * (1.0 - h)


BLEND = 0.035     # (m) how wide limbs blend into the torso


def _parts():
    """The body's parts: (kind, arguments) in the bind pose."""
    P = {name: BIND[k] for k, name in enumerate(NAMES)}
    parts = [("ellipsoid", (0.0, 0.94, -0.01), (0.165, 0.12, 0.115)),        # pelvis
             ("ellipsoid", (0.0, 1.09, 0.0), (0.135, 0.13, 0.10)),            # waist
             ("ellipsoid", (0.0, 1.29, 0.0), (0.165, 0.16, 0.112)),           # chest
             ("capsule", (-0.17, 1.40, 0.0), (0.17, 1.40, 0.0), 0.06, 0.06),  # shoulders
             ("capsule", (0.0, 1.40, 0.0), (0.0, 1.57, 0.0), 0.05, 0.048),    # neck
             ("ellipsoid", (0.0, 1.65, 0.012), (0.09, 0.115, 0.10))]          # head
    for s in ("l", "r"):
        hand = P[f"{s}_wrist"] + HAND * _ARM * np.array([1.0 if s == "l" else -1.0, 1.0, 1.0])
        parts += [("capsule", P[f"{s}_shoulder"], P[f"{s}_elbow"], 0.05, 0.04),
                  ("capsule", P[f"{s}_elbow"], P[f"{s}_wrist"], 0.04, 0.032),
                  ("capsule", P[f"{s}_wrist"], hand, 0.034, 0.03),
                  ("capsule", P[f"{s}_upleg"] + [0.0, 0.01, 0.0], P[f"{s}_knee"], 0.075, 0.05),
                  ("capsule", P[f"{s}_knee"], P[f"{s}_ankle"], 0.05, 0.036),
                  ("capsule", P[f"{s}_ankle"] + [0.0, -0.035, -0.03], P[f"{s}_ankle"] + [0.0, -0.04, 0.13],
                   0.04, 0.036)]
    return parts


def body_field(p: np.ndarray) -> np.ndarray:
    """The rest shape's field at points p (n, 3): negative inside, about the distance near the
    surface."""
    value = None
    for kind, *args in _parts():
        f = _ellipsoid(p, *args) if kind == "ellipsoid" else _capsule(p, *args)
        value = f if value is None else _smooth_union(value, f, BLEND)
    return value


def field_gradient(p: np.ndarray, h: float = 1e-4) -> np.ndarray:
    """The field's gradient by central differences."""
    g = np.empty_like(p)
    for axis in range(3):
        e = np.zeros(3)
        e[axis] = h
        g[:, axis] = (body_field(p + e) - body_field(p - e)) / (2 * h)
    return g


# -- marching tetrahedra ------------------------------------------------------------------------

# the six tetrahedra of a unit cube about its diagonal (0,0,0)-(1,1,1): corners as offsets
_TETS = []
for _order in ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)):
    _c = [np.zeros(3, int)]
    for _axis in _order:
        _c.append(_c[-1] + np.eye(3, dtype=int)[_axis])
    _TETS.append(np.array(_c))
_TETS = np.array(_TETS)            # (6, 4, 3)


def marching_tetrahedra(field, lo, hi, h):
    """The closed surface where `field` is 0 inside the box [lo, hi] sampled every h: vertices
    (on grid edges, linear in the field) and triangles wound outwards (towards field > 0)."""
    axes = [np.arange(lo[a], hi[a] + h / 2, h) for a in range(3)]
    shape = tuple(len(x) for x in axes)
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    values = field(grid)
    values[values == 0.0] = 1e-12        # no grid point exactly on the surface
    flat = lambda ijk: (ijk[..., 0] * shape[1] + ijk[..., 1]) * shape[2] + ijk[..., 2]
    cubes = np.stack(np.meshgrid(*[np.arange(n - 1) for n in shape], indexing="ij"), axis=-1).reshape(-1, 3)
    # only cubes the surface passes through
    corners = flat(cubes[:, None, :] + np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)]))
    inside = values[corners] < 0
    cubes = cubes[inside.any(axis=1) & ~inside.all(axis=1)]
    tets = flat(cubes[:, None, None, :] + _TETS[None]).reshape(-1, 4)   # (t, 4) grid indices
    inside = values[tets] < 0
    count = inside.sum(axis=1)
    edge_key, edge_a, edge_b = {}, [], []
    triangles = []

    def vertex(a, b):
        """Ids of the surface vertices on grid edges (a, b) (arrays), made once per edge."""
        lo_, hi_ = np.minimum(a, b), np.maximum(a, b)
        return lo_ * len(values) + hi_

    for n_in in (1, 2, 3):
        sel = tets[count == n_in]
        ins = inside[count == n_in]
        if not len(sel):
            continue
        # sort each tet's corners: inside first (stable), keeping track of orientation below
        order = np.argsort(~ins, axis=1, kind="stable")
        c = np.take_along_axis(sel, order, axis=1)
        if n_in == 1:
            tris = [(vertex(c[:, 0], c[:, 1]), vertex(c[:, 0], c[:, 2]), vertex(c[:, 0], c[:, 3]))]
        elif n_in == 3:
            tris = [(vertex(c[:, 3], c[:, 0]), vertex(c[:, 3], c[:, 1]), vertex(c[:, 3], c[:, 2]))]
        else:
            e02, e03, e12, e13 = (vertex(c[:, 0], c[:, 2]), vertex(c[:, 0], c[:, 3]),
                                  vertex(c[:, 1], c[:, 2]), vertex(c[:, 1], c[:, 3]))
            tris = [(e02, e03, e13), (e02, e13, e12)]
        for t in tris:
            triangles.append((np.stack(t, axis=1), c))
    keys = np.concatenate([t.reshape(-1) for t, _ in triangles])
    unique, inverse = np.unique(keys, return_inverse=True)
    a, b = unique // len(values), unique % len(values)
    fa, fb = values[a], values[b]
    s = fa / (fa - fb)
    vertices = grid[a] + s[:, None] * (grid[b] - grid[a])
    faces, start = [], 0
    for t, c in triangles:
        f = inverse[start:start + t.size].reshape(-1, 3)
        start += t.size
        # wind outwards: the normal points from the tet's inside corners to its outside ones
        tin = values[c] < 0
        pin = (grid[c] * tin[..., None]).sum(1) / tin.sum(1, keepdims=True)
        pout = (grid[c] * ~tin[..., None]).sum(1) / (~tin).sum(1, keepdims=True)
        v = vertices[f]
        normal = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        flip = np.einsum("ij,ij->i", normal, pout - pin) < 0
        f[flip] = f[flip][:, [0, 2, 1]]
        faces.append(f)
    faces = np.concatenate(faces)
    return vertices, faces


def _weld_short_edges(vertices, faces, shortest):
    """Collapses edges shorter than `shortest` (marching tetrahedra leaves slivers where the
    surface passes near a grid point) into their midpoints, dropping the faces that vanish;
    repeated until none is left. Keeps the surface closed: an edge is collapsed only when its
    ends share exactly two neighbours (the link condition)."""
    while True:
        e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
        length = np.linalg.norm(vertices[e[:, 0]] - vertices[e[:, 1]], axis=1)
        short = np.nonzero(length < shortest)[0]
        if not len(short):
            return vertices, faces
        neighbours = [set() for _ in range(len(vertices))]
        for i, j in e:
            neighbours[i].add(j)
            neighbours[j].add(i)
        merged = np.arange(len(vertices))
        touched = np.zeros(len(vertices), bool)
        done = 0
        for k in short[np.argsort(length[short], kind="stable")]:
            i, j = e[k]
            if touched[i] or touched[j] or len(neighbours[i] & neighbours[j]) != 2:
                continue
            touched[list(neighbours[i] | neighbours[j] | {i, j})] = True
            vertices[i] = 0.5 * (vertices[i] + vertices[j])
            merged[j] = i
            done += 1
        if not done:
            return vertices, faces
        faces = merged[faces]
        faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])]
        used = np.unique(faces)
        renumber = np.full(len(vertices), -1)
        renumber[used] = np.arange(len(used))
        vertices, faces = vertices[used], renumber[faces]


def _project(vertices, steps=3):
    """Newton steps onto the field's zero level."""
    for _ in range(steps):
        g = field_gradient(vertices)
        vertices = vertices - (body_field(vertices) / np.maximum((g * g).sum(1), 1e-12))[:, None] * g
    return vertices


def _relax(vertices, faces, rounds=8, rate=0.5):
    """Each vertex moved part way to its neighbours' mean, then back onto the surface."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    degree = np.bincount(e.ravel(), minlength=len(vertices)).astype(float)
    for _ in range(rounds):
        mean = np.zeros_like(vertices)
        np.add.at(mean, e[:, 0], vertices[e[:, 1]])
        np.add.at(mean, e[:, 1], vertices[e[:, 0]])
        mean /= degree[:, None]
        vertices = _project(vertices + rate * (mean - vertices))
    return vertices


GRID = 0.022       # (m) the marching grid's spacing


def body_mesh():
    """The body's rest mesh: vertices (n, 3) and outward triangles (m, 3)."""
    lo, hi = np.array([-0.50, -0.04, -0.16]), np.array([0.50, 1.80, 0.24])
    vertices, faces = marching_tetrahedra(body_field, lo, hi, GRID)
    vertices, faces = _weld_short_edges(vertices, faces, 0.3 * GRID)
    vertices = _relax(vertices, faces)
    return vertices, faces


# -- skin weights -------------------------------------------------------------------------------

def _bones():
    """Each joint's bone: segments (a, b) and its radius (m), in the bind pose."""
    P = {name: BIND[k] for k, name in enumerate(NAMES)}
    bones = {"hips": ([(P["l_upleg"] + [0, 0.02, 0], P["r_upleg"] + [0, 0.02, 0]), (P["hips"], P["spine"])], 0.13),
             "spine": ([(P["spine"], P["chest"])], 0.12),
             "chest": ([(P["chest"], P["neck"] - [0, 0.03, 0]), (P["l_shoulder"], P["r_shoulder"])], 0.14),
             "neck": ([(P["neck"], P["head"])], 0.05),
             "head": ([(P["head"] + [0, 0.04, 0], P["head"] + [0, 0.16, 0])], 0.10)}
    for s, sign in (("l", 1.0), ("r", -1.0)):
        hand = P[f"{s}_wrist"] + HAND * _ARM * np.array([sign, 1.0, 1.0])
        bones[f"{s}_shoulder"] = ([(P[f"{s}_shoulder"], P[f"{s}_elbow"])], 0.045)
        bones[f"{s}_elbow"] = ([(P[f"{s}_elbow"], P[f"{s}_wrist"])], 0.036)
        bones[f"{s}_wrist"] = ([(P[f"{s}_wrist"], hand)], 0.032)
        bones[f"{s}_upleg"] = ([(P[f"{s}_upleg"], P[f"{s}_knee"])], 0.065)
        bones[f"{s}_knee"] = ([(P[f"{s}_knee"], P[f"{s}_ankle"])], 0.043)
        bones[f"{s}_ankle"] = ([(P[f"{s}_ankle"] + [0, -0.04, -0.03], P[f"{s}_ankle"] + [0, -0.04, 0.13])], 0.04)
    return [bones[name] for name in NAMES]


INFLUENCES = 4


def skin_weights(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Joint indices and weights, (n, INFLUENCES) each, weights summing to 1."""
    bones = _bones()
    measure = np.stack([np.min([_segment_distance(vertices, a, b)[0] for a, b in segs], axis=0) / r
                        for segs, r in bones], axis=1)              # (n, joints)
    nearest = np.argmin(measure, axis=1)
    allowed = np.zeros((len(NAMES), len(NAMES)), bool)
    for k in range(len(NAMES)):
        allowed[k, k] = True
        if PARENT[k] >= 0:
            allowed[k, PARENT[k]] = True
        allowed[k, PARENT == k] = True
    w = np.where(allowed[nearest], np.maximum(measure, 1e-3) ** -4.0, 0.0)
    order = np.argsort(-w, axis=1, kind="stable")[:, :INFLUENCES]
    weights = np.take_along_axis(w, order, axis=1)
    weights /= weights.sum(axis=1, keepdims=True)
    return order.astype(np.int32), weights


# -- the walk -----------------------------------------------------------------------------------

STAND = 0.5           # (s) standing still at the start
RAMP = 0.8            # (s) to reach full speed after that
CYCLE = 1.3           # (s) a gait cycle: two steps
SPEED = 0.42          # (m/s) walking speed
DUTY = 0.6            # of a cycle a foot is on the ground
LIFT = 0.05           # (m) a swinging foot's lift
ANKLE_HEIGHT = 0.08   # (m) above the ground when the foot is flat on it
REACH = 0.835         # (m) hip to ankle of a stance leg (of 0.84: the knees a little bent)
ARM_SWING = math.radians(16.0)
FINE = 240            # samples a second of the walk's time integrals


def _smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _rot(axis: str, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
    m = np.eye(3)
    m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
    return m


class Walk:
    """The walk's pelvis and feet over time, and the joints' local rotations at any time."""

    def __init__(self):
        t = np.arange(0.0, SECONDS + 1.0, 1.0 / FINE)
        self.t = t
        self.speed = SPEED * _smoothstep((t - STAND) / RAMP)
        self.z = np.concatenate([[0.0], np.cumsum(0.5 * (self.speed[1:] + self.speed[:-1]) / FINE)])
        self.feet = {s: self._foot(s) for s in ("l", "r")}
        self.height = self._pelvis_height()

    def _at(self, series, time):
        return np.interp(time, self.t, series)

    def _foot(self, side: str) -> np.ndarray:
        """(samples, 3) ankle positions of one foot: planted, or swinging to its next spot."""
        x = 0.10 if side == "l" else -0.10
        first = STAND + (0.0 if side == "r" else CYCLE / 2)
        swing = (1.0 - DUTY) * CYCLE
        pos = np.zeros((len(self.t), 3))
        pos[:, 0], pos[:, 1] = x, ANKLE_HEIGHT
        planted, start = 0.0, first
        while start < self.t[-1]:
            end = start + swing
            land = self._at(self.z, end) + 0.3 * self._at(self.speed, end) * CYCLE
            during = (self.t >= start) & (self.t < end)
            u = (self.t[during] - start) / swing
            pos[during, 2] = planted + (land - planted) * (0.5 - 0.5 * np.cos(math.pi * u))
            stride = (land - planted) / (SPEED * CYCLE)
            pos[during, 1] = ANKLE_HEIGHT + LIFT * min(stride, 1.0) * np.sin(math.pi * u)
            pos[self.t >= end, 2] = land
            planted, start = land, start + CYCLE
        return pos

    def _pelvis_height(self) -> np.ndarray:
        """The hip joints' height: as high as the planted legs reach (REACH), smoothed."""
        height = np.full(len(self.t), ANKLE_HEIGHT + REACH)
        for foot in self.feet.values():
            planted = foot[:, 1] <= ANKLE_HEIGHT + 1e-9
            dz = foot[:, 2] - self.z
            reach = ANKLE_HEIGHT + np.sqrt(np.maximum(REACH ** 2 - dz ** 2, 0.0))
            height = np.where(planted, np.minimum(height, reach), height)
        kernel = np.hanning(int(0.2 * FINE) | 1)
        kernel /= kernel.sum()
        padded = np.pad(height, len(kernel) // 2, mode="edge")
        return np.convolve(padded, kernel, mode="valid")

    def pose(self, time: float):
        """(root translation (3,), local rotations (joints, 3, 3)) at `time` (s)."""
        gait = float(_smoothstep((time - STAND) / RAMP))
        feet = {s: np.array([self._at(self.feet[s][:, a], time) for a in range(3)]) for s in ("l", "r")}
        # the left leg's lead, 1 when it is furthest ahead (as its swing ends), smooth: the
        # hips turn and the arms swing with it
        ahead = gait * math.cos(2.0 * math.pi * (time - STAND - (0.5 + (1.0 - DUTY)) * CYCLE) / CYCLE)
        # lateral sway over the planted foot, the hips' turn with the forward leg
        phase = 2.0 * math.pi * (time - STAND) / CYCLE
        sway = 0.015 * gait * math.sin(phase)
        yaw = -math.radians(6.0) * ahead
        roll = math.radians(2.5) * gait * math.sin(phase)
        hip_height = self._at(self.height, time)
        root = np.array([sway, hip_height + (BIND[INDEX["hips"]][1] - BIND[INDEX["l_upleg"]][1]),
                         self._at(self.z, time)])
        local = np.repeat(np.eye(3)[None], len(NAMES), axis=0)
        local[INDEX["hips"]] = _rot("y", yaw) @ _rot("z", roll)
        local[INDEX["spine"]] = _rot("y", -0.5 * yaw) @ _rot("x", math.radians(3.0) * gait)
        local[INDEX["chest"]] = _rot("y", -0.9 * yaw) @ _rot("z", -roll)
        local[INDEX["neck"]] = _rot("y", 0.4 * yaw)
        local[INDEX["head"]] = _rot("x", -math.radians(3.0) * gait)
        for s in ("l", "r"):
            forward = -ahead if s == "l" else ahead          # an arm swings with the other leg
            local[INDEX[f"{s}_shoulder"]] = _rot("x", -ARM_SWING * forward)
            local[INDEX[f"{s}_elbow"]] = _rot("x", -math.radians(10.0 + 15.0 * gait * max(forward, 0.0)))
        world_r, world_p = self._world(root, local)
        for s in ("l", "r"):
            self._leg(s, feet[s], local, world_r, world_p)
        return root, local

    @staticmethod
    def _world(root, local):
        """Skeleton-space rotations and positions of every joint."""
        world_r = np.empty_like(local)
        world_p = np.empty((len(NAMES), 3))
        for k in range(len(NAMES)):
            p = PARENT[k]
            if p < 0:
                world_r[k], world_p[k] = local[k], root
            else:
                world_r[k] = world_r[p] @ local[k]
                world_p[k] = world_p[p] + world_r[p] @ (BIND[k] - BIND[p])
        return world_r, world_p

    @staticmethod
    def _leg(side, ankle, local, world_r, world_p):
        """Hip and knee by two-bone inverse kinematics, the knee forward; the foot level."""
        hip, knee, foot = INDEX[f"{side}_upleg"], INDEX[f"{side}_knee"], INDEX[f"{side}_ankle"]
        pelvis = world_r[PARENT[hip]]
        d = pelvis.T @ (ankle - world_p[hip])                 # in the pelvis's frame
        length = min(float(np.linalg.norm(d)), THIGH + SHIN - 1e-4)
        down = d / np.linalg.norm(d)
        cos_bend = (THIGH ** 2 + SHIN ** 2 - length ** 2) / (2 * THIGH * SHIN)
        bend = math.pi - math.acos(max(-1.0, min(1.0, cos_bend)))
        cos_a = (THIGH ** 2 + length ** 2 - SHIN ** 2) / (2 * THIGH * length)
        alpha = math.acos(max(-1.0, min(1.0, cos_a)))
        ahead = np.array([0.0, 0.0, 1.0]) - down[2] * down     # forward, across the leg
        ahead /= np.linalg.norm(ahead)
        thigh = math.cos(alpha) * down + math.sin(alpha) * ahead
        x = np.cross(-thigh, ahead)                            # the knee's hinge axis
        x = x / np.linalg.norm(x)
        y = -thigh
        z = np.cross(x, y)
        local[hip] = np.stack([x, y, z], axis=1)
        local[knee] = _rot("x", bend)
        shin_world = world_r[PARENT[hip]] @ local[hip] @ local[knee]
        local[foot] = shin_world.T                             # the foot level, facing +Z


# -- cloth shapes -------------------------------------------------------------------------------

def _surface_along(origins: np.ndarray, directions: np.ndarray, far: float = 0.5) -> np.ndarray:
    """How far along each ray (origins, unit directions) it first leaves the rest shape: where
    the field first turns from inside to outside out to `far`, bisected; 0 for a ray that
    meets no body."""
    steps = np.linspace(0.0, far, 400)
    f = np.stack([body_field(origins + s * directions) for s in steps], axis=1)   # (n, steps)
    inside = f < 0
    leaves = inside[:, :-1] & ~inside[:, 1:]
    first = np.argmax(leaves, axis=1)
    lo, hi = steps[first], steps[first + 1]
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        out = body_field(origins + mid[:, None] * directions) >= 0
        hi, lo = np.where(out, mid, hi), np.where(out, lo, mid)
    return np.where(leaves.any(axis=1), hi, 0.0)


CLEARANCE = 0.008     # (m) between a cloth's rest shape and the body's surface
CAPE = dict(width=0.46, length=0.82, top=1.40, columns=18, rows=29)
SKIRT = dict(waist=1.03, hem=0.62, hem_radius=0.27, around=40, rows=12)
# one cloth holds both garments, so that its self-collision keeps the cape off the skirt (two
# cloths do not collide with each other)
COSTUME = dict(area_density=0.2, stretch_stiffness=1200.0, bend_stiffness=2e-4, thickness=0.005, friction=0.3)


def cape_mesh(skirt: np.ndarray):
    """The cape's rest shape: a grid (columns x rows, row 0 the top) whose top row lies along
    the back of the shoulders, each column hanging straight down from it, kept CLEARANCE
    outside the body and outside the skirt (its points `skirt`, SKIRT's rings), over which it
    falls. Returns points, triangles and the top row's indices."""
    nx, ny = CAPE["columns"], CAPE["rows"]
    x = np.linspace(-CAPE["width"] / 2, CAPE["width"] / 2, nx)
    y = CAPE["top"] - np.linspace(0.0, CAPE["length"], ny)
    X, Y = np.meshgrid(x, y, indexing="xy")                          # (ny, nx)
    # the body's back along -z at each (x, y): a ray from well inside the body backwards
    origins = np.stack([X.ravel(), Y.ravel(), np.full(X.size, 0.0)], axis=1)
    back = -_surface_along(origins, np.tile([0.0, 0.0, -1.0], (X.size, 1))).reshape(ny, nx)
    back = np.minimum(back, _skirt_back(skirt, X, Y))
    # hanging: never closer to the body than the row above, never inside it
    Z = np.minimum.accumulate(back - CLEARANCE, axis=0)
    points = np.stack([X, Y, Z], axis=-1).reshape(-1, 3)
    tris = _grid_triangles(nx, ny, wrap=False)
    return points, tris, np.arange(nx)


def _skirt_back(skirt: np.ndarray, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """A bound on the skirt's back (its least z) at each (x, y) below its waist, +inf
    elsewhere: each ring's polygon cut by the line at x; between two rings the further out of
    their cuts, below the hem the hem's."""
    rings = skirt.reshape(SKIRT["rows"], SKIRT["around"], 3)
    heights = rings[:, 0, 1]                                          # from the waist down
    cuts = np.full((len(heights), X.shape[1]), np.inf)
    for k in range(len(heights)):
        a = rings[k][:, [0, 2]]
        b = np.roll(a, -1, axis=0)
        for c, x in enumerate(X[0]):
            spans = (a[:, 0] - x) * (b[:, 0] - x) <= 0
            if spans.any():
                dx = np.where(b[spans, 0] != a[spans, 0], b[spans, 0] - a[spans, 0], 1.0)
                t = (x - a[spans, 0]) / dx
                cuts[k, c] = (a[spans, 1] + t * (b[spans, 1] - a[spans, 1])).min()
    z = np.full(X.shape, np.inf)
    for r, height in enumerate(Y[:, 0]):
        if height > heights[0]:
            continue
        below = int(np.searchsorted(-heights, -height))           # the first ring at or below
        k = min(below, len(heights) - 1)
        z[r] = np.minimum(cuts[k], cuts[max(k - 1, 0)])
    return z


def skirt_mesh():
    """The skirt's rest shape: a tube (around x rows, row 0 the waistband) from the waist,
    CLEARANCE outside the body, flaring to a circular hem, kept outside the hips. Returns
    points, triangles and the waistband's indices."""
    n, rows = SKIRT["around"], SKIRT["rows"]
    theta = 2.0 * math.pi * np.arange(n) / n
    ring = np.stack([np.sin(theta), np.zeros(n), np.cos(theta)], axis=1)    # starts in front, turns left
    y = np.linspace(SKIRT["waist"], SKIRT["hem"], rows)
    points = []
    waist = None
    for k, height in enumerate(y):
        centre = np.array([0.0, height, -0.005])
        r_body = _surface_along(np.tile(centre, (n, 1)), ring, far=0.45) + CLEARANCE
        if waist is None:
            waist = r_body
        s = (height - y[0]) / (y[-1] - y[0])
        r = np.maximum(waist + (SKIRT["hem_radius"] - waist) * s ** 0.8, r_body)
        points.append(centre + r[:, None] * ring)
    points = np.concatenate(points)
    # clockwise seen from above so the triangles face outwards
    tris = _grid_triangles(n, rows, wrap=True)
    return points, tris, np.arange(n)


def _keep_clear(points: np.ndarray, rounds: int = 4) -> np.ndarray:
    """Points nearer the body than CLEARANCE (the rays above measure along fixed directions,
    not the surface's normal) moved out along the field's gradient."""
    for _ in range(rounds):
        f = body_field(points)
        near = f < CLEARANCE
        if not near.any():
            break
        g = field_gradient(points[near])
        g /= np.linalg.norm(g, axis=1, keepdims=True)
        points = points.copy()
        points[near] += (CLEARANCE - f[near])[:, None] * g
    return points


def costume_mesh():
    """The skirt, then the cape, as one mesh: points, triangles, the attached points (the
    skirt's waistband and the cape's top row) and each garment's triangles ({name: indices})."""
    skirt, skirt_tris, band = skirt_mesh()
    cape, cape_tris, top = cape_mesh(skirt)
    skirt, cape = _keep_clear(skirt), _keep_clear(cape)
    points = np.concatenate([skirt, cape])
    tris = np.concatenate([skirt_tris, cape_tris + len(skirt)])
    parts = {"skirt": np.arange(len(skirt_tris)), "cape": len(skirt_tris) + np.arange(len(cape_tris))}
    return points, tris, np.concatenate([band, top + len(skirt)]), parts


def _grid_triangles(nx, ny, wrap):
    """Two triangles per quad of an nx x ny grid (row-major); `wrap` closes the rows."""
    cols = nx if wrap else nx - 1
    i, j = np.meshgrid(np.arange(cols), np.arange(ny - 1), indexing="xy")
    p00 = j * nx + i
    p10 = j * nx + (i + 1) % nx
    p01, p11 = p00 + nx, p10 + nx
    return np.concatenate([np.stack([p00, p01, p11], -1).reshape(-1, 3),
                           np.stack([p00, p11, p10], -1).reshape(-1, 3)])


# -- USD --------------------------------------------------------------------------------------

def _matrix(rotation: np.ndarray, translation) -> "Gf.Matrix4d":
    """A rigid transform as USD's row-vector Matrix4d (p' = p M)."""
    from pxr import Gf

    m = np.eye(4)
    m[:3, :3], m[:3, 3] = rotation, translation
    return Gf.Matrix4d(*m.T.ravel().tolist())


def _quat(rotation: np.ndarray):
    """A rotation matrix as a unit quaternion (w, x, y, z), w >= 0."""
    m = rotation
    w = math.sqrt(max(0.0, 1.0 + m[0, 0] + m[1, 1] + m[2, 2])) / 2
    x = math.copysign(math.sqrt(max(0.0, 1.0 + m[0, 0] - m[1, 1] - m[2, 2])) / 2, m[2, 1] - m[1, 2])
    y = math.copysign(math.sqrt(max(0.0, 1.0 - m[0, 0] + m[1, 1] - m[2, 2])) / 2, m[0, 2] - m[2, 0])
    z = math.copysign(math.sqrt(max(0.0, 1.0 - m[0, 0] - m[1, 1] + m[2, 2])) / 2, m[1, 0] - m[0, 1])
    q = np.array([w, x, y, z])
    return q / np.linalg.norm(q)


def _stage(path: Path, end: int):
    """A shot's stage (generate_shots.new_stage: metres, Y up, FPS) with a ground Plane."""
    import importlib.util

    from pxr import UsdGeom, UsdPhysics

    spec = importlib.util.spec_from_file_location("generate_shots", HERE / "generate_shots.py")
    shots = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(shots)
    stage = shots.new_stage(path, "generate_character.py", START, end, FPS)
    ground = UsdGeom.Plane.Define(stage, "/World/Ground")
    ground.CreateAxisAttr("Y")
    ground.CreateWidthAttr(12.0)
    ground.CreateLengthAttr(12.0)
    UsdPhysics.CollisionAPI.Apply(ground.GetPrim())
    return stage


def _mesh(stage, path: str, points: np.ndarray, triangles: np.ndarray):
    from pxr import UsdGeom, Vt

    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(points, dtype=np.float32)))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(triangles), 3, dtype=np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(triangles, dtype=np.int32).ravel()))
    mesh.CreateSubdivisionSchemeAttr("none")
    lo, hi = points.min(axis=0), points.max(axis=0)
    mesh.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.array([lo, hi], dtype=np.float32)))
    return mesh


def _cloth(stage, path: str, points, triangles, attached, target: str, material: dict):
    """A SimbakeClothAPI mesh attached by `attached` (point indices) to the prim `target`."""
    from pxr import Sdf, Vt

    mesh = _mesh(stage, path, points, triangles)
    mesh.CreateDoubleSidedAttr(True)
    prim = mesh.GetPrim()
    prim.AddAppliedSchema("SimbakeClothAPI")
    for key in ("area_density", "stretch_stiffness", "bend_stiffness", "thickness", "friction"):
        name = key.split("_")[0] + "".join(w.title() for w in key.split("_")[1:])
        # custom=False: the same file whether or not SimbakeClothAPI's schema is registered
        prim.CreateAttribute(f"simbake:cloth:{name}", Sdf.ValueTypeNames.Float, custom=False).Set(material[key])
    prim.CreateRelationship("simbake:cloth:attachTo", custom=False).SetTargets([Sdf.Path(target)])
    prim.CreateAttribute("simbake:cloth:attached", Sdf.ValueTypeNames.IntArray, custom=False).Set(
        Vt.IntArray([int(i) for i in attached]))
    return mesh


def write_character(path: Path, end: int = END) -> Path:
    """The walking character with its cape and skirt, frames START .. end."""
    from pxr import Gf, UsdGeom, UsdPhysics, UsdSkel, Vt

    stage = _stage(path, end)
    UsdSkel.Root.Define(stage, "/World/Character")
    skeleton = UsdSkel.Skeleton.Define(stage, "/World/Character/Skel")
    skeleton.CreateJointsAttr(Vt.TokenArray(joint_paths()))
    skeleton.CreateBindTransformsAttr(Vt.Matrix4dArray([_matrix(np.eye(3), p) for p in BIND]))
    rest = [_matrix(np.eye(3), BIND[k] - (BIND[PARENT[k]] if PARENT[k] >= 0 else 0.0)) for k in range(len(NAMES))]
    skeleton.CreateRestTransformsAttr(Vt.Matrix4dArray(rest))
    anim = UsdSkel.Animation.Define(stage, "/World/Character/Skel/Walk")
    anim.CreateJointsAttr(Vt.TokenArray(joint_paths()))
    anim.CreateScalesAttr(Vt.Vec3hArray([Gf.Vec3h(1.0, 1.0, 1.0)] * len(NAMES)))
    translations, rotations = anim.CreateTranslationsAttr(), anim.CreateRotationsAttr()
    offsets = np.array([BIND[k] - (BIND[PARENT[k]] if PARENT[k] >= 0 else 0.0) for k in range(len(NAMES))])
    walk = Walk()
    for frame in range(START, end + 1):
        root, local = walk.pose((frame - START) / FPS)
        moved = offsets.copy()
        moved[INDEX["hips"]] = root
        translations.Set(Vt.Vec3fArray.FromNumpy(moved.astype(np.float32)), frame)
        rotations.Set(Vt.QuatfArray([Gf.Quatf(*_quat(r)) for r in local]), frame)
    UsdSkel.BindingAPI.Apply(skeleton.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])

    vertices, faces = body_mesh()
    body = _mesh(stage, "/World/Character/Body", vertices, faces)
    UsdPhysics.CollisionAPI.Apply(body.GetPrim())
    binding = UsdSkel.BindingAPI.Apply(body.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skeleton.GetPath()])
    indices, weights = skin_weights(vertices)
    binding.CreateJointIndicesPrimvar(False, INFLUENCES).Set(Vt.IntArray.FromNumpy(indices.ravel()))
    binding.CreateJointWeightsPrimvar(False, INFLUENCES).Set(Vt.FloatArray.FromNumpy(weights.astype(np.float32).ravel()))
    binding.CreateGeomBindTransformAttr(Gf.Matrix4d(1.0))
    binding.CreateSkinningMethodAttr("classicLinear")

    points, tris, attached, parts = costume_mesh()
    costume = _cloth(stage, "/World/Costume", points, tris, attached, "/World/Character/Body", COSTUME)
    for name, faces in parts.items():
        UsdGeom.Subset.CreateGeomSubset(costume, name, UsdGeom.Tokens.face, Vt.IntArray.FromNumpy(
            faces.astype(np.int32)), "garment", UsdGeom.Tokens.partition)
    stage.GetRootLayer().Save()
    return path


# -- the flag carried on a keyed arm ------------------------------------------------------------

FLAG_SECONDS = 4.0
FLAG_END = START + int(round(FLAG_SECONDS * FPS))
SHOULDER = (0.22, 1.42, 0.0)      # (m) the arm's origin at the start
ELBOW, FIST = (0.02, -0.26, 0.06), (0.04, -0.16, 0.30)               # (m) in the arm's frame
POLE = dict(radius=0.016, below=0.45, above=1.05)   # (m) the pole along the arm's y through the fist
FLAG = dict(width=0.80, height=0.52, columns=25, rows=17, area_density=0.15, stretch_stiffness=1000.0,
            bend_stiffness=1e-4, thickness=0.004, friction=0.3)


def arm_pose(time: float):
    """The arm's pose at `time` (s): the shoulder's position and the arm's rotation about it.
    It stands still for STAND s, then walks forward (+Z) at 0.6 m/s, bobbing, while the arm
    waves the pole in a figure of eight (side to side, and forward and back twice as fast)."""
    gait = float(_smoothstep((time - STAND) / RAMP))
    go = max(time - STAND, 0.0)
    x = min(go / RAMP, 1.0)                                # the walk's distance: 0.6 m/s ramped up
    walked = 0.6 * (RAMP * (x ** 3 - x ** 4 / 2) + max(go - RAMP, 0.0))
    w = 2.0 * math.pi / 1.6
    position = np.array([SHOULDER[0], SHOULDER[1] + 0.015 * gait * math.sin(2 * w * go), SHOULDER[2] + walked])
    rotation = _rot("z", math.radians(18.0) * gait * math.sin(w * go)) @ \
        _rot("x", math.radians(9.0) * gait * math.sin(2 * w * go))
    return position, rotation


def flag_mesh():
    """The flag's rest shape: a grid in the arm's x-y plane out from the pole (columns along
    x, rows down y, row-major); its column 0 along the pole, just off it. Points in the arm's
    frame, triangles and the pole column's indices."""
    nx, ny = FLAG["columns"], FLAG["rows"]
    x0 = FIST[0] + POLE["radius"] + FLAG["thickness"] + 0.002
    x = x0 + np.linspace(0.0, FLAG["width"], nx)
    y = FIST[1] + POLE["above"] - 0.03 - np.linspace(0.0, FLAG["height"], ny)
    X, Y = np.meshgrid(x, y, indexing="xy")
    points = np.stack([X, Y, np.full_like(X, FIST[2])], axis=-1).reshape(-1, 3)
    return points, _grid_triangles(nx, ny, wrap=False), np.arange(ny) * nx


def _between(stage, path: str, a, b, radius: float):
    """A Capsule from a to b (its axis Z turned onto b - a)."""
    from pxr import Gf, UsdGeom

    a, b = np.asarray(a, float), np.asarray(b, float)
    d = (b - a) / np.linalg.norm(b - a)
    x = np.cross([0.0, 1.0, 0.0], d)
    x /= np.linalg.norm(x)
    q = _quat(np.stack([x, np.cross(d, x), d], axis=1))
    capsule = UsdGeom.Capsule.Define(stage, path)
    capsule.CreateAxisAttr("Z")
    capsule.CreateRadiusAttr(radius)
    capsule.CreateHeightAttr(float(np.linalg.norm(b - a)))
    capsule.AddTranslateOp().Set(Gf.Vec3d(*(0.5 * (a + b))))
    capsule.AddOrientOp().Set(Gf.Quatf(*(float(c) for c in q)))
    return capsule


def write_flag_carried(path: Path, end: int = FLAG_END) -> Path:
    """The keyed arm waving the flag, frames START .. end."""
    from pxr import Gf, UsdGeom, UsdPhysics

    stage = _stage(path, end)
    arm = UsdGeom.Xform.Define(stage, "/World/Arm")
    UsdPhysics.RigidBodyAPI.Apply(arm.GetPrim()).CreateKinematicEnabledAttr(True)
    translate, orient = arm.AddTranslateOp(), arm.AddOrientOp()
    for frame in range(START, end + 1):
        position, rotation = arm_pose((frame - START) / FPS)
        translate.Set(Gf.Vec3d(*position), frame)
        orient.Set(Gf.Quatf(*(float(c) for c in _quat(rotation))), frame)
    parts = [_between(stage, "/World/Arm/UpperArm", (0.0, 0.0, 0.0), ELBOW, 0.05),
             _between(stage, "/World/Arm/Forearm", ELBOW, FIST, 0.04)]
    fist = UsdGeom.Sphere.Define(stage, "/World/Arm/Fist")
    fist.CreateRadiusAttr(0.05)
    fist.AddTranslateOp().Set(Gf.Vec3d(*FIST))
    pole = UsdGeom.Cylinder.Define(stage, "/World/Arm/Pole")
    pole.CreateAxisAttr("Y")
    pole.CreateRadiusAttr(POLE["radius"])
    pole.CreateHeightAttr(POLE["below"] + POLE["above"])
    pole.AddTranslateOp().Set(Gf.Vec3d(FIST[0], FIST[1] + 0.5 * (POLE["above"] - POLE["below"]), FIST[2]))
    for part in (*parts, fist, pole):
        UsdPhysics.CollisionAPI.Apply(part.GetPrim())
    local, tris, column = flag_mesh()
    position, rotation = arm_pose(0.0)
    _cloth(stage, "/World/Flag", local @ rotation.T + position, tris, column, "/World/Arm", FLAG)
    stage.GetRootLayer().Save()
    return path


def main() -> None:
    write_character(HERE / "character.usda")
    write_flag_carried(HERE / "flag_carried.usda")


if __name__ == "__main__":
    main()
