"""Writes joints.usda: a shot (metres, Y up, 48 frames) with a joint of every UsdPhysics type,
a breakable joint, a collision group and a filtered pair, in the style of OpenUSD's
usdPhysicsJoints.usda. Run it from anywhere; the output is checked in."""

from pathlib import Path

from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics


def cube(stage, path, size, position, dynamic=True, mass=None):
    c = UsdGeom.Cube.Define(stage, path)
    c.CreateSizeAttr(1.0)
    c.AddTranslateOp().Set(Gf.Vec3d(*position))
    c.AddScaleOp().Set(Gf.Vec3f(*size))
    UsdPhysics.CollisionAPI.Apply(c.GetPrim())
    if dynamic:
        UsdPhysics.RigidBodyAPI.Apply(c.GetPrim())
        if mass:
            UsdPhysics.MassAPI.Apply(c.GetPrim()).CreateMassAttr(mass)
    return c.GetPrim()


def joint(stage, kind, path, body0, body1, pos0, pos1):
    j = kind.Define(stage, path)
    if body0:
        j.CreateBody0Rel().SetTargets([body0])
    j.CreateBody1Rel().SetTargets([body1])
    j.CreateLocalPos0Attr(Gf.Vec3f(*pos0))
    j.CreateLocalPos1Attr(Gf.Vec3f(*pos1))
    return j


def main() -> None:
    path = Path(__file__).with_name("joints.usda")
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, "Y")
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(48)
    stage.SetTimeCodesPerSecond(24)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    UsdPhysics.Scene.Define(stage, "/World/physicsScene")
    ground = UsdGeom.Plane.Define(stage, "/World/ground")
    ground.CreateAxisAttr("Y")
    UsdPhysics.CollisionAPI.Apply(ground.GetPrim())
    post = cube(stage, "/World/post", (0.2, 3.0, 0.2), (0, 1.5, 0), dynamic=False)
    # revolute: a door to the post (limited), with an angular velocity drive
    door = cube(stage, "/World/door", (1.0, 1.0, 0.05), (0.6, 2.0, 0), mass=10)
    rev = joint(stage, UsdPhysics.RevoluteJoint, "/World/joints/hinge", "/World/post", "/World/door",
                (0.5, 0.1667, 0), (-0.5, 0, 0))
    rev.CreateAxisAttr("Y")
    rev.CreateLowerLimitAttr(-90.0)
    rev.CreateUpperLimitAttr(90.0)
    drive = UsdPhysics.DriveAPI.Apply(rev.GetPrim(), "angular")
    drive.CreateDampingAttr(50.0)
    drive.CreateTargetVelocityAttr(45.0)
    # prismatic: a slider along the post, limited
    slider = cube(stage, "/World/slider", (0.3, 0.3, 0.3), (0, 0.6, 0.4), mass=2)
    pri = joint(stage, UsdPhysics.PrismaticJoint, "/World/joints/slide", "/World/post", "/World/slider",
                (0, -0.3, 2.0), (0, 0, 0))
    pri.CreateAxisAttr("Y")
    pri.CreateLowerLimitAttr(-0.3)
    pri.CreateUpperLimitAttr(0.3)
    # spherical: a pendulum with a cone, to the world
    # (localPos is in the body's own, scaled, coordinates: 5 x 0.2 = 1 m above the bob)
    bob = cube(stage, "/World/bob", (0.2, 0.2, 0.2), (2.0, 1.5, 0), mass=1)
    UsdPhysics.RigidBodyAPI(bob).CreateVelocityAttr(Gf.Vec3f(3.0, 0.0, 1.0))
    sph = joint(stage, UsdPhysics.SphericalJoint, "/World/joints/ball", None, "/World/bob", (2.0, 2.5, 0), (0, 5.0, 0))
    sph.CreateAxisAttr("Y")
    sph.CreateConeAngle0LimitAttr(40.0)
    sph.CreateConeAngle1LimitAttr(40.0)
    # distance: a second bob on a rope of at most 0.8 m below the first
    bob2 = cube(stage, "/World/bob2", (0.15, 0.15, 0.15), (2.0, 0.9, 0), mass=0.5)
    dist = joint(stage, UsdPhysics.DistanceJoint, "/World/joints/rope", "/World/bob", "/World/bob2", (0, 0, 0), (0, 0, 0))
    dist.CreateMaxDistanceAttr(0.8)
    # fixed: a pair glued, falling onto the ground; a breakable glue under a heavy block
    a = cube(stage, "/World/glued_a", (0.3, 0.3, 0.3), (-2.0, 0.4, 0), mass=1)
    b = cube(stage, "/World/glued_b", (0.3, 0.3, 0.3), (-2.0, 0.7, 0), mass=1)
    joint(stage, UsdPhysics.FixedJoint, "/World/joints/glue", "/World/glued_a", "/World/glued_b", (0, 0.5, 0), (0, -0.5, 0))
    hang = cube(stage, "/World/hanging", (0.3, 0.3, 0.3), (-3.0, 2.0, 0), mass=5)
    weak = joint(stage, UsdPhysics.FixedJoint, "/World/joints/weak", None, "/World/hanging", (-3.0, 2.15, 0), (0, 0.5, 0))
    weak.CreateBreakForceAttr(30.0)  # under 5 kg x 9.81 m/s^2: it breaks at once
    # D6: a block free along X (limited), turning about Z (limited), everything else locked
    d6b = cube(stage, "/World/d6_block", (0.3, 0.2, 0.2), (0, 2.5, -1.5), mass=1)
    d6 = joint(stage, UsdPhysics.Joint, "/World/joints/d6", None, "/World/d6_block", (0, 2.5, -1.5), (0, 0, 0))
    for dof, low, high in (("transX", -0.5, 0.5), ("transY", 1, -1), ("transZ", 1, -1), ("rotX", 1, -1),
                           ("rotY", 1, -1), ("rotZ", -30, 30)):
        limit = UsdPhysics.LimitAPI.Apply(d6.GetPrim(), dof)
        limit.CreateLowAttr(low)
        limit.CreateHighAttr(high)
    # an articulation root over the pendulum pair (maximal coordinates: read as its joints)
    UsdPhysics.ArticulationRootAPI.Apply(bob)
    # collision filtering: the slider passes through the door (a filtered pair); a group of
    # the two bobs that does not collide with itself
    UsdPhysics.FilteredPairsAPI.Apply(slider).CreateFilteredPairsRel().SetTargets(["/World/door"])
    group = UsdPhysics.CollisionGroup.Define(stage, "/World/bobs")
    group.CreateFilteredGroupsRel().SetTargets(["/World/bobs"])
    Usd.CollectionAPI.Get(group.GetPrim(), "colliders").CreateIncludesRel().SetTargets(["/World/bob", "/World/bob2"])
    stage.GetRootLayer().Save()


if __name__ == "__main__":
    main()
