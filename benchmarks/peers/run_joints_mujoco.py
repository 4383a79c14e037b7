"""MuJoCo on one joint scene of the peer benchmark; prints one JSON line.

    benchmarks/peers/.venv-peers/bin/python benchmarks/peers/run_joints_mujoco.py chain50|ragdoll
        [--steps-per-frame N]

Settings (MuJoCo 4.0.0, kept Y up: gravity 0 -9.81 0, the floor plane turned to face +y):
- time step 1/504 s (21 steps per 1/24 s frame, as run_mujoco.py; --steps-per-frame), default integrator
  (Euler), solver (Newton), solimp/solref defaults, pyramidal friction cones, condim 3;
- joints in MuJoCo's own way: generalized coordinates, a kinematic tree (chain50: link 0's
  ball joint at the origin, each link a child of the one before with a ball joint at its -x
  end; ragdoll: the pelvis free, every other body a child of its parent joint's body 0). A
  tree's joints cannot open, so MuJoCo's joint gap is zero by construction (what is left is
  rounding in the forward kinematics);
- ragdoll limits: knees and elbows are hinges with their ranges; a D6 joint (twist within
  +-t, round swing cone c) is a ball joint whose range c limits the whole rotation angle
  (MuJoCo has no separate twist limit), so twist is held within c, not t: the limit error
  measured is of the cone and hinge limits; twist beyond t is allowed and shows in it;
- friction: MuJoCo combines a pair by max, so every geom gets mu; contacts between a parent
  and child body are excluded (MuJoCo's default), as simbake's jointed pairs;
- initial velocities: every body's linear and angular velocity of the scene cannot be set
  in a tree; the pelvis gets its own (free joint), the joints none, so the limbs start turning
  with the pelvis (simbake starts each body with the same linear velocity and projects);
- chain50 geoms do not collide (contype 0); inertia from the boxes at the scene's masses.
Only mj_step is timed.
"""

from __future__ import annotations

import json
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import joint_scenes  # noqa: E402
import scenes  # noqa: E402

import mujoco  # noqa: E402

STEPS_PER_FRAME = 21


def fmt(v) -> str:
    return " ".join(f"{float(a):.17g}" for a in v)


def quat_conj(q):
    return (q[0], -q[1], -q[2], -q[3])


def rotate(q, v):
    return np.array(scenes.quat_multiply(scenes.quat_multiply(q, (0.0, *v)), quat_conj(q))[1:])


def geom(b: joint_scenes.Body, mu: float, collide: bool) -> str:
    flags = "" if collide else ' contype="0" conaffinity="0"'
    if b.shape == "sphere":
        return f'<geom type="sphere" size="{b.size[0]}" mass="{b.mass}" friction="{mu} 0.005 0.0001"{flags}/>'
    return f'<geom type="box" size="{fmt(np.array(b.size) / 2)}" mass="{b.mass}" friction="{mu} 0.005 0.0001"{flags}/>'


def model_xml(scene: joint_scenes.Scene, steps_per_frame: int = STEPS_PER_FRAME) -> str:
    """The scene as a kinematic tree: each body's frame placed relative to its parent's."""
    parent = {j.body1: j for j in scene.joints}
    children: dict[int, list[int]] = {}
    roots = []
    for i, b in enumerate(scene.bodies):
        if b.kinematic:
            continue
        j = parent.get(i)
        if j is None or j.body0 < 0:
            roots.append(i)
        else:
            children.setdefault(j.body0, []).append(i)

    def body_xml(i: int, frame_pos, frame_quat) -> str:
        b = scene.bodies[i]
        # pose relative to the parent's frame
        rel_q = scenes.quat_multiply(quat_conj(frame_quat), b.orientation)
        rel_p = rotate(quat_conj(frame_quat), np.array(b.position) - np.array(frame_pos))
        j = parent.get(i)
        if j is None:
            joint = "<freejoint/>"
        else:
            pos = fmt(j.local_position1)
            if j.type == "spherical":
                joint = f'<joint type="ball" pos="{pos}"/>'
            elif j.type == "d6":
                joint = f'<joint type="ball" pos="{pos}" limited="true" range="0 {j.cone}"/>'
            else:   # revolute: about the frames' axis (identity local rotations in these scenes)
                assert j.local_rotation0 == j.local_rotation1 == (1.0, 0.0, 0.0, 0.0)
                axis = np.eye(3)[{"x": 0, "y": 1, "z": 2}[j.axis]]
                joint = f'<joint type="hinge" pos="{pos}" axis="{fmt(axis)}" limited="true" range="{j.lower} {j.upper}"/>'
        inner = "".join(body_xml(k, b.position, b.orientation) for k in children.get(i, []))
        return (f'<body name="b{i}" pos="{fmt(rel_p)}" quat="{fmt(rel_q)}">{joint}'
                f'{geom(b, scene.mu, b.collides)}{inner}</body>')

    world = []
    if scene.ground:
        world.append(f'<geom type="plane" size="0 0 1" zaxis="0 1 0" friction="{scene.mu} 0.005 0.0001"/>')
    for b in scene.bodies:
        if b.kinematic:
            world.append(f'<geom type="box" pos="{fmt(b.position)}" quat="{fmt(b.orientation)}" '
                         f'size="{fmt(np.array(b.size) / 2)}" friction="{scene.mu} 0.005 0.0001"/>')
    for r in roots:
        world.append(body_xml(r, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0)))
    dt = 1.0 / (joint_scenes.FPS * steps_per_frame)
    return (f'<mujoco><compiler angle="radian" autolimits="true"/>'
            f'<option timestep="{dt:.17g}" gravity="0 {-joint_scenes.G} 0"/>'
            f'<size memory="64M"/><worldbody>{"".join(world)}</worldbody></mujoco>')


def main(argv=None) -> None:
    import argparse
    ap = argparse.ArgumentParser()
    ap.add_argument("scene", choices=list(joint_scenes.SCENES))
    ap.add_argument("--seconds", type=float, default=None)
    ap.add_argument("--steps-per-frame", type=int, default=STEPS_PER_FRAME)
    args = ap.parse_args(argv)
    scene = joint_scenes.build(args.scene, args.seconds)
    steps = args.steps_per_frame
    model = mujoco.MjModel.from_xml_string(model_xml(scene, steps))
    data = mujoco.MjData(model)
    ids = {i: model.body(f"b{i}").id for i, b in enumerate(scene.bodies) if not b.kinematic}
    # the root's initial velocity (free joint: linear world, angular in the body frame)
    for i, b in enumerate(scene.bodies):
        if b.kinematic or any(j.body1 == i for j in scene.joints):
            continue
        adr = model.jnt_dofadr[model.body_jntadr[ids[i]]]
        data.qvel[adr:adr + 3] = b.linear_velocity
        data.qvel[adr + 3:adr + 6] = rotate(quat_conj(b.orientation), b.angular_velocity)
    mujoco.mj_forward(model, data)
    recorder = joint_scenes.Recorder(scene)
    n = len(scene.bodies)
    vel = np.zeros(6)

    def record(frame):
        x, q, v, w = np.zeros((n, 3)), np.zeros((n, 4)), np.zeros((n, 3)), np.zeros((n, 3))
        q[:, 0] = 1.0
        for i, b in enumerate(scene.bodies):
            if b.kinematic:
                x[i], q[i] = b.position, b.orientation
                continue
            k = ids[i]
            x[i], q[i] = data.xpos[k], data.xquat[k]
            mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_BODY, k, vel, 0)
            w[i], v[i] = vel[:3], vel[3:]
        recorder.record(frame, x, q, v, w)

    record(0)
    clock = joint_scenes.Clock()
    for frame in range(1, scene.frames + 1):
        with clock:
            for _ in range(steps):
                mujoco.mj_step(model, data)
        record(frame)
    out = joint_scenes.result("mujoco", mujoco.__version__, scene, clock, recorder,
                              {"time_step": model.opt.timestep, "integrator": "Euler", "joints": "generalized coordinates"})
    # (MuJoCo resets the state to the model's start when accelerations blow up, and warns)
    out["accuracy"]["unstable_resets"] = int(data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
