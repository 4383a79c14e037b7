"""Bodies that share one shape, written as one ``PointInstancer`` (``--instancing``).

A pile of identical rocks or a thousand boxes is one prototype mesh and a few arrays per
frame instead of one Xform per body: PLATFORM.md measured 1,000 bodies over 300 frames at
1.1 s and 17 MB as Xforms against 0.06 s and 6 MB as one instancer. Layout, under ``/World``::

    /<name>                 def PointInstancer
        prototypes          -> </World/<name>/Prototypes/mesh>
        protoIndices        int[] (all 0), written once
        ids                 int64[]: the bodies' indices in the scene, written once
        simbake:names       string[]: the bodies' names, written once
        positions           point3f[]   the mesh origins (m), every frame
        orientations        quath[]     (w, x, y, z), every frame
        velocities          vector3f[]  of the mesh origins (m/s), every frame
        angularVelocities   vector3f[]  (degrees per second, world axes), every frame
        extent              float3[]    every instance's bounds, every frame
        /Prototypes         def Scope
            /mesh           def Mesh: the shared shape (as a body's mesh)

Velocities are the motion over the frame, as for cloth: a renderer that blurs with
``positions + velocities x time`` (and the angular velocity about each instance's origin)
lands on the next frame's pose. Which bodies share a shape, and from how many an instancer
is made, is decided by the driver (simulate.py, ``INSTANCING_AUTO``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pxr import Sdf, Vt

__all__ = ["InstancerGroup", "InstancerSpecs", "quaternion_rate"]

_TN = Sdf.ValueTypeNames


@dataclass(frozen=True)
class InstancerGroup:
    """One PointInstancer: its prim name and the indices of the bodies it draws."""

    name: str
    bodies: tuple[int, ...]


class InstancerSpecs:
    """The specs of a cache's instancers, authored once, then their samples frame by frame."""

    def __init__(self, writer, world: Sdf.Path, groups, bodies):
        self.groups = tuple(groups)
        self._paths = []
        for group in self.groups:
            proto_body = bodies[group.bodies[0]]
            inst = writer._def(world, group.name, "PointInstancer")
            scope = writer._def(inst.path, "Prototypes", "Scope")
            mesh = writer._def(scope.path, "mesh", "Mesh")
            writer._mesh_topology(mesh, proto_body.face_vertex_counts, proto_body.face_vertex_indices)
            writer._attr(mesh, "points", _TN.Point3fArray, Vt.Vec3fArray.FromNumpy(proto_body.points))
            n = writer._attr(mesh, "normals", _TN.Normal3fArray, Vt.Vec3fArray.FromNumpy(proto_body.normals))
            n.SetInfo("interpolation", proto_body.normals_interpolation)
            points = proto_body.points.astype(np.float64)
            writer._attr(mesh, "extent", _TN.Float3Array, Vt.Vec3fArray.FromNumpy(
                np.stack([points.min(axis=0), points.max(axis=0)]).astype(np.float32)))
            rel = Sdf.RelationshipSpec(inst, "prototypes", custom=False)
            rel.targetPathList.explicitItems = [mesh.path]
            count = len(group.bodies)
            writer._attr(inst, "protoIndices", _TN.IntArray, Vt.IntArray.FromNumpy(np.zeros(count, np.int32)))
            writer._attr(inst, "ids", _TN.Int64Array, Vt.Int64Array.FromNumpy(np.asarray(group.bodies, np.int64)))
            names = Sdf.AttributeSpec(inst, "simbake:names", _TN.StringArray, Sdf.VariabilityUniform)
            names.custom = True
            names.default = Vt.StringArray([bodies[i].name for i in group.bodies])
            sampled = {}
            for attr, type_name in (("positions", _TN.Point3fArray), ("orientations", _TN.QuathArray),
                                    ("velocities", _TN.Vector3fArray), ("angularVelocities", _TN.Vector3fArray),
                                    ("extent", _TN.Float3Array)):
                sampled[attr] = writer._attr(inst, attr, type_name).path
            reach = float(np.linalg.norm(points, axis=1).max())  # prototype's farthest point
            self._paths.append((np.asarray(group.bodies, np.int64), sampled, reach))

    @property
    def sampled_count(self) -> int:
        return 5 * len(self.groups)

    def frame_bytes(self) -> int:
        return sum(len(idx) * (12 + 8 + 12 + 12) + 24 for idx, _, _ in self._paths)

    def write(self, layer: Sdf.Layer, time: float, translations: np.ndarray, orientations: np.ndarray,
              velocities: np.ndarray, angular_velocities: np.ndarray) -> None:
        """One frame's samples (inside the caller's Sdf.ChangeBlock); angular velocities in rad/s."""
        for idx, paths, reach in self._paths:
            p = np.ascontiguousarray(translations[idx], dtype=np.float32)
            q = orientations[idx]
            # GfQuath is laid out (i, j, k, real) in memory
            quats = Vt.QuathArray.FromNumpy(np.ascontiguousarray(q[:, [1, 2, 3, 0]], dtype=np.float16))
            layer.SetTimeSample(paths["positions"], time, Vt.Vec3fArray.FromNumpy(p))
            layer.SetTimeSample(paths["orientations"], time, quats)
            layer.SetTimeSample(paths["velocities"], time, Vt.Vec3fArray.FromNumpy(
                np.ascontiguousarray(velocities[idx], dtype=np.float32)))
            layer.SetTimeSample(paths["angularVelocities"], time, Vt.Vec3fArray.FromNumpy(
                np.ascontiguousarray(np.degrees(angular_velocities[idx]), dtype=np.float32)))
            lo = translations[idx].min(axis=0) - reach  # every instance within `reach` of its origin
            hi = translations[idx].max(axis=0) + reach
            layer.SetTimeSample(paths["extent"], time, Vt.Vec3fArray.FromNumpy(np.stack([lo, hi]).astype(np.float32)))


def quaternion_rate(q0: np.ndarray, q1: np.ndarray, dt: float) -> np.ndarray:
    """World-frame angular velocities (rad/s, rows) turning q0 into q1 in dt: the rotation
    vector of q1 q0^-1 over dt (the shorter way round)."""
    w0, v0 = q0[:, :1], q0[:, 1:]
    w1, v1 = q1[:, :1], q1[:, 1:]
    # d = q1 * conj(q0)
    dw = w1 * w0 + np.sum(v1 * v0, axis=1, keepdims=True)
    dv = -w1 * v0 + w0 * v1 - np.cross(v1, v0)
    sign = np.where(dw < 0, -1.0, 1.0)
    dw, dv = dw * sign, dv * sign
    s = np.linalg.norm(dv, axis=1, keepdims=True)
    angle = 2.0 * np.arctan2(s, dw)
    axis = np.divide(dv, s, out=np.zeros_like(dv), where=s > 0)
    return axis * angle / dt
