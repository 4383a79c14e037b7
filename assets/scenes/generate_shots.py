"""Writes the shipped USD shots: shot.usda (metres, Y up) and shot_cm_zup.usda (the same
shot in centimetres, Z up).

Run `python assets/scenes/generate_shots.py` (with usd-core installed); the outputs are
checked in. The shot is described once below in simbake's frame (SI, Y up) and authored in
each stage's units and axes: a point p becomes C^T p / metersPerUnit, a rotation q becomes
qC^-1 q qC (the same physical rotation in the stage's axes), where C turns the stage's axes
into Y up. Tests import `write_shot` and `equivalent_toml` to make variants.

The shot: a crate (Cube, mass 8 kg, rotated), a ball (Sphere, density 500 kg/m^3, thrown)
and a pill (Capsule along X, spinning) fall under a parent Xform that is moved and turned;
a static block (a scaled Cube collider, no rigid body) and the ground (a static Plane) with
a bound rubber physics material; a kinematic pusher (Cube) animated across the ground; a
cloth (a 0.8 m sheet, 12 x 12 points, SimbakeClothAPI) falls onto the block.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
FPS, START, END = 24, 1, 36
_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])

# the props' parent: moved and turned 20 degrees about the up axis
PROPS_T = (0.5, 0.0, 0.2)
PROPS_Q = (math.cos(math.radians(10)), 0.0, math.sin(math.radians(10)), 0.0)
RUBBER = dict(friction=0.6, restitution=0.3)
BODIES = [  # in the props' frame
    dict(name="Crate", kind="cube", size=0.4, position=(-1.0, 1.0, 0.0), mass=8.0,
         orientation=(math.cos(math.radians(15)), 0.0, math.sin(math.radians(15)), 0.0),
         material=True),
    dict(name="Ball", kind="sphere", radius=0.25, position=(0.0, 1.5, 0.8), density=500.0,
         velocity=(0.5, 0.0, 0.0)),
    dict(name="Pill", kind="capsule", radius=0.15, height=0.4, position=(1.0, 1.2, -0.5),
         angular_velocity=(0.0, 90.0, 0.0)),
]
BLOCK = dict(position=(2.2, 0.25, 1.2), scale=(1.0, 0.5, 1.0))  # a unit Cube, static
PUSHER = dict(size=0.3, start=(-2.0, 0.15, -1.5), end=(2.0, 0.15, -1.5))  # kinematic, keyed
SHEET = dict(size=0.8, resolution=12, position=(2.2, 0.9, 1.2), area_density=0.2,
             stretch_stiffness=500.0, bend_stiffness=2e-4, thickness=0.01, pinned=())


def _grid(size: float, n: int):
    """A regular n x n grid in the XZ plane (simbake's grid order and triangles)."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="xy")
    x = (i / (n - 1) - 0.5) * size
    z = (j / (n - 1) - 0.5) * size
    points = np.stack([x, np.zeros_like(x), z], axis=-1).reshape(-1, 3)
    p00 = (j[:-1, :-1] * n + i[:-1, :-1]).ravel()
    p10, p01, p11 = p00 + 1, p00 + n, p00 + n + 1
    tris = np.concatenate([np.stack([p00, p01, p11], -1), np.stack([p00, p11, p10], -1)])
    return points, tris


def new_stage(path: Path, generator: str, start: int, end: int, fps: float = FPS, up: str = "Y", mpu: float = 1.0):
    """A shot's stage at `path`: its axis, units, frames and rate; `/World` (the default prim)
    and a PhysicsScene (gravity: 9.81 m/s^2 down the up axis). `generator`: the script in
    assets/scenes that writes it."""
    from pxr import Usd, UsdGeom, UsdPhysics

    stage = Usd.Stage.CreateNew(str(path))
    stage.SetMetadata("comment", f"Written by assets/scenes/{generator}; edit that and run it again.")
    UsdGeom.SetStageUpAxis(stage, up)
    UsdGeom.SetStageMetersPerUnit(stage, mpu)
    UsdPhysics.SetStageKilogramsPerUnit(stage, 1.0)
    stage.SetStartTimeCode(start)
    stage.SetEndTimeCode(end)
    stage.SetTimeCodesPerSecond(fps)
    stage.SetFramesPerSecond(fps)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    UsdPhysics.Scene.Define(stage, "/World/PhysicsScene")
    return stage


def write_shot(path: Path, units: str = "m", up: str = "Y", *, capsule: bool = True,
               cloth: bool = True, end: int = END) -> Path:
    """Author the shot at `path` in metres ("m") or centimetres ("cm"), Y or Z up."""
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdShade, Vt

    mpu = {"m": 1.0, "cm": 0.01}[units]
    C = _Z_UP if up == "Z" else np.eye(3)
    qc = (math.sqrt(0.5), -math.sqrt(0.5), 0.0, 0.0) if up == "Z" else (1.0, 0.0, 0.0, 0.0)

    def pos(p):  # a point or length vector of simbake's frame, in stage units and axes
        return Gf.Vec3d(*(C.T @ np.asarray(p, dtype=np.float64) / mpu))

    def vec(v):  # a direction without units
        return Gf.Vec3f(*(C.T @ np.asarray(v, dtype=np.float64)))

    def quat(q):  # qc^-1 q qc
        a = Gf.Quatd(qc[0], Gf.Vec3d(*qc[1:]))
        return Gf.Quatf(a.GetInverse() * Gf.Quatd(q[0], Gf.Vec3d(*q[1:])) * a)

    def axis(token):  # an axis token of simbake's frame in the stage's axes
        return {"X": "X", "Y": up, "Z": "Y" if up == "Z" else "Z"}[token]

    def place(prim, position, orientation=None, scale=None):
        xf = UsdGeom.Xformable(prim)
        xf.AddTranslateOp().Set(pos(position))
        if orientation is not None:
            xf.AddOrientOp().Set(quat(orientation))
        if scale is not None:
            s = np.abs(C.T @ np.asarray(scale, dtype=np.float64))
            xf.AddScaleOp().Set(Gf.Vec3f(*s))

    stage = new_stage(path, "generate_shots.py", START, end, up=up, mpu=mpu)

    rubber = UsdShade.Material.Define(stage, "/World/Looks/Rubber")
    rubber_api = UsdPhysics.MaterialAPI.Apply(rubber.GetPrim())
    rubber_api.CreateDynamicFrictionAttr(RUBBER["friction"])
    rubber_api.CreateStaticFrictionAttr(RUBBER["friction"])
    rubber_api.CreateRestitutionAttr(RUBBER["restitution"])

    def bind(prim):
        UsdShade.MaterialBindingAPI.Apply(prim).Bind(rubber, UsdShade.Tokens.weakerThanDescendants, "physics")

    ground = UsdGeom.Plane.Define(stage, "/World/Ground")
    ground.CreateAxisAttr(axis("Y"))
    ground.CreateWidthAttr(10.0 / mpu)
    ground.CreateLengthAttr(10.0 / mpu)
    UsdPhysics.CollisionAPI.Apply(ground.GetPrim())
    bind(ground.GetPrim())

    props = UsdGeom.Xform.Define(stage, "/World/Props")
    place(props.GetPrim(), PROPS_T, PROPS_Q)
    for b in BODIES:
        if b["kind"] == "capsule" and not capsule:
            continue
        prim_path = f"/World/Props/{b['name']}"
        if b["kind"] == "cube":
            geom = UsdGeom.Cube.Define(stage, prim_path)
            geom.CreateSizeAttr(b["size"] / mpu)
        elif b["kind"] == "sphere":
            geom = UsdGeom.Sphere.Define(stage, prim_path)
            geom.CreateRadiusAttr(b["radius"] / mpu)
        else:
            geom = UsdGeom.Capsule.Define(stage, prim_path)
            geom.CreateRadiusAttr(b["radius"] / mpu)
            geom.CreateHeightAttr(b["height"] / mpu)
            geom.CreateAxisAttr(axis("X"))
        prim = geom.GetPrim()
        place(prim, b["position"], b.get("orientation", (1.0, 0.0, 0.0, 0.0)))
        body = UsdPhysics.RigidBodyAPI.Apply(prim)
        if "velocity" in b:  # world frame: the props' rotation applied
            v = Gf.Rotation(Gf.Quatd(PROPS_Q[0], Gf.Vec3d(*PROPS_Q[1:]))).TransformDir(Gf.Vec3d(*b["velocity"]))
            body.CreateVelocityAttr(Gf.Vec3f(*(C.T @ np.asarray(v) / mpu)))
        if "angular_velocity" in b:
            w = Gf.Rotation(Gf.Quatd(PROPS_Q[0], Gf.Vec3d(*PROPS_Q[1:]))).TransformDir(Gf.Vec3d(*b["angular_velocity"]))
            body.CreateAngularVelocityAttr(vec(w))
        UsdPhysics.CollisionAPI.Apply(prim)
        mass = UsdPhysics.MassAPI.Apply(prim)
        if "mass" in b:
            mass.CreateMassAttr(b["mass"])
        if "density" in b:
            mass.CreateDensityAttr(b["density"] * mpu ** 3)
        if b.get("material"):
            bind(prim)

    block = UsdGeom.Cube.Define(stage, "/World/Block")
    block.CreateSizeAttr(1.0 / mpu)
    place(block.GetPrim(), BLOCK["position"], scale=BLOCK["scale"])
    UsdPhysics.CollisionAPI.Apply(block.GetPrim())

    pusher = UsdGeom.Cube.Define(stage, "/World/Pusher")
    pusher.CreateSizeAttr(PUSHER["size"] / mpu)
    op = pusher.AddTranslateOp()
    op.Set(pos(PUSHER["start"]), Usd.TimeCode(START))
    op.Set(pos(PUSHER["end"]), Usd.TimeCode(end))
    UsdPhysics.RigidBodyAPI.Apply(pusher.GetPrim()).CreateKinematicEnabledAttr(True)
    UsdPhysics.CollisionAPI.Apply(pusher.GetPrim())

    if cloth:
        points, tris = _grid(SHEET["size"], SHEET["resolution"])
        sheet = UsdGeom.Mesh.Define(stage, "/World/Sheet")
        sheet.CreatePointsAttr(Vt.Vec3fArray.FromNumpy((points @ C / mpu).astype(np.float32)))
        sheet.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(tris)))
        sheet.CreateFaceVertexIndicesAttr(Vt.IntArray(tris.reshape(-1).tolist()))
        sheet.CreateSubdivisionSchemeAttr("none")
        lo, hi = points.min(axis=0) @ C / mpu, points.max(axis=0) @ C / mpu
        sheet.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*np.minimum(lo, hi)), Gf.Vec3f(*np.maximum(lo, hi))]))
        place(sheet.GetPrim(), SHEET["position"])
        prim = sheet.GetPrim()
        prim.AddAppliedSchema("SimbakeClothAPI")
        attrs = {"areaDensity": (Sdf.ValueTypeNames.Float, SHEET["area_density"] * mpu ** 2),
                 "stretchStiffness": (Sdf.ValueTypeNames.Float, SHEET["stretch_stiffness"]),
                 "bendStiffness": (Sdf.ValueTypeNames.Float, SHEET["bend_stiffness"] / mpu ** 2),
                 "thickness": (Sdf.ValueTypeNames.Float, SHEET["thickness"] / mpu)}
        for name, (type_name, value) in attrs.items():
            prim.CreateAttribute(f"simbake:cloth:{name}", type_name).Set(value)
    stage.GetRootLayer().Save()
    return path


def equivalent_toml(*, capsule: bool = False, cloth: bool = True, end: int = END) -> str:
    """The same shot as a TOML scene (the capsule, a mesh in USD, is left out by default)."""
    def v(x):
        return "[" + ", ".join(repr(float(c)) for c in x) + "]"

    def qmul(a, b):
        aw, ax, ay, az = a
        bw, bx, by, bz = b
        return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)

    def rotate(q, p):
        w, x, y, z = q
        r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                      [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                      [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
        return r @ np.asarray(p, dtype=np.float64)

    out = [f"[scene]\nfps = {FPS}\nstart_frame = {START}\nend_frame = {end}\ngravity = [0.0, -9.81, 0.0]\n",
           f"[ground]\nheight = 0.0\nfriction = {RUBBER['friction']}\nrestitution = {RUBBER['restitution']}\n"]
    for b in BODIES:
        if b["kind"] == "capsule":
            if capsule:
                raise ValueError("the capsule has no TOML equivalent here")
            continue
        position = rotate(PROPS_Q, b["position"]) + np.asarray(PROPS_T)
        q = qmul(PROPS_Q, b.get("orientation", (1.0, 0.0, 0.0, 0.0)))
        shape = (f'shape = {{ type = "box", size = {v([b["size"]] * 3)} }}' if b["kind"] == "cube"
                 else f'shape = {{ type = "sphere", radius = {float(b["radius"])!r} }}')
        lines = [f'[[bodies]]\nname = "{b["name"]}"', shape, f"position = {v(position)}", f"orientation = {v(q)}"]
        lines.append(f"mass = {b['mass']!r}" if "mass" in b else f"density = {float(b.get('density', 1000.0))!r}")
        if "velocity" in b:
            lines.append(f"linear_velocity = {v(rotate(PROPS_Q, b['velocity']))}")
        if "angular_velocity" in b:
            lines.append(f"angular_velocity = {v(rotate(PROPS_Q, np.radians(b['angular_velocity'])))}")
        if b.get("material"):
            lines += [f"friction = {RUBBER['friction']}", f"restitution = {RUBBER['restitution']}"]
        out.append("\n".join(lines) + "\n")
    size = [BLOCK["scale"][0], BLOCK["scale"][1], BLOCK["scale"][2]]
    out.append(f'[[bodies]]\nname = "Block"\nshape = {{ type = "box", size = {v(size)} }}\n'
               f"position = {v(BLOCK['position'])}\nkinematic = true\n")
    keys = ", ".join(
        f"{{ time = {(k - START) / FPS!r}, position = "
        f"{v(np.asarray(PUSHER['start']) + (np.asarray(PUSHER['end']) - np.asarray(PUSHER['start'])) * (k - START) / (end - START))} }}"
        for k in range(START, end + 1))
    out.append(f'[[bodies]]\nname = "Pusher"\nshape = {{ type = "box", size = {v([PUSHER["size"]] * 3)} }}\n'
               f"position = {v(PUSHER['start'])}\nkinematic = true\nkeys = [{keys}]\n")
    if cloth:
        n = SHEET["resolution"]
        out.append(f'[[cloths]]\nname = "Sheet"\ngrid = {{ size = {v([SHEET["size"]] * 2)}, resolution = [{n}, {n}] }}\n'
                   f"position = {v(SHEET['position'])}\narea_density = {SHEET['area_density']!r}\n"
                   f"stretch_stiffness = {SHEET['stretch_stiffness']!r}\nbend_stiffness = {SHEET['bend_stiffness']!r}\n"
                   f"thickness = {SHEET['thickness']!r}\n")
    return "\n".join(out)


def main() -> None:
    sys.path.insert(0, str(HERE.parents[1] / "pipeline"))
    import simbake  # noqa: F401  registers SimbakeClothAPI before the first stage

    write_shot(HERE / "shot.usda", "m", "Y")
    write_shot(HERE / "shot_cm_zup.usda", "cm", "Z")


if __name__ == "__main__":
    main()
