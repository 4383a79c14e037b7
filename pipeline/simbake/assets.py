"""Assets: the geometry of each body, and its level set, ready for the core.

Meshes are read with trimesh (any format it reads), merged into one triangle mesh and
checked: a body's mesh must be closed (watertight, consistently wound) because its mass
properties and its level set both need an inside. Primitives get exact analytic distances
and mass properties; their surface samples and USD mesh are a cube-projected sphere or a
subdivided box.

Level sets are baked with OpenVDB only for bodies something can touch, and cached on disk
by a hash of the mesh and the voxel size: a second bake of the same scene reads them back.
The cache lives in ``$SIMBAKE_CACHE_DIR`` or ``$XDG_CACHE_HOME/simbake`` (default
``~/.cache/simbake``); every file is written beside, read back and renamed, so a crash or a
full disk never leaves a half-written grid that a later bake would trust. Each entry carries
what it was baked from in the grid's own metadata (``simbake:key``: the hash of the mesh and
voxel size that also names the file) and is used only when that and its voxel size match:
a valid .vdb of another mesh copied to a cache path is baked again, not trusted.
"""

from __future__ import annotations

import errno
import hashlib
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import _core
from .errors import SceneError
from .files import write_atomically
from .mesh_files import load_mesh, read_triangles
from .scene import Body, Scene

SPHERE_SUBDIVISIONS = 8  # 386 samples on a sphere, 0.5% faceting of the radius
BOX_SUBDIVISIONS = 3     # 56 samples on a box: corners, edge thirds and 4 inside each face
                         # (inner face samples are what hold an exactly aligned stack)
SAMPLES_ACROSS = 4       # mesh bodies: edge samples no further apart than the thinnest
                         # extent over this, so that coarse edges still catch other bodies
VOXELS_ACROSS = 64       # automatic voxel size: the longest extent over this ...
MIN_VOXELS_THIN = 6      # ... but at least this many voxels across the thinnest extent
MAX_VOXELS = 5e7         # a filled grid of 5e7 voxels takes ~0.75 GB
SHELL_THICKNESS = 0.01   # m: half-thickness of an open static collider (a two-sided surface)
SHELL_VOXELS = 2e6       # voxels an open collider's shell may take (it is a band around a surface)
SHELL_VOXELS_ACROSS = 1024  # ... and voxels need not be finer than its longest extent over this
CACHE_FORMAT = "levelset-v1"
CACHE_KEY = "simbake:key"     # grid metadata: the cache key the entry was baked for


@dataclass(frozen=True)
class BodyAsset:
    """Geometry of one body in its mesh's own frame."""

    vertices: np.ndarray        # (n, 3) float64 (m)
    triangles: np.ndarray       # (m, 3) int32
    normals: np.ndarray         # (n, 3) float64, area-weighted vertex normals
    samples: np.ndarray         # (s, 3) float64 collision samples: vertices, then edge points
    mass_properties: dict       # volume, center, inertia at unit density
    level_set: "_core.LevelSet | None"  # None when nothing can touch the body
    voxel_size: float           # of the baked grid, 0 when analytic or not baked


def cache_dir() -> Path:
    """$SIMBAKE_CACHE_DIR, else $XDG_CACHE_HOME/simbake or ~/.cache/simbake (an empty variable
    counts as unset: it must not mean the current directory)."""
    if os.environ.get("SIMBAKE_CACHE_DIR"):
        return Path(os.environ["SIMBAKE_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "simbake"


def shell_voxel_size(vertices: np.ndarray, triangles: np.ndarray, thickness: float) -> float:
    """An open collider's voxel size: no coarser than its thickness (the shell must be
    resolved: |d| interpolated trilinearly is off by up to h/2 at the surface), but coarse
    enough that the band of ~2 (t/h + 3) voxels around its area fits SHELL_VOXELS."""
    a, b, c = (vertices[triangles[:, i]] for i in range(3))
    area = 0.5 * float(np.linalg.norm(np.cross(b - a, c - a), axis=1).sum())
    extent = float((vertices.max(axis=0) - vertices.min(axis=0)).max())
    return max(thickness, extent / SHELL_VOXELS_ACROSS, math.sqrt(8.0 * area / SHELL_VOXELS))


def automatic_voxel_size(vertices: np.ndarray) -> float:
    extent = vertices.max(axis=0) - vertices.min(axis=0)
    return float(min(extent.max() / VOXELS_ACROSS, extent.min() / MIN_VOXELS_THIN))


def write_level_set(level_set: "_core.LevelSet", path: Path, metadata: dict[str, str] | None = None) -> None:
    """Write a baked level set to `path` whole or not at all: written beside, read back (the
    .vdb writer does not report a full disk), then renamed; an OutputError otherwise."""
    metadata = dict(metadata or {})

    def write(tmp: str) -> None:
        try:
            level_set.write(tmp, metadata)
        except RuntimeError as error:
            raise OSError(errno.EIO, str(error)) from None

    def verify(tmp: str) -> None:
        try:
            back = _core.LevelSet.read(tmp)
            whole = (back.active_voxel_count == level_set.active_voxel_count
                     and all(back.metadata.get(k) == v for k, v in metadata.items()))
        except RuntimeError:
            whole = False
        if not whole:
            full = os.statvfs(os.path.dirname(tmp) or ".").f_bavail == 0
            raise OSError(errno.ENOSPC if full else errno.EIO,
                          os.strerror(errno.ENOSPC) if full else "the written file does not read back whole")

    write_atomically(Path(path), write, verify)


def level_set_cache_path(vertices: np.ndarray, triangles: np.ndarray, voxel_size: float,
                         cache: Path | None = None, thickness: float = 0.0) -> Path:
    """Where the level set of this mesh at this voxel size is cached (it may not exist yet);
    `thickness` > 0: its two-sided shell of that half-thickness (LevelSet.bake_shell)."""
    cache = cache_dir() if cache is None else cache
    digest = hashlib.sha256()
    digest.update(CACHE_FORMAT.encode())
    digest.update(np.ascontiguousarray(vertices, dtype="<f8").tobytes())
    digest.update(np.ascontiguousarray(triangles, dtype="<i4").tobytes())
    digest.update(repr(float(voxel_size)).encode())
    if thickness > 0:
        digest.update(f"shell {float(thickness)!r}".encode())
    return cache / "levelsets" / f"{digest.hexdigest()}.vdb"


def bake_level_set(vertices: np.ndarray, triangles: np.ndarray, voxel_size: float,
                   cache: Path | None = None, thickness: float = 0.0) -> "_core.LevelSet":
    """The mesh's level set, read from the cache when this mesh and voxel size were baked
    before (and the entry says so), else baked and stored."""
    path = level_set_cache_path(vertices, triangles, voxel_size, cache, thickness)
    key = path.stem
    if path.is_file():
        try:
            entry = _core.LevelSet.read(str(path))
            if entry.metadata.get(CACHE_KEY) == key and math.isclose(entry.voxel_size, voxel_size, rel_tol=1e-9):
                return entry
        except RuntimeError:
            pass  # unreadable cache entry: bake again and replace it
    if thickness > 0:
        level_set = _core.LevelSet.bake_shell(vertices, triangles, voxel_size, thickness)
    else:
        level_set = _core.LevelSet.bake(vertices, triangles, voxel_size)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_level_set(level_set, path, {CACHE_KEY: key})
    except OSError:
        pass  # a read-only or full cache costs a re-bake next time, nothing else
    return level_set


def needs_level_set(scene: Scene, index: int) -> bool:
    """A body's level set is needed only when a cloth or another body could touch it
    (two kinematic bodies never meet: neither can be pushed)."""
    me = scene.bodies[index]
    return bool(scene.cloths) or any(
        j != index and not (me.kinematic and other.kinematic) for j, other in enumerate(scene.bodies))


def check_voxel_count(vertices: np.ndarray, voxel_size: float, file: str | Path, key: str) -> None:
    """Refuse a grid that would not fit (the interior is filled, so voxels grow as 1/h^3), or
    whose voxels are larger than the mesh itself (it would describe nothing of its shape)."""
    extent = vertices.max(axis=0) - vertices.min(axis=0)
    if voxel_size > float(extent.max()):
        raise SceneError(file, key, f"voxel size {voxel_size:g} m is larger than the mesh ({float(extent.max()):g} m "
                                    "across); a level set needs voxels smaller than the shape it describes")
    voxels = float(np.prod(extent / voxel_size + 6.0))
    if voxels > MAX_VOXELS:
        raise SceneError(file, key, f"voxel size {voxel_size:g} m needs ~{voxels:.2g} voxels for this mesh "
                                    f"(at most {MAX_VOXELS:.0e}); use a larger voxel size")


def load_body(scene: Scene, index: int, body: Body, with_level_set: bool,
              shared: dict | None = None) -> BodyAsset:
    """One body's geometry; `shared` maps (mesh file, voxel size) to an asset already loaded
    for another body, so a pile of copies of one mesh holds one grid, not one per body."""
    memo_key = None
    if body.shape.kind == "mesh" and body.shape.mesh_path is not None:
        memo_key = (body.shape.mesh_path, body.voxel_size, with_level_set)
    if shared is not None and memo_key in shared:
        return shared[memo_key]
    asset = _load_body(scene, index, body, with_level_set)
    if shared is not None and memo_key is not None:
        shared[memo_key] = asset
    return asset


def _load_body(scene: Scene, index: int, body: Body, with_level_set: bool) -> BodyAsset:
    key = f"bodies[{index}]"
    file = scene.source or str(scene.path)
    shape = body.shape
    voxel_size = 0.0
    if shape.kind == "sphere":
        vertices, triangles = _core.sphere_mesh(shape.radius, SPHERE_SUBDIVISIONS)
        props = _core.sphere_mass_properties(shape.radius)
        level_set = _core.LevelSet.sphere(shape.radius)
    elif shape.kind == "box":
        vertices, triangles = _core.box_mesh(np.array(shape.size), BOX_SUBDIVISIONS)
        props = _core.box_mass_properties(np.array(shape.size))
        level_set = _core.LevelSet.box(np.array(shape.size))
    else:
        if shape.mesh_vertices is not None:  # inline (a USD shot's collider, checked closed)
            vertices = np.ascontiguousarray(shape.mesh_vertices, dtype=np.float64)
            triangles = np.ascontiguousarray(shape.mesh_triangles, dtype=np.int32)
            file, key = (file, shape.mesh_source) if shape.mesh_source else (file, key)
        else:
            vertices, triangles = load_mesh(shape.mesh_path, file, f"{key}.mesh")
        if shape.thickness > 0:  # an open static collider: a two-sided shell (no inside, no mass)
            return _load_shell(body, vertices, triangles, with_level_set)
        try:
            props = _core.mass_properties(vertices, triangles)
        except ValueError as error:
            raise SceneError(file, f"{key}.mesh", f"{shape.mesh_path or 'collider mesh'}: {error}") from None
        level_set = None
        if with_level_set:
            voxel_size = body.voxel_size or automatic_voxel_size(vertices)
            check_voxel_count(vertices, voxel_size, file, f"{key}.voxel_size")
            level_set = bake_level_set(vertices, triangles, voxel_size)
    normals = _core.vertex_normals(vertices, triangles)
    samples = vertices
    if shape.kind == "mesh":
        extent = vertices.max(axis=0) - vertices.min(axis=0)
        samples = _core.surface_samples(vertices, triangles, float(extent.min()) / SAMPLES_ACROSS)
    return BodyAsset(vertices, triangles, normals, samples, props, level_set, voxel_size)


def _load_shell(body: Body, vertices: np.ndarray, triangles: np.ndarray, with_level_set: bool) -> BodyAsset:
    """An open or non-manifold kinematic collider: phi = |d| - t, t its half-thickness raised
    to the voxel size when the surface is too large for a finer grid (PhysX treats such a
    mesh as a two-sided surface; bodies rest on it at t). It has no inside, so no mass: its
    mass properties are a placeholder (kinematic bodies never use them) centred on its box."""
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    h = body.voxel_size or shell_voxel_size(vertices, triangles, body.shape.thickness)
    thickness = max(body.shape.thickness, h)
    props = {"volume": 1.0, "center": 0.5 * (lo + hi), "inertia": np.eye(3)}
    level_set = bake_level_set(vertices, triangles, h, thickness=thickness) if with_level_set else None
    normals = _core.vertex_normals(vertices, triangles)
    # samples 1/64 of its longest extent apart (the thickness at least)
    spacing = max(float((hi - lo).max()) / 64.0, thickness)
    samples = _core.surface_samples(vertices, triangles, spacing)
    return BodyAsset(vertices, triangles, normals, samples, props, level_set, h if with_level_set else 0.0)


def load_assets(scene: Scene) -> list[BodyAsset]:
    shared: dict = {}
    return [load_body(scene, i, body, needs_level_set(scene, i), shared) for i, body in enumerate(scene.bodies)]


# --------------------------------------------------------------------------------------------
# Cloth
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class ClothAsset:
    """A cloth's rest shape, placed in the world (its initial state)."""

    vertices: np.ndarray   # (n, 3) float64 world positions (m)
    triangles: np.ndarray  # (m, 3) int32


def grid_mesh(size: tuple[float, float], resolution: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """A regular grid in the XZ plane centred on the origin, normals +y. Vertex (i, j), i along
    x and j along z, has index j * nx + i; vertex 0 is the (-x, -z) corner."""
    nx, nz = resolution
    i, j = np.meshgrid(np.arange(nx), np.arange(nz), indexing="xy")  # (nz, nx): row j, column i
    x = (i / (nx - 1) - 0.5) * size[0]
    z = (j / (nz - 1) - 0.5) * size[1]
    vertices = np.stack([x, np.zeros_like(x), z], axis=-1).reshape(-1, 3)
    p00 = (j[:-1, :-1] * nx + i[:-1, :-1]).ravel()
    p10, p01, p11 = p00 + 1, p00 + nx, p00 + nx + 1
    # (p00, p01, p11) and (p00, p11, p10) wind counter-clockwise seen from +y
    triangles = np.concatenate([np.stack([p00, p01, p11], -1), np.stack([p00, p11, p10], -1)])
    return vertices.astype(np.float64), triangles.astype(np.int32)


def _rotate(q: tuple[float, float, float, float], points: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                  [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                  [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    return points @ R.T


def load_cloth(scene: Scene, index: int) -> ClothAsset:
    cloth = scene.cloths[index]
    key, file = f"cloths[{index}]", scene.source or str(scene.path)
    if cloth.mesh_vertices is not None:  # a USD shot's mesh: world rest positions already
        return ClothAsset(np.ascontiguousarray(cloth.mesh_vertices, dtype=np.float64),
                          np.ascontiguousarray(cloth.mesh_triangles, dtype=np.int32))
    if cloth.mesh_path is not None:
        # the file's vertex order is kept: `pinned` and `attach` index the file's vertices
        mesh = read_triangles(cloth.mesh_path, file, f"{key}.mesh", process=False)
        vertices = np.asarray(mesh.vertices, dtype=np.float64)
        triangles = np.asarray(mesh.faces, dtype=np.int32)
    else:
        vertices, triangles = grid_mesh(cloth.grid_size, cloth.grid_resolution)
    for name, indices in (("pinned", cloth.pinned), ("attach.points", cloth.attached)):
        bad = [p for p in indices if p >= len(vertices)]
        if bad:
            raise SceneError(file, f"{key}.{name}", f"vertex {bad[0]} does not exist (the cloth has {len(vertices)})")
    placed = _rotate(cloth.orientation, vertices) + np.asarray(cloth.position)
    return ClothAsset(np.ascontiguousarray(placed), np.ascontiguousarray(triangles))
