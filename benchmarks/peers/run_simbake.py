"""simbake on one peer-benchmark scene; prints one JSON line.

    /work/main/.venv/bin/python benchmarks/peers/run_simbake.py SCENE [--seconds S]

Settings: the world's defaults (automatic substeps per 1/24 s frame: at most 1/120 s each,
1/240 s while a body may bounce, no body travels more than 0.2 of its thickness per substep;
speculative contacts, exact box-box contacts; 5 collision sweeps, up to 10 contact sweeps,
shock propagation), every body with the scene's mu and e (the core combines
friction by geometric mean and restitution by max, so the pair gets exactly mu and e).
Boxes: LevelSet.box and box_mesh(size, 4) samples; spheres: LevelSet.sphere and
sphere_mesh(r, 8) samples (as the pipeline's primitives). Only World.step_frame is timed.

pile_meshes (assets/scenes/pile.toml): the world is built by the pipeline itself, exactly as
`simbake bake assets/scenes/pile.toml` builds it (simbake.load_scene, simbake.assets.
load_assets: each mesh's level set at its automatic voxel size, its surface samples and its
mass properties; simbake.simulate.build_world), with threads=1, stepped with the scene's
[solver] substeps (0: automatic) as the bake does. The script checks that the pipeline's
scene is the benchmark's (every body's mesh, pose, velocities, density, friction).
"""

from __future__ import annotations

import datetime
import hashlib
import json
import math
import os

import numpy as np

import simbake
from benchmarks.peers import scenes
from simbake import _core

BOX_SUBDIVISIONS = 4
SPHERE_SUBDIVISIONS = 8


def build_world(scene: scenes.Scene, **settings) -> "_core.World":
    """The scene's world, with World settings (e.g. threads) on top of the defaults."""
    world = _core.World(gravity=np.array(scene.gravity, dtype=float), **settings)
    world.set_ground(height=scene.ground_height, friction=scenes.per_object(scene.mu, "geometric"),
                     restitution=0.0)
    shapes = {}   # one level set and sample set per distinct shape (the pile shares one)
    for b in scene.bodies:
        key = (b.shape, b.size)
        if key not in shapes:
            if b.shape == "box":
                size = np.array(b.size, dtype=float)
                shapes[key] = (_core.LevelSet.box(size), _core.box_mesh(size, BOX_SUBDIVISIONS)[0],
                               _core.box_mass_properties(size))
            else:
                shapes[key] = (_core.LevelSet.sphere(b.radius), _core.sphere_mesh(b.radius, SPHERE_SUBDIVISIONS)[0],
                               _core.sphere_mass_properties(b.radius))
        level_set, samples, mass_properties = shapes[key]
        world.add_body(shape=level_set, samples=samples, mass_properties=mass_properties, mass=b.mass,
                       origin=np.array(b.position, dtype=float),
                       orientation=np.array(b.orientation, dtype=float), linear_velocity=np.zeros(3),
                       angular_velocity=np.zeros(3), friction=scenes.per_object(scene.mu, "geometric"),
                       restitution=scene.e, kinematic=False)
    return world


def pipeline_world(scene: scenes.Scene):
    """The world `simbake bake` builds for the scene file (one thread), and the file's
    [solver] substeps; checks that the file is the benchmark's scene."""
    from simbake.assets import load_assets
    from simbake import load_scene
    from simbake.simulate import build_world as bake_world

    sim = load_scene(scenes.ROOT / scenes.MESH_PILE)
    assert len(sim.bodies) == len(scene.bodies), "body count"
    for a, b in zip(sim.bodies, scene.bodies):
        assert a.shape.kind == "mesh" and a.shape.mesh_path == (scenes.ROOT / b.mesh).resolve(), a.name
        assert (tuple(a.position), tuple(a.orientation), a.density, tuple(a.linear_velocity),
                tuple(a.angular_velocity)) == (b.position, b.orientation, b.density, b.linear_velocity,
                                                b.angular_velocity), a.name
        assert math.sqrt(a.friction * sim.ground.friction) == scene.mu and not a.kinematic, a.name
    assert tuple(sim.gravity) == scene.gravity and sim.ground.height == scene.ground_height
    assert (sim.end_frame - sim.start_frame) / sim.fps == scene.frames / scenes.FPS or scene.notes
    return bake_world(sim, load_assets(sim), threads=1), sim.substeps


def main() -> None:
    args = scenes.common_args()
    scene = scenes.build(args.scene, args.seconds)
    mesh_scene = any(b.shape == "mesh" for b in scene.bodies)
    if mesh_scene:
        world, scene_substeps = pipeline_world(scene)
    else:
        world, scene_substeps = build_world(scene), 0
    record = set(scene.recorded_frames())
    positions, orientations = [world.mesh_poses()[0].copy()], [world.mesh_poses()[1].copy()]  # centred meshes
    clock = scenes.StepClock()
    substeps = []
    for frame in range(1, scene.frames + 1):
        with clock:
            substeps.append(world.step_frame(1.0 / scenes.FPS, scene_substeps))
        if frame in record:
            translation, orientation = world.mesh_poses()
            positions.append(translation.copy())
            orientations.append(orientation.copy())
    stats = world.statistics()
    profile = {k: float(v) for k, v in world.profile().items()}
    settings = {
        "substeps": "automatic (step_frame(1/24, 0))",
        "substeps_per_frame_mean": float(np.mean(substeps)),
        "substeps_per_frame_max": int(max(substeps)),
        "friction_per_object": scenes.per_object(scene.mu, "geometric"),
        "restitution_body": scene.e, "restitution_ground": 0.0,
        "combine": "friction sqrt(a b), restitution max(a, b)",
        "box_samples": f"box_mesh(size, {BOX_SUBDIVISIONS})", "sphere_samples": f"sphere_mesh(r, {SPHERE_SUBDIVISIONS})",
    }
    if mesh_scene:
        settings = {
            "world": f"the pipeline's: load_scene({scenes.MESH_PILE}) + load_assets + simulate.build_world(threads=1)",
            "substeps": f"step_frame(1/24, {scene_substeps}) ({'automatic' if scene_substeps == 0 else 'the scene file'})",
            "substeps_per_frame_mean": float(np.mean(substeps)),
            "substeps_per_frame_max": int(max(substeps)),
            "friction": "per body 0.5 (simbake's default), ground 0.5: every pair sqrt(a b) = 0.5",
            "nonconvex_meshes": "level set of each mesh (automatic voxel size) + its surface samples; "
                                "mass properties of the closed mesh",
            "threads": 1,
        }
    with open(_core.__file__, "rb") as f:
        core_sha1 = hashlib.sha1(f.read()).hexdigest()[:12]
    extra = {"core_module": {"path": _core.__file__, "sha1": core_sha1,
                             "mtime": datetime.datetime.fromtimestamp(os.path.getmtime(_core.__file__),
                                                                      datetime.timezone.utc).isoformat(timespec="seconds")},
             "profile_seconds": profile,
             "profile_per_simulated_second": {k: v / (scene.frames / scenes.FPS) for k, v in profile.items()},
             "statistics": {k: (float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else v)
                            for k, v in stats.items()}}
    print(json.dumps(scenes.result("simbake", simbake.__version__, scene, clock,
                                   np.array(positions), settings, extra, np.array(orientations))))


if __name__ == "__main__":
    main()
