"""PyBullet on one joint scene of the peer benchmark; prints one JSON line.

    benchmarks/peers/.venv-peers/bin/python benchmarks/peers/run_joints_pybullet.py chain50|ragdoll

Settings (PyBullet 3.2.7, DIRECT, kept Y up: gravity 0 -9.81 0, the ground a static box whose
top is y = 0):
- time step 1/240 s (PyBullet's default; 10 steps per 1/24 s frame), default solver
  iterations and ERP;
- joints as constraints between separate rigid bodies (maximal coordinates, like simbake's
  and Blender's): createConstraint(JOINT_POINT2POINT) at each joint, the first chain link to
  the world. PyBullet's user constraints are point-to-point, fixed, gear and prismatic only:
  no hinge and no limits, so the ragdoll's knees and elbows are ball joints too and nothing
  limits twist, cone or hinge range (its limit error shows that; a multibody URDF would have
  hinge limits but no cone limits either);
- jointed pairs do not collide (setCollisionFilterPair 0), as in simbake; chain50 collides
  with nothing; friction: PyBullet multiplies a pair's, so every object gets sqrt(mu);
- linear and angular damping 0 (PyBullet's default 0.04 would drain the chain's energy);
- each body's initial linear and angular velocity as the scene gives them.
Only stepSimulation is timed.
"""

from __future__ import annotations

import json
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import joint_scenes  # noqa: E402

import pybullet as p  # noqa: E402

STEPS_PER_FRAME = 10


def xyzw(q):
    return (q[1], q[2], q[3], q[0])


def main(argv=None) -> None:
    args = joint_scenes.common_args(argv)
    scene = joint_scenes.build(args.scene, args.seconds)
    p.connect(p.DIRECT)
    p.setGravity(0.0, -joint_scenes.G, 0.0)
    p.setTimeStep(1.0 / (joint_scenes.FPS * STEPS_PER_FRAME))
    mu = math.sqrt(scene.mu)
    ids = []
    if scene.ground:
        ground = p.createMultiBody(0.0, p.createCollisionShape(p.GEOM_BOX, halfExtents=[100.0, 1.0, 100.0]),
                                   basePosition=[0.0, -1.0, 0.0])
        p.changeDynamics(ground, -1, lateralFriction=mu, restitution=0.0)
    for b in scene.bodies:
        if b.shape == "sphere":
            shape = p.createCollisionShape(p.GEOM_SPHERE, radius=b.size[0])
        else:
            shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.5 * s for s in b.size])
        k = p.createMultiBody(0.0 if b.kinematic else b.mass, shape, basePosition=b.position,
                              baseOrientation=xyzw(b.orientation))
        p.changeDynamics(k, -1, lateralFriction=mu, restitution=0.0, linearDamping=0.0, angularDamping=0.0)
        if not b.collides:
            p.setCollisionFilterGroupMask(k, -1, 0, 0)
        if not b.kinematic:
            p.resetBaseVelocity(k, b.linear_velocity, b.angular_velocity)
        ids.append(k)
    for j in scene.joints:
        if j.body0 < 0:
            p.createConstraint(ids[j.body1], -1, -1, -1, p.JOINT_POINT2POINT, [0, 0, 0], j.local_position1,
                               j.local_position0)
        else:
            p.createConstraint(ids[j.body0], -1, ids[j.body1], -1, p.JOINT_POINT2POINT, [0, 0, 0],
                               j.local_position0, j.local_position1)
            p.setCollisionFilterPair(ids[j.body0], ids[j.body1], -1, -1, 0)
    recorder = joint_scenes.Recorder(scene)
    n = len(scene.bodies)

    def record(frame):
        x, q, v, w = np.zeros((n, 3)), np.zeros((n, 4)), np.zeros((n, 3)), np.zeros((n, 3))
        for i, k in enumerate(ids):
            pos, orn = p.getBasePositionAndOrientation(k)
            lin, ang = p.getBaseVelocity(k)
            x[i], q[i], v[i], w[i] = pos, (orn[3], orn[0], orn[1], orn[2]), lin, ang
        recorder.record(frame, x, q, v, w)

    record(0)
    clock = joint_scenes.Clock()
    for frame in range(1, scene.frames + 1):
        with clock:
            for _ in range(STEPS_PER_FRAME):
                p.stepSimulation()
        record(frame)
    params = p.getPhysicsEngineParameters()
    out = joint_scenes.result("pybullet", "3.2.7", scene, clock, recorder,
                              {"time_step": params["fixedTimeStep"], "solver_iterations": params["numSolverIterations"],
                               "joints": "JOINT_POINT2POINT constraints (maximal coordinates)"})
    print(json.dumps(out))


if __name__ == "__main__":
    main()
