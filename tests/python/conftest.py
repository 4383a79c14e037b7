"""Shared fixtures for the end-to-end pipeline and CLI tests.

* every test gets its own level-set cache directory (``SIMBAKE_CACHE_DIR``), so no test
  reads or writes ``~/.cache/simbake`` and no test sees another's cached grids;
* ``write_scene(text, name)`` writes a scene TOML into ``tmp_path`` and returns its path;
* ``meshes`` copies the shipped torus and L-shape OBJs into ``tmp_path``.
"""

from __future__ import annotations

import importlib.util
import shutil
import textwrap
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]

# two unit boxes, the dynamic one ("b") resting 1 cm deep in the kinematic one ("a"), no
# gravity: a bake whose first frame's QA reports 10 mm of penetration
BOXES_ONE_CM_DEEP = """
    [scene]
    end_frame = 2
    gravity = [0.0, 0.0, 0.0]
    [[bodies]]
    name = "a"
    shape = { type = "box", size = [1.0, 1.0, 1.0] }
    kinematic = true
    [[bodies]]
    name = "b"
    shape = { type = "box", size = [1.0, 1.0, 1.0] }
    position = [0.0, 0.99, 0.0]
"""
MESH_DIR = REPO / "assets" / "meshes"


def module_from_file(path: Path):
    """A script (a scene generator beside its output) imported as a module, by its path."""
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def assert_same_usda(written: str, checked_in: str, name: str) -> None:
    """A generated .usda the same as the checked-in one: the same text between its numbers,
    and the numbers equal to float32 round-off (1e-7 absolute, 1e-6 relative: numpy's sin
    and cos differ in the last bits from one CPU's SIMD path to another's)."""
    import re

    import numpy as np

    assert re.split(_NUMBER, written) == re.split(_NUMBER, checked_in), name
    a = np.array(re.findall(_NUMBER, written), dtype=np.float64)
    b = np.array(re.findall(_NUMBER, checked_in), dtype=np.float64)
    worst = int(np.argmax(np.abs(a - b) - 1e-6 * np.abs(b)))
    assert np.allclose(a, b, rtol=1e-6, atol=1e-7), (name, a[worst], b[worst])


def bake_error(scene: Path, out: Path, capsys) -> str:
    """`simbake bake scene -o out -q` refused as bad input: exit 2, nothing written, and its
    message, which must be one line (returned stripped, for the caller to check its text)."""
    from simbake.cli import main

    assert main(["bake", str(scene), "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err, err
    assert not out.exists()
    return err


@pytest.fixture(autouse=True)
def simbake_cache_dir(tmp_path_factory, monkeypatch) -> Path:
    """A private, initially absent level-set cache for each test (subprocesses inherit it)."""
    cache = tmp_path_factory.mktemp("simbake-cache") / "cache"
    monkeypatch.setenv("SIMBAKE_CACHE_DIR", str(cache))
    # make sure nothing falls back to the real home cache if the variable were ignored
    monkeypatch.setenv("XDG_CACHE_HOME", str(cache.parent / "xdg-must-stay-unused"))
    return cache


@pytest.fixture
def write_scene(tmp_path):
    """write_scene(text, name="scene.toml") -> the path of the scene file in tmp_path."""

    def write(text: str, name: str = "scene.toml") -> Path:
        path = tmp_path / name
        path.write_text(textwrap.dedent(text))
        return path

    return write


@pytest.fixture
def meshes(tmp_path) -> dict[str, Path]:
    """The shipped torus.obj and lshape.obj copied into tmp_path, by stem."""
    out = {}
    for name in ("torus.obj", "lshape.obj"):
        out[Path(name).stem] = Path(shutil.copy(MESH_DIR / name, tmp_path / name))
    return out
