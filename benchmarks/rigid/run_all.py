"""Run the scene-level rigid benchmarks and write benchmarks/results/rigid_<name>.{json,md,png}.

    .venv/bin/python benchmarks/rigid/run_all.py                  # all of them (~4-8 min)
    .venv/bin/python benchmarks/rigid/run_all.py rigid_stacks     # only the named ones

Also writes results/rigid_run_all.json with the time each took. Nothing here pins the
process to one CPU: worlds are built with threads=1, the ring-toss bakes run pinned in child
processes and every pile run is its own child process, so the order does not matter.
"""

from __future__ import annotations

import json
import sys
import time

import common_rigid as cr
from common_rigid import common
import contact_accuracy
import piles
import ring_toss
import stacks

BENCHMARKS = [contact_accuracy, stacks, ring_toss, piles]


def main(names: list[str]) -> None:
    known = {module.NAME: module for module in BENCHMARKS}
    unknown = [name for name in names if name not in known]
    if unknown:
        sys.exit(f"unknown benchmark(s): {', '.join(unknown)}; known: {', '.join(known)}")
    chosen = [module for module in BENCHMARKS if not names or module.NAME in names]
    start = time.perf_counter()
    seconds = {}
    for module in chosen:
        t0 = time.perf_counter()
        common.run_and_write(module.run)
        seconds[module.NAME] = time.perf_counter() - t0
    total = time.perf_counter() - start
    summary = {"machine": common.machine_info(), "core_module": cr.core_module_info(),
               "benchmark_seconds": seconds, "total_seconds": total}
    common.RESULTS_DIR.mkdir(parents=True, exist_ok=True)
    (common.RESULTS_DIR / "rigid_run_all.json").write_text(json.dumps(summary, indent=2) + "\n")
    print(f"\nrigid/run_all: {len(chosen)} benchmark(s) in {total:.1f} s "
          f"({', '.join(f'{k} {v:.1f} s' for k, v in seconds.items())})")


if __name__ == "__main__":
    main(sys.argv[1:])
