"""The shipped joint scenes behave as physics says: the ragdoll down the stairs
(assets/scenes/ragdoll.toml) never explodes, keeps its joints closed and within their limits
and comes to rest on the lower steps; the flywheel (assets/scenes/wheel.toml) spins up at the
acceleration its drive's torque limit gives and then turns at the drive's target speed.

Every figure is measured here from the bodies' poses and velocities (joint frames placed with
numpy, benchmarks/peers/joint_scenes.py), never from the solver's own joint error."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import simbake
from benchmarks.peers import joint_scenes
from simbake.assets import load_assets
from simbake.simulate import build_world

REPO = Path(__file__).resolve().parents[2]
SCENES = REPO / "assets" / "scenes"
G = 9.81


def _run(scene, record=lambda world: None):
    """Steps a scene's world frame by frame (one thread, automatic substeps, as a bake does);
    returns every frame's (centres, orientations, velocities, angular velocities), frame 0
    the start."""
    world = build_world(scene, load_assets(scene), threads=1)
    frames = []

    def state():
        s = world.body_states()
        x, q = world.mesh_poses()
        frames.append((x.copy(), q.copy(), s["linear_velocity"].copy(), s["angular_velocity"].copy()))
        record(world)

    state()
    for _ in range(scene.end_frame - scene.start_frame):
        world.step_frame(1.0 / scene.fps)
        state()
    return [np.array(a) for a in zip(*frames)]


@pytest.fixture(scope="module")
def ragdoll():
    scene = simbake.load_scene(SCENES / "ragdoll.toml")
    x, q, v, w = _run(scene)
    return scene, joint_scenes.ragdoll(), x, q, v, w


def test_ragdoll_is_the_benchmark_ragdoll(ragdoll):
    scene, bench, x, q, v, w = ragdoll
    assert len(scene.bodies) == len(bench.bodies) == 21 and len(scene.joints) == len(bench.joints) == 14
    assert sum(not b.kinematic for b in scene.bodies) == 15
    assert {j.type for j in scene.joints} == {"d6", "revolute"}
    # (boxes and a sphere: the mesh origin is the centre of mass, so poses are the bodies')
    assert np.allclose(x[0], [b.position for b in scene.bodies])


def test_ragdoll_never_explodes(ragdoll):
    """No body faster than the fall allows. Energy first (exact): the figure never gains any
    (inelastic contacts and the joints' damping only take it away; at most 0.1% of m g h above
    its start, measured 0), so no body's kinetic energy can exceed what the whole figure has
    released, E0 - PE(t) (measured at most 21% of it). Speed then: each body's centre at most
    2 sqrt(v0^2 + 2 g (H - y)), v0 = 1.2 m/s the push, H the figure's highest centre at the
    start (its head) and y the body's height: free fall from the top, with room for a figure
    toppling about its feet (a rod falling about one end moves its top at sqrt(3/2) = 1.22x
    free fall) whose legs are then stopped by a step while the rest swings on about the hips
    (its momentum carried by less mass); measured 1.51x (the head, 10.3 m/s, as the legs hit
    the first steps). The bound allows 15 m/s at the bottom; an explosion is far beyond it."""
    scene, bench, x, q, v, w = ragdoll
    moving = bench.moving()
    assert np.isfinite(x).all() and np.isfinite(v).all()
    e = joint_scenes.energy(bench, x, q, v, w)
    masses = np.array([bench.bodies[i].mass for i in moving])
    assert (e - e[0]).max() <= 1e-3 * masses.sum() * G * 1.2
    speed = np.linalg.norm(v[:, moving], axis=-1)
    released = e[0] - G * (masses * x[:, moving, 1]).sum(-1)
    assert (0.5 * masses * speed ** 2 <= released[:, None] + 1e-9).all()
    top = x[0, moving, 1].max()
    allowed = np.sqrt(1.2 ** 2 + 2.0 * G * (top - x[:, moving, 1]).clip(0.0))
    assert (speed <= 2.0 * allowed).all(), f"worst ratio {(speed / allowed).max():.3f}"
    assert speed.max() > 5.0  # (it did fall down the stairs)


def test_ragdoll_joints_closed_and_within_limits(ragdoll):
    """Every joint's frames within 1 um of each other at every frame: a thousandth of the QA's
    1 mm joint-error warning, four orders above what is measured (1e-10 m: the joints'
    Newton solve stops at 1e-10); a joint the solver lets open for one step (a gap of
    centimetres) fails it. No twist, swing cone or hinge passed by more than 0.5 degree (the
    issue's bound for hinge limits), the hinges' axes kept aligned as well."""
    scene, bench, x, q, v, w = ragdoll
    gaps, past = joint_scenes.joint_measures(bench, x, q)
    assert gaps.max() < 1e-6
    assert np.degrees(past.max()) < 0.5
    # (the limits are reached: the figure is not just hanging loose inside them)
    R = joint_scenes.matrices(q)
    knee = next(k for k, j in enumerate(bench.joints) if j.name == "knee_l")
    j = bench.joints[knee]
    rel = np.swapaxes(R[:, j.body0], -1, -2) @ R[:, j.body1]
    bend = np.arctan2(rel[:, 1, 0] - rel[:, 0, 1], rel[:, 0, 0] + rel[:, 1, 1])
    assert bend.min() < -0.2 and bend.max() < 0.5 * math.pi / 180.0


def test_ragdoll_rests_on_the_lower_steps(ragdoll):
    """Over its last second every body moves slower than 0.1 m/s (from a peak of 10 m/s; see
    README Limitations: jointed bodies lying across the stairs' edges creep at up to 3 cm/s,
    they do not fall asleep), its energy is within 1% of m g h of its end value, every body
    has left the landing (x > 0) and is below the first step's top (1.0 m); the trunk lies on
    the lower steps or the ground beyond them (x > 1.05 m: past the third step)."""
    scene, bench, x, q, v, w = ragdoll
    moving = bench.moving()
    last = slice(-25, None)
    assert np.linalg.norm(v[last][:, moving], axis=-1).max() < 0.1
    e = joint_scenes.energy(bench, x, q, v, w)
    mass = sum(b.mass for b in bench.bodies)
    assert np.ptp(e[last]) < 0.01 * mass * G * 1.2
    assert (x[-1, moving, 0] > 0.0).all() and (x[-1, moving, 1] < 1.0).all()
    names = [b.name for b in scene.bodies]
    for part in ("pelvis", "abdomen", "belly", "chest", "head"):
        assert x[-1, names.index(part), 0] > 1.05, part
    assert (x[:, moving, 1] > 0.0).all()  # (nothing through the ground)


def test_ragdoll_lands_on_the_stairs_not_in_them(ragdoll):
    """Every box of the figure against every step (exact box-box overlap, the separating axes,
    benchmarks/peers/scenes.box_overlap) at every frame: less than 15 mm deep, and no two
    parts not jointed together overlap by more than 5 mm (the QA's bound). Measured: 7.9 mm
    (the pelvis resting on the last step: joints solved after the contacts push resting
    jointed bodies in, README Limitations; the QA warns of it), parts 0 mm."""
    from benchmarks.peers.scenes import box_overlap

    scene, bench, x, q, v, w = ragdoll
    R = joint_scenes.matrices(q)
    boxes = [i for i, b in enumerate(bench.bodies) if b.shape == "box"]

    def depth(a, b):
        half = [np.broadcast_to(np.array(bench.bodies[i].size) / 2, (len(x), 3)) for i in (a, b)]
        return box_overlap(x[:, a], R[:, a], half[0], x[:, b], R[:, b], half[1]).max()

    steps = [i for i in boxes if bench.bodies[i].kinematic]
    parts = [i for i in boxes if not bench.bodies[i].kinematic]
    assert max(depth(a, b) for a in parts for b in steps) < 0.015
    joined = {frozenset((j.body0, j.body1)) for j in bench.joints}
    assert max(depth(a, b) for a in parts for b in parts if a < b and frozenset((a, b)) not in joined) < 0.005


# The flywheel: a regular 24-gon prism (circumradius 0.4 m, 20 kg) and a 0.76 x 0.06 x 0.12 m
# bar (2 kg) glued across it, on a hinge about z, driven towards 0.8 pi rad/s at most 4 N m
SIDES, RADIUS, WHEEL_M, BAR, BAR_M, TORQUE, TARGET = 24, 0.4, 20.0, (0.76, 0.06, 0.12), 2.0, 4.0, 0.8 * math.pi


@pytest.fixture(scope="module")
def flywheel():
    scene = simbake.load_scene(SCENES / "wheel.toml")
    return scene, _run(scene)


def _spin(scene, w):
    names = [b.name for b in scene.bodies]
    return w[:, names.index("wheel"), 2] - w[:, names.index("stand"), 2], names


def test_flywheel_spins_up_at_the_drives_torque_limit(flywheel):
    """Below its target the drive gives its whole 4 N m: the wheel turns up at T / I, I about
    the axle from the shapes by hand: the 24-gon prism's J = m R^2 (2 + cos(2 pi / 24)) / 6
    (each of its triangles from the centre: A (2 R^2 + R^2 cos a) / 6), the bar's
    m (a^2 + b^2) / 12. alpha = 2.383 rad/s^2 within 0.5%, from the frames whose speed is
    between 10% and 90% of the target; the bar turns with it."""
    scene, (x, q, v, w) = flywheel
    spin, names = _spin(scene, w)
    inertia = (WHEEL_M * RADIUS ** 2 * (2.0 + math.cos(2.0 * math.pi / SIDES)) / 6.0
               + BAR_M * (BAR[0] ** 2 + BAR[1] ** 2) / 12.0)
    expected = TORQUE / inertia
    t = np.arange(len(spin)) / scene.fps
    ramp = (spin > 0.1 * TARGET) & (spin < 0.9 * TARGET)
    assert ramp.sum() >= 10
    slope, _ = np.polyfit(t[ramp], spin[ramp], 1)
    assert slope == pytest.approx(expected, rel=0.005)
    assert np.allclose(w[:, names.index("bar")], w[:, names.index("wheel")], atol=1e-6)


def test_flywheel_drive_holds_target_velocity(flywheel):
    """Once there (at 1.05 s by the same figures), the drive holds 0.4 turn a second within
    1% (the issue's bound) to the end, the axle stays put (within 0.1 mm of the stand's
    point: the hinge's gap) and the wheel's axis stays along z."""
    scene, (x, q, v, w) = flywheel
    spin, names = _spin(scene, w)
    late = slice(int(1.3 * scene.fps), None)
    assert np.abs(spin[late] / TARGET - 1.0).max() < 0.01
    wheel = names.index("wheel")
    assert np.linalg.norm(x[:, wheel] - [0.0, 0.6, 0.0], axis=-1).max() < 1e-4
    assert np.abs(w[:, wheel, :2]).max() < 1e-6
