"""simbake's rigid speed against the peers' saved figures, without rerunning the peers.

    python3 benchmarks/peers/speed_report.py [--baseline-python /work/main/.venv/bin/python]
        [--scenes tower pyramid pile pile_aligned] [--repeats 3]

Runs compare.py for simbake alone (this checkout's .venv, pinned to one CPU, thread variables
at 1, median of --repeats runs) into a scratch directory, and, with --baseline-python, the same
for another simbake build (say the main checkout's, for the speed-up of this branch measured
in one sitting). Blender, MuJoCo and PyBullet are read from benchmarks/results/peers.json, the
last full peer run (compare.py overwrites peers.json whole, so a simbake-only run there would
drop them). Writes benchmarks/results/rigid_speed.{json,md}.

The machine is shared: besides wall seconds per simulated second (the peer table's measure)
the table gives the stepping's CPU seconds per simulated second, which another process's load
inflates far less; the peers' saved runs had CPU / wall near 1.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
RESULTS = ROOT / "benchmarks" / "results"
PEERS = ("blender", "mujoco", "pybullet")
LABELS = {"simbake": "simbake (this branch)", "baseline": "simbake (baseline)", "blender": "Blender (bpy)",
          "mujoco": "MuJoCo", "pybullet": "PyBullet"}


def run_compare(python: Path, scenes: list, repeats: int) -> dict:
    with tempfile.TemporaryDirectory() as scratch:
        cmd = [sys.executable, str(HERE / "compare.py"), "--engines", "simbake", "--scenes", *scenes,
               "--simbake-pile-seconds", "0", "--no-extras", "--repeats", str(repeats), "--out", scratch,
               "--simbake-python", str(python)]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        return json.loads((Path(scratch) / "peers.json").read_text())


def row(entry: dict) -> dict:
    acc = entry.get("accuracy", {})
    runs = entry.get("raw", entry)
    cpu = entry.get("step_cpu_over_wall")
    wall = entry.get("wall_per_simulated_second")
    return {"wall_per_simulated_second": wall,
            "cpu_per_simulated_second": wall * cpu if (wall is not None and cpu is not None) else None,
            "penetration_mm": acc.get("penetration_mm"), "penetration_end_mm": acc.get("penetration_end_mm"),
            "drift_mm": acc.get("drift_mm"), "max_speed_end": acc.get("max_speed_end"),
            "substeps_per_frame": (entry.get("settings") or {}).get("substeps_per_frame_mean"),
            "runs": entry.get("runs")}


def fmt(x, digits=3):
    return "-" if x is None else f"{x:.{digits}g}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", nargs="+", default=["tower", "pyramid", "pile", "pile_aligned"])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--baseline-python", type=Path, default=None)
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args()
    load_start = list(os.getloadavg())
    saved = json.loads((RESULTS / "peers.json").read_text())
    engines = {"simbake": run_compare(ROOT / ".venv" / "bin" / "python", args.scenes, args.repeats)}
    if args.baseline_python:
        engines["baseline"] = run_compare(args.baseline_python, args.scenes, args.repeats)
    table = {}
    for scene in args.scenes:
        table[scene] = {name: row(run["results"]["simbake"][scene]) for name, run in engines.items()
                        if scene in run["results"].get("simbake", {})}
        for peer in PEERS:
            entry = saved["results"].get(peer, {}).get(scene)
            if entry:
                table[scene][peer] = row(entry)
    payload = {"benchmark": "rigid_speed", "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
               "command": " ".join(["python3", "benchmarks/peers/speed_report.py", *sys.argv[1:]]),
               "load_average_start": load_start, "load_average_end": list(os.getloadavg()),
               "peers_from": {"file": "benchmarks/results/peers.json", "date": saved["machine"].get("date"),
                              "load_average_start": saved.get("load_average_start")},
               "simbake_runs": {name: {"machine": run["machine"], "modules": run.get("simbake_modules"),
                                       "git": run.get("git")} for name, run in engines.items()},
               "table": table}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "rigid_speed.json").write_text(json.dumps(payload, indent=1) + "\n")
    names = [n for n in ("simbake", "baseline", *PEERS) if any(n in t for t in table.values())]
    lines = ["# Rigid speed: simbake against the peers' saved figures", "",
             f"{payload['date']}; `{payload['command']}`; load average at the start "
             f"{', '.join(f'{x:.2f}' for x in load_start)} (2 vCPU, shared). simbake runs: compare.py, pinned to one CPU, "
             f"thread variables at 1, median of {args.repeats}; peers: benchmarks/results/peers.json "
             f"({payload['peers_from']['date']}, the last full peer run, not rerun).", "",
             "Each cell: wall s / simulated s (CPU s / simulated s), deepest penetration at any frame / at the end "
             "(mm; piles) or drift (mm; tower, pyramid).", "",
             "| scene | " + " | ".join(LABELS[n] for n in names) + " |", "| --- |" + " --- |" * len(names)]
    for scene, cells in table.items():
        out = []
        for n in names:
            c = cells.get(n)
            if not c:
                out.append("-")
                continue
            accuracy = (f"pen {fmt(c['penetration_mm'])} / {fmt(c['penetration_end_mm'])} mm" if scene.startswith("pile")
                        else f"drift {fmt(c['drift_mm'])} mm, pen {fmt(c['penetration_mm'])} mm")
            out.append(f"{fmt(c['wall_per_simulated_second'])} ({fmt(c['cpu_per_simulated_second'])}); {accuracy}")
        lines.append(f"| {scene} | " + " | ".join(out) + " |")
    (args.out / "rigid_speed.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
