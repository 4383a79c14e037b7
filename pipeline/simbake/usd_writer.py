"""Streaming writer for simbake's USD cache, version 1 (see DESIGN.md, "USD cache, version 1").

Layout of a cache::

    /World                      def Xform, kind = "component" (defaultPrim)
        /<body>                 def Xform: xformOp:translate (double3), xformOp:orient (quatd),
                                xformOpOrder; time-sampled every frame for a dynamic body,
                                default values only for a static one
            /<body>             def Mesh, static, named as its body (importers that merge an
                                Xform with its single child, as Blender's does, keep the
                                body's name): points, faceVertexCounts, faceVertexIndices,
                                normals ("faceVarying", split at creases; or "vertex"),
                                extent, subdivisionScheme "none"
        /<cloth>                def Mesh: topology once; points, normals, velocities and
                                extent time-sampled every frame; subdivisionScheme "none"

Usage::

    with CacheWriter("out.usdc", fps=24, start_frame=1, end_frame=120,
                     bodies=[BodyPrim(...), ...], provenance={"simbake": "0.1"}) as w:
        for frame in range(1, 121):
            w.write_frame(frame, translations, orientations)

How it works, and why:

* Everything is authored with the Sdf-level API (``Sdf.CreatePrimInLayer``,
  ``Sdf.AttributeSpec``, ``Sdf.Layer.SetTimeSample``) with ``Vt`` arrays made from numpy, one
  ``Sdf.ChangeBlock`` per frame. That is many times faster than UsdGeom schema calls.
* The layer lives in a hidden temp file beside the target (same directory, so the final
  ``os.replace`` is atomic) and is saved as the bake goes. Crate saves are incremental: new
  values are appended to the file and array values (cloth points, normals, velocities) are
  then held as lazy, memory-mapped references into it, so memory stays bounded however long
  a cloth bake is (2,000 frames of a 64x64 cloth: ~10 MB more than at the start, against
  ~290 MB without saving). Small values (a body's translate and orient) are different: USD
  keeps each attribute's samples unpacked in memory once the attribute is edited again, about
  60 bytes per sample whether saved or not, so a rigid-body cache costs memory in proportion
  to bodies x frames (1,000 bodies x 2,000 frames: ~300 MB). Each save also rewrites every
  sampled attribute's time index (8 bytes per sample so far) and the old one stays in the
  file as dead space, so saving many small samples every 50 frames made that cache 5x bigger
  (735 MB instead of 138 MB) and slower. Hence the rule: save once ``flush_every`` frames are
  pending *and* the pending sample data is at least as large as the index a save rewrites.
  Cloth caches are saved every ``flush_every`` frames; rigid-body-only caches get
  geometrically rarer saves (file within ~2x of one save at the end, no doubled memory peak
  when packing at close).
* ``.usda`` output is baked exactly the same way into a crate temp file and exported to text
  once at :meth:`CacheWriter.close` (re-saving a growing text file every few frames would be
  quadratic and would not bound memory).
* Output is deterministic: identical calls give byte-identical files (no timestamps, no temp
  names inside the file, provenance dictionaries are sorted by USD).
"""

from __future__ import annotations

import itertools
import math
import os
import uuid
import weakref
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from pxr import Gf, Sdf, Vt  # (Sdf alone: Usd and the schema modules are not loaded for a bake)

from .errors import SimulationError
from .files import commit, remove_if_present, remove_stale_temps
from .usd_instancer import InstancerGroup
from .usd_values import merge_into, to_usd

__all__ = ["BodyPrim", "ClothPrim", "CacheWriter", "FORMATS", "InstancerGroup"]

#: target suffix -> file format the layer is saved in
FORMATS = {".usdc": "usdc", ".usd": "usdc", ".usda": "usda"}

_TN = Sdf.ValueTypeNames
_TRANSLATE = "xformOp:translate"
_ORIENT = "xformOp:orient"
_OP_ORDER = Vt.TokenArray([_TRANSLATE, _ORIENT])
_STATIC_POSE_ATOL = 1e-7  # a static body whose pose moves more than this is a caller bug
_INDEX_BYTES = 8  # crate bytes per time sample in an attribute's index, rewritten on each save


# --------------------------------------------------------------------------------------------
# prim descriptions
# --------------------------------------------------------------------------------------------

def _check_name(kind: str, name: str) -> None:
    if not isinstance(name, str) or not Sdf.Path.IsValidIdentifier(name):
        raise ValueError(f"{kind} name {name!r} is not a valid USD prim name")


def _topology(kind: str, name: str, counts: Any, indices: Any) -> tuple[np.ndarray, np.ndarray]:
    counts = np.ascontiguousarray(counts, dtype=np.int32).reshape(-1)
    indices = np.ascontiguousarray(indices, dtype=np.int32).reshape(-1)
    if counts.size and counts.min() < 3:
        raise ValueError(f"{kind} {name!r}: every face needs at least 3 vertices")
    if int(counts.sum(dtype=np.int64)) != indices.size:
        raise ValueError(
            f"{kind} {name!r}: face_vertex_counts sum to {int(counts.sum())} "
            f"but there are {indices.size} face_vertex_indices")
    if indices.size and indices.min() < 0:
        raise ValueError(f"{kind} {name!r}: negative face vertex index")
    counts.setflags(write=False)
    indices.setflags(write=False)
    return counts, indices


def _vec3(kind: str, name: str, field: str, value: Any, n: int | None = None) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3 or (n is not None and arr.shape[0] != n):
        want = f"({n}, 3)" if n is not None else "(n, 3)"
        raise ValueError(f"{kind} {name!r}: {field} must have shape {want}, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{kind} {name!r}: {field} contains NaN or inf")
    return arr


@dataclass(frozen=True)
class BodyPrim:
    """A rigid body: its mesh in its own frame, and whether its pose changes over time.

    Arrays are normalised on construction (points/normals float32 (n, 3), topology int32) and
    validated: shapes, counts summing to the index count, indices within the points. Normals
    are per point ("vertex") or per face-vertex ("faceVarying", one per face_vertex_indices
    entry: hard edges, see simbake.normals), told apart by their count.
    """

    name: str
    points: np.ndarray
    face_vertex_counts: np.ndarray
    face_vertex_indices: np.ndarray
    normals: np.ndarray
    dynamic: bool
    interpolation: str = ""  # of the normals: "vertex" | "faceVarying"; "" = by their count
    level_set: str = ""  # the .vdb the solver used (absolute path), shown as a guide Volume
    # a deforming body (its pose the identity): its points at every frame from `first_frame`
    # (frames, n, 3), written as time samples (no normals: they change), and its level sets,
    # a .vdb a frame (absolute paths, from first_frame), the guide Volume's time-sampled filePath
    frames: Any = field(default=None, compare=False, repr=False)
    first_frame: int = 0
    level_sets: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        _check_name("body", self.name)
        pts = _vec3("body", self.name, "points", self.points)
        counts, idx = _topology("body", self.name, self.face_vertex_counts,
                                self.face_vertex_indices)
        nrm = _vec3("body", self.name, "normals", self.normals)
        rows = {"vertex": (pts.shape[0],), "faceVarying": (idx.size,), "": (pts.shape[0], idx.size)}
        if self.interpolation not in rows:
            raise ValueError(f"body {self.name!r}: unknown normals interpolation {self.interpolation!r}")
        if nrm.shape[0] not in rows[self.interpolation]:
            raise ValueError(f"body {self.name!r}: normals must have one row per point "
                             f"({pts.shape[0]}) or per face vertex ({idx.size}), got {nrm.shape[0]}")
        if idx.size and idx.max() >= pts.shape[0]:
            raise ValueError(f"body {self.name!r}: face vertex index {int(idx.max())} "
                             f"out of range for {pts.shape[0]} points")
        for name, value in (("points", pts), ("normals", nrm)):
            value = np.ascontiguousarray(value, dtype=np.float32)
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        if self.frames is not None:
            frames = np.ascontiguousarray(self.frames, dtype=np.float32)
            if frames.ndim != 3 or frames.shape[1:] != pts.shape:
                raise ValueError(f"body {self.name!r}: frames must be (frames, {pts.shape[0]}, 3), got {frames.shape}")
            frames.setflags(write=False)
            object.__setattr__(self, "frames", frames)
        object.__setattr__(self, "face_vertex_counts", counts)
        object.__setattr__(self, "face_vertex_indices", idx)
        object.__setattr__(self, "dynamic", bool(self.dynamic))

    @property
    def normals_interpolation(self) -> str:
        """"vertex" (one normal per point) or "faceVarying" (one per face vertex)."""
        if self.interpolation:
            return self.interpolation
        if self.normals.shape[0] == self.points.shape[0]:
            return "vertex"
        return "faceVarying"


@dataclass(frozen=True)
class ClothPrim:
    """A cloth mesh: only its topology; points, normals and velocities come every frame."""

    name: str
    face_vertex_counts: np.ndarray
    face_vertex_indices: np.ndarray

    def __post_init__(self) -> None:
        _check_name("cloth", self.name)
        counts, idx = _topology("cloth", self.name, self.face_vertex_counts,
                                self.face_vertex_indices)
        object.__setattr__(self, "face_vertex_counts", counts)
        object.__setattr__(self, "face_vertex_indices", idx)


# --------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------

def _extent(points32: np.ndarray) -> Vt.Vec3fArray:
    if points32.shape[0] == 0:
        return Vt.Vec3fArray.FromNumpy(np.zeros((2, 3), np.float32))
    return Vt.Vec3fArray.FromNumpy(np.stack([points32.min(axis=0), points32.max(axis=0)]))


def _vertex_normals(points: np.ndarray, counts: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals (polygons fanned into triangles), unit length."""
    p = np.asarray(points, dtype=np.float64)
    normals = np.zeros_like(p)
    starts = np.zeros(counts.size, dtype=np.int64)
    np.cumsum(counts[:-1], out=starts[1:])
    for c in np.unique(counts):
        faces = indices[(starts[counts == c][:, None] + np.arange(c)).reshape(-1)].reshape(-1, c)
        for k in range(1, c - 1):
            a, b, d = faces[:, 0], faces[:, k], faces[:, k + 1]
            fn = np.cross(p[b] - p[a], p[d] - p[a])
            for v in (a, b, d):
                np.add.at(normals, v, fn)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)
    normals[length[:, 0] == 0] = (0.0, 1.0, 0.0)
    return normals


@contextmanager
def one_thread():
    """OpenUSD's own work (Work, and TBB under it) on one thread for the block: its parallel
    reductions (UsdUtils' clip stitching, the UsdPhysics parser) then run in one fixed order,
    so the same input gives the same bytes and the same reports every time."""
    from pxr import Work

    limit = Work.GetConcurrencyLimit()
    Work.SetConcurrencyLimit(1)
    try:
        yield
    finally:
        Work.SetConcurrencyLimit(limit)


def _cleanup(paths: list[Path]) -> None:  # weakref.finalize callback: must not reference self
    for p in paths:
        remove_if_present(p)


_counter = itertools.count()


# --------------------------------------------------------------------------------------------
# the writer
# --------------------------------------------------------------------------------------------

class StreamingWriter:
    """A writer used as a context manager: close() when the block ends normally, abort()
    (nothing written) when it raises. Subclasses define abort(); a writer of one layer
    (``_layer``, its temp files, frames start_frame..end_frame) finishes with this close(),
    others define their own."""

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    def close(self) -> Path:
        """Finish: final save, then move the file into place. Returns the path written.

        Raises ``RuntimeError`` (and removes the temp file) if not every frame was written.
        """
        if self._done:
            return self.path
        if self._layer is None:
            raise RuntimeError(f"{self.path}: writer was aborted")
        if self._next_frame != self.end_frame + 1:
            missing = self.end_frame + 1 - self._next_frame
            self.abort()
            raise RuntimeError(f"{self.path}: {missing} frame(s) not written (next expected "
                               f"{self._next_frame}, end {self.end_frame}); nothing saved")
        try:
            self._commit_layer()
        except BaseException:
            self.abort()
            raise
        self._done = True
        self._committed()
        return self.path

    def _committed(self) -> None:
        """Called once the file is in place (nothing more to do by default)."""

    def _commit_layer(self) -> None:
        """Save the layer to its temp file (and export it as text for .usda), then move it
        into place: fsync, then rename. The layer is released first (crate files are mapped)."""
        if not self._layer.Save():
            raise OSError(f"{self._tmp}: saving the USD layer failed")
        final = self._tmp
        if self._tmp_text is not None:
            if not self._layer.Export(str(self._tmp_text)):
                raise OSError(f"{self._tmp_text}: exporting the USD layer failed")
            final = self._tmp_text
        self._layer = None
        outputs = getattr(self, "outputs", None)
        if outputs is None:
            commit(Path(final), Path(self.path))
        else:  # one of a bake's outputs: renamed into place with the others (simbake.outputs)
            outputs.stage(Path(final), Path(self.path))
        if final != self._tmp:
            remove_if_present(self._tmp)



def body_mesh_name(name: str) -> str:
    """The name of a body's Mesh child: the body's own (``/World/ball/ball``), so that an
    importer that merges an Xform with its single child (Blender does) keeps the name; a body
    called ``levelset`` would meet its level-set Volume, so its mesh is ``levelset_mesh``."""
    return name if name != "levelset" else "levelset_mesh"

class CacheWriter(StreamingWriter):
    """Streams a simbake USD cache (version 1) to ``path``; see the module docstring.

    ``path`` ending in ``.usdc`` or ``.usd`` gives a binary crate file, ``.usda`` a text file;
    any other suffix is a :class:`ValueError`. ``flush_every`` is the least number of frames
    between saves of the temp file (see the module docstring for when a save happens).
    ``provenance`` goes to the layer's ``customLayerData``: strings, bools, ints, floats,
    paths, nested mappings and homogeneous lists become their USD types; mixed lists become
    dictionaries keyed ``"0000"``, ``"0001"``...; ``None`` values are left out.
    Frames ``start_frame..end_frame`` (inclusive) must each be written exactly once, in
    increasing order. The file appears at ``path`` only when :meth:`close` succeeds;
    :meth:`abort` (or an exception inside a ``with`` block) leaves ``path`` as it was.
    ``.usda`` is baked into a crate temp file and converted at :meth:`close`, which then
    holds the whole cache in memory once (text USD cannot be appended to).
    ``outputs`` (a :class:`simbake.outputs.Outputs`): the finished file is staged there, to be
    renamed into place with a bake's other outputs, instead of at :meth:`close`.
    """

    def __init__(self, path: str | Path, *, fps: float, start_frame: int, end_frame: int,
                 bodies: Sequence[BodyPrim], cloths: Sequence[ClothPrim] = (),
                 provenance: Mapping[str, Any] = {}, flush_every: int = 50,
                 instancers: Sequence["InstancerGroup"] = (), outputs=None):
        self.path = Path(path)
        self.outputs = outputs
        suffix = self.path.suffix.lower()
        if suffix not in FORMATS:
            raise ValueError(f"{self.path}: unknown USD file extension {self.path.suffix!r} "
                             f"(use one of {', '.join(sorted(FORMATS))})")
        self.format = FORMATS[suffix]
        fps = float(fps)
        if not (math.isfinite(fps) and fps > 0):
            raise ValueError(f"fps must be a positive number, got {fps}")
        if int(start_frame) != start_frame or int(end_frame) != end_frame:
            raise ValueError("start_frame and end_frame must be integers")
        start_frame, end_frame = int(start_frame), int(end_frame)
        if end_frame < start_frame:
            raise ValueError(f"end_frame {end_frame} is before start_frame {start_frame}")
        if int(flush_every) < 1:
            raise ValueError(f"flush_every must be >= 1, got {flush_every}")
        bodies, cloths = tuple(bodies), tuple(cloths)
        for b in bodies:
            if not isinstance(b, BodyPrim):
                raise TypeError(f"bodies must be BodyPrim, got {type(b).__name__}")
        for c in cloths:
            if not isinstance(c, ClothPrim):
                raise TypeError(f"cloths must be ClothPrim, got {type(c).__name__}")
        names = [p.name for p in bodies + cloths]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"duplicate prim names: {', '.join(dup)}")
        if not self.path.parent.is_dir():
            raise FileNotFoundError(f"{self.path}: directory {self.path.parent} does not exist")
        provenance_usd = to_usd(dict(provenance), "customLayerData")

        self.fps = fps
        self.start_frame, self.end_frame = start_frame, end_frame
        self.bodies, self.cloths = bodies, cloths
        self.instancer_groups = tuple(instancers)
        self._instanced = {i for g in self.instancer_groups for i in g.bodies}
        taken = set(names)
        for g in self.instancer_groups:
            _check_name("instancer", g.name)
            if g.name in taken or not g.bodies or any(not 0 <= i < len(bodies) for i in g.bodies):
                raise ValueError(f"instancer {g.name!r}: a duplicate name or bad body indices")
            taken.add(g.name)
        self.flush_every = int(flush_every)
        self._next_frame = start_frame
        self._since_flush = 0
        self._pending_bytes = 0
        self._static_pose: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._cloth_nverts: list[int | None] = [None] * len(cloths)
        self._done = False

        # temp files beside the target; the crate one always, the text one only for .usda
        # (and those a killed bake of the same target left behind are removed first)
        remove_stale_temps(self.path)
        tag = f".{self.path.name}.{os.getpid()}-{next(_counter)}-{uuid.uuid4().hex[:8]}.tmp"
        self._tmp = self.path.with_name(tag + ".usdc")
        self._tmp_text = self.path.with_name(tag + ".usda") if self.format == "usda" else None
        temps = [self._tmp] + ([self._tmp_text] if self._tmp_text else [])
        self._finalizer = weakref.finalize(self, _cleanup, temps)

        layer = Sdf.Layer.CreateNew(str(self._tmp), args={"format": "usdc"})
        if layer is None:
            raise OSError(f"{self._tmp}: cannot create USD layer")
        self._layer = layer
        try:
            self._author_static(provenance_usd)
            layer.Save()
        except BaseException:
            self.abort()
            raise

    # -- authoring ----------------------------------------------------------------------------

    def _author_static(self, provenance: dict) -> None:
        layer = self._layer
        # stage-level metadata, the fields UsdGeom.SetStageUpAxis, SetStageMetersPerUnit and
        # UsdPhysics.SetStageKilogramsPerUnit author (set on the layer: a stage, and the schema
        # modules, cost a bake's start-up a tenth of a second)
        layer.pseudoRoot.SetInfo("upAxis", "Y")
        layer.pseudoRoot.SetInfo("metersPerUnit", 1.0)
        layer.pseudoRoot.SetInfo("kilogramsPerUnit", 1.0)
        layer.timeCodesPerSecond = self.fps
        layer.framesPerSecond = self.fps
        layer.startTimeCode = float(self.start_frame)
        layer.endTimeCode = float(self.end_frame)
        layer.defaultPrim = "World"
        if provenance:
            layer.customLayerData = provenance

        self._translate_paths: list[Sdf.Path] = []
        self._orient_paths: list[Sdf.Path] = []
        self._cloth_paths: list[tuple[Sdf.Path, Sdf.Path, Sdf.Path, Sdf.Path]] = []
        self._deforming: list[tuple[int, Sdf.Path, Sdf.Path]] = []  # (body, points, extent)
        with Sdf.ChangeBlock():
            world = self._def(Sdf.Path.absoluteRootPath, "World", "Xform")
            world.kind = "component"  # the cache is one referenceable asset (a leaf model)
            for index, body in enumerate(self.bodies):
                if index in self._instanced:  # drawn by its PointInstancer
                    self._translate_paths.append(None)
                    self._orient_paths.append(None)
                    continue
                xf = self._def(world.path, body.name, "Xform")
                t = self._attr(xf, _TRANSLATE, _TN.Double3)
                o = self._attr(xf, _ORIENT, _TN.Quatd)
                self._attr(xf, "xformOpOrder", _TN.TokenArray, _OP_ORDER, uniform=True)
                self._translate_paths.append(t.path)
                self._orient_paths.append(o.path)
                mesh = self._def(xf.path, body_mesh_name(body.name), "Mesh")
                self._mesh_topology(mesh, body.face_vertex_counts, body.face_vertex_indices)
                if body.frames is not None:  # sampled every frame (write_frame)
                    p = self._attr(mesh, "points", _TN.Point3fArray)
                    e = self._attr(mesh, "extent", _TN.Float3Array)
                    self._deforming.append((index, p.path, e.path))
                else:
                    self._attr(mesh, "points", _TN.Point3fArray, Vt.Vec3fArray.FromNumpy(body.points))
                    n = self._attr(mesh, "normals", _TN.Normal3fArray,
                                   Vt.Vec3fArray.FromNumpy(body.normals))
                    n.SetInfo("interpolation", body.normals_interpolation)
                    self._attr(mesh, "extent", _TN.Float3Array, _extent(body.points))
                if body.level_set or body.level_sets:
                    self._level_set_volume(xf, body)
            for cloth in self.cloths:
                mesh = self._def(world.path, cloth.name, "Mesh")
                self._mesh_topology(mesh, cloth.face_vertex_counts, cloth.face_vertex_indices)
                self._attr(mesh, "doubleSided", _TN.Bool, True, uniform=True)
                p = self._attr(mesh, "points", _TN.Point3fArray)
                n = self._attr(mesh, "normals", _TN.Normal3fArray)
                n.SetInfo("interpolation", "vertex")
                v = self._attr(mesh, "velocities", _TN.Vector3fArray)
                e = self._attr(mesh, "extent", _TN.Float3Array)
                self._cloth_paths.append((p.path, n.path, v.path, e.path))
            from .usd_instancer import InstancerSpecs

            self._instancers = InstancerSpecs(self, world.path, self.instancer_groups, self.bodies)
        self._dynamic = [(i, self._translate_paths[i], self._orient_paths[i])
                         for i, b in enumerate(self.bodies) if b.dynamic and i not in self._instanced]
        self._static = [i for i, b in enumerate(self.bodies) if not b.dynamic and i not in self._instanced]
        self._n_sampled = 2 * len(self._dynamic) + 4 * len(self.cloths) + self._instancers.sampled_count \
            + 2 * len(self._deforming)
        # filled in for cloths on the first frame
        self._frame_bytes = 56 * len(self._dynamic) + self._instancers.frame_bytes() \
            + sum(12 * len(self.bodies[i].points) + 24 for i, _, _ in self._deforming)

    def _level_set_volume(self, xf: Sdf.PrimSpec, body: BodyPrim) -> None:
        """levelset: a guide Volume whose OpenVDBAsset field is the body's .vdb (grid "surface"),
        by a path relative to this file, in the body's (mesh origin's) frame."""
        volume = self._def(xf.path, "levelset", "Volume")
        self._attr(volume, "purpose", _TN.Token, "guide", uniform=True)
        field = self._def(volume.path, "surface", "OpenVDBAsset")
        file_path = self._attr(field, "filePath", _TN.Asset, self._relative_asset(body.level_set or body.level_sets[0]))
        for frame in range(self.start_frame, self.end_frame + 1) if body.level_sets else ():  # one a frame
            self._layer.SetTimeSample(file_path.path, float(frame),
                                      self._relative_asset(body.level_sets[frame - body.first_frame]))
        self._attr(field, "fieldName", _TN.Token, "surface")
        rel = Sdf.RelationshipSpec(volume, "field:surface", custom=False)
        rel.targetPathList.explicitItems = [field.path]
        # (the grid's narrow band hugs the surface, over every frame of a deforming one)
        points = body.points if body.frames is None else body.frames.reshape(-1, 3)
        self._attr(volume, "extent", _TN.Float3Array, _extent(points))

    def _relative_asset(self, path: str) -> Sdf.AssetPath:
        relative = os.path.relpath(path, self.path.parent.absolute())
        return Sdf.AssetPath(relative if relative.startswith("..") else f"./{relative}")

    def _def(self, parent: Sdf.Path, name: str, type_name: str) -> Sdf.PrimSpec:
        spec = Sdf.CreatePrimInLayer(self._layer, parent.AppendChild(name))
        spec.specifier = Sdf.SpecifierDef
        spec.typeName = type_name
        return spec

    @staticmethod
    def _attr(prim: Sdf.PrimSpec, name: str, type_name: Sdf.ValueTypeName, default: Any = None,
              uniform: bool = False) -> Sdf.AttributeSpec:
        var = Sdf.VariabilityUniform if uniform else Sdf.VariabilityVarying
        attr = Sdf.AttributeSpec(prim, name, type_name, var)
        if default is not None:
            attr.default = default
        return attr

    def _mesh_topology(self, mesh: Sdf.PrimSpec, counts: np.ndarray, indices: np.ndarray) -> None:
        self._attr(mesh, "faceVertexCounts", _TN.IntArray, Vt.IntArray.FromNumpy(counts))
        self._attr(mesh, "faceVertexIndices", _TN.IntArray, Vt.IntArray.FromNumpy(indices))
        self._attr(mesh, "subdivisionScheme", _TN.Token, "none", uniform=True)
        self._attr(mesh, "orientation", _TN.Token, "rightHanded", uniform=True)

    # -- per frame ----------------------------------------------------------------------------

    def write_frame(self, frame: int, translations: np.ndarray, orientations: np.ndarray,
                    cloth_points: Sequence[np.ndarray] = (),
                    cloth_velocities: Sequence[np.ndarray] = (),
                    cloth_normals: Sequence[np.ndarray] = (),
                    body_velocities: np.ndarray | None = None,
                    body_angular_velocities: np.ndarray | None = None) -> None:
        """Author one frame.

        ``translations`` (nbodies, 3): world position of each body's mesh origin;
        ``orientations`` (nbodies, 4): unit quaternions ``[w, x, y, z]``, in the order of
        ``bodies``. Static bodies take their pose from the first frame only (a later pose that
        differs is a ``ValueError``). Per cloth: ``cloth_points`` and ``cloth_velocities``
        (metres per second), both (nverts, 3), are required; ``cloth_normals`` may be left
        empty, in which case area-weighted vertex normals are computed here. With instancers,
        ``body_velocities`` (m/s, of the mesh origins) and ``body_angular_velocities`` (rad/s,
        world axes), both (nbodies, 3), are required too.
        Non-finite values raise :class:`simbake.errors.SimulationError`.
        """
        if self._done or self._layer is None:
            raise RuntimeError(f"{self.path}: writer is already closed")
        if frame != self._next_frame:
            if self._next_frame > self.end_frame:
                raise ValueError(f"frame {frame}: all frames up to {self.end_frame} are written")
            raise ValueError(f"frame {frame}: expected frame {self._next_frame} "
                             f"(frames {self.start_frame}..{self.end_frame}, in order, once each)")
        nb = len(self.bodies)
        tr = np.asarray(translations, dtype=np.float64).reshape(-1, 3) if nb else np.zeros((0, 3))
        qs = np.asarray(orientations, dtype=np.float64).reshape(-1, 4) if nb else np.zeros((0, 4))
        if tr.shape != (nb, 3) or qs.shape != (nb, 4):
            raise ValueError(f"frame {frame}: expected translations ({nb}, 3) and "
                             f"orientations ({nb}, 4), got {np.shape(translations)} and "
                             f"{np.shape(orientations)}")
        if not (np.isfinite(tr).all() and np.isfinite(qs).all()):
            bad = ~(np.isfinite(tr).all(axis=1) & np.isfinite(qs).all(axis=1))
            raise SimulationError(f"frame {frame}: body {self.bodies[int(np.argmax(bad))].name!r} "
                                  "has a non-finite pose")
        cloth_data = self._cloth_frame(frame, cloth_points, cloth_velocities, cloth_normals)
        bv = bw = None
        if self.instancer_groups:
            if body_velocities is None or body_angular_velocities is None:
                raise ValueError(f"frame {frame}: instancers need body_velocities and body_angular_velocities")
            bv = np.asarray(body_velocities, dtype=np.float64).reshape(nb, 3)
            bw = np.asarray(body_angular_velocities, dtype=np.float64).reshape(nb, 3)
            if not (np.isfinite(bv).all() and np.isfinite(bw).all()):
                raise SimulationError(f"frame {frame}: a body velocity is not finite")

        first = frame == self.start_frame
        if not first:
            for i, (t0, q0) in self._static_pose.items():
                if (np.abs(tr[i] - t0).max() > _STATIC_POSE_ATOL
                        or np.abs(qs[i] - q0).max() > _STATIC_POSE_ATOL):
                    raise ValueError(f"frame {frame}: static body {self.bodies[i].name!r} "
                                     "moved; mark it dynamic")

        time = float(frame)
        layer = self._layer
        set_sample = layer.SetTimeSample
        # python floats: much faster into Gf (only where a body is sampled on its own prim)
        rows_t, rows_q = (tr.tolist(), qs.tolist()) if self._dynamic or (first and self._static) else ((), ())
        Vec3d, Quatd, from_numpy = Gf.Vec3d, Gf.Quatd, Vt.Vec3fArray.FromNumpy
        with Sdf.ChangeBlock():
            for i, t_path, q_path in self._dynamic:
                t, q = rows_t[i], rows_q[i]
                set_sample(t_path, time, Vec3d(t[0], t[1], t[2]))
                set_sample(q_path, time, Quatd(q[0], q[1], q[2], q[3]))
            if first:
                for i in self._static:
                    t, q = rows_t[i], rows_q[i]
                    self._static_pose[i] = (tr[i].copy(), qs[i].copy())
                    layer.GetAttributeAtPath(self._translate_paths[i]).default = \
                        Vec3d(t[0], t[1], t[2])
                    layer.GetAttributeAtPath(self._orient_paths[i]).default = \
                        Quatd(q[0], q[1], q[2], q[3])
            if self.instancer_groups:
                self._instancers.write(layer, time, tr, qs, bv, bw)
            for i, p_path, e_path in self._deforming:
                body = self.bodies[i]
                pts = body.frames[frame - body.first_frame]
                set_sample(p_path, time, from_numpy(pts))
                set_sample(e_path, time, _extent(pts))
            for paths, (pts, nrm, vel) in zip(self._cloth_paths, cloth_data):
                p_path, n_path, v_path, e_path = paths
                set_sample(p_path, time, from_numpy(pts))
                set_sample(n_path, time, from_numpy(nrm))
                set_sample(v_path, time, from_numpy(vel))
                set_sample(e_path, time, _extent(pts))
        self._next_frame += 1
        self._since_flush += 1
        self._pending_bytes += self._frame_bytes
        # An incremental crate save appends the new values but rewrites the whole time index of
        # every sampled attribute (8 bytes per sample so far). Save only when the pending data
        # outweighs that, so saves of many small samples (rigid bodies) get geometrically rarer
        # instead of bloating the file; big samples (cloth) are saved every flush_every frames.
        if (self._since_flush >= self.flush_every and self._next_frame <= self.end_frame
                and self._pending_bytes >= _INDEX_BYTES * self._n_sampled * self.frames_written):
            self.flush()

    def _cloth_frame(self, frame, points, velocities, normals):
        nc = len(self.cloths)
        points, velocities, normals = list(points), list(velocities), list(normals)
        if len(points) != nc or len(velocities) != nc or len(normals) not in (0, nc):
            raise ValueError(
                f"frame {frame}: expected {nc} cloth_points and cloth_velocities arrays (and "
                f"cloth_normals: {nc} or none), got {len(points)}, {len(velocities)}, "
                f"{len(normals)}")
        out = []
        for c, cloth in enumerate(self.cloths):
            p = np.ascontiguousarray(points[c], dtype=np.float32)
            n = self._cloth_nverts[c]
            if n is None:
                n = p.shape[0] if p.ndim == 2 else -1
                idx = cloth.face_vertex_indices
                if idx.size and idx.max() >= n:
                    raise ValueError(f"frame {frame}: cloth {cloth.name!r} has {n} points but "
                                     f"its faces use vertex {int(idx.max())}")
                self._cloth_nverts[c] = n
                self._frame_bytes += 3 * 12 * n + 24  # points, normals, velocities, extent
            arrays = [p, np.ascontiguousarray(velocities[c], dtype=np.float32)]
            if normals:
                arrays.append(np.ascontiguousarray(normals[c], dtype=np.float32))
            for what, a in zip(("points", "velocities", "normals"), arrays):
                if a.shape != (n, 3):
                    raise ValueError(f"frame {frame}: cloth {cloth.name!r} {what} must have "
                                     f"shape ({n}, 3), got {a.shape}")
                if not np.isfinite(a).all():
                    raise SimulationError(f"frame {frame}: cloth {cloth.name!r} {what} "
                                          "contain NaN or inf")
            if not normals:
                arrays.append(_vertex_normals(p, cloth.face_vertex_counts,
                                              cloth.face_vertex_indices).astype(np.float32))
            out.append((arrays[0], arrays[2], arrays[1]))
        return out

    def add_layer_data(self, data: Mapping[str, Any]) -> None:
        """Merge `data` into the layer's customLayerData (nested dictionaries merged key by
        key), e.g. a summary known only once every frame is written; same rules as provenance."""
        if self._done or self._layer is None:
            raise RuntimeError(f"{self.path}: writer is already closed")
        merged = dict(self._layer.customLayerData)
        merge_into(merged, to_usd(dict(data), "customLayerData"))
        self._layer.customLayerData = merged

    # -- finishing ----------------------------------------------------------------------------

    @property
    def frames_written(self) -> int:
        return self._next_frame - self.start_frame

    def flush(self) -> None:
        """Save what is authored so far to the temp file (crate saves append; memory drops)."""
        if self._layer is None:
            raise RuntimeError(f"{self.path}: writer is already closed")
        if not self._layer.Save():
            raise OSError(f"{self._tmp}: saving the USD layer failed")
        self._since_flush = 0
        self._pending_bytes = 0

    def _committed(self) -> None:
        self._finalizer.detach()  # the temp files are gone: nothing left to clean up

    def abort(self) -> None:
        """Discard everything: remove the temp file(s); ``path`` is left untouched."""
        if self._done:
            return
        self._layer = None
        self._finalizer()  # removes the temp files (once)

