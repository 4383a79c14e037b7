"""Deforming colliders of a USD shot: a collider ``Mesh`` (PhysicsCollisionAPI, under no rigid
body) whose ``points`` are time-sampled, or that UsdSkel skins (a ``SkelRoot`` with a bound
``Skeleton`` and its ``SkelAnimation``).

Its surface is read at every frame of the bake into world vertices (metres, Y up), one
topology for the whole bake (:class:`simbake.scene.Deformation`):

* time-sampled points: the points at time code ``c`` through the prim's world transform at
  ``c`` (an animated parent moves them too);
* UsdSkel: OpenUSD's own skinning, ``UsdSkelSkinningQuery.ComputeSkinnedPoints`` with the
  skeleton's ``ComputeSkinningTransforms`` at ``c`` (linear or dual-quaternion blending, as
  the mesh's ``primvars:skel:skinningMethod`` says; blend shapes are not applied), which gives
  skeleton-space points, then the skeleton's world transform at ``c``. The mesh's own
  transform does not take part (UsdSkel ignores it; ``geomBindTransform`` places the mesh).

Then ``x = metersPerUnit * C x_stage`` as for every point of a shot (simbake.usd_scene).
"""

from __future__ import annotations

import numpy as np

from .scene import Deformation


def deformation_source(prim) -> str | None:
    """"skel" when UsdSkel skins the mesh, "points" when its points are time-sampled (they may
    change between frames), None for a rigid mesh."""
    from pxr import UsdGeom, UsdSkel

    if UsdSkel.Root.Find(prim) and UsdSkel.BindingAPI(prim).GetInheritedSkeleton():
        query = _skinning(prim)[0]
        if query is not None and query.HasJointInfluences():
            return "skel"
    if UsdGeom.Mesh(prim).GetPointsAttr().ValueMightBeTimeVarying():
        return "points"
    return None


def _skinning(prim):
    """(UsdSkelSkinningQuery, UsdSkelSkeletonQuery) of a mesh under a SkelRoot, or Nones."""
    from pxr import Usd, UsdSkel

    cache = UsdSkel.Cache()
    cache.Populate(UsdSkel.Root.Find(prim), Usd.PrimDefaultPredicate)
    skinning = cache.GetSkinningQuery(prim)
    skeleton = UsdSkel.BindingAPI(prim).GetInheritedSkeleton()
    skel_query = cache.GetSkelQuery(skeleton) if skeleton else None
    if not skinning or not skel_query:
        return None, None
    return skinning, skel_query


def read_deformation(reader, prim, triangles: np.ndarray, count: int, source: str) -> Deformation:
    """The mesh `prim`'s world surface at every frame of `reader` (simbake.usd_scene's reader:
    its range, axes, units and messages); `count` points, `triangles` from its faces."""
    from pxr import Usd, UsdGeom

    path = prim.GetPath()
    mesh = UsdGeom.Mesh(prim)
    for attr in (mesh.GetFaceVertexCountsAttr(), mesh.GetFaceVertexIndicesAttr()):
        if attr.ValueMightBeTimeVarying():
            raise reader.error(path, attr.GetName(), "is time-sampled: a deforming collider keeps one topology "
                                                     "(only its points may move)")
    skinning, skel_query = _skinning(prim) if source == "skel" else (None, None)
    codes = range(int(reader.start), int(reader.end) + 1)
    frames = np.empty((len(codes), count, 3), dtype=np.float64)
    for k, code in enumerate(codes):
        time = Usd.TimeCode(code)
        points = mesh.GetPointsAttr().Get(time)
        if points is None or len(points) != count:
            raise reader.error(path, "points", f"has {0 if points is None else len(points)} points at time code "
                                               f"{code}, {count} at the start: a deforming collider keeps its "
                                               "point count")
        if skinning is not None:
            transforms = skel_query.ComputeSkinningTransforms(time)
            if not skinning.ComputeSkinnedPoints(transforms, points, time):
                raise reader.error(path, "primvars:skel:jointIndices",
                                   f"UsdSkel cannot skin the mesh at time code {code} (check its joint "
                                   "indices, weights and the skeleton's joints)")
            to_world = reader.world(skel_query.GetPrim(), time)
        else:
            to_world = reader.world(prim, time)
        local = np.asarray(points, dtype=np.float64)
        world = local @ to_world[:3, :3].T + to_world[:3, 3]
        frames[k] = (world @ reader.C.T) * reader.mpu
        if not np.isfinite(frames[k]).all():
            raise reader.error(path, "points", f"contains NaN or infinity at time code {code}")
    frames.setflags(write=False)
    faces = np.ascontiguousarray(triangles, dtype=np.int32)
    faces.setflags(write=False)
    return Deformation(vertices=frames, triangles=faces, source=source)
