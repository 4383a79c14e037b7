"""Every shipped cloth scene, baked and read back from its cache: no layer through another,
and ready to render.

At every written frame the cache is checked apart from the core by
benchmarks/cloth/render_ready.py (its docstring has the details): the cloth's triangles
against each other (layers through layers, by benchmarks/cloth/crossings.py); the strain
within the cloth's strain limit + 1% of it; no cloth edge deeper than 0.5 mm in the ground or
a body (analytic bodies by their exact distance, mesh bodies by their own triangles as
written in the cache); no body edge through the cloth.

Every scene is baked over its whole frame range: a failure can come late (cloth_demo's ring
went through the sheet at frames 87 and 95-97 of 97, when this test baked only the first 2 s),
and the whole set bakes in about 4 minutes on this machine class. SIMBAKE_RENDER_READY_FRAMES=N
bakes only each scene's first N frames, for a quicker look (49: its first 2 s):

    SIMBAKE_RENDER_READY_FRAMES=49 .venv/bin/python -m pytest tests/python/test_cloth_render_ready.py
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np
import pytest

import simbake
from benchmarks.cloth.crossings import crossing_count
from benchmarks.cloth.render_ready import (DEEPEST_INSIDE, MESSAGES, analytic_distance, box_edges, edge_samples,
                                           inside_mesh, largest_strain, mesh_depth, mesh_edges, render_ready_failures,
                                           segments_through_mesh, triangle_distance, winding_number)
from conftest import REPO
from simbake.scene import Shape

CLOTH_SCENES = ["drape", "flag", "tablecloth", "cape_on_mover", "cloth_demo", "heap", "towel_on_rod", "box_plow"]
FRAMES = int(os.environ.get("SIMBAKE_RENDER_READY_FRAMES", "0"))  # 0: every frame of the scene
# (scene, check) pairs that fail today, each a limitation in the README: the test then
# reports them as an expected failure (with the frames and figures) instead of passing;
# layers through layers are never excused
KNOWN_GAPS: set = set()


def test_the_body_checks_find_what_they_look_for():
    # a flat 1 m sheet at y = 0: a box with a corner 1 cm through it near the middle, a sphere 2 mm
    # into it from below, and the sheet stretched 5% one way
    from simbake.assets import grid_mesh

    points, triangles = grid_mesh((1.0, 1.0), (11, 11))
    edges = mesh_edges(triangles)
    rest = np.linalg.norm(points[edges[:, 1]] - points[edges[:, 0]], axis=1)
    assert abs(largest_strain(points, edges, rest)) < 1e-12
    stretched = points * np.array([1.05, 1.0, 1.0])
    assert abs(largest_strain(stretched, edges, rest) - 0.05) < 1e-12
    # a 10 cm box turned so that a corner points down, its corner at y = -0.01 under (0.03, 0.04)
    tilt = np.arccos(1 / np.sqrt(3))
    axis = np.array([1.0, 0.0, -1.0]) / np.sqrt(2)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    R = np.eye(3) + np.sin(tilt) * K + (1 - np.cos(tilt)) * K @ K   # takes (1, 1, 1)/sqrt(3) to +y
    segs = box_edges((0.1, 0.1, 0.1)) @ R.T
    segs += np.array([0.03, -0.01, 0.04]) - segs.reshape(-1, 3)[np.argmin(segs.reshape(-1, 3)[:, 1])]
    assert segments_through_mesh(segs, points, triangles) == 3   # the corner's three edges
    segs += np.array([0.0, -0.2, 0.0])
    assert segments_through_mesh(segs, points, triangles) == 0   # all of it below the sheet
    sphere = Shape(kind="sphere", radius=0.2)
    depth = -analytic_distance(sphere, edge_samples(points, edges) - np.array([0.0, -0.198, 0.0])).min()
    assert abs(depth - 0.002) < 1e-12
    box = Shape(kind="box", size=(0.4, 0.4, 0.4))
    assert abs(analytic_distance(box, np.array([[0.0, 0.19, 0.0], [0.3, 0.3, 0.2]]))
               - [-0.01, np.sqrt(0.02)]).max() < 1e-12


def test_the_mesh_body_checks_find_what_they_look_for():
    # a unit cube as a closed triangle mesh (outward), against the box's exact distance
    from simbake import _core

    points, triangles = _core.box_mesh(np.array([1.0, 1.0, 1.0]), 2)
    corners = np.asarray(points)[np.asarray(triangles).reshape(-1, 3)]
    probes = np.array([[0.0, 0.0, 0.0], [0.45, 0.1, -0.2], [0.2, 0.3, 0.499], [0.7, 0.0, 0.0], [0.6, 0.6, 0.6]])
    assert np.allclose(winding_number(probes, corners), [1, 1, 1, 0, 0], atol=1e-9)
    exact = np.abs(analytic_distance(Shape(kind="box", size=(1.0, 1.0, 1.0)), probes))
    assert np.allclose(triangle_distance(probes, corners), exact, atol=1e-12)
    assert abs(mesh_depth(probes, corners) - 0.5) < 1e-12            # the centre, half a side deep
    assert mesh_depth(probes[3:], corners) == 0.0                     # outside: none


def test_ray_parity_agrees_with_winding_numbers():
    # the shipped torus, and points around and through it: inside by the rays' parity exactly
    # where the winding number (an independent formula) says so
    import trimesh

    torus = trimesh.load(REPO / "assets" / "meshes" / "torus.obj")
    corners = np.asarray(torus.vertices)[np.asarray(torus.faces)]
    rng = np.random.default_rng(4)
    lo, hi = corners.min(axis=(0, 1)), corners.max(axis=(0, 1))
    probes = rng.uniform(lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo), size=(4000, 3))
    winding = winding_number(probes, corners)
    clear = np.abs(winding - 0.5) > 0.25   # away from the surface, where the formula is exact
    assert clear.mean() > 0.99 and 200 < (winding > 0.5).sum() < 3800
    assert np.array_equal(inside_mesh(probes, corners)[clear], (winding > 0.5)[clear])


def test_the_check_finds_crossings():
    # a flat grid and the same grid with its far half folded back through the near half
    from simbake.assets import grid_mesh

    points, triangles = grid_mesh((1.0, 1.0), (11, 11))
    assert crossing_count(points, triangles) == 0
    folded = points.copy()
    far = folded[:, 2] > 0.05
    folded[far, 1] = 0.3 * folded[far, 2] * np.sin(7 * folded[far, 0])
    folded[far, 2] = -folded[far, 2] + 0.1 * np.cos(5 * folded[far, 0])
    count = crossing_count(folded, triangles)
    assert count > 10
    from simbake import _core

    assert count == len(_core.intersecting_triangle_pairs(folded, triangles.astype(np.int32)))


@pytest.mark.parametrize("name", CLOTH_SCENES)
def test_shipped_cloth_is_render_ready(name, tmp_path):
    scene = simbake.load_scene(REPO / "assets" / "scenes" / f"{name}.toml")
    if FRAMES > 0:
        scene = dataclasses.replace(scene, end_frame=min(scene.end_frame, scene.start_frame + FRAMES - 1))
    stats = simbake.bake(scene, tmp_path / f"{name}.usdc")
    crossings, found = render_ready_failures(scene, stats.output)
    assert not crossings, f"crossing triangle pairs at (cloth, frame): {crossings}"
    failed = {check: (found[check], message) for check, message in MESSAGES.items()}
    known = [f"{message}: {hits}" for check, (hits, message) in failed.items()
             if hits and (name, check) in KNOWN_GAPS]
    unexpected = [f"{check}: {message}: {hits}" for check, (hits, message) in failed.items()
                  if hits and (name, check) not in KNOWN_GAPS]
    assert not unexpected, "; ".join(unexpected)
    if known:
        pytest.xfail("known gap (README, limitations): " + "; ".join(known))


def test_the_heap_stays_out_of_the_ground_at_every_step():
    # the checks above see written frames only; the heap (no bodies: one cloth step a
    # substep) is stepped here one cloth step at a time through its landing, and no vertex may
    # end a step deeper than 0.5 mm under the ground. Before the collision impulses and the
    # impact zones respected the ground under a vertex, steps between frames ended up to
    # 5.4 mm under it (frame 19 itself at 1.08 mm)
    from simbake import simulate
    from simbake.assets import load_assets, load_cloth

    scene = simbake.load_scene(REPO / "assets" / "scenes" / "heap.toml")
    assert not scene.bodies and scene.ground is not None
    world = simulate.build_world(scene, load_assets(scene), [load_cloth(scene, 0)])
    frame_dt = 1.0 / scene.fps
    substeps = world.automatic_substeps(frame_dt)
    assert world.automatic_cloth_steps(frame_dt) == substeps
    deepest = []
    for _ in range(30):
        for _ in range(substeps):
            world.step(frame_dt / substeps)
            deepest.append(scene.ground.height - world.cloth_state(0)[0][:, 1].min())
    assert world.statistics()["impact_zone_rounds"] > 0   # the landing needed impact zones
    assert max(deepest) > -0.01                                     # and it reached the ground
    assert max(deepest) <= DEEPEST_INSIDE, f"deepest under the ground {1000 * max(deepest):.2f} mm at step {int(np.argmax(deepest))}"
