"""Run the scene-level rigid benchmarks and write benchmarks/results/rigid_<name>.{json,md,png}.

    .venv/bin/python benchmarks/rigid/run_all.py                  # all of them (~4-8 min)
    .venv/bin/python benchmarks/rigid/run_all.py rigid_stacks     # only the named ones

Also writes results/rigid_run_all.json with the time each took. Nothing here pins the
process to one CPU: worlds are built with threads=1, the ring-toss bakes run pinned in child
processes and every pile run is its own child process, so the order does not matter.
"""

from __future__ import annotations

import sys

import common_rigid as cr
from common_rigid import common
import contact_accuracy
import piles
import ring_toss
import stacks

BENCHMARKS = [contact_accuracy, stacks, ring_toss, piles]


def main(names: list[str]) -> None:
    common.run_benchmarks(BENCHMARKS, names, "rigid_run_all.json", "rigid/run_all",
                          extra={"core_module": cr.core_module_info()})


if __name__ == "__main__":
    main(sys.argv[1:])
