"""Box on a slope: sliding velocity and sticking creep under tilted gravity.

A 0.5 m cube (10 kg) rests on the ground (y = 0) while gravity is tilted by a = 30 degrees:
g = 9.81 (sin a, -cos a, 0). Body and ground have the same friction mu (the pair's friction
is their geometric mean, so mu itself) and restitution 0.
- mu = 0.3 < tan a: the box slides; v(t) = g (sin a - mu cos a) t, 4.7126 m/s at t = 2 s.
- mu = 0.7 > tan a = 0.577: the box must stick; any motion along the slope is creep.

Measured per substep count (fixed and automatic) with World.step_frame, state read at frame
boundaries: the relative error of the velocity along the slope at t = 2 s (mu 0.3); the
creep distance over 3 s and the creep speed over the last second (mu 0.7); and, for both,
how far the box turned (rotation angle, degrees) and drifted sideways (|z|, m), which the
exact answer has at zero. Wall time per simulated second over the same 2 s and 3 s,
median of 5, one thread.
"""

from __future__ import annotations

import math

import numpy as np

import common
from common import AUTOMATIC, FPS, SUBSTEPS, Result, Series, _core

NAME = "rigid_slide"
SIZE = (0.5, 0.5, 0.5)
MASS = 10.0
ANGLE = math.radians(30.0)
G = 9.81
MU_SLIDE, SLIDE_SECONDS = 0.3, 2.0
MU_STICK, STICK_SECONDS = 0.7, 3.0


def make_world(mu: float) -> "_core.World":
    world = _core.World(gravity=common.vec(G * math.sin(ANGLE), -G * math.cos(ANGLE), 0.0))
    world.set_ground(height=0.0, friction=mu, restitution=0.0)
    common.add_box(world, SIZE, MASS, (0.0, 0.5 * SIZE[1], 0.0), friction=mu, restitution=0.0)
    return world


def rotation_degrees(q0: np.ndarray, q1: np.ndarray) -> float:
    rotvec = common.rotation_vector(common.quat_multiply(q1, common.quat_conjugate(q0)))
    return float(np.degrees(np.linalg.norm(rotvec)))


def simulate(mu: float, substeps: int, seconds: float) -> dict:
    """Positions and velocities at every frame boundary."""
    world = make_world(mu)
    frames = int(round(seconds * FPS))
    s = common.body_state(world, 0)
    x, v, q, counts = [s["center_of_mass"]], [s["linear_velocity"]], [s["orientation"]], []
    for _ in range(frames):
        counts.append(world.step_frame(1.0 / FPS, substeps))
        s = common.body_state(world, 0)
        x.append(s["center_of_mass"]), v.append(s["linear_velocity"]), q.append(s["orientation"])
    return {"x": np.array(x), "v": np.array(v), "q": np.array(q), "counts": counts,
            "impulses_per_substep": world.statistics()["impulses"] / sum(counts),
            "max_penetration_last_frame": world.statistics()["max_penetration"],
            "finite": world.statistics()["finite"]}


def measure(substeps: int) -> dict:
    slide = simulate(MU_SLIDE, substeps, SLIDE_SECONDS)
    expected = G * (math.sin(ANGLE) - MU_SLIDE * math.cos(ANGLE)) * SLIDE_SECONDS
    velocity = float(slide["v"][-1, 0])
    stick = simulate(MU_STICK, substeps, STICK_SECONDS)
    creep = float(stick["x"][-1, 0] - stick["x"][0, 0])
    creep_speed = float(stick["x"][-1, 0] - stick["x"][-1 - FPS, 0])  # over the last second
    counts = slide["counts"] + stick["counts"]
    return {
        "substeps": substeps,
        "substeps_per_frame": {"mean": float(np.mean(counts)), "min": int(min(counts)), "max": int(max(counts))},
        "slide": {"mu": MU_SLIDE, "t": SLIDE_SECONDS, "velocity": velocity, "expected": expected,
                  "relative_error": (velocity - expected) / expected,
                  "rotation_degrees": rotation_degrees(slide["q"][0], slide["q"][-1]),
                  "sideways_drift": float(abs(slide["x"][-1, 2] - slide["x"][0, 2])),
                  "impulses_per_substep": slide["impulses_per_substep"],
                  "max_penetration_last_frame": slide["max_penetration_last_frame"]},
        "stick": {"mu": MU_STICK, "t": STICK_SECONDS, "creep": creep, "creep_speed_last_second": creep_speed,
                  "creep_speed_over_g_sin_a_dt": creep_speed / (G * math.sin(ANGLE) / FPS / np.mean(stick["counts"])),
                  "rotation_degrees": rotation_degrees(stick["q"][0], stick["q"][-1]),
                  "sideways_drift": float(abs(stick["x"][-1, 2] - stick["x"][0, 2])),
                  "impulses_per_substep": stick["impulses_per_substep"],
                  "max_penetration_last_frame": stick["max_penetration_last_frame"]},
    }


def run() -> Result:
    data, rows = [], []
    for substeps in SUBSTEPS + [AUTOMATIC]:
        m = measure(substeps)
        m["slide"]["timing"] = common.time_stepping(lambda: make_world(MU_SLIDE), substeps,
                                                    int(round(SLIDE_SECONDS * FPS)), repeats=5)
        m["stick"]["timing"] = common.time_stepping(lambda: make_world(MU_STICK), substeps,
                                                    int(round(STICK_SECONDS * FPS)), repeats=5)
        data.append(m)
        label = common.substeps_label(substeps, m["substeps_per_frame"]["mean"] if substeps == AUTOMATIC else None)
        sl, st = m["slide"], m["stick"]
        rows.append([label, f"{sl['velocity']:.4f}", 100.0 * sl["relative_error"], sl["rotation_degrees"],
                     1000.0 * st["creep"], 1000.0 * st["creep_speed_last_second"], st["rotation_degrees"],
                     f"{sl['impulses_per_substep']:.0f} / {st['impulses_per_substep']:.0f}",
                     sl["timing"]["per_simulated_second"], st["timing"]["per_simulated_second"]])
    fixed = [d for d in data if d["substeps"] > 0]
    auto = [d for d in data if d["substeps"] == AUTOMATIC]
    labels = [str(d["substeps"]) for d in fixed]
    auto_labels = [common.substeps_label(0, d["substeps_per_frame"]["mean"]) for d in auto]
    series = [
        Series(f"mu {MU_SLIDE}: |relative error| of v(2 s)", [d["slide"]["timing"]["per_simulated_second"] for d in fixed],
               [abs(d["slide"]["relative_error"]) for d in fixed], labels),
        Series(f"mu {MU_STICK}: creep over 3 s (m)", [d["stick"]["timing"]["per_simulated_second"] for d in fixed],
               [d["stick"]["creep"] for d in fixed], labels, "s"),
        Series(f"mu {MU_SLIDE}, automatic", [d["slide"]["timing"]["per_simulated_second"] for d in auto],
               [abs(d["slide"]["relative_error"]) for d in auto], auto_labels, "*"),
        Series(f"mu {MU_STICK}, automatic", [d["stick"]["timing"]["per_simulated_second"] for d in auto],
               [d["stick"]["creep"] for d in auto], auto_labels, "P"),
    ]
    expected = G * (math.sin(ANGLE) - MU_SLIDE * math.cos(ANGLE)) * SLIDE_SECONDS
    return Result(
        name=NAME,
        title="Box (0.5 m, 10 kg) under gravity tilted 30 deg: slides at mu 0.3, sticks at mu 0.7",
        data={"size": SIZE, "mass": MASS, "angle_degrees": 30.0, "fps": FPS, "runs": data},
        table_headers=["substeps/frame", "mu 0.3: v(2 s) m/s", "v err %", "mu 0.3: turned deg",
                       "mu 0.7: creep 3 s mm", "creep mm/s (last s)", "mu 0.7: turned deg",
                       "impulses / substep (0.3 / 0.7)",
                       "wall s / sim s (0.3)", "wall s / sim s (0.7)"],
        table_rows=rows,
        series=series,
        xlabel="wall seconds per simulated second (one thread, median of 5)",
        ylabel="mu 0.3: |relative velocity error|   mu 0.7: creep distance (m)",
        notes=[f"mu 0.3 expected v(2 s) = g (sin a - mu cos a) t = {expected:.4f} m/s; mu 0.7 expected creep 0",
               "turned: rotation angle of the box between t = 0 and the end (the exact answer does not turn)",
               "impulses / substep: collision and contact impulses the world applied, per substep "
               "(the contact stage stops at 20 sweeps, about 25 bottom samples x 20 = 500)",
               "creep speed / (g sin a dt) for each run is in the JSON (stick.creep_speed_over_g_sin_a_dt)"],
    )


if __name__ == "__main__":
    common.main(run)
