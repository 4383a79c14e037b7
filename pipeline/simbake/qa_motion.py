"""Motion figures of the QA (simbake.qa): what no solver step should do, measured from the
bodies' states at every written frame.

* ``energy_gain`` (J): the total energy now less the energy at the start, E(f) - E(start),
  with E = kinetic + gravitational potential (dynamic bodies and cloths) + the cloths' elastic
  energy. When bodies start inside each other (deeper than the penetration threshold), the
  count starts at the first frame they no longer are: pushing them apart makes energy, and
  the penetration figure already says why. Without a source of energy (a keyed or moving kinematic body) friction, damping and
  inelastic contact can only take energy away, so a gain is the solver making it up (an
  impossible inertia, too few substeps). Threshold: ``ENERGY_GAIN`` of the largest kinetic
  energy of the bake, plus the energy of everything falling ``ENERGY_FLOOR_HEIGHT`` and
  moving at ``ENERGY_FLOOR_SPEED`` (resting contacts' round-off, bodies that start a little
  inside each other pushed apart); no threshold when the scene has a source.
* ``unexplained_stop`` (m/s): the speed a dynamic body lost over a frame while nothing was
  near it: it was going at least ``STOP_SPEED`` and lost more than half of that, and at the
  end of the frame its bounding sphere is more than ``CLEAR_GAP`` from the ground, from every
  other body's bounding sphere anywhere along that body's path over the frame, and from every
  cloth's bounds. The scheme detects a collision at the step's end and changes the velocity at
  its start, so a fast body with too few substeps stops in mid-air, short of what it hit.
  Threshold: 0 (any such stop).
* ``imparted_speed`` (m/s): how much faster the fastest dynamic body goes than anything in the
  scene could make it without a keyed body: its speed less the largest speed at the start
  (spin at the rim included) and what gravity adds in the time since, v - (v0 + |g| t).
  Energy bounds this by 0 without a source; a keyed body can add up to twice its own speed.
  Threshold: ``IMPARTED_SPEED`` (100 m/s, 360 km/h: beyond what a shot's keyed prop gives,
  a sign of a key that jumps between frames).
"""

from __future__ import annotations

import numpy as np

ENERGY_GAIN = 0.1            # of the bake's largest kinetic energy
ENERGY_FLOOR_HEIGHT = 0.01   # (m): everything falling 1 cm ...
ENERGY_FLOOR_SPEED = 0.1     # (m/s) ... and moving at 0.1 m/s: the floor of the energy threshold
STOP_SPEED = 1.0             # (m/s): slower bodies stop by friction and sleep
CLEAR_GAP = 0.1              # (m) between bounding spheres (or to the ground, a cloth's bounds)
IMPARTED_SPEED = 100.0       # (m/s)
_FULL_MATRIX = 4096          # pairs: fewer are tested all at once, without the grid
_ROUND_OFF = 1e-9            # (m): far above the round-off of distances of a scene's size


def _moving_kinematic(body) -> bool:
    return body.kinematic and (bool(body.keys) or any(body.linear_velocity) or any(body.angular_velocity)
                               or body.deformation is not None)


def _segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance of each point (n, 3) to each segment a_j b_j (m, 3): (n, m)."""
    ab = b - a
    length2 = np.einsum("ij,ij->i", ab, ab)
    ap = points[:, None, :] - a[None, :, :]
    t = np.clip(np.einsum("nmk,mk->nm", ap, ab) / np.where(length2 > 0, length2, 1.0), 0.0, 1.0)
    closest = a[None, :, :] + t[..., None] * ab[None, :, :]
    return np.linalg.norm(points[:, None, :] - closest, axis=-1)


def _any_within(bodies: np.ndarray, origins: np.ndarray, radii: np.ndarray, gap: float) -> np.ndarray:
    """For each of `bodies`, whether the bounding sphere (origins, radii) of another body is
    within `gap` of its own: |o_j - o_i| - r_i - r_j <= gap. Pairs come from a grid of cubes
    as wide as the widest two spheres and the gap (a pair further apart along an axis is
    further apart than that), each tested as a full matrix of every body would be."""
    if not len(bodies):
        return np.zeros(0, dtype=bool)
    if len(bodies) * len(origins) <= _FULL_MATRIX:  # few: every pair, as the grid's would be
        rows = np.repeat(np.arange(len(bodies)), len(origins))
        i, cols = bodies[rows], np.tile(np.arange(len(origins)), len(bodies))
        keep = cols != i
        rows, i, cols = rows[keep], i[keep], cols[keep]
        ends = np.linalg.norm(origins[cols] - origins[i], axis=-1) - radii[i] - radii[cols]
        return np.bincount(rows[ends <= gap], minlength=len(bodies)) > 0
    cube = (2.0 * float(radii.max()) + max(gap, 0.0)) * (1.0 + 1e-9) + 1e-9
    cells = np.floor(origins / cube).astype(np.int64)
    cells -= cells.min(axis=0)
    span = cells.max(axis=0) + 3
    keys = (cells[:, 0] * span[1] + cells[:, 1]) * span[2] + cells[:, 2]
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    offsets = np.array([(dx * span[1] + dy) * span[2] + dz
                        for dx in (-1, 0, 1) for dy in (-1, 0, 1) for dz in (-1, 0, 1)])
    wanted = (keys[bodies][:, None] + offsets[None, :]).ravel()
    lo = np.searchsorted(sorted_keys, wanted, "left")
    counts = np.searchsorted(sorted_keys, wanted, "right") - lo
    rows = np.repeat(np.repeat(np.arange(len(bodies)), len(offsets)), counts)
    starts = np.repeat(lo - np.concatenate(([0], np.cumsum(counts)[:-1])), counts)
    cols = order[starts + np.arange(len(rows))]
    i = bodies[rows]
    keep = cols != i
    rows, i, cols = rows[keep], i[keep], cols[keep]
    ends = np.linalg.norm(origins[cols] - origins[i], axis=-1) - radii[i] - radii[cols]
    return np.bincount(rows[ends <= gap], minlength=len(bodies)) > 0


class MotionFigures:
    """Measures the three figures above frame by frame; `radii` (m) bound each body's mesh
    about its mesh origin, `cloth_masses` are each cloth's lumped vertex masses (kg)."""

    def __init__(self, scene, masses: np.ndarray, radii: np.ndarray, cloth_masses: list[np.ndarray]):
        self.gravity = np.asarray(scene.gravity, dtype=np.float64)
        self._g = float(np.linalg.norm(self.gravity))
        self._up = -self.gravity / self._g if self._g > 0 else np.array([0.0, 1.0, 0.0])
        self.ground = scene.ground.height if scene.ground is not None else None
        self.dynamic = np.array([not b.kinematic for b in scene.bodies], dtype=bool)
        self._dynamic = np.flatnonzero(self.dynamic)
        # (a joint drive is a motor: a source too)
        self.has_source = (any(_moving_kinematic(b) for b in scene.bodies)
                           or any(j.drives and j.enabled for j in getattr(scene, "joints", ())))
        self.masses, self.radii = np.asarray(masses, dtype=np.float64), np.asarray(radii, dtype=np.float64)
        self.cloth_masses = cloth_masses
        self.total_mass = float(self.masses[self.dynamic].sum() + sum(m.sum() for m in cloth_masses))
        self.start_time = None
        self.start_energy = None  # the baseline: at the start, or once a starting overlap is gone
        self.start_speed = 0.0
        self.largest_kinetic = 0.0
        self._speeds = None       # each dynamic body's speed at the last frame (m/s)
        self._origins = None      # every body's mesh origin at the last frame (m)

    # -- state -------------------------------------------------------------------------------

    def _rigid(self, world):
        """Velocities, energies and the fastest rim speed of the dynamic bodies now (at the
        start only: later frames take their energies from the core's statistics)."""
        if not len(self._dynamic):
            return np.zeros((0, 3)), 0.0, 0.0, 0.0
        if self.start_time is not None:
            v = world.linear_velocities()
            return (v if len(self._dynamic) == len(v) else v[self._dynamic]), 0.0, 0.0, 0.0
        states = world.body_states()
        x, v, w = (np.asarray(states[key])[self.dynamic] for key in ("center_of_mass", "linear_velocity", "angular_velocity"))
        spin = np.einsum("ij,ij->i", w, np.asarray(states["angular_momentum"])[self.dynamic])
        m = self.masses[self.dynamic]
        kinetic = float(0.5 * (m * np.einsum("ij,ij->i", v, v)).sum() + 0.5 * spin.sum())
        potential = float(-(m * (x @ self.gravity)).sum())
        rim = np.linalg.norm(w, axis=1) * self.radii[self.dynamic]
        return v, kinetic, potential, float((np.linalg.norm(v, axis=1) + rim).max())

    def _start_energy(self, world, kinetic: float, potential: float) -> float:
        """The energy at the start, before any step (the core's statistics are not yet
        gathered): the cloths rest in their rest shape, still."""
        for k, masses in enumerate(self.cloth_masses):
            points = np.asarray(world.cloth_state(k)[0])
            potential -= float(masses @ (points @ self.gravity))
        return kinetic + potential

    # -- per frame ---------------------------------------------------------------------------

    def record(self, world, time: float, origins: np.ndarray, overlapping: bool = False) -> dict:
        """The figures of `world` at `time` (s); `origins` (bodies, 3) are the mesh origins;
        `overlapping`: bodies are inside each other deeper than the penetration threshold."""
        velocities, kinetic, potential, fastest = self._rigid(world)
        x, y, z = velocities.T
        speeds = np.sqrt(x * x + y * y + z * z)  # (np.linalg.norm's sum, in its order)
        if self.start_time is None:
            self.start_time = time
            energy = self._start_energy(world, kinetic, potential)
            self.start_speed = fastest
        else:
            stats = world.statistics(penetrations=False)
            energy = stats["kinetic_energy"] + stats["potential_energy"] + stats["elastic_energy"]
            kinetic = stats["kinetic_energy"]
        if self.start_energy is None and not overlapping:
            self.start_energy = energy
        self.largest_kinetic = max(self.largest_kinetic, kinetic)
        stop, stopped = self._unexplained_stop(world, speeds, origins)
        self._speeds, self._origins = speeds, np.array(origins, dtype=np.float64)
        free = self.start_speed + self._g * (time - self.start_time)
        fastest = int(np.argmax(speeds)) if len(speeds) else -1
        return {"energy_gain": max(0.0, energy - self.start_energy) if self.start_energy is not None else 0.0,
                "unexplained_stop": stop, "stopped_body": stopped,
                "imparted_speed": max(0.0, float(speeds.max(initial=0.0)) - free),
                "fastest_body": int(self._dynamic[fastest]) if fastest >= 0 else -1}

    def _unexplained_stop(self, world, speeds: np.ndarray, origins: np.ndarray) -> tuple[float, int]:
        """(speed lost, body index) of the largest stop clear of everything, or (0, -1); on a
        tie the first body."""
        if self._speeds is None or not len(speeds):
            return 0.0, -1
        lost = self._speeds - speeds
        stopped = np.flatnonzero((self._speeds >= STOP_SPEED) & (lost > 0.5 * self._speeds))
        if not len(stopped):
            return 0.0, -1
        origins = np.asarray(origins, dtype=np.float64)
        bodies = np.flatnonzero(self.dynamic)[stopped]
        # the quick tests for all at once (most stopped bodies in a pile touch another), then
        # the rest body by body, the largest loss first (a stable sort: the first on a tie)
        near = ~self._clear_at_end(bodies, origins)
        for k in np.argsort(-lost[stopped], kind="stable"):
            if not near[k] and self._clear_on_path(world, int(bodies[k]), origins):
                return float(lost[stopped[k]]), int(bodies[k])
        return 0.0, -1

    def _clear_at_end(self, bodies: np.ndarray, origins: np.ndarray) -> np.ndarray:
        """Whether each of `bodies` ends the frame farther than CLEAR_GAP from the ground and
        from every other body's bounding sphere."""
        here, r = origins[bodies], self.radii[bodies]
        clear = np.ones(len(bodies), dtype=bool)
        if self.ground is not None:
            clear &= here @ self._up - r - self.ground > CLEAR_GAP
        if len(origins) > 1:
            # a body within the gap where it ends the frame is within it along its path too
            # (the path's distance is at most the end's; the margin covers round-off)
            left = np.flatnonzero(clear)
            clear[left] = ~_any_within(bodies[left], origins, self.radii, CLEAR_GAP - _ROUND_OFF)
        return clear

    def _clear_on_path(self, world, body: int, origins: np.ndarray) -> bool:
        """Whether `body`, clear at the end of the frame (_clear_at_end), was farther than
        CLEAR_GAP from every other body's path over the frame and ends it so from every
        cloth's bounds."""
        here, r = origins[body:body + 1], self.radii[body]
        if len(origins) > 1:
            others = np.delete(np.arange(len(origins)), body)
            gaps = _segment_distance(here, self._origins[others], origins[others])[0] - r - self.radii[others]
            if gaps.min() <= CLEAR_GAP:
                return False
        for k in range(len(self.cloth_masses)):
            points = np.asarray(world.cloth_state(k)[0])
            outside = np.maximum(points.min(axis=0) - here[0], 0) + np.maximum(here[0] - points.max(axis=0), 0)
            if np.linalg.norm(outside) - r <= CLEAR_GAP:
                return False
        return True

    # -- thresholds --------------------------------------------------------------------------

    def thresholds(self) -> dict[str, float | None]:
        floor = self.total_mass * (float(np.linalg.norm(self.gravity)) * ENERGY_FLOOR_HEIGHT
                                   + 0.5 * ENERGY_FLOOR_SPEED ** 2)
        return {"energy_gain": None if self.has_source else ENERGY_GAIN * self.largest_kinetic + floor + 1e-9,
                "unexplained_stop": 0.0,
                "imparted_speed": IMPARTED_SPEED}


def lumped_masses(vertices: np.ndarray, triangles: np.ndarray, area_density: float) -> np.ndarray:
    """A cloth's vertex masses as the core lumps them: a third of each triangle's mass (kg)."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    third = area_density * 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1) / 3.0
    masses = np.zeros(len(vertices))
    for k in range(3):
        np.add.at(masses, triangles[:, k], third)
    return masses


def mean_edge(vertices: np.ndarray, triangles: np.ndarray) -> float:
    """The mean length of a mesh's triangle edges (each counted once per triangle side) (m)."""
    if not len(triangles):
        return 0.0
    p = vertices[triangles]
    return float(np.linalg.norm(p - np.roll(p, 1, axis=1), axis=2).mean())


def bounding_radius(vertices: np.ndarray) -> float:
    """The radius about the mesh origin that holds the whole mesh (m)."""
    return float(np.linalg.norm(vertices, axis=1).max()) if len(vertices) else 0.0

