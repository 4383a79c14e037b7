"""Wedges on Dask against sequential bakes, and the Dask path's cost per take.

    .venv/bin/python benchmarks/wedge_speed.py [--rounds 2] [--frames 13] [--tiny-takes 24]

1. A 12-take wedge of the shipped flag (assets/scenes/flag.toml, its first FRAMES frames:
   `--set scene.end_frame=FRAMES`): stretch stiffness 750 / 1500 / 3000 N/m x bend stiffness
   1e-4 / 1e-3 N m x seeds 0, 1. Four ways, each a whole process timed from outside (start-up,
   cluster start and the gathered USD included), run in turn round after round so that a
   busy minute hits them alike:
   - `sequential-1`: one process baking the 12 takes' scenes one after another, 1 thread each;
   - `sequential-2`: the same, each bake on 2 threads (one bake using both CPUs);
   - `wedge-1`: `simbake wedge ... --workers 1` (a LocalCluster of one worker process);
   - `wedge-2`: `simbake wedge ... --workers 2`.
   Speed-ups are ratios within one round (sequential-1 / wedge-2, ...), then their median.
2. The Dask path's cost per take on a tiny scene (a ball and a box, 3 frames, a few ms a
   bake): `simbake wedge --workers 1` with 1 and with TINY takes, and the sequential process
   with 1 and TINY takes. Per take: the slope (time(TINY) - time(1)) / (TINY - 1) of each;
   the overhead per take is the wedge's slope less the sequential one, the fixed cost (cluster
   start and stop) the difference at one take.

Writes benchmarks/results/wedge_speed.json (every run) and wedge_speed.md (the tables).
"""

from __future__ import annotations

import argparse
import json
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(HERE))
import common  # noqa: E402

SIMBAKE = str(Path(sys.executable).with_name("simbake"))
FLAG = REPO / "assets" / "scenes" / "flag.toml"
FLAG_SETS = ["cloths.flag.stretch_stiffness=750,1500,3000", "cloths.flag.bend_stiffness=1e-4,1e-3"]
FLAG_SEEDS = 2
TINY = """[scene]
end_frame = 3
[ground]
[[bodies]]
name = "ball"
shape = { type = "sphere", radius = 0.2 }
position = [0.0, 0.5, 0.0]
[[bodies]]
name = "crate"
shape = { type = "box", size = [0.3, 0.3, 0.3] }
position = [0.5, 0.15, 0.0]
"""


def _sets(frames: int | None) -> list[str]:
    return FLAG_SETS + ([f"scene.end_frame={frames}"] if frames else [])


def sequential(scene: str, sets: list[str], seeds: int, threads: int, out: Path) -> None:
    """Bake every take's scene one after another in this process (the baseline)."""
    import simbake
    from simbake.wedge_takes import parse_set, plan_takes, take_scene

    variations = dict(parse_set(s, scene) for s in sets)
    for take in plan_takes(variations, seeds, scene):
        simbake.bake(take_scene(scene, take, out, {}), out / f"{take.name}.usdc", threads=threads)


def _timed(command: list[str]) -> tuple[float, float]:
    """Wall seconds and CPU seconds (user + system of the whole process tree) of a command."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def _sequential_command(scene: Path, sets: list[str], seeds: int, threads: int, out: Path) -> list[str]:
    return [sys.executable, __file__, "sequential", str(scene), "--threads", str(threads), "--seeds", str(seeds),
            "--out", str(out), *[a for s in sets for a in ("--set", s)]]


def _wedge_command(scene: Path, sets: list[str], seeds: int, workers: int, out: Path) -> list[str]:
    return [SIMBAKE, "wedge", str(scene), *[a for s in sets for a in ("--set", s)], "--seeds", str(seeds),
            "--workers", str(workers), "-o", str(out / "w.usda"), "-q"]


def _fresh(folder: Path) -> Path:
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    return folder


def flag_rounds(rounds: int, frames: int, scratch: Path) -> dict[str, list[tuple[float, float]]]:
    """Each way's (wall, CPU) seconds per round, the four run in turn (rotated each round)."""
    sets = _sets(frames)
    ways = {
        "sequential-1": lambda out: _sequential_command(FLAG, sets, FLAG_SEEDS, 1, out),
        "sequential-2": lambda out: _sequential_command(FLAG, sets, FLAG_SEEDS, 2, out),
        "wedge-1": lambda out: _wedge_command(FLAG, sets, FLAG_SEEDS, 1, out),
        "wedge-2": lambda out: _wedge_command(FLAG, sets, FLAG_SEEDS, 2, out),
    }
    times: dict[str, list[tuple[float, float]]] = {name: [] for name in ways}
    names = list(ways)
    for r in range(rounds):
        for name in names[r % len(names):] + names[:r % len(names)]:
            wall, cpu = _timed(ways[name](_fresh(scratch / name)))
            times[name].append((wall, cpu))
            print(f"round {r + 1} {name}: {wall:.1f} s wall, {cpu:.1f} s CPU, load {common.load_average()[:1]}",
                  flush=True)
    return times


def tiny_runs(takes: int, repeats: int, scratch: Path) -> dict[str, list[tuple[float, float]]]:
    """(wall, CPU) seconds of the wedge (1 worker) and the sequential process at 1 and `takes` takes."""
    scene = scratch / "tiny.toml"
    scratch.mkdir(parents=True, exist_ok=True)
    scene.write_text(TINY)
    one = ["bodies.ball.restitution=0.5"]
    many = ["bodies.ball.restitution=" + ",".join(f"{0.02 * (k + 1):.2f}" for k in range(takes))]
    runs = {f"{way}-{n}": [] for way in ("wedge", "sequential") for n in (1, takes)}
    for _ in range(repeats):
        for sets, n in ((one, 1), (many, takes)):
            runs[f"wedge-{n}"].append(_timed(_wedge_command(scene, sets, 1, 1, _fresh(scratch / "w"))))
            runs[f"sequential-{n}"].append(_timed(_sequential_command(scene, sets, 1, 1, _fresh(scratch / "s"))))
    return runs


def _median(runs: list[tuple[float, float]], k: int) -> float:
    return statistics.median(run[k] for run in runs)


def _flag_tables(flag: dict) -> list[str]:
    def ratio(a: str, b: str) -> float:
        return statistics.median(x[0] / y[0] for x, y in zip(flag[a], flag[b]))

    rows = [[name, _median(runs, 0), min(r[0] for r in runs), max(r[0] for r in runs), _median(runs, 0) / 12,
             _median(runs, 1), statistics.median(cpu / wall for wall, cpu in runs)] for name, runs in flag.items()]
    return [
        common.markdown_table(["way", "median wall s", "min", "max", "wall s per take", "median CPU s",
                               "CPUs used (CPU s / wall s)"], rows), "",
        "Speed-ups (wall-time ratios within a round, median over rounds):", "",
        common.markdown_table(["ratio", "value"], [
            ["sequential-1 / wedge-2 (2 workers against one bake after another)", ratio("sequential-1", "wedge-2")],
            ["sequential-2 / wedge-2 (against one bake at a time on both threads)", ratio("sequential-2", "wedge-2")],
            ["sequential-1 / wedge-1 (1 worker: the Dask path's cost)", ratio("sequential-1", "wedge-1")],
            ["wedge-1 / wedge-2 (the second worker)", ratio("wedge-1", "wedge-2")],
            ["sequential-1 / sequential-2 (the second thread inside a bake)", ratio("sequential-1", "sequential-2")],
        ])]


def _tiny_tables(tiny: dict, n: int) -> list[str]:
    rows, slopes = [], {}
    for way, label in (("wedge", "simbake wedge --workers 1"), ("sequential", "sequential bakes in one process")):
        for k, unit in ((0, "wall"), (1, "CPU")):
            first, last = _median(tiny[f"{way}-1"], k), _median(tiny[f"{way}-{n}"], k)
            slopes[(way, k)] = (last - first) / (n - 1)
            rows.append([f"{label} ({unit})", first, last, slopes[(way, k)]])
    once = _median(tiny["wedge-1"], 0) - _median(tiny["sequential-1"], 0)
    return [
        common.markdown_table(["run", "1 take s", f"{n} takes s", "s per added take"], rows), "",
        f"Overhead of the Dask path per take: {slopes[('wedge', 0)] - slopes[('sequential', 0)]:.3f} s wall, "
        f"{slopes[('wedge', 1)] - slopes[('sequential', 1)]:.3f} s CPU; once per wedge: {once:.1f} s wall "
        "(a local cluster's start and stop, the gathered USD).",
    ]


def _autogroup() -> str:
    """Linux shares the CPUs between sessions first when autogroup is on: say so."""
    try:
        on = Path("/proc/sys/kernel/sched_autogroup_enabled").read_text().strip() == "1"
    except OSError:
        return ""
    return (" The kernel schedules by session (`kernel.sched_autogroup_enabled = 1`): with other sessions busy,"
            " all the processes of this one share one session's part of the CPUs, however many they are"
            " (the last column).") if on else ""


def _report(flag: dict, tiny: dict, args, command: str, load: tuple) -> str:
    return "\n".join([
        "# Wedges on Dask against sequential bakes", "",
        f"`{command}`", "",
        f"Load average (1 min) {load[0]:.1f} at the start, {load[1]:.1f} at the end, on 2 CPUs shared with other "
        "processes: wall times are this run's; CPU seconds (user + system of the whole process tree) do not "
        "depend on the load as much." + _autogroup(), "",
        f"12 takes of `assets/scenes/flag.toml` (frames 1-{args.frames}; {', '.join(FLAG_SETS)}; seeds 0, 1), "
        f"whole processes, {args.rounds} round(s), the four ways in turn:", "",
        *_flag_tables(flag), "",
        f"The Dask path on a tiny scene (a ball and a box, 3 frames), 1 worker, medians of {args.tiny_repeats}:", "",
        *_tiny_tables(tiny, args.tiny_takes), "",
    ])


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command")
    s = sub.add_parser("sequential", help="(internal) bake a wedge's takes one after another")
    s.add_argument("scene")
    s.add_argument("--set", dest="sets", action="append", default=[])
    s.add_argument("--seeds", type=int, default=1)
    s.add_argument("--threads", type=int, default=1)
    s.add_argument("--out", type=Path, required=True)
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--frames", type=int, default=13, help="the flag's last frame (its first frames)")
    p.add_argument("--tiny-takes", type=int, default=24)
    p.add_argument("--tiny-repeats", type=int, default=3)
    p.add_argument("--report-only", action="store_true", help="write the tables again from the last run's JSON")
    args = p.parse_args()
    if args.command == "sequential":
        sequential(args.scene, args.sets, args.seeds, args.threads, args.out)
        return 0
    if args.report_only:
        return _rewrite_report()
    command = "python benchmarks/wedge_speed.py " + " ".join(sys.argv[1:])
    scratch = Path(tempfile.mkdtemp(prefix="wedge_speed-"))
    try:
        info = common.machine_info()
        tiny = tiny_runs(args.tiny_takes, args.tiny_repeats, scratch / "tiny")
        flag = flag_rounds(args.rounds, args.frames, scratch / "flag")
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    text = _report(flag, tiny, args, command, (info["load_average_1_5_15_min"][0], common.load_average()[0]))
    common.RESULTS_DIR.mkdir(exist_ok=True)
    (common.RESULTS_DIR / "wedge_speed.md").write_text(text)
    (common.RESULTS_DIR / "wedge_speed.json").write_text(json.dumps(
        {"command": command, "machine": info, "machine_after": common.load_average(), "flag_seconds": flag,
         "tiny_seconds": tiny, "frames": args.frames, "tiny_takes": args.tiny_takes}, indent=1) + "\n")
    print(text)
    return 0


def _rewrite_report() -> int:
    data = json.loads((common.RESULTS_DIR / "wedge_speed.json").read_text())
    args = argparse.Namespace(frames=data["frames"], tiny_takes=data["tiny_takes"],
                              rounds=len(data["flag_seconds"]["wedge-1"]),
                              tiny_repeats=len(data["tiny_seconds"]["wedge-1"]))
    text = _report(data["flag_seconds"], data["tiny_seconds"], args, data["command"],
                   (data["machine"]["load_average_1_5_15_min"][0], data["machine_after"][0]))
    (common.RESULTS_DIR / "wedge_speed.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
