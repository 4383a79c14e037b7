"""PyBullet on one peer-benchmark scene; prints one JSON line.

    benchmarks/peers/.venv-peers/bin/python benchmarks/peers/run_pybullet.py SCENE [--seconds S]

Settings (PyBullet 3.2.7, DIRECT mode, Z up: scenes are converted from Y up):
- time step 1/240 s (PyBullet's default), 10 stepSimulation calls per 1/24 s frame; the
  default solver (sequential impulses, 50 iterations in PyBullet's default parameters);
- Bullet multiplies the friction (and the restitution) of a pair, so every object gets
  sqrt(mu) (sqrt(e)) and each pair exactly mu (e); rolling and spinning friction 0;
- no damping (PyBullet's default linear damping 0.04 and angular 0.04 set to 0);
- boxes: GEOM_BOX with the exact half extents (Bullet keeps its 0.04 m margin inside the
  box); spheres: GEOM_SPHERE; ground: a GEOM_PLANE; inertia from the shape and the mass;
- sphere drop only: contactBreakingThreshold 0.005 m (the default 0.02 keeps stale contacts
  alive and swallows the bounce; the parameter is global to the process, so the stacking
  scenes keep the default that helps them stay still);
- deactivation (sleeping) left as Bullet's default.
- pile_meshes (nonconvex tori, L-shapes, spheres): a dynamic body in Bullet must be convex or
  a compound of convex shapes (GEOM_MESH with indices is a static-only triangle mesh), so
  each mesh is given as a compound of convex hulls, as PyBullet does for a V-HACD result: an
  .obj with one object per convex piece, loaded with GEOM_MESH (PyBullet makes one
  btConvexHullShape per object). The pieces are scenes.py's exact decomposition (the
  torus's 32 tube segments, the L's two boxes, the sphere whole), whose union is the mesh:
  no hull of a whole torus. Each body's frame is its centre of mass and principal axes;
  mass from the mesh's volume and the density, inertia (localInertiaDiagonal) the mesh's
  principal moments; initial linear and angular velocities set with resetBaseVelocity.
Only the stepSimulation calls are timed.
"""

from __future__ import annotations

import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import scenes  # noqa: E402

import pybullet as p  # noqa: E402

TIME_STEP = 1.0 / 240.0
STEPS_PER_FRAME = int(round(1.0 / (TIME_STEP * scenes.FPS)))   # 10


def xyzw(q_wxyz):
    w, x, y, z = q_wxyz
    return (x, y, z, w)


def pieces_obj(mesh: str):
    """The mesh's convex pieces (principal frame) as an .obj of one object each (faces: a fan
    over each piece's points, enough for Bullet, which takes the hull of each object's points)."""
    shape = scenes.mesh_shape(mesh)
    scenes.PROBE_CACHE.mkdir(exist_ok=True)
    path = scenes.PROBE_CACHE / f"pieces-{os.path.basename(mesh)[:-4]}-{shape.sha1}.obj"
    lines, base = [], 1
    for k, piece in enumerate(shape.pieces):
        pts = shape.principal(piece)
        lines.append(f"o piece{k}")
        lines += [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in pts]
        lines += [f"f {base} {base + i} {base + i + 1}" for i in range(1, len(pts) - 1)]
        base += len(pts)
    text = "\n".join(lines) + "\n"
    if not path.exists() or path.read_text() != text:
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(text)
        os.replace(tmp, path)
    return path


def build(scene: scenes.Scene, client: int) -> tuple[list, dict]:
    p.resetSimulation(physicsClientId=client)
    p.setGravity(*scenes.vec_to_zup(scene.gravity), physicsClientId=client)
    p.setTimeStep(TIME_STEP, physicsClientId=client)
    if scene.name == "drop":
        p.setPhysicsEngineParameter(contactBreakingThreshold=0.005, physicsClientId=client)
    params = p.getPhysicsEngineParameters(physicsClientId=client)
    mu = scenes.per_object(scene.mu, "product")
    e = scenes.per_object(scene.e, "product") if scene.e > 0 else 0.0
    plane = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=client)
    ground = p.createMultiBody(0.0, plane, -1, (0.0, 0.0, scene.ground_height), physicsClientId=client)
    p.changeDynamics(ground, -1, lateralFriction=mu, restitution=e, rollingFriction=0.0,
                     spinningFriction=0.0, physicsClientId=client)
    shapes, ids = {}, []
    for b in scene.bodies:
        key = (b.shape, b.size, b.mesh)
        if b.shape == "mesh":
            if key not in shapes:
                shapes[key] = p.createCollisionShape(p.GEOM_MESH, fileName=str(pieces_obj(b.mesh)),
                                                     physicsClientId=client)
            shape = scenes.mesh_shape(b.mesh)
            com, q = scenes.principal_pose(b)
            body = p.createMultiBody(b.mass, shapes[key], -1, scenes.vec_to_zup(com),
                                     xyzw(scenes.quat_to_zup(q)), physicsClientId=client)
            p.changeDynamics(body, -1, lateralFriction=mu, restitution=e, rollingFriction=0.0,
                             spinningFriction=0.0, linearDamping=0.0, angularDamping=0.0,
                             localInertiaDiagonal=[float(v) for v in b.density * shape.moments],
                             physicsClientId=client)
            p.resetBaseVelocity(body, scenes.vec_to_zup(b.linear_velocity), scenes.vec_to_zup(b.angular_velocity),
                                physicsClientId=client)
            ids.append(body)
            continue
        if key not in shapes:
            if b.shape == "box":
                shapes[key] = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.5 * s for s in b.size],
                                                     physicsClientId=client)
            else:
                shapes[key] = p.createCollisionShape(p.GEOM_SPHERE, radius=b.radius, physicsClientId=client)
        body = p.createMultiBody(b.mass, shapes[key], -1, scenes.vec_to_zup(b.position),
                                 xyzw(scenes.quat_to_zup(b.orientation)), physicsClientId=client)
        p.changeDynamics(body, -1, lateralFriction=mu, restitution=e, rollingFriction=0.0,
                         spinningFriction=0.0, linearDamping=0.0, angularDamping=0.0,
                         physicsClientId=client)
        ids.append(body)
    mesh_settings = {}
    if any(b.shape == "mesh" for b in scene.bodies):
        mesh_settings = {"nonconvex_meshes": "compound of convex hulls (GEOM_MESH from an .obj of one object "
                                             "per piece), scenes.py's exact decomposition",
                         "pieces": {os.path.basename(m): len(scenes.mesh_shape(m).pieces)
                                    for m in sorted({b.mesh for b in scene.bodies})},
                         "children_per_shape": {os.path.basename(k[2]): len(p.getCollisionShapeData(
                             ids[[b.mesh for b in scene.bodies].index(k[2])], -1, physicsClientId=client))
                             for k in shapes},
                         "inertia": "mesh principal moments x density (localInertiaDiagonal)"}
    settings = {
        **mesh_settings,
        "time_step": TIME_STEP, "steps_per_frame": STEPS_PER_FRAME,
        "solver_iterations": params.get("numSolverIterations"),
        "contact_breaking_threshold": 0.005 if scene.name == "drop" else "default (0.02)",
        "friction_per_object": mu, "restitution_per_object": e, "combine": "product (Bullet)",
        "damping": "linear 0, angular 0", "rolling_spinning_friction": 0.0,
        "engine_parameters": {k: v for k, v in params.items() if isinstance(v, (int, float))},
    }
    return ids, settings


def main() -> None:
    args = scenes.common_args()
    scene = scenes.build(args.scene, args.seconds)
    client = p.connect(p.DIRECT)
    ids, settings = build(scene, client)

    def centres():
        return scenes.positions_from_zup(
            [p.getBasePositionAndOrientation(i, physicsClientId=client)[0] for i in ids])

    def turns():   # PyBullet's quaternions are [x, y, z, w]
        xyzw = np.array([p.getBasePositionAndOrientation(i, physicsClientId=client)[1] for i in ids])
        return scenes.orientations_from_zup(xyzw[:, [3, 0, 1, 2]])

    if any(b.shape == "mesh" for b in scene.bodies):   # principal frames -> the meshes' origins
        centres, turns = scenes.origin_pose_readers(scene, centres, turns)

    record = set(scene.recorded_frames())
    positions, orientations = [centres()], [turns()]
    clock = scenes.StepClock()
    for frame in range(1, scene.frames + 1):
        with clock:
            for _ in range(STEPS_PER_FRAME):
                p.stepSimulation(physicsClientId=client)
        if frame in record:
            positions.append(centres())
            orientations.append(turns())
    version = "3.2.7 (API %d)" % p.getAPIVersion(physicsClientId=client)
    try:
        from importlib.metadata import version as dist_version
        version = dist_version("pybullet")
    except Exception:
        pass
    p.disconnect(client)
    print(json.dumps(scenes.result("pybullet", version, scene, clock,
                                   np.array(positions), settings, None, np.array(orientations))))


if __name__ == "__main__":
    main()
