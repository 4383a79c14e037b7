"""The bake's quality figures (simbake.qa) against scenes with known answers.

Each reference is computed here, apart from the core: a box placed 1 cm into another, a
cloth mesh that crosses itself counted by an all-pairs test written in numpy (a different
formulation from the core's: the segment's plane crossing point and its barycentric
coordinates, not signed volumes), and a hanging strip's static strain from its weight.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from conftest import BOXES_ONE_CM_DEEP

import numpy as np
import pytest

import simbake
from simbake.qa import load_qa, qa_path


def _bake(scene_path: Path, tmp_path: Path, name: str = "out.usdc"):
    scene = simbake.load_scene(scene_path)
    return scene, simbake.bake(scene, tmp_path / name)


# --------------------------------------------------------------------------------------------
# an independent triangle-triangle count


def _segment_hits_triangle(p, q, a, b, c) -> bool:
    """The segment pq meets triangle abc at a point strictly inside both (barycentric)."""
    n = np.cross(b - a, c - a)
    dp, dq = np.dot(n, p - a), np.dot(n, q - a)
    if dp * dq >= 0:
        return False
    x = p + (q - p) * (dp / (dp - dq))  # where pq crosses the plane
    v0, v1, v2 = b - a, c - a, x - a
    d00, d01, d11 = v0 @ v0, v0 @ v1, v1 @ v1
    d20, d21 = v2 @ v0, v2 @ v1
    den = d00 * d11 - d01 * d01
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    return v > 0 and w > 0 and v + w < 1


def count_crossings(points: np.ndarray, triangles: np.ndarray) -> int:
    count = 0
    for i in range(len(triangles)):
        for j in range(i + 1, len(triangles)):
            ti, tj = triangles[i], triangles[j]
            if set(ti) & set(tj):
                continue
            A, B = points[ti], points[tj]
            hit = any(_segment_hits_triangle(A[k], A[(k + 1) % 3], *B) for k in range(3)) or \
                any(_segment_hits_triangle(B[k], B[(k + 1) % 3], *A) for k in range(3))
            count += hit
    return count


def _write_obj(path: Path, points: np.ndarray, triangles: np.ndarray) -> None:
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in points]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in triangles]
    path.write_text("\n".join(lines) + "\n")


def _strip(n: int, start: np.ndarray, step: np.ndarray, across: np.ndarray, offset: int):
    """A strip of n cells: two rows of vertices along `step`, `across` apart."""
    points = np.array([start + k * step + s * across for k in range(n + 1) for s in (0, 1)])
    tris = []
    for k in range(n):
        a, b, c, d = 2 * k, 2 * k + 1, 2 * k + 2, 2 * k + 3
        tris += [(a, b, d), (a, d, c)]
    return points, np.array(tris) + offset


# --------------------------------------------------------------------------------------------


def test_box_pushed_one_centimetre_into_another_reports_one_centimetre(write_scene, tmp_path):
    path = write_scene("""
        [scene]
        end_frame = 2
        gravity = [0.0, 0.0, 0.0]
        [[bodies]]
        name = "base"
        shape = { type = "box", size = [1.0, 1.0, 1.0] }
        kinematic = true
        [[bodies]]
        name = "top"
        shape = { type = "box", size = [0.5, 0.5, 0.5] }
        position = [0.1, 0.74, 0.05]
    """)
    _, stats = _bake(path, tmp_path)
    qa = load_qa(tmp_path / "out.usdc")
    first = qa["figures"]["body_penetration"][0]
    # the top box's bottom face is at 0.74 - 0.25 = 0.49, the base's top at 0.5: 1 cm, exactly
    # (analytic box distances, samples on the faces)
    assert first == pytest.approx(0.01, abs=1e-9)
    assert qa["figures"]["body_penetration_between"][0] == ["top", "base"]
    assert qa["frames"] == [1, 2]
    # over the 5 mm threshold: one warning naming the frame and the figure
    assert len(stats.warnings) == 1
    assert "body penetration 10 mm (top into base) at frame 1" in stats.warnings[0]
    assert stats.qa == qa_path(tmp_path / "out.usdc") == tmp_path / "out.qa.json"
    # and the cache carries the summary
    from pxr import Sdf

    layer = Sdf.Layer.FindOrOpen(str(tmp_path / "out.usdc"))
    summary = layer.customLayerData["simbake"]["qa"]
    assert summary["body_penetration"]["worst"] == pytest.approx(0.01, abs=1e-9)
    assert summary["body_penetration"]["frame"] == 1
    assert summary["warnings"] == 1


def test_cloth_crossing_itself_reports_its_intersections(write_scene, tmp_path):
    # one cloth mesh of two strips: a flat one along x and a vertical one along y crossing it,
    # and a third strip far away that crosses nothing
    p1, t1 = _strip(6, np.array([-0.6, 0.0, -0.05]), np.array([0.2, 0.0, 0.0]), np.array([0, 0, 0.1]), 0)
    p2, t2 = _strip(6, np.array([-0.03, -0.55, 0.0]), np.array([0.0, 0.2, 0.0]), np.array([0.07, 0, 0.03]), len(p1))
    p3, t3 = _strip(3, np.array([3.0, 0.0, 0.0]), np.array([0.2, 0.0, 0.0]), np.array([0, 0, 0.1]),
                    len(p1) + len(p2))
    points, triangles = np.vstack([p1, p2, p3]), np.vstack([t1, t2, t3])
    expected = count_crossings(points, triangles)
    assert expected >= 2
    _write_obj(tmp_path / "crossing.obj", points, triangles)
    path = write_scene("""
        [scene]
        end_frame = 3
        gravity = [0.0, 0.0, 0.0]
        [[cloths]]
        name = "knot"
        mesh = "crossing.obj"
        position = [0.0, 2.0, 0.0]
    """)
    _, stats = _bake(path, tmp_path)
    qa = load_qa(tmp_path / "out.usdc")
    assert qa["cloths"]["knot"]["self_intersections"][0] == expected
    assert qa["figures"]["cloth_self_intersections"][0] == expected
    assert any("cloth 'knot' self-intersections" in w and "from frame 1" in w for w in stats.warnings)


def test_pinned_strip_strain_is_its_weight_over_its_stiffness(tmp_path, write_scene):
    # A strip one cell wide, pinned at its top two vertices, hanging at rest (damped, 3 s).
    # Each side edge carries the weight of its own column below it (statics of each cut, to
    # first order in the strain), and a side spring's constant is E = 0.4 Y w (the springs'
    # calibration, README "Cloth material"): the top side edge's strain is
    # g m_column / (0.4 Y w), with masses lumped a third of each triangle to its vertices.
    rows, h, w, density, Y, g = 10, 0.1, 0.1, 0.1, 500.0, 9.81
    points, triangles = _strip(rows, np.array([0.0, 0.0, 0.0]), np.array([0.0, -h, 0.0]),
                               np.array([w, 0.0, 0.0]), 0)
    _write_obj(tmp_path / "strip.obj", points, triangles)
    area = 0.5 * np.linalg.norm(np.cross(points[triangles[:, 1]] - points[triangles[:, 0]],
                                         points[triangles[:, 2]] - points[triangles[:, 0]]), axis=1)
    masses = np.zeros(len(points))
    np.add.at(masses, triangles.reshape(-1), np.repeat(density * area / 3, 3))
    E = 0.4 * Y * w
    top = max(g * masses[2 + column::2].sum() / E for column in (0, 1))
    path = write_scene(f"""
        [scene]
        fps = 24
        end_frame = 73
        [[cloths]]
        name = "strip"
        mesh = "strip.obj"
        position = [0.0, 2.0, 0.0]
        area_density = {density}
        stretch_stiffness = {Y}
        bend_stiffness = 0.0
        strain_limit = 0.0
        damping = 0.05
        pinned = [0, 1]
    """)
    _, stats = _bake(path, tmp_path)
    strain = load_qa(tmp_path / "out.usdc")["cloths"]["strip"]["strain"]
    # the two columns' weights differ by a third of a triangle, so the strip leans a little
    # and the diagonals take some load: a relative error of order the strain itself (the
    # core's hanging-strip test measures -0.57 x the strain); 2% covers that and the sway
    # left after 3 s of damping
    assert top == pytest.approx(0.00245, rel=0.05)
    assert strain[-1] == pytest.approx(top, rel=0.02)
    assert strain[0] == pytest.approx(0.0, abs=1e-12)
    assert not stats.warnings  # no strain limit, no crossings, nothing penetrates


def test_cli_bake_prints_qa_warnings_after_the_summary(write_scene, tmp_path):
    path = write_scene(BOXES_ONE_CM_DEEP)
    out = tmp_path / "cli.usdc"
    result = subprocess.run([sys.executable, "-m", "simbake", "bake", str(path), "-o", str(out), "-q"],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("simbake: warning: QA: deepest body penetration 10 mm (b into a) at frame 1")
    data = json.loads((tmp_path / "cli.qa.json").read_text())
    assert data["cache"] == "cli.usdc"
    assert set(data["profile"]) >= {"contacts", "cloths", "quality", "usd_writer"}
