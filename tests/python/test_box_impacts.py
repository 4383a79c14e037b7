"""Tilted boxes landing hard on a stack: how deep a falling box gets into the box it lands on.

A 0.5 m box tilted a few degrees falls at 7 m/s (a 2.5 m drop) onto a box resting on a fixed
one, as the upper layers of a falling pile do, the last steps before impact at several gaps.
Within a substep (1/120 s) it travels 58 mm; edge first, it turns about the edge it lands on
and its face closes on the box below within the same step. The overlap is measured
independently of the solver, by the separating-axis depth of the two boxes
(benchmarks.peers.scenes.box_overlap, the peer benchmark's measure), at every substep.
The worst of these cases goes 4.0 mm deep; with only the edge's point for an edge contact
(no face points behind it) it goes 13.9 mm. The bound, 6 mm, is well inside the 10 mm a pile
may reach (issue 35) and above the measured worst by half again for round-off in other builds.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from benchmarks.peers.scenes import box_overlap, quaternion_matrices
from simbake import _core

SIZE = 0.5
MASS = 125.0           # (kg) 1000 kg/m^3
SPEED = 7.0            # (m/s)
STEPS = 24             # (1/120 s each): the impact and the settling after it


def _quat(tilt_x: float, twist: float, tilt_z: float) -> np.ndarray:
    """(w, x, y, z) of the rotation by tilt_x about X, then twist about Y, then tilt_z about Z
    (degrees, axes fixed in the world)."""
    q = np.array([1.0, 0.0, 0.0, 0.0])
    for axis, angle in ((0, tilt_x), (1, twist), (2, tilt_z)):
        h = math.radians(angle) / 2.0
        r = np.array([math.cos(h), 0.0, 0.0, 0.0])
        r[1 + axis] = math.sin(h)
        w0, v0 = r[0], r[1:]
        w1, v1 = q[0], q[1:]
        q = np.concatenate([[w0 * w1 - v0 @ v1], w0 * v1 + w1 * v0 + np.cross(v0, v1)])
    return q


def _deepest_landing(tilt_x: float, tilt_z: float, twist: float, gap: float) -> float:
    world = _core.World(threads=1)
    world.set_ground(friction=0.5, restitution=0.0)
    size = np.full(3, SIZE)
    shape, samples, mass_properties = (_core.LevelSet.box(size), _core.box_mesh(size, 4)[0],
                                       _core.box_mass_properties(size))
    q = _quat(tilt_x, twist, tilt_z)
    lowest = (np.abs(quaternion_matrices(q[None])[0][1, :]) * SIZE / 2).sum()  # centre above its lowest corner
    bodies = [((0.0, 0.25, 0.0), (1.0, 0.0, 0.0, 0.0), 0.0, True),            # fixed
              ((0.0, 0.75, 0.0), (1.0, 0.0, 0.0, 0.0), 0.0, False),           # resting on it
              ((0.02, 1.0 + lowest + gap, 0.01), tuple(q), SPEED, False)]     # falling onto that
    for origin, orientation, speed, kinematic in bodies:
        world.add_body(shape=shape, samples=samples, mass_properties=mass_properties, mass=MASS,
                       origin=np.array(origin), orientation=np.array(orientation),
                       linear_velocity=np.array([0.0, -speed, 0.0]), friction=0.5, restitution=0.0,
                       kinematic=kinematic)
    half = np.full((1, 3), SIZE / 2)
    deepest = 0.0
    for _ in range(STEPS):
        world.step_frame(1.0 / 120.0)
        state = world.body_states()
        R = quaternion_matrices(state["orientation"])
        p = state["center_of_mass"]
        deepest = max(deepest, float(box_overlap(p[1:2], R[1:2], half, p[2:3], R[2:3], half)[0]))
    return deepest


def test_tilted_box_landing_hard_stays_out_of_the_box_below():
    cases = list(itertools.product([4.0, 8.0, 12.0], [3.0, 7.0], [0.0, 30.0], [0.01, 0.03, 0.05]))
    depths = {case: _deepest_landing(*case) for case in cases}
    worst = max(depths, key=depths.get)
    assert depths[worst] < 6e-3, f"{1000 * depths[worst]:.1f} mm deep (tilts, twist, gap {worst})"
