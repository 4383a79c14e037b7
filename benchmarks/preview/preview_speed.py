"""How fast `simbake preview` draws: seconds per frame at two sizes, per kind of cache.

    .venv/bin/python benchmarks/preview/preview_speed.py

Bakes three shipped scenes into a temporary directory (demo: 6 rigid bodies; pile: 200
meshes; drape: a 64 x 64 cloth, 8k triangles), then renders every frame of each at
640x360 and 1280x720 (4x multisampling, the shadow map, the burned-in label) and reports
the median seconds per frame: in all, and the part spent reading the cache (pxr: points,
transforms, normals per frame) apart from drawing it. The one-time start (opening the
stage, the OpenGL context) is reported separately. One CPU for the process (Mesa's llvmpipe
would otherwise use both cores: LP_NUM_THREADS=1), so the figures are single-thread ones.
Writes benchmarks/results/preview.{json,md}.
"""

from __future__ import annotations

import json
import os
import statistics
import tempfile
import time
from pathlib import Path

os.environ.setdefault("LP_NUM_THREADS", "1")  # before Mesa loads

HERE = Path(__file__).resolve().parent

import simbake  # noqa: E402  (after LP_NUM_THREADS)
from benchmarks import common  # noqa: E402
from simbake.preview import Preview  # noqa: E402

SCENES = ["demo", "pile", "drape"]
SIZES = [(640, 360), (1280, 720)]
SCENE_DIR = HERE.parents[1] / "assets" / "scenes"


def measure(cache: Path, size: tuple[int, int]) -> dict:
    started = time.perf_counter()
    preview = Preview(cache, size)
    frames = list(range(preview.start, preview.end + 1))
    lo_hi = preview.frame_range(frames)  # the automatic camera's bounds (also inside frames())
    setup = time.perf_counter() - started
    reading = []
    for f in frames:
        t = time.perf_counter()
        preview.geometry.triangles(float(f))
        reading.append(time.perf_counter() - t)
    per_frame = []
    clock = time.perf_counter()
    for _ in preview.frames(frames):
        now = time.perf_counter()
        per_frame.append(now - clock)
        clock = now
    triangles = len(preview.geometry.triangles(float(frames[-1]))[0]) // 3
    preview.close()
    return {"size": f"{size[0]}x{size[1]}", "frames": len(frames), "triangles": triangles,
            "setup_s": setup, "frame_s": statistics.median(per_frame[1:] or per_frame),
            "read_s": statistics.median(reading), "bounds": [list(map(float, v)) for v in lo_hi[:2]]}


def main() -> None:
    common.pin_to_one_cpu()
    rows = []
    with tempfile.TemporaryDirectory() as work:
        for name in SCENES:
            scene = simbake.load_scene(SCENE_DIR / f"{name}.toml")
            stats = simbake.bake(scene, Path(work) / f"{name}.usdc", qa=False)
            for size in SIZES:
                row = {"scene": name, **measure(stats.output, size)}
                rows.append(row)
                print(f"{name:6s} {row['size']:>9s}: {row['frame_s'] * 1e3:6.1f} ms/frame "
                      f"(reading {row['read_s'] * 1e3:5.1f} ms), {row['triangles']} triangles, "
                      f"setup {row['setup_s']:.2f} s")
    common.RESULTS_DIR.mkdir(exist_ok=True)
    (common.RESULTS_DIR / "preview.json").write_text(json.dumps(
        {"machine": common.machine_info(), "rows": rows}, indent=1) + "\n")
    lines = ["# simbake preview: seconds per frame", "",
             "`.venv/bin/python benchmarks/preview/preview_speed.py`: every frame of each baked "
             "scene, automatic camera, 4x multisampling, shadow map, label; one CPU "
             "(LP_NUM_THREADS=1); median over the frames. *reading* is the part spent getting "
             "the frame's triangles from the cache (pxr), included in *per frame*.", "",
             "| scene | triangles | size | per frame (ms) | reading (ms) | frames/s | start (s) |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        lines.append(f"| {r['scene']} | {r['triangles']} | {r['size']} | {r['frame_s'] * 1e3:.1f} | "
                     f"{r['read_s'] * 1e3:.1f} | {1 / r['frame_s']:.1f} | {r['setup_s']:.2f} |")
    (common.RESULTS_DIR / "preview.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
