"""Any scene file to a validated Scene: a TOML scene (simbake.scene) or a USD shot
(simbake.usd_scene), told apart by the file's suffix. Both give the same Scene; nothing after
loading knows which it came from.

This module sits above both readers so that neither imports the other: usd_scene builds
scene.py's dataclasses, and scene.py knows nothing of USD (pxr loads only for a shot).
"""

from __future__ import annotations

import os
from pathlib import Path

from .scene import Scene, load_toml_scene

__all__ = ["USD_SCENE_SUFFIXES", "is_usd_scene", "load_scene"]

USD_SCENE_SUFFIXES = (".usd", ".usda", ".usdc")


def is_usd_scene(path: str | os.PathLike[str]) -> bool:
    """Whether `path` names a USD shot (by its suffix) rather than a TOML scene."""
    return Path(os.fspath(path)).suffix.lower() in USD_SCENE_SUFFIXES


def load_scene(path: str | os.PathLike[str]) -> Scene:
    """Read and validate a scene file (TOML, or a USD shot: .usd, .usda, .usdc); raise
    :class:`~simbake.errors.SceneError` on any problem."""
    if is_usd_scene(path):
        from .usd_scene import load_shot  # pxr is loaded only for USD shots

        return load_shot(path)
    return load_toml_scene(path)
