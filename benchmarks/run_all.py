"""Run every run-time-versus-error benchmark and write benchmarks/results/<name>.{json,md,png}.

    .venv/bin/python benchmarks/run_all.py              # all of them
    .venv/bin/python benchmarks/run_all.py rigid_spin   # only the named ones

The level-set benchmark runs last: it pins the process to one CPU before its first bake
(see common.py), which then holds for the rest of the process.
"""

from __future__ import annotations

import sys

import common
import levelset_sphere
import rigid_bounce
import rigid_slide
import rigid_spin

BENCHMARKS = [rigid_bounce, rigid_spin, rigid_slide, levelset_sphere]  # levelset_sphere last


def main(names: list[str]) -> None:
    common.run_benchmarks(BENCHMARKS, names, "run_all.json", "run_all")


if __name__ == "__main__":
    main(sys.argv[1:])
