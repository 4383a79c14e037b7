"""Shared helpers of the run-time-versus-error benchmarks.

Every benchmark script defines ``NAME`` and ``run() -> Result`` and ends with
``if __name__ == "__main__": common.main(run)``; ``run_all.py`` calls the same ``run``
functions. Python only orchestrates: all stepping and baking happens in the C++ core.

Conventions:
- every wall time is a single-thread figure (see /work/shared/PLATFORM.md: the second vCPU
  is not always there). The world step runs on one thread anyway; OpenVDB bakes with TBB,
  so the level-set benchmark calls ``pin_to_one_cpu()`` before its first bake (TBB sizes
  its pool from the affinity mask when it first starts, so this holds for the rest of the
  process: run it last);
- wall times are medians of repeats, and only the stepping (or baking) is inside the clock;
  the process CPU time of the same repeats is kept beside them (wall much above CPU means
  the machine was busy);
- results go to ``benchmarks/results/<name>.json`` (raw numbers and machine info),
  ``<name>.md`` (a markdown table) and ``<name>.png`` (run time against error, log-log).
"""

from __future__ import annotations

import datetime
import json
import math
import os
import platform
import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

import simbake
from simbake import _core

RESULTS_DIR = Path(__file__).resolve().parent / "results"

FPS = 24
SUBSTEPS = [1, 2, 4, 8, 16, 32, 64]
AUTOMATIC = 0  # substeps=0: the world's automatic rule picks the count every frame


def pin_to_one_cpu() -> list[int]:
    """Restrict this process to one CPU (TBB, once started, keeps a pool of that size)."""
    if hasattr(os, "sched_setaffinity"):
        cpus = sorted(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cpus[-1]})
    return allowed_cpus()


def allowed_cpus() -> list[int]:
    return sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []


def load_average() -> list[float]:
    try:
        return list(os.getloadavg())
    except OSError:
        return []


# ---------------------------------------------------------------------------------------
# machine info and timing


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def machine_info() -> dict:
    return {
        "platform": platform.platform(),
        "cpu_model": cpu_model(),
        "logical_cpus": os.cpu_count(),
        "allowed_cpus": allowed_cpus(),
        "load_average_1_5_15_min": load_average(),
        "python": sys.version.split()[0],
        "numpy": np.__version__,
        "simbake_version": getattr(simbake, "__version__", _core.__version__),
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
    }


_WALL_OVER_CPU: list[float] = []  # of every timed repeat since the last write_result


def median_time(body: Callable[[object], object], setup: Callable[[], object] = lambda: None,
                repeats: int = 5) -> dict:
    """Median wall time of body(setup()) over `repeats`; only body is inside the clock."""
    times, cpu = [], []
    for _ in range(repeats):
        state = setup()
        start, start_cpu = time.perf_counter(), time.process_time()
        body(state)
        cpu.append(time.process_time() - start_cpu)
        times.append(time.perf_counter() - start)
        if cpu[-1] > 0.0:
            _WALL_OVER_CPU.append(times[-1] / cpu[-1])
    return {"median": statistics.median(times), "min": min(times), "max": max(times),
            "cpu_median": statistics.median(cpu), "repeats": repeats, "all": times}


# ---------------------------------------------------------------------------------------
# building worlds (the core's Python API, with the benchmarks' defaults)

IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])
SPHERE_SUBDIVISIONS = 8  # same surface samples as the pipeline's sphere primitive (386)
BOX_SUBDIVISIONS = 4     # same surface samples as the pipeline's box primitive (98)


def vec(*values: float) -> np.ndarray:
    return np.array(values, dtype=np.float64)


def body_state(world: "_core.World", i: int) -> dict:
    """Body i's state (center_of_mass, orientation, linear_velocity, ...), from the world's arrays."""
    return {key: values[i] for key, values in world.body_states().items()}


def add_sphere(world: "_core.World", radius: float, mass: float, position, **kwargs) -> int:
    vertices, _ = _core.sphere_mesh(radius, SPHERE_SUBDIVISIONS)
    return world.add_body(shape=_core.LevelSet.sphere(radius), samples=vertices,
                          mass_properties=_core.sphere_mass_properties(radius), mass=mass,
                          origin=np.asarray(position, dtype=float), orientation=IDENTITY, **kwargs)


def add_box(world: "_core.World", size, mass: float, position, with_shape: bool = True, **kwargs) -> int:
    size = np.asarray(size, dtype=float)
    vertices, _ = _core.box_mesh(size, BOX_SUBDIVISIONS)
    shape = _core.LevelSet.box(size) if with_shape else None
    return world.add_body(shape=shape, samples=vertices, mass_properties=_core.box_mass_properties(size),
                          mass=mass, origin=np.asarray(position, dtype=float), orientation=IDENTITY, **kwargs)


def frame_substeps(world: "_core.World", substeps: int, frame_dt: float = 1.0 / FPS) -> int:
    """The substeps of the next frame: the fixed count, or what the automatic rule picks."""
    return substeps if substeps > 0 else world.automatic_substeps(frame_dt)


def time_stepping(make_world: Callable[[], "_core.World"], substeps: int, frames: int,
                  repeats: int = 5) -> dict:
    """Median wall time of `frames` calls of World.step_frame (all stepping in C++), per
    simulated second; the world is built outside the clock."""
    def body(world):
        for _ in range(frames):
            world.step_frame(1.0 / FPS, substeps)

    timing = median_time(body, make_world, repeats)
    seconds = frames / FPS
    timing["per_simulated_second"] = timing["median"] / seconds
    timing["cpu_per_simulated_second"] = timing["cpu_median"] / seconds
    timing["simulated_seconds"] = seconds
    return timing


def substeps_label(substeps: int, automatic_mean: float | None = None) -> str:
    if substeps > 0:
        return str(substeps)
    return "auto" if automatic_mean is None else f"auto ({automatic_mean:.3g})"


# ---------------------------------------------------------------------------------------
# quaternions [w, x, y, z], vectorised over a leading axis (numpy only, for measurements)


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    aw, ax, ay, az = np.moveaxis(np.asarray(a, dtype=float), -1, 0)
    bw, bx, by, bz = np.moveaxis(np.asarray(b, dtype=float), -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw], axis=-1)


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    return np.asarray(q, dtype=float) * np.array([1.0, -1.0, -1.0, -1.0])


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
                     np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
                     np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], -2)


def rotation_vector(q: np.ndarray) -> np.ndarray:
    """Axis times angle (rad) of unit quaternions, the angle in [0, pi]."""
    q = np.asarray(q, dtype=float)
    q = np.where(q[..., :1] < 0.0, -q, q)  # the short way round
    v = q[..., 1:]
    s = np.linalg.norm(v, axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, q[..., :1])
    # angle / s -> 2 as s -> 0
    scale = np.where(s > 1e-12, angle / np.where(s > 1e-12, s, 1.0), 2.0)
    return v * scale


def quat_from_rotation_vector(r: np.ndarray) -> np.ndarray:
    r = np.asarray(r, dtype=float)
    angle = np.linalg.norm(r, axis=-1, keepdims=True)
    half = 0.5 * angle
    scale = np.where(angle > 1e-12, np.sin(half) / np.where(angle > 1e-12, angle, 1.0), 0.5)
    return np.concatenate([np.cos(half), r * scale], axis=-1)


# ---------------------------------------------------------------------------------------
# results


@dataclass
class Series:
    """One line of a run-time-versus-error plot."""
    label: str
    time: Sequence[float]            # x: wall seconds (per simulated second, or per bake)
    error: Sequence[float]           # y: the error (relative or absolute)
    point_labels: Sequence[str]      # substeps or voxel size, written beside each point
    marker: str = "o"


@dataclass
class Result:
    name: str
    title: str
    data: dict                       # raw numbers (JSON-serialisable)
    table_headers: list[str]
    table_rows: list[list]
    series: list[Series]
    xlabel: str
    ylabel: str
    notes: list[str] = field(default_factory=list)
    reference_lines: list[tuple[float, str]] = field(default_factory=list)  # dashed (y, label)


def fmt(value, digits: int = 3) -> str:
    if value is None:
        return "-"
    if isinstance(value, str):
        return value
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    value = float(value)
    if math.isnan(value):
        return "nan"
    if value == 0.0:
        return "0"
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    if 1e-3 <= abs(value) < 1e5:
        return f"{value:.{digits}g}"
    return f"{value:.{max(digits - 1, 1)}e}"


def markdown_table(headers: Sequence[str], rows: Sequence[Sequence]) -> str:
    lines = ["| " + " | ".join(headers) + " |", "| " + " | ".join("---" for _ in headers) + " |"]
    lines += ["| " + " | ".join(fmt(v) for v in row) + " |" for row in rows]
    return "\n".join(lines)


def _jsonable(value):
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None if math.isnan(value) else ("inf" if value > 0 else "-inf")
    return value


def plot(result: Result, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 5.2), dpi=120)
    floor = None
    positive = [e for s in result.series for e in s.error if e is not None and e > 0 and math.isfinite(e)]
    if positive:
        floor = min(positive) / 3.0
    for s in result.series:
        xs, ys, labels, clipped = [], [], [], []
        for x, y, label in zip(s.time, s.error, s.point_labels):
            if x is None or y is None or not math.isfinite(x) or not math.isfinite(y):
                continue
            is_clipped = y <= 0.0 and floor is not None
            xs.append(x)
            ys.append(floor if is_clipped else y)
            labels.append(label + (" (=0)" if is_clipped else ""))
            clipped.append(is_clipped)
        if not xs:
            continue
        line, = ax.plot(xs, ys, marker=s.marker, label=s.label)
        for x, y, label in zip(xs, ys, labels):
            ax.annotate(label, (x, y), textcoords="offset points", xytext=(5, 4), fontsize=7.5,
                        color=line.get_color())
    for y, label in result.reference_lines:
        ax.axhline(y, color="gray", linestyle="--", linewidth=0.9)
        ax.annotate(label, (0.01, y), xycoords=("axes fraction", "data"), textcoords="offset points",
                    xytext=(0, 3), fontsize=7.5, color="gray")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(result.xlabel)
    ax.set_ylabel(result.ylabel)
    ax.set_title(result.title, fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.text(0.99, 0.005, f"simbake {machine_info()['simbake_version']}, one thread, "
             f"{cpu_model()}", ha="right", va="bottom", fontsize=6.5, color="gray")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def write_result(result: Result, seconds: float, results_dir: Path = RESULTS_DIR) -> dict:
    results_dir.mkdir(parents=True, exist_ok=True)
    info = machine_info()
    ratio = statistics.median(_WALL_OVER_CPU) if _WALL_OVER_CPU else float("nan")
    _WALL_OVER_CPU.clear()
    payload = {"benchmark": result.name, "title": result.title, "machine": info,
               "benchmark_wall_seconds": seconds, "median_wall_over_cpu": ratio,
               "notes": result.notes, "results": result.data}
    (results_dir / f"{result.name}.json").write_text(json.dumps(_jsonable(payload), indent=2) + "\n")
    md = [f"# {result.title}", "",
          f"simbake {info['simbake_version']}, {info['cpu_model']}, one thread, {info['date']}, "
          f"load average {', '.join(f'{v:.2f}' for v in info['load_average_1_5_15_min'])} "
          f"(2 vCPU); the benchmark took {seconds:.1f} s. Wall times are medians of repeats "
          f"of the stepping (or baking) alone; wall / CPU time of those repeats: {ratio:.2f} "
          "(median; 1.0 = the CPU was ours alone).", "",
          markdown_table(result.table_headers, result.table_rows), ""]
    md += [f"- {note}" for note in result.notes]
    (results_dir / f"{result.name}.md").write_text("\n".join(md).rstrip() + "\n")
    plot(result, results_dir / f"{result.name}.png")
    return payload


def run_and_write(run: Callable[[], Result]) -> Result:
    _WALL_OVER_CPU.clear()
    start = time.perf_counter()
    result = run()
    seconds = time.perf_counter() - start
    write_result(result, seconds)
    print(f"\n## {result.title}  ({seconds:.1f} s)\n")
    print(markdown_table(result.table_headers, result.table_rows))
    for note in result.notes:
        print(f"- {note}")
    print(f"-> {RESULTS_DIR / result.name}.{{json,md,png}}", flush=True)
    return result


def main(run: Callable[[], Result]) -> None:
    run_and_write(run)


def run_benchmarks(modules, names: list[str], summary_name: str, label: str, extra: dict | None = None) -> None:
    """Run the benchmark modules named in `names` (all when empty), write each one's results
    and a summary RESULTS_DIR/<summary_name> with the seconds each took."""
    import json
    import sys
    import time

    known = {module.NAME: module for module in modules}
    unknown = [name for name in names if name not in known]
    if unknown:
        sys.exit(f"unknown benchmark(s): {', '.join(unknown)}; known: {', '.join(known)}")
    chosen = [module for module in modules if not names or module.NAME in names]
    start = time.perf_counter()
    seconds = {}
    for module in chosen:
        t0 = time.perf_counter()
        run_and_write(module.run)
        seconds[module.NAME] = time.perf_counter() - t0
    total = time.perf_counter() - start
    summary = {"machine": machine_info(), **(extra or {}), "benchmark_seconds": seconds, "total_seconds": total}
    RESULTS_DIR.mkdir(parents=True, exist_ok=True)
    (RESULTS_DIR / summary_name).write_text(json.dumps(summary, indent=2) + "\n")
    print(f"\n{label}: {len(chosen)} benchmark(s) in {total:.1f} s "
          f"({', '.join(f'{k} {v:.1f} s' for k, v in seconds.items())})")
