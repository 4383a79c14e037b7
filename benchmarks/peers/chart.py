"""Bar chart of benchmarks/results/peers.json (called by compare.py with a matplotlib venv).

    python chart.py peers.json peers.png

Wall seconds per simulated second (log scale) per scene and engine, each bar annotated with
its accuracy; bars that did not simulate the full scene are hatched.
"""

from __future__ import annotations

import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

COLORS = {"simbake": "#d62728", "pybullet": "#1f77b4", "mujoco": "#2ca02c", "blender": "#ff7f0e"}
LABELS = {"simbake": "simbake", "pybullet": "PyBullet", "mujoco": "MuJoCo", "blender": "Blender (bpy)"}
SCENE_LABELS = {
    "tower": "(a) tower\n10 boxes", "pyramid": "(c) pyramid\n120 boxes",
    "pile": "(b) pile\n1000 boxes", "pile216": "(b') pile\n216 boxes",
    "drop": "(d) sphere drop\ne 0.5", "incline_slide": "(e) incline\nmu 0.5",
    "incline_stick": "(e) incline\nmu 0.7", "pile_aligned": "(b) pile\n1000 aligned",
    "pile_meshes": "(f) pile.toml\n200 meshes",
}


def scene_label(payload, scene):
    spans = [payload["results"][e][scene]["simulated_seconds"] for e in payload["engines"]
             if "error" not in payload["results"][e][scene]]
    return SCENE_LABELS.get(scene, scene) + (f", {max(set(spans), key=spans.count):g} s" if spans else "")


def main(json_path: str, png_path: str) -> None:
    payload = json.loads(open(json_path).read())
    engines, scenes, res = payload["engines"], payload["scenes"], payload["results"]
    width = 0.8 / len(engines)
    fig, ax = plt.subplots(figsize=(max(9.0, 1.9 * len(scenes) + 2.0), 6.8), dpi=120)
    values = []
    for j, engine in enumerate(engines):
        for i, scene in enumerate(scenes):
            entry = res.get(engine, {}).get(scene)
            x = i + (j - 0.5 * (len(engines) - 1)) * width
            if not entry or "error" in entry:
                ax.annotate("failed" if entry else "not run", (x, 0), xycoords=("data", "axes fraction"),
                            xytext=(0, 4), textcoords="offset points", rotation=90, ha="center",
                            va="bottom", fontsize=6.5, color="gray")
                continue
            rate = entry["wall_per_simulated_second"]
            runs = entry["wall_per_simulated_second_runs"]
            spans = [res[e][scene]["simulated_seconds"] for e in engines if "error" not in res[e][scene]]
            capped = entry["simulated_seconds"] < max(spans) - 1e-9
            ax.bar(x, rate, width * 0.92, color=COLORS.get(engine, "gray"), hatch="///" if capped else None,
                   edgecolor="white" if capped else None, linewidth=0,
                   label=LABELS.get(engine, engine) if i == 0 else None)
            if len(runs) > 1:
                ax.plot([x, x], [min(runs), max(runs)], color="black", linewidth=0.8)
            text = entry["summary"] + (f" [first {entry['simulated_seconds']:g} s]" if capped else "")
            ax.annotate(text, (x, rate), xytext=(0, 3), textcoords="offset points", rotation=90,
                        ha="center", va="bottom", fontsize=6.5)
            values.append(rate)
    ax.set_yscale("log")
    if values:
        ax.set_ylim(min(values) / 3.0, max(values) * 3000.0)   # room for the labels above the bars
    ax.axhline(1.0, color="gray", linestyle="--", linewidth=0.8)
    ax.annotate("real time", (0.995, 1.0), xycoords=("axes fraction", "data"), xytext=(0, 2),
                textcoords="offset points", ha="right", fontsize=7, color="gray")
    ax.set_xticks(range(len(scenes)))
    ax.set_xticklabels([scene_label(payload, s) for s in scenes], fontsize=8)
    ax.set_ylabel("wall seconds per simulated second (one thread, log)")
    ax.set_title("Rigid bodies, same scenes: stepping time and accuracy per engine", fontsize=10)
    ax.grid(True, axis="y", which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", ncol=len(engines))
    versions = ", ".join(f"{LABELS.get(e, e)} {payload['versions'].get(e) or '-'}" for e in engines)
    fig.text(0.99, 0.005, f"{versions}; {payload['machine']['cpu_model']}; {payload['machine']['date']}; "
             "hatched = capped run; whiskers = min/max of runs", ha="right", va="bottom", fontsize=6, color="gray")
    fig.tight_layout(rect=(0, 0.02, 1, 1))
    fig.savefig(png_path)
    plt.close(fig)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
