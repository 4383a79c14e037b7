"""The drape's cost per doubling of the resolution: run_simbake.py at each resolution, several
times in turn, the median CPU seconds per simulated second of each, and the ratio from one
resolution to the next (issue 9 asks at most 4.5x: four times the vertices, and a little).

    .venv/bin/python benchmarks/cloth/doubling.py [--resolutions 17 33 65 129 257]
        [--repeats 3] [--repeats-257 2] [--cpu 0] [--name doubling]

Every run is its own process pinned to one CPU (--cpu), the rounds interleaved (17, 33, ...,
257, then again), so that a slow minute of a shared machine falls on every resolution alike;
the other CPU should be idle or running something steady. Writes
benchmarks/results/cloth_<name>.{json,md}: every run's CPU seconds, its cloth sub-stages
(World.profile: forces and solve, contacts, strain limiting, self-collision), the solver's
iterations and the self-collision's candidate pairs, and per resolution the medians.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
RESULTS = ROOT / "benchmarks" / "results"
STAGES = ("cloth_forces", "cloth_contacts", "cloth_strain", "cloth_self_collision")


def run(n: int, cpu: int) -> dict:
    out = subprocess.run(["taskset", "-c", str(cpu), sys.executable, str(HERE / "run_simbake.py"), str(n)],
                         capture_output=True, text=True, check=True).stdout
    record = json.loads(out.strip().splitlines()[-1])
    seconds = record["wall_seconds"] / record["wall_per_sim_second"]
    return {"n": n, "cpu_per_s": record["cpu_seconds"] / seconds,
            "solver_cpu_per_s": record["solver_cpu_seconds"] / seconds,
            "stages_per_s": {s: record["profile"][s] / seconds for s in STAGES},
            "iterations": record["solver_iterations"],
            "candidates": record["self_collision"]["self_collision_candidates"],
            "crossings": record["self_crossings"], "max_strain": record["max_strain"],
            "max_penetration": record["max_penetration"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--resolutions", type=int, nargs="+", default=[17, 33, 65, 129, 257])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--repeats-257", type=int, default=2, help="runs of 257 x 257 (each ~5-8 min)")
    parser.add_argument("--cpu", type=int, default=0)
    parser.add_argument("--name", default="doubling")
    args = parser.parse_args()
    runs: list[dict] = []
    started = time.strftime("%Y-%m-%d %H:%M")
    for round_ in range(args.repeats):
        for n in args.resolutions:
            if n >= 257 and round_ >= args.repeats_257:
                continue
            runs.append(run(n, args.cpu))
            print(f"round {round_ + 1}: {n} x {n}: {runs[-1]['cpu_per_s']:.3f} CPU s/s", flush=True)
    medians = {}
    for n in args.resolutions:
        mine = [r for r in runs if r["n"] == n]
        medians[n] = {"cpu_per_s": statistics.median(r["cpu_per_s"] for r in mine),
                      "solver_cpu_per_s": statistics.median(r["solver_cpu_per_s"] for r in mine),
                      **{s: statistics.median(r["stages_per_s"][s] for r in mine) for s in STAGES},
                      "runs": len(mine)}
    result = {"started": started, "cpu": args.cpu, "runs": runs, "medians": {str(n): m for n, m in medians.items()}}
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / f"cloth_{args.name}.json").write_text(json.dumps(result, indent=1) + "\n")
    lines = [f"# The drape's cost per doubling ({started}, CPU {args.cpu}, `benchmarks/cloth/doubling.py`)", "",
             "Medians of each resolution's runs, CPU seconds per simulated second; the ratio is to the "
             "resolution before.", "",
             "| n x n | runs | CPU s/s | ratio | solve | forces (with solve) | self-collision | contacts | strain |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    previous = None
    for n in args.resolutions:
        m = medians[n]
        ratio = f"{m['cpu_per_s'] / previous:.2f}x" if previous else ""
        lines.append(f"| {n} | {m['runs']} | {m['cpu_per_s']:.3f} | {ratio} | {m['solver_cpu_per_s']:.3f} | "
                     f"{m['cloth_forces']:.3f} | {m['cloth_self_collision']:.3f} | {m['cloth_contacts']:.3f} | "
                     f"{m['cloth_strain']:.3f} |")
        previous = m["cpu_per_s"]
    lines += ["", "Every run: " + ", ".join(f"{r['n']}: {r['cpu_per_s']:.3f}" for r in runs), ""]
    (RESULTS / f"cloth_{args.name}.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
