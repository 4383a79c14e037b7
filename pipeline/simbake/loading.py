"""Any scene file to a validated Scene: a TOML scene (simbake.scene) or a USD shot
(simbake.usd_scene), told apart by the file's suffix. Both give the same Scene; nothing after
loading knows which it came from.

This module sits above both readers so that neither imports the other: usd_scene builds
scene.py's dataclasses, and scene.py knows nothing of USD (pxr loads only for a shot).
"""

from __future__ import annotations

import os
from pathlib import Path

from dataclasses import replace

from .limits import check_scene
from .scene import Scene, frame_range, load_toml_scene, read_sequences, stage_range

__all__ = ["USD_SCENE_SUFFIXES", "is_usd_scene", "load_scene", "with_frames"]

USD_SCENE_SUFFIXES = (".usd", ".usda", ".usdc")


def is_usd_scene(path: str | os.PathLike[str]) -> bool:
    """Whether `path` names a USD shot (by its suffix) rather than a TOML scene."""
    return Path(os.fspath(path)).suffix.lower() in USD_SCENE_SUFFIXES


def load_scene(path: str | os.PathLike[str], *, start_frame: int | None = None,
               end_frame: int | None = None) -> Scene:
    """Read and validate a scene file (TOML, or a USD shot: .usd, .usda, .usdc); raise
    :class:`~simbake.errors.SceneError` on any problem. `start_frame`/`end_frame` (``--frames``)
    override the file's own range; a USD stage without startTimeCode/endTimeCode needs both."""
    file = os.fspath(path)  # named in messages exactly as the user gave it
    frames = frame_range(file, start_frame, end_frame)
    if is_usd_scene(path):
        from .usd_scene import load_shot  # pxr is loaded only for USD shots

        if frames is not None and None in frames:  # one end given: the other is the stage's
            frames = stage_range(load_shot(path, None), frames)
        return load_shot(path, frames)
    return with_frames(load_toml_scene(file, frames), start_frame, end_frame)


def with_frames(scene: Scene, start_frame: int | None = None, end_frame: int | None = None) -> Scene:
    """The scene baked over another range (``--frames``): the initial state is written at the
    new start. A USD shot is read again at that range (its kinematic animation and initial
    poses are the stage's at those time codes); a TOML scene's keys stay seconds after the
    (new) start frame."""
    frames = frame_range(scene.source or str(scene.path), start_frame, end_frame)
    if frames is None:
        return scene
    frames = stage_range(scene, frames)
    if frames == (scene.start_frame, scene.end_frame):
        return scene
    if scene.shot is not None:
        from .usd_scene import load_shot

        return load_shot(scene.source or scene.shot.path, frames)
    ranged = replace(scene, start_frame=frames[0], end_frame=frames[1])
    check_scene(ranged)
    return read_sequences(ranged)  # a deforming body's frames: those of the new range
