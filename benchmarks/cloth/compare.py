"""The cloth benchmark: run time against error on the drape (drape_spec.py), for simbake's
implicit and explicit integrators over resolutions 17 ... 257 vertices a side, and side by
side with Blender's cloth modifier, Newton's VBD (CPU) and MuJoCo's flex.

    python3 benchmarks/cloth/compare.py              # every run below (~40 min on 2 cores)
    python3 benchmarks/cloth/compare.py --quick      # resolutions 17 and 33 only
    python3 benchmarks/cloth/compare.py --self-collision --fresh   # every engine with self-collision on
    python3 benchmarks/cloth/compare.py --engines simbake --fresh
    python3 benchmarks/cloth/compare.py --report     # tables and plots from the saved runs
    taskset -c 0 python3 benchmarks/cloth/compare.py --engines simbake --resolutions 17 33 65 &
    taskset -c 1 python3 benchmarks/cloth/compare.py --engines simbake --resolutions 129 257 --suffix _big
    taskset -c 0 python3 benchmarks/cloth/compare.py --engines simbake --labels default --fresh --suffix _alone
                                                     # the per-doubling figures: one run at a time, the
                                                     # other CPU idle (257 is bound by memory traffic,
                                                     # which a run on the other CPU shares)

Each run is one subprocess of the engine's runner (simbake: .venv; Blender, Newton and MuJoCo:
the venvs of benchmarks/peers, see its README), pinned to one CPU with the thread variables
at 1, timed by the runner over its stepping alone (wall and CPU seconds). Runs are saved as
they finish in benchmarks/results/cloth_runs_<engine>[suffix].json (a rerun skips those
already there unless --fresh; every such file is read), then compared:
- strain: the largest edge strain over the run (the sheet is 2000 N/m under ~1 N/m of
  weight: a converged answer is under 1 %; simbake also limits it to 10 %);
- penetration: the deepest vertex inside the sphere or the ground;
- profile error: the drape's rotationally averaged shape against the reference run (simbake,
  129 x 129, 1/240 s steps, CG tolerance 1e-6): the 17 x 17 common material points binned by
  their distance from the cloth's centre (8 rings), each ring's mean height and mean distance
  from the sphere's axis; the error is the RMS over rings of the distance between the two
  curves, at 0.5, 1 and 3 s. Folds form by symmetry breaking, so where they land (and with it
  any pointwise comparison) changes with every setting; the profile does not;
- shape error at 0.5 s: the RMS pointwise distance before folds form.
Writes benchmarks/results/cloth.{json,md} and cloth_time.png, cloth_accuracy.png.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
PEERS = HERE.parent / "peers"
RESULTS = ROOT / "benchmarks" / "results"
sys.path.insert(0, str(HERE))
import drape_spec as spec  # noqa: E402
from benchmarks.peers import compare as peer_driver  # noqa: E402  (pinned runs, machine, git state)

ENGINES = {
    "simbake": (ROOT / ".venv" / "bin" / "python", HERE / "run_simbake.py"),
    "blender": (PEERS / ".venv-bpy" / "bin" / "python", HERE / "run_blender.py"),
    "newton": (PEERS / ".venv-newton" / "bin" / "python", HERE / "run_newton.py"),
    "mujoco": (PEERS / ".venv-peers" / "bin" / "python", HERE / "run_mujoco.py"),
}
LABELS = {"simbake": "simbake (implicit)", "simbake-explicit": "simbake (explicit)", "blender": "Blender 5.0.1",
          "newton": "Newton 1.8.0 VBD", "mujoco": "MuJoCo 4.0.0 flex"}
REFERENCE = ("simbake", 129, ["--cloth-step", str(1.0 / 240.0), "--tolerance", "1e-6"], "reference")

# (engine, resolution, extra arguments, label); the label names the setting
RUNS_FULL = [
    REFERENCE,
    *[("simbake", n, [], "default") for n in (17, 33, 65, 129, 257)],
    *[("simbake", 65, ["--cloth-step", repr(s)], f"step 1/{round(1 / s)} s") for s in (1 / 24, 1 / 60, 1 / 240)],
    *[("simbake", 65, ["--tolerance", t], f"tolerance {t}") for t in ("1e-2", "1e-4")],
    ("simbake", 65, ["--model", "membrane"], "membrane"),
    *[("simbake", n, ["--integrator", "explicit"], "explicit") for n in (17, 33)],
    *[("blender", n, [], "default") for n in (17, 33, 65, 129)],
    *[("blender", 65, ["--quality", q], f"{q} steps/frame") for q in ("5", "10", "40")],
    *[("newton", n, [], "default") for n in (17, 33, 65)],
    ("newton", 65, ["--substeps", "10"], "10 substeps/frame"),
    *[("mujoco", n, [], "default") for n in (17, 33, 65)],
    ("mujoco", 65, ["--steps-per-frame", "8"], "8 steps/frame"),
]
# the drape with every engine's self-collision on (simbake's is on by default), counted for
# layers through layers by crossings.py at 4 frames a second (drape_spec.Meter)
SELF = ["--self-collision", "on"]
RUNS_SELF = [
    *[("simbake", n, [], "default") for n in (17, 33, 65, 129, 257)],
    *[("blender", n, SELF, "self-collision") for n in (17, 33, 65, 129, 257)],
    *[("newton", n, SELF, "self-collision") for n in (17, 33, 65)],
    *[("mujoco", n, SELF, "self-collision") for n in (17, 33, 65)],
]
RINGS = 8


def run_key(engine: str, n: int, extra: list) -> str:
    return " ".join([engine, str(n), *extra])


def run_once(engine: str, n: int, extra: list, timeout: float) -> dict:
    python, script = ENGINES[engine]
    if not python.exists():
        return {"error": f"{python} not found (see benchmarks/peers/README.md)"}
    return peer_driver.run_pinned([str(python), str(script), str(n), *extra], timeout)


# ---- measures

def _material_radius() -> np.ndarray:
    step = spec.SIZE / (spec.COMMON - 1)
    j, i = np.meshgrid(np.arange(spec.COMMON), np.arange(spec.COMMON), indexing="ij")
    return np.hypot((i.ravel() - (spec.COMMON - 1) / 2) * step, (j.ravel() - (spec.COMMON - 1) / 2) * step)


def profile(points) -> np.ndarray:
    """(RINGS x 2): each ring's mean height and mean distance from the sphere's axis."""
    x = np.asarray(points, dtype=float)
    rho = _material_radius()
    ring = np.minimum((rho / rho.max() * RINGS).astype(int), RINGS - 1)
    axis = np.hypot(x[:, 0] - spec.SPHERE_CENTER[0], x[:, 2] - spec.SPHERE_CENTER[2])
    return np.array([[x[ring == r, 1].mean(), axis[ring == r].mean()] for r in range(RINGS)])


def profile_error(run: dict, reference: dict, t: str) -> float | None:
    if t not in run.get("shapes", {}) or t not in reference.get("shapes", {}):
        return None
    d = profile(run["shapes"][t]) - profile(reference["shapes"][t])
    return float(np.sqrt(np.mean(np.sum(d * d, axis=1))))


def shape_error(run: dict, reference: dict, t: str) -> float | None:
    if t not in run.get("shapes", {}) or t not in reference.get("shapes", {}):
        return None
    d = np.asarray(run["shapes"][t]) - np.asarray(reference["shapes"][t])
    return float(np.sqrt(np.mean(np.sum(d * d, axis=1))))


def cpu_per_sim_second(run: dict) -> float | None:
    cpu = run.get("cpu_seconds", run.get("step_cpu_seconds"))
    return cpu / spec.SECONDS if cpu is not None else None


def summarize(runs: dict) -> list[dict]:
    reference = runs.get(run_key(REFERENCE[0], REFERENCE[1], REFERENCE[2]), {})
    rows = []
    for key, run in runs.items():
        engine, n, label = run["engine_name"], run["n"], run["label"]
        row = {"key": key, "engine": engine, "resolution": n, "label": label}
        if "error" in run:
            row["error"] = run["error"]
        else:
            row.update({
                "wall_per_sim_second": run["wall_per_sim_second"],
                "cpu_per_sim_second": cpu_per_sim_second(run),
                "memory_mib": run["memory_mib"],
                "max_strain": run["max_strain"],
                "max_penetration": run["max_penetration"],
                "self_crossings": run.get("self_crossings"),
                "self_crossings_time": run.get("self_crossings_time"),
                "profile_error": {t: profile_error(run, reference, t) for t in ("0.5", "1", "3")},
                "shape_error_0.5": shape_error(run, reference, "0.5"),
            })
        rows.append(row)
    order = list(ENGINES)
    rows.sort(key=lambda r: (order.index(r["engine"]), r["label"] != "default", r["resolution"], r["label"]))
    return rows


# ---- report

def fmt(value, digits: int = 3) -> str:
    if value is None:
        return "-"
    if isinstance(value, float) and not math.isfinite(value):
        return "inf"
    return f"{value:.{digits}g}"


def crossings(row: dict) -> str:
    count = row.get("self_crossings")
    if count is None:
        return "-"
    return str(count) if not count else f"{count} ({fmt(row['self_crossings_time'], 3)})"


def write_markdown(payload: dict, path: Path) -> None:
    lines = [
        "# Cloth benchmark: the drape (`benchmarks/cloth/compare.py`)",
        "",
        "A 2 m square cloth (area density 0.1 kg/m^2, sheet stiffness 2000 N/m, bending 1e-4 N m,",
        "friction 0.45, 5 mm thickness) dropped from 1.2 m onto a 0.5 m sphere and the ground, 3 s",
        "at 24 fps; n x n vertices. Each engine on one CPU; CPU and wall seconds of stepping per",
        "simulated second (the other CPU was running another engine). Profile error: the rotationally averaged drape against",
        "the reference (simbake 129 x 129, 1/240 s steps, tolerance 1e-6), RMS over 8 rings of",
        "material radius, in mm. Settings of every engine: the docstrings of `run_*.py`.",
        "",
        f"Machine: {payload['machine']['cpu_model']}, load average at the start "
        f"{', '.join(f'{v:.1f}' for v in payload['machine']['load_average'])}; simbake {payload['git']['head']}.",
        "",
        "Self-crossings: the most crossing pairs of non-adjacent triangles at any counted frame (4 a second",
        "and the last; `crossings.py`, the same code and triangulation for every engine), and when; '-'",
        "for runs saved before it was counted.",
        "",
        "| engine | n | setting | CPU s / sim s | wall s / sim s | memory MiB | max strain | max penetration mm | self-crossings (at s) | profile error 0.5 / 1 / 3 s (mm) | shape error 0.5 s (mm) |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in payload["rows"]:
        label = LABELS["simbake-explicit" if r["label"] == "explicit" else r["engine"]]
        if "error" in r:
            lines.append(f"| {label} | {r['resolution']} | {r['label']} | {r['error']} | | | | | | | |")
            continue
        pe = r["profile_error"]
        errors = " / ".join(fmt(None if pe[t] is None else 1000 * pe[t], 2) for t in ("0.5", "1", "3"))
        shape = r["shape_error_0.5"]
        lines.append(
            f"| {label} | {r['resolution']} | {r['label']} | {fmt(r['cpu_per_sim_second'])} | "
            f"{fmt(r['wall_per_sim_second'])} | {fmt(r['memory_mib'], 3)} | "
            f"{fmt(r['max_strain'], 2)} | {fmt(1000 * r['max_penetration'], 2)} | {crossings(r)} | {errors} | "
            f"{fmt(None if shape is None else 1000 * shape, 2)} |")
    path.write_text("\n".join(lines) + "\n")


def write_plots(payload: dict) -> None:
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib not available: no plots")
        return
    rows = [r for r in payload["rows"] if "error" not in r and r["label"] != "reference"]
    colors = {"simbake": "C0", "blender": "C1", "newton": "C2", "mujoco": "C3"}
    # run time against resolution, default settings
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for engine in ENGINES:
        pts = sorted((r["resolution"], r["cpu_per_sim_second"]) for r in rows
                     if r["engine"] == engine and r["label"] == "default")
        if pts:
            ax.loglog(*zip(*pts), "o-", color=colors[engine], label=LABELS[engine])
    pts = sorted((r["resolution"], r["cpu_per_sim_second"]) for r in rows if r["label"] == "explicit")
    if pts:
        ax.loglog(*zip(*pts), "s--", color="C0", label=LABELS["simbake-explicit"])
    ax.set_xlabel("vertices a side")
    ax.set_ylabel("CPU seconds per simulated second")
    ax.set_title("Drape, 3 s: run time by resolution (one CPU)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(RESULTS / "cloth_time.png", dpi=120)
    plt.close(fig)
    # accuracy against run time at 65 x 65, every setting
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2))
    for ax, measure, title in ((axes[0], "max_strain", "largest edge strain"),
                               (axes[1], "profile3", "profile error at 3 s (m)")):
        for r in rows:
            if r["resolution"] != 65:
                continue
            y = r["profile_error"]["3"] if measure == "profile3" else r[measure]
            if y is None:
                continue
            ax.loglog(r["cpu_per_sim_second"], max(y, 1e-4), "o", color=colors[r["engine"]])
            ax.annotate(r["label"] if r["label"] != "default" else LABELS[r["engine"]].split()[0],
                        (r["cpu_per_sim_second"], max(y, 1e-4)), fontsize=7, xytext=(3, 3), textcoords="offset points")
        ax.set_xlabel("CPU seconds per simulated second")
        ax.set_ylabel(title)
        ax.grid(True, which="both", alpha=0.3)
    fig.suptitle("Drape at 65 x 65: error against run time (lower left is better)")
    fig.tight_layout()
    fig.savefig(RESULTS / "cloth_accuracy.png", dpi=120)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="resolutions 17 and 33 only")
    parser.add_argument("--self-collision", action="store_true",
                        help="the self-collision comparison (RUNS_SELF): every engine's self-collision on")
    parser.add_argument("--engines", nargs="+", choices=list(ENGINES), default=list(ENGINES))
    parser.add_argument("--fresh", action="store_true", help="rerun runs already saved")
    parser.add_argument("--report", action="store_true", help="no runs: report the saved ones")
    parser.add_argument("--timeout", type=float, default=1800.0, help="per run (s)")
    parser.add_argument("--resolutions", type=int, nargs="+", help="only the runs at these resolutions")
    parser.add_argument("--labels", nargs="+", help="only the runs of these settings (default, reference, "
                        "explicit, membrane, ...)")
    parser.add_argument("--suffix", default="", help="save to cloth_runs_<engine><suffix>.json (for drivers "
                        "running at once, e.g. pinned to different CPUs)")
    args = parser.parse_args()
    RESULTS.mkdir(parents=True, exist_ok=True)
    # each engine's runs in a file of its own (drivers for different engines may run at once)
    def runs_file(engine: str) -> Path:
        return RESULTS / f"cloth_runs_{engine}{args.suffix}.json"
    runs = {}
    for path in sorted(RESULTS.glob("cloth_runs_*.json")):
        runs.update(json.loads(path.read_text()))
    plan = RUNS_SELF if args.self_collision else RUNS_FULL
    plan = [r for r in plan if r[0] in args.engines and (not args.resolutions or r[1] in args.resolutions)
            and (not args.quick or r[1] in (17, 33)) and (not args.labels or r[3] in args.labels)]
    if not args.report:
        for engine, n, extra, label in plan:
            key = run_key(engine, n, extra)
            if key in runs and "error" not in runs[key] and not args.fresh:
                continue
            print(f"{key} ...", end=" ", flush=True)
            out = run_once(engine, n, extra, args.timeout)
            out.update({"engine_name": engine, "n": n, "label": label})
            runs[key] = out
            runs_file(engine).write_text(json.dumps({k: r for k, r in runs.items() if r["engine_name"] == engine}))
            print(out.get("error") or f"{cpu_per_sim_second(out):.3g} CPU s/s, strain {out['max_strain']:.3f}")
    payload = {"machine": peer_driver.machine_info(), "git": peer_driver.git_state(), "rows": summarize(runs)}
    (RESULTS / "cloth.json").write_text(json.dumps(payload, indent=1))
    write_markdown(payload, RESULTS / "cloth.md")
    write_plots(payload)
    print(f"wrote {RESULTS / 'cloth.md'}")


if __name__ == "__main__":
    main()
