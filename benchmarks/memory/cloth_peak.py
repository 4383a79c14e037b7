"""Peak memory of a cloth bake against simbake's estimate (README, "Resource budget").

Each run bakes one square grid (N x N vertices, 2 m, one substep a frame, QA on, .usdc unless
--usda) for F frames in a fresh Python process, on one thread, and reports that process's own
peak resident set (VmHWM in /proc/self/status) beside the estimate of
simbake.limits.estimated_memory for the same bake. Two layouts:

    sag    pinned at its four corners: it sags and swings, never folds onto itself
    hang   pinned at two corners of one edge: it falls into folds, and its self-collision
           keeps more as the folds grow (the part of the peak the estimate does not model)

    .venv/bin/python benchmarks/memory/cloth_peak.py --layout sag --sizes 128 256 384 --frames 2 60

prints a Markdown table: N, vertices, frames, estimate, peak (MiB) and peak / estimate.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

SCENE = """[scene]
end_frame = {frames}
[solver]
substeps = 1
[[cloths]]
name = "sheet"
grid = {{ size = [2.0, 2.0], resolution = [{n}, {n}] }}
position = [0.0, 1.0, 0.0]
pinned = {pinned}
"""

RUN = """
import json, sys
from pathlib import Path
import simbake
from simbake.assets import load_cloth
from simbake.limits import crowding, estimated_memory
from simbake.qa_motion import mean_edge
scene = simbake.load_scene(sys.argv[1])
cloths = [(len(a.vertices), crowding(c.thickness, mean_edge(a.vertices, a.triangles)))
          for c, a in zip(scene.cloths, (load_cloth(scene, i) for i in range(len(scene.cloths))))]
estimate = estimated_memory(scene.frame_count, cloths, 0, Path(sys.argv[2]))
simbake.bake(scene, sys.argv[2], threads=1)
# the peak of this process's own memory (VmHWM): ru_maxrss would also count the parent's
# resident set at the fork (a test runner that has baked other scenes, say)
with open("/proc/self/status") as status:
    peak = next(int(line.split()[1]) * 1024 for line in status if line.startswith("VmHWM:"))
print(json.dumps({"estimate": estimate, "peak": peak}))
"""


def pins(layout: str, n: int) -> list[int]:
    return [0, n - 1, n * n - n, n * n - 1] if layout == "sag" else [0, n - 1]


def measure(layout: str, n: int, frames: int, suffix: str) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        scene = Path(tmp) / "cloth.toml"
        scene.write_text(SCENE.format(frames=frames, n=n, pinned=pins(layout, n)))
        result = subprocess.run([sys.executable, "-c", RUN, str(scene), str(Path(tmp) / f"cloth{suffix}")],
                                capture_output=True, text=True, check=True,
                                env={"SIMBAKE_CACHE_DIR": str(Path(tmp) / "cache"), "PATH": "/usr/bin:/bin"})
        return json.loads(result.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--layout", choices=("sag", "hang"), default="sag")
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 128, 256])
    parser.add_argument("--frames", type=int, nargs="+", default=[2, 60])
    parser.add_argument("--usda", action="store_true", help="write .usda (the cache held once as text is written)")
    args = parser.parse_args()
    print(f"| layout | N x N | vertices | frames | estimate (MiB) | peak (MiB) | peak / estimate |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for n in args.sizes:
        for frames in args.frames:
            m = measure(args.layout, n, frames, ".usda" if args.usda else ".usdc")
            print(f"| {args.layout} | {n} x {n} | {n * n:,} | {frames} | {m['estimate'] / 2**20:,.0f} | "
                  f"{m['peak'] / 2**20:,.0f} | {m['peak'] / m['estimate']:.3f} |", flush=True)


if __name__ == "__main__":
    main()
