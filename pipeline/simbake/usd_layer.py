"""The cache layer of a USD shot (DESIGN.md, "USD shots in, cache layers out (cache version 2)").

A shot's cache holds only ``over`` opinions at the input's own prim paths, so that a stage
which sublayers it over the input shows the simulated shot:

    /<rigid body>   xformOpOrder = [xformOp:translate, xformOp:orient (, xformOp:scale)],
                    translate and orient time-sampled at every frame, local to the prim's
                    parent; scale (the prim's own, when it is not 1) written once
    /<cloth mesh>   points, normals ("vertex"), velocities (stage units / s) and extent,
                    time-sampled at every frame, in the mesh's own space
    /<instance>     instanceable = false, for every instanceable prim above a simulated one
                    (composition ignores overs on instance proxies)

Layer metadata (upAxis, metersPerUnit, kilogramsPerUnit, timeCodesPerSecond,
framesPerSecond, start and end time codes, defaultPrim) is the input's; values are in the
input's units and axes. Kinematic bodies and static colliders are not written: the input
already says where they are.

Simulated poses come in simbake's frame (SI, Y up; usd_scene.py's module docstring). A
body's simulated world pose (R, t) goes back to the stage as ``R_s = C^T R C``,
``t_s = C^T t / metersPerUnit``, then local to the parent (rotation ``R_p``, translation
``t_p``, uniform scale ``s_p``): orient ``R_p^T R_s``, translate ``R_p^T (t_s - t_p) / s_p``;
with the prim's own scale after the orient, the composed world transform is the body frame
times the prim's world scale, as at the start.

Writing is the same as the standalone cache's (usd_writer.py): Sdf-level specs, ``Vt``
arrays from numpy, one ``Sdf.ChangeBlock`` per frame, a crate temp file beside the target
saved every ``flush_every`` frames when the shot has cloth, exported to text at the end for
``.usda``, renamed into place only when complete. Same scene in, same bytes out.
"""

from __future__ import annotations

import os
import secrets
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from pxr import Gf, Sdf, Vt

from .errors import SceneError, SimulationError
from .files import remove_if_present, write_atomically
from .usd_values import merge_into, to_usd
from .usd_writer import FORMATS, StreamingWriter

__all__ = ["ShotLayerWriter", "write_shot_stage"]

_TN = Sdf.ValueTypeNames
_TRANSLATE, _ORIENT, _SCALE = "xformOp:translate", "xformOp:orient", "xformOp:scale"
_VEC3 = {"double3": (_TN.Double3, Gf.Vec3d), "float3": (_TN.Float3, Gf.Vec3f), "half3": (_TN.Half3, Gf.Vec3h)}
_QUAT = {"quatd": (_TN.Quatd, Gf.Quatd), "quatf": (_TN.Quatf, Gf.Quatf), "quath": (_TN.Quath, Gf.Quath)}


def copy_stage_metadata(layer: Sdf.Layer, shot) -> None:
    """The input shot's stage metadata: axes, units, time codes, default prim."""
    root = layer.pseudoRoot
    root.SetInfo("upAxis", shot.up_axis)
    root.SetInfo("metersPerUnit", shot.meters_per_unit)
    root.SetInfo("kilogramsPerUnit", shot.kilograms_per_unit)
    layer.timeCodesPerSecond = shot.time_codes_per_second
    layer.framesPerSecond = shot.frames_per_second or shot.time_codes_per_second
    layer.startTimeCode, layer.endTimeCode = shot.start_time_code, shot.end_time_code
    if shot.default_prim:
        layer.defaultPrim = shot.default_prim


# --------------------------------------------------------------------------------------------
# quaternions (w, x, y, z), vectorized over rows
# --------------------------------------------------------------------------------------------

def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw], axis=-1)


def _qconj(q: np.ndarray) -> np.ndarray:
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def _qrotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate rows v by rows q: v + 2 w (u x v) + 2 u x (u x v)."""
    w, u = q[..., :1], q[..., 1:]
    c = np.cross(u, v)
    return v + 2.0 * w * c + 2.0 * np.cross(u, c)


# --------------------------------------------------------------------------------------------
# the writer
# --------------------------------------------------------------------------------------------

def author_joint_breaks(layer: Sdf.Layer, breaks: Mapping[str, int], start: int, end: int) -> None:
    """Joints that broke (prim path: the first frame it is broken at): ``over`` the joint
    with ``physics:jointEnabled`` time-sampled at every frame of [start, end]: true before that
    frame, false from it (a sample at every frame, as every other attribute the cache samples)."""
    for path, frame in sorted(breaks.items()):
        prim = Sdf.CreatePrimInLayer(layer, path)
        prim.specifier = Sdf.SpecifierOver
        attr = prim.attributes.get("physics:jointEnabled") or Sdf.AttributeSpec(
            prim, "physics:jointEnabled", Sdf.ValueTypeNames.Bool)
        for f in range(start, end + 1):
            layer.SetTimeSample(attr.path, float(f), f < frame)


class ShotLayerWriter(StreamingWriter):
    """Streams a shot's cache layer to ``path`` (``.usdc``/``.usd`` crate, ``.usda`` text).

    The same interface as :class:`simbake.usd_writer.CacheWriter`: frames
    ``start_frame..end_frame`` written once each, in order, with :meth:`write_frame`; the file
    appears at :meth:`close`; :meth:`abort` (or an exception in a ``with`` block) leaves
    ``path`` as it was.
    """

    def __init__(self, path: str | Path, scene, *, provenance: Mapping[str, Any] = {},
                 flush_every: int = 50, start_frame: int | None = None, end_frame: int | None = None,
                 level_sets: Mapping[int, Path] | None = None, outputs=None):
        self.path = Path(path)
        self.outputs = outputs  # simbake.outputs.Outputs: staged there at close (CacheWriter's)
        suffix = self.path.suffix.lower()
        if suffix not in FORMATS:
            raise ValueError(f"{self.path}: unknown USD file extension {self.path.suffix!r}")
        shot = scene.shot
        self.shot, self.scene = shot, scene
        # a clip (usd_clips.ShotClipsWriter) writes a part of the shot's frames
        self.start_frame = scene.start_frame if start_frame is None else int(start_frame)
        self.end_frame = scene.end_frame if end_frame is None else int(end_frame)
        self._level_sets = dict(level_sets or {})
        self.flush_every = int(flush_every) if shot.cloths else 0
        self._next_frame = self.start_frame
        tag = f".{self.path.name}.{os.getpid()}-{secrets.token_hex(4)}.tmp"
        self._tmp = self.path.parent / f"{tag}.usdc"
        self._tmp_text = self.path.parent / f"{tag}.usda" if FORMATS[suffix] == "usda" else None
        self._done = False
        layer = Sdf.Layer.CreateNew(str(self._tmp))
        if layer is None:
            raise OSError(f"{self._tmp}: cannot create the USD layer")
        self._layer = layer
        try:
            self._define(layer, provenance)
        except BaseException:
            self.abort()
            raise

    # -- the layer's specs, once ----------------------------------------------------------

    def _define(self, layer: Sdf.Layer, provenance: Mapping[str, Any]) -> None:
        shot = self.shot
        copy_stage_metadata(layer, shot)
        layer.customLayerData = to_usd(dict(provenance), "customLayerData")

        # instances above simulated prims become ordinary prims here: composition ignores
        # opinions on instance proxies, so the overs below would show nothing
        for path in getattr(shot, "instances", ()):
            Sdf.CreatePrimInLayer(layer, path).SetInfo("instanceable", False)
        # prims this layer writes (value clips go on their root prims)
        self.sampled_prims = [b.prim_path for b in shot.bodies] + [c.prim_path for c in shot.cloths]
        self._bodies = []  # (body index, translate path, orient path, Vec3 type, Quat type)
        self._matrix_bodies = []  # (row, transform path, A (3x3)): ShotBody.shape_matrix
        for row, b in enumerate(shot.bodies):
            spec = Sdf.CreatePrimInLayer(layer, b.prim_path)  # `over`, ancestors too
            if b.shape_matrix is not None:  # its world transform whole, after !resetXformStack!
                op = Sdf.AttributeSpec(spec, "xformOp:transform", _TN.Matrix4d)
                Sdf.AttributeSpec(spec, "xformOpOrder", _TN.TokenArray, variability=Sdf.VariabilityUniform
                                  ).default = Vt.TokenArray(["!resetXformStack!", "xformOp:transform"])
                self._matrix_bodies.append((row, op.path, np.array(b.shape_matrix, dtype=np.float64)))
                self._bodies.append(None)
                continue
            t_name, t_type = _VEC3.get(b.op_types.get(_TRANSLATE, "double3"), _VEC3["double3"])
            q_name, q_type = _QUAT.get(b.op_types.get(_ORIENT, "quatf"), _QUAT["quatf"])
            Sdf.AttributeSpec(spec, _TRANSLATE, t_name)
            Sdf.AttributeSpec(spec, _ORIENT, q_name)
            order = (["!resetXformStack!"] if b.reset_xform_stack else []) + [_TRANSLATE, _ORIENT]
            if b.scale is not None:
                s_name, s_type = _VEC3.get(b.op_types.get(_SCALE, "float3"), _VEC3["float3"])
                Sdf.AttributeSpec(spec, _SCALE, s_name).default = s_type(*b.scale)
                order.append(_SCALE)
            Sdf.AttributeSpec(spec, "xformOpOrder", _TN.TokenArray,
                              variability=Sdf.VariabilityUniform).default = Vt.TokenArray(order)
            path = Sdf.Path(b.prim_path)
            self._bodies.append((b.index, path.AppendProperty(_TRANSLATE), path.AppendProperty(_ORIENT),
                                 t_type, q_type))
        count = len(shot.bodies)
        self._parent_q = np.array([b.parent_rotation for b in shot.bodies], dtype=np.float64).reshape(count, 4)
        self._parent_t = np.array([b.parent_translation for b in shot.bodies], dtype=np.float64).reshape(count, 3)
        self._parent_s = np.array([b.parent_scale for b in shot.bodies], dtype=np.float64).reshape(count, 1)
        self._index = np.array([b.index for b in shot.bodies], dtype=np.int64)
        # animated parents: (row, rotations (frames, 4), translations (frames, 3), scales (frames, 1))
        self._tracks = [(row, np.array([f[0] for f in b.parent_track]), np.array([f[1] for f in b.parent_track]),
                         np.array([[f[2]] for f in b.parent_track]))
                        for row, b in enumerate(shot.bodies) if b.parent_track]

        self._cloths = []  # (cloth index, world_to_local 4x4, local_to_world 3x3, paths)
        for c in shot.cloths:
            spec = Sdf.CreatePrimInLayer(layer, c.prim_path)
            paths = []
            for name, type_name in (("points", _TN.Point3fArray), ("normals", _TN.Normal3fArray),
                                    ("velocities", _TN.Vector3fArray), ("extent", _TN.Float3Array)):
                attr = Sdf.AttributeSpec(spec, name, type_name)
                if name == "normals":
                    attr.SetInfo("interpolation", "vertex")
                paths.append(attr.path)
            to_local = np.array(c.world_to_local, dtype=np.float64)
            self._cloths.append((c.index, to_local, np.linalg.inv(to_local[:3, :3]), paths))
        self._volume_tracks, self._volume_keyed = [], []
        if self._level_sets:
            self._level_set_volumes(layer)

    def _level_set_volumes(self, layer: Sdf.Layer) -> None:
        """Each level set the bake used: a ``def Volume`` (purpose guide) whose
        ``OpenVDBAsset`` field "surface" names the .vdb by a path relative to the cache.

        The Volume is ``levelset`` under its body's prim (an ``over``) when that prim is not
        itself a Gprim; under a Gprim (a Mesh, Capsule or Cylinder collider that is its own
        body) OpenUSD forbids a nested Gprim, so it is ``<name>_levelset`` beside the prim,
        its ``xformOp:transform`` time-sampled to follow it. The grid is in simbake's body
        frame (metres, Y up); the transform takes it into the prim's own space (stage units
        and axes, the prim's scale undone), from the input's transform at the start."""
        from pxr import Usd, UsdGeom

        shot, scene = self.shot, self.scene
        stage = Usd.Stage.Open(str(shot.path), Usd.Stage.LoadNone)
        xforms = UsdGeom.XformCache(Usd.TimeCode(shot.start_time_code))
        C, mpu = shot.axes, shot.meters_per_unit
        rows = {b.index: row for row, b in enumerate(shot.bodies)}
        self._volume_tracks = []  # (row of a dynamic body, transform path, M (4x4, column vectors))
        self._volume_keyed = []   # (transform path, (frames, 4, 4) row-vector matrices from the start)
        for index, vdb in sorted(self._level_sets.items()):
            body = scene.bodies[index]
            prim = stage.GetPrimAtPath(body.prim_path)
            if not prim:
                continue
            # the body frame (m, simbake axes) -> stage world, column vectors: x = r C^T b / mpu + t
            w, x, y, z = body.orientation
            R = np.array(Gf.Matrix3d(Gf.Rotation(Gf.Quatd(w, Gf.Vec3d(x, y, z)))).GetTranspose())
            to_world = np.eye(4)
            to_world[:3, :3] = C.T @ R / mpu
            to_world[:3, 3] = C.T @ np.asarray(body.position, dtype=np.float64) / mpu
            prim_world = np.array(xforms.GetLocalToWorldTransform(prim)).T  # Gf is row-vector
            local = np.linalg.inv(prim_world) @ to_world  # the grid in the prim's own space
            gprim = prim.IsA(UsdGeom.Gprim)
            if gprim:
                parent_path = prim.GetPath().GetParentPath()
                name = f"{prim.GetName()}_levelset"
                while stage.GetPrimAtPath(parent_path.AppendChild(name)):
                    name += "_"
                if parent_path == Sdf.Path.absoluteRootPath:
                    volume = Sdf.PrimSpec(layer, name, Sdf.SpecifierDef, "Volume")
                else:
                    volume = Sdf.PrimSpec(Sdf.CreatePrimInLayer(layer, parent_path), name, Sdf.SpecifierDef, "Volume")
            else:
                volume = Sdf.PrimSpec(Sdf.CreatePrimInLayer(layer, body.prim_path), "levelset",
                                      Sdf.SpecifierDef, "Volume")
            Sdf.AttributeSpec(volume, "purpose", _TN.Token, variability=Sdf.VariabilityUniform).default = "guide"
            if gprim:
                xformable = UsdGeom.Xformable(prim)
                reset = xformable.GetResetXformStack() or (index in rows and self.shot.bodies[rows[index]].reset_xform_stack)
                order = (["!resetXformStack!"] if reset else []) + ["xformOp:transform"]
                op = Sdf.AttributeSpec(volume, "xformOp:transform", _TN.Matrix4d)
                if index in rows:  # dynamic: the cache's pose of the prim, every frame
                    self._volume_tracks.append((rows[index], op.path, local))
                elif xformable.TransformMightBeTimeVarying():  # kinematic: the input's animation
                    mats = np.array([np.array(xformable.GetLocalTransformation(Usd.TimeCode(code)))
                                     for code in range(int(shot.start_time_code), int(shot.end_time_code) + 1)])
                    self._volume_keyed.append((op.path, np.einsum("ij,fjk->fik", local.T, mats)))
                else:  # static
                    op.default = Gf.Matrix4d((local.T @ np.array(xformable.GetLocalTransformation())).tolist())
            elif not np.allclose(local, np.eye(4), rtol=0.0, atol=1e-12):
                order = ["xformOp:transform"]
                Sdf.AttributeSpec(volume, "xformOp:transform", _TN.Matrix4d).default = Gf.Matrix4d(local.T.tolist())
            else:
                order = []
            if order:
                Sdf.AttributeSpec(volume, "xformOpOrder", _TN.TokenArray, variability=Sdf.VariabilityUniform
                                  ).default = Vt.TokenArray(order)
            field = Sdf.PrimSpec(volume, "surface", Sdf.SpecifierDef, "OpenVDBAsset")
            sequence = tuple(vdb) if isinstance(vdb, (list, tuple)) else (vdb,)  # a deforming collider's: a frame each
            file_path = Sdf.AttributeSpec(field, "filePath", _TN.Asset)
            file_path.default = self._relative_asset(sequence[0])
            for k, frame_vdb in enumerate(sequence if len(sequence) > 1 else ()):
                layer.SetTimeSample(file_path.path, shot.start_time_code + k, self._relative_asset(frame_vdb))
            Sdf.AttributeSpec(field, "fieldName", _TN.Token).default = "surface"
            rel = Sdf.RelationshipSpec(volume, "field:surface", custom=False)
            rel.targetPathList.explicitItems = [field.path]
            points = np.asarray(body.shape.mesh_vertices if body.deformation is None  # the band hugs the surface
                                else body.deformation.vertices.reshape(-1, 3), dtype=np.float32)
            Sdf.AttributeSpec(volume, "extent", _TN.Float3Array).default = Vt.Vec3fArray.FromNumpy(
                np.stack([points.min(axis=0), points.max(axis=0)]))
            self.sampled_prims.append(str(volume.path))

    def _relative_asset(self, vdb) -> Sdf.AssetPath:
        """A .vdb beside the cache as an asset path relative to the cache."""
        relative = os.path.relpath(Path(vdb).absolute(), self.path.parent.absolute())
        return Sdf.AssetPath(relative if relative.startswith("..") else f"./{relative}")

    # -- frames -------------------------------------------------------------------------------

    def write_frame(self, frame: int, translations, orientations, *, cloth_points: Sequence = (),
                    cloth_velocities: Sequence = (), cloth_normals: Sequence = ()) -> None:
        """One frame: every body's simulated pose (simbake's frame), every cloth's state."""
        if self._done or self._layer is None:
            raise RuntimeError(f"{self.path}: writer is closed")
        if frame != self._next_frame:
            raise ValueError(f"frame {frame} written out of order (expected {self._next_frame})")
        shot, layer = self.shot, self._layer
        mpu, C = shot.meters_per_unit, shot.axes
        translations = np.asarray(translations, dtype=np.float64).reshape(-1, 3)
        orientations = np.asarray(orientations, dtype=np.float64).reshape(-1, 4)
        if not (np.isfinite(translations).all() and np.isfinite(orientations).all()):
            raise SimulationError(f"frame {frame}: a body pose contains NaN or inf")
        # stage world poses, then local to each parent
        t_world = translations[self._index] @ C / mpu  # rows: C^T t / mpu
        qc = np.array(shot.axes_quaternion)[None, :]
        q_world = _qmul(_qmul(_qconj(qc), orientations[self._index]), qc)  # qC^-1 q qC
        parent_q, parent_t, parent_s = self._parent_q, self._parent_t, self._parent_s
        if self._tracks:  # parents that move: their pose at this frame
            parent_q, parent_t, parent_s = parent_q.copy(), parent_t.copy(), parent_s.copy()
            k = frame - self.scene.start_frame  # tracks start at the shot's first frame
            for row, qs, ts, ss in self._tracks:
                parent_q[row], parent_t[row], parent_s[row] = qs[k], ts[k], ss[k]
        parent_inv = _qconj(parent_q)
        q_local = _qmul(parent_inv, q_world)
        q_local /= np.linalg.norm(q_local, axis=1, keepdims=True)
        t_local = _qrotate(parent_inv, t_world - parent_t) / parent_s

        cloth_data = []
        for index, to_local, to_world3, paths in self._cloths:
            p = np.asarray(cloth_points[index], dtype=np.float64) @ C / mpu
            v = np.asarray(cloth_velocities[index], dtype=np.float64) @ C / mpu
            n = np.asarray(cloth_normals[index], dtype=np.float64) @ C
            if not (np.isfinite(p).all() and np.isfinite(v).all()):
                raise SimulationError(f"frame {frame}: cloth {self.scene.cloths[index].name!r} contains NaN or inf")
            p = p @ to_local[:3, :3].T + to_local[:3, 3]
            v = v @ to_local[:3, :3].T
            n = n @ to_world3  # normals go by the inverse transpose of world -> local
            length = np.linalg.norm(n, axis=1, keepdims=True)
            n = np.divide(n, length, out=np.zeros_like(n), where=length > 0)
            p32 = np.ascontiguousarray(p, dtype=np.float32)
            extent = np.stack([p32.min(axis=0), p32.max(axis=0)])
            cloth_data.append((paths, p32, np.ascontiguousarray(n, dtype=np.float32),
                               np.ascontiguousarray(v, dtype=np.float32), extent))

        time = float(frame)
        with Sdf.ChangeBlock():
            for body, t, q in zip(self._bodies, t_local, q_local):
                if body is None:  # written whole below
                    continue
                _, t_path, q_path, t_type, q_type = body
                layer.SetTimeSample(t_path, time, t_type(*t))
                layer.SetTimeSample(q_path, time, q_type(float(q[0]), float(q[1]), float(q[2]), float(q[3])))
            whole = {}
            for row, op_path, a in self._matrix_bodies:  # [R(t) A, t(t)], row vectors for Gf
                m = np.eye(4)
                m[:3, :3] = np.array(Gf.Matrix3d(Gf.Rotation(Gf.Quatd(*q_local[row])))).T @ a
                m[:3, 3] = t_local[row]
                whole[row] = m
                layer.SetTimeSample(op_path, time, Gf.Matrix4d(m.T.tolist()))
            for row, op_path, local in self._volume_tracks:  # Volumes beside Gprim bodies
                if row in whole:
                    layer.SetTimeSample(op_path, time, Gf.Matrix4d((whole[row] @ local).T.tolist()))
                    continue
                m = np.eye(4)
                m[:3, :3] = np.array(Gf.Matrix3d(Gf.Rotation(Gf.Quatd(*q_local[row])))).T
                if shot.bodies[row].scale is not None:
                    m[:3, :3] = m[:3, :3] * np.asarray(shot.bodies[row].scale)
                m[:3, 3] = t_local[row]
                layer.SetTimeSample(op_path, time, Gf.Matrix4d((m @ local).T.tolist()))
            for op_path, mats in self._volume_keyed:
                layer.SetTimeSample(op_path, time, Gf.Matrix4d(mats[frame - self.scene.start_frame].tolist()))
            for paths, p32, n32, v32, extent in cloth_data:
                layer.SetTimeSample(paths[0], time, Vt.Vec3fArray.FromNumpy(p32))
                layer.SetTimeSample(paths[1], time, Vt.Vec3fArray.FromNumpy(n32))
                layer.SetTimeSample(paths[2], time, Vt.Vec3fArray.FromNumpy(v32))
                layer.SetTimeSample(paths[3], time, Vt.Vec3fArray.FromNumpy(extent))
        self._next_frame += 1
        written = self._next_frame - self.start_frame
        if self.flush_every and written % self.flush_every == 0 and self._next_frame <= self.end_frame:
            self._save()

    def write_joint_breaks(self, breaks: Mapping[str, int]) -> None:
        author_joint_breaks(self._layer, breaks, self.start_frame, self.end_frame)

    def add_layer_data(self, data: Mapping[str, Any]) -> None:
        merged = dict(self._layer.customLayerData)
        merge_into(merged, to_usd(dict(data), "customLayerData"))
        self._layer.customLayerData = merged

    # -- finishing ----------------------------------------------------------------------------

    def _save(self) -> None:
        if not self._layer.Save():
            raise OSError(f"{self._tmp}: saving the USD layer failed")

    def abort(self) -> None:
        if self._done:
            return
        self._layer = None
        for p in (self._tmp, self._tmp_text):
            if p is not None:
                remove_if_present(p)


# --------------------------------------------------------------------------------------------
# --shot: a stage that sublayers the cache over the input
# --------------------------------------------------------------------------------------------

def write_shot_stage(path: str | Path, cache: str | Path, shot, outputs=None) -> Path:
    """Write ``path``: a stage whose sublayers are ``cache`` (stronger) over the input shot,
    both by relative path, with the input's stage metadata (written beside and renamed; with
    `outputs`, a simbake.outputs.Outputs, staged there to be renamed with the cache)."""
    path = Path(path)
    here = path.absolute().parent

    def relative(p) -> str:
        """Relative to the shot stage when they share a directory below the root, else absolute."""
        target = Path(p).absolute()
        if os.path.commonpath([here, target]) == os.path.sep:
            return str(target)
        rel = os.path.relpath(target, here)
        return rel if rel.startswith("..") else f"./{rel}"

    layer = Sdf.Layer.CreateAnonymous(".usda")
    layer.subLayerPaths.append(relative(cache))
    layer.subLayerPaths.append(relative(shot.path))
    copy_stage_metadata(layer, shot)
    fmt = FORMATS.get(path.suffix.lower(), "usda")

    def write(tmp: str) -> None:
        if not layer.Export(tmp, args={"format": fmt}):
            raise OSError(f"{path}: writing the shot stage failed")

    if outputs is not None:
        outputs.write(path, write)
    else:
        write_atomically(path, write)
    return path
