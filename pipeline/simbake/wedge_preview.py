"""`simbake preview OUT.usda --wedges`: a contact sheet of a wedge, one row per take.

Each row is a band naming the take and what it changes, then the same frames of that take
(default 6, evenly spaced over the wedge's range), drawn by simbake.preview's renderer with
one camera and one ground for every take (framing all of them), so that rows compare
directly. Each take is the wedge stage itself with its variant selected (in the session
layer: the file is not changed), so the sheet shows what a lead flipping variants sees. A
failed take's row is its band, in red, with its one-line error.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from .errors import SceneError
from .files import check_output_path, write_atomically
from .wedge_stage import WedgeStage, read_wedge_stage, select_take

SHEET_COLUMNS = 6                  # frames per take when --frames is not given
TILE_SIZE = (320, 180)             # pixels of each frame
GAP = 4
BAND_COLOR, FAILED_COLOR = (40, 40, 46), (160, 32, 32)


def _wedge(path: Path) -> WedgeStage:
    wedge = read_wedge_stage(path)
    if wedge is None:
        raise SceneError(path, "--wedges", "is not a wedge stage (written by simbake wedge); "
                                           "preview a cache without --wedges")
    if not any(t.error is None for t in wedge.takes):
        raise SceneError(path, "--wedges", "has no baked take to draw")
    return wedge


def _band(text: str, width: int, color: tuple[int, int, int]) -> np.ndarray:
    """A strip of `width` pixels with `text` in white on `color`."""
    from PIL import Image, ImageDraw

    from .preview import label_font

    font = label_font(15)
    height = 26
    picture = Image.new("RGB", (width, height), color)
    ImageDraw.Draw(picture).text((8, 5), text, font=font, fill=(255, 255, 255))
    return np.asarray(picture)


def _framing(preview, wedge: WedgeStage, frames: Sequence[int]):
    """Bounds and ground height over every baked take: (lo, hi, extent, ground)."""
    from .preview import CacheGeometry

    lo, hi, ground = np.full(3, np.inf), np.full(3, -np.inf), np.inf
    for take in (t for t in wedge.takes if t.error is None):
        select_take(preview.stage, wedge.prim, take.name)
        preview.geometry = CacheGeometry(preview.stage)
        take_lo, take_hi, _, take_ground = preview.frame_range(frames)
        lo, hi, ground = np.minimum(lo, take_lo), np.maximum(hi, take_hi), min(ground, take_ground)
    extent = float(max(hi[0] - lo[0], hi[2] - lo[2], hi[1] - lo[1], 1e-3))
    return lo, hi, extent, ground


def _rows(preview, wedge: WedgeStage, frames: Sequence[int], size: tuple[int, int]) -> list[np.ndarray]:
    """One image per take: its band over its frames (a failed take: the band alone)."""
    from .preview import CacheGeometry, Renderer, auto_camera, burn_in, contact_sheet, light_camera

    lo, hi, extent, ground = _framing(preview, wedge, frames)
    camera, light = auto_camera(lo, hi, size[0] / size[1]), light_camera(lo, hi)
    width = len(frames) * (size[0] + GAP) + GAP
    renderer = Renderer(size)
    rows = []
    try:
        for take in wedge.takes:
            if take.error is not None:
                rows.append(_band(f"{take.name} FAILED ({take.label}): {take.error}", width, FAILED_COLOR))
                continue
            select_take(preview.stage, wedge.prim, take.name)
            geometry = CacheGeometry(preview.stage)
            images = [burn_in(renderer.render(camera, geometry.triangles(float(f)), ground, extent, light),
                              f"frame {f}") for f in frames]
            rows.append(np.vstack([_band(f"{take.name}   {take.label}", width, BAND_COLOR),
                                   contact_sheet(images, columns=len(frames), gap=GAP)]))
    finally:
        renderer.release()
    return rows


def write_wedge_sheet(path: str | Path, output: str | Path | None = None, *, frames: str | None = None,
                      size: tuple[int, int] | None = None) -> tuple[Path, int]:
    """Renders the wedge stage `path` as a contact sheet (.png, default OUT.png beside it);
    returns the sheet's path and the number of takes (rows)."""
    from .preview import Preview, parse_frames, save_png

    path = Path(path)
    out = Path(output) if output is not None else path.with_suffix(".png")
    check_output_path(out, (".png",), inputs=[path])
    wedge = _wedge(path)
    size = size or TILE_SIZE
    preview = Preview(path, size)
    try:
        chosen = parse_frames(frames, preview.start, preview.end, SHEET_COLUMNS)
        rows = _rows(preview, wedge, chosen, size)
    finally:
        preview.close()
    sheet = np.vstack([np.pad(r, ((0, GAP), (0, 0), (0, 0)), constant_values=255) for r in rows])
    write_atomically(out, lambda tmp: save_png(tmp, sheet))
    return out, len(rows)
