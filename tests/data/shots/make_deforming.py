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
* ``caped_sphere.usda`` and ``caped_skinned_sphere.usda``: the swaying sphere (swelling by
  ``CAPE["dr"]`` only, within the cape's strain limit) with time-sampled points, or skinned, and
  a cape (a mesh cloth) sewn to it: its top row on an arc over the sphere's top, the cloth's
  thickness off its surface (``simbake:cloth:attachTo`` the sphere, ``simbake:cloth:attached``
  that row), the rest laid out behind it, to fall and hang down the sphere's back.

* ``sleeve.usda``: an arm, a closed cylinder ``Mesh`` (radius ``ARM["radius"]``, capped) along
  +x with ``PhysicsCollisionAPI``, skinned by UsdSkel to two joints: the shoulder (the root,
  still) and the elbow (``ARM["elbow"]`` along the arm, its hinge on the inner side of the arm,
  at -z), which bends the forearm 90 degrees about +y (towards -z) between frames ``BEND``,
  eased, and holds. The points' weights blend the two joints over ``ARM["blend"]`` either side
  of the elbow (a smoothstep). A sleeve (a tube ``Mesh`` cloth) around it: its first ring, at
  the shoulder end, is sewn to the arm (the cloth's thickness off it); it widens to
  ``SLEEVE["radius"]`` within ``SLEEVE["taper"]`` and runs loose to ``SLEEVE["length"]`` along
  the arm, past the elbow. No ground: the sleeve hangs on the arm.

Both spheres' surfaces are known in closed form at every frame (``sphere_at``), which is what
the tests measure the cloth against; ``arm_at`` gives the arm's surface at a frame as UsdSkel
skins it (linear blending, written out here with numpy). Run it from anywhere:
``python make_deforming.py``.
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
# the cape: `columns` along an arc of +-`arc` degrees over the sphere's top (radius R + thickness
# at the start), `rows` laid out behind it over `length` (m); the sphere swells by `dr` (m)
CAPE = dict(arc=50.0, columns=17, rows=13, length=0.6, dr=0.02, area_density=0.2, stretch_stiffness=500.0,
            bend_stiffness=2e-4, thickness=0.005)
RISE = 0.1                                  # (m/s) the slab's top rises this fast
BEND = (5, 45)                        # the elbow bends between these frames, 0 to 90 degrees
ARM_Y = 1.0                           # (m) the arm's axis height
ARM = dict(start=-0.1, end=0.65, radius=0.05, elbow=0.3, blend=0.05, rings=31, segments=16)
SLEEVE = dict(length=0.55, radius=0.075, taper=0.08, rings=23, segments=16, area_density=0.15,
              stretch_stiffness=500.0, bend_stiffness=1e-4, thickness=0.005)


def sphere_at(frame: float, dr: float | None = None) -> tuple[np.ndarray, float]:
    """The sphere's centre (m) and radius (m) at a (fractional) frame, swelling by `dr` (DR)."""
    t = (frame - START) / FPS
    s = math.sin(OMEGA * t)
    return np.array([SWAY * s, Y0, 0.0]), R + (DR if dr is None else dr) * s


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


def _stage(path: Path, ground: bool = True) -> Usd.Stage:
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
    if ground:
        plane = UsdGeom.Plane.Define(stage, "/World/ground")
        plane.CreateAxisAttr("Y")
        UsdPhysics.CollisionAPI.Apply(plane.GetPrim())
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
    _cloth(_mesh(stage, "/World/Sheet", points, [3] * len(tris), tris.reshape(-1)), SHEET)


def _cloth(mesh: UsdGeom.Mesh, settings: dict, target: str = "", attached: list[int] = ()) -> None:
    """SimbakeClothAPI on `mesh` with its `settings` (SHEET's keys), and its `attached` points
    sewn to the prim `target`."""
    prim = mesh.GetPrim()
    prim.AddAppliedSchema("SimbakeClothAPI")
    for name, key in (("areaDensity", "area_density"), ("stretchStiffness", "stretch_stiffness"),
                      ("bendStiffness", "bend_stiffness"), ("thickness", "thickness")):
        prim.CreateAttribute(f"simbake:cloth:{name}", Sdf.ValueTypeNames.Float).Set(settings[key])
    if target:
        prim.CreateRelationship("simbake:cloth:attachTo").SetTargets([Sdf.Path(target)])
        prim.CreateAttribute("simbake:cloth:attached", Sdf.ValueTypeNames.IntArray).Set(Vt.IntArray(list(attached)))


def _cape(stage, target: str) -> None:
    """The cape (CAPE), its top row attached to `target`."""
    n, m, h = CAPE["columns"], CAPE["rows"], CAPE["thickness"]
    theta = np.radians(np.linspace(-CAPE["arc"], CAPE["arc"], n))
    i, j = np.meshgrid(np.arange(n), np.arange(m), indexing="xy")
    points = np.stack([(R + h) * np.sin(theta)[i], Y0 + (R + h) * np.cos(theta)[i],
                       -CAPE["length"] * j / (m - 1)], axis=-1).reshape(-1, 3)
    p00 = (j[:-1, :-1] * n + i[:-1, :-1]).ravel()
    tris = np.concatenate([np.stack([p00, p00 + n + 1, p00 + n], -1), np.stack([p00, p00 + 1, p00 + n + 1], -1)])
    _cloth(_mesh(stage, "/World/Cape", points, [3] * len(tris), tris.reshape(-1)), CAPE, target, range(n))


def _sampled_sphere(stage, dr: float | None = None) -> None:
    unit, counts, indices = unit_sphere()
    centre, radius = sphere_at(START, dr)
    body = _mesh(stage, "/World/Body", centre + radius * unit, counts, indices)
    UsdPhysics.CollisionAPI.Apply(body.GetPrim())
    for frame in range(START, END + 1):
        centre, radius = sphere_at(frame, dr)
        body.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy((centre + radius * unit).astype(np.float32)), frame)


def write_deforming_sphere(path: Path) -> Path:
    stage = _stage(path)
    _sampled_sphere(stage)
    _sheet(stage)
    stage.GetRootLayer().Save()
    return path


def write_caped_sphere(path: Path, skinned: bool = False) -> Path:
    """The cape (CAPE) sewn to the swaying sphere, its points time-sampled or skinned."""
    if skinned:
        return write_skinned_sphere(path, dr=CAPE["dr"], cloth=lambda stage: _cape(stage, "/World/Character/Body"))
    stage = _stage(path)
    _sampled_sphere(stage, CAPE["dr"])
    _cape(stage, "/World/Body")
    stage.GetRootLayer().Save()
    return path


def write_skinned_sphere(path: Path, method: str = "classicLinear", dr: float | None = None, cloth=None) -> Path:
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
        centre, radius = sphere_at(frame, dr)
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
    (cloth or _sheet)(stage)
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


def elbow_angle(frame: float) -> float:
    """The elbow's bend (rad) at a frame: 0 before BEND, pi / 2 after, eased in between."""
    s = min(max((frame - BEND[0]) / (BEND[1] - BEND[0]), 0.0), 1.0)
    return 0.5 * math.pi * (3 * s * s - 2 * s * s * s)


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def arm_mesh() -> tuple[np.ndarray, np.ndarray]:
    """The arm at rest: points (its axis at height ARM_Y along +x) and triangles, closed, wound
    outwards (rings of segments, a centre point at each end)."""
    n, m = ARM["rings"], ARM["segments"]
    x = np.linspace(ARM["start"], ARM["end"], n)
    phi = 2.0 * np.pi * np.arange(m) / m
    r = ARM["radius"]
    ring = np.stack([np.broadcast_to(x[:, None], (n, m)), ARM_Y + r * np.cos(phi)[None, :].repeat(n, 0),
                     r * np.sin(phi)[None, :].repeat(n, 0)], axis=-1).reshape(-1, 3)
    points = np.concatenate([ring, [[ARM["start"], ARM_Y, 0.0], [ARM["end"], ARM_Y, 0.0]]])
    first, last = n * m, n * m + 1
    tris = []
    for i in range(n - 1):
        for j in range(m):
            a, b = i * m + j, i * m + (j + 1) % m
            c, d = a + m, b + m
            tris += [(a, b, d), (a, d, c)]
    for j in range(m):
        tris.append((first, (j + 1) % m, j))
        tris.append((last, (n - 1) * m + j, (n - 1) * m + (j + 1) % m))
    return points, np.array(tris, dtype=np.int32)


def elbow_weights(points: np.ndarray) -> np.ndarray:
    """Each point's weight on the elbow joint (the shoulder's is 1 less it)."""
    return _smoothstep((points[:, 0] - (ARM["elbow"] - ARM["blend"])) / (2.0 * ARM["blend"]))


def _hinge() -> np.ndarray:
    return np.array([ARM["elbow"], ARM_Y, -ARM["radius"]])


def arm_at(frame: float, points: np.ndarray | None = None) -> np.ndarray:
    """The arm's points (or `points`, weighted as the arm's are) at a frame, skinned by linear
    blending: (1 - w) p + w (R (p - e) + e), R the elbow's turn about +y and e its hinge."""
    points = arm_mesh()[0] if points is None else points
    a = elbow_angle(frame)
    turn = np.array([[math.cos(a), 0.0, math.sin(a)], [0.0, 1.0, 0.0], [-math.sin(a), 0.0, math.cos(a)]])
    e = _hinge()
    w = elbow_weights(points)[:, None]
    return (1.0 - w) * points + w * ((points - e) @ turn.T + e)


def sleeve_mesh() -> tuple[np.ndarray, np.ndarray]:
    """The sleeve: rings along +x from the shoulder end, its first ring the cloth's thickness off
    the arm, widening to SLEEVE["radius"] over SLEEVE["taper"]; triangles wound outwards."""
    n, m = SLEEVE["rings"], SLEEVE["segments"]
    x = np.linspace(0.0, SLEEVE["length"], n)
    inner = ARM["radius"] + SLEEVE["thickness"]
    radius = inner + (SLEEVE["radius"] - inner) * _smoothstep(x / SLEEVE["taper"])
    phi = 2.0 * np.pi * (np.arange(m) + 0.5) / m
    points = np.stack([np.broadcast_to(x[:, None], (n, m)), ARM_Y + radius[:, None] * np.cos(phi)[None, :],
                       radius[:, None] * np.sin(phi)[None, :]], axis=-1).reshape(-1, 3)
    tris = []
    for i in range(n - 1):
        for j in range(m):
            a, b = i * m + j, i * m + (j + 1) % m
            tris += [(a, b, b + m), (a, b + m, a + m)]
    return points, np.array(tris, dtype=np.int32)


def write_sleeve(path: Path) -> Path:
    stage = _stage(path, ground=False)
    UsdSkel.Root.Define(stage, "/World/Character")
    skeleton = UsdSkel.Skeleton.Define(stage, "/World/Character/Skel")
    joints = ["shoulder", "shoulder/elbow"]
    skeleton.CreateJointsAttr(Vt.TokenArray(joints))
    shoulder = Gf.Matrix4d(1.0).SetTranslate(Gf.Vec3d(0.0, ARM_Y, 0.0))
    e = _hinge()
    elbow_world = Gf.Matrix4d(1.0).SetTranslate(Gf.Vec3d(*e))
    elbow_local = Gf.Matrix4d(1.0).SetTranslate(Gf.Vec3d(e[0], 0.0, e[2]))
    skeleton.CreateBindTransformsAttr(Vt.Matrix4dArray([shoulder, elbow_world]))
    skeleton.CreateRestTransformsAttr(Vt.Matrix4dArray([shoulder, elbow_local]))
    anim = UsdSkel.Animation.Define(stage, "/World/Character/Skel/Anim")
    anim.CreateJointsAttr(Vt.TokenArray(joints))
    anim.CreateTranslationsAttr(Vt.Vec3fArray([Gf.Vec3f(0.0, ARM_Y, 0.0), Gf.Vec3f(float(e[0]), 0.0, float(e[2]))]))
    anim.CreateScalesAttr(Vt.Vec3hArray([Gf.Vec3h(1.0, 1.0, 1.0)] * 2))
    rotations = anim.CreateRotationsAttr()
    for frame in range(START, END + 1):
        a = elbow_angle(frame)
        rotations.Set(Vt.QuatfArray([Gf.Quatf(1.0), Gf.Quatf(math.cos(a / 2), 0.0, math.sin(a / 2), 0.0)]), frame)
    UsdSkel.BindingAPI.Apply(skeleton.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    points, triangles = arm_mesh()
    arm = _mesh(stage, "/World/Character/Arm", points, [3] * len(triangles), triangles.reshape(-1))
    UsdPhysics.CollisionAPI.Apply(arm.GetPrim())
    binding = UsdSkel.BindingAPI.Apply(arm.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skeleton.GetPath()])
    w = elbow_weights(points)
    binding.CreateJointIndicesPrimvar(False, 2).Set(Vt.IntArray([0, 1] * len(points)))
    binding.CreateJointWeightsPrimvar(False, 2).Set(Vt.FloatArray(np.stack([1.0 - w, w], -1).reshape(-1).tolist()))
    binding.CreateGeomBindTransformAttr(Gf.Matrix4d(1.0))
    binding.CreateSkinningMethodAttr("classicLinear")
    points, triangles = sleeve_mesh()
    _cloth(_mesh(stage, "/World/Sleeve", points, [3] * len(triangles), triangles.reshape(-1)), SLEEVE,
           str(arm.GetPath()), range(SLEEVE["segments"]))
    stage.GetRootLayer().Save()
    return path


def main() -> None:
    write_deforming_sphere(HERE / "deforming_sphere.usda")
    write_skinned_sphere(HERE / "skinned_sphere.usda")
    write_rising_floor(HERE / "rising_floor.usda")
    write_caped_sphere(HERE / "caped_sphere.usda")
    write_caped_sphere(HERE / "caped_skinned_sphere.usda", skinned=True)
    write_sleeve(HERE / "sleeve.usda")


if __name__ == "__main__":
    main()
