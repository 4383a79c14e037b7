"""Baked level set of a sphere mesh against the exact distance |p| - 1.

The mesh is sphere_mesh(1.0, 96) (a cube-projected sphere, 110,592 triangles), baked with
OpenVDB by LevelSet.bake at voxel sizes 0.2 ... 0.0125 m. The exact signed distance of the
unit sphere is |p| - 1 and its normal p / |p|; the mesh's own faceting (its largest gap to
the sphere, in the notes) is a floor that no voxel size removes.

Measured per voxel size (one thread, the process pinned to one CPU before the first bake):
- bake time, median of 3; active voxels; memory_bytes;
- rms and max |phi - (|p| - 1)| over 20,000 deterministic points within one voxel of the
  surface (Fibonacci directions, radii 1 + h u with u a golden-ratio sequence in [-1, 1));
- the sign error rate over 20,000 points (uniform in volume, deterministic) in each of the
  shells 0.5 < r < 0.95 (phi must be < 0) and 1.05 < r < 1.5 (phi must be > 0);
- the normal angle error (degrees, rms and max) at the near-surface points;
- the cost of a phi query and of a phi-and-normal query (ns, median of 3 over the points,
  in their Fibonacci order).
"""

from __future__ import annotations

import time

import numpy as np

import common
from common import Result, Series, _core

NAME = "levelset_sphere"
RADIUS = 1.0
SUBDIVISIONS = 96
VOXEL_SIZES = [0.2, 0.1, 0.05, 0.025, 0.0125]
POINTS = 20_000
GOLDEN = (np.sqrt(5.0) - 1.0) / 2.0


def fibonacci_directions(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    y = 1.0 - 2.0 * i / n
    r = np.sqrt(1.0 - y * y)
    phi = np.pi * (3.0 - np.sqrt(5.0)) * i
    return np.column_stack([r * np.cos(phi), y, r * np.sin(phi)])


def golden_sequence(n: int, offset: float = 0.0) -> np.ndarray:
    """Deterministic, evenly spread numbers in [0, 1)."""
    return np.mod(offset + GOLDEN * (np.arange(n) + 1), 1.0)


def near_surface_points(h: float) -> np.ndarray:
    u = 2.0 * golden_sequence(POINTS) - 1.0
    return fibonacci_directions(POINTS) * (RADIUS + h * u)[:, None]


def shell_points(r0: float, r1: float) -> np.ndarray:
    """Uniform in the volume of the shell r0 < r < r1 (radius from the inverse CDF)."""
    u = golden_sequence(POINTS, offset=0.25)
    r = np.cbrt(r0 ** 3 + u * (r1 ** 3 - r0 ** 3))
    return fibonacci_directions(POINTS) * r[:, None]


def mesh_faceting(vertices: np.ndarray, triangles: np.ndarray) -> float:
    """Largest gap between the mesh and the sphere, sampled at triangle and edge midpoints."""
    tri = vertices[triangles]
    points = [tri.mean(axis=1)] + [0.5 * (tri[:, a] + tri[:, b]) for a, b in ((0, 1), (1, 2), (2, 0))]
    return float(max(np.max(RADIUS - np.linalg.norm(p, axis=1)) for p in points))


def measure(vertices: np.ndarray, triangles: np.ndarray, h: float) -> dict:
    baked = []  # the last timed bake is the one measured; the previous one is freed off the clock
    timing = common.median_time(lambda _: baked.append(_core.LevelSet.bake(vertices, triangles, h)),
                                setup=baked.clear, repeats=3)
    level_set = baked.pop()

    near = near_surface_points(h)
    r = np.linalg.norm(near, axis=1)
    error = level_set.phi(near) - (r - RADIUS)
    normals = level_set.normals(near)
    cosine = np.clip(np.einsum("ni,ni->n", normals, near / r[:, None]), -1.0, 1.0)
    angle = np.degrees(np.arccos(cosine))

    inside = level_set.phi(shell_points(0.5, 0.95))
    outside = level_set.phi(shell_points(1.05, 1.5))
    wrong = int(np.count_nonzero(inside >= 0.0) + np.count_nonzero(outside <= 0.0))

    phi_timing = common.median_time(lambda _: level_set.phi(near), repeats=3)
    normal_timing = common.median_time(lambda _: level_set.normals(near), repeats=3)
    return {
        "voxel_size": h,
        "bake_seconds": timing,
        "active_voxels": int(level_set.active_voxel_count),
        "memory_bytes": int(level_set.memory_bytes),
        "phi_rms_error": float(np.sqrt(np.mean(error ** 2))),
        "phi_max_error": float(np.max(np.abs(error))),
        "phi_mean_error": float(np.mean(error)),
        "phi_rms_error_over_h2": float(np.sqrt(np.mean(error ** 2))) / h ** 2,
        "sign_errors": wrong,
        "sign_error_rate": wrong / (2 * POINTS),
        "sign_errors_inside": int(np.count_nonzero(inside >= 0.0)),
        "sign_errors_outside": int(np.count_nonzero(outside <= 0.0)),
        "normal_rms_degrees": float(np.sqrt(np.mean(angle ** 2))),
        "normal_max_degrees": float(np.max(angle)),
        "phi_query_ns": 1e9 * phi_timing["median"] / POINTS,
        "normal_query_ns": 1e9 * normal_timing["median"] / POINTS,
    }


def run() -> Result:
    cpus = common.pin_to_one_cpu()  # before the first bake starts TBB
    vertices, triangles = _core.sphere_mesh(RADIUS, SUBDIVISIONS)
    faceting = mesh_faceting(vertices, triangles)
    data, rows = [], []
    for h in VOXEL_SIZES:
        m = measure(vertices, triangles, h)
        data.append(m)
        rows.append([f"{h:g}", m["bake_seconds"]["median"], m["active_voxels"], f"{m['memory_bytes'] / 2**20:.2f}",
                     m["phi_rms_error"], m["phi_max_error"], m["phi_rms_error_over_h2"],
                     100.0 * m["sign_error_rate"], m["normal_rms_degrees"], m["normal_max_degrees"],
                     f"{m['phi_query_ns']:.0f}", f"{m['normal_query_ns']:.0f}"])
    times = [d["bake_seconds"]["median"] for d in data]
    labels = [f"h={d['voxel_size']:g}" for d in data]
    series = [
        Series("rms |phi - (|p| - 1)| (m)", times, [d["phi_rms_error"] for d in data], labels),
        Series("max |phi - (|p| - 1)| (m)", times, [d["phi_max_error"] for d in data], labels, "s"),
        Series("normal error, rms (degrees)", times, [d["normal_rms_degrees"] for d in data], labels, "^"),
    ]
    return Result(
        name=NAME,
        title=f"Level set of sphere_mesh(1.0, {SUBDIVISIONS}) ({len(triangles):,} triangles) vs |p| - 1",
        data={"radius": RADIUS, "subdivisions": SUBDIVISIONS, "triangles": int(len(triangles)),
              "vertices": int(len(vertices)), "mesh_faceting": faceting, "points": POINTS,
              "bake_cpus": cpus, "runs": data},
        table_headers=["voxel h (m)", "bake s", "active voxels", "memory MiB", "phi rms err (m)",
                       "phi max err (m)", "rms / h^2", "sign err %", "normal rms deg", "normal max deg",
                       "phi ns", "phi+normal ns"],
        table_rows=rows,
        series=series,
        xlabel="bake seconds (one thread, median of 3)",
        ylabel="error against the exact sphere (m, or degrees for normals)",
        notes=[f"mesh faceting (largest gap between the mesh and the sphere): {faceting:.2e} m, a floor "
               "for the max phi error at any voxel size (the rms faceting error is lower)",
               f"phi and normal errors over {POINTS:,} points with ||p| - 1| < h; sign errors over "
               f"{POINTS:,} points in each of 0.5 < r < 0.95 and 1.05 < r < 1.5",
               "phi ns / phi+normal ns: LevelSet.phi / LevelSet.normals per point (the binding loops in C++)"],
        reference_lines=[(faceting, f"largest mesh-to-sphere gap {faceting:.2g} m (floor of the max phi error)")],
    )


if __name__ == "__main__":
    common.main(run)
