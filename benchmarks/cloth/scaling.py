"""How the cloth's implicit solve scales with resolution: block-Jacobi against multigrid
preconditioned conjugate gradients on the drape (drape_spec.py), 17 ... 257 vertices a side.

    .venv/bin/python benchmarks/cloth/scaling.py                     # 0.5 s of the drape, self-collision off
    .venv/bin/python benchmarks/cloth/scaling.py --seconds 3 --self-collision on \\
        --resolutions 33 65 --repeats 1 --name accuracy              # whole drapes: profile error
    .venv/bin/python benchmarks/cloth/scaling.py --report            # the table from the saved runs

Each run is one subprocess of run_simbake.py pinned to one CPU (thread variables at 1),
repeated (--repeats, medians reported; the machine is shared). Reported per resolution and
preconditioner: CG iterations per cloth step; the solver's CPU seconds (preconditioner update
and CG) and the whole step's CPU seconds, both per simulated second; their ratio to the
resolution below (per doubling); the drape's profile error against compare.py's reference
run (simbake 129 x 129, 1/240 s, tolerance 1e-6) at the shape times the run reaches.
Self-collision is off by default so that the figures are the solve's and the rest of the
step's (self-collision's own cost is measured by compare.py and the scenes' bakes).
Runs go to benchmarks/results/cloth_scaling_<name>.json; --report writes cloth_scaling.md.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import compare  # noqa: E402  (the runner, the reference run and the profile error)

RESULTS = compare.RESULTS
PRECONDITIONERS = ("block_jacobi", "multigrid")


def reference() -> dict:
    runs = {}
    for path in sorted(RESULTS.glob("cloth_runs_simbake*.json")):
        runs.update(json.loads(path.read_text()))
    return runs[compare.run_key(*compare.REFERENCE[:3])]


def measure(args) -> None:
    out = RESULTS / f"cloth_scaling_{args.name}.json"
    saved = json.loads(out.read_text()) if out.exists() else {}
    for n in args.resolutions:
        for pc in args.preconditioners:
            key = f"{n} {pc}"
            extra = ["--seconds", str(args.seconds), "--preconditioner", pc, "--self-collision", args.self_collision]
            runs = []
            for _ in range(args.repeats):
                run = compare.run_once("simbake", n, extra, args.timeout)
                if "error" in run:
                    print(key, run["error"], file=sys.stderr)
                    break
                runs.append(run)
                print(f"{key}: {run['cpu_seconds'] / args.seconds:.3f} CPU s/s, solver "
                      f"{run['solver_cpu_seconds'] / args.seconds:.3f}, "
                      f"{run['solver_iterations'] / run['cloth_steps']:.1f} iterations/step", flush=True)
            if runs:
                saved[key] = {"seconds": args.seconds, "self_collision": args.self_collision, "runs": runs}
                out.write_text(json.dumps(saved, indent=1))


def summarize(saved: dict, ref: dict) -> list[dict]:
    rows = []
    for key, entry in saved.items():
        n, pc = key.split()
        runs, seconds = entry["runs"], entry["seconds"]
        first = runs[0]
        rows.append({
            "n": int(n), "preconditioner": pc, "seconds": seconds, "repeats": len(runs),
            "self_collision": entry["self_collision"],
            "iterations_per_step": first["solver_iterations"] / first["cloth_steps"],
            "cpu_per_sim_second": statistics.median(r["cpu_seconds"] for r in runs) / seconds,
            "solver_per_sim_second": statistics.median(r["solver_cpu_seconds"] for r in runs) / seconds,
            "max_strain": first["max_strain"], "max_penetration": first["max_penetration"],
            "profile_error": {t: compare.profile_error(first, ref, t) for t in ("0.5", "1", "3")
                              if t in first.get("shapes", {})},
        })
    rows.sort(key=lambda r: (r["preconditioner"], r["n"]))
    for r in rows:
        below = [q for q in rows if q["preconditioner"] == r["preconditioner"] and q["n"] == (r["n"] + 1) // 2
                 and q["seconds"] == r["seconds"]]
        if below:
            r["solver_ratio"] = r["solver_per_sim_second"] / below[0]["solver_per_sim_second"]
            r["cpu_ratio"] = r["cpu_per_sim_second"] / below[0]["cpu_per_sim_second"]
    return rows


def report() -> None:
    ref = reference()
    lines = ["# Cloth solver scaling: block-Jacobi against multigrid (benchmarks/cloth/scaling.py)", "",
             "The drape (drape_spec.py), one thread pinned to one CPU, medians of the repeats. CPU seconds per",
             "simulated second: the solver's (preconditioner update and conjugate gradients) and the whole",
             "step's; x: the ratio to the resolution below (one doubling). Profile error (mm) against",
             "compare.py's reference run at the shape times the run reaches.", ""]
    # runs of the same length and self-collision setting share a table (and its ratios)
    groups: dict[tuple, dict] = {}
    for path in sorted(RESULTS.glob("cloth_scaling_*.json")):
        for key, entry in json.loads(path.read_text()).items():
            groups.setdefault((entry["seconds"], entry["self_collision"]), {})[key] = entry
    for (seconds, self_collision), saved in sorted(groups.items()):
        rows = summarize(saved, ref)
        r0 = rows[0]
        lines += [f"## {r0['seconds']:g} s simulated, self-collision {r0['self_collision']}", "",
                  "| n x n | preconditioner | iterations / step | solver CPU s/s (x) | step CPU s/s (x) | "
                  "profile error (mm) | largest strain | repeats |",
                  "| --- | --- | --- | --- | --- | --- | --- | --- |"]
        for r in sorted(rows, key=lambda r: (r["n"], r["preconditioner"])):
            ratio = (lambda k: f" ({r[k]:.1f}x)" if k in r else "")
            errors = ", ".join(f"{1000 * e:.1f} at {t} s" for t, e in r["profile_error"].items() if e is not None)
            lines.append(f"| {r['n']} | {r['preconditioner'].replace('_', '-')} | {r['iterations_per_step']:.1f} | "
                         f"{r['solver_per_sim_second']:.3g}{ratio('solver_ratio')} | "
                         f"{r['cpu_per_sim_second']:.3g}{ratio('cpu_ratio')} | {errors} | "
                         f"{100 * r['max_strain']:.1f}% | {r['repeats']} |")
        lines.append("")
    (RESULTS / "cloth_scaling.md").write_text("\n".join(lines))
    print("\n".join(lines))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--resolutions", type=int, nargs="+", default=list(compare.spec.RESOLUTIONS))
    parser.add_argument("--seconds", type=float, default=0.5, help="simulated seconds per run")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--preconditioners", nargs="+", choices=PRECONDITIONERS, default=list(PRECONDITIONERS))
    parser.add_argument("--self-collision", choices=("on", "off"), default="off")
    parser.add_argument("--name", default="drape", help="results file cloth_scaling_<name>.json")
    parser.add_argument("--timeout", type=float, default=3600.0)
    parser.add_argument("--report", action="store_true", help="only the table from the saved runs")
    args = parser.parse_args()
    if not args.report:
        measure(args)
    report()


if __name__ == "__main__":
    main()
