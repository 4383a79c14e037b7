"""The render-ready checks (render_ready.py; tests/python/test_cloth_render_ready.py runs them on
every shipped cloth scene) on any scene: bakes it and, at every frame, counts layers through
layers, strain past the limit + 1%, cloth edges deeper than 0.5 mm in a body, and body edges
through the cloth (boxes and mesh bodies).

    .venv/bin/python benchmarks/cloth/render_check.py SCENE.toml [-o CACHE.usdc]

Prints each failing frame's figures and exits 1 if any frame fails. The shipped cloth scenes
pass over their whole length (the test bakes those; this is for any other scene).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

import simbake
from benchmarks.cloth.render_ready import MESSAGES, render_ready_failures


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("scene")
    parser.add_argument("-o", "--output", help="the cache (default: a temporary file)")
    args = parser.parse_args()
    scene = simbake.load_scene(args.scene)
    with tempfile.TemporaryDirectory() as work:
        cache = args.output or str(Path(work) / "check.usdc")
        stats = simbake.bake(scene, cache)
        crossings, found = render_ready_failures(scene, stats.output)
    by_frame = defaultdict(list)
    for (cloth, frame), count in crossings.items():
        by_frame[frame].append(f"{cloth}: {count} crossing triangle pairs")
    for check, hits in found.items():
        for key, value in hits.items():
            by_frame[key[-1]].append(f"{check} {key[:-1]}: {value}")
    for frame in sorted(by_frame):
        print(f"frame {frame}: " + "; ".join(by_frame[frame]))
    print(f"{len(by_frame)} of {scene.end_frame - scene.start_frame + 1} frames fail"
          + ("" if not by_frame else f" ({', '.join(MESSAGES[c] for c in found if found[c])})"))
    return 1 if by_frame else 0


if __name__ == "__main__":
    sys.exit(main())
