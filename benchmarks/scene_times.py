"""Every shipped scene's whole bake, alone and with a busy process on each CPU (one `yes` per
CPU), in turns: wall and CPU time, the QA's share (the sidecar profile's `quality` stage
against the sum of its top-level stages, and against the whole bake's wall time, start-up
included) and the loaded / alone ratio. Writes benchmarks/results/scene_times.md.

    .venv/bin/python benchmarks/scene_times.py [SCENE ...] [--threads N]

The start-up of a bake (about 0.8 s here: benchmarks/README.md) is in every wall time.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.busy_neighbours import bake

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "assets" / "scenes"
RESULTS = ROOT / "benchmarks" / "results" / "scene_times.md"
TOP_STAGES = ("broad_phase", "collisions", "contacts", "shock_propagation", "velocities", "positions",
              "sleeping", "joints", "kinematic_bodies", "cloths", "statistics", "quality", "usd_writer")


def shipped() -> list[Path]:
    return sorted(p for p in SCENES.iterdir() if p.suffix in (".toml", ".usda"))


def qa_share(profile: dict) -> float:
    total = sum(profile.get(stage, 0.0) for stage in TOP_STAGES)
    return profile.get("quality", 0.0) / total if total > 0 else 0.0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenes", nargs="*", type=Path)
    p.add_argument("--threads", type=int, default=0)
    args = p.parse_args()
    simbake = Path(sys.executable).with_name("simbake")
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for scene in args.scenes or shipped():
            out = Path(folder) / f"{scene.stem}.usdc"
            runs = {}
            for mode in ("alone", "loaded"):
                hogs = [subprocess.Popen(["yes"], stdout=subprocess.DEVNULL)
                        for _ in range(os.cpu_count() or 1)] if mode == "loaded" else []
                try:
                    runs[mode] = bake(simbake, str(scene), out, None, args.threads)
                finally:
                    for hog in hogs:
                        hog.kill()
                        hog.wait()
            (wall, cpu, profile), (lwall, lcpu, _) = runs["alone"], runs["loaded"]
            row = (scene.name, wall, cpu, qa_share(profile), profile.get("quality", 0.0) / wall, lwall, lcpu,
                   lwall / wall)
            rows.append(row)
            print(f"{row[0]:22s} alone {wall:7.2f} s wall {cpu:7.2f} s CPU  QA {100 * row[3]:4.1f}% "
                  f"({100 * row[4]:4.1f}% of the wall)  loaded {lwall:7.2f} s wall {lcpu:7.2f} s CPU  "
                  f"{row[7]:.2f}x", flush=True)
    lines = ["# Every shipped scene's bake, alone and beside a busy process on each CPU", "",
             f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs; "
             f"{time.strftime('%Y-%m-%d %H:%M')}; `.venv/bin/python benchmarks/scene_times.py`"
             f"{f' --threads {args.threads}' if args.threads else ''}; one run each, in turns.", "",
             "| scene | alone wall s | alone CPU s | QA of the stages | QA of the wall | loaded wall s | "
             "loaded CPU s | loaded / alone |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    lines += [f"| {n} | {w:.2f} | {c:.2f} | {100 * q:.1f}% | {100 * qw:.1f}% | {lw:.2f} | {lc:.2f} | {r:.2f}x |"
              for n, w, c, q, qw, lw, lc, r in rows]
    if not args.scenes:
        RESULTS.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
