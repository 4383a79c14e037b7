"""Writes the deforming-collider shots (metres, Y up, 24 fps), checked in beside this file:

* ``deforming_sphere.usda``: a closed sphere ``Mesh`` with ``PhysicsCollisionAPI`` (under no
  rigid body) whose ``points`` are time-sampled at every frame: it swells and sways, radius
  ``R + DR sin(w t)`` about the centre ``(SWAY sin(w t), Y0, 0)``; a sheet (SimbakeClothAPI)
  is dropped on it, over a ground plane.
* ``skinned_sphere.usda``: the very same motion made by UsdSkel: a ``SkelRoot`` with a
  one-joint ``Skeleton``, a ``SkelAnimation`` whose joint translates (the sway) and scales
  uniformly (the swelling, ``(R + DR sin(w t)) / R``), and the sphere's rest mesh bound to the
  joint with weight 1 at every point (``vertex`` interpolation, so not rigidly deformed),
  linear blend skinning; the same sheet and ground.
* ``rising_floor.usda``: a flat closed slab (a box ``Mesh`` with time-sampled points) whose
  top rises slowly (``RISE`` m/s), and a rigid ball resting on it.

Both spheres' surfaces are known in closed form at every frame (``sphere_at``), which is what
the tests measure the cloth against. Run it from anywhere: ``python make_deforming.py``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdSkel, Vt

HERE = Path(__file__).resolve().parent
FPS = 24
START, END = 1, 48
R, DR, SWAY, Y0 = 0.35, 0.06, 0.10, 0.45   # (m) radius, its swing, the sway, the centre's height
OMEGA = 2.0 * math.pi / 2.0                 # (rad/s): one swell and sway every 2 s
LAT, LON = 16, 32                           # the sphere's rings and segments
SHEET = dict(size=1.2, resolution=25, height=0.95, area_density=0.2, stretch_stiffness=500.0,
             bend_stiffness=2e-4, thickness=0.005)
SLAB = dict(size=(1.2, 0.2, 1.2), top=0.1, ball_radius=0.1)
RISE = 0.1                                  # (m/s) the slab's top rises this fast


def sphere_at(frame: float) -> tuple[np.ndarray, float]:
    """The sphere's centre (m) and radius (m) at a (fractional) frame."""
    t = (frame - START) / FPS
    s = math.sin(OMEGA * t)
    return np.array([SWAY * s, Y0, 0.0]), R + DR * s


def unit_sphere() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A closed lat-long sphere of radius 1 at the origin, wound outwards: points, face
    vertex counts and indices (quads, triangles at the poles)."""
    points = [(0.0, 1.0, 0.0)]
    for i in range(1, LAT):
        theta = math.pi * i / LAT
        for j in range(LON):
            phi = 2.0 * math.pi * j / LON
            points.append((math.sin(theta) * math.cos(phi), math.cos(theta), -math.sin(theta) * math.sin(phi)))
    points.append((0.0, -1.0, 0.0))
    bottom = len(points) - 1

    def ring(i, j):  # ring i in 1 .. LAT-1
        return 1 + (i - 1) * LON + j % LON

    counts, indices = [], []
    for j in range(LON):
        counts.append(3)
        indices += [0, ring(1, j), ring(1, j + 1)]
    for i in range(1, LAT - 1):
        for j in range(LON):
            counts.append(4)
            indices += [ring(i, j), ring(i + 1, j), ring(i + 1, j + 1), ring(i, j + 1)]
    for j in range(LON):
        counts.append(3)
        indices += [bottom, ring(LAT - 1, j + 1), ring(LAT - 1, j)]
    return np.array(points), np.array(counts), np.array(indices)


def unit_sphere_triangles() -> np.ndarray:
    """The sphere's faces fanned into triangles (0, k, k + 1), in face order."""
    _, counts, indices = unit_sphere()
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    return np.array([(indices[s], indices[s + k], indices[s + k + 1])
                     for s, c in zip(starts, counts) for k in range(1, c - 1)])


def _stage(path: Path) -> Usd.Stage:
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, "Y")
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetStartTimeCode(START)
    stage.SetEndTimeCode(END)
    stage.SetTimeCodesPerSecond(FPS)
    stage.SetFramesPerSecond(FPS)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    UsdPhysics.Scene.Define(stage, "/World/physicsScene")
    ground = UsdGeom.Plane.Define(stage, "/World/ground")
    ground.CreateAxisAttr("Y")
    UsdPhysics.CollisionAPI.Apply(ground.GetPrim())
    return stage


def _mesh(stage, path: str, points: np.ndarray, counts, indices) -> UsdGeom.Mesh:
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(points.astype(np.float32)))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray([int(c) for c in counts]))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray([int(i) for i in indices]))
    mesh.CreateSubdivisionSchemeAttr("none")
    return mesh


def _sheet(stage) -> None:
    n, size = SHEET["resolution"], SHEET["size"]
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="xy")
    points = np.stack([(i / (n - 1) - 0.5) * size, np.full(i.shape, SHEET["height"]),
                       (j / (n - 1) - 0.5) * size], axis=-1).reshape(-1, 3)
    p00 = (j[:-1, :-1] * n + i[:-1, :-1]).ravel()
    tris = np.concatenate([np.stack([p00, p00 + n, p00 + n + 1], -1), np.stack([p00, p00 + n + 1, p00 + 1], -1)])
    sheet = _mesh(stage, "/World/Sheet", points, [3] * len(tris), tris.reshape(-1))
    prim = sheet.GetPrim()
    prim.AddAppliedSchema("SimbakeClothAPI")
    for name in ("areaDensity", "stretchStiffness", "bendStiffness", "thickness"):
        key = {"areaDensity": "area_density", "stretchStiffness": "stretch_stiffness",
               "bendStiffness": "bend_stiffness", "thickness": "thickness"}[name]
        prim.CreateAttribute(f"simbake:cloth:{name}", Sdf.ValueTypeNames.Float).Set(SHEET[key])


def write_deforming_sphere(path: Path) -> Path:
    stage = _stage(path)
    unit, counts, indices = unit_sphere()
    centre, radius = sphere_at(START)
    body = _mesh(stage, "/World/Body", centre + radius * unit, counts, indices)
    UsdPhysics.CollisionAPI.Apply(body.GetPrim())
    for frame in range(START, END + 1):
        centre, radius = sphere_at(frame)
        body.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy((centre + radius * unit).astype(np.float32)), frame)
    _sheet(stage)
    stage.GetRootLayer().Save()
    return path


def write_skinned_sphere(path: Path, method: str = "classicLinear") -> Path:
    stage = _stage(path)
    root = UsdSkel.Root.Define(stage, "/World/Character")
    skeleton = UsdSkel.Skeleton.Define(stage, "/World/Character/Skel")
    skeleton.CreateJointsAttr(Vt.TokenArray(["root"]))
    rest = Gf.Matrix4d(1.0).SetTranslate(Gf.Vec3d(0.0, Y0, 0.0))
    skeleton.CreateBindTransformsAttr(Vt.Matrix4dArray([rest]))
    skeleton.CreateRestTransformsAttr(Vt.Matrix4dArray([rest]))
    anim = UsdSkel.Animation.Define(stage, "/World/Character/Skel/Anim")
    anim.CreateJointsAttr(Vt.TokenArray(["root"]))
    anim.CreateRotationsAttr(Vt.QuatfArray([Gf.Quatf(1.0)]))
    translations, scales = anim.CreateTranslationsAttr(), anim.CreateScalesAttr()
    for frame in range(START, END + 1):
        centre, radius = sphere_at(frame)
        translations.Set(Vt.Vec3fArray([Gf.Vec3f(*centre)]), frame)
        s = radius / R
        scales.Set(Vt.Vec3hArray([Gf.Vec3h(s, s, s)]), frame)
    UsdSkel.BindingAPI.Apply(skeleton.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    unit, counts, indices = unit_sphere()
    # the rest mesh: radius R about the joint's rest position (what the bind transform places)
    body = _mesh(stage, "/World/Character/Body", np.array([0.0, Y0, 0.0]) + R * unit, counts, indices)
    UsdPhysics.CollisionAPI.Apply(body.GetPrim())
    binding = UsdSkel.BindingAPI.Apply(body.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skeleton.GetPath()])
    binding.CreateJointIndicesPrimvar(False, 1).Set(Vt.IntArray([0] * len(unit)))
    binding.CreateJointWeightsPrimvar(False, 1).Set(Vt.FloatArray([1.0] * len(unit)))
    binding.CreateGeomBindTransformAttr(Gf.Matrix4d(1.0))
    binding.CreateSkinningMethodAttr(method)
    del root
    _sheet(stage)
    stage.GetRootLayer().Save()
    return path


def slab_top(frame: float) -> float:
    """The rising slab's top (m) at a (fractional) frame."""
    return SLAB["top"] + RISE * (frame - START) / FPS


def write_rising_floor(path: Path) -> Path:
    stage = _stage(path)
    sx, sy, sz = SLAB["size"]
    corners = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-1.0, 0.0) for z in (-0.5, 0.5)])
    corners *= np.array([sx, sy, sz])
    # quads wound outwards (corner index = 4 x + 2 y + z over {0, 1})
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    slab = _mesh(stage, "/World/Floor", corners + [0.0, slab_top(START), 0.0], [4] * 6, np.array(quads).reshape(-1))
    UsdPhysics.CollisionAPI.Apply(slab.GetPrim())
    for frame in range(START, END + 1):
        slab.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy((corners + [0.0, slab_top(frame), 0.0]).astype(np.float32)),
                                 frame)
    ball = UsdGeom.Sphere.Define(stage, "/World/Ball")
    ball.CreateRadiusAttr(SLAB["ball_radius"])
    ball.AddTranslateOp().Set(Gf.Vec3d(0.0, slab_top(START) + SLAB["ball_radius"], 0.0))
    UsdPhysics.CollisionAPI.Apply(ball.GetPrim())
    UsdPhysics.RigidBodyAPI.Apply(ball.GetPrim())
    stage.GetRootLayer().Save()
    return path


def main() -> None:
    write_deforming_sphere(HERE / "deforming_sphere.usda")
    write_skinned_sphere(HERE / "skinned_sphere.usda")
    write_rising_floor(HERE / "rising_floor.usda")


if __name__ == "__main__":
    main()
