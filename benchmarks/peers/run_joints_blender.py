"""Blender's rigid body constraints (bpy, Bullet inside) on one joint scene; one JSON line.

    benchmarks/peers/.venv-bpy/bin/python benchmarks/peers/run_joints_blender.py chain50|ragdoll

Settings (bpy 5.0.1 from PyPI, factory settings; kept Y up: scene gravity 0 -9.81 0, the
ground a passive 200 x 2 x 200 m box whose top is y = 0):
- rigid body world at 24 fps, 10 substeps per frame (Blender's default: 240 Hz), solver
  iterations 10 (default); linear and angular damping 0 (Blender's defaults 0.04 / 0.1 would
  drain the chain); deactivation off; BOX and SPHERE collision shapes, default margins;
- each joint an Empty at the joint's frame carrying a rigid body constraint between the two
  bodies (Bullet's constraints in maximal coordinates, like simbake's): chain50 POINT
  constraints, link 0's to a passive anchor body; ragdoll D6 joints GENERIC constraints with
  the translations locked, the twist (the frame's X) limited to +-t and both swing angles to
  +-c (Bullet's generic 6-DOF limits each Euler angle: a box, not a round cone, so it allows
  swings up to about 1.4 c diagonally: the limit error measured counts that), knees and
  elbows HINGE constraints (about the frame's Z) with their ranges; disable_collisions on
  (jointed pairs do not collide, as in simbake); chain50 links collide with nothing;
- friction: Bullet multiplies a pair's, so every object gets sqrt(mu);
- initial velocities: Blender has none for a rigid body, so the ragdoll starts at rest
  (tilted as the scene places it) where the others start at 0.9 m/s: its fall differs;
- velocities, which Blender does not expose: a second run of the same scene at 240 fps and
  one substep per frame (the same 240 Hz Bullet steps), poses every step, central
  differences at 1/240 s; energy comes from that run, everything else (and the time) from
  the first.
Only scene.frame_set (which steps the rigid body world) is timed.
"""

from __future__ import annotations

import json
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import joint_scenes  # noqa: E402

import bpy  # noqa: E402
from mathutils import Quaternion, Vector  # noqa: E402
from run_blender import make_mesh  # noqa: E402

SUBSTEPS = 10


def build(scene: joint_scenes.Scene, fps: int, substeps: int):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = fps, 1.0
    sc.use_gravity = True
    sc.gravity = (0.0, -joint_scenes.G, 0.0)
    bpy.ops.rigidbody.world_add()
    rbw = sc.rigidbody_world
    rbw.substeps_per_frame = substeps
    rbw.time_scale = 1.0
    frames = int(round(scene.seconds * fps))
    sc.frame_start, sc.frame_end = 1, frames + 1
    rbw.point_cache.frame_start, rbw.point_cache.frame_end = 1, frames + 1
    mu = math.sqrt(scene.mu)
    objects, passive = [], []
    for i, b in enumerate(scene.bodies):
        obj = bpy.data.objects.new(b.name, make_mesh(b.name, b.shape, b.size))
        sc.collection.objects.link(obj)
        obj.location = b.position
        obj.rotation_mode = "QUATERNION"
        obj.rotation_quaternion = b.orientation
        objects.append(obj)
        if b.kinematic:
            passive.append(obj)
    if scene.ground:
        ground = bpy.data.objects.new("ground", make_mesh("ground", "box", (200.0, 2.0, 200.0)))
        sc.collection.objects.link(ground)
        ground.location = (0.0, -1.0, 0.0)
        passive.append(ground)
    anchor = None
    if any(j.body0 < 0 for j in scene.joints):
        anchor = bpy.data.objects.new("anchor", make_mesh("anchor", "box", (0.01, 0.01, 0.01)))
        sc.collection.objects.link(anchor)
        anchor.location = (0.0, 10.0, 0.0)   # (out of the way; it never moves)
        passive.append(anchor)
    bpy.context.view_layer.update()
    for kind, group in (("ACTIVE", [o for o in objects if o not in passive]), ("PASSIVE", passive)):
        for obj in sc.objects:
            obj.select_set(obj in group)
        bpy.context.view_layer.objects.active = group[0]
        bpy.ops.rigidbody.objects_add(type=kind)
    for obj, b in zip(objects, scene.bodies):
        rb = obj.rigid_body
        rb.collision_shape = "BOX" if b.shape == "box" else "SPHERE"
        if not b.kinematic:
            rb.mass = b.mass
        rb.friction, rb.restitution = mu, 0.0
        rb.linear_damping = rb.angular_damping = 0.0
        rb.use_deactivation = False
        if not b.collides:
            rb.collision_collections = [False] * 19 + [True]   # a collection of its own ...
    if anchor is not None:
        anchor.rigid_body.collision_collections = [False] * 18 + [True, False]
    for obj in passive:
        obj.rigid_body.friction = mu
        obj.rigid_body.collision_shape = "BOX"
    chain_links = [o for o, b in zip(objects, scene.bodies) if not b.collides]
    if chain_links:   # ... and the links must not collide with each other either: Blender
        # collides objects sharing a collection, so each link gets one of 20 in turn, and
        # nothing else is in those: links 20 apart share one, but lie 2 m apart at the start
        for k, obj in enumerate(chain_links):
            obj.rigid_body.collision_collections = [c == k % 18 for c in range(20)]
    for j in scene.joints:
        empty = bpy.data.objects.new(f"{j.name}_constraint", None)
        sc.collection.objects.link(empty)
        if j.body0 < 0:
            frame_pos, frame_rot = Vector(j.local_position0), Quaternion(j.local_rotation0)
        else:
            b0 = scene.bodies[j.body0]
            q0 = Quaternion(b0.orientation)
            frame_pos = Vector(b0.position) + q0 @ Vector(j.local_position0)
            frame_rot = q0 @ Quaternion(j.local_rotation0)
        empty.location = frame_pos
        empty.rotation_mode = "QUATERNION"
        empty.rotation_quaternion = frame_rot
        bpy.context.view_layer.objects.active = empty
        for obj in sc.objects:
            obj.select_set(obj is empty)
        bpy.ops.rigidbody.constraint_add()
        c = empty.rigid_body_constraint
        c.object1 = anchor if j.body0 < 0 else objects[j.body0]
        c.object2 = objects[j.body1]
        c.disable_collisions = True
        if j.type == "spherical":
            c.type = "POINT"
        elif j.type == "revolute":
            assert j.axis == "z", j.name
            c.type = "HINGE"
            c.use_limit_ang_z = True
            # (Blender measures the hinge's angle the other way round: object 1 turning against
            # object 2; with the range as given the knees bent forward, 116-144 degrees past)
            c.limit_ang_z_lower, c.limit_ang_z_upper = -j.upper, -j.lower
        else:
            c.type = "GENERIC"
            for axis in "xyz":
                setattr(c, f"use_limit_lin_{axis}", True)
                setattr(c, f"limit_lin_{axis}_lower", 0.0)
                setattr(c, f"limit_lin_{axis}_upper", 0.0)
                setattr(c, f"use_limit_ang_{axis}", True)
                half = j.twist if axis == "x" else j.cone
                setattr(c, f"limit_ang_{axis}_lower", -half)
                setattr(c, f"limit_ang_{axis}_upper", half)
    settings = {"fps": fps, "substeps_per_frame": substeps, "solver_iterations": rbw.solver_iterations,
                "friction_per_object": mu, "damping": "linear 0, angular 0", "deactivation": False,
                "initial_velocity": "NOT SET: Blender rigid bodies have no initial velocity (bodies start at rest)",
                "joints": "rigid body constraints on Empties: POINT (chain), GENERIC with box limits (D6), HINGE"}
    return sc, objects, settings


def poses(objects):
    x = np.array([tuple(o.matrix_world.translation) for o in objects])
    q = np.array([tuple(o.matrix_world.decompose()[1]) for o in objects])
    return x, q


def velocities(x_prev, q_prev, x_next, q_next, h):
    """Central differences over 2h: linear velocity and world angular velocity."""
    v = (x_next - x_prev) / (2.0 * h)
    w = np.zeros_like(v)
    for i in range(len(v)):
        d = Quaternion(q_next[i]) @ Quaternion(q_prev[i]).inverted()
        if d.w < 0.0:
            d.negate()
        axis, angle = d.to_axis_angle()
        w[i] = np.array(axis) * angle / (2.0 * h)
    return v, w


def main(argv=None) -> None:
    args = joint_scenes.common_args(argv)
    scene = joint_scenes.build(args.scene, args.seconds)
    n = len(scene.bodies)
    # the timed run: 24 fps, 10 substeps; poses at every frame
    sc, objects, settings = build(scene, joint_scenes.FPS, SUBSTEPS)
    sc.frame_set(1)
    xs, qs = [], []
    x, q = poses(objects)
    xs.append(x), qs.append(q)
    clock = joint_scenes.Clock()
    for frame in range(1, scene.frames + 1):
        with clock:
            sc.frame_set(frame + 1)
        x, q = poses(objects)
        xs.append(x), qs.append(q)
    # the energy run: 240 fps, 1 substep; velocities by central differences at each 24 fps frame
    fine = joint_scenes.FPS * SUBSTEPS
    sc2, objects2, _ = build(scene, fine, 1)
    sc2.frame_set(1)
    fx, fq = [], []
    x, q = poses(objects2)
    fx.append(x), fq.append(q)
    for frame in range(1, scene.frames * SUBSTEPS + 2):
        sc2.frame_set(frame + 1)
        x, q = poses(objects2)
        fx.append(x), fq.append(q)
    recorder = joint_scenes.Recorder(scene)
    h = 1.0 / fine
    for frame in range(scene.frames + 1):
        k = frame * SUBSTEPS
        if k == 0:   # (the start: at rest)
            v, w = np.zeros((n, 3)), np.zeros((n, 3))
        else:
            v, w = velocities(fx[k - 1], fq[k - 1], fx[k + 1], fq[k + 1], h)
        recorder.record(frame, xs[frame], qs[frame], v, w)
    # the fine run's energy, but the timed run's poses for gaps and limits (they differ only in
    # when poses are read); both runs' gaps reported
    out = joint_scenes.result("blender", bpy.app.version_string, scene, clock, recorder, settings)
    fine_rec = joint_scenes.Recorder(scene)
    for frame in range(scene.frames + 1):
        k = frame * SUBSTEPS
        v, w = (np.zeros((n, 3)), np.zeros((n, 3))) if k == 0 else velocities(fx[k - 1], fq[k - 1], fx[k + 1],
                                                                                fq[k + 1], h)
        fine_rec.record(frame, fx[k], fq[k], v, w)
    fine_acc = fine_rec.analyze(scene)
    for key in ("energy_start_J", "energy_end_J", "energy_rise_max_J", "energy_change_J", "speed_max"):
        out["accuracy"][key] = fine_acc[key]
    out["accuracy"]["fine_run_joint_gap_max_m"] = fine_acc["joint_gap_max_m"]
    print(json.dumps(out))


if __name__ == "__main__":
    main()
