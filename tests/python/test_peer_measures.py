"""The peer benchmark's pose-only measures (benchmarks/peers/scenes.py): every engine's pile
penetration is read from its poses by this code, so it is checked here against answers
worked out by hand and against brute force."""

import math

import numpy as np
import pytest

from benchmarks.peers import scenes


def rotation_y(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def overlap(ca, Ra, ha, cb, Rb, hb):
    one = lambda a: np.asarray(a, float)[None]
    return float(scenes.box_overlap(one(ca), one(Ra), one(ha), one(cb), one(Rb), one(hb))[0])


def test_aligned_boxes_overlap_by_the_shorter_axis():
    h = np.full(3, 0.5)
    # unit cubes 0.9 apart in x and 0.2 in y: they overlap 0.1 in x, 0.8 in y, so 0.1
    assert overlap([0, 0, 0], np.eye(3), h, [0.9, 0.2, 0], np.eye(3), h) == pytest.approx(0.1, abs=1e-12)
    assert overlap([0, 0, 0], np.eye(3), h, [1.01, 0, 0], np.eye(3), h) == 0.0


def test_a_turned_box_corner_into_a_face():
    # a unit cube turned 45 degrees about y reaches sqrt(2)/2 along x; its edge 1.1 from the
    # other cube's centre enters that cube's face (at 0.5) by 0.5 + sqrt(2)/2 - 1.1
    h = np.full(3, 0.5)
    depth = overlap([0, 0, 0], np.eye(3), h, [1.1, 0, 0], rotation_y(math.pi / 4), h)
    assert depth == pytest.approx(0.5 + math.sqrt(0.5) - 1.1, abs=1e-12)
    # both turned alike and 1.4 apart along x: their edges cross by 2 sqrt(2)/2 - 1.4 along x,
    # but the shortest way apart is along their common face normal, 1 - 1.4 sqrt(2)/2
    depth = overlap([0, 0, 0], rotation_y(math.pi / 4), h, [1.4, 0, 0], rotation_y(math.pi / 4), h)
    assert depth == pytest.approx(1.0 - 1.4 * math.sqrt(0.5), abs=1e-12)


def test_separation_agrees_with_point_sampling():
    # random box pairs: where the measure says apart, no point of a fine grid of one box lies
    # in the other; where it says overlapping, some point does (the overlaps chosen > 2 cm)
    rng = np.random.default_rng(7)
    grid = np.stack(np.meshgrid(*[np.linspace(-1, 1, 21)] * 3, indexing="ij"), -1).reshape(-1, 3)
    checked = {"apart": 0, "overlapping": 0}
    for _ in range(200):
        q = rng.normal(size=(2, 4))
        R = scenes.quaternion_matrices(q)
        h = rng.uniform(0.2, 0.6, size=(2, 3))
        c = np.array([[0.0, 0.0, 0.0], rng.uniform(-1.2, 1.2, 3)])
        depth = overlap(c[0], R[0], h[0], c[1], R[1], h[1])
        points = c[0] + (grid * h[0]) @ R[0].T                          # inside box 0
        local = (points - c[1]) @ R[1]                                  # in box 1's frame
        inside = np.all(np.abs(local) <= h[1], axis=1).any()
        if depth == 0.0:
            assert not inside
            checked["apart"] += 1
        elif depth > 0.02:
            assert inside
            checked["overlapping"] += 1
    assert min(checked.values()) > 20


def test_close_pairs_are_the_brute_force_pairs():
    rng = np.random.default_rng(3)
    centres = rng.uniform(-3.0, 3.0, size=(400, 3))
    found = {tuple(p) for p in scenes.close_pairs(centres, 0.7)}
    d = np.linalg.norm(centres[:, None] - centres[None], axis=-1)
    expected = {(i, j) for i, j in zip(*np.nonzero(d < 0.7)) if i < j}
    assert found == expected and len(expected) > 100


def test_pile_penetration_of_a_resting_and_a_sunk_box():
    scene = scenes.Scene("pile_test", "two boxes", [scenes.Body("box", (0.5, 0.5, 0.5), (0, 0.25, 0)),
                                                    scenes.Body("box", (0.5, 0.5, 0.5), (0, 0.8, 0))],
                         1.0 / scenes.FPS, mu=0.5)
    q = np.tile([1.0, 0.0, 0.0, 0.0], (2, 2, 1))
    p = np.array([[[0, 0.25, 0], [0, 0.8, 0]],          # resting, 5 cm apart
                  [[0, 0.24, 0], [0, 0.72, 0]]])        # 1 cm into the ground, 2 cm into each other
    out = scenes.box_penetration(scene, p, q)
    assert out["penetration_ground_mm"] == pytest.approx(10.0, abs=1e-9)
    assert out["penetration_boxes_mm"] == pytest.approx(20.0, abs=1e-9)
    assert out["penetration_time"] == pytest.approx(1.0 / scenes.FPS)


def test_orientations_from_zup_match_the_scalar_conversion():
    rng = np.random.default_rng(11)
    q = rng.normal(size=(20, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    expected = np.array([scenes.quat_from_zup(tuple(v)) for v in q])
    assert np.allclose(scenes.orientations_from_zup(q), expected, atol=1e-15)
    # and a round trip through quat_to_zup
    back = scenes.orientations_from_zup(np.array([scenes.quat_to_zup(tuple(v)) for v in q]))
    assert np.allclose(back, q, atol=1e-15)
