"""What simbake takes on: the physical range of a scene's values and the resource budget of a
bake, both checked before any work is done (README, "Guarantees").

Physically absurd input (a 1e300 m grid, gravity of 1e300 m/s^2, a cloth 1e6 m thick) is bad
input, not a simulation failure: :func:`check_scene` refuses it when the scene is loaded, with
the file and key named, exit status 2. :func:`check_budget` estimates, once the world is built
and before the first frame, the memory, disk and substeps the bake would need, and refuses
what does not fit, naming the key to change.
"""

from __future__ import annotations

import math
import os
import shutil
from pathlib import Path

import numpy as np

from .errors import SceneError

# --- the physical range (SI units) -------------------------------------------------------
LENGTH = 1e5            # m: positions, sizes, heights, voxel sizes, mesh coordinates
SMALLEST = 1e-6         # m: the smallest radius, box or grid size
THICKNESS = 1.0         # m: a cloth's collision thickness
SPEED = 1e5             # m/s, and rad/s for spin
ACCELERATION = 1e4      # m/s^2: gravity (about 1,000 g)
FPS = (1e-3, 1e5)       # frames per second
DENSITY = (1e-6, 1e6)   # kg/m^3
MASS = (1e-9, 1e12)     # kg
AREA_DENSITY = (1e-9, 1e4)  # kg/m^2
STIFFNESS = 1e12        # N/m (a cloth's stretch stiffness)
BEND = 1e6              # N m
DAMPING = 1e3           # s
STRAIN = 1e3            # a strain limit
INERTIA_TOLERANCE = 1e-6  # relative slack of an inertia tensor's symmetry and triangle inequality
FRICTION = 1e3          # a friction coefficient
KEY_TIME = 1e9          # s
FRAME_NUMBER = 2 ** 53  # |frame|: time codes are doubles, exact only up to here
SUBSTEPS_PER_FRAME = 4096  # [solver] substeps: the solver's own cap per frame

# --- the resource budget -----------------------------------------------------------------
MAX_FRAMES = 1_000_000           # frames in one bake (11.5 hours at 24 fps)
MAX_SUBSTEPS = 100_000_000       # solver steps in one bake (estimated from the first frame)
DEFAULT_MEMORY = 8 * 2 ** 30     # bytes, or half the machine's memory when that is less;
                                 # SIMBAKE_MEMORY_BUDGET (bytes, or with K, M, G) overrides
# The memory model of a bake, fitted to measured peaks (benchmarks/memory/cloth_peak.py,
# resource.getrusage's peak resident set, one thread; benchmarks/results/memory_estimate.md):
#   BASE + per cloth, vertices x (CLOTH_VERTEX_BYTES + ramp x SELF_COLLISION_BYTES x
#                                  crowding ^ CROWDING_EXPONENT + buffered frames x CLOTH_SAMPLE_BYTES)
#        + moving bodies x frames x RIGID_SAMPLE_BYTES  (+ the whole cache once for .usda)
# crowding = (thickness / mean rest edge)^2: once the sheet bends, the self-collision keeps the
# pairs of its elements closer than the thickness, more per vertex as the thickness grows
# against the edges; ramp: none after one step, all by SELF_COLLISION_FRAMES (as it moves).
BASE_BYTES = 160 * 2 ** 20       # Python, pxr, the core and trimesh loaded (measured 150-190 MiB)
CLOTH_VERTEX_BYTES = 9728        # the cloth solver per vertex (measured 8.6-9.9 kB, 64^2 to 512^2)
CLOTH_SAMPLE_BYTES = 40          # the writer per cloth vertex and frame held until a save
                                 # (points, normals, velocities as float32: 36 B, and Vt's own)
BUFFERED_FRAMES = 50             # frames the writer holds between saves (CacheWriter.flush_every)
SELF_COLLISION_BYTES = 30720     # per vertex at crowding 1, for a sheet that bends and swings
CROWDING_EXPONENT = 1.7          # (fitted from crowding 0.08 to 0.71: 64^2 to 384^2 vertices on
                                 # 2 m at 5 mm; one that folds into layers keeps up to 4x more:
                                 # README, "Limitations")
SELF_COLLISION_FRAMES = 13       # frames by which they have all appeared (measured: none at 2, all at 13)
RIGID_SAMPLE_BYTES = 120         # writer memory per dynamic body and frame (USD holds rigid
                                 # samples unpacked until the file is closed: ~60 B each)
TEXT_SAMPLE_BYTES = 36           # .usda: the finished cache is held once while written as text
FRAME_INDEX_BYTES = 16           # file bytes per sampled attribute and frame, besides its values


def _error(scene, key: str, problem: str) -> SceneError:
    """The problem at a scene key, named where the user wrote it (a shot's prim and attribute)."""
    key = scene.source_key(key) if hasattr(scene, "source_key") else key
    return SceneError(scene.source or scene.path, key, problem)


def _range(scene, key: str, value: float, lo: float | None, hi: float, unit: str = "") -> None:
    unit = f" {unit}" if unit else ""
    if abs(value) > hi:
        raise _error(scene, key, f"{value:g}{unit} is outside simbake's physical range "
                                 f"(at most {hi:g}{unit} in size)")
    if lo is not None and 0 < value < lo:
        raise _error(scene, key, f"{value:g}{unit} is below simbake's physical range (at least {lo:g}{unit})")


def _vector(scene, key: str, values, hi: float, unit: str, lo: float | None = None) -> None:
    for i, v in enumerate(values):
        _range(scene, f"{key}[{i}]", v, lo, hi, unit)


def check_scene(scene) -> None:
    """Refuse values outside the physical range, frame numbers that time codes cannot hold
    exactly, and cloth grids whose solver would not fit the memory budget."""
    for name in ("start_frame", "end_frame"):
        if abs(getattr(scene, name)) > FRAME_NUMBER:
            raise _error(scene, f"scene.{name}", f"must be within +-2^53 ({FRAME_NUMBER}), where every frame's "
                                                 f"time code is exact, got {getattr(scene, name)}")
    _range(scene, "scene.fps", scene.fps, FPS[0], FPS[1], "fps")
    if scene.substeps > SUBSTEPS_PER_FRAME:
        raise _error(scene, "solver.substeps", f"must be at most {SUBSTEPS_PER_FRAME} (the solver's cap "
                                               f"per frame), got {scene.substeps}")
    _vector(scene, "scene.gravity", scene.gravity, ACCELERATION, "m/s^2")
    if scene.frame_count > MAX_FRAMES:
        raise _error(scene, "scene.end_frame", f"{scene.frame_count} frames is more than the budget of "
                                               f"{MAX_FRAMES:,} frames in one bake; bake a part with --frames START:END")
    if scene.ground is not None:
        _range(scene, "ground.height", scene.ground.height, None, LENGTH, "m")
        _range(scene, "ground.friction", scene.ground.friction, None, FRICTION)
    for i, b in enumerate(scene.bodies):
        key = f"bodies[{i}]"
        if b.shape.kind == "sphere":
            _range(scene, f"{key}.shape.radius", b.shape.radius, SMALLEST, LENGTH, "m")
        elif b.shape.kind == "box":
            _vector(scene, f"{key}.shape.size", b.shape.size, LENGTH, "m", SMALLEST)
        if b.density is not None:
            _range(scene, f"{key}.density", b.density, *DENSITY, "kg/m^3")
        if b.mass is not None:
            _range(scene, f"{key}.mass", b.mass, *MASS, "kg")
        _vector(scene, f"{key}.position", b.position, LENGTH, "m")
        _vector(scene, f"{key}.linear_velocity", b.linear_velocity, SPEED, "m/s")
        _vector(scene, f"{key}.angular_velocity", b.angular_velocity, SPEED, "rad/s")
        _range(scene, f"{key}.friction", b.friction, None, FRICTION)
        _range(scene, f"{key}.voxel_size", b.voxel_size, None, LENGTH, "m")
        _check_mass_distribution(scene, key, b)
        for k, keyed in enumerate(b.keys):
            _range(scene, f"{key}.keys[{k}].time", keyed.time, None, KEY_TIME, "s")
            _vector(scene, f"{key}.keys[{k}].position", keyed.position, LENGTH, "m")
    for i, c in enumerate(scene.cloths):
        _check_cloth(scene, f"cloths[{i}]", c)


def _check_cloth(scene, key: str, c) -> None:
    """A cloth's physical range, then (a grid's size known) the memory its solver needs."""
    if c.grid_size is not None:
        _vector(scene, f"{key}.grid.size", c.grid_size, LENGTH, "m", SMALLEST)
    _vector(scene, f"{key}.position", c.position, LENGTH, "m")
    _range(scene, f"{key}.area_density", c.area_density, *AREA_DENSITY, "kg/m^2")
    _range(scene, f"{key}.stretch_stiffness", c.stretch_stiffness, None, STIFFNESS, "N/m")
    _range(scene, f"{key}.bend_stiffness", c.bend_stiffness, None, BEND, "N m")
    _range(scene, f"{key}.damping", c.damping, None, DAMPING, "s")
    _range(scene, f"{key}.strain_limit", c.strain_limit, None, STRAIN)
    _range(scene, f"{key}.friction", c.friction, None, FRICTION)
    _range(scene, f"{key}.thickness", c.thickness, None, THICKNESS, "m")
    if c.grid_size is not None:  # once the thickness is known to be in range
        vertices = c.grid_resolution[0] * c.grid_resolution[1]
        dx, dz = (size / (n - 1) for size, n in zip(c.grid_size, c.grid_resolution))
        edge = (dx + dz + math.hypot(dx, dz)) / 3  # the mean of a grid triangle's sides
        _memory(scene, f"{key}.grid.resolution",
                estimated_memory(scene.frame_count, [(vertices, crowding(c.thickness, edge))], 0, Path("x.usdc")),
                f"a {c.grid_resolution[0]} x {c.grid_resolution[1]} cloth")


def _check_mass_distribution(scene, key: str, body) -> None:
    """A given centre of mass must be finite; a given inertia tensor that of some real body:
    symmetric, positive definite, and no principal moment larger than the other two together
    (the triangle inequality every mass distribution satisfies)."""
    if body.center_of_mass is not None and not np.isfinite(np.asarray(body.center_of_mass, dtype=float)).all():
        raise _error(scene, f"{key}.center_of_mass", "must be three finite numbers")
    if body.inertia is None:
        return
    tensor = np.asarray(body.inertia, dtype=np.float64)
    if tensor.shape != (3, 3) or not np.isfinite(tensor).all():
        raise _error(scene, f"{key}.inertia", "must be a finite 3 x 3 tensor")
    scale = float(np.abs(tensor).max())
    if np.abs(tensor - tensor.T).max() > INERTIA_TOLERANCE * scale:
        raise _error(scene, f"{key}.inertia", "must be symmetric")
    moments = np.linalg.eigvalsh(tensor)
    if not moments[0] > 0:
        raise _error(scene, f"{key}.inertia", f"must be positive definite (principal moments "
                                              f"{', '.join(f'{m:g}' for m in moments)} kg m^2)")
    if moments[2] > (moments[0] + moments[1]) * (1 + INERTIA_TOLERANCE):
        raise _error(scene, f"{key}.inertia", f"principal moments {', '.join(f'{m:g}' for m in moments)} kg m^2 "
                                              "are not those of any body: the largest must not exceed the sum of "
                                              "the other two (triangle inequality)")


def check_mesh_extent(vertices, file, key: str, path) -> None:
    """A mesh's coordinates must lie within the physical range too."""
    largest = float(abs(vertices).max()) if len(vertices) else 0.0
    if largest > LENGTH:
        raise SceneError(file, key, f"{path} has a coordinate of {largest:g} m, outside simbake's "
                                    f"physical range (at most {LENGTH:g} m)")


def memory_budget() -> int:
    """Bytes a bake may plan to use: SIMBAKE_MEMORY_BUDGET, else the smaller of 8 GiB and half
    the machine's memory."""
    text = os.environ.get("SIMBAKE_MEMORY_BUDGET", "").strip().upper()
    if text:
        scale = {"K": 2 ** 10, "M": 2 ** 20, "G": 2 ** 30}.get(text[-1], 1)
        try:
            return int(float(text.rstrip("KMG")) * scale)
        except ValueError:
            pass  # unreadable: the default
    try:
        half = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE") // 2
    except (OSError, ValueError):
        half = DEFAULT_MEMORY
    return min(DEFAULT_MEMORY, half)


def _gb(n: float) -> str:
    return f"{n / 2 ** 30:.3g} GiB" if n >= 2 ** 30 else f"{n / 2 ** 20:.3g} MiB"


def _memory(scene, key: str, needed: float, what: str) -> None:
    budget = memory_budget()
    if needed > budget:
        raise _error(scene, key, f"{what} needs ~{_gb(needed)} of memory, more than the budget of "
                                 f"{_gb(budget)} (SIMBAKE_MEMORY_BUDGET)")


def crowding(thickness: float, mean_edge: float) -> float:
    """(thickness / mean rest edge)^2: how many self-collision pairs a vertex keeps, relatively
    (the ratio capped at 1e6: beyond any real sheet, and no overflow)."""
    return min(thickness / mean_edge, 1e6) ** 2 if mean_edge > 0 else 0.0


def estimated_memory(frames: int, cloths: list[tuple[int, float]], dynamic_bodies: int, output: Path) -> int:
    """The peak memory (bytes) of a bake of `frames` frames (the model above); `cloths`: each
    cloth's (vertices, crowding)."""
    ramp = min(1.0, max(0.0, (frames - 2) / (SELF_COLLISION_FRAMES - 2)))
    per_frame = min(frames, BUFFERED_FRAMES) * CLOTH_SAMPLE_BYTES
    cloth = sum(n * (CLOTH_VERTEX_BYTES + ramp * SELF_COLLISION_BYTES * c ** CROWDING_EXPONENT + per_frame)
                for n, c in cloths)
    vertices = sum(n for n, _ in cloths)
    text = frames * vertices * TEXT_SAMPLE_BYTES if Path(output).suffix.lower() == ".usda" else 0
    return int(BASE_BYTES + cloth + frames * dynamic_bodies * RIGID_SAMPLE_BYTES + text)


def resident_bytes() -> int | None:
    """This process's resident memory now (bytes), or None where /proc does not say."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return None


def check_memory_in_flight(scene, frame: int) -> None:
    """Stop a bake whose memory has outgrown the budget (the estimate cannot foresee all: a
    cloth's self-collision keeps more as it folds), before the machine starts to swap."""
    from .errors import SimulationError

    held, budget = resident_bytes(), memory_budget()
    if held is not None and held > budget:
        cause = "; a folding cloth's self-collision grows beyond the estimate" if scene.cloths else ""
        raise SimulationError(f"{scene.source or scene.path}: frame {frame}: the bake holds {_gb(held)} of memory, "
                              f"over the budget of {_gb(budget)} (SIMBAKE_MEMORY_BUDGET); nothing was written{cause}")


def check_budget(scene, output: Path, substeps_per_frame: int, dynamic_bodies: int,
                 cloths: list[tuple[int, float]]) -> None:
    """Refuse a bake whose estimated substeps, memory or disk do not fit, before it starts.

    substeps_per_frame: the scene's fixed count, or the automatic count of the first frame;
    cloths: each cloth's (vertices, crowding).
    """
    cloth_vertices = [n for n, _ in cloths]
    frames = scene.frame_count
    fixed = scene.substeps > 0
    total = frames * substeps_per_frame
    if total > MAX_SUBSTEPS:
        key = "solver.substeps" if fixed else "scene.end_frame"
        raise _error(scene, key, f"{frames} frames at {substeps_per_frame} substeps each is ~{total:.3g} "
                                 f"solver steps, more than the budget of {MAX_SUBSTEPS:.0e}")
    vertices = sum(cloth_vertices)
    _memory(scene, "scene.end_frame", estimated_memory(frames, cloths, dynamic_bodies, Path(output)),
            f"{frames} frames of {dynamic_bodies} moving bodies and {vertices} cloth vertices")
    sampled = 2 * dynamic_bodies + 4 * len(cloth_vertices)
    per_frame = 56 * dynamic_bodies + sum(36 * n + 24 for n in cloth_vertices) + FRAME_INDEX_BYTES * sampled
    disk = frames * per_frame
    try:
        free = shutil.disk_usage(Path(output).parent).free
    except OSError:
        return
    if disk > free:
        raise _error(scene, "scene.end_frame", f"the cache needs ~{_gb(disk)} on disk, more than the "
                                               f"{_gb(free)} free in {Path(output).parent}")
