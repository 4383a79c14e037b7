"""QA motion figures (simbake.qa_motion; issue 30, items 16-18): energy the solver made up, a
body stopping in mid-air, a body launched by a keyed one; and the substeps figure only where
it means something. Each scene is the issue's repro; each warning is checked against the
quantity it names, from the cache or the scene, not from the QA itself.
"""

from __future__ import annotations

import json
import textwrap
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import simbake
import simbake.simulate
from pxr import Usd, UsdGeom

from test_cli import simbake as run

STOPS_IN_MID_AIR = """
    [scene]
    end_frame = 12
    [solver]
    substeps = 1
    [ground]
    [[bodies]]
    name = "box"
    shape = { type = "box", size = [0.4, 0.4, 0.4] }
    position = [0.0, 10.0, 0.0]
    linear_velocity = [0.0, -200.0, 0.0]
"""

# a keyed bat that jumps 2 km between two frames (1000 m to each side of the box at 24 fps)
KEY_JUMP = """
    [scene]
    end_frame = 24
    [ground]
    [[bodies]]
    name = "box"
    shape = { type = "box", size = [0.4, 0.4, 0.4] }
    position = [0.0, 0.2, 0.0]
    [[bodies]]
    name = "bat"
    shape = { type = "box", size = [0.5, 0.5, 0.5] }
    kinematic = true
    position = [-1000.0, 0.3, 0.0]
    keys = [{ time = 0.0 }, { time = 0.25 }, { time = 0.2917, position = [1000.0, 0.3, 0.0] }]
"""

FIXED_AT_THE_CAP = """
    [scene]
    end_frame = 3
    [solver]
    substeps = 4096
    [ground]
    [[bodies]]
    name = "box"
    shape = { type = "box", size = [0.4, 0.4, 0.4] }
    position = [0.0, 1.0, 0.0]
"""


def bake(tmp_path: Path, text: str) -> tuple[list[str], dict, Path]:
    (tmp_path / "scene.toml").write_text(textwrap.dedent(text))
    result = run("bake", "scene.toml", "-o", "out.usdc", "-q", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    qa = json.loads((tmp_path / "out.qa.json").read_text())
    return result.stderr.splitlines(), qa, tmp_path / "out.usdc"


def heights(cache: Path, prim: str) -> np.ndarray:
    stage = Usd.Stage.Open(str(cache))
    xf = UsdGeom.Xformable(stage.GetPrimAtPath(prim))
    frames = range(int(stage.GetStartTimeCode()), int(stage.GetEndTimeCode()) + 1)
    return np.array([xf.ComputeLocalToWorldTransform(f).ExtractTranslation()[1] for f in frames])


def test_a_box_stopping_in_mid_air_is_a_warning(tmp_path):
    """Issue 30, 17: with `substeps = 1` a box at 200 m/s stopped dead 4.7 m above the ground,
    then fell; no QA warning."""
    lines, qa, cache = bake(tmp_path, STOPS_IN_MID_AIR)
    y = heights(cache, "/World/box")
    stopped = int(np.argmax(np.abs(np.diff(y)) < 1.0)) + 1  # the first frame it barely moved
    assert y[stopped] - 0.2 > 1.0  # the cache shows it: clear of the ground by over a metre
    (line,) = [l for l in lines if "stopped in mid-air" in l]
    assert line.startswith("simbake: warning: QA: ") and "(box)" in line and f"at frame {stopped + 1}" in line
    lost = qa["figures"]["unexplained_stop"][stopped]
    assert lost == pytest.approx(200.0, rel=0.05)  # it lost nearly all its 200 m/s


def test_a_keyed_body_launching_a_box_is_a_warning(tmp_path):
    """Issue 30, 17: a keyed body that jumps 1 km between frames launched a box at 25 km/s with
    only a substep warning."""
    lines, qa, cache = bake(tmp_path, KEY_JUMP)
    stage = Usd.Stage.Open(str(cache))
    translate = stage.GetPrimAtPath("/World/box").GetAttribute("xformOp:translate")
    x = np.array([translate.Get(f)[0] for f in range(1, 25)])
    speed = np.abs(np.diff(x)).max() * 24  # from the cache: far beyond 100 m/s
    assert speed > 1000
    (line,) = [l for l in lines if "a keyed body launched it" in l]
    assert "(box)" in line and "over 100 m/s" in line
    assert max(qa["figures"]["imparted_speed"]) > 1000


def test_a_fixed_substep_count_at_the_cap_is_not_a_warning(tmp_path):
    """Issue 30, 18: `substeps = 4096` (the allowed maximum) warned "over 4095": a fixed count is
    the scene's own choice, not the automatic rule running out."""
    lines, qa, _ = bake(tmp_path, FIXED_AT_THE_CAP)
    assert qa["figures"]["substeps"][1:] == [4096, 4096]
    assert lines == [] and qa["warnings"] == []
    assert qa["thresholds"]["substeps"] is None


def test_energy_from_an_impossible_inertia_is_a_warning(tmp_path, monkeypatch):
    """Issue 30, 16: an inertia that breaks the triangle inequality (100, 0.001, 0.001), mass 2,
    spinning, gained energy (1,371 J to 5.3e7 J) with only a substeps warning. Such inertia is
    now refused at load (test_usd_faults.py); this checks the QA would still see the energy it
    makes up if one got through, by turning the range check off."""
    (tmp_path / "scene.toml").write_text(textwrap.dedent("""
        [scene]
        end_frame = 24
        [ground]
        [[bodies]]
        name = "box"
        shape = { type = "box", size = [0.4, 0.4, 0.4] }
        position = [0.0, 1.0, 0.0]
        mass = 2.0
        angular_velocity = [0.0, 35.0, 9.0]
    """))
    scene = simbake.load_scene(tmp_path / "scene.toml")
    impossible = ((100.0, 0.0, 0.0), (0.0, 0.001, 0.0), (0.0, 0.0, 0.001))
    scene = replace(scene, bodies=(replace(scene.bodies[0], inertia=impossible),))
    monkeypatch.setattr(simbake.simulate, "check_scene", lambda scene: None)
    stats = simbake.bake(scene, tmp_path / "out.usdc")
    qa = json.loads((tmp_path / "out.qa.json").read_text())
    energy = np.array(qa["figures"]["kinetic_energy"])
    start = 0.5 * (0.001 * 35.0 ** 2 + 0.001 * 9.0 ** 2) + 2.0 * 9.81 * 1.0  # spin + height (J)
    assert energy.max() > 10 * start  # the state itself gained it
    (line,) = [w for w in stats.warnings if "energy gained without a source" in w]
    assert max(qa["figures"]["energy_gain"]) > 10 * start


@pytest.mark.parametrize("scene", ["drape.toml", "tower.toml", "dominoes.toml"])
def test_passive_shipped_scenes_gain_no_energy(tmp_path, scene):
    """The figures must not cry wolf: shipped scenes without a keyed body (stacks at rest,
    falling dominoes, cloth reaching a sphere), cut to half a second, warn about none of the
    three."""
    text = (Path(__file__).resolve().parents[2] / "assets" / "scenes" / scene).read_text()
    assert "start_frame = 1\n" in text and "mesh" not in text
    (tmp_path / scene).write_text("\n".join("end_frame = 13" if l.startswith("end_frame") else l
                                            for l in text.splitlines()))
    result = run("bake", scene, "-o", "out.usdc", "-q", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    qa = json.loads((tmp_path / "out.qa.json").read_text())
    for figure in ("energy_gain", "unexplained_stop", "imparted_speed"):
        assert qa["summary"][figure]["first_over"] is None, (figure, qa["summary"][figure])
