"""The cloth benchmark's one problem, shared by every engine's runner: a square cloth
dropped onto a sphere and the ground (assets/scenes/drape.toml at several resolutions).

Y up, SI units. Engines with Z up convert at their boundary (x, y, z) -> (x, -z, y).

Every runner reports, as one JSON line (see `report`):
- wall seconds per simulated second of the stepping alone (model building excluded),
- peak resident memory of the process (MiB),
- the deepest penetration of any cloth vertex into the sphere or the ground over all frames
  (m, past the surface itself: thickness is not subtracted),
- the largest edge strain |l|/L - 1 over all frames (grid edges, diagonals excluded, so that
  every engine is measured on the same edges whatever its triangulation),
- layers through layers: crossing pairs of non-adjacent triangles (crossings.py, NumPy alone)
  every CROSSING_EVERY frames and at the last, the most at any of them and when; every engine's
  vertices are triangulated as grid() does, so the count is the same code on the same
  triangles (an engine splitting its quads the other way is measured on ours),
- the positions, at SHAPE_TIMES, of the 17 x 17 material points common to every resolution
  (resolution 16 k + 1 vertices a side), row-major: point (i, j), i along x and j along z,
  is at index j * 17 + i. compare.py turns these into shape errors against a reference run.
"""

from __future__ import annotations

import json
import resource
import numpy as np

if __package__:  # imported as benchmarks.cloth.drape_spec (simbake's own benchmarks)
    from .crossings import crossing_count
else:            # beside a peer engine's runner, which runs as a file in that engine's Python
    from crossings import crossing_count

SIZE = 2.0                    # cloth side (m)
HEIGHT = 1.2                  # cloth plane's height (m), centred over the sphere
SPHERE_RADIUS = 0.5
SPHERE_CENTER = (0.0, 0.5, 0.0)
GROUND = 0.0
GRAVITY = 9.81
AREA_DENSITY = 0.1            # kg/m^2
STRETCH = 2000.0              # the sheet's stiffness, Young's modulus x thickness (N/m): a grid
                              # pulled along an axis resists with this (simbake's springs and membrane)
BEND = 1e-4                   # N m
THICKNESS = 0.005             # m, the collision distance
FRICTION = 0.4                # cloth against sphere and ground (simbake combines sqrt(mu_a mu_b))
FPS = 24
SECONDS = 3.0
FRAMES = int(round(SECONDS * FPS))
SHAPE_TIMES = (0.5, 1.0, 3.0) # s
COMMON = 17                   # common material points a side
RESOLUTIONS = (17, 33, 65, 129, 257)
CROSSING_EVERY = 6            # frames between crossing counts (4 a second)


def grid(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The n x n vertex grid at its start, index j * n + i (i along x, j along z), and its
    triangles wound counter-clockwise seen from +y (assets.grid_mesh's layout)."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="xy")
    x = (i / (n - 1) - 0.5) * SIZE
    z = (j / (n - 1) - 0.5) * SIZE
    vertices = np.stack([x, np.full_like(x, HEIGHT, dtype=float), z], -1).reshape(-1, 3)
    p00 = (j[:-1, :-1] * n + i[:-1, :-1]).ravel()
    p10, p01, p11 = p00 + 1, p00 + n, p00 + n + 1
    triangles = np.concatenate([np.stack([p00, p01, p11], -1), np.stack([p00, p11, p10], -1)])
    return vertices.astype(np.float64), triangles.astype(np.int32)


def common_indices(n: int) -> np.ndarray:
    """Indices, in the n x n grid, of the 17 x 17 common material points (row-major)."""
    if (n - 1) % (COMMON - 1):
        raise ValueError(f"resolution {n} is not 16 k + 1")
    step = (n - 1) // (COMMON - 1)
    j, i = np.meshgrid(np.arange(COMMON) * step, np.arange(COMMON) * step, indexing="ij")
    return (j * n + i).ravel()


def grid_edges(n: int) -> np.ndarray:
    """The (i, j) pairs of the grid's structural edges (along x and along z)."""
    k = np.arange(n * n).reshape(n, n)
    along_x = np.stack([k[:, :-1].ravel(), k[:, 1:].ravel()], -1)
    along_z = np.stack([k[:-1, :].ravel(), k[1:, :].ravel()], -1)
    return np.concatenate([along_x, along_z])


class Meter:
    """Accumulates the per-frame measurements of one run from Y-up vertex positions."""

    def __init__(self, n: int):
        self.n = n
        self.edges = grid_edges(n)
        rest = grid(n)[0]
        self.rest = np.linalg.norm(rest[self.edges[:, 1]] - rest[self.edges[:, 0]], axis=1)
        self.common = common_indices(n)
        self.triangles = grid(n)[1]
        self.frames = 0
        self.crossings = 0            # the most crossing triangle pairs at any counted frame
        self.crossings_time = None    # (s) when first seen at that count
        self.crossings_counted = 0
        self.penetration = 0.0
        self.strain = 0.0
        self.shapes: dict[str, list] = {}

    def frame(self, t: float, x: np.ndarray) -> None:
        x = np.asarray(x, dtype=np.float64).reshape(-1, 3)
        depth = SPHERE_RADIUS - np.linalg.norm(x - np.array(SPHERE_CENTER), axis=1)
        self.penetration = max(self.penetration, float(depth.max()), float((GROUND - x[:, 1]).max()))
        lengths = np.linalg.norm(x[self.edges[:, 1]] - x[self.edges[:, 0]], axis=1)
        self.strain = max(self.strain, float((lengths / self.rest - 1.0).max()))
        for ts in SHAPE_TIMES:
            if abs(t - ts) < 0.25 / FPS:
                self.shapes[f"{ts:g}"] = x[self.common].round(6).tolist()
        if self.frames % CROSSING_EVERY == 0 or abs(t - SECONDS) < 0.25 / FPS:
            count = crossing_count(x, self.triangles) if np.isfinite(x).all() else -1
            self.crossings_counted += 1
            if count > self.crossings or count < 0:
                self.crossings, self.crossings_time = count, t
        self.frames += 1
        if not np.isfinite(x).all():
            self.penetration = self.strain = float("inf")


def peak_memory_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def report(engine: str, n: int, settings: dict, wall: float, meter: Meter, **extra) -> None:
    """Print the run's one JSON line."""
    print(json.dumps({
        "engine": engine, "resolution": n, "settings": settings,
        "wall_per_sim_second": wall / SECONDS, "wall_seconds": wall,
        "memory_mib": peak_memory_mib(),
        "max_penetration": meter.penetration, "max_strain": meter.strain,
        "self_crossings": meter.crossings, "self_crossings_time": meter.crossings_time,
        "self_crossings_frames_counted": meter.crossings_counted,
        "shapes": meter.shapes, **extra,
    }))
