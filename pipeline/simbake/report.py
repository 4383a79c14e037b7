"""`simbake report`: one page that tells a lead in ten seconds whether a bake is right.

From the cache's QA sidecar (CACHE.qa.json, simbake.qa) and the cache itself: a verdict line
(clean, or the warnings), the quality figures against frame with their thresholds
(penetrations, cloth strain, self-intersections, kinetic energy, substeps and wall time),
where the bake's time went (the stage profile), the scene's settings, and a strip of preview
frames (simbake.preview). As a PNG (one matplotlib page) or as a self-contained HTML page
(the same page as an embedded image, with the warnings and settings as text).
"""

from __future__ import annotations

import base64
import html
import io
import json
from pathlib import Path
from typing import Any

import numpy as np

from .errors import SceneError
from .files import check_input_file, check_output_path, describe, sha256_of, write_atomically
from .qa import BODY_PENETRATION, CLOTH_PENETRATION, QA_VERSION, STRAIN_MARGIN, qa_path

OUTPUT_SUFFIXES = (".html", ".png")
STRIP_FRAMES = 6
STRIP_SIZE = (400, 225)
OK_COLOR, BAD_COLOR = "#2e7d32", "#c62828"


def report_path(cache: str | Path) -> Path:
    cache = Path(cache)
    return cache.with_name(cache.stem + ".report.html")


def _load(cache: Path) -> dict[str, Any]:
    """The QA data beside `cache`: a sidecar simbake wrote for this very cache (its SHA-256
    matches), of the shape simbake writes; else a one-line SceneError."""
    check_input_file(cache, cache, "")
    sidecar = qa_path(cache)
    if not sidecar.is_file():
        raise SceneError(cache, "", f"no QA data beside it ({sidecar.name} is missing; bake it again to make one)")
    try:
        data = json.loads(sidecar.read_text())
    except (OSError, ValueError) as error:
        raise SceneError(sidecar, "", f"cannot read the QA data: {describe(error)}") from None
    if not isinstance(data, dict) or data.get("simbake_qa") != QA_VERSION:
        version = data.get("simbake_qa") if isinstance(data, dict) else None
        raise SceneError(sidecar, "simbake_qa", f"unknown QA data version {version!r} (this simbake reads "
                                                f"{QA_VERSION}; bake again to make one)")
    _expect(data, SIDECAR, "", sidecar)
    frames = len(data["frames"])
    for group, series in [("figures", data["figures"])] + [(f"cloths.{n}", c) for n, c in data["cloths"].items()]:
        for name, values in series.items():
            if isinstance(values, list) and len(values) != frames:
                raise SceneError(sidecar, f"{group}.{name}", f"has {len(values)} values for {frames} frames")
    if sha256_of(cache) != data["cache_sha256"]:
        raise SceneError(sidecar, "cache_sha256", f"is the QA data of another cache, not of {cache.name} "
                                                  "(the cache was replaced or edited since); bake it again")
    return data


# The sidecar's shape, as far as the report reads it (simbake.qa writes it): a type, NUMBER,
# [schema] (a list of), {key: schema} (a table; "*" for any key), or a tuple of alternatives
NUMBER = "number"
_SERIES = [(NUMBER, type(None))]
SIDECAR = {
    "cache_sha256": str, "frames": [int], "warnings": [str], "profile": {"*": NUMBER},
    "figures": {name: _SERIES for name in ("body_penetration", "cloth_penetration", "kinetic_energy",
                                           "substeps", "wall_seconds")},
    "cloths": {"*": {"strain": _SERIES, "self_intersections": _SERIES}},
    "summary": {"*": {"worst": NUMBER, "frame": int, "threshold": (NUMBER, type(None)),
                      "first_over": (int, type(None))}},
    "scene": {"sha256": str, "settings": {
        "path": str, "start_frame": int, "end_frame": int, "fps": NUMBER, "gravity": [NUMBER], "substeps": int,
        "ground": (type(None), {"height": NUMBER, "friction": NUMBER, "restitution": NUMBER}),
        "bodies": [{"shape": {"kind": str}, "kinematic": bool}],
        "cloths": [{"name": str, "grid_resolution": (type(None), [int]), "mesh_path": (type(None), str),
                    "model": str, "stretch_stiffness": NUMBER, "strain_limit": NUMBER, "thickness": NUMBER,
                    "pinned": [int]}]}},
}


def _expect(value, schema, key: str, sidecar: Path) -> None:
    """Refuse a value of the wrong shape, naming its key in the sidecar."""
    if isinstance(schema, tuple):
        for alternative in schema:
            try:
                return _expect(value, alternative, key, sidecar)
            except SceneError:
                pass
        raise SceneError(sidecar, key, "has the wrong type (not a QA sidecar simbake wrote; bake again)")
    if schema == NUMBER:
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    elif isinstance(schema, type):
        ok = isinstance(value, schema) and (schema is bool or not isinstance(value, bool))
    else:
        ok = isinstance(value, list if isinstance(schema, list) else dict)
    if not ok:
        raise SceneError(sidecar, key or "(top)", "has the wrong type (not a QA sidecar simbake wrote; bake again)")
    if isinstance(schema, list):
        for k, item in enumerate(value):
            _expect(item, schema[0], f"{key}[{k}]", sidecar)
    elif isinstance(schema, dict):
        for name, inner in schema.items():
            names = [n for n in value if isinstance(n, str)] if name == "*" else [name]
            for n in names:
                if n not in value:
                    raise SceneError(sidecar, f"{key}.{n}".lstrip("."), "is missing (not a QA sidecar simbake wrote; bake again)")
                _expect(value[n], inner, f"{key}.{n}".lstrip("."), sidecar)


def _settings_lines(qa: dict[str, Any]) -> list[str]:
    """The scene in a few lines: time, solver, ground, bodies by shape, each cloth."""
    s = qa["scene"]["settings"]
    frames = s["end_frame"] - s["start_frame"] + 1
    lines = [f"scene  {Path(s['path']).name}  (sha256 {qa['scene']['sha256'][:12]})",
             f"frames {s['start_frame']}-{s['end_frame']} ({frames}) at {s['fps']:g} fps, "
             f"{(frames - 1) / s['fps']:.2f} s",
             f"gravity {tuple(s['gravity'])} m/s^2, substeps {s['substeps'] or 'automatic'}"]
    g = s.get("ground")
    lines.append(f"ground y = {g['height']:g}, friction {g['friction']:g}, restitution {g['restitution']:g}"
                 if g else "no ground")
    bodies = s.get("bodies", [])
    if bodies:
        kinds: dict[str, int] = {}
        for b in bodies:
            kinds[b["shape"]["kind"]] = kinds.get(b["shape"]["kind"], 0) + 1
        kinematic = sum(1 for b in bodies if b["kinematic"])
        noun = "body" if len(bodies) == 1 else "bodies"
        lines.append(f"{len(bodies)} {noun}: " + ", ".join(f"{n} {k}" for k, n in sorted(kinds.items()))
                     + (f" ({kinematic} kinematic)" if kinematic else ""))
    for c in s.get("cloths", []):
        res = c.get("grid_resolution")
        shape = f"{res[0]}x{res[1]} grid" if res else Path(c["mesh_path"]).name
        lines.append(f"cloth {c['name']}: {shape}, {c['model']}, {c['stretch_stiffness']:g} N/m, "
                     f"limit {c['strain_limit']:g}, thickness {c['thickness'] * 1e3:g} mm, "
                     f"{len(c['pinned'])} pinned")
    return lines


def _strip(cache: Path, qa: dict[str, Any]) -> tuple[list[tuple[int, np.ndarray]], str | None]:
    """Preview frames for the page, or none and the reason."""
    from .preview import Preview, parse_frames

    try:
        preview = Preview(cache, STRIP_SIZE)
        try:
            frames = parse_frames(None, preview.start, preview.end, STRIP_FRAMES)
            return list(preview.frames(frames)), None
        finally:
            preview.close()
    except SceneError as error:
        return [], error.problem


def figure(cache: Path, qa: dict[str, Any]):
    """The report page as a matplotlib Figure."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    frames = np.array(qa["frames"])
    f = qa["figures"]
    summary, warnings = qa["summary"], qa["warnings"]
    strip, strip_problem = _strip(cache, qa)

    fig = plt.figure(figsize=(16, 10.5), dpi=100)
    grid = fig.add_gridspec(4, 4, height_ratios=[0.62, 1, 1, 0.8], hspace=0.5, wspace=0.3,
                            left=0.05, right=0.98, top=0.97, bottom=0.03)
    # the verdict, and the scene beside it
    head = fig.add_subplot(grid[0, :2])
    head.axis("off")
    verdict = "clean: no figure over its threshold" if not warnings else f"{len(warnings)} warning(s)"
    wall = sum(f["wall_seconds"])
    head.text(0, 1, f"{cache.name}", fontsize=18, weight="bold", va="top")
    head.text(0, 0.78, f"{len(frames)} frames, {sum(f['substeps'])} substeps, {wall:.1f} s of stepping",
              fontsize=11, va="top")
    head.text(0, 0.58, verdict, fontsize=14, color=OK_COLOR if not warnings else BAD_COLOR, va="top", weight="bold")
    for k, line in enumerate(warnings[:4]):
        head.text(0, 0.38 - 0.15 * k, line.split("; see")[0], fontsize=9.5, color=BAD_COLOR, va="top")
    scene = fig.add_subplot(grid[0, 2:])
    scene.axis("off")
    for k, line in enumerate(_settings_lines(qa)[:9]):
        scene.text(0, 1 - 0.12 * k, line, fontsize=9, family="monospace", va="top")

    def plot(cell, title, series, threshold=None, unit=""):
        ax = fig.add_subplot(cell)
        for label, values, scale in series:
            ax.plot(frames, np.asarray(values, dtype=float) * scale, label=label, lw=1.4)
        if threshold is not None:
            ax.axhline(threshold, color=BAD_COLOR, ls="--", lw=1, label="threshold")
        ax.set_title(title, fontsize=11)
        ax.set_xlabel("frame", fontsize=9)
        if unit:
            ax.set_ylabel(unit, fontsize=9)
        ax.tick_params(labelsize=8)
        ax.grid(alpha=0.3)
        if len(series) > 1 or threshold is not None:
            ax.legend(fontsize=8, loc="best")
        return ax

    cloths = qa.get("cloths", {})
    plot(grid[1, 0], "deepest penetration", [("bodies", f["body_penetration"], 1e3)]
         + ([("cloth", f["cloth_penetration"], 1e3)] if cloths else []),
         summary.get("body_penetration", {}).get("threshold", 0) * 1e3, "mm")
    if cloths:
        ax = plot(grid[1, 1], "largest cloth strain", [(n, c["strain"], 1e2) for n, c in cloths.items()], unit="%")
        limits = {c["strain_limit"] for c in qa["scene"]["settings"]["cloths"] if c["strain_limit"] > 0}
        for limit in limits:
            ax.axhline(limit * 100, color=BAD_COLOR, ls="--", lw=1)
        plot(grid[1, 2], "cloth self-intersections (triangle pairs)",
             [(n, c["self_intersections"], 1) for n, c in cloths.items()], unit="pairs")
    else:
        for cell in (grid[1, 1], grid[1, 2]):
            ax = fig.add_subplot(cell)
            ax.axis("off")
            ax.text(0.5, 0.5, "no cloth", ha="center", va="center", color="grey")
    plot(grid[1, 3], "kinetic energy", [("", f["kinetic_energy"], 1)], unit="J")
    plot(grid[2, 0], "substeps per frame", [("", f["substeps"], 1)])
    plot(grid[2, 1], "wall time per frame (stepping)", [("", f["wall_seconds"], 1)], unit="s")
    # where the time went
    ax = fig.add_subplot(grid[2, 2:])
    # the cloth_* entries are parts of "cloths": shown, not added again to the total
    stages = sorted(((v, k) for k, v in qa["profile"].items() if v > 0), reverse=True)
    names, seconds = [k for _, k in stages][::-1], [v for v, _ in stages][::-1]
    ax.barh(names, seconds, color=["#9bb3cc" if k.startswith("cloth_") else "#5c7fa3" for k in names])
    total = sum(v for v, k in stages if not k.startswith("cloth_")) or 1.0
    for y, v in enumerate(seconds):
        ax.text(v, y, f" {v:.2f} s ({v / total:.0%})", va="center", fontsize=8)
    ax.set_xlim(0, max(seconds, default=1.0) * 1.25)
    ax.set_title("where the bake's time went (wall s per stage; light: parts of cloths)", fontsize=11)
    ax.tick_params(labelsize=8)
    # the strip of frames
    if strip:
        sub = grid[3, :].subgridspec(1, len(strip), wspace=0.03)
        for k, (frame, image) in enumerate(strip):
            ax = fig.add_subplot(sub[0, k])
            ax.imshow(image)
            ax.axis("off")
    else:
        ax = fig.add_subplot(grid[3, :])
        ax.axis("off")
        ax.text(0.5, 0.5, f"no preview frames: {strip_problem}", ha="center", va="center", color="grey")
    return fig


def write_report(cache: str | Path, output: str | Path | None = None) -> Path:
    """Writes the report of `cache` to `output` (.html or .png; default CACHE.report.html)."""
    cache = Path(cache)
    out = Path(output) if output is not None else report_path(cache)
    check_output_path(out, OUTPUT_SUFFIXES, inputs=[cache, qa_path(cache)])
    qa = _load(cache)
    fig = figure(cache, qa)
    png = io.BytesIO()
    fig.savefig(png, format="png")
    import matplotlib.pyplot as plt

    plt.close(fig)
    if out.suffix.lower() == ".png":
        write_atomically(out, lambda tmp: Path(tmp).write_bytes(png.getvalue()))
    else:
        page = _html(cache, qa, png.getvalue())
        write_atomically(out, lambda tmp: Path(tmp).write_text(page))
    return out


def _html(cache: Path, qa: dict[str, Any], png: bytes) -> str:
    e = html.escape
    warnings = qa["warnings"]
    verdict = (f'<p class="ok">clean: no figure over its threshold</p>' if not warnings else
               f'<p class="bad">{len(warnings)} warning(s)</p><ul>'
               + "".join(f"<li>{e(w)}</li>" for w in warnings) + "</ul>")
    rows = "".join(
        f"<tr><td>{e(name)}</td><td>{e(format_figure(name, s['worst']))}</td><td>{s['frame']}</td>"
        f"<td>{e(format_figure(name, s['threshold'])) if s['threshold'] is not None else ''}</td>"
        f"<td>{s['first_over'] if s['first_over'] is not None else ''}</td></tr>"
        for name, s in qa["summary"].items())
    settings = "".join(f"<li>{e(line)}</li>" for line in _settings_lines(qa))
    image = base64.b64encode(png).decode()
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>simbake report: {e(cache.name)}</title>
<style>body{{font-family:sans-serif;margin:1.5em;color:#222}} .ok{{color:{OK_COLOR};font-weight:bold}}
.bad{{color:{BAD_COLOR};font-weight:bold}} table{{border-collapse:collapse}} td,th{{border:1px solid #ccc;
padding:2px 8px;text-align:right}} td:first-child{{text-align:left}} img{{max-width:100%}}</style></head>
<body><h1>{e(cache.name)}</h1>{verdict}
<img alt="QA figures, stage profile, scene and preview frames" src="data:image/png;base64,{image}">
<h2>Worst values</h2><table><tr><th>figure</th><th>worst</th><th>at frame</th><th>threshold</th>
<th>first frame over</th></tr>{rows}</table>
<h2>Scene</h2><ul>{settings}</ul>
<p>QA data: {e(qa_path(cache).name)}; thresholds: simbake.qa (body penetration {BODY_PENETRATION * 1e3:g} mm,
cloth {CLOTH_PENETRATION * 1e3:g} mm past a surface, strain limit + {STRAIN_MARGIN:.0%}, no self-intersection).</p>
</body></html>
"""


def format_figure(name: str, value: float) -> str:
    """A QA figure's value with its unit (mm, %, J, s) as the report pages show it."""
    if "penetration" in name:
        return f"{value * 1e3:.3g} mm"
    if "strain" in name:
        return f"{value * 1e2:.3g}%"
    if name == "kinetic_energy":
        return f"{value:.4g} J"
    if name == "wall_seconds":
        return f"{value:.3g} s"
    return f"{value:g}"
