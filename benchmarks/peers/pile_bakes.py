"""The whole bake of the 1000-box piles against MuJoCo's stepping, for compare.py.

    python3 benchmarks/peers/compare.py --pile-bakes-only            # this part alone
    .venv/bin/python benchmarks/peers/pile_bakes.py write pile OUT.toml   # the scene file it bakes

What a user waits for is `simbake bake`, not the solver: start-up (imports, the scene file,
the world), the rigid stages, the QA figures and the USD cache. Each round bakes the jittered
pile (scenes.py "pile": 0.5 m boxes from a 10x10x10 grid at 0.8 m, each tilted up to 20
degrees) and the aligned one, written as a scene file as benchmarks/core_instructions.py
writes it but at 60 fps, frames 1-301 (5 s), with `simbake bake SCENE -o OUT.usdc -q` at the
default settings, one process pinned to one CPU (so one solver thread, like the peers); and
runs MuJoCo on the same piles (run_mujoco.py, its 1/504 s step). In turns, so that both see
the same machine. The bake's time is its process's wall and CPU time (start-up included);
"solver alone" is the rigid stages of the bake's own profile (its QA sidecar); the deepest
overlap between boxes is the QA's figure over every frame (samples and separating axes,
world/quality.h). MuJoCo's time is its stepping alone (the model built before the clock).

Jolt Physics 5.5 is not on PyPI; its figures are the ones measured on this machine on the
jittered pile (shared/PLATFORM.md, 2026-11-23, one thread, default solver), quoted as
measured, as a share of MuJoCo's time in that run.
"""

from __future__ import annotations

import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
PILES = ["pile", "pile_aligned"]
FPS = 60
END_FRAME = 301
RIGID_STAGES = ["kinematic_bodies", "broad_phase", "collisions", "velocities", "contacts", "shock_propagation",
                "joints", "positions", "sleeping", "statistics"]
TARGET_RATIO = 0.13   # issue 35: the whole bake at most 0.13x MuJoCo's time
TARGET_OVERLAP_MM = 10.0
# Jolt 5.5 on the jittered pile (shared/PLATFORM.md, measured 2026-11-23): s per simulated s,
# its share of MuJoCo's time in that run, deepest overlap into the ground and between boxes
JOLT = [
    {"rate": "60 Hz", "seconds_per_second": 0.109, "of_mujoco": 0.029, "ground_mm": 132.0, "boxes_mm": 24.0},
    {"rate": "500 Hz", "seconds_per_second": 0.485, "of_mujoco": 0.129, "ground_mm": 16.0, "boxes_mm": 9.0},
]


def scene_text(name: str, fps: int = FPS, end_frame: int = END_FRAME) -> str:
    """The pile as a simbake scene file (needs NumPy: run with simbake's interpreter)."""
    from benchmarks.peers import scenes
    pile = scenes.build(name)
    lines = ["[scene]", f"fps = {fps}", "start_frame = 1", f"end_frame = {end_frame}", "",
             "[ground]", "height = 0.0", "friction = 0.5", ""]
    for i, b in enumerate(pile.bodies):
        lines += ["[[bodies]]", f'name = "box{i:04d}"',
                  f'shape = {{ type = "box", size = [{b.size[0]}, {b.size[1]}, {b.size[2]}] }}',
                  f"position = [{', '.join(repr(v) for v in b.position)}]",
                  f"orientation = [{', '.join(repr(q) for q in b.orientation)}]",
                  "density = 1000.0", "friction = 0.5", ""]
    return "\n".join(lines)


def bake_once(python: Path, scene: Path, folder: Path, cpu: int | None, env: dict, timeout: float) -> dict:
    """One `simbake bake` in its own process pinned to `cpu`: wall and CPU seconds, the
    QA's deepest box overlap and the bake's stage profile."""
    out = folder / f"{scene.stem}.usdc"
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    preexec = (lambda: os.sched_setaffinity(0, {cpu})) if cpu is not None else None
    start = time.perf_counter()
    try:
        proc = subprocess.run([str(python), "-m", "simbake", "bake", str(scene), "-o", str(out), "-q"],
                              capture_output=True, text=True, env=env, cwd=str(ROOT), timeout=timeout,
                              preexec_fn=preexec)
    except subprocess.TimeoutExpired:
        return {"error": f"timed out after {timeout:.0f} s"}
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        return {"error": f"exit {proc.returncode}: " + " | ".join(proc.stderr.strip().splitlines()[-4:])}
    qa = json.loads(out.with_suffix(".qa.json").read_text())
    profile = qa.get("profile", {})
    body = qa["summary"]["body_penetration"]
    return {"wall_seconds": wall,
            "cpu_seconds": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
            "solver_seconds": sum(profile.get(s, 0.0) for s in RIGID_STAGES),
            "qa_seconds": profile.get("quality"), "usd_seconds": profile.get("usd_writer"),
            "profile": profile, "overlap_mm": 1000.0 * body["worst"], "overlap_frame": body["frame"],
            "warnings": [line for line in proc.stderr.splitlines() if "warning" in line]}


def run(simbake_python: Path, mujoco_run, rounds: int, cpu: int | None, env: dict, timeout: float, log) -> dict:
    """`rounds` rounds, each: per pile, MuJoCo then the simbake bake. mujoco_run(scene) runs
    run_mujoco.py on the scene and returns its JSON line (compare.run_once)."""
    runs = {p: {"simbake": [], "mujoco": []} for p in PILES}
    with tempfile.TemporaryDirectory(prefix="pile-bakes-") as tmp:
        folder = Path(tmp)
        for name in PILES:
            made = subprocess.run([str(simbake_python), str(Path(__file__)), "write", name, str(folder / f"{name}.toml")],
                                  capture_output=True, text=True, env=env, cwd=str(ROOT))
            if made.returncode != 0:
                return {"error": f"writing {name}: {made.stderr.strip()[-200:]}"}
        for r in range(rounds):
            for name in PILES:
                m = mujoco_run(name)
                runs[name]["mujoco"].append(m)
                log(f"MuJoCo {name} round {r + 1}: " + (m.get("error") or f"{m['step_wall_seconds']:.1f} s wall, "
                                                         f"{m['step_cpu_seconds']:.1f} s CPU stepping"))
                s = bake_once(simbake_python, folder / f"{name}.toml", folder, cpu, env, timeout)
                runs[name]["simbake"].append(s)
                log(f"simbake bake {name} round {r + 1}: " + (s.get("error") or f"{s['wall_seconds']:.2f} s wall, "
                                                              f"{s['cpu_seconds']:.2f} s CPU, overlap {s['overlap_mm']:.1f} mm"))
    return {"rounds": rounds, "runs": runs, "summary": {p: summarize(runs[p]) for p in PILES}, "jolt": JOLT,
            "target_ratio": TARGET_RATIO, "target_overlap_mm": TARGET_OVERLAP_MM}


def summarize(runs: dict) -> dict:
    """Medians over the rounds, and the ratios within each round (then their median)."""
    pairs = [(s, m) for s, m in zip(runs["simbake"], runs["mujoco"]) if "error" not in s and "error" not in m]
    if not pairs:
        return {"error": next((x["error"] for x in runs["simbake"] + runs["mujoco"] if "error" in x), "not run")}
    med = lambda xs: statistics.median(xs)  # noqa: E731
    s0, m0 = pairs[0]
    return {
        "bake_wall": med([s["wall_seconds"] for s, _ in pairs]), "bake_cpu": med([s["cpu_seconds"] for s, _ in pairs]),
        "solver": med([s["solver_seconds"] for s, _ in pairs]),
        "qa": med([s["qa_seconds"] or 0.0 for s, _ in pairs]), "usd": med([s["usd_seconds"] or 0.0 for s, _ in pairs]),
        "mujoco_wall": med([m["step_wall_seconds"] for _, m in pairs]),
        "mujoco_cpu": med([m["step_cpu_seconds"] for _, m in pairs]),
        "ratio_wall": med([s["wall_seconds"] / m["step_wall_seconds"] for s, m in pairs]),
        "ratio_cpu": med([s["cpu_seconds"] / m["step_cpu_seconds"] for s, m in pairs]),
        "solver_ratio": med([s["solver_seconds"] / m["step_wall_seconds"] for s, m in pairs]),
        "overlap_mm": s0["overlap_mm"], "overlap_frame": s0["overlap_frame"],
        "overlap_same_every_round": all(s["overlap_mm"] == s0["overlap_mm"] for s, _ in pairs),
        "mujoco_overlap_mm": m0["accuracy"].get("penetration_boxes_mm"),
        "mujoco_ground_mm": m0["accuracy"].get("penetration_ground_mm"),
        "rounds": len(pairs),
    }


def markdown(result: dict) -> list[str]:
    """The section of peers.md."""
    if "error" in result:
        return ["## Whole bakes of the 1000-box piles", "", f"failed: {result['error']}", ""]
    f = lambda v, d=3: "-" if v is None else f"{v:.{d}g}"  # noqa: E731
    lines = ["## Whole bakes of the 1000-box piles against MuJoCo", "",
             f"`simbake bake` of each pile (60 fps, 5 s, default settings, pinned to one CPU), start-up, solver, QA "
             f"and USD included, against MuJoCo's stepping of the same pile, in turns; medians of "
             f"{result['rounds']} rounds, ratios taken within each round. The goal (issue 35): the whole bake at most "
             f"{TARGET_RATIO}x MuJoCo and the deepest overlap between boxes at most {TARGET_OVERLAP_MM:g} mm.", "",
             "| pile | bake wall s | bake CPU s | solver alone s | QA s | USD s | MuJoCo stepping wall / CPU s | "
             "bake / MuJoCo (wall, CPU) | solver / MuJoCo | deepest box overlap, QA (mm) | MuJoCo's (mm) |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for name in PILES:
        s = result["summary"][name]
        if "error" in s:
            lines.append(f"| {name} | failed: {s['error'][:80]} |" + " |" * 9)
            continue
        lines.append(f"| {name} | {f(s['bake_wall'])} | {f(s['bake_cpu'])} | {f(s['solver'])} | {f(s['qa'])} | "
                     f"{f(s['usd'])} | {f(s['mujoco_wall'])} / {f(s['mujoco_cpu'])} | "
                     f"{f(s['ratio_wall'], 2)}x, {f(s['ratio_cpu'], 2)}x | {f(s['solver_ratio'], 2)}x | "
                     f"{f(s['overlap_mm'], 2)} (frame {s['overlap_frame']}) | {f(s['mujoco_overlap_mm'])} |")
    lines += ["", "Jolt Physics 5.5 on the jittered pile (not on PyPI; measured on this machine, one thread, "
              "shared/PLATFORM.md 2026-11-23, against MuJoCo in the same run):", "",
              "| Jolt rate | s per simulated s | share of MuJoCo's time | deepest into the ground (mm) | between boxes (mm) |",
              "| --- | --- | --- | --- | --- |"]
    for j in JOLT:
        lines.append(f"| {j['rate']} | {j['seconds_per_second']} | {j['of_mujoco']}x | {j['ground_mm']:g} | {j['boxes_mm']:g} |")
    lines.append("")
    return lines


def main(argv: list[str]) -> int:
    if len(argv) == 3 and argv[0] == "write" and argv[1] in PILES:
        Path(argv[2]).write_text(scene_text(argv[1]))
        return 0
    print(__doc__)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
