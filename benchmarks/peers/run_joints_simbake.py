"""simbake on one joint scene of the peer benchmark; prints one JSON line.

    .venv/bin/python benchmarks/peers/run_joints_simbake.py chain50|ragdoll [--seconds S] [--substeps N]

Settings: the world's defaults, one thread, stepped frame by frame (1/24 s) with automatic
substeps, as a bake steps it (--substeps N: N per frame instead; N = 10 is the peers' 240 Hz). chain50: the world of tests/cpp/rigid/test_joints.cpp's
FiftyLinkChainStaysClosed (links with no shape: nothing collides), built with the bindings;
ragdoll: the pipeline's own world for assets/scenes/ragdoll.toml (simbake.load_scene,
load_assets, simulate.build_world). Only World.step_frame is timed.
"""

from __future__ import annotations

import json

import numpy as np

import simbake
from benchmarks.peers import joint_scenes
from simbake import _core


def chain_world(scene: joint_scenes.Scene) -> "_core.World":
    world = _core.World(threads=1)
    for b in scene.bodies:
        size = np.array(b.size)  # (samples as the C++ test's box_body; no shape: never collides)
        world.add_body(samples=_core.box_mesh(size, 1)[0], mass_properties=_core.box_mass_properties(size), mass=b.mass,
                       origin=np.array(b.position), orientation=np.array(b.orientation))
    for j in scene.joints:
        world.add_joint(type="spherical", body0=j.body0, body1=j.body1, local_position0=np.array(j.local_position0),
                        local_position1=np.array(j.local_position1))
    return world


def ragdoll_world(scene: joint_scenes.Scene, seconds: float) -> "_core.World":
    from simbake.assets import load_assets
    from simbake.simulate import build_world

    sim = simbake.load_scene(joint_scenes.RAGDOLL)
    assert [b.name for b in sim.bodies] == [b.name for b in scene.bodies]
    return build_world(sim, load_assets(sim), threads=1)


def main(argv=None) -> None:
    import argparse
    ap = argparse.ArgumentParser()
    ap.add_argument("scene", choices=list(joint_scenes.SCENES))
    ap.add_argument("--seconds", type=float, default=None)
    ap.add_argument("--substeps", type=int, default=0, help="per frame (default 0: automatic)")
    args = ap.parse_args(argv)
    scene = joint_scenes.build(args.scene, args.seconds)
    world = chain_world(scene) if scene.name == "chain50" else ragdoll_world(scene, scene.seconds)
    recorder = joint_scenes.Recorder(scene)

    def record(frame):
        s = world.body_states()
        x, q = world.mesh_poses()
        recorder.record(frame, x, q, s["linear_velocity"], s["angular_velocity"])

    record(0)
    clock = joint_scenes.Clock()
    for frame in range(1, scene.frames + 1):
        with clock:
            world.step_frame(1.0 / joint_scenes.FPS, args.substeps)
        record(frame)
    out = joint_scenes.result("simbake", simbake.__version__, scene, clock, recorder,
                              {"threads": 1, "substeps": args.substeps or "automatic", "steps_taken": world.statistics()["substeps"]})
    print(json.dumps(out))


if __name__ == "__main__":
    main()
