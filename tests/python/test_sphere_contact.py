"""Balls roll: a sphere's contact is its point nearest the other surface, not its vertices.

Known answers (rolling without slipping, no rolling resistance in the model):
- on level ground a ball set rolling keeps its speed (energy is conserved: nothing slips,
  nothing bounces); sampled at its vertices it would be a polyhedron, keeping 37% over 3 s;
- down a 20 degree slope (a kinematic box) a ball starting at rest accelerates at
  a = (5/7) g sin(theta) (a solid sphere, I = 2/5 m r^2; friction 0.5 is above the
  (2/7) tan(theta) = 0.10 that rolling needs), so it travels a t^2 / 2.
The tolerances are the contact's: its Baumgarte push and the substep (1/120 s) change speeds
by far less than 0.5%.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from simbake import _core

R = 0.2
G = 9.81


def _ball(world, origin, velocity=(0.0, 0.0, 0.0), spin=(0.0, 0.0, 0.0)):
    points, _ = _core.sphere_mesh(R, 8)
    return world.add_body(shape=_core.LevelSet.sphere(R), samples=points, mass=1.0,
                          mass_properties=_core.sphere_mass_properties(R), origin=np.array(origin, float),
                          linear_velocity=np.array(velocity, float), angular_velocity=np.array(spin, float),
                          friction=0.5, restitution=0.0)


def test_ball_rolling_on_the_ground_keeps_its_speed():
    world = _core.World(threads=1)
    world.set_ground(friction=0.5, restitution=0.0)
    ball = _ball(world, (0.0, R, 0.0), velocity=(1.0, 0.0, 0.0), spin=(0.0, 0.0, -1.0 / R))
    for _ in range(72):
        world.step_frame(1.0 / 24.0)
    state = world.body_states()
    assert state["linear_velocity"][ball] == pytest.approx([1.0, 0.0, 0.0], abs=5e-3)
    assert state["center_of_mass"][ball][1] == pytest.approx(R, abs=1e-3)


def test_ball_rolls_down_a_slope_at_five_sevenths_g_sin_theta():
    theta = math.radians(20.0)
    world = _core.World(threads=1)
    size = np.array([20.0, 1.0, 4.0])
    turn = np.array([math.cos(theta / 2), 0.0, 0.0, math.sin(theta / 2)])  # about +z: the slope falls towards -x
    down = np.array([-math.cos(theta), -math.sin(theta), 0.0])
    normal = np.array([-math.sin(theta), math.cos(theta), 0.0])
    world.add_body(shape=_core.LevelSet.box(size), samples=_core.box_mesh(size, 2)[0], mass=1.0,
                   mass_properties=_core.box_mass_properties(size), origin=np.zeros(3), orientation=turn,
                   friction=0.5, restitution=0.0, kinematic=True)
    start = (0.5 * size[1] + R) * normal + 3.0 * -down
    ball = _ball(world, start)
    seconds = 1.0
    for _ in range(24):
        world.step_frame(seconds / 24.0)
    state = world.body_states()
    a = (5.0 / 7.0) * G * math.sin(theta)
    assert state["linear_velocity"][ball] @ down == pytest.approx(a * seconds, rel=5e-3)
    steps = world.statistics()["substeps"]
    travelled = (state["center_of_mass"][ball] - start) @ down
    assert travelled == pytest.approx(0.5 * a * seconds ** 2 * (1.0 + 1.0 / steps), rel=5e-3)
    assert (state["center_of_mass"][ball] - start) @ normal == pytest.approx(0.0, abs=1e-3)  # on the slope
