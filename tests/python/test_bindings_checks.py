"""The bindings check every index and number before it reaches the core (issue 10).

The core trusts its callers; simbake._core is the boundary where Python's values come in.
A bad index must be IndexError and a bad number ValueError: never a segfault, never an
answer read from someone else's memory. Each call runs in this process: a crash here would
take the test run down with it, which is the failure these tests exist to catch.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from simbake import _core


def one_body_world() -> "_core.World":
    world = _core.World()
    vertices, _ = _core.box_mesh(np.array([1.0, 1.0, 1.0]), 1)
    world.add_body(shape=_core.LevelSet.box(np.array([1.0, 1.0, 1.0])), samples=vertices,
                   mass_properties=_core.box_mass_properties(np.array([1.0, 1.0, 1.0])), mass=1.0,
                   origin=np.zeros(3), orientation=np.array([1.0, 0.0, 0.0, 0.0]))
    return world


def one_cloth_world() -> "_core.World":
    world = _core.World()
    rest = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    world.add_cloth(rest=rest, triangles=np.array([[0, 2, 1]], dtype=np.int32))
    return world


BAD_INDICES = [1, 99, 10**6, -1, -5, 2**40]


@pytest.mark.parametrize("index", BAD_INDICES)
@pytest.mark.parametrize("method, world, what", [
    ("asleep", one_body_world, "body"),
    ("cloth_max_strain", one_cloth_world, "cloth"),
    ("cloth_state", one_cloth_world, "cloth"),
])
def test_index_out_of_range_is_index_error(method, world, what, index):
    with pytest.raises(IndexError, match=f"{what} index {index} out of range"):
        getattr(world(), method)(index)


def test_valid_indices_still_answer():
    world = one_body_world()
    assert world.asleep(0) is False
    assert world.body_states()["center_of_mass"].shape == (1, 3)
    cloth = one_cloth_world()
    assert cloth.cloth_max_strain(0) == pytest.approx(0.0, abs=1e-12)


def test_kinematic_track_index_is_checked():
    world = one_body_world()
    with pytest.raises(IndexError, match="body index"):
        world.set_kinematic_track(7, [0.0], np.zeros((1, 3)), np.array([[1.0, 0.0, 0.0, 0.0]]))


@pytest.mark.parametrize("dt", [-1.0, 0.0, math.nan, math.inf, -math.inf])
def test_step_needs_a_positive_finite_dt(dt):
    world = one_body_world()
    with pytest.raises(ValueError, match="dt must be a finite number > 0"):
        world.step(dt)
    with pytest.raises(ValueError, match="frame_dt"):
        world.step_frame(dt)
    with pytest.raises(ValueError, match="frame_dt"):
        world.automatic_substeps(dt)
    with pytest.raises(ValueError, match="frame_dt"):
        world.automatic_cloth_steps(dt)
    assert world.time == 0.0  # nothing was stepped


def test_step_frame_rejects_negative_substeps():
    world = one_body_world()
    with pytest.raises(ValueError, match="substeps must be >= 0"):
        world.step_frame(1 / 24, -5)
    assert world.time == 0.0
    assert world.step_frame(1 / 24, 2) == 2  # a good call still steps


@pytest.mark.parametrize("call", [
    lambda: _core.sphere_mesh(-1.0, 4),
    lambda: _core.sphere_mesh(math.nan, 4),
    lambda: _core.box_mesh(np.array([1.0, -1.0, 1.0]), 1),
    lambda: _core.sphere_mass_properties(math.inf),
    lambda: _core.box_mass_properties(np.array([0.0, 1.0, 1.0])),
    lambda: _core.LevelSet.sphere(0.0),
    lambda: _core.LevelSet.box(np.array([1.0, math.nan, 1.0])),
    lambda: _core.World(max_substep=math.nan),
    lambda: _core.World(travel_fraction=-1.0),
    lambda: _core.World(cloth_max_substep=0.0),
    lambda: _core.surface_samples(*_core.box_mesh(np.array([1.0, 1.0, 1.0]), 1), 1e-300),
    lambda: _core.surface_samples(*_core.box_mesh(np.array([1.0, 1.0, 1.0]), 1), math.nan),
])
def test_bad_numbers_are_value_errors(call):
    with pytest.raises(ValueError):
        call()


def test_random_arguments_never_crash():
    """A fixed-seed sample of hostile arguments to every method taking an index or a number:
    each call returns or raises IndexError/ValueError/TypeError (a crash ends the test run)."""
    import random

    rng = random.Random(10)
    ints = [0, 1, -1, 2, 99, -5, 10**6, 2**31, 2**40, -(2**63), 2**63 - 1]
    floats = [0.0, -0.0, 1.0, -1.0, 1e-309, 1e300, -1e300, math.nan, math.inf, -math.inf]
    body, cloth = one_body_world(), one_cloth_world()
    calls = [
        lambda w: w.asleep(rng.choice(ints)),
        lambda w: w.body_states(),
        lambda w: w.cloth_state(rng.choice(ints)),
        lambda w: w.cloth_max_strain(rng.choice(ints)),
        lambda w: w.step(rng.choice(floats)),
        lambda w: w.step_frame(rng.choice(floats), rng.choice(ints)),
        lambda w: w.automatic_substeps(rng.choice(floats)),
        lambda w: w.automatic_cloth_steps(rng.choice(floats)),
        lambda w: w.set_kinematic_track(rng.choice(ints), [rng.choice(floats)], np.zeros((1, 3)),
                                        np.array([[1.0, 0.0, 0.0, 0.0]])),
        lambda w: w.set_ground(height=rng.choice(floats), friction=rng.choice(floats),
                               restitution=rng.choice(floats)),
    ]
    outcomes = set()
    for _ in range(400):
        world = rng.choice([body, cloth])
        try:
            rng.choice(calls)(world)
            outcomes.add("ok")
        except (IndexError, ValueError, TypeError) as error:
            outcomes.add(type(error).__name__)
    assert {"ok", "IndexError", "ValueError", "TypeError"} <= outcomes


def test_body_mesh_is_checked():
    """A body's mesh (for its sharp edges against cloth) comes whole: both arrays, indices in range."""
    size = np.array([1.0, 1.0, 1.0])
    vertices, triangles = _core.box_mesh(size, 1)
    args = dict(shape=_core.LevelSet.box(size), samples=vertices, mass_properties=_core.box_mass_properties(size),
                mass=1.0, origin=np.zeros(3), orientation=np.array([1.0, 0.0, 0.0, 0.0]))
    with pytest.raises(ValueError, match="mesh_vertices and mesh_triangles"):
        _core.World().add_body(**args, mesh_vertices=vertices)
    with pytest.raises(ValueError):
        _core.World().add_body(**args, mesh_vertices=vertices, mesh_triangles=triangles + len(vertices))
    assert _core.World().add_body(**args, mesh_vertices=vertices, mesh_triangles=triangles) == 0


@pytest.mark.parametrize("threads", [-1, 1025, 65536, 100000, 2**31 - 1])
def test_threads_out_of_range_is_a_value_error(threads):
    """Issue 30: World(threads=100000).step_frame() crashed inside TBB. The core takes 0 (every
    CPU) to MAX_THREADS (1024), the cap `simbake bake --threads` has too."""
    assert _core.MAX_THREADS == 1024
    with pytest.raises(ValueError, match="threads must be in"):
        _core.World(threads=threads)
    with pytest.raises(ValueError, match="threads must be in"):
        _core.World(_core.WorldSettings(threads=threads))


@pytest.mark.parametrize("threads", [0, 1, 2, 1024])
def test_threads_in_range_step(threads):
    world = _core.World(threads=threads)
    world.add_body(shape=_core.LevelSet.sphere(0.5), samples=_core.sphere_mesh(0.5, 2)[0],
                   mass_properties=_core.sphere_mass_properties(0.5), mass=1.0, origin=np.array([0.0, 2.0, 0.0]))
    assert world.step_frame(1 / 24) >= 1
    assert world.settings.threads == threads


def test_settings_and_descriptions_take_their_fields_by_keyword():
    """Every field is a keyword; an unknown one is a TypeError naming it, and none is positional."""
    with pytest.raises(TypeError, match="WorldSettings has no field 'substep'"):
        _core.WorldSettings(substep=0.01)
    with pytest.raises(TypeError, match="ClothDesc has no field 'frictoin'"):
        _core.ClothDesc(frictoin=0.2)
    with pytest.raises(TypeError):
        _core.World(_core.WorldSettings(), threads=1)  # settings or its fields, not both
    with pytest.raises(TypeError):
        _core.GroundDef(0.0)
    world = _core.World(gravity=np.zeros(3), sleep_time=0.0)
    assert world.settings.sleep_time == 0.0
    world.settings.threads = 100000  # a copy: the world's own settings stay checked
    assert world.settings.threads == 0
    with pytest.raises(ValueError, match="unknown choice 'mesh'"):
        _core.ClothDesc(model="mesh")


# --------------------------------------------------------------------------------------------
# issue 30, 10: bounded work, and indices that cannot wrap
# --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("make", [_core.box_mesh, _core.sphere_mesh])
def test_mesh_subdivisions_are_bounded_before_anything_is_allocated(make):
    """`_core.box_mesh(v, 2**31-1)` allocated 3.4 GB instead of raising: at most 512
    subdivisions (3.1 million triangles)."""
    size = np.ones(3) if make is _core.box_mesh else 1.0
    for s in (0, 513, 2**31 - 1):
        with pytest.raises(ValueError, match=rf"subdivisions must be in \[1, 512\], got {s}"):
            make(size, s)
    vertices, triangles = make(size, 512)
    assert len(triangles) == 12 * 512 ** 2 and len(vertices) == 6 * 512 ** 2 + 2


def test_triangle_pair_search_refuses_quadratic_work_up_front():
    """`intersecting_triangle_pairs` on 100k random triangles never returned (~1e10 candidate
    pairs in a few cells): more than its budget of 2e8 candidate pairs is refused before any
    is tested, in well under a second."""
    import time

    rng = np.random.default_rng(30)
    vertices = rng.random((300_000, 3))
    triangles = np.arange(300_000, dtype=np.int32).reshape(-1, 3)
    start = time.monotonic()
    with pytest.raises(ValueError, match=r"candidate pairs, more than the budget of 200000000"):
        _core.intersecting_triangle_pairs(vertices, triangles)
    assert time.monotonic() - start < 5
    # an even sheet of the same count is near linear and answers
    n = 224  # 224 x 224 grid: 99,458 triangles
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="xy")
    grid = np.stack([i.ravel() / n, np.zeros(n * n), j.ravel() / n], axis=1)
    p = (j[:-1, :-1] * n + i[:-1, :-1]).ravel()
    sheet = np.concatenate([np.stack([p, p + n, p + n + 1], 1), np.stack([p, p + n + 1, p + 1], 1)]).astype(np.int32)
    assert _core.intersecting_triangle_pairs(grid, sheet).shape == (0, 2)


@pytest.mark.parametrize("triangles, words", [
    (np.array([[0, 1, 2**32 + 2]], dtype=np.int64), "triangle index 4294967298 does not fit in 32 bits"),
    (np.array([[0, 1, -(2**40)]], dtype=np.int64), "triangle index -1099511627776 does not fit in 32 bits"),
    (np.array([[0.0, 1.7, 2.2]]), "triangle indices must be integers, got an array of float64"),
])
def test_triangle_indices_never_wrap_or_truncate(triangles, words):
    """int64 triangle indices past 2^32 wrapped silently (2^32 + 2 became vertex 2), floats were
    truncated: every function taking triangles refuses them."""
    vertices = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    for call in (_core.vertex_normals, _core.is_closed, _core.mass_properties, _core.intersecting_triangle_pairs):
        with pytest.raises(ValueError, match=words):
            call(vertices, triangles)
    assert _core.vertex_normals(vertices, np.array([[0, 1, 2]], dtype=np.int64)).shape == (3, 3)
    assert _core.vertex_normals(vertices, np.zeros((0, 3))).shape == (3, 3)  # no triangles at all


def test_quality_of_a_crumpled_cloth_is_bounded_and_says_so():
    """The QA's self-intersection count has the triangle-pair budget too: a cloth of 100,000
    triangles crumpled into a 1 mm cube (~1e10 candidate pairs) answers at once with -1 (not
    counted), which the QA turns into a warning; an even sheet is counted (0)."""
    import time

    rng = np.random.default_rng(31)
    world = _core.World()
    world.add_cloth(rest=1e-3 * rng.random((300_000, 3)), triangles=np.arange(300_000, dtype=np.int32).reshape(-1, 3),
                    self_collision=False)
    start = time.monotonic()
    assert world.quality()["cloths"][0]["self_intersections"] == -1
    assert time.monotonic() - start < 30
    n = 16
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="xy")
    p = (j[:-1, :-1] * n + i[:-1, :-1]).ravel()
    sheet = np.concatenate([np.stack([p, p + n, p + n + 1], 1), np.stack([p, p + n + 1, p + 1], 1)]).astype(np.int32)
    world.add_cloth(rest=np.stack([i.ravel() / n, np.ones(n * n), j.ravel() / n], axis=1), triangles=sheet)
    assert world.quality()["cloths"][1]["self_intersections"] == 0
