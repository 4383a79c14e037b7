"""Bakes every shipped scene and writes a strip of four preview frames for each.

    .venv/bin/python assets/previews/generate.py [SCENE ...]   # default: every assets/scenes/*.toml and *.usda

A USD shot's strip shows its --shot stage (the cache layer over the shot), as a TD opens it.

Each strip, assets/previews/<scene>.png, is four evenly spaced frames at 320x180 side by
side (simbake.preview), quantized to 256 colours to stay small; the README's scene table
links them. The bakes go to a temporary directory; their QA warnings are printed so that a
strip is never mistaken for a clean bake.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
SCENES = HERE.parent / "scenes"
FRAMES, SIZE = 4, (320, 180)


def strip(scene_path: Path, work: Path) -> Path:
    from PIL import Image

    import simbake
    from simbake.preview import Preview, contact_sheet, parse_frames

    scene = simbake.load_scene(scene_path)
    shot = work / f"{scene_path.stem}.shot.usda" if scene.shot is not None else None
    stats = simbake.bake(scene, work / f"{scene_path.stem}.usdc", shot=shot)
    for line in stats.warnings:
        print(f"  {scene_path.name}: {line}")
    preview = Preview(shot or stats.output, SIZE)
    try:
        frames = parse_frames(None, preview.start, preview.end, FRAMES)
        images = [image for _, image in preview.frames(frames)]
    finally:
        preview.close()
    out = HERE / f"{scene_path.stem}.png"
    picture = Image.fromarray(contact_sheet(images, columns=FRAMES))
    picture.quantize(256, method=Image.Quantize.MEDIANCUT).save(out, optimize=True)
    print(f"{scene_path.name}: {stats.frames} frames in {stats.wall_seconds:.1f} s -> {out.relative_to(HERE.parents[1])}")
    return out


def main(names: list[str]) -> None:
    paths = [Path(n) for n in names] if names else sorted([*SCENES.glob("*.toml"), *SCENES.glob("*.usda")])
    with tempfile.TemporaryDirectory() as work:
        for path in paths:
            strip(path.resolve(), Path(work))


if __name__ == "__main__":
    main(sys.argv[1:])
