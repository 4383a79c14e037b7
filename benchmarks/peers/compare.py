"""Side-by-side rigid-body benchmark: simbake, PyBullet, MuJoCo and Blender on the same scenes.

    python3 benchmarks/peers/compare.py                  # everything (see README.md for the time)
    python3 benchmarks/peers/compare.py --quick          # short durations, one run each
    python3 benchmarks/peers/compare.py --engines simbake mujoco --scenes tower drop
    python3 benchmarks/peers/compare.py --seconds pyramid=5 pile=2 --simbake-pile-seconds 5
    python3 benchmarks/peers/compare.py --scenes pile_meshes --cpu 1   # pile.toml's 200 meshes
    python3 benchmarks/peers/compare.py --pile-bakes-only --cpu 1      # the piles' whole bakes against MuJoCo

Each engine runs in its own interpreter (simbake: /work/main/.venv; PyBullet and MuJoCo:
benchmarks/peers/.venv-peers; Blender: benchmarks/peers/.venv-bpy), one subprocess per run,
pinned to one CPU with OMP/BLAS/TBB threads set to 1; every script times only its stepping.
Timings are the median of --repeats runs (default 3); a run whose stepping took more than
--slow seconds is not repeated. With simbake, MuJoCo and a 1000-box pile among the scenes,
the whole `simbake bake` of both piles is also timed against MuJoCo, in turns (pile_bakes.py).
Writes benchmarks/results/peers.{json,md,png}.
Needs only the standard library to run; the chart is drawn with the matplotlib of
.venv-peers (or of the main venv).
"""

from __future__ import annotations

import argparse
import ast
import datetime
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

import pile_bakes

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
RESULTS = ROOT / "benchmarks" / "results"

ENGINES = {
    "simbake": (ROOT / ".venv" / "bin" / "python", HERE / "run_simbake.py"),
    "pybullet": (HERE / ".venv-peers" / "bin" / "python", HERE / "run_pybullet.py"),
    "mujoco": (HERE / ".venv-peers" / "bin" / "python", HERE / "run_mujoco.py"),
    "blender": (HERE / ".venv-bpy" / "bin" / "python", HERE / "run_blender.py"),
}
LABELS = {"simbake": "simbake", "pybullet": "PyBullet", "mujoco": "MuJoCo", "blender": "Blender (bpy)"}
SCENE_ORDER = ["tower", "pyramid", "pile", "pile_aligned", "pile216", "pile_meshes", "drop", "incline_slide",
               "incline_stick"]
SCENE_LABELS = {
    "tower": "(a) tower, 10 boxes",
    "pyramid": "(c) pyramid, 120 boxes",
    "pile": "(b) pile, 1000 boxes",
    "pile_aligned": "(b) pile, 1000 aligned boxes",
    "pile216": "(b') pile, 216 boxes",
    "drop": "(d) sphere drop, e 0.5",
    "incline_slide": "(e) incline 30 deg, mu 0.5",
    "incline_stick": "(e) incline 30 deg, mu 0.7",
    "pile_meshes": "(f) mesh pile, pile.toml: 200 tori, L-shapes, spheres",
}


def scene_label(payload: dict, scene: str) -> str:
    """The scene's label with the simulated seconds most engines ran."""
    spans = [payload["results"][e][scene]["simulated_seconds"] for e in payload["engines"]
             if "error" not in payload["results"][e][scene]]
    span = statistics.mode(spans) if spans else None
    return SCENE_LABELS.get(scene, scene) + (f", {span:g} s" if span else "")
QUICK_SECONDS = {"tower": 2.0, "pyramid": 2.0, "pile": 1.0, "pile_aligned": 1.0, "pile216": 2.0, "pile_meshes": 1.0}
# extra runs (once each): settings that change an engine's answer a lot
EXTRAS = [
    ("blender", "drop", ["--substeps", "20"], "20 substeps per frame"),
    ("blender", "drop", ["--substeps", "40"], "40 substeps per frame"),
    ("blender", "drop", ["--substeps", "100"], "100 substeps per frame"),
    ("blender", "tower", ["--default-damping"], "default damping (linear 0.04, angular 0.1)"),
    ("blender", "pyramid", ["--default-damping"], "default damping (linear 0.04, angular 0.1)"),
    ("blender", "pile_meshes", ["--mesh-shape", "MESH"], "MESH collision shape (Bullet GImpact) instead of COMPOUND"),
]
THREAD_VARIABLES = ["OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS",
                    "VECLIB_MAXIMUM_THREADS", "TBB_NUM_THREADS", "BLIS_NUM_THREADS"]


def child_environment() -> dict:
    env = dict(os.environ)
    for name in THREAD_VARIABLES:
        env[name] = "1"
    env.pop("PYTHONPATH", None)
    env.pop("VIRTUAL_ENV", None)
    return env


PIN_CPU = None   # --cpu; None: the last CPU this process may use


def pinned_cpu() -> int | None:
    if PIN_CPU is not None:
        return PIN_CPU
    if hasattr(os, "sched_getaffinity"):
        return sorted(os.sched_getaffinity(0))[-1]
    return None


def run_once(engine: str, scene: str, seconds: float | None, extra_args: list, timeout: float) -> dict:
    python, script = ENGINES[engine]
    if not python.exists():
        return {"error": f"{python} not found (create the venv: see benchmarks/peers/README.md)"}
    cmd = [str(python), str(script), scene] + (["--seconds", repr(seconds)] if seconds else []) + extra_args
    return run_pinned(cmd, timeout)


def run_pinned(cmd: list, timeout: float) -> dict:
    """Runs one engine script pinned to one CPU; its last JSON line, or the error."""
    cpu = pinned_cpu()
    preexec = (lambda: os.sched_setaffinity(0, {cpu})) if cpu is not None else None
    start = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, env=child_environment(), cwd=str(ROOT),
                              timeout=timeout, preexec_fn=preexec)
    except subprocess.TimeoutExpired:
        return {"error": f"timed out after {timeout:.0f} s", "command": cmd}
    elapsed = time.perf_counter() - start
    lines = [line for line in proc.stdout.splitlines() if line.startswith("{")]
    if proc.returncode != 0 or not lines:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-6:]
        return {"error": f"exit {proc.returncode}: " + " | ".join(tail), "command": cmd}
    out = json.loads(lines[-1])
    out["process_wall_seconds"] = elapsed
    out["command"] = cmd[1:]
    return out


def scene_seconds(args, scene: str, engine: str) -> float | None:
    if engine == "simbake" and scene in ("pile", "pile_aligned") and args.simbake_pile_seconds:
        return args.simbake_pile_seconds
    if scene in args.seconds_map:
        return args.seconds_map[scene]
    if args.quick and scene in QUICK_SECONDS:
        return QUICK_SECONDS[scene]
    return None


def aggregate(runs: list) -> dict:
    good = [r for r in runs if "error" not in r]
    if not good:
        return {"error": runs[0]["error"] if runs else "not run", "runs": runs}
    first = good[0]
    rates = [r["wall_per_simulated_second"] for r in good]
    cpu_rates = [r["step_cpu_seconds"] / r["simulated_seconds"] for r in good if r.get("simulated_seconds")]
    by_second = [r["wall_per_simulated_second_by_second"] for r in good]
    first_second = [b[0] for b in by_second if b]
    cpu_over_wall = [r["step_cpu_seconds"] / r["step_wall_seconds"] for r in good if r["step_wall_seconds"] > 0]
    return {
        "engine": first["engine"], "version": first["version"], "scene": first["scene"],
        "scene_digest": first["scene_digest"], "bodies": first["bodies"],
        "simulated_seconds": first["simulated_seconds"],
        "wall_per_simulated_second": statistics.median(rates),
        "wall_per_simulated_second_runs": rates,
        "cpu_per_simulated_second": statistics.median(cpu_rates) if cpu_rates else None,
        "cpu_per_simulated_second_runs": cpu_rates,
        "first_second_wall": statistics.median(first_second) if first_second else None,
        "step_cpu_over_wall": statistics.median(cpu_over_wall) if cpu_over_wall else None,
        "runs": len(good),
        "accuracy": first["accuracy"], "summary": first["summary"],
        "accuracy_same_in_all_runs": all(r["summary"] == first["summary"] for r in good),
        "settings": first["settings"],
        "extra": {k: v for k, v in first.items() if k in ("profile_seconds", "profile_per_simulated_second",
                                                           "statistics", "core_module", "mujoco_warnings",
                                                           "max_contacts_at_frame_ends")},
        "process_wall_seconds": [r["process_wall_seconds"] for r in good],
        "wall_per_simulated_second_by_second": by_second[0],
    }


# ---------------------------------------------------------------------------------------
# reporting


def fmt(value, digits=3) -> str:
    if value is None:
        return "-"
    if isinstance(value, str):
        return value
    if value == 0:
        return "0"
    if 1e-3 <= abs(value) < 1e5:
        return f"{value:.{digits}g}"
    return f"{value:.{digits - 1}e}"


def finite(value):
    """JSON without NaN or infinity (they become null)."""
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def script_docstring(path: Path) -> str:
    return ast.get_docstring(ast.parse(path.read_text())) or ""


def machine_info() -> dict:
    cpu = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"platform": platform.platform(), "cpu_model": cpu, "logical_cpus": os.cpu_count(),
            "allowed_cpus": sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
            "pinned_cpu": pinned_cpu(), "load_average": list(os.getloadavg()),
            "python": sys.version.split()[0],
            "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}


def git_state() -> dict:
    def git(*a):
        try:
            return subprocess.run(["git", *a], cwd=ROOT, capture_output=True, text=True, timeout=20).stdout
        except Exception:
            return ""
    dirty = git("status", "--porcelain", "--", "core", "bindings", "CMakeLists.txt")
    return {"head": git("rev-parse", "--short", "HEAD").strip(),
            "uncommitted_core_changes": [line[3:] for line in dirty.splitlines() if line.strip()]}


def cell(entry: dict | None, capped_note: str = "", repeats: int = 3) -> str:
    if entry is None:
        return "not run"
    if "error" in entry:
        return "failed: " + entry["error"][:80]
    runs = "" if entry["runs"] >= repeats else f" ({entry['runs']} run{'s' if entry['runs'] > 1 else ''})"
    return f"{fmt(entry['wall_per_simulated_second'])}{capped_note}{runs}; {entry['summary']}"



def mesh_pile_row(label: str, shape: str, runs, cpu, entry: dict) -> str:
    """One row of the mesh pile's table: an engine's run (or median entry) and its accuracy."""
    a = entry["accuracy"]
    return (f"| {label} | {shape} | {runs} | {fmt(cpu)} | {fmt(entry['wall_per_simulated_second'])} | "
            f"{fmt(a.get('penetration_bodies_mm'))} (at {fmt(a.get('penetration_bodies_time'))} s) | "
            f"{fmt(a.get('penetration_ground_mm'))} (at {fmt(a.get('penetration_ground_time'))} s) | "
            f"{fmt(a.get('penetration_bodies_end_mm'))} / {fmt(a.get('penetration_ground_end_mm'))} | "
            f"{fmt(a.get('max_speed_end'))} | {fmt(a.get('mean_speed_end'))} | {a.get('below_ground')} | "
            f"{fmt(a.get('max_radius_end'))} | {a.get('exploded')} |")

def write_markdown(payload: dict, path: Path) -> None:
    res, engines = payload["results"], payload["engines"]
    info, lines = payload["machine"], []
    lines += ["# Peer benchmark: simbake, PyBullet, MuJoCo, Blender on the same rigid-body scenes", "",
              f"{info['cpu_model']}, {info['logical_cpus']} vCPU, every run in its own process pinned "
              f"to CPU {info['pinned_cpu']} with thread variables at 1; {info['date']}; load average at the "
              f"start {', '.join(f'{v:.2f}' for v in payload['load_average_start'])}, at the end "
              f"{', '.join(f'{v:.2f}' for v in payload['load_average_end'])}. compare.py took "
              f"{payload['compare_wall_seconds']:.0f} s{' (--quick)' if payload['options']['quick'] else ''}.", "",
              "Each cell: wall seconds per simulated second of the stepping alone ("
              + (f"median of {payload['options']['repeats']} runs unless marked" if payload['options']['repeats'] > 1
                 else "one run")
              + "; below 1 = faster than real time), then "
              "the accuracy. Frames of 1/24 s; setup, model compilation and pose read-back are outside the clock.", "",
              "Versions: " + ", ".join(f"{LABELS[e]} {payload['versions'].get(e, '-')}" for e in engines) + ".", ""]
    if payload.get("pile_bakes"):
        lines += pile_bakes.markdown(payload["pile_bakes"])
    if payload["options"].get("command"):
        lines += [f"Reproduce: `{payload['options']['command']}` (from the repository's root; the peers' venvs "
                  "as in benchmarks/peers/README.md).", ""]
    header = "| scene | " + " | ".join(LABELS[e] for e in engines) + " |"
    lines += [header, "|" + " --- |" * (len(engines) + 1)]
    for scene in payload["scenes"]:
        row = [scene_label(payload, scene)]
        for e in engines:
            entry = res.get(e, {}).get(scene)
            note = ""
            spans = [res[x][scene]["simulated_seconds"] for x in engines if "error" not in res[x][scene]]
            if entry and "error" not in entry and entry["simulated_seconds"] < max(spans) - 1e-9:
                note = f" (first {entry['simulated_seconds']:g} s only)"
            row.append(cell(entry, note, payload["options"]["repeats"]))
        lines.append("| " + " | ".join(row) + " |")
    lines += ["", "Accuracy: tower and pyramid, the largest displacement of any box from its start at any "
              "frame (drift); pile, the largest speed over the last frame (vmax) and the bodies whose centre "
              "ended below the ground; drop, the first rebound apex of the sphere's bottom against "
              "e^2 x 1.5 m = 0.375 m (parabola through the frames around the apex); incline mu 0.5, the "
              "acceleration fitted to the positions from 0.25 s against g (sin 30 - 0.5 cos 30) = 0.6571 "
              "m/s^2; incline mu 0.7, the creep speed over the last second (exact answer: 0).", ""]

    # the pile in detail
    if any(s.startswith("pile") for s in payload["scenes"]):
        lines += ["## Piles in detail", "",
                  "| engine | scene | simulated s | runs | wall / sim s | first second | vmax end (m/s) | "
                  "below ground | lowest centre (m) | highest centre (m) | farthest centre from the axis (m) | exploded | "
                  "deepest penetration (mm) | body into body / ground (mm) | at (s) | penetration at end (mm) |",
                  "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
        for scene in [s for s in payload["scenes"] if s.startswith("pile")]:
            for e in engines:
                entry = res.get(e, {}).get(scene)
                if not entry or "error" in entry:
                    continue
                a = entry["accuracy"]
                lines.append(f"| {LABELS[e]} | {scene} | {entry['simulated_seconds']:g} | {entry['runs']} | "
                             f"{fmt(entry['wall_per_simulated_second'])} | {fmt(entry['first_second_wall'])} | "
                             f"{fmt(a.get('max_speed_end'))} | {a.get('below_ground')} | {fmt(a.get('min_height_end'))} | "
                             f"{fmt(a.get('max_height_end'))} | {fmt(a.get('max_radius_end'))} | {a.get('exploded')} | "
                             f"{fmt(a.get('penetration_mm'))} | {fmt(a.get('penetration_boxes_mm', a.get('penetration_bodies_mm')))} / "
                             f"{fmt(a.get('penetration_ground_mm'))} | {fmt(a.get('penetration_time'))} | "
                             f"{fmt(a.get('penetration_end_mm'))} |")
        lines += ["", "'first second' is the stepping wall time of simulated second 1 (free fall and the "
                  "first impacts): the only window where a capped simbake pile compares like for like. "
                  "'exploded' means a centre below the ground, a speed above free fall from the highest "
                  "start, or a centre above the highest start. Penetration is measured from every engine's "
                  "poses at every frame by the same code (scenes.box_penetration: the separating-axis "
                  "overlap of each pair of boxes closer than their diagonals, and box corners below the "
                  "ground), so edge-edge overlaps that a sample-based contact misses are counted.", ""]

    # the mesh pile
    if "pile_meshes" in payload["scenes"]:
        scene = "pile_meshes"
        method = next((res[e][scene]["accuracy"].get("penetration_method") for e in engines
                       if "error" not in res[e][scene]), "")
        lines += ["## Mesh pile: assets/scenes/pile.toml (200 nonconvex meshes, 6 s)", "",
                  "| engine | nonconvex meshes as | runs | CPU s / sim s | wall s / sim s | deepest body into body (mm) | "
                  "deepest into ground (mm) | body / ground at end (mm) | max speed, last frame (m/s) | mean speed (m/s) | "
                  "centres below ground | farthest centre from the axis (m) | exploded |",
                  "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
        for e in engines:
            entry = res.get(e, {}).get(scene)
            if not entry:
                continue
            if "error" in entry:
                lines.append(f"| {LABELS[e]} | failed: {entry['error'][:80]} |" + " |" * 11)
                continue
            lines.append(mesh_pile_row(LABELS[e], entry["settings"].get("nonconvex_meshes", ""), entry["runs"],
                                       entry.get("cpu_per_simulated_second"), entry))
        for x in payload.get("extras", []):
            if x["scene"] != scene:
                continue
            entry = x["result"]
            if "error" in entry:
                lines.append(f"| {LABELS[x['engine']]}, {x['label']} | failed: {entry['error'][:80]} |" + " |" * 11)
                continue
            lines.append(mesh_pile_row(f"{LABELS[x['engine']]}, extra run",
                                       entry["settings"].get("nonconvex_meshes", x["label"]), 1,
                                       entry["step_cpu_seconds"] / entry["simulated_seconds"], entry))
        lines += ["", "Measured by scenes.py from each engine's poses of the meshes (the same code for every "
                  "engine), against the true meshes of assets/meshes, whatever shapes the engine simulated: "
                  + method + ". Resolution: each sample's depth is exact; the deepest point between samples can "
                  "be missed by at most about the sample spacing's share of the overlap's slope (a sample within "
                  "10 mm of every surface point). Speeds are of the centres of mass over the last frame. "
                  "'CPU s / sim s' is the stepping's process CPU time (one thread, pinned) per simulated second.", ""]

    # simbake's stage profile
    prof = [(s, res["simbake"][s]) for s in payload["scenes"]
            if "simbake" in res and s in res["simbake"] and "error" not in res["simbake"][s]
            and "profile_per_simulated_second" in res["simbake"][s]["extra"]]
    if prof:
        stages = list(prof[0][1]["extra"]["profile_per_simulated_second"])
        lines += ["## simbake: wall seconds per simulated second by stage (first run)", "",
                  "| scene | substeps/frame | " + " | ".join(stages) + " | total (stepping) |",
                  "|" + " --- |" * (len(stages) + 3)]
        for scene, entry in prof:
            p = entry["extra"]["profile_per_simulated_second"]
            lines.append(f"| {scene} | {fmt(entry['settings'].get('substeps_per_frame_mean'))} | "
                         + " | ".join(fmt(p.get(s)) for s in stages)
                         + f" | {fmt(entry['wall_per_simulated_second'])} |")
        core = prof[0][1]["extra"].get("core_module", {})
        lines += ["", f"simbake core module {core.get('path', '?')} (sha1 {core.get('sha1', '?')}, built "
                  f"{core.get('mtime', '?')}), run by {payload['options']['simbake_python']}; "
                  f"git HEAD at the end of the run {payload['git']['head']}"
                  + (f", with uncommitted changes to {', '.join(payload['git']['uncommitted_core_changes'])} "
                     "(the module may not match them)" if payload['git']['uncommitted_core_changes'] else "")
                  + (". WARNING: the module changed during the run: " + ", ".join(payload["simbake_modules"])
                     if len(payload["simbake_modules"]) > 1 else "."), ""]

    if payload.get("extras"):
        lines += ["## Extra runs (one each): settings that change an answer", "",
                  "| engine | scene | setting | wall / sim s | accuracy |", "| --- | --- | --- | --- | --- |"]
        for x in payload["extras"]:
            entry = x["result"]
            if "error" in entry:
                lines.append(f"| {LABELS[x['engine']]} | {x['scene']} | {x['label']} | failed | {entry['error'][:80]} |")
            else:
                lines.append(f"| {LABELS[x['engine']]} | {x['scene']} | {x['label']} | "
                             f"{fmt(entry['wall_per_simulated_second'])} | {entry['summary']} |")
        lines.append("")

    lines += ["## Settings per engine", "",
              "Every engine gets each pair of bodies (and body-ground) the same friction mu and "
              "restitution e, through its own combination rule; Z-up engines get the scenes rotated "
              "+90 degrees about x. From each script's docstring:", ""]
    for e in engines:
        lines += [f"### {LABELS[e]}", "", "```", script_docstring(ENGINES[e][1]).strip(), "```", ""]
    if payload.get("notes"):
        lines += ["## Notes", ""] + [f"- {n}" for n in payload["notes"]] + [""]
    path.write_text("\n".join(lines).rstrip() + "\n")


def write_chart(json_path: Path, png_path: Path) -> str:
    """Draw the chart with whichever venv has matplotlib (this script needs none)."""
    for python in (ENGINES["pybullet"][0], ENGINES["simbake"][0], Path(sys.executable)):
        if not python.exists():
            continue
        proc = subprocess.run([str(python), str(HERE / "chart.py"), str(json_path), str(png_path)],
                              capture_output=True, text=True, env=child_environment())
        if proc.returncode == 0:
            return f"chart drawn with {python}"
        last = proc.stderr.strip().splitlines()[-1:] if proc.stderr else []
        print(f"chart with {python} failed: {last}", file=sys.stderr)
    return "no chart: no interpreter with matplotlib"


def run_pile_bakes(args, rounds: int, start: float) -> dict:
    """The piles' whole bakes against MuJoCo (pile_bakes.py), `rounds` rounds in turns."""
    return pile_bakes.run(args.simbake_python, lambda scene: run_once("mujoco", scene, None, [], args.timeout),
                          rounds, pinned_cpu(), child_environment(), args.timeout,
                          lambda line: print(f"[{time.perf_counter() - start:6.0f} s] {line}", flush=True))


def bake_piles_only(args) -> None:
    """--pile-bakes-only: the piles' whole bakes alone, into pile_bakes.{json,md} beside peers.*"""
    start = time.perf_counter()
    load_start = list(os.getloadavg())
    result = run_pile_bakes(args, args.pile_bakes or 3, start)
    result.update({"machine": machine_info(), "git": git_state(), "load_average_start": load_start,
                   "load_average_end": list(os.getloadavg()), "seconds": time.perf_counter() - start,
                   "command": " ".join(["python3", "benchmarks/peers/compare.py"] + sys.argv[1:]),
                   "simbake_python": str(args.simbake_python)})
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "pile_bakes.json").write_text(json.dumps(finite(result), indent=1) + "\n")
    info = result["machine"]
    lines = ["# Whole bakes of the 1000-box piles against MuJoCo", "",
             f"{info['cpu_model']}, {info['logical_cpus']} vCPU, pinned to CPU {info['pinned_cpu']}; {info['date']}; "
             f"load average at the start {', '.join(f'{v:.2f}' for v in load_start)}, at the end "
             f"{', '.join(f'{v:.2f}' for v in result['load_average_end'])}; git {result['git']['head']}.", "",
             f"Reproduce: `{result['command']}`", ""] + pile_bakes.markdown(result)[1:]
    (args.out / "pile_bakes.md").write_text("\n".join(lines).rstrip() + "\n")
    print("\n".join(lines))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--engines", nargs="+", default=list(ENGINES), choices=list(ENGINES))
    ap.add_argument("--scenes", nargs="+", default=SCENE_ORDER, choices=SCENE_ORDER)
    ap.add_argument("--repeats", type=int, default=3, help="runs per engine and scene (median wall time)")
    ap.add_argument("--slow", type=float, default=20.0,
                    help="a first run whose stepping took more than this (s) is not repeated")
    ap.add_argument("--seconds", nargs="*", default=[], metavar="SCENE=S",
                    help="simulated seconds of a scene, for every engine (e.g. pile=2 pyramid=5)")
    ap.add_argument("--simbake-pile-seconds", type=float, default=1.0,
                    help="simulated seconds of simbake's 1000-box pile (default 1: it has no sleeping and "
                         "an O(n^2) broad phase yet); 0 = the same as the peers")
    ap.add_argument("--quick", action="store_true",
                    help="short scenes (" + ", ".join(f"{k} {v:g} s" for k, v in QUICK_SECONDS.items())
                         + "), one run each, no extras")
    ap.add_argument("--no-extras", action="store_true", help="skip the extra Blender settings runs")
    ap.add_argument("--timeout", type=float, default=1800.0, help="per run (s)")
    ap.add_argument("--cpu", type=int, default=None,
                    help="pin every run to this CPU (default: the last CPU this process may use)")
    ap.add_argument("--out", type=Path, default=RESULTS, help="directory of peers.{json,md,png}")
    ap.add_argument("--simbake-python", type=Path, default=ENGINES["simbake"][0],
                    help="interpreter with simbake installed (default: the project's .venv); e.g. one "
                         "built from a clean checkout of HEAD while the work tree is being edited")
    ap.add_argument("--note", action="append", default=[],
                    help="a line for the notes of peers.md (e.g. which commit the simbake module was built from)")
    ap.add_argument("--pile-bakes", type=int, default=None, metavar="ROUNDS",
                    help="rounds of the piles' whole bakes against MuJoCo (default: --repeats; 0: none)")
    ap.add_argument("--pile-bakes-only", action="store_true",
                    help="only the piles' whole bakes against MuJoCo (simbake and MuJoCo, both piles)")
    ap.add_argument("--render-only", type=Path, metavar="PEERS_JSON",
                    help="no runs: rewrite peers.md and peers.png (in --out) from an existing peers.json, "
                         "adding any --note")
    args = ap.parse_args()
    if args.render_only:
        payload = json.loads(args.render_only.read_text())
        payload["notes"] = payload.get("notes", []) + [n for n in args.note if n not in payload.get("notes", [])]
        args.out.mkdir(parents=True, exist_ok=True)
        json_path = args.out / "peers.json"
        json_path.write_text(json.dumps(finite(payload), indent=1) + "\n")
        write_markdown(payload, args.out / "peers.md")
        print(write_chart(json_path, args.out / "peers.png"))
        return
    ENGINES["simbake"] = (args.simbake_python, ENGINES["simbake"][1])
    global PIN_CPU
    PIN_CPU = args.cpu
    args.seconds_map = {}
    for item in args.seconds:
        name, _, value = item.partition("=")
        if name not in SCENE_ORDER or not value:
            ap.error(f"--seconds wants SCENE=S with SCENE one of {', '.join(SCENE_ORDER)}")
        args.seconds_map[name] = float(value)
    if args.quick:
        args.repeats = 1
        args.no_extras = True
        if args.simbake_pile_seconds == 1.0:
            args.simbake_pile_seconds = 0.5

    if args.pile_bakes_only:
        bake_piles_only(args)
        return
    start = time.perf_counter()
    load_start = list(os.getloadavg())
    runs = {e: {s: [] for s in args.scenes} for e in args.engines}
    for scene in [s for s in SCENE_ORDER if s in args.scenes]:
        for rep in range(args.repeats):
            for engine in args.engines:
                done = runs[engine][scene]
                if rep > 0 and (not done or "error" in done[0] or done[0]["step_wall_seconds"] > args.slow):
                    continue
                r = run_once(engine, scene, scene_seconds(args, scene, engine), [], args.timeout)
                done.append(r)
                status = r.get("error") or (f"{r['wall_per_simulated_second']:.4g} s/s over "
                                            f"{r['simulated_seconds']:g} s; {r['summary']}")
                print(f"[{time.perf_counter() - start:6.0f} s] {engine:8s} {scene:14s} run {rep + 1}: {status}",
                      flush=True)
    results = {e: {s: aggregate(runs[e][s]) for s in args.scenes} for e in args.engines}

    bakes = None
    rounds = args.pile_bakes if args.pile_bakes is not None else args.repeats
    if rounds > 0 and {"simbake", "mujoco"} <= set(args.engines) and set(pile_bakes.PILES) & set(args.scenes):
        bakes = run_pile_bakes(args, rounds, start)

    extras = []
    if not args.no_extras:
        for engine, scene, extra_args, label in EXTRAS:
            if engine in args.engines and scene in args.scenes:
                r = run_once(engine, scene, scene_seconds(args, scene, engine), extra_args, args.timeout)
                extras.append({"engine": engine, "scene": scene, "args": extra_args, "label": label, "result": r})
                print(f"[{time.perf_counter() - start:6.0f} s] extra {engine} {scene} {label}: "
                      f"{r.get('error') or r['summary']}", flush=True)

    # checks: same scenes everywhere, one simbake module throughout
    notes = list(args.note)
    for scene in args.scenes:
        digests = {e: results[e][scene].get("scene_digest") for e in args.engines if "error" not in results[e][scene]}
        if len(set(digests.values())) > 1:
            notes.append(f"scene {scene}: engines built different scenes: {digests}")
    modules = sorted({r["core_module"]["sha1"] for s in runs.get("simbake", {}).values() for r in s
                      if "core_module" in r})
    if len(modules) > 1:
        notes.append(f"simbake's compiled module changed during the run ({', '.join(modules)}): "
                     "the lead rebuilt it; re-run for consistent simbake numbers")
    for e in args.engines:
        for s in args.scenes:
            entry = results[e][s]
            if "error" in entry:
                notes.append(f"{LABELS[e]} {s} failed: {entry['error']}")
            elif not entry["accuracy_same_in_all_runs"]:
                notes.append(f"{LABELS[e]} {s}: the accuracy differed between runs (first run reported)")
            elif entry["step_cpu_over_wall"] and entry["step_cpu_over_wall"] < 0.9:
                notes.append(f"{LABELS[e]} {s}: stepping CPU / wall {entry['step_cpu_over_wall']:.2f} "
                             "(the CPU was shared with another process)")

    versions = {e: next((r["version"] for s in runs[e].values() for r in s if "version" in r), None)
                for e in args.engines}
    payload = {
        "benchmark": "peers", "machine": machine_info(), "git": git_state(),
        "options": {"simbake_python": str(args.simbake_python), "engines": args.engines,
                    "scenes": args.scenes, "repeats": args.repeats, "slow": args.slow,
                    "quick": args.quick, "seconds": args.seconds_map, "cpu": args.cpu,
                    "command": " ".join(["python3", "benchmarks/peers/compare.py"] + sys.argv[1:]),
                    "simbake_pile_seconds": args.simbake_pile_seconds, "extras": not args.no_extras},
        "engines": args.engines, "scenes": [s for s in SCENE_ORDER if s in args.scenes],
        "versions": versions, "simbake_modules": modules,
        "load_average_start": load_start, "load_average_end": list(os.getloadavg()),
        "results": results, "extras": extras, "notes": notes, "pile_bakes": bakes,
        "raw_runs": runs,
    }
    payload["compare_wall_seconds"] = time.perf_counter() - start
    args.out.mkdir(parents=True, exist_ok=True)
    json_path = args.out / "peers.json"
    json_path.write_text(json.dumps(finite(payload), indent=1) + "\n")
    write_markdown(payload, args.out / "peers.md")
    chart = write_chart(json_path, args.out / "peers.png")
    print(f"{chart}\n-> {args.out / 'peers'}.{{json,md,png}} in {time.perf_counter() - start:.0f} s")
    print((args.out / "peers.md").read_text().split("## Piles")[0])


if __name__ == "__main__":
    main()
