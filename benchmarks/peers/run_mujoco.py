"""MuJoCo on one peer-benchmark scene; prints one JSON line.

    benchmarks/peers/.venv-peers/bin/python benchmarks/peers/run_mujoco.py SCENE [--seconds S]

Settings (MuJoCo 4.0.0, Z up: scenes are converted from Y up):
- time step 1/504 s (21 steps per 1/24 s frame; MuJoCo's default is 0.002 s, which does not
  divide a frame), default integrator (Euler), solver (Newton), pyramidal friction cones,
  condim 3 (sliding friction only), default solimp;
- MuJoCo combines the friction of a pair by max, so every geom (and the floor plane) gets mu;
  torsional and rolling friction at MuJoCo's defaults (0.005, 0.0001) do nothing with condim 3;
- no restitution coefficient in MuJoCo: contacts are spring-dampers set by solref
  (timeconst, dampratio). e = 0 scenes keep the default (0.02 s, 1, critically damped).
  The sphere drop gets the damping ratio of a linear spring-damper whose coefficient of
  restitution is e: zeta = -ln e / sqrt(pi^2 + ln^2 e) = 0.2155 for e = 0.5, timeconst 0.02 s;
- boxes and spheres as primitive geoms with the scene's mass (inertia from the shape);
  the ground is an infinite plane.
- pile_meshes (nonconvex tori, L-shapes, spheres): MuJoCo collides a mesh geom as its convex
  hull, so each nonconvex body is several convex mesh geoms, the way MuJoCo's documentation
  asks for nonconvex shapes: scenes.py's exact decomposition (the torus's 32 tube segments,
  the L's two boxes, the sphere whole), whose union is the mesh, never the hull of a whole
  torus. The script checks it: the pieces' hull volumes (MuJoCo's own, inertia="convex")
  add up to the mesh's volume. Each body's frame is its centre of mass and principal axes,
  with an explicit <inertial> (mass from the mesh's volume and the density, the mesh's
  principal moments); multi-point convex contacts (multiccd) are on, MuJoCo's default;
  initial velocities in qvel (angular in the body frame). Arena memory 1 GB.
Only mj_step is timed (the model is compiled before the clock starts).
"""

from __future__ import annotations

import json
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import scenes  # noqa: E402

import mujoco  # noqa: E402

STEPS_PER_FRAME = 21
TIME_STEP = 1.0 / (scenes.FPS * STEPS_PER_FRAME)
TIMECONST = 0.02


def damping_ratio_for_restitution(e: float) -> float:
    if e <= 0.0:
        return 1.0
    ln = math.log(e)
    return -ln / math.sqrt(math.pi ** 2 + ln ** 2)


def mesh_name(mesh: str) -> str:
    return os.path.basename(mesh).rsplit(".", 1)[0]


def decomposition_check(mesh: str) -> dict:
    """MuJoCo's own volume of the pieces' hulls (unit density) against the mesh's volume."""
    shape = scenes.mesh_shape(mesh)
    assets = "".join(f'<mesh name="p{k}" vertex="{" ".join(f"{float(v):.17g}" for v in shape.principal(piece).ravel())}" '
                     f'inertia="convex"/>' for k, piece in enumerate(shape.pieces))
    geoms = "".join(f'<geom type="mesh" mesh="p{k}" density="1"/>' for k in range(len(shape.pieces)))
    model = mujoco.MjModel.from_xml_string(f'<mujoco><asset>{assets}</asset><worldbody><body><freejoint/>'
                                           f'{geoms}</body></worldbody></mujoco>')
    return {"pieces": len(shape.pieces), "hull_volume_sum": float(model.body_mass[1]),
            "mesh_volume": shape.volume, "ratio": float(model.body_mass[1]) / shape.volume}


def model_xml(scene: scenes.Scene) -> tuple[str, dict]:
    mu = scenes.per_object(scene.mu, "max")
    zeta = damping_ratio_for_restitution(scene.e)
    solref = f"{TIMECONST} {zeta:.6f}"
    gx, gy, gz = scenes.vec_to_zup(scene.gravity)
    memory = max(16, 2 * len(scene.bodies) // 10 + 16)   # MB of the arena (contacts, solver)
    meshes = sorted({b.mesh for b in scene.bodies if b.shape == "mesh"})
    if meshes:
        memory = 1024
    lines = [
        '<mujoco model="peer">',
        f'  <option timestep="{TIME_STEP!r}" gravity="{gx!r} {gy!r} {gz!r}"/>',
        f'  <size memory="{memory}M"/>',
        f'  <default><geom friction="{mu} 0.005 0.0001" condim="3" solref="{solref}"/></default>',
    ]
    if meshes:
        lines.append("  <asset>")
        for m in meshes:
            shape = scenes.mesh_shape(m)
            for k, piece in enumerate(shape.pieces):
                pts = " ".join(f"{float(v):.17g}" for v in shape.principal(piece).ravel())
                lines.append(f'    <mesh name="{mesh_name(m)}_{k}" vertex="{pts}" inertia="convex"/>')
        lines.append("  </asset>")
    lines += [
        '  <worldbody>',
        f'    <geom name="ground" type="plane" size="0 0 1" pos="0 0 {scene.ground_height!r}"/>',
    ]
    for i, b in enumerate(scene.bodies):
        if b.shape == "mesh":
            shape = scenes.mesh_shape(b.mesh)
            com, q = scenes.principal_pose(b)
            pos = " ".join(f"{float(v)!r}" for v in scenes.vec_to_zup(com))
            quat = " ".join(f"{float(v)!r}" for v in scenes.quat_to_zup(q))
            inertia = " ".join(f"{float(v)!r}" for v in b.density * shape.moments)
            geoms = "".join(f'<geom type="mesh" mesh="{mesh_name(b.mesh)}_{k}"/>' for k in range(len(shape.pieces)))
            lines.append(f'    <body name="b{i}" pos="{pos}" quat="{quat}"><freejoint/>'
                         f'<inertial pos="0 0 0" mass="{b.mass!r}" diaginertia="{inertia}"/>{geoms}</body>')
            continue
        pos = " ".join(repr(float(v)) for v in scenes.vec_to_zup(b.position))
        quat = " ".join(repr(float(v)) for v in scenes.quat_to_zup(b.orientation))
        if b.shape == "box":
            geom = f'type="box" size="{0.5 * b.size[0]!r} {0.5 * b.size[1]!r} {0.5 * b.size[2]!r}"'
        else:
            geom = f'type="sphere" size="{b.radius!r}"'
        lines.append(f'    <body name="b{i}" pos="{pos}" quat="{quat}"><freejoint/>'
                     f'<geom {geom} mass="{b.mass!r}"/></body>')
    lines += ['  </worldbody>', '</mujoco>']
    settings = {
        "time_step": TIME_STEP, "steps_per_frame": STEPS_PER_FRAME, "integrator": "Euler (default)",
        "solver": "Newton (default)", "cone": "pyramidal (default)", "condim": 3,
        "friction_per_geom": mu, "combine": "max (MuJoCo)",
        "solref": [TIMECONST, zeta], "solref_note": ("damping ratio from e (linear spring-damper)"
                                                     if scene.e > 0 else "default (0.02 s, critically damped)"),
        "solimp": "default (0.9 0.95 0.001 0.5 2)", "arena_memory_mb": memory,
    }
    if meshes:
        settings["nonconvex_meshes"] = "several convex mesh geoms per body (scenes.py's exact decomposition)"
        settings["decomposition_check"] = {mesh_name(m): decomposition_check(m) for m in meshes}
        settings["inertia"] = "explicit <inertial>: mesh mass and principal moments"
        settings["multiccd"] = "on (default)"
    return "\n".join(lines), settings


def main() -> None:
    args = scenes.common_args()
    scene = scenes.build(args.scene, args.seconds)
    xml, settings = model_xml(scene)
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    mesh_scene = any(b.shape == "mesh" for b in scene.bodies)
    if mesh_scene:   # initial velocities: free joints take linear in the world, angular in the body
        for i, b in enumerate(scene.bodies):
            _, q = scenes.principal_pose(b)
            R = scenes.quaternion_matrices(np.array(scenes.quat_to_zup(q)))
            dof = model.jnt_dofadr[model.body_jntadr[i + 1]]
            data.qvel[dof:dof + 3] = scenes.vec_to_zup(b.linear_velocity)
            data.qvel[dof + 3:dof + 6] = R.T @ np.array(scenes.vec_to_zup(b.angular_velocity))
    mujoco.mj_forward(model, data)

    def centres():
        return scenes.positions_from_zup(data.xpos[1:].copy())

    def turns():
        return scenes.orientations_from_zup(data.xquat[1:].copy())

    if mesh_scene:   # principal frames -> the meshes' origins
        centres, turns = scenes.origin_pose_readers(scene, centres, turns)

    record = set(scene.recorded_frames())
    positions, orientations = [centres()], [turns()]
    clock = scenes.StepClock()
    max_contacts = 0
    for frame in range(1, scene.frames + 1):
        with clock:
            mujoco.mj_step(model, data, nstep=STEPS_PER_FRAME)
        max_contacts = max(max_contacts, int(data.ncon))
        if frame in record:
            positions.append(centres())
            orientations.append(turns())
    warnings = {str(mujoco.mjtWarning(i)).split(".")[-1]: int(w.number)
                for i, w in enumerate(data.warning) if w.number}
    print(json.dumps(scenes.result("mujoco", mujoco.__version__, scene, clock,
                                   np.array(positions), settings,
                                   {"max_contacts_at_frame_ends": max_contacts, "mujoco_warnings": warnings},
                                   np.array(orientations))))


if __name__ == "__main__":
    main()
