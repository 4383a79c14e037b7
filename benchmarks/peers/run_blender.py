"""Blender's rigid body world (bpy, Bullet inside) on one peer-benchmark scene; one JSON line.

    benchmarks/peers/.venv-bpy/bin/python benchmarks/peers/run_blender.py SCENE [--seconds S]
        [--substeps N]

Settings (bpy 5.0.1 from PyPI, factory settings, Z up: scenes are converted from Y up):
- 24 fps, time scale 1, solver iterations 10 (default), split impulse off (default),
  substeps per frame 10 (default, 240 Hz) in every scene. The sphere's rebound depends
  erratically on the substeps (Bullet drops the restitution of a contact that has existed for
  more than a couple of steps, and its 0.04 m contact margin makes contacts appear before
  impact when the steps are short): compare.py also runs the drop at 20, 40 and 100 substeps
  (--substeps) and reports them beside the default;
- Bullet multiplies the friction and restitution of a pair, so every object (and the ground)
  gets sqrt(mu) and sqrt(e);
- linear and angular damping 0 (Blender's defaults 0.04 and 0.1 damp every body, which
  slows the sliding box and the falling sphere; --default-damping keeps them, and
  compare.py also runs the tower and the pyramid that way);
- collision shapes BOX and SPHERE (the default is CONVEX_HULL), collision margin left at
  Blender's default (0.04 m, which Bullet keeps inside box and sphere shapes);
- deactivation off (default); the ground is a passive 200 x 200 x 2 m box, top at the
  ground height.
- pile_meshes (nonconvex tori, L-shapes, spheres): each body an object with the true mesh,
  its origin at the centre of mass (Blender's rigid bodies turn about the object origin) and
  its axes the principal axes, mass from the mesh's volume and the density (Blender takes
  the inertia from the collision shape itself: there is no setting for it). Collision shape
  (--mesh-shape): COMPOUND (default): a Compound Parent whose children are CONVEX_HULL
  objects, one per piece of scenes.py's exact decomposition (the torus's 32 tube segments,
  the L's two boxes, the sphere whole): Blender's way to a nonconvex active body made of
  convex parts; or MESH: Bullet's GImpact triangle mesh of the object itself, which Blender
  allows for active bodies (compare.py runs it once as an extra). Margins: Blender's
  defaults (convex hulls: 0.04 m embedded, i.e. the hull shrunk by it and the margin added
  back round it, which rounds the hull's edges and corners: a box-like corner of the true
  mesh can then sit up to (sqrt 3 - 1) 0.04 = 29 mm inside what it rests on; MESH: 0.04 m
  round the triangles, so bodies rest up to 4 cm apart). Initial velocities: Blender has
  no setting for a rigid body's initial velocity (keying 'Animated' off after a keyed first
  frame did not hand over the spin in bpy 5.0.1), so pile.toml's initial spins (up to
  2 rad/s) are NOT given: Blender's bodies start at rest.
Only scene.frame_set (which steps the rigid body world, and evaluates the depsgraph as
Blender always does) is timed.
"""

from __future__ import annotations

import json
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import scenes  # noqa: E402

import bpy  # noqa: E402  (first: bmesh and mathutils come with it)
import bmesh  # noqa: E402
from mathutils import Matrix  # noqa: E402

DEFAULT_SUBSTEPS = 10


def make_mesh(name: str, shape: str, size) -> "bpy.types.Mesh":
    me = bpy.data.meshes.new(name)
    bm = bmesh.new()
    if shape == "box":
        bmesh.ops.create_cube(bm, size=1.0, matrix=Matrix.Diagonal((size[0], size[1], size[2], 1.0)))
    else:   # 32 x 16 keeps vertices on the poles and the equator: bounds are exactly 2 r
        bmesh.ops.create_uvsphere(bm, u_segments=32, v_segments=16, radius=size[0])
    bm.to_mesh(me)
    bm.free()
    return me


def mesh_from(name: str, vertices, triangles=None) -> "bpy.types.Mesh":
    """A mesh datablock from vertices and triangles; without triangles, their convex hull."""
    me = bpy.data.meshes.new(name)
    if triangles is not None:
        me.from_pydata([tuple(float(c) for c in v) for v in vertices], [], [tuple(int(i) for i in t) for t in triangles])
    else:
        bm = bmesh.new()
        for v in vertices:
            bm.verts.new(tuple(float(c) for c in v))
        bmesh.ops.convex_hull(bm, input=list(bm.verts))
        bm.to_mesh(me)
        bm.free()
    me.update()
    return me


def new_world(scene: scenes.Scene, substeps: int):
    """An empty Blender scene with a rigid body world (substeps per frame, the scene's frames,
    gravity) and the ground box; the per-object friction and restitution giving each pair
    the scene's mu and e. Returns (scene, rigid body world, mu, e, ground)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = scenes.FPS, 1.0
    sc.use_gravity = True
    sc.gravity = scenes.vec_to_zup(scene.gravity)
    bpy.ops.rigidbody.world_add()
    rbw = sc.rigidbody_world
    rbw.substeps_per_frame = substeps
    rbw.time_scale = 1.0
    sc.frame_start, sc.frame_end = 1, scene.frames + 1
    rbw.point_cache.frame_start, rbw.point_cache.frame_end = 1, scene.frames + 1
    mu = scenes.per_object(scene.mu, "product")
    e = scenes.per_object(scene.e, "product") if scene.e > 0 else 0.0
    ground = bpy.data.objects.new("ground", make_mesh("ground", "box", (200.0, 200.0, 2.0)))
    sc.collection.objects.link(ground)
    ground.location = (0.0, 0.0, scene.ground_height - 1.0)
    return sc, rbw, mu, e, ground


def add_rigid_bodies(sc, active, ground) -> None:
    """Every object of the scene but the ground an active rigid body, the ground a passive one:
    one operator call per type over the selection (per-object operators are slow)."""
    for obj in sc.objects:
        obj.select_set(obj is not ground)
    bpy.context.view_layer.objects.active = active
    bpy.ops.rigidbody.objects_add(type="ACTIVE")
    for obj in sc.objects:
        obj.select_set(obj is ground)
    bpy.context.view_layer.objects.active = ground
    bpy.ops.rigidbody.objects_add(type="PASSIVE")


def build_meshes(scene: scenes.Scene, substeps: int, mesh_shape: str):
    """pile_meshes: objects with the true meshes (principal frames), COMPOUND or MESH shapes."""
    sc, rbw, mu, e, ground = new_world(scene, substeps)

    whole, pieces = {}, {}
    for m in sorted({b.mesh for b in scene.bodies}):
        shape = scenes.mesh_shape(m)
        # the principal frame's axes are the object's; the mesh is given in them
        whole[m] = mesh_from(os.path.basename(m), shape.principal(shape.vertices), shape.triangles)
        pieces[m] = [mesh_from(f"{os.path.basename(m)}.{k}", shape.principal(p)) for k, p in enumerate(shape.pieces)]
    objects, children = [], []
    for i, b in enumerate(scene.bodies):
        com, q = scenes.principal_pose(b)
        obj = bpy.data.objects.new(f"body{i:05d}", whole[b.mesh])
        sc.collection.objects.link(obj)
        obj.location = scenes.vec_to_zup(com)
        obj.rotation_mode = "QUATERNION"
        obj.rotation_quaternion = scenes.quat_to_zup(q)
        objects.append(obj)
        if mesh_shape == "COMPOUND":
            for k, me in enumerate(pieces[b.mesh]):
                child = bpy.data.objects.new(f"body{i:05d}.{k}", me)
                sc.collection.objects.link(child)
                child.parent = obj          # identity parent inverse: the child sits in obj's frame
                children.append(child)
    add_rigid_bodies(sc, objects[0], ground)
    for obj, b in zip(objects, scene.bodies):
        rb = obj.rigid_body
        rb.collision_shape = mesh_shape
        if mesh_shape == "MESH":
            rb.mesh_source = "BASE"
        rb.mass = b.mass
        rb.friction, rb.restitution = mu, e
        rb.linear_damping = rb.angular_damping = 0.0
        rb.use_deactivation = False
    for child in children:
        rb = child.rigid_body
        rb.collision_shape = "CONVEX_HULL"
        rb.friction, rb.restitution = mu, e
    rb = ground.rigid_body
    rb.collision_shape = "BOX"
    rb.friction, rb.restitution = mu, e
    if any(any(b.angular_velocity) or any(b.linear_velocity) for b in scene.bodies):
        # Blender has no initial velocity for a rigid body: animated for one frame instead
        # would change the start; the benchmark says so rather than fake it
        initial_velocity = "NOT SET: Blender rigid bodies have no initial velocity (bodies start at rest)"
    else:
        initial_velocity = "zero"
    settings = {
        "fps": scenes.FPS, "substeps_per_frame": substeps, "solver_iterations": rbw.solver_iterations,
        "split_impulse": rbw.use_split_impulse, "time_scale": rbw.time_scale,
        "friction_per_object": mu, "restitution_per_object": e, "combine": "product (Bullet)",
        "damping": "linear 0, angular 0 (Blender defaults 0.04 / 0.1)",
        "nonconvex_meshes": (f"COMPOUND parent of CONVEX_HULL children, scenes.py's exact decomposition "
                             f"({len(children)} children)" if mesh_shape == "COMPOUND"
                             else "MESH (Bullet GImpact triangle mesh of the true mesh)"),
        "collision_shape": mesh_shape,
        "collision_margin": objects[0].rigid_body.collision_margin, "use_margin": objects[0].rigid_body.use_margin,
        "inertia": "Blender's, from the collision shape (not settable)",
        "initial_velocity": initial_velocity, "deactivation": False,
        "threads": "process pinned to one CPU by compare.py" if len(os.sched_getaffinity(0)) == 1
                   else f"{len(os.sched_getaffinity(0))} CPUs allowed",
    }
    return sc, objects, settings


def build(scene: scenes.Scene, substeps: int, damping: bool = False):
    sc, rbw, mu, e, ground = new_world(scene, substeps)

    meshes, objects = {}, []
    for i, b in enumerate(scene.bodies):
        key = (b.shape, b.size)
        if key not in meshes:
            meshes[key] = make_mesh(f"{b.shape}{len(meshes)}", b.shape, b.size)
        obj = bpy.data.objects.new(f"body{i:05d}", meshes[key])
        sc.collection.objects.link(obj)
        obj.location = scenes.vec_to_zup(b.position)
        obj.rotation_mode = "QUATERNION"
        obj.rotation_quaternion = scenes.quat_to_zup(b.orientation)
        objects.append(obj)

    add_rigid_bodies(sc, objects[0], ground)

    for obj, b in zip(objects, scene.bodies):
        rb = obj.rigid_body
        rb.collision_shape = "BOX" if b.shape == "box" else "SPHERE"
        rb.mass = b.mass
        rb.friction, rb.restitution = mu, e
        if not damping:
            rb.linear_damping = rb.angular_damping = 0.0
        rb.use_deactivation = False
    rb = ground.rigid_body
    rb.collision_shape = "BOX"
    rb.friction, rb.restitution = mu, e
    margin = objects[0].rigid_body.collision_margin
    settings = {
        "fps": scenes.FPS, "substeps_per_frame": substeps, "solver_iterations": rbw.solver_iterations,
        "split_impulse": rbw.use_split_impulse, "time_scale": rbw.time_scale,
        "friction_per_object": mu, "restitution_per_object": e, "combine": "product (Bullet)",
        "damping": ("Blender defaults: linear 0.04, angular 0.1" if damping
                    else "linear 0, angular 0 (Blender defaults 0.04 / 0.1)"),
        "collision_margin": margin, "use_margin": objects[0].rigid_body.use_margin,
        "collision_shapes": "BOX / SPHERE", "deactivation": False,
        "threads": "process pinned to one CPU by compare.py" if len(os.sched_getaffinity(0)) == 1
                   else f"{len(os.sched_getaffinity(0))} CPUs allowed",
    }
    return sc, objects, settings


def main() -> None:
    import argparse
    ap = argparse.ArgumentParser()
    ap.add_argument("scene", choices=list(scenes.SCENES))
    ap.add_argument("--seconds", type=float, default=None)
    ap.add_argument("--substeps", type=int, default=None, help=f"substeps per frame (default {DEFAULT_SUBSTEPS})")
    ap.add_argument("--default-damping", action="store_true",
                    help="keep Blender's default damping (linear 0.04, angular 0.1) instead of 0")
    ap.add_argument("--mesh-shape", choices=["COMPOUND", "MESH"], default="COMPOUND",
                    help="mesh scenes: the collision shape of the nonconvex bodies (default COMPOUND)")
    args = ap.parse_args()
    scene = scenes.build(args.scene, args.seconds)
    substeps = args.substeps or DEFAULT_SUBSTEPS
    mesh_scene = any(b.shape == "mesh" for b in scene.bodies)
    if mesh_scene:
        sc, objects, settings = build_meshes(scene, substeps, args.mesh_shape)
    else:
        sc, objects, settings = build(scene, substeps, args.default_damping)
    sc.frame_set(1)                      # the initial state (builds the Bullet world)

    def centres():
        return scenes.positions_from_zup([tuple(o.matrix_world.translation) for o in objects])

    def turns():   # the rotation of each world matrix without its scale, [w, x, y, z]
        return scenes.orientations_from_zup([tuple(o.matrix_world.decompose()[1]) for o in objects])

    if mesh_scene:   # principal frames -> the meshes' origins
        centres, turns = scenes.origin_pose_readers(scene, centres, turns)

    record = set(scene.recorded_frames())
    positions, orientations = [centres()], [turns()]
    clock = scenes.StepClock()
    for frame in range(1, scene.frames + 1):
        with clock:
            sc.frame_set(frame + 1)
        if frame in record:
            positions.append(centres())
            orientations.append(turns())
    print(json.dumps(scenes.result("blender", bpy.app.version_string, scene, clock,
                                   np.array(positions), settings, None, np.array(orientations))))


if __name__ == "__main__":
    main()
