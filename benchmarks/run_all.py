"""Run every run-time-versus-error benchmark and write benchmarks/results/<name>.{json,md,png}.

    .venv/bin/python benchmarks/run_all.py              # all of them
    .venv/bin/python benchmarks/run_all.py rigid_spin   # only the named ones

The level-set benchmark runs last: it pins the process to one CPU before its first bake
(see common.py), which then holds for the rest of the process.
"""

from __future__ import annotations

import json
import sys
import time

import common
import levelset_sphere
import rigid_bounce
import rigid_slide
import rigid_spin

BENCHMARKS = [rigid_bounce, rigid_spin, rigid_slide, levelset_sphere]  # levelset_sphere last


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
    summary = {"machine": common.machine_info(), "benchmark_seconds": seconds, "total_seconds": total}
    common.RESULTS_DIR.mkdir(parents=True, exist_ok=True)
    (common.RESULTS_DIR / "run_all.json").write_text(json.dumps(summary, indent=2) + "\n")
    print(f"\nrun_all: {len(chosen)} benchmark(s) in {total:.1f} s "
          f"({', '.join(f'{k} {v:.1f} s' for k, v in seconds.items())})")


if __name__ == "__main__":
    main(sys.argv[1:])
