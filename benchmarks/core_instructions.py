"""Instructions the core executes inside World::step_frame, counted by Valgrind's callgrind, for
two builds on the same workloads: a speed comparison that does not depend on the machine's load
(these 2-CPU machines are shared; wall times vary by 15% within the hour, instruction counts
not at all: the bakes are deterministic).

    .venv/bin/python benchmarks/core_instructions.py BEFORE_PYTHON AFTER_PYTHON [--only NAME ...]

Each PYTHON is the interpreter of an environment with simbake installed (a checkout's
`.venv/bin/python`). The workloads, each baked with `--threads 1` (all work on the calling
thread, which callgrind's toggle follows):

* box1000: the peer benchmark's pile of 1,000 boxes (benchmarks/peers/scenes.py), frames 1-24;
* drape65: assets/scenes/drape.toml at 65 x 65 vertices, frames 1-25;
* drape129: the same at 129 x 129, frames 1-12 (the sheet reaches the sphere at frame 6);
* cloth_demo: assets/scenes/cloth_demo.toml, frames 1-12;
* pile_mesh: assets/scenes/pile.toml (200 tori, L-shapes and spheres: samples against level
  sets), frames 1-30.

Prints a table (instructions before, after, after / before) and writes it to
benchmarks/results/core_instructions.md. Valgrind makes each run about 50x slower than native.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import tempfile
from pathlib import Path

from benchmarks.peers import pile_bakes

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "assets" / "scenes"


def _box1000(end: int) -> str:
    return pile_bakes.scene_text("pile", fps=24, end_frame=end)


def _ranged(text: str, end: int) -> str:
    return re.sub(r"end_frame = \d+", f"end_frame = {end}", text)


def workloads() -> dict[str, str]:
    drape = (SCENES / "drape.toml").read_text()
    meshes = f'"{ROOT / "assets" / "meshes"}/'
    demo = (SCENES / "cloth_demo.toml").read_text().replace('"../meshes/', meshes)
    pile = (SCENES / "pile.toml").read_text().replace('"../meshes/', meshes)
    return {
        "box1000": _box1000(24),
        "drape65": _ranged(drape, 25),  # (64 cells a side: 65 vertices)
        "drape129": _ranged(drape.replace("resolution = [64, 64]", "resolution = [128, 128]"), 12),
        "cloth_demo": _ranged(demo, 12),
        "pile_mesh": _ranged(pile, 30),
    }


def count(python: str, scene: Path, folder: Path) -> int:
    """Instructions inside World::step_frame over the bake of `scene`."""
    out = folder / f"{scene.stem}.{abs(hash(python))}.callgrind"
    run = subprocess.run(["valgrind", "--tool=callgrind", "--toggle-collect=simbake::World::step_frame*",
                          f"--callgrind-out-file={out}", python, "-m", "simbake", "bake", str(scene),
                          "-o", str(folder / f"{scene.stem}.usdc"), "--threads", "1", "-q"],
                         capture_output=True, text=True, check=True)
    return int(re.search(r"Collected : (\d+)", run.stderr)[1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("before")
    parser.add_argument("after")
    parser.add_argument("--only", nargs="*")
    args = parser.parse_args()
    rows = ["| workload | before | after | after / before |", "| --- | --- | --- | --- |"]
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for name, text in workloads().items():
            if args.only and name not in args.only:
                continue
            scene = folder / f"{name}.toml"
            scene.write_text(text)
            before, after = count(args.before, scene, folder), count(args.after, scene, folder)
            rows.append(f"| {name} | {before:,} | {after:,} | {after / before:.4f} |")
            print(rows[-1], flush=True)
    text = ("# Instructions inside World::step_frame (callgrind)\n\n"
            f"`python benchmarks/core_instructions.py {args.before} {args.after}`\n\n" + "\n".join(rows) + "\n")
    (ROOT / "benchmarks" / "results" / "core_instructions.md").write_text(text)


if __name__ == "__main__":
    main()
