"""The cloth-under-a-keyed-body family (issue 30, item 6): a keyed kinematic body presses a
cloth onto something that cannot give, and keeps going. The cloth cannot be in two places;
what the step does then must cost a bounded amount of work per frame, never a hang.

- shape   a box (0.3 m) or a sphere (r 0.15 m), kinematic, keyed straight down from y 0.8
- speed   1, 30 or 1000 m/s (keys 10 s apart: it never stops)
- onto    "ground": a 1 m, 32 x 32 sheet at y 0.5 over the ground (it falls onto it first; at
          1 m/s the body reaches it at frame 17); "pins": the same sheet with no ground,
          pinned along its whole border (a trampoline the body pushes through)

36 frames at 24 fps (1.5 s), automatic substeps, one thread. Each case runs in its own
process, frame by frame, with a deadline (--timeout, 300 s by default); per frame it records
the wall time and the work counters of World.statistics() (substeps, cloth steps,
self-collision candidates and tests, impact-zone rounds, the budgets' fallbacks), and at the
end the worst strain, self-intersections and cloth penetration of World.quality().

    .venv/bin/python benchmarks/stress/cloth_press.py                     # all 12 cases
    .venv/bin/python benchmarks/stress/cloth_press.py --only box-1-ground --tag before
    .venv/bin/python benchmarks/stress/cloth_press.py --scenes DIR        # write the TOML scenes only

Writes benchmarks/results/cloth_press[_TAG].{json,md}.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "benchmarks" / "results"

SHAPES = ("box", "sphere")
SPEEDS = (1.0, 30.0, 1000.0)
ONTO = ("ground", "pins")
FRAMES = 36
RESOLUTION = 32
# the counters of World.statistics() recorded per frame (differences over the frame)
COUNTERS = ("substeps", "cloth_steps", "self_collision_searches", "self_collision_candidates",
            "self_collision_tests", "impact_zone_rounds", "impact_zone_vertices", "cloth_held_still",
            "self_collision_over_budget", "impact_zone_yields", "cloth_let_in", "cloth_gave")


def case_name(shape: str, speed: float, onto: str) -> str:
    return f"{shape}-{speed:g}-{onto}"


def press_scene(shape: str, speed: float, onto: str, frames: int = FRAMES, substeps: int = 0,
                resolution: int = RESOLUTION, sheet: float = 0.5, gap: float = 0.15) -> str:
    """The TOML text of one member of the family: the sheet at height `sheet`, the body's
    lowest point `gap` above it (the tests' smaller, shorter variant changes these)."""
    n = resolution
    body = ('shape = { type = "box", size = [0.3, 0.3, 0.3] }' if shape == "box"
            else 'shape = { type = "sphere", radius = 0.15 }')
    top = sheet + gap + 0.15  # the body's centre
    border = [j * n + i for j in range(n) for i in range(n) if i in (0, n - 1) or j in (0, n - 1)]
    lines = [
        f"# {case_name(shape, speed, onto)}: benchmarks/stress/cloth_press.py",
        "[scene]", "fps = 24", "start_frame = 1", f"end_frame = {frames + 1}", "",
        "[solver]", f"substeps = {substeps}", "",
    ]
    if onto == "ground":
        lines += ["[ground]", "height = 0.0", "friction = 0.5", ""]
    lines += [
        "[[bodies]]", 'name = "press"', body, f"position = [0.0, {top:.6g}, 0.0]", "kinematic = true",
        f"keys = [{{ time = 0.0 }}, {{ time = 10.0, position = [0.0, {top - 10.0 * speed:.6g}, 0.0] }}]", "",
        "[[cloths]]", 'name = "sheet"', f"grid = {{ size = [1.0, 1.0], resolution = [{n}, {n}] }}",
        f"position = [0.0, {sheet:.6g}, 0.0]",
    ]
    if onto == "pins":
        lines.append(f"pinned = {border}")
    return "\n".join(lines) + "\n"


def child(scene_path: str, frames: int) -> None:
    """Steps the scene frame by frame, one JSON line per frame on stdout."""
    import numpy as np

    import simbake
    from simbake.assets import load_assets, load_cloth
    from simbake.simulate import build_world

    scene = simbake.load_scene(scene_path)
    assets = load_assets(scene)
    cloths = [load_cloth(scene, i) for i in range(len(scene.cloths))]
    world = build_world(scene, assets, cloths, threads=1)
    last = world.statistics()
    for frame in range(frames):
        start = time.perf_counter()
        world.step_frame(1.0 / scene.fps, scene.substeps)
        wall = time.perf_counter() - start
        stats = world.statistics()
        quality = world.quality()["cloths"][0]
        x, v, _ = world.cloth_state(0)
        out = {"frame": scene.start_frame + frame + 1, "wall": wall, "finite": bool(stats["finite"]),
               "strain": float(quality["max_strain"]), "crossings": int(quality["self_intersections"]),
               "penetration": float(max(quality["vertex_penetration"][0], quality["edge_penetration"][0])),
               "fastest": float(np.linalg.norm(v, axis=1).max()), "lowest": float(x[:, 1].min())}
        for k in COUNTERS:
            if k in stats:
                out[k] = int(stats[k] - last[k])
        last = stats
        print(json.dumps(out), flush=True)
        if not stats["finite"]:
            break


def run_case(shape: str, speed: float, onto: str, timeout: float, frames: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "press.toml"
        path.write_text(press_scene(shape, speed, onto, frames))
        env = dict(os.environ, SIMBAKE_CACHE_DIR=str(Path(tmp) / "cache"))
        start = time.perf_counter()
        python = [sys.executable] + (["-S"] if sys.flags.no_site else [])  # (a frozen build on PYTHONPATH)
        process = subprocess.Popen(python + [__file__, "--child", str(path), str(frames)],
                                   stdout=subprocess.PIPE, text=True, env=env)
        rows: list[dict] = []
        status = "done"
        try:
            import selectors

            selector = selectors.DefaultSelector()
            selector.register(process.stdout, selectors.EVENT_READ)
            while True:
                left = timeout - (time.perf_counter() - start)
                if left <= 0:
                    status = f"timeout ({timeout:g} s)"
                    break
                if not selector.select(left):
                    continue
                line = process.stdout.readline()
                if not line:
                    break
                rows.append(json.loads(line))
        finally:
            if process.poll() is None:
                process.kill()
            process.wait()
        if status == "done" and (process.returncode != 0 or len(rows) < frames):
            status = "non-finite" if rows and not rows[-1]["finite"] else f"exit {process.returncode}"
        return {"status": status, "wall_seconds": time.perf_counter() - start, "frames": rows}


def summary(result: dict) -> dict:
    rows = result["frames"]
    out = {"status": result["status"], "frames_done": len(rows)}
    if not rows:
        return out
    for key in ("wall",) + COUNTERS:
        if key in rows[0]:
            out["max_" + key] = max(r[key] for r in rows)
    out["total_wall"] = sum(r["wall"] for r in rows)
    for key in ("strain", "crossings", "penetration", "fastest"):
        out["worst_" + key] = max(r[key] for r in rows)
    out["lowest"] = min(r["lowest"] for r in rows)
    return out


def write_markdown(results: dict, path: Path, command: str) -> None:
    lines = [f"# Cloth under a keyed body (`benchmarks/stress/cloth_press.py`)", "",
             f"Command: `{command}`", f"Machine: {results['machine']}; commit {results['commit']}", "",
             "Per case, the worst frame: wall seconds (one thread, a shared 2-CPU machine: noisy), "
             "substeps, cloth steps, self-collision candidates found and pairs put through the "
             "continuous test, impact-zone rounds; the budgets' fallbacks taken over the run; the "
             "worst strain, layer crossings and cloth penetration at any frame end.", "",
             "| case | status | frames | worst frame s | total s | substeps | cloth steps | candidates | tests | zone rounds | "
             "fallbacks (zones held over the ground / let in / past 3x the limit / over budget) | held still | strain | crossings | penetration (mm) |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for name, r in results["cases"].items():
        s = r["summary"]
        if s["frames_done"] == 0:
            lines.append(f"| {name} | {s['status']} | 0 |" + " - |" * 12)
            continue
        rows = r["frames"]
        fallbacks = " / ".join(str(sum(row.get(k, 0) for row in rows)) for k in
                               ("impact_zone_yields", "cloth_let_in", "cloth_gave", "self_collision_over_budget"))
        stills = sum(row.get("cloth_held_still", 0) for row in rows)
        lines.append(
            f"| {name} | {s['status']} | {s['frames_done']} | {s['max_wall']:.3g} | {s['total_wall']:.3g} | "
            f"{s['max_substeps']} | {s['max_cloth_steps']} | {s['max_self_collision_candidates']:,} | "
            f"{s['max_self_collision_tests']:,} | {s['max_impact_zone_rounds']} | {fallbacks} | {stills} | "
            f"{s['worst_strain']:.3g} | {s['worst_crossings']} | {1000 * s['worst_penetration']:.3g} |")
    path.write_text("\n".join(lines) + "\n")


def write_comparison(before: dict, after: dict, path: Path) -> None:
    """One table of both runs: per case the worst frame's wall time and work, before and after."""
    def cell(r: dict | None, key: str, fmt: str = "{:,}") -> str:
        if r is None or r["summary"]["frames_done"] == 0:
            return "-"
        value = r["summary"].get(key)
        return "-" if value is None else fmt.format(value)

    lines = ["# Cloth under a keyed body, before and after (`benchmarks/stress/cloth_press.py`)", "",
             f"Before: `{before['command']}` on {before['commit']}; after: `{after['command']}` on "
             f"{after['commit']}. {after['machine']}, one thread each, the other CPU busy with "
             "other work (wall times are noisy; the counters are not).", "",
             "Worst frame of each case (36 frames at 24 fps, or those done before the deadline): wall "
             "seconds, cloth steps, self-collision candidate pairs found and impact-zone rounds in "
             "that frame's worst, and the case's fallbacks over the run (after: zones held over the "
             "ground / steps that let a body in / steps past 3x the strain limit / steps over a "
             "budget / steps held still).", "",
             "| case | before: status, frames | worst frame s | cloth steps | candidates | after: status | "
             "worst frame s | total s | cloth steps | candidates | zone rounds | fallbacks | end strain |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for name, a in after["cases"].items():
        b = before["cases"].get(name)
        rows = a["frames"]
        fallbacks = " / ".join(str(sum(row.get(k, 0) for row in rows)) for k in
                               ("impact_zone_yields", "cloth_let_in", "cloth_gave", "self_collision_over_budget",
                                "cloth_held_still"))
        end = f"{rows[-1]['strain']:.3g}" if rows else "-"
        lines.append(
            f"| {name} | {b['summary']['status'] if b else '-'}, {b['summary']['frames_done'] if b else '-'} | "
            f"{cell(b, 'max_wall', '{:.3g}')} | {cell(b, 'max_cloth_steps')} | "
            f"{cell(b, 'max_self_collision_candidates')} | {a['summary']['status']} | "
            f"{cell(a, 'max_wall', '{:.3g}')} | {cell(a, 'total_wall', '{:.3g}')} | {cell(a, 'max_cloth_steps')} | "
            f"{cell(a, 'max_self_collision_candidates')} | {cell(a, 'max_impact_zone_rounds')} | {fallbacks} | {end} |")
    path.write_text("\n".join(lines) + "\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--only", nargs="*", help="case names (shape-speed-onto, e.g. box-1-ground)")
    parser.add_argument("--timeout", type=float, default=300.0, help="seconds per case")
    parser.add_argument("--frames", type=int, default=FRAMES)
    parser.add_argument("--tag", default="", help="results go to cloth_press_TAG.{json,md}")
    parser.add_argument("--scenes", help="write the scenes' TOML files into this folder and stop")
    parser.add_argument("--compare", nargs=2, metavar=("BEFORE", "AFTER"),
                        help="write cloth_press.md from two runs' tags and stop")
    parser.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args.child[0], int(args.child[1]))
        return
    if args.compare:
        runs = [json.loads((RESULTS / f"cloth_press_{tag}.json").read_text()) for tag in args.compare]
        write_comparison(*runs, RESULTS / "cloth_press.md")
        return
    cases = [(s, v, o) for s in SHAPES for v in SPEEDS for o in ONTO]
    if args.scenes:
        folder = Path(args.scenes)
        folder.mkdir(parents=True, exist_ok=True)
        for c in cases:
            (folder / f"{case_name(*c)}.toml").write_text(press_scene(*c, args.frames))
        return
    if args.only:
        cases = [c for c in cases if case_name(*c) in args.only]
    stem = "cloth_press" + (f"_{args.tag}" if args.tag else "")
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "core", "bindings"],
                           capture_output=True, text=True).stdout.strip()
    command = "python benchmarks/stress/cloth_press.py " + " ".join(sys.argv[1:])
    results = {"command": command.strip(), "commit": commit + (" (core modified)" if dirty else ""),
               "machine": f"{platform.node()}, {os.cpu_count()} CPUs", "timeout": args.timeout, "cases": {}}
    for c in cases:
        name = case_name(*c)
        r = run_case(*c, args.timeout, args.frames)
        r["summary"] = summary(r)
        results["cases"][name] = r
        s = r["summary"]
        print(f"{name:20s} {s['status']:16s} frames {s['frames_done']:3d} worst frame "
              f"{s.get('max_wall', float('nan')):8.3f} s  substeps {s.get('max_substeps', '-')}  "
              f"candidates {s.get('max_self_collision_candidates', '-')}", flush=True)
        (RESULTS / f"{stem}.json").write_text(json.dumps(results, indent=1))
    write_markdown(results, RESULTS / f"{stem}.md", results["command"])
    print(f"wrote {RESULTS / stem}.md")


if __name__ == "__main__":
    main()
