"""The joints' automatic substeps (`joint_turn`) against what they keep of a chain's energy,
and where the ragdoll's step goes.

    .venv/bin/python benchmarks/rigid/joint_turn.py [--turns 0.05 0.1 0.2] [--seconds S]

Chains of 20, 50 and 80 links (0.1 m, 0.1 kg boxes with no shape, ball joints, the first to
the world at the origin: tests/cpp/rigid/test_joints.cpp's chain), released at rest lying at
0 or 0.5 rad above level, stepped in 24 fps frames at automatic substeps for 10 s, one
thread, at each `joint_turn`. An undriven chain keeps its energy: any rise above the start
is the solver's, and so is what it loses. Energy: benchmarks/peers/joint_scenes.py's measure
(kinetic and potential of the frames' states). Then assets/scenes/ragdoll.toml's world
(the pipeline's build_world) at the defaults, its stages' share of the step (World.profile()).
Writes benchmarks/results/joint_turn.md.
"""

from __future__ import annotations

import argparse
import platform
import subprocess
import time
from pathlib import Path

import numpy as np

from benchmarks.peers import joint_scenes
from simbake import _core

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "benchmarks" / "results" / "joint_turn.md"
CHAINS = [(20, 0.0), (20, 0.5), (50, 0.0), (50, 0.5), (80, 0.0), (80, 0.5)]
LENGTH, MASS, FPS = 0.1, 0.1, 24


def chain(links: int, tilt: float, turn: float):
    world = _core.World(threads=1, joint_turn=turn)
    bodies = []
    size = np.array((LENGTH, 0.02, 0.02))
    axis = np.array((np.cos(tilt), np.sin(tilt), 0.0))
    orientation = np.array((np.cos(tilt / 2), 0.0, 0.0, np.sin(tilt / 2)))
    for i in range(links):
        centre = (i + 0.5) * LENGTH * axis
        bodies.append(joint_scenes.Body(f"link{i}", "box", tuple(size), MASS, tuple(centre)))
        world.add_body(samples=_core.box_mesh(size, 1)[0], mass_properties=_core.box_mass_properties(size), mass=MASS,
                       origin=centre, orientation=orientation)
        world.add_joint(type="spherical", body0=i - 1, body1=i,
                        local_position0=np.array((0.0, 0.0, 0.0) if i == 0 else (0.5 * LENGTH, 0.0, 0.0)),
                        local_position1=np.array((-0.5 * LENGTH, 0.0, 0.0)))
    return world, joint_scenes.Scene("chain", "chain", bodies, [], 0.0)


def energy(world, scene) -> float:
    s = world.body_states()
    x, q = world.mesh_poses()
    return float(joint_scenes.energy(scene, x[None], q[None], s["linear_velocity"][None], s["angular_velocity"][None])[0])


def run_chain(links: int, tilt: float, turn: float, seconds: float) -> dict:
    world, scene = chain(links, tilt, turn)
    e0 = energy(world, scene)
    energies, cpu = [], 0.0
    for _ in range(int(round(seconds * FPS))):
        start = time.process_time()
        world.step_frame(1.0 / FPS, 0)
        cpu += time.process_time() - start
        energies.append(energy(world, scene))
    e = np.array(energies) - e0
    scale = MASS * links * joint_scenes.G * LENGTH * links / 2.0   # released hanging straight
    return {"substeps": int(world.statistics(penetrations=False)["substeps"]), "cpu_per_second": cpu / seconds,
            "rise": max(0.0, float(e.max())), "change": float(e[-1]), "scale": scale}


def ragdoll_shares() -> dict:
    import simbake
    from simbake.assets import load_assets
    from simbake.simulate import build_world

    scene = simbake.load_scene(joint_scenes.RAGDOLL)
    world = build_world(scene, load_assets(scene), threads=1)
    for _ in range(scene.frame_count - 1):
        world.step_frame(1.0 / scene.fps, 0)
    profile = world.profile()
    total = sum(profile.values())
    return {k: v / total for k, v in sorted(profile.items(), key=lambda kv: -kv[1]) if v / total >= 0.01}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--turns", type=float, nargs="+", default=[0.05, 0.1, 0.2])
    ap.add_argument("--seconds", type=float, default=10.0)
    args = ap.parse_args(argv)
    git = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    lines = ["# Joint substeps against a chain's energy", "",
             f"{platform.processor() or platform.machine()}, one thread; {time.strftime('%Y-%m-%d')}; git {git}.", "",
             "Reproduce: `.venv/bin/python benchmarks/rigid/joint_turn.py`", "",
             f"Chains released at rest for {args.seconds:g} s (24 fps frames, automatic substeps): substeps, CPU s per "
             "simulated s, the largest rise of the energy above the start and its change by the end, as a share of "
             "the energy released (the chain falling to hang straight).", "",
             "| links | tilt (rad) | joint_turn (rad) | substeps | CPU s/s | largest rise | change |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    for links, tilt in CHAINS:
        for turn in args.turns:
            r = run_chain(links, tilt, turn, args.seconds)
            row = (f"| {links} | {tilt:g} | {turn:g} | {r['substeps']} | {r['cpu_per_second']:.3f} | "
                   f"{r['rise']:.3g} J ({100 * r['rise'] / r['scale']:.2f}%) | {r['change']:.3g} J "
                   f"({100 * r['change'] / r['scale']:.1f}%) |")
            print(row, flush=True)
            lines.append(row)
    shares = ragdoll_shares()
    lines += ["", "assets/scenes/ragdoll.toml at the defaults, one thread: each stage's share of the step (1% or more): " +
              ", ".join(f"{k} {100 * v:.0f}%" for k, v in shares.items()) + "."]
    print(lines[-1])
    RESULTS.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
