"""A bake alone and with a busy process on each CPU (`yes`, one per CPU), in turns: wall
time, CPU time and the stage profile of each run, and the ratio loaded / alone.

    .venv/bin/python benchmarks/busy_neighbours.py SCENE [--frames A:B] [--threads N] [--rounds R]

CPU time about the same loaded as alone means nothing in the bake spins or waits: it only
got less of the CPUs.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def bake(simbake: Path, scene: str, out: Path, frames: str | None, threads: int) -> tuple[float, float, dict]:
    before = os.times()
    start = time.perf_counter()
    subprocess.run([str(simbake), "bake", scene, "-o", str(out), "-q", "--threads", str(threads)]
                   + (["--frames", frames] if frames else []), check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - start
    after = os.times()
    cpu = after.children_user - before.children_user + after.children_system - before.children_system
    return wall, cpu, json.loads(out.with_name(out.stem + ".qa.json").read_text())["profile"]


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene")
    p.add_argument("--frames")
    p.add_argument("--threads", type=int, default=0)
    p.add_argument("--rounds", type=int, default=2)
    args = p.parse_args()
    simbake = Path(sys.executable).with_name("simbake")
    walls = {"alone": [], "loaded": []}
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "busy.usdc"
        for _ in range(args.rounds):
            for mode in ("alone", "loaded"):
                hogs = [subprocess.Popen(["yes"], stdout=subprocess.DEVNULL)
                        for _ in range(os.cpu_count() or 1)] if mode == "loaded" else []
                try:
                    wall, cpu, profile = bake(simbake, args.scene, out, args.frames, args.threads)
                finally:
                    for hog in hogs:
                        hog.kill()
                        hog.wait()
                walls[mode].append(wall)
                top = {stage: round(s, 2) for stage, s in profile.items() if s > 0.05 * wall}
                print(f"{mode:6s} wall {wall:7.2f} s  cpu {cpu:7.2f} s  load {os.getloadavg()[0]:.1f}  {top}", flush=True)
    ratios = [loaded / alone for alone, loaded in zip(walls["alone"], walls["loaded"])]
    print(f"loaded / alone: {statistics.median(walls['loaded']) / statistics.median(walls['alone']):.2f} "
          f"(medians); pairs {[round(r, 2) for r in ratios]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
