"""Bouncing sphere: apex heights against e^(2k) h0, for substeps per frame.

A sphere (r 0.1 m, 1 kg, restitution 0.5, friction 0) is dropped with its bottom h0 = 1.0 m
above the ground (restitution 0, so the pair's restitution is max(0.5, 0) = 0.5). Without
air the k-th apex (bottom height) is e^(2k) h0: 0.25, 0.0625, 0.015625 m.

Measured per substep count (fixed, and the automatic rule):
- the first three apex heights, found by stepping with World.step(dt) and watching v_y turn
  from positive to non-positive; the apex is the higher of the two states around the turn
  ("sampled", what a cache at substep rate would show), and also y + v^2/(2g) from the last
  rising state ("ballistic", the apex that state implies, free of sampling error);
- the same errors over 8 drop heights h0 = 1.0 ... 1.175 m (references scaled with h0): the
  impact falls at a different point inside a substep for each, and the apex error depends on
  that phase, so the worst case over the 8 shows the trend that a single drop hides;
- the wall time per simulated second of World.step_frame over the same 30 frames (1.25 s,
  past the third apex), median of 5 repeats, one thread.
"""

from __future__ import annotations

import numpy as np

import common
from common import FPS, AUTOMATIC, SUBSTEPS, Result, Series, _core

NAME = "rigid_bounce"
RADIUS = 0.1
MASS = 1.0
H0 = 1.0            # initial height of the sphere's bottom above the ground (m)
E = 0.5             # restitution
G = 9.81
FRAMES = 30         # 1.25 s: the third apex is at ~1.18 s
APEXES = 3
REFERENCE = [E ** (2 * k) * H0 for k in range(1, APEXES + 1)]


ENVELOPE_H0 = [H0 + 0.025 * i for i in range(8)]  # spans one impact phase at 1 substep


def make_world(h0: float = H0) -> "_core.World":
    world = _core.World(gravity=common.vec(0.0, -G, 0.0))
    world.set_ground(height=0.0, friction=0.0, restitution=0.0)
    common.add_sphere(world, RADIUS, MASS, (0.0, h0 + RADIUS, 0.0), friction=0.0, restitution=E)
    return world


def measure(substeps: int, h0: float = H0) -> dict:
    world = make_world(h0)
    reference = [r * h0 / H0 for r in REFERENCE]
    sampled, ballistic, times, counts = [], [], [], []
    t = 0.0
    state = common.body_state(world, 0)
    y_prev, v_prev = state["center_of_mass"][1], state["linear_velocity"][1]
    for _ in range(FRAMES):
        n = common.frame_substeps(world, substeps)
        counts.append(n)
        dt = 1.0 / FPS / n
        for _ in range(n):
            world.step(dt)
            t += dt
            state = common.body_state(world, 0)
            y, v = state["center_of_mass"][1], state["linear_velocity"][1]
            if v_prev > 0.0 and v <= 0.0 and len(sampled) < APEXES:
                sampled.append(max(y_prev, y) - RADIUS)
                ballistic.append(y_prev + v_prev ** 2 / (2.0 * G) - RADIUS)
                times.append(t - dt if y_prev >= y else t)
            y_prev, v_prev = y, v
    missing = APEXES - len(sampled)
    sampled += [float("nan")] * missing
    ballistic += [float("nan")] * missing
    times += [float("nan")] * missing
    rel = [(h - r) / r for h, r in zip(sampled, reference)]
    rel_ballistic = [(h - r) / r for h, r in zip(ballistic, reference)]
    return {
        "substeps": substeps,
        "h0": h0,
        "substeps_per_frame": {"mean": float(np.mean(counts)), "min": int(min(counts)), "max": int(max(counts))},
        "apex_sampled": sampled,
        "apex_ballistic": ballistic,
        "apex_times": times,
        "relative_error_sampled": rel,
        "relative_error_ballistic": rel_ballistic,
        "max_abs_relative_error_sampled": float(np.max(np.abs(rel))),
        "max_abs_relative_error_ballistic": float(np.max(np.abs(rel_ballistic))),
        "max_penetration_last_frame": world.statistics()["max_penetration"],
    }


def run() -> Result:
    rows, data = [], []
    for substeps in SUBSTEPS + [AUTOMATIC]:
        m = measure(substeps)
        others = [measure(substeps, h0) for h0 in ENVELOPE_H0]
        m["envelope"] = {
            "h0": ENVELOPE_H0,
            "max_abs_relative_error_sampled": [o["max_abs_relative_error_sampled"] for o in others],
            "worst_sampled": max(o["max_abs_relative_error_sampled"] for o in others),
            "worst_ballistic": max(o["max_abs_relative_error_ballistic"] for o in others),
        }
        m["timing"] = common.time_stepping(make_world, substeps, FRAMES, repeats=5)
        data.append(m)
        label = common.substeps_label(substeps, m["substeps_per_frame"]["mean"] if substeps == AUTOMATIC else None)
        rows.append([label] + [100.0 * e for e in m["relative_error_sampled"]]
                    + [100.0 * m["max_abs_relative_error_ballistic"], 100.0 * m["envelope"]["worst_sampled"],
                       m["timing"]["per_simulated_second"]])
    fixed = [d for d in data if d["substeps"] > 0]
    auto = [d for d in data if d["substeps"] == AUTOMATIC]
    auto_label = [common.substeps_label(0, d["substeps_per_frame"]["mean"]) for d in auto]
    series = [
        Series("sampled apex, fixed substeps", [d["timing"]["per_simulated_second"] for d in fixed],
               [d["max_abs_relative_error_sampled"] for d in fixed], [str(d["substeps"]) for d in fixed]),
        Series("sampled apex, worst of 8 drop heights", [d["timing"]["per_simulated_second"] for d in fixed],
               [d["envelope"]["worst_sampled"] for d in fixed], [str(d["substeps"]) for d in fixed], "^"),
        Series("sampled apex, automatic", [d["timing"]["per_simulated_second"] for d in auto],
               [d["max_abs_relative_error_sampled"] for d in auto], auto_label, "*"),
    ]
    return Result(
        name=NAME,
        title="Bouncing sphere (r 0.1 m, e 0.5, dropped from 1 m): apex heights vs e^(2k)",
        data={"reference_apex": REFERENCE, "fps": FPS, "frames": FRAMES, "runs": data},
        table_headers=["substeps/frame", "apex 1 err %", "apex 2 err %", "apex 3 err %",
                       "ballistic max err %", "worst of 8 drops err %", "wall s / sim s"],
        table_rows=rows,
        series=series,
        xlabel="wall seconds per simulated second (one thread, median of 5)",
        ylabel="largest |relative error| of the first three apex heights",
        notes=[f"reference apex heights (bottom above ground): {', '.join(f'{r:g}' for r in REFERENCE)} m",
               "apex err: sampled apex (higher state around the v_y sign change) vs reference; "
               "ballistic: y + v^2/(2g) from the last rising state (no sampling error)",
               "worst of 8 drops: largest |error| of the sampled apexes over h0 = "
               f"{ENVELOPE_H0[0]:g} ... {ENVELOPE_H0[-1]:g} m (the impact phase inside a substep varies)",
               "auto: the world's automatic rule; the mean substeps per frame it picked is in brackets"],
    )


if __name__ == "__main__":
    common.main(run)
