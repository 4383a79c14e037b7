"""The drape's edge strain frame by frame with strain limiting off, so that what the limiter
would have to hold shows: with and without the cloth's contacts held in the implicit solve
(WorldSettings::cloth_contacts_in_solve).

    .venv/bin/python benchmarks/cloth/strain_trace.py [--n 33] [--seconds 3] [--stiffness 2000]

The drape of drape_spec.py (self-collision on, friction 0.4), strain_limit 0. Per setting:
the largest edge strain over the run and the frame it came at, the frames over 10%, and the
median and largest of each frame's largest strain after 1 s (the cloth at rest on the
sphere and the ground). Edge strains are measured here from the frames' positions.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import drape_spec as spec  # noqa: E402
import run_simbake  # noqa: E402


def trace(n: int, seconds: float, held: bool, stiffness: float = spec.STRETCH) -> list[float]:
    world = run_simbake.build(n, 1.0 / 120.0, 1e-3, "implicit", "springs", contacts_in_solve=held,
                              stretch=stiffness, strain_limit=0.0)
    vertices, triangles = spec.grid(n)
    edges = np.unique(np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]),
                              axis=1), axis=0)
    rest = np.linalg.norm(vertices[edges[:, 1]] - vertices[edges[:, 0]], axis=1)
    strains = []
    for _ in range(int(round(seconds * spec.FPS))):
        world.step_frame(1.0 / spec.FPS)
        x = world.cloth_state(0)[0]
        strains.append(float((np.linalg.norm(x[edges[:, 1]] - x[edges[:, 0]], axis=1) / rest - 1.0).max()))
    return strains


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=int, default=33)
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--stiffness", type=float, default=spec.STRETCH, help="sheet stiffness (N/m)")
    args = parser.parse_args()
    print(f"drape {args.n} x {args.n}, {args.seconds:g} s, {args.stiffness:g} N/m, strain limiting off")
    for held in (True, False):
        s = trace(args.n, args.seconds, held, args.stiffness)
        rest = s[spec.FPS:]
        print(f"contacts in the solve {'on ' if held else 'off'}: peak {max(s):.3f} at frame {s.index(max(s)) + 1}, "
              f"{sum(v > 0.1 for v in s)} frames over 10%, after 1 s median {statistics.median(rest):.3f} "
              f"largest {max(rest):.3f}")


if __name__ == "__main__":
    main()
